"""Files a characterization writes besides the model: source_velocity.h5.

Schema in ``docs/formats.md``.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import ArrayLike

from holoprobe.errors import InputError
from holoprobe.io._atomic import atomic_write

__all__ = ["SOURCE_VELOCITY_KIND", "read_source_velocity", "write_source_velocity"]

SOURCE_VELOCITY_KIND = "holoprobe_source_velocity"
"""The ``kind`` attribute of source_velocity.h5."""


def write_source_velocity(path: str | os.PathLike, velocity: ArrayLike, x: ArrayLike,
                          y: ArrayLike, sampling_rate: float, band: tuple[float, float], *,
                          overwrite: bool = False,
                          protect: Iterable[str | os.PathLike] = ()) -> Path:
    """Write the back-projected surface velocity to ``source_velocity.h5`` atomically.

    Parameters
    ----------
    path : str or PathLike
        Output file.
    velocity : array_like, shape (nx, ny, nt)
        Normal surface velocity on the source plane z = 0 in m/s, time domain, sample n
        at n/fs after the emission.
    x, y : array_like, shapes (nx,), (ny,)
        Grid axes in m.
    sampling_rate : float
        fs in Hz.
    band : (float, float)
        The signal band in Hz.
    overwrite, protect
        As for :func:`holoprobe.io.atomic_write`.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    path = Path(path)
    with atomic_write(path, overwrite=overwrite, protect=protect) as tmp, \
            h5py.File(tmp, "w") as f:
        f.attrs["kind"] = SOURCE_VELOCITY_KIND
        f.attrs["description"] = (
            "back-projected normal surface velocity on the source plane z = 0 (last "
            "iteration, before lens-delay reversal), time domain, sample n at n/fs after "
            "the emission (advanced by the onset t0 like the transmit IR)")
        ds = f.create_dataset("velocity", data=velocity, chunks=True)
        ds.attrs["units"] = "m/s"
        ds.attrs["axes"] = "x, y, t"
        for name, arr in (("x", x), ("y", y)):
            d = f.create_dataset(name, data=np.asarray(arr))
            d.attrs["units"] = "m"
        d = f.create_dataset("sampling_rate", data=sampling_rate)
        d.attrs["units"] = "Hz"
        d = f.create_dataset("frequency_band", data=np.array(band))
        d.attrs["units"] = "Hz"
    return path


def read_source_velocity(path: str | os.PathLike) -> dict[str, Any]:
    """Read ``source_velocity.h5`` (written by ``holoprobe characterize``).

    Returns
    -------
    dict
        ``velocity`` (nx, ny, nt) in m/s, ``x``, ``y`` in m, ``sampling_rate`` in Hz and
        ``start_time`` in s (0 when the file has none: sample n at n/fs).

    Raises
    ------
    InputError
        When the file is missing, not HDF5, of another kind, or lacks a dataset.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file (run 'holoprobe characterize' first)", file=str(path))
    try:
        with h5py.File(path, "r") as f:
            kind = f.attrs.get("kind")
            if isinstance(kind, bytes):
                kind = kind.decode()
            if kind is not None and kind != SOURCE_VELOCITY_KIND:
                raise InputError(f"expected kind {SOURCE_VELOCITY_KIND!r}, got {kind!r}",
                                 file=str(path), field="kind")
            out: dict[str, Any] = {}
            for name in ("velocity", "x", "y", "sampling_rate"):
                if name not in f:
                    raise InputError("missing dataset", file=str(path), field=name)
                out[name] = np.asarray(f[name][()])
            out["start_time"] = float(f["start_time"][()]) if "start_time" in f else 0.0
    except OSError as exc:
        raise InputError(f"not a readable HDF5 file ({exc})", file=str(path)) from None
    out["sampling_rate"] = float(out["sampling_rate"])
    if out["velocity"].ndim != 3:
        raise InputError(f"expected shape (nx, ny, nt), got {out['velocity'].shape}",
                         file=str(path), field="velocity")
    return out
