"""Alignment of a focused source from its hologram: focal maximum and acoustic axis.

The forward-projected field is the plane-wave sum of :class:`PlaneWaveField`, evaluated at
continuous points, so nothing is limited by an evaluation grid:

* **focal maximum** — coarse search of |p| along the power-weighted beam direction, a
  lateral re-centring, then Newton's method on |p|² with the analytic gradient and Hessian;
* **acoustic axis** — the axis of the focal lobe as holography users define it: in planes
  across the lobe (perpendicular to the current axis, spanning ``axis_span`` of its −6 dB
  axial extent on each side of the maximum) the lobe's centre (the in-plane maximum, again
  by Newton) is found; the axis is the least-squares line through those centres, and the
  planes are re-oriented to it a few times;
* **power-weighted beam direction** — Σ W_κ k̂_κ over the plane waves, reported separately
  (a weak segment tilts it, not the lobe axis);
* **the scan window** — the hologram is brought smoothly to zero over the outer
  ``window_taper`` of its width (Tukey) before the focus and axis are found. A hard
  truncation of a field still a few per cent of its peak at the window's edge leaks
  spectrum beyond |κ| = k, which a λ/2 scan folds back into wide-angle plane waves; their
  weak field near the focus tilts the very flat axial lobe (a lobe 10–20 mm long moves by
  tens of µm for a slope of 0.1 % of its peak per mm). The taper removes most of that
  leakage and changes only the weak, outward-going edge of the field; the change of the
  estimate between the tapered and the untapered window is kept as the window term of
  the uncertainty (on twins the tapered error stayed within it);
* **uncertainties** — the hologram's noise (estimated from its evanescent spectrum, or
  given) is propagated linearly: the focus and every lobe centre move by one Newton step
  −H⁻¹δ∇|p|², a real-linear function of the white hologram noise whose covariance is
  computed exactly (through the taper, the padding and the kept plane waves); that is the
  limit of infinitely many Monte-Carlo draws (``monte_carlo`` = n > 0 draws them
  instead: a few draws give a σ that is itself uncertain by ~1/√(2n), and one fixed
  seed makes that error the same in every run). The noise term, with the line fit's
  standard errors and the window term in quadrature, is the standard uncertainty.
"""

from __future__ import annotations

import dataclasses
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
import scipy.fft
from numpy.typing import NDArray

from holoprobe.characterize._hologram_config import HologramConfig
from holoprobe.characterize._hologram_field import PlaneWaveField, plane_wave_field
from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid
from holoprobe.signal import workers

__all__ = ["FocusAlignment", "align_focused", "hologram_noise_level", "orthonormal_frame",
           "window_taper"]


@dataclass(frozen=True)
class FocusAlignment:
    """Focal maximum and acoustic axis of a focused source (scan coordinates, SI).

    Attributes
    ----------
    focus : ndarray, shape (3,)
        Position of the focal pressure maximum in m.
    focus_uncertainty : ndarray, shape (3,)
        Standard uncertainty of each coordinate in m.
    focal_pressure : float
        |p| at the focus in Pa.
    axis : ndarray, shape (3,)
        Unit direction of the focal lobe's axis (z component > 0).
    axis_uncertainty : float
        Standard uncertainty of the axis direction in rad (cone half-angle).
    power_direction : ndarray, shape (3,)
        Power-weighted beam direction (unit vector).
    lobe_centres : ndarray, shape (n, 3)
        The lobe centres the axis was fitted through, m.
    axial_extent : (float, float)
        Distances (m) from the maximum to the −6 dB points along the axis, before and after.
    noise_level : float
        Noise standard deviation per hologram sample used for the uncertainties (Pa).
    window_shift : ndarray, shape (3,)
        Focus of the untapered window minus ``focus`` (m): the window term.
    window_tilt : float
        Angle between the untapered window's axis and ``axis`` (rad).
    """

    focus: NDArray[np.float64]
    focus_uncertainty: NDArray[np.float64]
    focal_pressure: float
    axis: NDArray[np.float64]
    axis_uncertainty: float
    power_direction: NDArray[np.float64]
    lobe_centres: NDArray[np.float64]
    axial_extent: tuple[float, float]
    noise_level: float
    window_shift: NDArray[np.float64] = dataclasses.field(default_factory=lambda: np.zeros(3))
    window_tilt: float = 0.0


