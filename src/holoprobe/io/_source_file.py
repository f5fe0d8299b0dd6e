"""The self-describing source file (``kind = "source_velocity"``): a reconstructed source.

A sampled surface (points, unit normals, areas) and its complex normal velocity per
frequency, in scan coordinates, with the medium and the source's geometry. Any simulator
can rebuild the source from it (a velocity source on the points, or the per-point
waveforms ``irfft`` of the spectra). Schema in ``docs/formats.md`` ("Source files").
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError, require_instance
from holoprobe.geometry import Medium, Surface
from holoprobe.io._atomic import atomic_write
from holoprobe.io._native import _dataset, _open_checked, _Reader, _write_medium, _write_root

__all__ = ["KIND_SOURCE_VELOCITY", "SourceVelocity", "read_source", "write_source"]

KIND_SOURCE_VELOCITY = "source_velocity"
_CONVENTION = "v(t) = Re{V exp(-i omega t)} (holoprobe: V = conj(FFT{v}))"


@dataclass(frozen=True)
class SourceVelocity:
    """A source surface and its complex normal velocity.

    Attributes
    ----------
    surface : Surface
        Points (m), unit normals (into the medium) and areas (m²), shape (n, ·).
    frequencies : ndarray, shape (nf,)
        Hz.
    velocity : ndarray, complex, shape (n, nf)
        Normal velocity: CW amplitudes in m/s (``spectral=False``) or spectra in m/s·s
        (``spectral=True``, bins of a record of ``n_time`` samples at ``sampling_rate``).
    medium : Medium
    kind : str
        Source model (``"spherical-cap"``, ``"flat-disc"``, ...).
    radius_of_curvature : float or None
        m.
    aperture : (float, float)
        m (diameter twice for circular sources).
    apex, axis : ndarray, shape (3,)
        Apex (or centre) and unit axis, m / 1.
    spectral : bool
        Whether ``velocity`` holds spectra of a transient source.
    sampling_rate : float or None
        Hz (spectral only).
    n_time : int or None
        Record length (spectral only).
    coordinates : str
        What the coordinates are (e.g. scan coordinates).
    """

    surface: Surface
    frequencies: NDArray[np.float64]
    velocity: NDArray[np.complex128]
    medium: Medium = field(default_factory=Medium)
    kind: str = ""
    radius_of_curvature: float | None = None
    aperture: tuple[float, float] = (0.0, 0.0)
    apex: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    axis: NDArray[np.float64] = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    spectral: bool = False
    sampling_rate: float | None = None
    n_time: int | None = None
    coordinates: str = "scan"

    def __post_init__(self) -> None:
        f = np.atleast_1d(np.asarray(self.frequencies, float))
        v = np.asarray(self.velocity, np.complex128)
        if v.ndim == 1:
            v = v[:, None]
        if v.shape != (self.surface.size, f.size):
            raise InputError(f"expected shape ({self.surface.size}, {f.size}) (points, "
                             f"frequencies), got {v.shape}", field="velocity")
        if not (np.all(np.isfinite(f)) and np.all(f > 0)):
            raise InputError("expected positive finite frequencies in Hz", field="frequencies")
        if self.spectral and (self.sampling_rate is None or self.n_time is None):
            raise InputError("spectral velocities need sampling_rate and n_time",
                             field="sampling_rate")
        object.__setattr__(self, "frequencies", f)
        object.__setattr__(self, "velocity", v)

    def waveforms(self) -> NDArray[np.float64]:
        """Normal-velocity waveforms (m/s), shape (n, n_time), of a spectral source."""
        if not self.spectral:
            raise InputError("a CW source has no waveforms", field="spectral")
        n, fs = self.n_time, self.sampling_rate
        assert n is not None and fs is not None  # __post_init__: a spectral source has both
        spec = np.zeros((self.surface.size, n // 2 + 1), np.complex128)
        bins = np.rint(self.frequencies * n / fs).astype(int)
        spec[:, bins] = self.velocity
        return np.fft.irfft(np.conj(spec), n, axis=1) * float(fs)


def write_source(path: str | os.PathLike, source: SourceVelocity, *,
                 overwrite: bool = False) -> Path:
    """Write a :class:`SourceVelocity` to an HDF5 file atomically (schema: docs/formats.md).

    Returns
    -------
    pathlib.Path
    """
    require_instance(source, SourceVelocity, "source")
    target = Path(path)
    with atomic_write(target, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as f:
        _write_root(f, KIND_SOURCE_VELOCITY, "", "holoprobe.io.write_source")
        f.attrs["coordinates"] = source.coordinates
        f.attrs["convention"] = _CONVENTION
        _write_medium(f, source.medium)
        s = f.create_group("surface")
        _dataset(s, "points", source.surface.points, "m")
        _dataset(s, "normals", source.surface.normals, "1")
        _dataset(s, "areas", source.surface.weights, "m^2")
        _dataset(f, "frequencies", source.frequencies, "Hz")
        _dataset(f, "velocity", source.velocity, "m/s*s" if source.spectral else "m/s")
        g = f.create_group("geometry")
        g.attrs["kind"] = source.kind
        if source.radius_of_curvature is not None:
            _dataset(g, "radius_of_curvature", float(source.radius_of_curvature), "m")
        _dataset(g, "aperture", np.asarray(source.aperture, float), "m")
        _dataset(g, "apex", np.asarray(source.apex, float), "m")
        _dataset(g, "axis", np.asarray(source.axis, float), "1")
        if source.spectral:
            fs, n = source.sampling_rate, source.n_time
            assert fs is not None and n is not None  # __post_init__: a spectral source has both
            _dataset(f, "sampling_rate", float(fs), "Hz")
            _dataset(f, "n_time", np.int64(n), "1")
    return target


def read_source(path: str | os.PathLike) -> SourceVelocity:
    """Read a source file written by :func:`write_source` (every dataset checked)."""
    f, file = _open_checked(path, KIND_SOURCE_VELOCITY)
    with f:
        r = _Reader(f, file)
        points = r.array("surface/points", units="m", ndim=2)
        normals = r.array("surface/normals", units="1", ndim=2)
        areas = r.array("surface/areas", units="m^2", ndim=1)
        freqs = r.array("frequencies", units="Hz", ndim=1)
        spectral = "sampling_rate" in f
        vel = r.complex_array("velocity", units="m/s*s" if spectral else "m/s",
                              shape=(points.shape[0], freqs.size))
        roc = r.scalar("geometry/radius_of_curvature", units="m", positive=True) \
            if "geometry/radius_of_curvature" in f else None
        kind = r.attr_str(f["geometry"], "kind", "geometry")
        surface = r.build(Surface, "surface", points=points, normals=normals, weights=areas)
        return r.build(
            SourceVelocity, "", surface=surface, frequencies=freqs, velocity=vel,
            medium=r.medium(), kind=kind,
            radius_of_curvature=roc,
            aperture=tuple(r.array("geometry/aperture", units="m", ndim=1)),
            apex=r.array("geometry/apex", units="m", ndim=1),
            axis=r.array("geometry/axis", units="1", ndim=1), spectral=spectral,
            sampling_rate=r.scalar("sampling_rate", units="Hz") if spectral else None,
            n_time=r.integer("n_time") if spectral else None,
            coordinates=r.attr_str(f, "coordinates", "/", default="scan"))
