"""Results files besides the model: source_velocity.h5, field.h5, rf.h5, the k-Wave
source file.

Schema in ``docs/formats.md``.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.io._atomic import atomic_write

__all__ = [
    "FIELD_FORMAT",
    "KWAVE_SOURCE_FORMAT",
    "RF_FORMAT",
    "SOURCE_VELOCITY_KIND",
    "FieldWriter",
    "field_writer",
    "read_results_h5",
    "read_source_velocity",
    "write_field",
    "write_kwave_source",
    "write_rf",
    "write_source_velocity",
]

SOURCE_VELOCITY_KIND = "holoprobe_source_velocity"
"""The ``kind`` attribute of source_velocity.h5."""


def _text_attr(f: h5py.File, name: str) -> Any:
    """A root attribute, bytes decoded to str (None when absent)."""
    value = f.attrs.get(name)
    return value.decode() if isinstance(value, bytes) else value


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
        at n/fs after the emission (stored as float32, contiguous).
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
        # float32 (the documented dtype: half of float64's 300 MB for a full-size scan),
        # contiguous (readers take it whole; chunking made writing ~1.7x slower)
        ds = f.create_dataset("velocity", data=np.asarray(velocity, dtype=np.float32))
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
            kind = _text_attr(f, "kind")
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


FIELD_FORMAT = "holoprobe-field"
RF_FORMAT = "holoprobe-rf"


def _tag(f: h5py.File, fmt: str, provenance: dict[str, str] | None) -> None:
    """The tags every results file carries: ``format``, ``kind`` and ``schema_version``."""
    f.attrs["format"] = fmt
    f.attrs["kind"] = fmt.removeprefix("holoprobe-")
    f.attrs["schema_version"] = 1
    for key, value in (provenance or {}).items():
        f.attrs[key] = value


def _dataset(f: h5py.File, path: str, data: ArrayLike, units: str, **attrs: str) -> None:
    d = f.create_dataset(path, data=data)
    d.attrs["units"] = units
    for key, value in attrs.items():
        d.attrs[key] = value


def write_field(path: str | os.PathLike, pressure: ArrayLike, time: ArrayLike,
                time_offset: ArrayLike, points: ArrayLike, peak: ArrayLike, *,
                sampling_rate: float, frequency_band: tuple[float, float], method: str,
                plane: str | None = None, axes: tuple[ArrayLike, ArrayLike] | None = None,
                provenance: dict[str, str] | None = None, overwrite: bool = False,
                protect: Iterable[str | os.PathLike] = ()) -> Path:
    """Write a predicted pressure field (``holoprobe field``) to ``field.h5`` atomically.

    Parameters
    ----------
    path : str or PathLike
        Output file.
    pressure : array_like, shape (..., nt)
        Pa; point shape ``S`` (a plane (n0, n1) or (n,) points).
    time : array_like, shape (nt,)
        s; sample n of a point lies at ``time_offset + time[n]``.
    time_offset : array_like, shape S
        s.
    points : array_like, shape S + (3,)
        m.
    peak : array_like, shape S
        Peak positive pressure in Pa.
    sampling_rate, frequency_band, method
        Hz, Hz, the prediction method.
    plane : str, optional
        The plane's axis names (e.g. ``"xz"``); None for points.
    axes : (array_like, array_like), optional
        The plane's axes in m, named by ``plane``.
    provenance : dict of str to str, optional
        More root attributes (model file, transmit file and its TOML).
    overwrite, protect
        As for :func:`holoprobe.io.atomic_write`.
    """
    shape = np.shape(peak)
    with field_writer(path, shape, np.asarray(time), sampling_rate=sampling_rate,
                      frequency_band=frequency_band, plane=plane, axes=axes,
                      provenance=provenance, overwrite=overwrite, protect=protect) as w:
        w.method = method
        w.write(0, np.reshape(pressure, (-1, np.shape(time)[0])), np.ravel(time_offset),
                np.reshape(points, (-1, 3)), np.ravel(peak))
    return Path(path)


class FieldWriter:
    """An open ``field.h5`` being filled chunk by chunk (from :func:`field_writer`).

    Attributes
    ----------
    method : str
        The prediction method, written as a root attribute when the file is closed.
    written : int
        Points written so far.
    """

    def __init__(self, f: h5py.File, shape: tuple[int, ...]):
        self._f = f
        self._shape = shape
        self.method = ""
        self.written = 0

    def write(self, start: int, pressure: ArrayLike, time_offset: ArrayLike,
              points: ArrayLike, peak: ArrayLike) -> None:
        """Store points ``start … start + len(pressure)`` (in the C order of the point shape).

        Parameters
        ----------
        start : int
            First point.
        pressure : array_like, shape (m, nt)
            Pa.
        time_offset : array_like, shape (m,)
            s.
        points : array_like, shape (m, 3)
            m.
        peak : array_like, shape (m,)
            Peak positive pressure in Pa.
        """
        p = np.asarray(pressure, dtype=np.float32)
        m = p.shape[0]
        values = {"pressure": p, "time_offset": np.asarray(time_offset, dtype=float),
                  "points": np.asarray(points, dtype=float),
                  "peak_positive_pressure": np.asarray(peak, dtype=float)}
        if len(self._shape) != 1:  # a plane: written whole
            if start != 0 or m != int(np.prod(self._shape)):
                raise InputError("a plane is written in one piece", field="start")
            for name, v in values.items():
                self._f[name][...] = v.reshape(self._f[name].shape)
        else:
            for name, v in values.items():
                self._f[name][start:start + m] = v
        self.written += m


@contextmanager
def field_writer(path: str | os.PathLike, shape: tuple[int, ...], time: NDArray, *,
                 sampling_rate: float, frequency_band: tuple[float, float],
                 plane: str | None = None, axes: tuple[ArrayLike, ArrayLike] | None = None,
                 provenance: dict[str, str] | None = None, overwrite: bool = False,
                 protect: Iterable[str | os.PathLike] = ()) -> Iterator[FieldWriter]:
    """Open ``field.h5`` for writing chunk by chunk, renamed into place when complete.

    The datasets of :func:`write_field` are created at full size (``pressure`` float32,
    chunked along the points, so memory stays bounded by the caller's chunks) and filled
    by :meth:`FieldWriter.write`; the file appears at ``path`` only when the block exits
    without an error (``holoprobe.io.atomic_write``).

    Parameters
    ----------
    path : str or PathLike
        Output file.
    shape : tuple of int
        Point shape S: (n,) for points, (n0, n1) for a plane.
    time : ndarray, shape (nt,)
        s.
    sampling_rate, frequency_band, plane, axes, provenance, overwrite, protect
        As in :func:`write_field`.

    Yields
    ------
    FieldWriter
    """
    nt = int(np.shape(time)[0])
    n = int(np.prod(shape))
    rows = max(1, min(n, (4 << 20) // max(1, 4 * nt)))  # ~4 MB pressure chunks
    with atomic_write(path, overwrite=overwrite, protect=protect) as tmp, \
            h5py.File(tmp, "w") as f:
        _tag(f, FIELD_FORMAT, provenance)
        f.attrs["plane"] = plane or "points"
        f.attrs["sampling_rate"] = sampling_rate
        f.attrs["frequency_band"] = np.asarray(frequency_band)
        for name, extra, dtype, units in (("pressure", (nt,), np.float32, "Pa"),
                                          ("time_offset", (), float, "s"),
                                          ("points", (3,), float, "m"),
                                          ("peak_positive_pressure", (), float, "Pa")):
            d = f.create_dataset(name, shape=(*shape, *extra), dtype=dtype,
                                 chunks=(rows, *extra) if len(shape) == 1 else None)
            d.attrs["units"] = units
        f["time_offset"].attrs["description"] = ("sample n of a point is at time_offset "
                                                 "+ time[n]")
        f["peak_positive_pressure"].attrs["description"] = (
            "peak of the band-limited record between its samples (holoprobe field: "
            "signal.band_limited_peaks; 4x Fourier interpolation above half Nyquist)")
        _dataset(f, "time", time, "s")
        if axes is not None and plane is not None:
            for k, (name, ax) in enumerate(zip(plane, axes, strict=True)):
                _dataset(f, f"axis_{k}", ax, "m", name=name)
        writer = FieldWriter(f, tuple(shape))
        yield writer
        if writer.written != n:
            raise InputError(f"{writer.written} of {n} points written", file=str(path),
                             field="pressure")
        f.attrs["method"] = writer.method


FOCAL_VOLUME_FORMAT = "holoprobe-focal-volume"


def write_focal_volume(path: str | os.PathLike, pressure: ArrayLike,
                       axes: tuple[ArrayLike, ArrayLike, ArrayLike], *, focus: ArrayLike,
                       axis: ArrayLike, e1: ArrayLike, e2: ArrayLike, frequency: float,
                       provenance: dict[str, str] | None = None, overwrite: bool = False,
                       protect: Iterable[str | os.PathLike] = ()) -> Path:
    """Write the 3-D complex pressure around a focus (``focal_volume.h5``) atomically.

    The grid is aligned with the focal lobe: node (i, j, l) lies at
    ``focus + a1[i] e1 + a2[j] e2 + a3[l] axis`` (scan coordinates); its positions are
    also stored (``points``).

    Parameters
    ----------
    path : str or PathLike
        Output file.
    pressure : array_like, complex, shape (n1, n2, n3)
        CW complex pressure amplitude in Pa (``p(t) = Re{P e^{−iωt}}``).
    axes : (array_like, array_like, array_like)
        a1, a2, a3 in m: distances from the focus along e1, e2 and the axis.
    focus, axis, e1, e2 : array_like, shape (3,)
        Focal maximum (m) and the grid's unit directions (scan coordinates).
    frequency : float
        Hz.
    provenance : dict of str to str, optional
        More root attributes.
    overwrite, protect
        As for :func:`holoprobe.io.atomic_write`.
    """
    path = Path(path)
    p = np.asarray(pressure, np.complex128)
    a1, a2, a3 = (np.asarray(a, float).reshape(-1) for a in axes)
    if p.shape != (a1.size, a2.size, a3.size):
        raise InputError(f"expected pressure of shape {(a1.size, a2.size, a3.size)}, got "
                         f"{p.shape}", file=str(path), field="pressure")
    frame = np.stack([np.asarray(v, float).reshape(3) for v in (e1, e2, axis)])
    grid = np.stack(np.meshgrid(a1, a2, a3, indexing="ij"), axis=-1)
    points = np.asarray(focus, float).reshape(3) + grid @ frame
    with atomic_write(path, overwrite=overwrite, protect=protect) as tmp, \
            h5py.File(tmp, "w") as f:
        _tag(f, FOCAL_VOLUME_FORMAT, provenance)
        f.attrs["frequency"] = float(frequency)
        f.attrs["coordinates"] = "scan"
        f.attrs["convention"] = "p(t) = Re{P exp(-i omega t)}"
        _dataset(f, "pressure", p, "Pa", description="complex pressure amplitude")
        for name, values in (("axis_e1", a1), ("axis_e2", a2), ("axis_along", a3)):
            _dataset(f, name, values, "m", description="distance from the focus")
        _dataset(f, "points", points, "m", description="node positions, scan coordinates")
        _dataset(f, "focus", np.asarray(focus, float).reshape(3), "m")
        for name, vec in (("e1", e1), ("e2", e2), ("axis", axis)):
            _dataset(f, name, np.asarray(vec, float).reshape(3), "1")
    return path


def write_rf(path: str | os.PathLike, rf: ArrayLike, time: ArrayLike, scatterers: ArrayLike,
             amplitudes: ArrayLike, *, unit: str, sampling_rate: float,
             provenance: dict[str, str] | None = None, overwrite: bool = False,
             protect: Iterable[str | os.PathLike] = ()) -> Path:
    """Write simulated element RF (``holoprobe rf``) to ``rf.h5`` atomically.

    Parameters
    ----------
    rf : array_like, shape (n_elements, nt)
        In ``unit`` (the model's receive unit).
    time : array_like, shape (nt,)
        s from the emission.
    scatterers : array_like, shape (n, 3)
        Point positions in m.
    amplitudes : array_like, shape (n,)
        Scattering amplitudes in m.
    """
    path = Path(path)
    with atomic_write(path, overwrite=overwrite, protect=protect) as tmp, \
            h5py.File(tmp, "w") as f:
        _tag(f, RF_FORMAT, provenance)
        f.attrs["sampling_rate"] = sampling_rate
        _dataset(f, "rf", rf, unit)
        _dataset(f, "time", time, "s")
        _dataset(f, "scatterers", scatterers, "m")
        _dataset(f, "amplitudes", amplitudes, "m")
    return path


def read_results_h5(path: str | os.PathLike, fmt: str) -> dict[str, Any]:
    """Every dataset and root attribute of a field.h5 / rf.h5 file of format ``fmt``
    (``"holoprobe-field"`` or ``"holoprobe-rf"``); InputError for another format."""
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", file=str(path))
    try:
        with h5py.File(path, "r") as f:
            found = _text_attr(f, "format")
            if found != fmt:
                raise InputError(f"expected format {fmt!r}, got {found!r}", file=str(path),
                                 field="format")
            out: dict[str, Any] = {k: f.attrs[k] for k in f.attrs}
            out.update({name: np.asarray(f[name][()]) for name in f})
    except OSError as exc:
        raise InputError(f"not a readable HDF5 file ({exc})", file=str(path)) from None
    return out


KWAVE_SOURCE_FORMAT = "holoprobe-kwave-source"


def write_kwave_source(path: str | os.PathLike, mask: ArrayLike, signals: ArrayLike, *,
                       representation: str, spacing: float, dt: float,
                       overwrite: bool = False,
                       protect: Iterable[str | os.PathLike] = ()) -> Path:
    """Write an on-grid k-Wave source (``holoprobe export kwave``) atomically.

    Parameters
    ----------
    mask : array_like, bool, shape (Nx, Ny, Nz)
        Source points of the k-Wave grid (x propagation, y lateral, z elevation, C order).
    signals : array_like, shape (mask.sum(), nt)
        Pa (``representation="monopole"``: source.p = ρ0c0·u) or m/s (``"dipole"``:
        source.ux = u), rows in C order of the mask.
    spacing, dt : float
        Grid step in m and time step in s.
    """
    if representation not in ("monopole", "dipole"):
        raise InputError(f"expected 'monopole' or 'dipole', got {representation!r}",
                         field="representation")
    path = Path(path)
    with atomic_write(path, overwrite=overwrite, protect=protect) as tmp, \
            h5py.File(tmp, "w") as f:
        _tag(f, KWAVE_SOURCE_FORMAT, None)
        f.attrs["representation"] = representation
        f.attrs["axes"] = "x propagation, y lateral, z elevation (k-Wave grid, C order)"
        f.attrs["spacing"] = spacing
        f.attrs["dt"] = dt
        f.create_dataset("mask", data=mask)
        _dataset(f, "signals", signals, "Pa" if representation == "monopole" else "m/s")
    return path
