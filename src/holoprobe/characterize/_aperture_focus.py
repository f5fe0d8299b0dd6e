"""The focal maximum radiated by the reconstructed aperture (``hologram.focus_estimator``).

The plane-wave estimate of :func:`holoprobe.characterize.align_focused` uses every
propagating wave of the hologram. Most of its noise comes through waves that cross the
focus at angles the aperture cannot radiate (on a 40/R40 81² twin at 40 dB, the waves
within 40° of the axis carry 97.7 % of the signal and give σ z 3.4 µm of its 12.8 µm), but
the maximum depends on them too: cutting them off moves it by hundreds of µm. The source
does not radiate them; only its rim's diffraction does. So the field is radiated again
from the source itself: the hologram's plane waves give the normal velocity on the placed
source surface, kept within ``aperture_margin_wavelengths`` of the fitted aperture's
rim, and its Rayleigh integral (∝ Σ w_s v_s e^{ikR}/R) has its maximum found by Newton's
method with analytic derivatives. What the Rayleigh integral of a curved surface's own
velocity does not reproduce (a few µm, the same for a uniform cap) is the model's
bias: the same estimate on the hologram of a uniform cap placed where the source was
(:func:`cap_hologram`), minus that cap's exact maximum (O'Neil), is removed and kept
in σ. The noise is propagated linearly: the focus moves by −H⁻¹ δ∇|p|², a real-linear
functional of the hologram samples through the expansion, the velocity and the integral.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from holoprobe.characterize._alignment import (
    _fit_axis,
    _half_level_distance,
    _sample_functionals,
    orthonormal_frame,
)
from holoprobe.characterize._hologram_config import HologramConfig
from holoprobe.characterize._hologram_field import PlaneWaveField, _type3, plane_wave_field
from holoprobe.geometry import Medium, PlaneGrid

__all__ = ["aperture_axis", "aperture_focus"]

# type-3 NUFFT tolerance of the velocity and the noise functional (the back-projection's,
# :func:`hologram_plan`), on one thread (a second one only added spin-waits under load)
_EPS = 1e-6


class _RadiatedField:
    """p(r) = Σ_s a_s e^{ikR_s}/R_s (R_s = |r − x_s|) with its derivatives: the
    Rayleigh integral of the kept nodes x_s (a_s = w_s v_s, the constant factor dropped)."""

    def __init__(self, nodes: NDArray, strengths: NDArray, k: float):
        self.nodes, self.strengths, self.k = nodes, strengths, k

    def kernels(self, point: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        """G (n,), ∇G (n, 3) and ∇∇G (n, 3, 3) of e^{ikR}/R at ``point``."""
        d = point[None, :] - self.nodes
        r = np.linalg.norm(d, axis=1)
        u = d / r[:, None]
        k = self.k
        g = np.exp(1j * k * r) / r
        f1 = (1j * k - 1 / r)                                   # dG/dR = f1 G
        f2 = (1j * k - 1 / r) ** 2 + 1 / r**2                   # d²G/dR² = f2 G
        grad = (f1 * g)[:, None] * u
        outer = u[:, :, None] * u[:, None, :]
        eye = np.eye(3)[None, :, :]
        hess = g[:, None, None] * (f2[:, None, None] * outer
                                   + (f1 / r)[:, None, None] * (eye - outer))
        return g, grad, hess

    def derivatives(self, point: NDArray) -> tuple[complex, NDArray, NDArray]:
        g, grad, hess = self.kernels(np.asarray(point, float))
        a = self.strengths
        return complex(a @ g), a @ grad, np.einsum("s,sij->ij", a, hess)

    def amplitude_local(self, origin: NDArray, directions: NDArray, local: NDArray
                        ) -> NDArray[np.float64]:
        """|p| at origin + local @ directions (local (npts, m), directions (m, 3))."""
        d = np.linalg.norm((origin + local @ directions)[:, None, :] - self.nodes[None],
                           axis=2)
        return np.abs((np.exp(1j * self.k * d) / d) @ self.strengths)

    def intensity_derivatives(self, point: NDArray) -> tuple[float, NDArray, NDArray]:
        p, g, h = self.derivatives(point)
        return (abs(p) ** 2, 2 * np.real(np.conj(p) * g),
                2 * np.real(np.outer(np.conj(g), g) + np.conj(p) * h))


def _velocity(field: PlaneWaveField, nodes: NDArray, normals: NDArray) -> NDArray:
    """Normal velocity (m/s, up to ρc: Σ c (k·n)/k e^{ik·x}) at the nodes."""
    cols = _type3(field.wave_vectors, field.coefficients[None, :] * field.wave_vectors.T,
                  nodes, _EPS, threads=1)
    return np.einsum("sj,js->s", normals, cols) / field.wavenumber


def _maximum(field: _RadiatedField, start: NDArray, wavelength: float,
             iterations: int = 40) -> NDArray:
    """Newton on |p|² from ``start`` (steps ≤ λ/4; gradient ascent where not concave)."""
    r = np.asarray(start, float).copy()
    for _ in range(iterations):
        _, g, h = field.intensity_derivatives(r)
        w = np.linalg.eigvalsh(h)
        step = -np.linalg.solve(h, g) if np.all(w < 0) else g / (np.abs(w).max() + 1e-300)
        norm = np.linalg.norm(step)
        if norm > wavelength / 4:
            step *= wavelength / 4 / norm
        r = r + step
        if norm < 1e-10:
            break
    return r


def _radiating(pressure: NDArray, grid: PlaneGrid, frequency: float, medium: Medium,
               nodes: NDArray, normals: NDArray, weights: NDArray, keep: NDArray,
               start: NDArray, velocity: NDArray | None, cfg: HologramConfig
               ) -> tuple[PlaneWaveField, _RadiatedField, NDArray, NDArray, NDArray]:
    """The expansion reaching the kept nodes and ``start``, the field those nodes radiate,
    and the kept nodes, normals and weights."""
    x, n, w = nodes[keep], normals[keep], weights[keep]
    field = plane_wave_field(pressure, grid, frequency, medium,
                             reach=np.vstack([x, start[None, :]]),
                             prune_tolerance=cfg.prune_tolerance,
                             guard_energy=cfg.guard_energy,
                             guard_margin_deg=cfg.guard_margin_deg)
    v = _velocity(field, x, n) if velocity is None else \
        np.asarray(velocity)[keep] * medium.impedance       # ρc v: the units of _velocity
    return field, _RadiatedField(x, w * v, field.wavenumber), x, n, w


def aperture_focus(pressure: NDArray, grid: PlaneGrid, frequency: float, medium: Medium,
                   nodes: NDArray, normals: NDArray, weights: NDArray, keep: NDArray,
                   start: NDArray, *, noise_level: float = 0.0,
                   velocity: NDArray | None = None, cfg: HologramConfig | None = None
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Focal maximum (m) of the field the kept source nodes radiate, and its noise σ (m).

    Parameters
    ----------
    pressure : ndarray, complex, shape (nx, ny)
        CW hologram (Pa) on ``grid`` (untapered).
    grid : PlaneGrid
    frequency : float
        Hz.
    medium : Medium
    nodes, normals : ndarray, shape (n, 3)
        The placed source surface's nodes (m) and unit normals (into the medium).
    weights : ndarray, shape (n,)
        Their quadrature weights (m²).
    keep : ndarray of bool, shape (n,)
        The nodes that radiate (the aperture and its rim).
    start : ndarray, shape (3,)
        Where Newton's method starts (m; the plane-wave estimate).
    noise_level : float
        White noise per hologram sample (Pa); 0: no noise term.
    velocity : ndarray, complex, shape (n,), optional
        The normal velocity (m/s) of ``pressure`` at every node, already back-projected
        (:func:`backproject_source`); default computed here from the expansion.
    cfg : HologramConfig, optional
        The plane-wave expansion's settings (``prune_tolerance``, ``guard_energy``,
        ``guard_margin_deg``).

    Returns
    -------
    focus : ndarray, shape (3,)
    sigma : ndarray, shape (3,)
        The hologram noise's standard deviation of each coordinate (m).
    """
    cfg = cfg or HologramConfig()
    field, rad, _, n, w = _radiating(pressure, grid, frequency, medium, nodes, normals,
                                     weights, keep, start, velocity, cfg)
    k = rad.k
    focus = _maximum(rad, start, 2 * np.pi / k)
    if not noise_level > 0:
        return focus, np.zeros(3)
    u = _gradient_noise(field, rad, n, w, [focus], [-np.linalg.inv(
        rad.intensity_derivatives(focus)[2])], grid.shape)
    cov = 2 * noise_level**2 * np.real(u @ u.conj().T)
    return focus, np.sqrt(np.clip(np.diag(cov), 0.0, None))