def orthonormal_frame(axis: NDArray[np.float64]) -> tuple[NDArray, NDArray]:
    """Two unit vectors e1, e2 completing ``axis`` to a right-handed frame.

    e1 is the scan x axis made perpendicular to ``axis`` (so the unrolled maps keep the
    scan's orientation).
    """
    d = axis / np.linalg.norm(axis)
    ref = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = ref - (ref @ d) * d
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(d, e1)


def hologram_noise_level(pressure: NDArray, dx: float, dy: float, wavenumber: float,
                         *, min_fraction: float = 0.05) -> float:
    """Noise standard deviation per sample (Pa) from the evanescent part of the spectrum.

    A hologram taken several wavelengths from the source holds no evanescent energy, so
    white measurement noise is all there is beyond |κ| = 1.1 k. Returns 0 when the scan
    does not sample that region (step ≥ λ/2.2) over at least ``min_fraction`` of k-space.
    """
    nx, ny = pressure.shape
    kx = 2 * np.pi * np.fft.fftfreq(nx, dx)
    ky = 2 * np.pi * np.fft.fftfreq(ny, dy)
    outside = np.hypot(kx[:, None], ky[None, :]) > 1.1 * wavenumber
    if outside.mean() < min_fraction:
        return 0.0
    spec = np.fft.fft2(pressure)
    return float(np.sqrt(np.mean(np.abs(spec[outside]) ** 2) / pressure.size))


def _newton(field: PlaneWaveField, start: NDArray, basis: NDArray, *, step_limit: float,
            iterations: int = 30, tol: float = 1e-10) -> NDArray:
    """Maximise |p|² over start + basis @ t (basis: (3, m) orthonormal columns)."""
    r = start.copy()
    for _ in range(iterations):
        _, g, h = field.intensity_derivatives(r)
        gb, hb = basis.T @ g, basis.T @ h @ basis
        w, _v = np.linalg.eigh(hb)
        if np.all(w < 0):
            step = -np.linalg.solve(hb, gb)
        else:  # not concave here: gradient ascent along the steepest direction
            step = gb / (np.abs(w).max() + 1e-300)
        norm = np.linalg.norm(step)
        if norm > step_limit:
            step *= step_limit / norm
        r = r + basis @ step
        if norm < tol:
            break
    return r


def _coarse_focus(field: PlaneWaveField, origin: NDArray, direction: NDArray,
                  span: tuple[float, float], n: int, wavelength: float) -> NDArray:
    """Maximum of |p| sampled along a line, then re-centred laterally on a small grid."""
    t = np.linspace(span[0], span[1], n)
    amp = np.abs(field.pressure_local(origin, direction[None, :], t[:, None]))
    best = origin + t[np.argmax(amp)] * direction
    e1, e2 = orthonormal_frame(direction)
    u = np.linspace(-2, 2, 17) * wavelength
    uu, vv = np.meshgrid(u, u, indexing="ij")
    local = np.stack([uu.ravel(), vv.ravel()], axis=1)
    amp = np.abs(field.pressure_local(best, np.stack([e1, e2]), local))
    return best + local[np.argmax(amp)] @ np.stack([e1, e2])


def _half_level_distance(field: PlaneWaveField, focus: NDArray, direction: NDArray,
                         peak: float, length: float, sign: float) -> float:
    """Distance from the focus along ±direction to where |p| falls to half the peak."""
    t = np.linspace(0.0, length, 160)
    amp = np.abs(field.pressure_local(focus, sign * direction[None, :], t[:, None]))
    below = np.nonzero(amp < 0.5 * peak)[0]
    if below.size == 0:
        return float(length)
    i = below[0]
    a0, a1 = amp[i - 1], amp[i]
    return float(t[i - 1] + (a0 - 0.5 * peak) / (a0 - a1) * (t[i] - t[i - 1]))


