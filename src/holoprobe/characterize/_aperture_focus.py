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

from holoprobe.characterize._alignment import _sample_functionals
from holoprobe.characterize._hologram_config import HologramConfig
from holoprobe.characterize._hologram_field import PlaneWaveField, _type3, plane_wave_field
from holoprobe.geometry import Medium, PlaneGrid

__all__ = ["aperture_focus"]

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
    x, n, w = nodes[keep], normals[keep], weights[keep]
    field = plane_wave_field(pressure, grid, frequency, medium,
                             reach=np.vstack([x, start[None, :]]),
                             prune_tolerance=cfg.prune_tolerance,
                             guard_energy=cfg.guard_energy,
                             guard_margin_deg=cfg.guard_margin_deg)
    k = field.wavenumber
    v = _velocity(field, x, n) if velocity is None else \
        np.asarray(velocity)[keep] * medium.impedance       # ρc v: the units of _velocity
    rad = _RadiatedField(x, w * v, k)
    focus = _maximum(rad, start, 2 * np.pi / k)
    if not noise_level > 0:
        return focus, np.zeros(3)
    # δ∇|p|² = 2 Re(Σ_s b_s δv_s), b_s = w_s (conj(∇p) G_s + conj(p) ∇G_s); δv_s is
    # Σ_κ (k_κ·n_s)/k e^{ik_κ·x_s} δc_κ: the functional on the plane waves is a
    # type-3 sum over the nodes per component pair
    p, g, h = rad.derivatives(focus)
    gk, gradk, _ = rad.kernels(focus)
    b = w[:, None] * (np.conj(g)[None, :] * gk[:, None] + np.conj(p) * gradk)  # (n, 3)
    kv = field.wave_vectors
    pairs = _type3(x, (b.T[:, None, :] * n.T[None, :, :]).reshape(9, -1), kv, _EPS, threads=1)
    q = np.einsum("ajm,mj->am", pairs.reshape(3, 3, -1), kv)
    hess = 2 * np.real(np.outer(np.conj(g), g) + np.conj(p) * h)
    u = _sample_functionals(field, -np.linalg.inv(hess) @ (q / k),
                            np.ones(grid.shape))
    cov = 2 * noise_level**2 * np.real(u @ u.conj().T)
    return focus, np.sqrt(np.clip(np.diag(cov), 0.0, None))
