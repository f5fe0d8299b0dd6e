"""Alignment of a focused source from its hologram: focal maximum and acoustic axis.

The forward-projected field is the plane-wave sum of :class:`PlaneWaveField`, evaluated at
continuous points, so nothing is limited by an evaluation grid:

* **focal maximum** — coarse search of |p| along the power-weighted beam direction, a
  lateral re-centring, then Newton's method on |p|² with the analytic gradient and Hessian
  (the local maximum); finally the maximum along the lobe's axis of the axial |p|²
  profile smoothed by a sixth-order Gaussian kernel (width ``focus_smoothing`` × the
  lobe's shorter −6 dB half-length). A lobe 10–25 mm long is so flat that ripples of
  1e-4 of its peak with axial periods of 1–2 λ (the scan window's edges and a λ/2
  sampling: a few wide-angle waves interfering with the beam) moved its local maximum by
  20–60 µm; the kernel damps them and keeps exact bowl lobes' maxima within 1 µm;
* **acoustic axis** — the axis of the focal lobe as holography users define it: in planes
  across the lobe (perpendicular to the current axis, spanning ``axis_span`` of its −6 dB
  axial extent on each side of the maximum) the lobe's centre (the in-plane maximum, again
  by Newton) is found; the axis is the least-squares line through those centres, and the
  planes are re-oriented to it a few times;
* **power-weighted beam direction** — Σ W_κ k̂_κ over the plane waves, reported separately
  (a weak segment tilts it, not the lobe axis);
* **the scan window** — the hologram is brought smoothly to zero over the outer
  ``window_taper`` of its width (Tukey; scaled by the outward-going share of the power
  in that band, see :func:`edge_taper_fraction`) before the focus and axis are found. A hard
  truncation of a field still a few per cent of its peak at the window's edge leaks
  spectrum beyond |κ| = k, which a λ/2 scan folds back into wide-angle plane waves; their
  weak field near the focus tilts the very flat axial lobe (a lobe 10–20 mm long moves by
  tens of µm for a slope of 0.1 % of its peak per mm). The taper removes most of that
  leakage and changes only the weak, outward-going edge of the field; the change of the
  estimate between the tapered and the untapered window is kept as the window term of
  the uncertainty (on twins the tapered error stayed within it), less the part of that
  difference that is the two estimates' different noise (propagated linearly; it is in
  the noise term already). That term is the *untapered* window's bias and overstated the
  tapered one's 3–30× on twins; with a placed source, :func:`correct_window_bias` models
  the tapered estimate's bias instead (a uniform cap of the source's geometry radiated
  onto the same window), removes it and keeps it as the window term;
* **uncertainties** — the hologram's noise (estimated from its evanescent spectrum, or
  given) is propagated linearly: the focus and every lobe centre move by one Newton step
  −H⁻¹δ∇|p|² (the smoothed profile's maximum by one along the axis), a real-linear
  function of the white hologram noise whose covariance is
  computed exactly (through the taper, the padding and the kept plane waves); that is the
  limit of infinitely many Monte-Carlo draws (``monte_carlo`` = n > 0 draws them
  instead: a few draws give a σ that is itself uncertain by ~1/√(2n), and one fixed
  seed makes that error the same in every run). The noise term, with the line fit's
  standard errors and the window term in quadrature, is the standard uncertainty.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.fft
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from holoprobe.characterize._hologram_config import HologramConfig, check_band_monte_carlo
from holoprobe.characterize._hologram_field import (
    BandField,
    PlaneWaveField,
    grid_adjoint,
    grid_sums,
    plane_wave_field,
)
from holoprobe.characterize._window_model import cap_axial_maximum, cap_hologram
from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, SourceGeometry
from holoprobe.signal import Threads, workers

__all__ = ["FocusAlignment", "align_band", "align_focused", "band_noise_levels",
           "correct_window_bias", "edge_taper_fraction", "hologram_noise_level",
           "orthonormal_frame", "window_model", "window_taper"]


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
        The lobe centres the axis was fitted through, m (after
        :func:`correct_window_bias`, moved with the corrected focus and axis).
    axial_extent : (float, float)
        Distances (m) from the maximum to the −6 dB points along the axis, before and after.
    noise_level : float
        Noise standard deviation per hologram sample used for the uncertainties (Pa).
    window_shift : ndarray, shape (3,)
        Focus of the untapered window minus ``focus`` (m): the window term; after
        :func:`correct_window_bias`, the modelled window bias that was removed.
    window_tilt : float
        Angle between the untapered window's axis and ``axis`` (rad); after
        :func:`correct_window_bias`, the modelled axis bias that was removed.
    window_shift_noise : ndarray, shape (3,)
        Standard deviation (m) of the hologram noise's part of ``window_shift`` (linear
        propagation): the window term in ``focus_uncertainty`` is
        √max(window_shift² − window_shift_noise², 0), so that the noise is not counted
        twice.
    window_tilt_noise : float
        The same for ``window_tilt`` (rad).
    definition : {"cw", "band"}
        What the focus and axis are of: the CW field at one frequency, or a pulse's
        pulse-pressure-squared integral (:func:`align_band`).
    estimator : {"lobe", "aperture"}
        Where ``focus`` came from: the hologram's plane waves (this module), or the field
        the reconstructed aperture radiates (:func:`aperture_focus`).
    axis_estimator : {"lobe", "aperture"}
        The same for ``axis`` (:func:`aperture_axis`).
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
    window_shift_noise: NDArray[np.float64] = dataclasses.field(
        default_factory=lambda: np.zeros(3))
    window_tilt_noise: float = 0.0
    definition: str = "cw"
    estimator: str = "lobe"
    axis_estimator: str = "lobe"


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


Field = PlaneWaveField | BandField  # |p|² of one CW expansion, or a band's energy
_LINE_EPS = 1e-12  # NUFFT tolerance of _line_sums (relative to the summed magnitudes)


def _newton(field: Field, start: NDArray, basis: NDArray, *, step_limit: float,
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


def _half_level_distance(field: Field, focus: NDArray, direction: NDArray,
                         peak: float, length: float, sign: float) -> float:
    """Distance from the focus along ±direction to where |p| (√E) falls to half the peak."""
    t = np.linspace(0.0, length, 160)
    if isinstance(field, BandField):   # every bin on the line: exact sums, no NUFFT set-up
        energy = sum(w * np.abs(_line_sums(f, focus, sign * direction, t,
                                           f.coefficients[:, None])[0][:, 0]) ** 2
                     for f, w, _ in field.parts)
        amp = np.sqrt(np.asarray(energy, dtype=float))
    else:
        amp = field.amplitude_local(focus, sign * direction[None, :], t[:, None])
    below = np.nonzero(amp < 0.5 * peak)[0]
    if below.size == 0:
        return float(length)
    i = below[0]
    a0, a1 = amp[i - 1], amp[i]
    return float(t[i - 1] + (a0 - 0.5 * peak) / (a0 - a1) * (t[i] - t[i - 1]))


def _fit_axis(field: Field, focus: NDArray, axis: NDArray, offsets: NDArray,
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


@dataclass(frozen=True)
class _Estimate:
    """One alignment of one expansion: the lobe's axis and the axial profile's maximum.

    ``newton`` is the local maximum of |p|² (where ∇|p|² = 0); ``focus`` = newton +
    ``offset`` × axis, the maximum of the smoothed axial profile (:func:`_profile_focus`);
    ``nodes``/``weights`` are that smoothing's quadrature (offsets from ``newton`` along
    the axis, m, and kernel weights).
    """

    field: Field
    newton: NDArray[np.float64]
    axis: NDArray[np.float64]
    centres: NDArray[np.float64]
    se: float
    extent: tuple[float, float]
    offset: float
    nodes: NDArray[np.float64]
    weights: NDArray[np.float64]
    values: NDArray[np.complex128] | None = None  # p, ∇p, (∇∇p)a per bin at the nodes (nb, n, 7)

    @property
    def focus(self) -> NDArray[np.float64]:
        return self.newton + self.offset * self.axis


def _align_once(field: Field, start: NDArray, axis: NDArray, cfg: HologramConfig,
                wavelength: float) -> _Estimate:
    """Focus by Newton, the axis through the lobe centres (re-oriented a few times), then
    the maximum of the smoothed axial profile."""
    focus = _newton(field, start, np.eye(3), step_limit=wavelength / 2)
    peak = float(field.amplitude(focus))
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
    width = cfg.focus_smoothing * min(extent)
    if width <= 0:
        return _Estimate(field, focus, axis, centres, se, extent, 0.0, np.zeros(1),
                         np.ones(1))
    offset, nodes, weights, values = _profile_focus(field, focus, axis, width, wavelength)
    return _Estimate(field, focus, axis, centres, se, extent, offset, nodes, weights, values)


def _profile_kernel(t: NDArray, width: float) -> NDArray[np.float64]:
    """Smoothing kernel of the axial profile (1/m): a Gaussian of standard deviation
    ``width`` (m) made sixth-order, G(t)(15/8 − 5/4 u² + u⁴/8) with u = t/width.

    Its zeroth moment is 1 and its second and fourth vanish, so a smooth profile passes
    unchanged up to terms in width⁶ f⁽⁶⁾, while ripples of period P are damped by
    e^{−ω²w²/2}(1 + ω²w²/2 + ω⁴w⁴/8), ω = 2π/P.
    """
    u = np.asarray(t, dtype=float) / width
    return (np.exp(-0.5 * u * u) / (np.sqrt(2 * np.pi) * width)
            * (15 / 8 - 1.25 * u * u + u**4 / 8))


def _line_sums(field: PlaneWaveField, origin: NDArray, axis: NDArray, offsets: NDArray,
               columns: NDArray, left: NDArray | None = None
               ) -> tuple[NDArray, NDArray | None]:
    """E @ columns and, with ``left`` (n, r), leftᵀ @ E, for E_jκ = exp(i k_κ·x_j) at the
    equally spaced points x_j = origin + offsets_j · axis.

    A type-1 NUFFT for E @ columns and a type-2 for leftᵀ @ E along the line
    (:func:`grid_sums`, tolerance ``_LINE_EPS``); E is never formed.
    """
    kv = field.wave_vectors
    offsets = np.asarray(offsets, dtype=float)
    shift = np.exp(1j * (kv @ np.asarray(origin, float)))
    if offsets.size < 2:
        block = shift[None, :] * np.exp(1j * np.outer(offsets, kv @ axis))
        return block @ columns, None if left is None else left.T @ block
    ticks = [(float(offsets[0]), float(offsets[1] - offsets[0]), int(offsets.size))]
    kproj = (kv @ axis)[:, None]
    out = grid_sums(kproj, columns * shift[:, None], ticks, _LINE_EPS)
    back = None if left is None else grid_adjoint(kproj, left, ticks, _LINE_EPS) * shift[None, :]
    return out, back


def _profile_columns(field: PlaneWaveField, axis: NDArray) -> NDArray[np.complex128]:
    """Coefficients (m, 7) whose plane-wave sums are p, ∇p and (∇∇p)·axis."""
    kv, c = field.wave_vectors, field.coefficients
    return np.concatenate([c[:, None], 1j * kv * c[:, None],
                           -kv * ((kv @ axis) * c)[:, None]], axis=1)


def _profile_focus(field: Field, origin: NDArray, axis: NDArray, width: float,
                   wavelength: float, iterations: int = 20
                   ) -> tuple[float, NDArray, NDArray, NDArray]:
    """Offset (m) along ``axis`` from ``origin`` of the maximum of the smoothed |p|².

    The maximum of a flat focal lobe (10–25 mm long) moves by tens of µm under ripples of
    1e-4 of the peak, which the scan window's edges and a λ/2 sampling put on the
    plane-wave field with axial periods of 1–2 λ (interference of a few wide-angle waves
    with the beam). The profile smoothed by :func:`_profile_kernel` (``width``:
    ``focus_smoothing`` × the lobe's shorter −6 dB half-length) keeps the lobe's own shape
    (on O'Neil's exact axial field of bowls from F/0.5 to F/3 its maximum moves by < 1 µm)
    and damps those ripples. The derivatives of |p|² are sampled once on a grid of step
    width/2 (the kernel's transfer at the quadrature's alias frequency < 1e-6) reaching
    λ/2 beyond the kernel; Newton's method on the smoothed profile from the local maximum.
    Returns the offset and, for the noise functionals, the nodes (offsets from it), the
    kernel weights and the values p, ∇p, (∇∇p)·axis there (per bin, (nb, n, 7)); a
    band's profile is that of its energy E = Σ w_j |p_j|².
    """
    step, reach = width / 2, wavelength / 2
    grid = np.arange(-6 * width - reach, 6 * width + reach + step / 2, step)
    values = np.stack([_line_sums(f, origin, axis, grid, _profile_columns(f, axis))[0]
                       for f, _, _ in field.parts])
    w_bins = np.array([w for _, w, _ in field.parts])
    p, dp, ddp = values[:, :, 0], values[:, :, 1:4] @ axis, values[:, :, 4:7] @ axis
    d1 = w_bins @ (2 * np.real(np.conj(p) * dp))
    d2 = w_bins @ (2 * (np.abs(dp) ** 2 + np.real(np.conj(p) * ddp)))
    s = 0.0
    for _ in range(iterations):
        w = _profile_kernel(grid - s, width) * step
        g1, g2 = float(w @ d1), float(w @ d2)
        move = -g1 / g2 if g2 < 0 else np.sign(g1) * wavelength / 8
        move = float(np.clip(move, -wavelength / 4, wavelength / 4))
        s = float(np.clip(s + move, -reach, reach))
        if abs(move) < 1e-8:
            break
    keep = np.abs(grid - s) <= 6 * width + step / 2
    return s, grid[keep] - s, _profile_kernel(grid[keep] - s, width) * step, values[:, keep]


def _perturbed(field: PlaneWaveField, est: _Estimate, wavelength: float,
               phases: NDArray | None = None) -> tuple[NDArray, NDArray]:
    """Focus and axis of a perturbed field, linearised: one Newton step from each point.

    Noise moves the maxima by −H⁻¹∇(|p|²) to first order, which one Newton step from the
    unperturbed maxima gives; the planes keep their offsets along the axis, and the
    smoothed profile's maximum takes one Newton step along the axis through the moved
    local maximum. ``phases`` (n, m): exp(i k·x_j) at the unperturbed profile nodes.
    One CW expansion only (a band's uncertainties are propagated linearly).
    """
    assert isinstance(field, PlaneWaveField)
    f = _newton(field, est.newton, np.eye(3), step_limit=wavelength / 2, iterations=1)
    offsets = (est.centres - est.newton) @ est.axis
    new_axis, _, _ = _fit_axis(field, est.newton, est.axis, offsets, wavelength,
                               starts=est.centres, iterations=1)
    lateral = (f - est.newton) - ((f - est.newton) @ est.axis) * est.axis
    if phases is None:
        return f, new_axis
    ka = field.wave_vectors @ est.axis
    c = field.coefficients * np.exp(1j * (field.wave_vectors @ lateral))
    p, dp, ddp = (phases @ np.stack([c, 1j * ka * c, -ka * ka * c], axis=1)).T
    d1 = 2 * np.real(np.conj(p) * dp)
    d2 = 2 * (np.abs(dp) ** 2 + np.real(np.conj(p) * ddp))
    step = -float(est.weights @ d1) / float(est.weights @ d2)
    return est.focus + lateral + step * est.axis, new_axis


def _monte_carlo(est: _Estimate, window: NDArray, sigma: float, cfg: HologramConfig,
                 wavelength: float, seed: int) -> tuple[NDArray, float]:
    """Focus covariance (3, 3) in m² and mean squared axis deviation (rad²) over
    ``cfg.monte_carlo`` noise realisations (each estimate linearised by :func:`_perturbed`)."""
    field = est.field
    assert isinstance(field, PlaneWaveField)  # align_focused's one CW expansion
    rng = np.random.default_rng(seed)
    noises = [field.noise_coefficients(sigma, rng, window=window)
              for _ in range(cfg.monte_carlo)]
    phases = None
    if est.nodes.size > 1:
        nodes = est.newton + (est.offset + est.nodes)[:, None] * est.axis
        phases = np.exp(1j * (nodes @ field.wave_vectors.T))

    def one(noise: NDArray) -> tuple[NDArray, NDArray]:
        return _perturbed(field.with_coefficients(field.coefficients + noise), est,
                          wavelength, phases)

    with Threads(workers()) as threads:  # NumPy releases the GIL
        foci, axes = zip(*threads.map(one, noises), strict=True)
    cov = np.atleast_2d(np.cov(np.array(foci).T)) if len(foci) > 1 else np.zeros((3, 3))
    dev = np.arccos(np.clip(np.array(axes) @ est.axis, -1.0, 1.0))
    return cov, float(np.mean(dev**2))


def _gradient_functionals(field: Field, point: NDArray
                          ) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """b (3, m) with δ∇|p|²(point) = 2 Re(b @ δc) for coefficient changes δc; the Hessian of |p|².

    ∇|p|² = 2 Re(p* ∇p), so δ∇|p|² = 2 Re(∇p* δp + p* ∇δp) with δp = Σ δc e^{ik·r} and
    ∇δp = Σ i k δc e^{ik·r}. A band: E's, each bin's b_j times w_j, concatenated (m = Σ m_j).
    """
    blocks = []
    for f, w, _ in field.parts:
        p, g, _ = f.derivatives(point)
        phase = np.exp(1j * (f.wave_vectors @ point))
        blocks.append(w * (np.conj(g)[:, None] + np.conj(p) * 1j * f.wave_vectors.T) * phase)
    _, _, hess = field.intensity_derivatives(point)
    return np.concatenate(blocks, axis=1), hess


def _profile_functional(est: _Estimate, q_newton: NDArray) -> NDArray[np.complex128]:
    """Coefficient functional (m,) of the smoothed profile's maximum along the axis.

    The offset s from the local maximum f_N solves g'(s) = Σ_j w_j a·∇|p|²(x_j) = 0 at
    x_j = f_N + (s + t_j) a; under a change of the field and of f_N (rows ``q_newton``),
    δs = −(Σ_j w_j a·δ∇|p|²(x_j) + Σ_j w_j (H_j a)·δf_N) / Σ_j w_j aᵀH_j a, with
    a·δ∇|p|² = 2 Re((∂_a p* + p* i k·a) e^{ik·x} δc) (:func:`_gradient_functionals`).
    """
    a, w = est.axis, est.weights
    assert est.values is not None
    q_grad, h_a = [], np.zeros((w.size, 3))
    for (f, w_bin, _), values in zip(est.field.parts, est.values, strict=True):
        p, grad, hess_a = values[:, 0], values[:, 1:4], values[:, 4:7]
        dp = grad @ a
        left = np.stack([w * np.conj(dp), w * np.conj(p)], axis=1)
        _, back = _line_sums(f, est.newton, a, est.offset + est.nodes,
                             f.coefficients[:, None], left)
        assert back is not None
        q_grad.append(w_bin * (back[0] + 1j * (f.wave_vectors @ a) * back[1]))
        h_a += w_bin * 2 * np.real(np.conj(grad) * dp[:, None]
                                   + np.conj(p)[:, None] * hess_a)  # (n, 3)
    cross, curv = w @ h_a, float(w @ (h_a @ a))
    return -(np.concatenate(q_grad) + cross @ q_newton) / curv


def _noise_functionals(est: _Estimate, window: NDArray, axis: NDArray | None = None
                       ) -> tuple[NDArray, NDArray]:
    """The focus and axis moves as real-linear functionals of the hologram samples.

    The local maximum moves by δf = −H⁻¹ δ∇|p|², the smoothed profile's maximum along
    the axis with it (:func:`_profile_functional`), and each lobe centre in its plane by
    −(BᵀH_iB)⁻¹ Bᵀ δ∇|p|²; the axis tilt is the least-squares slope of those lateral
    shifts against the planes' offsets (what :func:`_perturbed` does, to first order).
    Each is 2 Re(u @ n) for a complex change n of the hologram samples (through the taper
    ``window``, the padding and the component selection of the field):
    u = window · crop(DFT(factors · q_κ)) for the functional q_κ on the plane-wave
    coefficients. Returns u, shape (5, nx·ny) (focus x, y, z; slope along e1, e2 of
    :func:`orthonormal_frame` (``axis``, default the estimate's)), and the fit's residual
    slope (2,) against that axis.
    """
    field = est.field
    axis = est.axis if axis is None else axis
    b_f, h_f = _gradient_functionals(field, est.newton)
    q_focus = -np.linalg.inv(h_f) @ b_f
    if est.nodes.size > 1:
        q_focus = q_focus + est.axis[:, None] * _profile_functional(est, q_focus)[None, :]
    e1, e2 = orthonormal_frame(axis)
    basis = np.stack([e1, e2], axis=1)
    rel = est.centres - est.newton
    design = np.stack([np.ones(len(est.centres)), rel @ axis], axis=1)
    weights = np.linalg.pinv(design)[1]  # slope = Σ_i weights_i × lateral_i
    slope0 = weights @ (rel @ basis)
    q_axis = np.zeros((2, field.coefficients.size), np.complex128)
    for w_i, centre in zip(weights, est.centres, strict=True):
        b_i, h_i = _gradient_functionals(field, centre)
        q_axis -= w_i * (np.linalg.inv(basis.T @ h_i @ basis) @ (basis.T @ b_i))
    return _sample_functionals(field, np.concatenate([q_focus, q_axis]), window), slope0


def _sample_functionals(field: Field, q: NDArray[np.complex128], window: NDArray
                        ) -> NDArray[np.complex128]:
    """Functionals (r, m) on the plane-wave coefficients as functionals of the hologram
    samples: u = window · crop(DFT(factors · q)). A band's bins carry independent noise:
    their u_j, each times the bin's noise scale, are concatenated (r, nb·nx·ny), so that
    2σ² Re(u uᴴ) is the covariance for the reference noise level σ."""
    out, start = [], 0
    for f, _, scale in field.parts:
        if f.indices is None or f.factors is None:
            raise InputError("this expansion keeps no record of its spectral grid",
                             field="field")
        m = f.coefficients.size
        npx, npy = f.padded_shape
        full = np.zeros((q.shape[0], npx * npy), np.complex128)
        full[:, f.indices] = q[:, start:start + m] * f.factors
        start += m
        nx, ny = f.grid_shape
        spec = scipy.fft.fft2(full.reshape(-1, npx, npy), axes=(1, 2), workers=workers())
        out.append(scale * (spec[:, :nx, :ny] * window).reshape(q.shape[0], -1))
    return np.concatenate(out, axis=1)


def _linear_noise(est: _Estimate, window: NDArray, sigma: float, cfg: HologramConfig,
                  wavelength: float, seed: int,
                  functionals: tuple[NDArray, NDArray] | None = None
                  ) -> tuple[NDArray, float]:
    """The Monte-Carlo estimate's limit for infinitely many draws, by linear propagation.

    With u from :func:`_noise_functionals`, Cov = 2σ² Re(U Uᴴ) for complex white noise of
    σ² per sample. Returns the focus covariance (3, 3) in m² and the expected squared axis
    deviation (rad²), the latter including the estimate's residual slope against its
    axis as :func:`_monte_carlo` does.
    """
    del cfg, wavelength, seed  # the same signature as _monte_carlo
    u, slope0 = functionals or _noise_functionals(est, window)
    cov = 2 * sigma**2 * np.real(u @ u.conj().T)
    return cov[:3, :3], float(slope0 @ slope0 + np.trace(cov[3:, 3:]))


def _window_term(tapered: _Estimate, plain: _Estimate, u_tapered: NDArray, sigma: float
                 ) -> tuple[NDArray, float, NDArray, float]:
    """The window term of the focus (3,) and axis (rad) with the noise of the difference removed.

    The untapered minus the tapered estimate is the window term; on a noisy hologram it
    also holds the difference of the two estimates' noise, which is already in the noise
    term (counted twice, it made σ z 1.3–1.6× the spread of the errors at 30–35 dB). Its
    variance v is propagated linearly (both estimates' functionals of the same samples,
    :func:`_noise_functionals`), and the term is √max(d² − v, 0) per coordinate (an
    unbiased estimate of the squared window bias d²). Returns the focus term, the axis
    term and the noise standard deviations of the raw differences. ``u_tapered``: the
    tapered estimate's functionals (:func:`_noise_functionals`).
    """
    shift = plain.focus - tapered.focus
    tilt = float(np.arccos(np.clip(plain.axis @ tapered.axis, -1.0, 1.0)))
    if sigma <= 0:
        return np.abs(shift), tilt, np.zeros(3), 0.0
    u_p, _ = _noise_functionals(plain, np.ones(plain.field.grid_shape), axis=tapered.axis)
    var = 2 * sigma**2 * np.sum(np.abs(u_p - u_tapered) ** 2, axis=1)
    shift_noise, tilt_noise = np.sqrt(var[:3]), float(np.sqrt(var[3:].sum()))
    return (np.sqrt(np.clip(shift**2 - var[:3], 0.0, None)),
            float(np.sqrt(max(tilt**2 - tilt_noise**2, 0.0))), shift_noise, tilt_noise)


def _expand(pressure: NDArray, grid: PlaneGrid, frequency: float, medium: Medium,
            reach: NDArray, cfg: HologramConfig, guard_energy: float) -> PlaneWaveField:
    return plane_wave_field(pressure, grid, frequency, medium, reach=reach,
                            prune_tolerance=cfg.prune_tolerance,
                            guard_energy=guard_energy,
                            guard_margin_deg=cfg.guard_margin_deg)


def align_focused(pressure: NDArray, grid: PlaneGrid, frequency: float,
                  medium: Medium | None = None, *, search_span: tuple[float, float],
                  cfg: HologramConfig | None = None, noise_level: float = 0.0,
                  seed: int = 0, window_term: bool = True) -> FocusAlignment:
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
    window_term : bool
        Add the window term |untapered − tapered estimate| to the uncertainties (False:
        leave the window to :func:`correct_window_bias`, which models it on the placed
        source).

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
    fraction = (edge_taper_fraction(pressure, grid, cfg.window_taper)
                if cfg.window_taper_follows_edge else cfg.window_taper)
    window = window_taper(grid.shape, fraction)
    field = _expand(pressure * window, grid, frequency, medium, lobe, cfg,
                    cfg.focal_guard_energy)
    est = _align_once(field, start, d_power, cfg, wavelength)
    functionals = _noise_functionals(est, window) if noise_level > 0 else None
    shift, tilt, term, term_tilt, shift_noise, tilt_noise = _untapered_window_term(
        est, pressure, grid, frequency, medium, lobe, cfg, wavelength,
        fraction if window_term else 0.0, functionals, noise_level)
    focus_u, axis_u = np.zeros(3), est.se
    if noise_level > 0:
        if cfg.monte_carlo > 0:
            focus_cov, axis_var = _monte_carlo(est, window, noise_level, cfg, wavelength,
                                               seed)
        else:
            focus_cov, axis_var = _linear_noise(est, window, noise_level, cfg, wavelength,
                                                seed, functionals)
        focus_u = np.sqrt(np.clip(np.diag(focus_cov), 0.0, None))
        axis_u = float(np.sqrt(axis_var + est.se**2))
    focus_u = np.hypot(focus_u, term)
    axis_u = float(np.hypot(axis_u, term_tilt))
    peak = abs(complex(field.pressure(est.focus)))
    return FocusAlignment(est.focus, focus_u, peak, est.axis, axis_u, d_power, est.centres,
                          est.extent, float(noise_level), shift, tilt, shift_noise,
                          tilt_noise)


def band_noise_levels(spectra: NDArray, grid: PlaneGrid, frequencies: NDArray,
                      medium: Medium, fallback: float) -> NDArray[np.float64]:
    """Noise per sample (nb,) of each bin of a transient hologram's band (Pa·s).

    Each bin's own evanescent estimate (:func:`hologram_noise_level`) where its scan
    step samples the evanescent region, interpolated in frequency (constant beyond the
    ends) for the bins where it does not (a λ/2 scan of the centre frequency sees no
    evanescent spectrum above ~1.3 times it); ``fallback`` (white noise) when no bin can.
    """
    freqs = np.asarray(frequencies, dtype=float)
    own = np.array([hologram_noise_level(spectra[:, :, j], grid.dx, grid.dy,
                                         float(medium.wavenumber(f)))
                    for j, f in enumerate(freqs)])
    known = own > 0
    if not np.any(known):
        return np.full(freqs.size, float(fallback))
    return np.interp(freqs, freqs[known], own[known])


def align_band(spectra: NDArray, grid: PlaneGrid, frequencies: NDArray, medium: Medium,
               start: FocusAlignment, *, pressure: NDArray, frequency: float,
               cfg: HologramConfig | None = None, noise_levels: NDArray | None = None
               ) -> FocusAlignment:
    """Focal maximum and lobe axis of a transient hologram from its whole band.

    The focus of a pulsed field is the maximum of its pulse-pressure-squared integral
    ∫ p(r, t)² dt = 2 Σ_j |P_j(r)|² Δf (Parseval over the record's bins), the axis the
    line through that integral's in-plane maxima across the lobe: the estimator of
    :func:`align_focused` on the band energy E = Σ_j |p_j|² (:class:`BandField`, every
    bin's plane waves through the same tapered window) instead of one bin's |p|². A
    focused bowl's maximum moves with frequency; E's is one defined point, and its noise
    is the pulse's, not one bin's: a bin carries the noise of the whole record against
    the pulse's share of the energy (on a 5-cycle 61² twin the focus z scatter fell
    2.5-fold). The uncertainty is propagated linearly, the bins' noise independent
    (``cfg.monte_carlo`` > 0 is refused: the draws are for the peak bin's focus).

    Parameters
    ----------
    spectra : ndarray, complex, shape (nx, ny, nb)
        The band's bins (Pa·s) on ``grid``.
    grid : PlaneGrid
    frequencies : ndarray, shape (nb,)
        Hz.
    medium : Medium
    start : FocusAlignment
        :func:`align_focused` on the peak bin ``pressure`` (where the search starts).
    pressure : ndarray, complex, shape (nx, ny)
        The peak bin: the window's taper follows its edge (:func:`edge_taper_fraction`).
    frequency : float
        Its frequency (Hz).
    cfg : HologramConfig, optional
    noise_levels : ndarray, shape (nb,), optional
        Noise per sample of each bin (Pa·s, :func:`band_noise_levels`); None: no noise term.

    Returns
    -------
    FocusAlignment
        ``focal_pressure`` is √E at the focus (Pa·s); ``power_direction`` and the window
        fields are ``start``'s (its window term, when it has one, is added to the
        uncertainties: the band is seen through the same window); ``noise_level`` the
        peak bin's. The pipeline then removes the peak bin's modelled window bias
        (:func:`correct_window_bias`, a CW cap at ``frequency``) from the band focus too:
        on a 31² 5-cycle twin the band focus is off by −14.5 µm without it and −2.3 µm
        with it (σ z 16 µm, the removed bias in it).
    """
    cfg = cfg or HologramConfig()
    check_band_monte_carlo(dataclasses.replace(cfg, transient_focus="band"))
    freqs = np.asarray(frequencies, dtype=float)
    wavelength = float(medium.wavelength(frequency))
    fraction = (edge_taper_fraction(pressure, grid, cfg.window_taper)
                if cfg.window_taper_follows_edge else cfg.window_taper)
    window = window_taper(grid.shape, fraction)
    reach = cfg.lobe_reach_wavelengths * float(medium.wavelength(freqs.min())) * start.axis
    lobe = np.array([start.focus - reach, start.focus + reach])
    levels = np.zeros(freqs.size) if noise_levels is None else np.asarray(noise_levels, float)
    ref = float(levels[int(np.argmin(np.abs(freqs - frequency)))])
    fields = tuple(_expand(spectra[:, :, j] * window, grid, f, medium, lobe, cfg,
                           cfg.focal_guard_energy) for j, f in enumerate(freqs))
    band = BandField(fields, np.ones(freqs.size),
                     levels / ref if ref > 0 else np.ones(freqs.size))
    est = _align_once(band, start.focus, start.axis, cfg, wavelength)
    focus_u, axis_u = np.zeros(3), est.se
    if ref > 0:
        cov, axis_var = _linear_noise(est, window, ref, cfg, wavelength, 0)
        focus_u = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        axis_u = float(np.sqrt(axis_var + est.se**2))
    # the peak bin's window term (align_focused with window_term=True; zero when the
    # window is left to correct_window_bias) stands for the band's, as its bias does there
    term = np.sqrt(np.clip(start.window_shift**2 - start.window_shift_noise**2, 0.0, None))
    term_tilt = float(np.sqrt(max(start.window_tilt**2 - start.window_tilt_noise**2, 0.0)))
    return FocusAlignment(est.focus, np.hypot(focus_u, term), float(band.amplitude(est.focus)),
                          est.axis, float(np.hypot(axis_u, term_tilt)), start.power_direction,
                          est.centres, est.extent, ref, start.window_shift, start.window_tilt,
                          start.window_shift_noise, start.window_tilt_noise,
                          definition="band")


def _untapered_window_term(est: _Estimate, pressure: NDArray, grid: PlaneGrid,
                           frequency: float, medium: Medium, lobe: NDArray,
                           cfg: HologramConfig, wavelength: float, fraction: float,
                           functionals: tuple[NDArray, NDArray] | None, noise_level: float
                           ) -> tuple[NDArray, float, NDArray, float, NDArray, float]:
    """The window term without a source model: the same estimate on the untapered
    window (shift (3,), tilt, their terms in σ, and the noise parts of the difference)."""
    if fraction <= 0:
        return np.zeros(3), 0.0, np.zeros(3), 0.0, np.zeros(3), 0.0
    plain = _expand(pressure, grid, frequency, medium, lobe, cfg, cfg.focal_guard_energy)
    est_plain = _align_once(plain, est.newton, est.axis, cfg, wavelength)
    term, term_tilt, shift_noise, tilt_noise = _window_term(
        est, est_plain, np.zeros(0) if functionals is None else functionals[0], noise_level)
    tilt = float(np.arccos(np.clip(est_plain.axis @ est.axis, -1.0, 1.0)))
    return est_plain.focus - est.focus, tilt, term, term_tilt, shift_noise, tilt_noise


def window_model(grid: PlaneGrid, frequency: float, medium: Medium,
                 placement: SourceGeometry, apex: NDArray, axis: NDArray,
                 cfg: HologramConfig) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """The hologram (nx, ny) a uniform cap of ``placement`` (apex, unit axis) radiates onto
    the scan grid (:func:`cap_hologram`) and its exact focal maximum (m, O'Neil)."""
    wavelength = float(medium.wavelength(frequency))
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    true_focus = np.asarray(apex, float) + cap_axial_maximum(placement,
                                                             2 * np.pi / wavelength) * axis
    model = cap_hologram(grid.points().reshape(-1, 3), apex, axis, placement, frequency,
                         medium, source_points_per_wavelength=cfg.window_model_source_points
                         ).reshape(grid.shape)
    return model, true_focus


def correct_window_bias(alignment: FocusAlignment, pressure: NDArray, grid: PlaneGrid,
                        frequency: float, medium: Medium, placement: SourceGeometry,
                        apex: NDArray, axis: NDArray, cfg: HologramConfig | None = None,
                        model: tuple[NDArray, NDArray] | None = None) -> FocusAlignment:
    """Remove the scan window's bias from a focus and axis, modelled on the placed source.

    A uniform cap of ``placement``'s geometry, with its apex and axis where the source
    was placed (its exact focal maximum from O'Neil's axial field), radiates onto the
    scan grid (:func:`holoprobe.characterize.cap_hologram`); the estimate of
    :func:`align_focused` on that hologram (same window, taper, expansion and start),
    minus the model's own focus and axis, is the window's bias. It is subtracted from
    ``alignment``'s focus and axis, and ``cfg.window_model_uncertainty`` × |bias| is
    added in quadrature to their uncertainties (the model's velocity is uniform).

    The source's own pose matters, not the lobe axis: on a 49² twin of an F/1.5 bowl
    with a dead 40° sector (lobe axis 0.45° off the bowl's axis) the model along the lobe
    axis gave −2.3 µm, along the bowl's axis +7.1 µm, for a true window bias of +10.6 µm.

    Parameters
    ----------
    alignment : FocusAlignment
        From :func:`align_focused` with ``window_term=False``.
    pressure, grid, frequency, medium
        As given to :func:`align_focused`.
    placement : SourceGeometry
        The cap's geometry (``spherical-cap``; its fitted radius and aperture).
    apex, axis : ndarray, shape (3,)
        The placed source's apex (m) and unit axis, scan coordinates.
    cfg : HologramConfig, optional
    model : (ndarray, ndarray), optional
        :func:`window_model` of these arguments, when already made.

    Returns
    -------
    FocusAlignment
        Corrected focus and axis; ``window_shift`` / ``window_tilt`` hold the removed
        bias (m, rad); ``window_shift_noise`` / ``window_tilt_noise`` are 0.
    """
    cfg = cfg or HologramConfig()
    wavelength = float(medium.wavelength(frequency))
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    fraction = (edge_taper_fraction(pressure, grid, cfg.window_taper)
                if cfg.window_taper_follows_edge else cfg.window_taper)
    window = window_taper(grid.shape, fraction)
    hologram, true_focus = model or window_model(grid, frequency, medium, placement, apex,
                                                 axis, cfg)
    reach = cfg.lobe_reach_wavelengths * wavelength * axis
    lobe = np.array([true_focus - reach, true_focus + reach])
    field = _expand(hologram * window, grid, frequency, medium, lobe, cfg,
                    cfg.focal_guard_energy)
    m = _align_once(field, true_focus, axis, cfg, wavelength)
    bias, axis_bias = m.focus - true_focus, m.axis - axis
    new_axis = (alignment.axis - axis_bias) / np.linalg.norm(alignment.axis - axis_bias)
    tilt = float(np.linalg.norm(axis_bias))
    frac = cfg.window_model_uncertainty
    focus = alignment.focus - bias
    # the lobe centres move with the line they define: turned from the old axis onto the
    # new one about the focus, then shifted with it (their fitted line is then the new axis)
    turn, _ = Rotation.align_vectors(new_axis[None], alignment.axis[None])
    centres = focus + turn.apply(np.asarray(alignment.lobe_centres) - alignment.focus)
    return dataclasses.replace(
        alignment, focus=focus, axis=new_axis, lobe_centres=centres,
        focus_uncertainty=np.hypot(alignment.focus_uncertainty, frac * np.abs(bias)),
        axis_uncertainty=float(np.hypot(alignment.axis_uncertainty, frac * tilt)),
        window_shift=bias, window_tilt=tilt, window_shift_noise=np.zeros(3),
        window_tilt_noise=0.0)


def edge_taper_fraction(pressure: NDArray, grid: PlaneGrid, maximum: float) -> float:
    """Tukey α for the scan window: ``maximum`` times the outward-going share of the power
    in the band that the full taper would cover.

    The taper is meant for field that leaves the window outward (diffraction off the
    source's edge, side lobes): it reaches the focal lobe only through the hard edge's
    spectral leakage, and tapering it costs nothing. Field still converging onto the
    focus at the window's edge (a large bowl scanned close) is part of the focal lobe:
    tapering it removes signal and biases the focus and axis (0.05°, 76 µm on a 171 × 171
    scan of an 87 mm F/1 bowl). The local transverse wavevector is the gradient of the
    phase (exp(−iωt): it points along the propagation); outward means away from the
    hologram's intensity centroid. Noise, with random phase gradients, counts half.

    Parameters
    ----------
    pressure : ndarray, complex, shape (nx, ny)
        CW hologram (Pa) on ``grid``.
    grid : PlaneGrid
        Scan grid.
    maximum : float
        Tukey α of the full taper, in [0, 1].

    Returns
    -------
    float
        Tukey α in [0, ``maximum``] (``maximum`` when the band carries no power).
    """
    if maximum <= 0 or min(pressure.shape) < 3:
        return float(max(maximum, 0.0))
    x, y = np.meshgrid(grid.x, grid.y, indexing="ij")
    power = np.abs(pressure) ** 2
    centre = power.ravel() @ np.stack([x.ravel(), y.ravel()], axis=1) / power.sum()
    conj = np.conj(pressure)
    kx = np.imag(conj * np.gradient(pressure, grid.x, axis=0))
    ky = np.imag(conj * np.gradient(pressure, grid.y, axis=1))  # power × wavevector
    radial = kx * (x - centre[0]) + ky * (y - centre[1])
    band = window_taper(pressure.shape, maximum) < 1.0
    total = power[band].sum()
    if not total > 0:
        return float(maximum)
    return float(maximum * power[band & (radial > 0)].sum() / total)


def window_taper(shape: tuple[int, int], fraction: float) -> NDArray[np.float64]:
    """Separable Tukey taper (nx, ny) that falls to zero over ``fraction`` of each axis.

    ``fraction`` is the Tukey α (0: no taper, all ones); half of it lies at each edge.
    """
    if not 0 <= fraction <= 1:
        raise InputError(f"expected a fraction in [0, 1], got {fraction!r}",
                         field="window_taper")
    from scipy.signal.windows import tukey  # lazy: scipy.signal costs ~1 s of start-up

    return np.outer(tukey(shape[0], fraction), tukey(shape[1], fraction))
