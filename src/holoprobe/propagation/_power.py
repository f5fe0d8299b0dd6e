"""Acoustic power through a plane and radiated by a baffled plane source (angular spectrum).

Through a plane (``plane_power``), the time average of ``p = Re{P e^{−iωt}}``::

    W = 1/(2 ρ0 c0) · 1/(4π²) ∫∫ |P̂(kx, ky)|² Re(kz / k) dkx dky

exact for the propagating part (evanescent waves carry no power). Leaving a source plane in
a rigid baffle with normal velocity ``U`` (``source_power``)::

    W = (ρ0 c0 / 2) · 1/(4π²) ∫∫ |Û|² Re(k / kz) dkx dky

whose integrable singularity at ``|κ| = k`` is handled by the ring-averaged propagator
(:func:`spectral_propagator`, ``averaged=True``, d = 0). For a baffled piston of area A this
is ``|u|²/2`` times the radiation resistance ``ρ0 c0 A [1 − J1(2ka)/(ka)]``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid
from holoprobe.propagation._angular_spectrum import (
    angular_spectrum,
    spectral_propagator,
    wavenumber_axes,
)

__all__ = ["plane_power", "source_power"]


def _weighted_energy(field: NDArray, grid: PlaneGrid, frequency: float, medium: Medium,
                     kind: str, padding: float, averaged: bool) -> float:
    """``1/(4π²) Σ |F̂|² Re G_kind(d=0) Δkx Δky`` on a grid zero-padded by ``padding``."""
    nx, ny = grid.shape
    shape = (max(nx, round(padding * nx)), max(ny, round(padding * ny)))
    spec = angular_spectrum(field, grid, shape=shape)
    kx, ky = wavenumber_axes(shape[0], shape[1], grid.dx, grid.dy)
    k = 2 * math.pi * frequency / medium.sound_speed
    g = spectral_propagator(kx, ky, k, 0.0, kind=kind, averaged=averaged)
    g = np.where(np.isfinite(g.real), g.real, 0.0)
    dkx, dky = 2 * math.pi / (shape[0] * grid.dx), 2 * math.pi / (shape[1] * grid.dy)
    return float(np.sum(np.abs(spec) ** 2 * g) * dkx * dky / (4 * math.pi**2))


def _check_plane(field: ArrayLike, grid: PlaneGrid, frequency: float, name: str) -> NDArray:
    arr = np.asarray(field)
    if not isinstance(grid, PlaneGrid):
        raise InputError("expected a PlaneGrid", field="grid")
    if arr.shape[:2] != grid.shape:
        raise InputError(f"expected shape {grid.shape}, got {arr.shape}", field=name)
    if not np.all(np.isfinite(arr)):
        raise InputError("contains NaN or inf", field=name)
    if not (math.isfinite(frequency) and frequency > 0):
        raise InputError(f"expected a positive frequency in Hz, got {frequency!r}",
                         field="frequency")
    return arr


def plane_power(pressure: ArrayLike, grid: PlaneGrid, frequency: float,
                medium: Medium | None = None, *, method: str = "angular_spectrum",
                padding: float = 2.0, averaged: bool = True) -> float:
    """Time-average power (W) of a CW field ``p = Re{P e^{−iωt}}`` through a plane.

    Parameters
    ----------
    pressure : array_like, complex, shape (nx, ny)
        Complex amplitude P in Pa on ``grid`` (a plane; the power crosses its normal).
    grid : PlaneGrid
        Uniform grid, steps ≤ λ/2 so that every propagating wave is resolved.
    frequency : float
        Hz.
    medium : Medium, optional
        ρ0, c0 (default water).
    method : {"angular_spectrum", "plane_wave"}
        Exact normal intensity of the propagating part, or the plane-wave approximation
        ``∫∫ |P|²/(2ρ0c0) dA`` (IEC).
    padding : float
        Zero-padding factor of the transform (finer k-space rings).
    averaged : bool
        Ring-averaged ``Re Ḡ_pv`` (default) or the point-sampled ``kz/k``.

    Returns
    -------
    float
        W.
    """
    med = Medium() if medium is None else medium
    p = _check_plane(pressure, grid, frequency, "pressure")
    if method == "plane_wave":
        return float(np.sum(np.abs(p) ** 2) * grid.dx * grid.dy / (2 * med.impedance))
    if method != "angular_spectrum":
        raise InputError(f"expected 'angular_spectrum' or 'plane_wave', got {method!r}",
                         field="method")
    energy = _weighted_energy(p, grid, frequency, med, "pv", padding, averaged)
    return energy / (2 * med.impedance)


def source_power(velocity: ArrayLike, grid: PlaneGrid, frequency: float,
                 medium: Medium | None = None, *, padding: float = 2.0) -> float:
    """Time-average power (W) radiated by a normal velocity ``u = Re{U e^{−iωt}}`` (m/s on
    ``grid``, zero outside the source) on a plane in a rigid baffle."""
    med = Medium() if medium is None else medium
    u = _check_plane(velocity, grid, frequency, "velocity")
    return _weighted_energy(u, grid, frequency, med, "vp", padding, True) * med.impedance / 2
