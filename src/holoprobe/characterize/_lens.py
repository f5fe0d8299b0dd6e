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
regular points; F = ∞ is reported when κ is not significant.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
from numpy.typing import ArrayLike, NDArray

from holoprobe.characterize._aperture import ApertureFit, _check_field, select_signal_bins
from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid

__all__ = ["LensFit", "fit_lens_focus", "lens_delays", "reverse_lens_delays"]


def _delays_from_curvature(
    y: NDArray[np.float64], curvature: float, half_height: float, sound_speed: float
) -> NDArray[np.float64]:
    """Exact lens delays with κ = 1/F, in a form that is regular at κ = 0 (s)."""
    kappa = float(curvature)
    a2 = half_height**2
    y2 = np.asarray(y, dtype=float) ** 2
    k2 = kappa * kappa
    return kappa * (a2 - y2) / (sound_speed * (np.sqrt(1.0 + k2 * a2) + np.sqrt(1.0 + k2 * y2)))


def lens_delays(
    y: ArrayLike, focus: float, height: float, sound_speed: float
) -> NDArray[np.float64]:
    """Exact lens delays along the elevation (paper eq. lens-delays).

    ``τ(y) = (√((H/2)² + F²) − √(y² + F²)) / c0``, evaluated as
    ``κ((H/2)² − y²) / (c0 (√(1 + κ²(H/2)²) + √(1 + κ²y²)))`` with κ = 1/F, which
    has no cancellation for weak lenses and gives 0 for F = ±∞.

    Parameters
    ----------
    y : array_like
        Elevation coordinate relative to the lens centre, in m (any shape).
    focus : float
        Focal distance F in m; ``inf`` for no lens; a negative F describes a
        diverging lens (delays of the opposite sign).
    height : float
        Aperture height H in m (delays are zero at ``y = ±H/2``).
    sound_speed : float
        c0 in m/s.

    Returns
    -------
    ndarray
        Delays τ in s, same shape as ``y``.

    Examples
    --------
    >>> tau = lens_delays([0.0, 7.14e-3], 0.1807, 14.28e-3, 1481.0)
    >>> [round(float(t) * 1e9, 2) for t in tau]
    [95.21, 0.0]
    """
    focus = float(focus)
    if focus == 0 or np.isnan(focus):
        raise InputError(f"expected a non-zero focal distance in m (inf: no lens), got {focus!r}",
                         field="focus")
    if not (np.isfinite(height) and height > 0):
        raise InputError(f"expected a positive height in m, got {height!r}", field="height")
    if not (np.isfinite(sound_speed) and sound_speed > 0):
        raise InputError(f"expected a positive sound speed in m/s, got {sound_speed!r}",
                         field="sound_speed")
    return _delays_from_curvature(np.asarray(y, dtype=float), 1.0 / focus, 0.5 * float(height),
                                  float(sound_speed))


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
    tau = lens_delays(np.asarray(grid.y) - float(center_y), focus, height, sound_speed)
    return v * np.exp(-1j * (2.0 * np.pi * f)[None, None, :] * tau[None, :, None])


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


def _crop(coord: NDArray[np.float64], lo: float, hi: float) -> NDArray[np.intp]:
    return np.flatnonzero((coord >= lo) & (coord <= hi))


def _covariance(jac: NDArray, residual: NDArray, n_linear: int) -> NDArray[np.float64]:
    dof = max(residual.size - jac.shape[1] - n_linear, 1)
    s2 = float(residual @ residual) / dof
    return np.linalg.pinv(jac.T @ jac) * s2


