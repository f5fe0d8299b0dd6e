"""A reconstructed source surface (:class:`holoprobe.io.SourceVelocity`) for k-wave-python.

On-grid (staircase) source: every surface point goes to its nearest grid point; a grid
point that receives several carries their area-weighted mean signal. A **monopole** source
drives the pressure, ``source.p = ρ0 c0 u`` (the usual k-Wave bowl/disc source); a
**dipole** source drives the particle velocity along the normal, split into
``source.ux, uy, uz`` (u n_x, u n_y, u n_z). NumPy only; :func:`kwave_surface_ksource`
wraps the result in a ``kSource`` (needs the ``[kwave]`` extra).

Axes: scan coordinates (z along the beam) map to k-Wave's (x, y, z) as
(z_scan, x_scan, y_scan) — k-Wave's x is the propagation direction, as in
:func:`holoprobe.export.kwave_source`. Grid point (i, j, l) lies at the k-Wave position
``origin + (i dx, j dy, l dz)``, ``origin`` being the k-Wave coordinates of point (0, 0, 0).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError

__all__ = ["kwave_surface_ksource", "kwave_surface_source", "scan_to_kwave"]

_REPRESENTATIONS = ("monopole", "dipole")


def scan_to_kwave(points: ArrayLike) -> NDArray[np.float64]:
    """Scan coordinates (x, y, z), shape (..., 3) → k-Wave axes (z, x, y)."""
    p = np.asarray(points, dtype=float)
    return p[..., [2, 0, 1]]


def _signals(source: Any, dt: float, nt: int, cycles_ramp: float) -> NDArray[np.float64]:
    """Normal velocity (m/s) per surface point on the k-Wave time axis t = n dt."""
    t = np.arange(nt) * dt
    if source.spectral:
        rate = float(source.sampling_rate)
        wave = source.waveforms()
        t_src = np.arange(wave.shape[1]) / rate
        return np.stack([np.interp(t, t_src, w, left=0.0, right=0.0) for w in wave])
    f = float(source.frequencies[0])
    ramp = np.clip(t * f / cycles_ramp, 0.0, 1.0) if cycles_ramp > 0 else np.ones_like(t)
    return np.real(source.velocity[:, :1] * np.exp(-2j * np.pi * f * t)[None, :]) * ramp


def kwave_surface_source(source: Any, shape: tuple[int, int, int],
                         spacing: tuple[float, float, float], origin: ArrayLike, dt: float,
                         nt: int, *, representation: str = "monopole",
                         drive_scale: float = 1.0, ramp_cycles: float = 3.0
                         ) -> tuple[NDArray[np.bool_], NDArray[np.float64] | tuple[NDArray, ...]]:
    """Staircase k-Wave source of a reconstructed surface: mask and per-point signals.

    Parameters
    ----------
    source : SourceVelocity
        From :func:`holoprobe.io.read_source` or
        :func:`holoprobe.characterize.source_velocity` (scan coordinates).
    shape : (int, int, int)
        k-Wave grid (Nx, Ny, Nz).
    spacing : (float, float, float)
        Grid steps (dx, dy, dz) in m.
    origin : array_like, shape (3,)
        k-Wave coordinates (m) of grid point (0, 0, 0) (:func:`scan_to_kwave` of a scan
        position).
    dt, nt : float, int
        Time step (s) and number of steps.
    representation : {"monopole", "dipole"}
        ``source.p = ρ0 c0 u`` or ``source.ux/uy/uz = u n``.
    drive_scale : float
        Multiplies the velocity (CW drive scaling).
    ramp_cycles : float
        CW sources: the amplitude ramps up linearly over this many cycles.

    Returns
    -------
    mask : ndarray of bool, shape (Nx, Ny, Nz)
    signals : ndarray, shape (mask.sum(), nt), or a tuple (ux, uy, uz) of them
        Pa (monopole) or m/s (dipole), rows in C order of the mask.
    """
    if representation not in _REPRESENTATIONS:
        raise InputError(f"expected one of {_REPRESENTATIONS}, got {representation!r}",
                         field="representation")
    dims = tuple(int(n) for n in shape)
    step = np.asarray(spacing, float)
    pts = scan_to_kwave(source.surface.points)
    idx = np.rint((pts - np.asarray(origin, float)) / step).astype(int)
    outside = np.any((idx < 0) | (idx >= np.array(dims)), axis=1)
    if np.any(outside):
        raise InputError(f"{int(outside.sum())} of {len(idx)} surface points fall outside "
                         f"the k-Wave grid {dims} (origin {np.asarray(origin)} m, steps "
                         f"{step} m)", field="shape")
    flat = np.ravel_multi_index(idx.T, dims)
    cells, row = np.unique(flat, return_inverse=True)
    w = source.surface.weights
    norm = np.bincount(row, w, cells.size)
    u = _signals(source, dt, nt, ramp_cycles) * drive_scale

    def mean_per_cell(values: NDArray) -> NDArray:
        out = np.zeros((cells.size, nt))
        np.add.at(out, row, values * w[:, None])
        return out / norm[:, None]

    mask = np.zeros(dims, bool)
    mask.ravel()[cells] = True  # np.unique sorts: rows follow the mask's C order
    if representation == "monopole":
        return mask, source.medium.impedance * mean_per_cell(u)
    normals = scan_to_kwave(source.surface.normals)
    return mask, tuple(mean_per_cell(u * normals[:, a][:, None]) for a in range(3))


def kwave_surface_ksource(source: Any, kgrid: Any, origin: ArrayLike, *,
                          representation: str = "monopole", drive_scale: float = 1.0,
                          ramp_cycles: float = 3.0) -> Any:
    """A k-wave-python ``kSource`` for a reconstructed surface (needs the ``[kwave]`` extra).

    ``kgrid`` supplies the shape, steps and time axis; see :func:`kwave_surface_source`.
    """
    from kwave.ksource import kSource

    mask, signals = kwave_surface_source(
        source, (int(kgrid.Nx), int(kgrid.Ny), int(kgrid.Nz)),
        (float(kgrid.dx), float(kgrid.dy), float(kgrid.dz)), origin, float(kgrid.dt),
        int(kgrid.Nt), representation=representation, drive_scale=drive_scale,
        ramp_cycles=ramp_cycles)
    ks = kSource()
    if representation == "monopole":
        ks.p_mask, ks.p = mask, signals
    else:
        ks.u_mask = mask
        ks.ux, ks.uy, ks.uz = signals
    return ks