def _gradient_noise(field: PlaneWaveField, rad: _RadiatedField, normals: NDArray,
                    weights: NDArray, points: list[NDArray], maps: list[NDArray],
                    shape: tuple[int, int]) -> NDArray[np.complex128]:
    """Functionals (m, samples) of Σ_j maps_j δ∇|p|²(points_j) on the hologram samples.

    δ∇|p|² = 2 Re(Σ_s b_s δv_s), b_s = w_s (conj(∇p) G_s + conj(p) ∇G_s); δv_s is
    Σ_κ (k_κ·n_s)/k e^{ik_κ·x_s} δc_κ: the functional on the plane waves is a type-3 sum
    over the nodes per (row, normal component) pair. ``maps_j`` is (m, 3): the linear
    response of the estimate to the gradient at ``points_j`` (−H⁻¹ for a maximum).
    """
    x = rad.nodes
    b = np.zeros((x.shape[0], maps[0].shape[0]), np.complex128)
    for point, lin in zip(points, maps, strict=True):
        p, g, _ = rad.derivatives(point)
        gk, gradk, _ = rad.kernels(point)
        b += weights[:, None] * (np.conj(g)[None, :] * gk[:, None] + np.conj(p) * gradk) \
            @ lin.T
    m, kv = b.shape[1], field.wave_vectors
    pairs = _type3(x, (b.T[:, None, :] * normals.T[None, :, :]).reshape(3 * m, -1), kv,
                   _EPS, threads=1)
    q = np.einsum("ajm,mj->am", pairs.reshape(m, 3, -1), kv)
    return _sample_functionals(field, q / rad.k, np.ones(shape))