def _fit_axis(field: PlaneWaveField, focus: NDArray, axis: NDArray, offsets: NDArray,
              wavelength: float, starts: NDArray | None = None, iterations: int = 30
              ) -> tuple[NDArray, NDArray, float]:
    """Lobe centres in planes across the lobe and the line through them."""
    e1, e2 = orthonormal_frame(axis)
    basis = np.stack([e1, e2], axis=1)
    if starts is None:
        starts = focus + offsets[:, None] * axis
    centres = np.array([_newton(field, start, basis, step_limit=wavelength / 4,
                                iterations=iterations) for start in starts])
    rel = centres - focus
    s = rel @ axis
    lat = rel @ basis  # (n, 2)
    design = np.stack([np.ones_like(s), s], axis=1)
    coef, *_ = np.linalg.lstsq(design, lat, rcond=None)
    slope = coef[1]
    new_axis = axis + basis @ slope
    new_axis /= np.linalg.norm(new_axis)
    resid = lat - design @ coef
    dof = max(len(s) - 2, 1)
    var = np.sum(resid**2, axis=0) / dof / np.sum((s - s.mean()) ** 2)
    return new_axis, centres, float(np.sqrt(var.sum()))


def _align_once(field: PlaneWaveField, start: NDArray, axis: NDArray, cfg: HologramConfig,
                wavelength: float) -> tuple[NDArray, NDArray, NDArray, float, tuple[float, float]]:
    """Focus by Newton, then the axis through the lobe centres, re-oriented a few times."""
    focus = _newton(field, start, np.eye(3), step_limit=wavelength / 2)
    peak = abs(complex(field.pressure(focus)))
    reach = cfg.lobe_reach_wavelengths * wavelength
    centres = focus[None, :]
    se = 0.0
    extent = (0.0, 0.0)
    for _ in range(max(cfg.axis_iterations, 1)):
        extent = (_half_level_distance(field, focus, axis, peak, reach, -1.0),
                  _half_level_distance(field, focus, axis, peak, reach, +1.0))
        offsets = np.linspace(-cfg.axis_span * extent[0], cfg.axis_span * extent[1],
                              cfg.axis_planes)
        axis, centres, se = _fit_axis(field, focus, axis, offsets, wavelength)
    return focus, axis, centres, se, extent


def _perturbed(field: PlaneWaveField, focus: NDArray, axis: NDArray, centres: NDArray,
               wavelength: float) -> tuple[NDArray, NDArray]:
    """Focus and axis of a perturbed field, linearised: one Newton step from each point.

    Noise moves the maxima by −H⁻¹∇(|p|²) to first order, which one Newton step from the
    unperturbed maxima gives; the planes keep their offsets along the axis.
    """
    f = _newton(field, focus, np.eye(3), step_limit=wavelength / 2, iterations=1)
    offsets = (centres - focus) @ axis
    new_axis, _, _ = _fit_axis(field, focus, axis, offsets, wavelength, starts=centres,
                               iterations=1)
    return f, new_axis



def _monte_carlo(field: PlaneWaveField, focus: NDArray, axis: NDArray, centres: NDArray,
                 window: NDArray, sigma: float, cfg: HologramConfig, wavelength: float,
                 seed: int) -> tuple[NDArray, float]:
    """Focus covariance (3, 3) in m² and mean squared axis deviation (rad²) over
    ``cfg.monte_carlo`` noise realisations (each estimate linearised by :func:`_perturbed`)."""
    rng = np.random.default_rng(seed)
    noises = [field.noise_coefficients(sigma, rng, window=window)
              for _ in range(cfg.monte_carlo)]

    def one(noise: NDArray) -> tuple[NDArray, NDArray]:
        noisy = field.with_coefficients(field.coefficients + noise)
        return _perturbed(noisy, focus, axis, centres, wavelength)

    with ThreadPoolExecutor(max_workers=workers()) as pool:  # NumPy releases the GIL
        foci, axes = zip(*pool.map(one, noises), strict=True)
    cov = np.atleast_2d(np.cov(np.array(foci).T)) if len(foci) > 1 else np.zeros((3, 3))
    dev = np.arccos(np.clip(np.array(axes) @ axis, -1.0, 1.0))
    return cov, float(np.mean(dev**2))


