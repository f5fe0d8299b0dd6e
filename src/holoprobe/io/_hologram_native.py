"""holoprobe's native HDF5 holograms (``kind = "cw_hologram"`` / ``"transient_hologram"``).

Same tagging as every native file (root attributes ``format``, ``kind``,
``schema_version``); every dataset carries ``units``. Schema in ``docs/formats.md``.
"""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError, require_instance
from holoprobe.geometry import PlaneGrid, Pose, SourceGeometry
from holoprobe.io._native import (
    _big_dataset_options,
    _create,
    _dataset,
    _open_checked,
    _Reader,
    _write_medium,
    _write_on_grid,
    read_file_kind,
)
from holoprobe.measurement import Hologram

__all__ = ["KIND_CW_HOLOGRAM", "KIND_TRANSIENT_HOLOGRAM", "read_hologram", "write_hologram"]

KIND_CW_HOLOGRAM = "cw_hologram"
KIND_TRANSIENT_HOLOGRAM = "transient_hologram"
HOLOGRAM_KINDS = (KIND_CW_HOLOGRAM, KIND_TRANSIENT_HOLOGRAM)
_CONVENTION = "p(t) = Re{P exp(-i omega t)} (holoprobe: P = conj(FFT{p}))"
_GEOMETRY_LENGTHS = ("aperture_min", "aperture_max", "opening_diameter")


def write_hologram(path: str | os.PathLike, hologram: Hologram, *, overwrite: bool = False,
                   compression: str | None = None, compression_level: int = 4,
                   chunk_bytes: int = 1 << 20) -> Path:
    """Write a hologram to a native holoprobe HDF5 file (atomically).

    Parameters
    ----------
    path : str or PathLike
        Output file (``.h5``).
    hologram : Hologram
        CW (``kind = "cw_hologram"``, complex ``/pressure`` (nx, ny)) or transient
        (``kind = "transient_hologram"``, real ``/pressure`` (nx, ny, nt)).
    overwrite, compression, compression_level, chunk_bytes
        As for :func:`holoprobe.io.write_scan`.

    Returns
    -------
    pathlib.Path
        The written file.
    """
    require_instance(hologram, Hologram, "hologram")
    kind = KIND_TRANSIENT_HOLOGRAM if hologram.is_transient else KIND_CW_HOLOGRAM
    data = np.asarray(hologram.pressure)
    target = Path(path)
    with _create(target, kind, hologram.source, "holoprobe.io.write_hologram", overwrite) as f:
        options = _big_dataset_options(data, compression, compression_level, chunk_bytes) \
            if hologram.is_transient else {}
        ds = _write_on_grid(f, hologram.grid, "pressure", data, "Pa", **options)
        _dataset(f, "z_position", hologram.z_position, "m")
        if hologram.is_transient:
            ds.dims[2].label = "t"
            _dataset(f, "sampling_rate", float(hologram.sampling_rate or 0.0), "Hz")
            _dataset(f, "start_time", hologram.start_time, "s")
        else:
            ds.attrs["convention"] = _CONVENTION
            # (type: ignore below) a CW Hologram has a frequency
            _dataset(f, "frequency", float(hologram.frequency), "Hz")  # type: ignore[arg-type]
        _write_medium(f, hologram.medium)
        _write_geometry(f, hologram.geometry)
    return target


def _write_geometry(f: h5py.File, g: SourceGeometry | None) -> None:
    if g is None:
        return
    group = f.create_group("source_geometry")
    group.attrs["kind"] = g.kind
    for name in _GEOMETRY_LENGTHS:
        _dataset(group, name, float(getattr(g, name)), "m")
    if g.radius_of_curvature is not None:
        _dataset(group, "radius_of_curvature", g.radius_of_curvature, "m")


class _HologramReader(_Reader):
    """The native reader plus the hologram's complex data and source geometry."""

    # (type: ignore below) reads the hologram's complex array by name and shape
    def complex_array(self, name: str, shape: tuple[int, int]) -> NDArray:  # type: ignore[override]
        if self.node(name).shape != shape:
            raise self.error(f"expected shape {shape} to match /x and /y, got "
                             f"{self.node(name).shape}", name)
        return super().complex_array(name, units="Pa", shape=shape)

    def geometry(self) -> SourceGeometry | None:
        if "source_geometry" not in self.f:
            return None
        g = self.node("/source_geometry", group=True)
        values: dict[str, object] = {
            name: self.scalar(f"/source_geometry/{name}", units="m")
            for name in _GEOMETRY_LENGTHS}
        values["radius_of_curvature"] = (
            self.scalar("/source_geometry/radius_of_curvature", units="m", positive=True)
            if "radius_of_curvature" in g else None)
        values["kind"] = self.attr_str(g, "kind", "/source_geometry")
        return self.build(SourceGeometry, "/source_geometry", **values)


def read_hologram(path: str | os.PathLike) -> Hologram:
    """Read a hologram from a native holoprobe HDF5 file, validating it.

    Parameters
    ----------
    path : str or PathLike
        A file written by :func:`write_hologram`.

    Returns
    -------
    Hologram
        ``source`` is ``str(path)``.

    Raises
    ------
    InputError
        Naming the file and the dataset: wrong kind, missing dataset, wrong shape or
        units, NaN/inf, a non-uniform grid, implausible values.
    """
    kind = read_file_kind(path)
    if kind not in HOLOGRAM_KINDS:
        raise InputError(f"file kind is {kind!r}, expected one of {HOLOGRAM_KINDS}",
                         file=str(path), field="/")
    f, file = _open_checked(path, kind)
    with f:
        r = _HologramReader(f, file)
        x, y = r.grid_axes()
        z = r.scalar("/z_position", units="m")
        extra: dict[str, float] = {}
        if kind == KIND_CW_HOLOGRAM:
            data = r.complex_array("/pressure", (x.size, y.size))
            extra["frequency"] = r.scalar("/frequency", units="Hz", positive=True)
        else:
            data = r.array("/pressure", units="Pa", ndim=3, shape=(x.size, y.size, None))
            extra["sampling_rate"] = r.scalar("/sampling_rate", units="Hz", positive=True)
            extra["start_time"] = r.scalar("/start_time", units="s")
        grid = r.build(PlaneGrid, "", x=x, y=y, pose=Pose(origin=(0.0, 0.0, z)))
        return r.build(Hologram, "", pressure=data, grid=grid, medium=r.medium(),
                       geometry=r.geometry(), source=file, **extra)
