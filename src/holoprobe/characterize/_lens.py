"""Acoustic lens: exact lens delays, focus fit in the complex domain, delay reversal.

A focusing lens delays the signal along the elevation y of the elements by
(paper eq. lens-delays)

    τ(y) = (√((H/2)² + F²) − √(y² + F²)) / c0,

zero at the aperture edges y = ±H/2 and largest in the centre. In holoprobe's
conjugate Fourier convention (``P(ω) = conj(FFT{p})``) a delay τ multiplies the
spectrum by ``e^{+iωτ}``; the reconstructed source is therefore
``V(x, y; ω) ≈ α(x; ω) e^{iωτ(y − y_L)}``.

The published code unwraps the phase along y only and fits the paraxial
parabola per bin (reference_spec section 7, item 11: 2π offsets between columns
corrupt the pooled fit). Here the focus is fitted directly in the complex domain
— no phase unwrapping at all: for trial (F, y_L) every column x of every bin
gets its own complex amplitude α (closed form), which absorbs per-bin phase,
time shifts and any lateral phase pattern, and the residual
``V − α e^{iωτ}`` is minimised over all bins at once with the exact delays.
The starting value is the paraxial parabola, taken from the phase differences
of neighbouring rows (a linear fit of the delay gradient, again without
unwrapping). The fit runs in curvature κ = 1/F, so weak lenses and F = ∞ are
regular points; F = ∞ is reported when κ is not significant. The residual
depends on each bin's block only through its Gram matrix ``Bᴴ B``, so the fit
works on those (cost and analytic Jacobian in closed form), on the field
normalised to unit energy (the result does not depend on the units of V), and
on the ``max_bins`` strongest bins.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.characterize._aperture import ApertureFit, _check_field, select_signal_bins
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import Medium, PlaneGrid
from holoprobe.lens import lens_delays
from holoprobe.signal import blas_threads

__all__ = ["LensFit", "fit_lens_focus", "lens_delays", "lens_reversal", "reverse_lens_delays"]


def reverse_lens_delays(
    velocity: ArrayLike,
    grid: PlaneGrid,
    frequencies: ArrayLike,
    focus: float,
    height: float,
    sound_speed: float,
    *,
    center_y: float = 0.0,
) -> NDArray[np.complex128]:
    """Undo the lens delays of a field on the source plane (paper section II F).

    Parameters
    ----------
    velocity : array_like, complex, shape (nx, ny, nf)
        Field in holoprobe's conjugate Fourier convention.
    grid : PlaneGrid
        The source-plane grid.
    frequencies : array_like, shape (nf,)
        Bin frequencies in Hz.
    focus, height : float
        Lens focal distance F and aperture height H in m (``inf``: no change).
    sound_speed : float
        c0 in m/s.
    center_y : float
        Elevation of the lens centre y_L in m.

    Returns
    -------
    ndarray, complex, shape (nx, ny, nf)
        ``V · e^{−iωτ(y − y_L)}``. In the conjugate convention a delay τ is the
        factor ``e^{+iωτ}``, so removing it is ``e^{−iωτ}`` (the paper's
        ``e^{+iωτ}`` refers to the plain FFT convention of the published code).
        Afterwards every point carries the timing of the aperture edges.
    """
    v, f = _check_field(velocity, grid, frequencies, min_points=1)
    return v * lens_reversal(grid, f, focus, height, sound_speed, center_y=center_y)[None]


def lens_reversal(grid: PlaneGrid, frequencies: ArrayLike, focus: float, height: float,
                  sound_speed: float, *, center_y: float = 0.0) -> NDArray[np.complex128]:
    """The factor ``e^{−iωτ(y − y_L)}`` of :func:`reverse_lens_delays`, shape (ny, nf)
    (rows of the grid, frequencies in Hz; ``focus``, ``height``, ``center_y`` in m,
    ``sound_speed`` in m/s)."""
    tau = lens_delays(np.asarray(grid.y) - float(center_y), focus, height, sound_speed)
    f = np.atleast_1d(np.asarray(frequencies, dtype=float))
    return np.exp(-1j * (2.0 * np.pi * f)[None, :] * tau[:, None])


@dataclass(frozen=True)
class LensFit:
    """Result of :func:`fit_lens_focus`.

    Attributes
    ----------
    focus : float
        Focal distance F in m (``inf`` when the curvature is not significant).
    focus_uncertainty : float
        Standard uncertainty of F in m (``inf`` when F is ``inf``).
    curvature, curvature_uncertainty : float
        κ = 1/F in 1/m and its standard uncertainty (the larger of the
        Jacobian-based value and the scatter of the per-bin estimates).
    center_y, center_y_uncertainty : float
        Lens centre y_L in m and its standard uncertainty (the aperture centre,
        uncertainty ``inf``, when the curvature is not significant). A residual
        linear delay along y (a θx error) shifts y_L by ``c0 g/κ`` for a delay
        slope g: to second order the two are the same function.
    significant : bool
        Whether |κ| exceeds ``significance`` standard uncertainties.
    frequencies : ndarray, shape (nb,)
        Frequencies (Hz) of the bins used.
    per_bin_curvature, per_bin_curvature_uncertainty : ndarray, shape (nb,)
        κ fitted in each bin alone (y_L fixed), and its uncertainty.
    per_bin_focus : ndarray, shape (nb,)
        ``1/per_bin_curvature`` in m.
    explained : float
        Fraction of the energy of V in the fit region that the model explains.
    """

    focus: float
    focus_uncertainty: float
    curvature: float
    curvature_uncertainty: float
    center_y: float
    center_y_uncertainty: float
    significant: bool
    frequencies: NDArray[np.float64]
    per_bin_curvature: NDArray[np.float64]
    per_bin_curvature_uncertainty: NDArray[np.float64]
    per_bin_focus: NDArray[np.float64]
    explained: float


def _delay_derivatives(
    s: NDArray[np.float64], curvature: NDArray[np.float64], half_height: float,
    sound_speed: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Lens delays τ(s; κ) and their derivatives ∂τ/∂κ and ∂τ/∂y_L (s = y − y_L).

    ``curvature`` broadcasts against ``s``; every expression is regular at κ = 0.
    """
    k = curvature
    a2 = half_height**2
    s2 = s * s
    sa = np.sqrt(1.0 + k * k * a2)
    ss = np.sqrt(1.0 + k * k * s2)
    den = sound_speed * (sa + ss)
    tau = k * (a2 - s2) / den
    dtau_dk = (a2 - s2) / den - tau * k * (a2 / sa + s2 / ss) / (sa + ss)
    dtau_dyl = k * s / (sound_speed * ss)
    return tau, dtau_dk, dtau_dyl