def _gradient_functionals(field: PlaneWaveField, point: NDArray
                          ) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """b (3, m) with δ∇|p|²(point) = 2 Re(b @ δc) for coefficient changes δc; the Hessian of |p|².

    ∇|p|² = 2 Re(p* ∇p), so δ∇|p|² = 2 Re(∇p* δp + p* ∇δp) with δp = Σ δc e^{ik·r} and
    ∇δp = Σ i k δc e^{ik·r}.
    """
    p, g, _ = field.derivatives(point)
    _, _, hess = field.intensity_derivatives(point)
    phase = np.exp(1j * (field.wave_vectors @ point))
    b = (np.conj(g)[:, None] + np.conj(p) * 1j * field.wave_vectors.T) * phase
    return b, hess


def _linear_noise(field: PlaneWaveField, focus: NDArray, axis: NDArray, centres: NDArray,
                  window: NDArray, sigma: float, cfg: HologramConfig, wavelength: float,
                  seed: int) -> tuple[NDArray, float]:
    """The Monte-Carlo estimate's limit for infinitely many draws, by linear propagation.

    The focus moves by δf = −H⁻¹ δ∇|p|² and each lobe centre in its plane by
    −(BᵀH_iB)⁻¹ Bᵀ δ∇|p|²; the axis tilt is the least-squares slope of those lateral
    shifts against the planes' offsets (what :func:`_perturbed` does, to first order).
    Each is a real-linear function 2 Re(q @ n) of the complex white hologram noise n
    (σ² per sample, through the taper ``window``, the padding and the component
    selection of ``field``): q = window · crop(DFT(factors · q_κ)) for the functional q_κ
    on the plane-wave coefficients, and Cov = 2σ² Re(Q Qᴴ). Returns the focus covariance
    (3, 3) in m² and the expected squared axis deviation (rad²), the latter including the
    estimate's residual slope against ``axis`` as :func:`_monte_carlo` does.
    """
    del cfg, wavelength, seed  # the same signature as _monte_carlo
    if field.indices is None or field.factors is None:
        raise InputError("this expansion keeps no record of its spectral grid", field="field")
    b_f, h_f = _gradient_functionals(field, focus)
    rows = [-np.linalg.solve(h_f, b_f)]
    e1, e2 = orthonormal_frame(axis)
    basis = np.stack([e1, e2], axis=1)
    rel = centres - focus
    design = np.stack([np.ones(len(centres)), rel @ axis], axis=1)
    weights = np.linalg.pinv(design)[1]  # slope = Σ_i weights_i × lateral_i
    slope0 = weights @ (rel @ basis)
    q_axis = np.zeros((2, field.coefficients.size), np.complex128)
    for w_i, centre in zip(weights, centres, strict=True):
        b_i, h_i = _gradient_functionals(field, centre)
        q_axis -= w_i * np.linalg.solve(basis.T @ h_i @ basis, basis.T @ b_i)
    rows.append(q_axis)
    q = np.concatenate(rows) * field.factors
    npx, npy = field.padded_shape
    full = np.zeros((q.shape[0], npx * npy), np.complex128)
    full[:, field.indices] = q
    nx, ny = field.grid_shape
    spec = scipy.fft.fft2(full.reshape(-1, npx, npy), axes=(1, 2), workers=workers())
    u = (spec[:, :nx, :ny] * window).reshape(q.shape[0], -1)
    cov = 2 * sigma**2 * np.real(u @ u.conj().T)
    return cov[:3, :3], float(slope0 @ slope0 + np.trace(cov[3:, 3:]))


def _expand(pressure: NDArray, grid: PlaneGrid, frequency: float, medium: Medium,
            reach: NDArray, cfg: HologramConfig, guard_energy: float) -> PlaneWaveField:
    return plane_wave_field(pressure, grid, frequency, medium, reach=reach,
                            prune_tolerance=cfg.prune_tolerance,
                            guard_energy=guard_energy,
                            guard_margin_deg=cfg.guard_margin_deg)