def fit_lens_focus(
    velocity: ArrayLike,
    grid: PlaneGrid,
    frequencies: ArrayLike,
    medium: Medium | None,
    aperture: ApertureFit,
    *,
    band: tuple[float, float] | None = None,
    threshold_db: float = 20.0,
    margin_wavelengths: float = 1.0,
    significance: float = 3.0,
    max_evaluations: int = 200,
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

    Parameters
    ----------
    velocity : array_like, complex, shape (nx, ny, nf)
        Normal surface velocity on the source plane (conjugate convention).
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
    margin_wavelengths : float
        The fit region is the aperture shrunk by this many wavelengths c0/f of
        each bin on every side (edge diffraction is not lens phase).
    significance : float
        F is reported as ``inf`` unless ``|κ| > significance · u(κ)``.
    max_evaluations : int
        Cap on residual evaluations of the global fit.

    Returns
    -------
    LensFit

    Raises
    ------
    InputError
        Wrong shapes or NaN, no bin with signal, or an aperture too small to
        keep three rows and columns after the margin.
    """
    medium = Medium() if medium is None else medium
    v, f = _check_field(velocity, grid, frequencies)
    c0 = medium.sound_speed
    if not (np.isfinite(margin_wavelengths) and margin_wavelengths >= 0):
        raise InputError(f"expected a non-negative number, got {margin_wavelengths!r}",
                         field="margin_wavelengths")
    bins = select_signal_bins(v, f, band=band, threshold_db=threshold_db)
    a = 0.5 * aperture.height
    x, y = np.asarray(grid.x), np.asarray(grid.y)
    omegas, blocks, ys, used = [], [], [], []
    for j in bins:
        m = margin_wavelengths * c0 / f[j]
        ix = _crop(x, aperture.center_x - 0.5 * aperture.width + m,
                   aperture.center_x + 0.5 * aperture.width - m)
        iy = _crop(y, aperture.center_y - a + m, aperture.center_y + a - m)
        if ix.size < 3 or iy.size < 3:
            continue
        used.append(f[j])
        omegas.append(2.0 * np.pi * f[j])
        blocks.append(v[np.ix_(ix, iy, [j])][:, :, 0])
        ys.append(y[iy])
    if not blocks:
        raise InputError(
            "the aperture shrunk by the margin keeps fewer than 3 rows or columns in every "
            "frequency bin; lower margin_wavelengths or use a finer grid",
            field="aperture",
        )
    n_linear = 2 * sum(b.shape[0] for b in blocks)
    energy = float(sum(np.sum(np.abs(b) ** 2) for b in blocks))

    # --- paraxial start: delay gradient from neighbouring-row phase differences
    grads, mids, wts = [], [], []
    for w, b, yy in zip(omegas, blocks, ys, strict=True):
        g = np.sum(b[:, 1:] * np.conj(b[:, :-1]), axis=0)
        grads.append(np.angle(g) / (w * (yy[1] - yy[0])))
        mids.append(0.5 * (yy[1:] + yy[:-1]))
        wts.append(np.abs(g))
    grads, mids, wts = (np.concatenate(q) for q in (grads, mids, wts))
    design = np.stack([np.ones_like(mids), mids - aperture.center_y], axis=1)
    sw = np.sqrt(wts)
    beta = np.linalg.lstsq(design * sw[:, None], grads * sw, rcond=None)[0]
    kappa0 = -beta[1] * c0
    yl0 = aperture.center_y
    if kappa0 != 0:
        yl0 = float(np.clip(aperture.center_y + beta[0] * c0 / kappa0,
                            aperture.center_y - a, aperture.center_y + a))

    # --- exact fit in the complex domain, parameters (κ, y_L)
    w_ref = float(np.sqrt(sum(np.sum(np.abs(b) ** 2) * w**2 for w, b in zip(
        omegas, blocks, strict=True)) / energy))
    kappa_scale = 2.0 * c0 / (w_ref * a * a)  # κ change giving ~1 rad at the edge
    step_y = float(y[1] - y[0])

    def residual_blocks(kappa: float, yl: float, which=None):
        out = []
        idx = range(len(blocks)) if which is None else which
        for i in idx:
            e = np.exp(1j * omegas[i] * _delays_from_curvature(ys[i] - yl, kappa, a, c0))
            alpha = blocks[i] @ np.conj(e) / e.size
            r = blocks[i] - alpha[:, None] * e[None, :]
            out.append(np.concatenate([r.real.ravel(), r.imag.ravel()]))
        return np.concatenate(out)

    result = scipy.optimize.least_squares(
        lambda p: residual_blocks(p[0], p[1]), np.array([kappa0, yl0]),
        x_scale=np.array([kappa_scale, step_y]), method="trf", max_nfev=max_evaluations,
        bounds=([-np.inf, aperture.center_y - a], [np.inf, aperture.center_y + a]),
    )
    kappa, yl = (float(q) for q in result.x)
    cov = _covariance(np.asarray(result.jac), result.fun, n_linear)
    u_kappa_jac = float(np.sqrt(cov[0, 0]))
    u_yl = float(np.sqrt(cov[1, 1]))
    explained = 1.0 - float(result.fun @ result.fun) / energy

    # --- per-bin curvature with y_L fixed
    per_k = np.empty(len(blocks))
    per_u = np.empty(len(blocks))
    for i in range(len(blocks)):
        res_i = scipy.optimize.least_squares(
            lambda p, i=i: residual_blocks(p[0], yl, which=[i]), np.array([kappa]),
            x_scale=np.array([kappa_scale * w_ref / omegas[i]]), method="trf",
            max_nfev=max_evaluations,
        )
        per_k[i] = res_i.x[0]
        per_u[i] = np.sqrt(_covariance(np.asarray(res_i.jac), res_i.fun,
                                       2 * blocks[i].shape[0])[0, 0])
    u_kappa = u_kappa_jac
    if per_k.size >= 3 and np.all(per_u > 0):
        wi = 1.0 / per_u**2
        mean = np.sum(wi * per_k) / np.sum(wi)
        scatter = np.sqrt(np.sum(wi * (per_k - mean) ** 2) / ((per_k.size - 1) * np.sum(wi)))
        u_kappa = max(u_kappa, float(scatter))

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
        frequencies=np.asarray(used), per_bin_curvature=per_k, per_bin_curvature_uncertainty=per_u,
        per_bin_focus=per_focus, explained=explained,
    )