def _normal_equations(
    gram: NDArray[np.complex128],
    mask: NDArray[np.float64],
    omegas: NDArray[np.float64],
    y: NDArray[np.float64],
    curvature: NDArray[np.float64],
    center_y: float,
    half_height: float,
    sound_speed: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Cost, ``Jᵀr`` and ``JᵀJ`` of the variable-projection residual of every bin.

    For a bin's block B (nx, ny) the residual with the closed-form amplitudes is
    ``r = B (I − P)``, ``P = ē eᵀ/n``, ``e = e^{iωτ}`` on the n rows of its fit
    region. It depends on B only through ``G = Bᴴ B`` (``gram``, (nb, ny, ny)):
    ``‖r‖² = tr G − eᵀ G ē / n``, and with ``∂P/∂p = (d̄ eᵀ + ē dᵀ)/n``,
    ``d = ∂e/∂p = iω (∂τ/∂p) e``, the Gauss-Newton matrix is
    ``Re tr(∂P/∂p G ∂P/∂q)``. Each evaluation costs O(ny²) per bin.

    Parameters
    ----------
    gram : ndarray, complex, shape (nb, ny, ny)
        ``Bᴴ B`` of every bin (zero outside its fit region).
    mask : ndarray, shape (nb, ny)
        1 on the rows of each bin's fit region, 0 elsewhere.
    omegas : ndarray, shape (nb,)
        Angular frequencies in rad/s.
    y : ndarray, shape (ny,)
        Elevation of the rows in m.
    curvature : ndarray, shape (nb,)
        κ of each bin in 1/m.
    center_y : float
        Lens centre y_L in m.
    half_height, sound_speed : float
        H/2 in m and c0 in m/s.

    Returns
    -------
    cost : ndarray, shape (nb,)
        ``‖r‖²`` of each bin.
    jtr : ndarray, shape (nb, 2)
        ``Jᵀr`` per bin for the parameters (κ, y_L).
    jtj : ndarray, shape (nb, 2, 2)
        ``JᵀJ`` per bin.
    """
    tau, dtau_dk, dtau_dyl = _delay_derivatives(y[None, :] - center_y, curvature[:, None],
                                                half_height, sound_speed)
    e = mask * np.exp(1j * omegas[:, None] * tau)
    u = np.conj(e)
    n = mask.sum(axis=1)
    rates = [omegas[:, None] * dtau_dk * mask, omegas[:, None] * dtau_dyl * mask]  # ω ∂τ/∂p
    d = [1j * rate * e for rate in rates]
    w = [np.conj(dp) for dp in d]
    # G u, G w_κ, G w_yL of every bin: one batch of (ny × ny)·(ny × 3) BLAS products
    with blas_threads(1):
        products = np.matmul(gram, np.stack([u, *w], axis=2))
    gu, gw = products[:, :, 0], [products[:, :, 1], products[:, :, 2]]
    egu = np.einsum("by,by->b", e, gu)  # real up to round-off
    cost = np.einsum("byy->b", gram).real - egu.real / n
    jtr = np.empty((gram.shape[0], 2))
    jtj = np.empty((gram.shape[0], 2, 2))
    for p in range(2):
        dgu = np.einsum("by,by->b", d[p], gu)
        jtr[:, p] = -dgu.real / n  # ½ ∂‖r‖²/∂p
        for q in range(p, 2):
            total = (np.einsum("by,by->b", e, gw[q]) * (-1j) * rates[p].sum(axis=1)
                     + egu * np.sum(rates[p] * rates[q], axis=1)
                     + np.einsum("by,by->b", d[p], gw[q]) * n
                     + dgu * 1j * rates[q].sum(axis=1))
            jtj[:, p, q] = jtj[:, q, p] = total.real / n**2
    return cost, jtr, jtj


@dataclass(frozen=True)
class _FitRegion:
    """The lens fit's data: every bin's Gram matrix ``Bᴴ B`` of the aperture block
    shrunk by the margin, normalised to unit total energy."""

    bins: NDArray[np.intp]  # (nb,) indices into the frequencies
    omegas: NDArray[np.float64]  # (nb,) rad/s
    gram: NDArray[np.complex128]  # (nb, ny, ny)
    mask_y: NDArray[np.float64]  # (nb, ny) 1 on each bin's rows
    y: NDArray[np.float64]  # (ny,) elevation of the kept rows, m
    n_x: NDArray[np.intp]  # (nb,) columns of each bin's region
    n_y: NDArray[np.intp]  # (nb,) rows of each bin's region
    bin_energy: NDArray[np.float64]  # (nb,) energy of each bin (before normalising)
    energy: float


def _check_lens_options(margin_wavelengths: float, max_bins: int | None, tolerance: float,
                        max_evaluations: int) -> None:
    if not (np.isfinite(margin_wavelengths) and margin_wavelengths >= 0):
        raise InputError(f"expected a non-negative number, got {margin_wavelengths!r}",
                         field="margin_wavelengths")
    if max_bins is not None and not (isinstance(max_bins, (int, np.integer)) and max_bins >= 1):
        raise InputError(f"expected a positive integer or None, got {max_bins!r}",
                         field="max_bins")
    if not (np.isfinite(tolerance) and 0 < tolerance < 1):
        raise InputError(f"expected a number in (0, 1), got {tolerance!r}", field="tolerance")
    if not (isinstance(max_evaluations, (int, np.integer)) and max_evaluations >= 1):
        raise InputError(f"expected a positive integer, got {max_evaluations!r}",
                         field="max_evaluations")


def _fit_region(v: NDArray, f: NDArray, bins: NDArray[np.intp], grid: PlaneGrid,
                aperture: ApertureFit, margin_wavelengths: float, sound_speed: float,
                max_bins: int | None) -> _FitRegion:
    """Each bin's fit region (the aperture shrunk by ``margin_wavelengths`` of its
    wavelength on every side: nested boxes), the ``max_bins`` strongest bins, and their
    Gram matrices."""
    a = 0.5 * aperture.height
    x, y = np.asarray(grid.x, dtype=float), np.asarray(grid.y, dtype=float)
    m = margin_wavelengths * sound_speed / f[bins]
    x_lo, x_hi = aperture.center_x - 0.5 * aperture.width, aperture.center_x + 0.5 * aperture.width
    y_lo, y_hi = aperture.center_y - a, aperture.center_y + a
    in_x = (x[None, :] >= x_lo + m[:, None]) & (x[None, :] <= x_hi - m[:, None])
    in_y = (y[None, :] >= y_lo + m[:, None]) & (y[None, :] <= y_hi - m[:, None])
    keep = (in_x.sum(axis=1) >= 3) & (in_y.sum(axis=1) >= 3)
    if not np.any(keep):
        raise FitError(
            "the aperture shrunk by the margin keeps fewer than 3 rows or columns in every "
            "frequency bin; lower margin_wavelengths or use a finer grid",
            field="aperture",
        )
    bins, in_x, in_y = bins[keep], in_x[keep], in_y[keep]
    ix, iy = np.flatnonzero(in_x.any(axis=0)), np.flatnonzero(in_y.any(axis=0))
    in_x, in_y = in_x[:, ix], in_y[:, iy]
    block = np.moveaxis(v[np.ix_(ix, iy, bins)], 2, 0).astype(np.complex128)  # (nb, nx, ny)
    block *= in_x[:, :, None] & in_y[:, None, :]
    bin_energy = np.einsum("bxy,bxy->b", block.real, block.real) + np.einsum(
        "bxy,bxy->b", block.imag, block.imag)
    if max_bins is not None and bins.size > max_bins:
        strongest = np.sort(np.argsort(bin_energy)[::-1][:max_bins])
        bins, in_x, in_y = bins[strongest], in_x[strongest], in_y[strongest]
        block, bin_energy = block[strongest], bin_energy[strongest]
    energy = float(np.sum(bin_energy))
    if not energy > 0:
        raise FitError("the field is zero in the fit region of every bin", field="velocity")
    # Bᴴ B of every bin (the residual depends on the block only through it), normalised
    # to unit total energy: the fit is scale-free
    gram = np.empty((block.shape[0], block.shape[2], block.shape[2]), np.complex128)
    with blas_threads(1):  # one ny × ny product per bin (BLAS: ~10× einsum's loops)
        for b, g in zip(block, gram, strict=True):
            np.matmul(b.conj().T, b, out=g)
    gram /= energy  # (nb, ny, ny)
    return _FitRegion(bins=bins, omegas=2.0 * np.pi * f[bins], gram=gram,
                      mask_y=in_y.astype(float), y=y[iy], n_x=in_x.sum(axis=1),
                      n_y=in_y.sum(axis=1), bin_energy=bin_energy, energy=energy)


def _paraxial_start(region: _FitRegion, step_y: float, aperture: ApertureFit,
                    sound_speed: float) -> tuple[float, float]:
    """Starting (κ, y_L): the delay gradient from neighbouring-row phase differences
    (``Σ_x V(x, y+1) conj V(x, y)`` is the first super-diagonal of ``Bᴴ B``), a
    weighted line through it, no unwrapping."""
    a = 0.5 * aperture.height
    yy, omegas = region.y, region.omegas
    g = np.diagonal(region.gram, offset=1, axis1=1, axis2=2)
    grads = (np.angle(g) / (omegas[:, None] * step_y)).ravel()
    mids = np.broadcast_to(0.5 * (yy[1:] + yy[:-1]), g.shape).ravel()
    sw = np.sqrt(np.abs(g)).ravel()
    design = np.stack([np.ones_like(mids), mids - aperture.center_y], axis=1)
    beta = np.linalg.lstsq(design * sw[:, None], grads * sw, rcond=None)[0]
    kappa0 = -beta[1] * sound_speed
    yl0 = aperture.center_y
    if kappa0 != 0:
        yl0 = float(np.clip(aperture.center_y + beta[0] * sound_speed / kappa0,
                            aperture.center_y - a, aperture.center_y + a))
    return kappa0, yl0


def _fit_global(region: _FitRegion, start: tuple[float, float], scale: NDArray[np.float64],
                y_bounds: tuple[float, float], half_height: float, sound_speed: float,
                max_evaluations: int, tolerance: float
                ) -> tuple[NDArray[np.float64], float, NDArray[np.float64]]:
    """(κ, y_L) minimising the residual over all bins: Gauss-Newton in scaled
    parameters, the step halved until the cost falls, y_L kept inside ``y_bounds``.
    Returns the parameters, the cost and ``JᵀJ``."""
    nb = region.bins.size

    def total(p: NDArray[np.float64]) -> tuple[float, NDArray, NDArray]:
        c, jtr, jtj = _normal_equations(region.gram, region.mask_y, region.omegas, region.y,
                                        np.full(nb, p[0]), float(p[1]), half_height,
                                        sound_speed)
        return float(np.sum(c)), np.sum(jtr, axis=0), np.sum(jtj, axis=0)

    params = np.array(start)
    cost, jtr, jtj = total(params)
    evaluations = 1
    while evaluations < max_evaluations:
        step = scale * np.linalg.lstsq(jtj * np.outer(scale, scale), -jtr * scale,
                                       rcond=None)[0]
        shrink, moved = 1.0, False
        while evaluations < max_evaluations and np.any(
                np.abs(shrink * step) > tolerance * scale):
            trial = params + shrink * step
            trial[1] = np.clip(trial[1], *y_bounds)
            c_new, jtr_new, jtj_new = total(trial)
            evaluations += 1
            if c_new < cost:
                params, cost, jtr, jtj, moved = trial, c_new, jtr_new, jtj_new, True
                break
            shrink *= 0.5
        if not moved:
            break  # no lower cost along the Gauss-Newton step: converged to round-off
    return params, cost, jtj


def _fit_per_bin(region: _FitRegion, kappa: float, center_y: float, scale_k: NDArray,
                 half_height: float, sound_speed: float, max_evaluations: int,
                 tolerance: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """κ of every bin alone with y_L fixed: Gauss-Newton on all bins at once (they are
    independent), the step halved where it does not lower a bin's cost. Returns κ per
    bin and its standard uncertainty (``inf`` where the curvature is not positive)."""
    nb = region.bins.size

    def per_bin(k: NDArray[np.float64]) -> tuple:
        c, jtr_b, jtj_b = _normal_equations(region.gram, region.mask_y, region.omegas,
                                            region.y, k, center_y, half_height, sound_speed)
        return c, jtr_b[:, 0], jtj_b[:, 0, 0]

    per_k = np.full(nb, kappa)
    cost_b, grad, curv = per_bin(per_k)
    active = curv > 0
    for _ in range(max_evaluations):
        step = np.where(active, -grad / np.where(curv > 0, curv, 1.0), 0.0)
        active &= np.abs(step) > tolerance * scale_k
        if not np.any(active):
            break
        shrink = np.ones(nb)
        pending = active.copy()
        for _ in range(max_evaluations):
            trial = per_k + shrink * step
            c_new, _, _ = per_bin(np.where(pending, trial, per_k))
            accept = pending & (c_new < cost_b)
            per_k = np.where(accept, trial, per_k)
            pending &= ~accept
            shrink = np.where(pending, 0.5 * shrink, shrink)
            stuck = pending & (np.abs(shrink * step) <= tolerance * scale_k)
            active &= ~stuck  # no lower cost along the step: converged to round-off
            pending &= ~stuck
            if not np.any(pending):
                break
        cost_b, grad, curv = per_bin(per_k)
    dof = np.maximum(2 * region.n_x * region.n_y - 1 - 2 * region.n_x, 1)
    per_u = np.sqrt(cost_b / dof / np.where(curv > 0, curv, np.nan))
    return per_k, np.where(np.isfinite(per_u), per_u, np.inf)


def _curvature_uncertainty(u_jacobian: float, per_k: NDArray, per_u: NDArray) -> float:
    """The larger of the Jacobian-based u(κ) and the weighted scatter of the per-bin κ
    (with at least 3 bins of finite, positive uncertainty)."""
    if per_k.size >= 3 and np.all(per_u > 0) and np.all(np.isfinite(per_u)):
        wi = 1.0 / per_u**2
        mean = np.sum(wi * per_k) / np.sum(wi)
        scatter = np.sqrt(np.sum(wi * (per_k - mean) ** 2) / ((per_k.size - 1) * np.sum(wi)))
        return max(u_jacobian, float(scatter))
    return u_jacobian


def fit_lens_focus(
    velocity: ArrayLike,
    grid: PlaneGrid,
    frequencies: ArrayLike,
    medium: Medium | None,
    aperture: ApertureFit,
    *,
    band: tuple[float, float] | None = None,
    threshold_db: float = 20.0,
    max_bins: int | None = 64,
    margin_wavelengths: float = 1.0,
    significance: float = 3.0,
    max_evaluations: int = 200,
    tolerance: float = 1e-10,
) -> LensFit:
    """Fit the lens focus F (and centre y_L) to the phase of the reconstructed source.

    Model, per bin ω and grid column x inside the aperture shrunk by a margin:
    ``V(x, y; ω) ≈ α(x; ω) e^{iωτ(y − y_L; F)}`` with the exact delays of
    :func:`lens_delays` (paper eq. lens-delays). The complex amplitudes α are
    solved in closed form (variable projection), so per-bin phase, time shift and
    any lateral phase pattern drop out; (κ = 1/F, y_L) minimise the complex
    least-squares residual summed over all bins with signal. Because the
    residual is taken on V itself, each bin and point counts with its power —
    the maximum-likelihood weighting for white noise; no phase unwrapping
    is involved.

    The fit is scale-free: V is normalised to unit energy in the fit region
    first, so F does not depend on the units of V. The residual of a bin
    depends on its block B (nx, ny) only through ``Bᴴ B`` (ny, ny), computed
    once; cost, gradient and Gauss-Newton matrix then follow in closed form at
    O(ny²) per bin whatever nx (analytic Jacobian, no BLAS threads in the loop).
    (κ, y_L) are found by Gauss-Newton with step halving from the paraxial
    start; the per-bin curvatures likewise, all bins at once.

    Parameters
    ----------
    velocity : array_like, complex, shape (nx, ny, nf)
        Normal surface velocity on the source plane (conjugate convention), in
        any unit (the result does not depend on a scale factor).
    grid : PlaneGrid
        The source-plane grid.
    frequencies : array_like, shape (nf,)
        Bin frequencies in Hz.
    medium : Medium or None
        Sound speed c0 (default water at 20 °C).
    aperture : ApertureFit
        The fitted aperture (W, H, centre; H/2 sets the zero of τ).
    band : (float, float), optional
        Frequency range in Hz; default all bins with signal.
    threshold_db : float
        Bins within this many dB of the strongest bin's energy are used.
    max_bins : int or None
        At most this many bins are fitted: those with the most energy in their
        fit region (``None``: all bins above the threshold). They carry nearly
        all the information on F; the cost grows linearly with their number.
    margin_wavelengths : float
        The fit region is the aperture shrunk by this many wavelengths c0/f of
        each bin on every side (edge diffraction is not lens phase).
    significance : float
        F is reported as ``inf`` unless ``|κ| > significance · u(κ)``.
    max_evaluations : int
        Cap on cost evaluations of the global fit and on the Gauss-Newton
        iterations of the per-bin fits.
    tolerance : float
        The iterations stop when a step is below this fraction of the
        parameter scale (for κ the change that moves the edge phase by ~1 rad,
        for y_L one grid step), or when no step lowers the cost.

    Returns
    -------
    LensFit

    Raises
    ------
    InputError
        Wrong shapes or NaN, bad options.
    FitError
        No bin with signal, or an aperture too small to keep three rows and columns
        after the margin (the data do not support a focus fit).
    """
    medium = Medium() if medium is None else medium
    v, f = _check_field(velocity, grid, frequencies)
    c0 = medium.sound_speed
    _check_lens_options(margin_wavelengths, max_bins, tolerance, max_evaluations)
    bins = select_signal_bins(v, f, band=band, threshold_db=threshold_db)
    a = 0.5 * aperture.height
    region = _fit_region(v, f, bins, grid, aperture, margin_wavelengths, c0, max_bins)
    step_y = float(grid.y[1] - grid.y[0])
    start = _paraxial_start(region, step_y, aperture, c0)
    # κ scale: the change giving ~1 rad at the edge; y_L: one grid step
    w_ref = float(np.sqrt(np.sum(region.bin_energy * region.omegas**2) / region.energy))
    kappa_scale = 2.0 * c0 / (w_ref * a * a)
    scale = np.array([kappa_scale, step_y])
    params, cost, jtj = _fit_global(region, start, scale,
                                    (aperture.center_y - a, aperture.center_y + a), a, c0,
                                    max_evaluations, tolerance)
    kappa, yl = (float(q) for q in params)
    n_linear = 2 * int(np.sum(region.n_x))
    n_residual = 2 * int(np.sum(region.n_x * region.n_y))
    s2 = cost / max(n_residual - 2 - n_linear, 1)
    cov = np.outer(scale, scale) * np.linalg.pinv(jtj * np.outer(scale, scale)) * s2
    u_yl = float(np.sqrt(cov[1, 1]))
    per_k, per_u = _fit_per_bin(region, kappa, yl, kappa_scale * w_ref / region.omegas, a, c0,
                                max_evaluations, tolerance)
    u_kappa = _curvature_uncertainty(float(np.sqrt(cov[0, 0])), per_k, per_u)
    significant = bool(abs(kappa) > significance * u_kappa)
    if significant:
        focus = 1.0 / kappa
        u_focus = u_kappa / kappa**2
    else:
        focus, u_focus = float("inf"), float("inf")
        yl, u_yl = float(aperture.center_y), float("inf")
    with np.errstate(divide="ignore"):
        per_focus = np.where(per_k != 0, 1.0 / per_k, np.inf)
    return LensFit(
        focus=float(focus), focus_uncertainty=float(u_focus),
        curvature=kappa, curvature_uncertainty=u_kappa,
        center_y=yl, center_y_uncertainty=u_yl, significant=significant,
        frequencies=f[region.bins].copy(), per_bin_curvature=per_k,
        per_bin_curvature_uncertainty=per_u, per_bin_focus=per_focus, explained=1.0 - cost,
    )