def align_focused(pressure: NDArray, grid: PlaneGrid, frequency: float,
                  medium: Medium | None = None, *, search_span: tuple[float, float],
                  cfg: HologramConfig | None = None, noise_level: float = 0.0,
                  seed: int = 0) -> FocusAlignment:
    """Focal maximum and acoustic axis of a focused source, with uncertainties.

    Parameters
    ----------
    pressure : ndarray, complex, shape (nx, ny)
        CW hologram in Pa on ``grid`` (exp(−iωt) convention).
    grid : PlaneGrid
        Scan grid, identity pose (scan coordinates: z away from the source).
    frequency : float
        Hz.
    medium : Medium, optional
        Default water at 20 °C.
    search_span : (float, float)
        Range (m) of the coarse search for the maximum, as distances along the
        power-weighted beam direction from the hologram's intensity centroid (negative:
        towards the source).
    cfg : HologramConfig, optional
        Settings.
    noise_level : float
        Noise standard deviation per hologram sample (Pa) for the noise term of the
        uncertainties (0: the line fit's standard error only).
    seed : int
        Seed of the noise realisations.

    Returns
    -------
    FocusAlignment
    """
    cfg = cfg or HologramConfig()
    medium = Medium() if medium is None else medium
    if not search_span[1] > search_span[0]:
        raise InputError(f"expected an increasing range in m, got {search_span}",
                         field="search_span")
    intensity = np.abs(pressure) ** 2
    points = grid.points()
    origin = intensity.ravel() @ points / intensity.sum()
    wavelength = float(medium.wavelength(frequency))
    # coarse expansion: padded for the whole search line
    probe = _expand(pressure, grid, frequency, medium, np.array(
        [origin + search_span[0] * np.array([0, 0, 1.0]),
         origin + search_span[1] * np.array([0, 0, 1.0])]), cfg, cfg.coarse_guard_energy)
    d_power = probe.power_direction()
    start = _coarse_focus(probe, origin, d_power, search_span, cfg.focus_search_points,
                          wavelength)
    # fine expansion: padded for the focal lobe only (fewer plane waves, same accuracy)
    lobe = start + np.array([-1, 1])[:, None] * cfg.lobe_reach_wavelengths * wavelength * d_power
    window = window_taper(grid.shape, cfg.window_taper)
    field = _expand(pressure * window, grid, frequency, medium, lobe, cfg,
                    cfg.focal_guard_energy)
    focus, axis, centres, se, extent = _align_once(field, start, d_power, cfg, wavelength)
    shift, tilt = np.zeros(3), 0.0
    if cfg.window_taper > 0:  # the window term: the same estimate on the untapered window
        plain = _expand(pressure, grid, frequency, medium, lobe, cfg, cfg.focal_guard_energy)
        f_plain, a_plain, *_ = _align_once(plain, focus, axis, cfg, wavelength)
        shift = f_plain - focus
        tilt = float(np.arccos(np.clip(a_plain @ axis, -1.0, 1.0)))
    focus_u, axis_u = np.zeros(3), se
    if noise_level > 0:
        propagate = _monte_carlo if cfg.monte_carlo > 0 else _linear_noise
        focus_cov, axis_var = propagate(field, focus, axis, centres, window, noise_level,
                                        cfg, wavelength, seed)
        focus_u = np.sqrt(np.clip(np.diag(focus_cov), 0.0, None))
        axis_u = float(np.sqrt(axis_var + se**2))
    focus_u = np.hypot(focus_u, shift)
    axis_u = float(np.hypot(axis_u, tilt))
    peak = abs(complex(field.pressure(focus)))
    return FocusAlignment(focus, focus_u, peak, axis, axis_u, d_power, centres, extent,
                          float(noise_level), shift, tilt)


def window_taper(shape: tuple[int, int], fraction: float) -> NDArray[np.float64]:
    """Separable Tukey taper (nx, ny) that falls to zero over ``fraction`` of each axis.

    ``fraction`` is the Tukey α (0: no taper, all ones); half of it lies at each edge.
    """
    if not 0 <= fraction <= 1:
        raise InputError(f"expected a fraction in [0, 1], got {fraction!r}",
                         field="window_taper")
    from scipy.signal.windows import tukey  # lazy: scipy.signal costs ~1 s of start-up

    return np.outer(tukey(shape[0], fraction), tukey(shape[1], fraction))