def aperture_axis(pressure: NDArray, grid: PlaneGrid, frequency: float, medium: Medium,
                  nodes: NDArray, normals: NDArray, weights: NDArray, keep: NDArray,
                  focus: NDArray, axis: NDArray, *,
                  noise_level: float = 0.0, velocity: NDArray | None = None,
                  cfg: HologramConfig | None = None) -> tuple[NDArray[np.float64], float]:
    """Lobe axis (unit vector) of the field the kept source nodes radiate, and its noise σ
    (rad): the lobe centres in ``cfg.axis_planes`` planes across ``cfg.axis_span`` of
    that field's own −6 dB axial half-lengths about ``focus`` (its maximum, m;
    :func:`_fit_axis`, as the plane-wave estimate, re-oriented ``cfg.axis_iterations``
    times from ``axis``). σ is
    the hologram noise propagated linearly: each centre moves by −H₂⁻¹ δ∇₂|p|² in its
    plane, the axis by the least-squares slope of those moves; the fit's own standard
    error (the centres' scatter about the line) is added, as for the plane-wave axis.
    Other parameters as
    :func:`aperture_focus`.
    """
    cfg = cfg or HologramConfig()
    field, rad, _, n, w = _radiating(pressure, grid, frequency, medium, nodes, normals,
                                     weights, keep, focus, velocity, cfg)
    wavelength = 2 * np.pi / rad.k
    peak, reach = float(np.sqrt(rad.intensity_derivatives(focus)[0])), \
        cfg.lobe_reach_wavelengths * wavelength
    for _ in range(max(cfg.axis_iterations, 1)):
        # (type: ignore below) _RadiatedField has the methods both use (duck-typed Field)
        extent = [_half_level_distance(rad, focus, axis, peak, reach, sign)  # type: ignore[arg-type]
                  for sign in (-1.0, 1.0)]
        offsets = np.linspace(-cfg.axis_span * extent[0], cfg.axis_span * extent[1],
                              cfg.axis_planes)
        # (type: ignore below) the same duck-typed field
        axis, centres, se = _fit_axis(rad, focus, axis, offsets, wavelength)  # type: ignore[arg-type]
    if not noise_level > 0:
        return axis, se
    e1, e2 = orthonormal_frame(axis)
    basis = np.stack([e1, e2], axis=1)                                    # (3, 2)
    s = (centres - focus) @ axis
    slope_row = np.linalg.pinv(np.stack([np.ones_like(s), s], axis=1))[1]   # (planes,)
    maps = [a * (basis @ -np.linalg.inv(basis.T @ rad.intensity_derivatives(c)[2] @ basis)
                 @ basis.T) for a, c in zip(slope_row, centres, strict=True)]
    u = _gradient_noise(field, rad, n, w, list(centres), maps, grid.shape)
    cov = 2 * noise_level**2 * np.real(u @ u.conj().T)
    return axis, float(np.sqrt(max(np.trace(cov), 0.0) + se**2))
