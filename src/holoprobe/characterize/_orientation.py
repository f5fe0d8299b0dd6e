"""Orientation of the scan plane from the angular spectrum (paper section II D).

A zero-angle transmission from a flat aperture sends most of its energy along the
transducer axis. On a scan plane with pose ``R = Rz(θz) @ Ry(θy) @ Rx(θx)`` that
wave vector ``(0, 0, k)`` has the in-plane components ``R^T (0, 0, k)``, so the
strongest component of the angular spectrum sits at

    k'x,max = k R31 = −k sin θy,      k'y,max = k R32 = k sin θx cos θy

which gives θx and θy. The rotation θz about the transducer axis is found from the
bright ``kx = 0`` / ``ky = 0`` lines of a rectangular aperture's spectrum: the
energy of the angular spectrum integrated along those lines, rotated into the scan
plane (paper eqs. rotated-points-x, rotated-points-y), is maximal for the true θz
(paper eq. rotation-optimization).

Unlike the published implementation (reference_spec 2.4), the peak is located with
sub-bin accuracy by maximising the *exact* continuous-k DFT of the scan, θz by a
continuous optimisation on exactly evaluated spectra (NUFFT, ``finufft``), the
frequency bins are chosen from the data, and bins with a spurious mode are detected
as outliers instead of being excluded by a hard-coded band.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import finufft
import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import FitError, InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose, rotation_matrix
from holoprobe.signal import Threads, bin_energy, mad_sigma
from holoprobe.signal import workers as _default_workers

__all__ = ["OrientationResult", "estimate_orientation"]



@dataclass(frozen=True)
class OrientationResult:
    """Estimated orientation of a scan plane.

    Attributes
    ----------
    theta_x, theta_y, theta_z : float
        Rotation angles in rad, ``R = Rz(θz) @ Ry(θy) @ Rx(θx)`` (paper section II D).
    u_theta_x, u_theta_y, u_theta_z : float
        Standard uncertainties in rad, from the weighted scatter of the per-bin
        estimates (``nan`` when fewer than two bins were used). See Notes of
        :func:`estimate_orientation`.
    frequencies : ndarray, shape (nf,)
        Frequencies of all input bins in Hz.
    per_bin : ndarray, shape (nf, 3)
        Per-bin estimates (θx, θy, θz) in rad; ``nan`` for bins not analysed.
    weights : ndarray, shape (nf,)
        Normalised weights of the bins in the final mean (0 for unused bins).
    peak_energy : ndarray, shape (nf,)
        Energy of the strongest angular-spectrum component per bin (units of
        ``|P̂|²``, see ``spectrum_weighting``); ``nan`` for bins not analysed.
    used : ndarray of bool, shape (nf,)
        Bins that entered the final estimate.
    reasons : tuple of str, length nf
        Why a bin was not used (``""`` for used bins).
    """

    theta_x: float
    theta_y: float
    theta_z: float
    u_theta_x: float
    u_theta_y: float
    u_theta_z: float
    frequencies: NDArray[np.float64]
    per_bin: NDArray[np.float64]
    weights: NDArray[np.float64]
    peak_energy: NDArray[np.float64]
    used: NDArray[np.bool_]
    reasons: tuple[str, ...]

    @property
    def angles(self) -> tuple[float, float, float]:
        """(θx, θy, θz) in rad."""
        return (self.theta_x, self.theta_y, self.theta_z)

    @property
    def angles_deg(self) -> tuple[float, float, float]:
        """(θx, θy, θz) in degrees."""
        tx, ty, tz = (float(np.rad2deg(a)) for a in self.angles)
        return tx, ty, tz

    @property
    def uncertainties(self) -> tuple[float, float, float]:
        """Standard uncertainties of (θx, θy, θz) in rad."""
        return (self.u_theta_x, self.u_theta_y, self.u_theta_z)

    @property
    def rotation(self) -> NDArray[np.float64]:
        """Rotation matrix R, shape (3, 3)."""
        return rotation_matrix(*self.angles)

    def pose(self, origin: ArrayLike = (0.0, 0.0, 0.0)) -> Pose:
        """The scan-plane pose with these angles and the given origin r0 (m)."""
        return Pose(self.theta_x, self.theta_y, self.theta_z,
                    tuple(np.asarray(origin, dtype=float).reshape(-1)))


# --------------------------------------------------------------------------- helpers


def _centered_axis(axis: NDArray[np.float64]) -> NDArray[np.float64]:
    """Coordinates relative to the sample ``n // 2`` (the NUFFT's zero mode)."""
    return axis - axis[axis.size // 2]


def _weight(kx: NDArray, ky: NDArray, k: float, mode: str) -> NDArray:
    """Spectral weight turning |P̂|² into |V̂|²·(ρ0 c0)² (velocity) or 1 (pressure)."""
    if mode == "pressure":
        return np.ones_like(np.asarray(kx, dtype=float))
    return np.maximum(k * k - kx * kx - ky * ky, 0.0) / (k * k)


def _peak_derivatives(field: NDArray, xc: NDArray, yc: NDArray, kx: float, ky: float):
    """Exact continuous-k DFT ``F = Σ P e^{-i kx x - i ky y}`` and its derivatives.

    Returns the 3×3 complex array ``C[a, b] = ∂^a_kx ∂^b_ky F`` (a, b ≤ 2), from one
    fused pass over the field (numba, :mod:`._orientation_numba`; no BLAS threads,
    which thrash when the bins run in threads).
    """
    from holoprobe.characterize._orientation_numba import peak_derivatives

    return peak_derivatives(field, xc, yc, float(kx), float(ky))


def _objective_and_derivatives(field, xc, yc, kx, ky, k, mode):
    """g = |F|²·w and its gradient and Hessian in (kx, ky)."""
    c = _peak_derivatives(field, xc, yc, kx, ky)
    f0, fx, fy, fxx, fxy, fyy = c[0, 0], c[1, 0], c[0, 1], c[2, 0], c[1, 1], c[0, 2]
    h = abs(f0) ** 2
    hg = 2.0 * np.array([np.real(np.conj(f0) * fx), np.real(np.conj(f0) * fy)])
    hxy = np.real(np.conj(fy) * fx + np.conj(f0) * fxy)
    hh = 2.0 * np.array([[np.real(np.conj(fx) * fx + np.conj(f0) * fxx), hxy],
                         [hxy, np.real(np.conj(fy) * fy + np.conj(f0) * fyy)]])
    if mode == "pressure":
        return h, hg, hh
    kk = k * k
    w = max(kk - kx * kx - ky * ky, 0.0) / kk
    wg = -2.0 * np.array([kx, ky]) / kk
    wh = -2.0 * np.eye(2) / kk
    g = h * w
    gg = hg * w + h * wg
    gh = hh * w + np.outer(hg, wg) + np.outer(wg, hg) + h * wh
    return g, gg, gh


def _refine_peak(field, xc, yc, kx0, ky0, k, mode, *, max_step, tol, max_iter):
    """Newton ascent of |P̂|²·w from (kx0, ky0) with exact derivatives (trust step)."""
    kvec = np.array([kx0, ky0], dtype=float)
    g, gg, gh = _objective_and_derivatives(field, xc, yc, kvec[0], kvec[1], k, mode)
    for _ in range(max_iter):
        eig = np.linalg.eigvalsh(gh)
        if np.all(eig < 0):
            step = -np.linalg.solve(gh, gg)
        else:
            norm = np.linalg.norm(gg)
            step = gg / norm * 0.5 * max_step if norm > 0 else np.zeros(2)
        length = np.linalg.norm(step)
        if length > max_step:
            step *= max_step / length
        accepted = False
        for _ in range(30):
            trial = kvec + step
            gt, ggt, ght = _objective_and_derivatives(field, xc, yc, trial[0], trial[1], k, mode)
            if gt >= g:
                accepted = True
                break
            step *= 0.5
        if not accepted:
            break
        kvec, g, gg, gh = trial, gt, ggt, ght
        if np.linalg.norm(step) < tol:
            break
    return kvec, g, gh


def _angles_from_peak(kx: float, ky: float, k: float) -> tuple[float, float]:
    """θx, θy from the strongest component (k'x = −k sin θy, k'y = k sin θx cos θy)."""
    theta_y = float(np.arcsin(np.clip(-kx / k, -1.0, 1.0)))
    theta_x = float(np.arcsin(np.clip(ky / (k * np.cos(theta_y)), -1.0, 1.0)))
    return theta_x, theta_y


def _line_points(theta_x, theta_y, theta_z, k, alphas):
    """In-plane (qx, qy) of the rotated kx = 0 / ky = 0 lines (paper eqs. rotated-points-x/-y).

    ``theta_z`` may be an array (nz,); returns arrays of shape (nz, 2·n_alpha).
    """
    theta_z = np.atleast_1d(np.asarray(theta_z, dtype=float))
    sa, ca = np.sin(alphas), np.cos(alphas)
    zeros = np.zeros_like(alphas)
    v = k * np.concatenate([np.stack([sa, zeros, ca]), np.stack([zeros, sa, ca])], axis=1)
    r_xy = rotation_matrix(theta_x, theta_y, 0.0)  # R = Rz @ (Ry @ Rx)
    cz, sz = np.cos(theta_z), np.sin(theta_z)
    # Rz^T v for every θz: (nz, 3, n)
    rzt_v = np.stack([cz[:, None] * v[0] + sz[:, None] * v[1],
                      -sz[:, None] * v[0] + cz[:, None] * v[1],
                      np.broadcast_to(v[2], (theta_z.size, v.shape[1]))], axis=1)
    q = np.einsum("ji,zjn->zin", r_xy, rzt_v)  # R^T v = (Ry Rx)^T Rz^T v
    return q[:, 0, :], q[:, 1, :]


class _LineEnergy:
    """Mean |P̂|²·w on the rotated lines for given θz (paper eq. rotation-optimization)."""

    def __init__(self, field, dx, dy, k, theta_x, theta_y, alphas, mode, eps):
        self.field = np.ascontiguousarray(field, dtype=np.complex128)
        self.dx, self.dy, self.k = dx, dy, k
        self.theta_x, self.theta_y = theta_x, theta_y
        self.alphas = alphas
        self.mode = mode
        self.plan = finufft.Plan(2, self.field.shape, eps=eps, isign=-1, nthreads=1,
                                 upsampfac=1.25)

    def __call__(self, theta_z) -> NDArray[np.float64]:
        qx, qy = _line_points(self.theta_x, self.theta_y, theta_z, self.k, self.alphas)
        self.plan.setpts(np.ascontiguousarray((qx * self.dx).ravel()),
                         np.ascontiguousarray((qy * self.dy).ravel()))
        values = self.plan.execute(self.field)
        energy = np.abs(values.reshape(qx.shape)) ** 2 * _weight(qx, qy, self.k, self.mode)
        return energy.mean(axis=1)


def _radial_window(field, grid_x, grid_y, taper):
    """Circular cosine-tapered window centred on the field's energy centroid.

    The scan's rectangular edges truncate the field and add a bright cross along
    the scan axes (θz = 0) to the angular spectrum, which pulls θz towards 0. A
    window with circular symmetry has no preferred direction. Its radius is the
    largest that fits in the scan around the centroid; the outer ``taper``
    fraction of the radius is tapered with ``sin²``.
    """
    power = np.abs(field) ** 2
    total = power.sum()
    uc = float(grid_x @ power.sum(axis=1) / total)
    vc = float(grid_y @ power.sum(axis=0) / total)
    r0 = min(uc - grid_x[0], grid_x[-1] - uc, vc - grid_y[0], grid_y[-1] - vc)
    r = np.hypot(*np.meshgrid(grid_x - uc, grid_y - vc, indexing="ij"))
    if r0 <= 0 or taper <= 0:
        return (r <= max(r0, 0.0)).astype(float)
    return np.sin(0.5 * np.pi * np.clip((r0 - r) / (taper * r0), 0.0, 1.0)) ** 2


@dataclass(frozen=True)
class _BinOptions:
    window_taper: float
    pad_factor: int
    spectrum_weighting: str
    theta_z_bounds: tuple[float, float]
    theta_z_step: float
    theta_z_xtol: float
    alpha_max: float | None
    alpha_min: float | None
    central_exclusion: float
    curve_sampling: float
    nufft_eps: float
    newton_tol: float
    newton_max_iter: int


def _analyse_bin(field, grid_x, grid_y, dx, dy, k, opt: _BinOptions):
    """Per-bin estimate: returns (θx, θy, θz, peak energy, reason)."""
    nx, ny = field.shape
    xc, yc = _centered_axis(grid_x), _centered_axis(grid_y)
    mode = opt.spectrum_weighting
    # coarse peak: zero-padded FFT (|P̂| does not depend on the phase origin)
    npx = scipy.fft.next_fast_len(opt.pad_factor * nx)
    npy = scipy.fft.next_fast_len(opt.pad_factor * ny)
    kxg = 2.0 * np.pi * np.fft.fftfreq(npx, dx)
    kyg = 2.0 * np.pi * np.fft.fftfreq(npy, dy)
    # only the rows and columns |kx|, |ky| < k can hold a propagating component: the
    # x-transform of the other columns and the energy outside are never formed
    rows, cols = np.flatnonzero(kxg**2 < k * k), np.flatnonzero(kyg**2 < k * k)
    spec = scipy.fft.fft(scipy.fft.fft(field, n=npy, axis=1, workers=1)[:, cols], n=npx,
                         axis=0, workers=1)[rows]
    kx2, ky2 = kxg[rows][:, None], kyg[cols][None, :]
    energy = np.abs(spec) ** 2 * _weight(kx2, ky2, k, mode)
    energy[kx2 ** 2 + ky2 ** 2 >= k * k] = 0.0
    if not np.any(energy > 0):
        return (np.nan, np.nan, np.nan, np.nan, "no propagating component")
    i, j = np.unravel_index(int(np.argmax(energy)), energy.shape)
    i, j = rows[i], cols[j]
    dkx, dky = kxg[1] - kxg[0], kyg[1] - kyg[0]
    step = max(abs(dkx), abs(dky))
    kpk, gpk, hess = _refine_peak(field, xc, yc, kxg[i], kyg[j], k, mode,
                                  max_step=step, tol=opt.newton_tol * step,
                                  max_iter=opt.newton_max_iter)
    if kpk[0] ** 2 + kpk[1] ** 2 >= k * k:
        return (np.nan, np.nan, np.nan, float(gpk), "peak outside the propagating disc")
    theta_x, theta_y = _angles_from_peak(kpk[0], kpk[1], k)
    tilt = float(np.arccos(np.clip(np.cos(theta_x) * np.cos(theta_y), -1.0, 1.0)))

    # integration range along the lines (paper eq. rotation-optimization)
    k_nyquist = min(np.pi / dx, np.pi / dy)
    alpha1 = float(np.arcsin(min(1.0, k_nyquist / k))) - tilt
    alpha1 = min(alpha1, np.pi / 3 if opt.alpha_max is None else opt.alpha_max)
    if opt.alpha_min is None:
        eig = np.linalg.eigvalsh(hess)
        widths = np.sqrt(np.clip(-6.0 * eig / gpk, 0.0, None)) if gpk > 0 else np.zeros(2)
        width = widths.min() if np.all(widths > 0) else min(nx * dx, ny * dy)
        alpha0 = opt.central_exclusion * 2.0 * np.pi / width / k
    else:
        alpha0 = opt.alpha_min
    if not alpha1 > alpha0:
        return (theta_x, theta_y, np.nan, float(gpk),
                "no room for the theta_z lines (alpha_min ≥ alpha_max)")
    dalpha = opt.curve_sampling * min(2.0 * np.pi / (nx * dx), 2.0 * np.pi / (ny * dy)) / k
    n_alpha = max(2, int(np.ceil((alpha1 - alpha0) / dalpha)) + 1)
    half = np.linspace(alpha0, alpha1, n_alpha)
    alphas = np.concatenate([-half[::-1], half])
    windowed = field * _radial_window(field, grid_x, grid_y, opt.window_taper)
    line_energy = _LineEnergy(windowed, dx, dy, k, theta_x, theta_y, alphas, mode,
                              opt.nufft_eps)

    lo, hi = opt.theta_z_bounds
    n_coarse = max(3, int(np.ceil((hi - lo) / opt.theta_z_step)) + 1)
    coarse = np.linspace(lo, hi, n_coarse)
    values = line_energy(coarse)
    best = int(np.argmax(values))
    if best in (0, n_coarse - 1):
        return (theta_x, theta_y, float(coarse[best]), float(gpk),
                "theta_z at the search bound")
    theta_z = _refine_maximum(line_energy, float(coarse[best - 1]), float(coarse[best + 1]),
                              opt.theta_z_xtol)
    return (theta_x, theta_y, theta_z, float(gpk), "")


_ZOOM_POINTS = 9  # θz per batched evaluation of the refinement (one NUFFT each)
_ZOOM_MAX_PASSES = 60  # the zoom narrows 4× per pass: 60 passes is 4⁻⁶⁰ of the bracket


def _refine_maximum(values: Callable[[NDArray[np.float64]], NDArray[np.float64]],
                    lo: float, hi: float, xtol: float) -> float:
    """The maximiser of a smooth function on ``[lo, hi]`` (a bracket of its maximum),
    to well within ``xtol``, from few batched evaluations.

    ``values`` takes an array of abscissae at once (the θz line energy: one type-2
    NUFFT for all of them, whose cost is its oversampled FFT of the field, not the
    points). A grid of ``_ZOOM_POINTS`` over the bracket; the bracket becomes the best
    point's neighbours (4× narrower) until the grid step h is at most ``4 xtol``; then
    the parabola through the best point and its neighbours gives the maximiser (its
    error, of order h³ times the third over the second derivative, is orders below
    ``xtol`` on a peak many steps wide). A sequential scalar search (bounded Brent to
    ``xtol``) took about 3× the NUFFTs.
    """
    for _ in range(_ZOOM_MAX_PASSES):  # 4× narrower per pass: far below any xtol > 0
        t = np.linspace(lo, hi, _ZOOM_POINTS)
        v = values(t)
        j = min(max(int(np.argmax(v)), 1), _ZOOM_POINTS - 2)
        h = t[1] - t[0]
        if h <= 4.0 * xtol:
            y0, y1, y2 = v[j - 1:j + 2]
            curvature = y0 - 2.0 * y1 + y2
            shift = 0.5 * (y0 - y2) / curvature if curvature < 0 else 0.0
            return float(t[j] + h * min(max(shift, -1.0), 1.0))
        lo, hi = float(t[j - 1]), float(t[j + 1])
    return float(t[j])


# --------------------------------------------------------------------------- public API


def estimate_orientation(
    spectrum: ArrayLike,
    grid: PlaneGrid,
    frequencies: ArrayLike,
    medium: Medium | None = None,
    *,
    band: tuple[float, float] | None = None,
    energy_threshold: float = 0.01,
    weights: str | ArrayLike = "energy",
    spectrum_weighting: str = "velocity",
    theta_z_bounds_deg: tuple[float, float] = (-5.0, 5.0),
    theta_z_step_deg: float = 0.5,
    theta_z_xtol: float = 1e-5,
    theta_z_window_taper: float = 0.2,
    alpha_max: float | None = None,
    alpha_min: float | None = None,
    central_exclusion: float = 2.0,
    curve_sampling: float = 0.5,
    pad_factor: int = 2,
    max_tilt: float = np.pi / 6,
    outlier_threshold: float = 5.0,
    min_spread: float = 3e-4,
    nufft_eps: float = 1e-5,
    newton_tol: float = 1e-7,
    newton_max_iter: int = 50,
    workers: int | None = None,
) -> OrientationResult:
    """Estimate the scan-plane orientation (θx, θy, θz) from its angular spectrum.

    Implements paper section II D: θx, θy from the strongest angular-spectrum
    component, θz by maximising the energy on the rotated ``kx = 0`` / ``ky = 0``
    lines (paper eqs. rotated-points-x, rotated-points-y, rotation-optimization),
    per frequency bin with signal, combined over the bins robustly.

    Parameters
    ----------
    spectrum : array_like, complex, shape (nx, ny, nf)
        Pressure on the scan plane per frequency bin, holoprobe's convention
        ``P = conj(FFT_t p)`` (any scale; Pa·s for a continuous transform).
    grid : PlaneGrid
        The scan grid (in-plane coordinates x, y in m; its pose is not used).
    frequencies : array_like, shape (nf,)
        Frequencies of the bins in Hz, all > 0 (drop the DC bin).
    medium : Medium, optional
        Propagation medium (default water at 20 °C).
    band : (float, float), optional
        Only bins with ``band[0] ≤ f ≤ band[1]`` (Hz) are considered.
    energy_threshold : float
        A bin is analysed when its energy ``Σ|P|²`` over the plane is at least this
        fraction of the largest bin energy (default 0.01, i.e. −20 dB).
    weights : {"energy", "uniform"} or array_like, shape (nf,)
        Weights of the per-bin estimates: the energy of the strongest component
        (default), equal, or user-given non-negative weights.
    spectrum_weighting : {"velocity", "pressure"}
        Quantity whose angular spectrum is searched. ``"velocity"`` (default) uses
        ``|P̂|²·(k² − κ²)/k²``, the normal-velocity spectrum ``|V̂|²(ρ0c0)²``, whose
        magnitude does not change when the plane is tilted (``V̂' = kz'/(kρ0c0)·P̂'``
        and ``dκ/dκ' = kz/kz'``), so its peak lies exactly at ``k R[2, :2]`` for a
        source whose velocity spectrum peaks at κ = 0. ``"pressure"`` uses ``|P̂|²``
        like the paper; its peak is pulled by the Jacobian ``kz/kz'`` (a few
        thousandths of a degree at 9° tilt).
    theta_z_bounds_deg : (float, float)
        Search interval for θz in degrees (user boundary, default ±5°). A bin whose
        maximum lies on a bound is rejected.
    theta_z_step_deg : float
        Step of the coarse θz scan in degrees before the continuous refinement.
    theta_z_xtol : float
        Absolute tolerance in rad of the refinement of θz (the batched zoom of
        :func:`_refine_maximum` ends at a grid step ≤ 4 × this, then a parabola).
    theta_z_window_taper : float
        The θz step works on the field times a circular window (centred on the
        field's energy centroid, the largest radius that fits in the scan) whose
        outer ``theta_z_window_taper`` fraction of the radius is tapered (default
        0.2). The scan's rectangular edges would otherwise add a bright cross along
        the scan axes to the spectrum and pull θz towards 0 (0.27° on the paper's
        angle demo).
    alpha_max : float, optional
        Upper limit α1 (rad) of the polar angle along the lines. Default: π/3, and
        never beyond ``asin(κ_Nyquist/k) − tilt`` so that the rotated lines stay
        inside the sampled (alias-free) part of the spectrum and below the
        evanescent limit.
    alpha_min : float, optional
        Lower limit (rad): the neighbourhood of the central peak where the lines
        cross (and which does not depend on θz) is excluded. Default:
        ``central_exclusion · 2π / (k W)`` with W the narrower main-lobe width
        measured from the curvature of the peak (``W = sqrt(−6 λ/g)``, exact for a
        sinc² lobe of a rectangle of width W).
    central_exclusion : float
        Radius of the excluded centre in main-lobe half-widths ``2π/W`` (default 2).
    curve_sampling : float
        Step along the lines as a fraction of the scan's native spectral step
        ``2π/(n d)`` (default 0.5).
    pad_factor : int
        Zero-padding factor of the FFT that gives the coarse peak (default 2; the
        padded size is rounded up to a fast FFT length).
    max_tilt : float
        Bins whose strongest component implies a tilt ``acos(cos θx cos θy)``
        larger than this (rad, default π/6) are rejected as "peak far from the
        centre" (a spurious mode or noise).
    outlier_threshold : float
        A bin is an outlier when one of its angles lies more than this many robust
        spreads from the median of all analysed bins (default 5).
    min_spread : float
        Floor (rad) of the robust spread, so that near-identical per-bin estimates
        on noise-free data do not turn small differences into outliers
        (default 3e-4 rad ≈ 0.017°).
    nufft_eps : float
        Relative accuracy of the NUFFT that evaluates the spectrum on the lines
        (default 1e-5: on the full-size P4-1 scan θz moves by 1e-8° from 1e-7's, per
        bin by ≤ 5e-6°, for 10 % less CPU of the orientation step).
    newton_tol : float
        Stop the peak refinement when the step is below this fraction of the
        padded spectral step.
    newton_max_iter : int
        Maximum Newton iterations of the peak refinement.
    workers : int, optional
        Threads over the frequency bins (default: the cores available).

    Returns
    -------
    OrientationResult
        Angles (rad), standard uncertainties, and the per-bin record.

    Raises
    ------
    InputError
        Shapes that do not match ``grid``/``frequencies``, non-finite data,
        frequencies ≤ 0, bad options.
    FitError
        No bin with signal, or no bin gave an estimate.

    Notes
    -----
    Per bin: a zero-padded FFT gives the coarse peak of the angular spectrum
    (propagating part only); Newton steps on the exact continuous-k DFT
    ``P̂(kx, ky) = Σ P(x_i, y_j) e^{−i kx x_i − i ky y_j}`` (two matrix products,
    analytic gradient and Hessian) refine it to the true maximum; then
    ``θy = asin(−k'x/k)``, ``θx = asin(k'y/(k cos θy))``. θz maximises the mean
    energy of the spectrum at the points ``R(θz)^T (k sin α, 0, k cos α)`` and
    ``R(θz)^T (0, k sin α, k cos α)``, ``α_min ≤ |α| ≤ α1``, evaluated exactly
    (type-2 NUFFT) for a coarse scan, then zoomed grids of θz (one NUFFT each) and a
    parabola through the best three.

    Bins are combined by their weighted mean after rejecting outliers: the robust
    centre is the median of the per-bin estimates, the spread ``1.4826·MAD``
    (floored at ``min_spread``). The standard uncertainty of each angle is
    ``u = s·sqrt(Σ w_i²)`` with normalised weights ``w_i`` and the weighted
    scatter ``s² = Σ w_i (θ_i − θ̄)² / (1 − Σ w_i²)``, i.e. the standard error of
    a weighted mean of independent bins. Neighbouring bins are not independent
    for a short record (their errors correlate), so ``u`` describes the random
    part only.

    References
    ----------
    Blanken, Versluis, Lajoinie, *Characterization and virtualization of a medical
    ultrasound transducer*, section II D.

    Examples
    --------
    >>> result = estimate_orientation(P, grid, freqs)  # doctest: +SKIP
    >>> result.angles_deg, result.pose(origin=(0.0, 0.0, 3.5e-3))  # doctest: +SKIP
    """
    medium = Medium() if medium is None else medium
    if not isinstance(grid, PlaneGrid):
        raise InputError("expected a holoprobe.PlaneGrid", field="grid")
    if not (np.isfinite(theta_z_xtol) and theta_z_xtol > 0):
        raise InputError(f"expected a tolerance > 0 rad, got {theta_z_xtol!r}",
                         field="theta_z_xtol")
    spectrum = np.asarray(spectrum)
    frequencies = np.array(frequencies, dtype=float)
    lo_deg, hi_deg, user_weights = _check_inputs(
        spectrum, frequencies, grid, spectrum_weighting, theta_z_bounds_deg, theta_z_step_deg,
        energy_threshold, pad_factor, weights)
    nf = frequencies.size
    selected, reasons = _select_bins(spectrum, frequencies, band, energy_threshold)
    opt = _BinOptions(
        window_taper=float(theta_z_window_taper),
        pad_factor=int(pad_factor), spectrum_weighting=spectrum_weighting,
        theta_z_bounds=(np.deg2rad(lo_deg), np.deg2rad(hi_deg)),
        theta_z_step=float(np.deg2rad(theta_z_step_deg)), theta_z_xtol=float(theta_z_xtol),
        alpha_max=alpha_max, alpha_min=alpha_min, central_exclusion=float(central_exclusion),
        curve_sampling=float(curve_sampling), nufft_eps=float(nufft_eps),
        newton_tol=float(newton_tol), newton_max_iter=int(newton_max_iter))
    dx, dy = grid.dx, grid.dy
    ks = medium.wavenumber(frequencies)

    def run(i: int):
        field = np.ascontiguousarray(spectrum[:, :, i], dtype=np.complex128)
        return _analyse_bin(field, grid.x, grid.y, dx, dy, float(ks[i]), opt)

    n_workers = _default_workers() if workers is None else max(1, int(workers))
    if n_workers > 1 and selected.size > 1:
        with Threads(n_workers) as threads:
            results = threads.map(run, selected)
    else:
        results = [run(int(i)) for i in selected]

    per_bin = np.full((nf, 3), np.nan)
    peak_energy = np.full(nf, np.nan)
    analysed = np.zeros(nf, dtype=bool)
    for i, (tx, ty, tz, g, reason) in zip(selected, results, strict=True):
        per_bin[i] = (tx, ty, tz)
        peak_energy[i] = g
        reasons[i] = reason
        if reason:
            continue
        if np.arccos(np.clip(np.cos(tx) * np.cos(ty), -1.0, 1.0)) > max_tilt:
            reasons[i] = "peak far from the centre (tilt above max_tilt)"
            continue
        analysed[i] = True

    used = _reject_outliers(per_bin, analysed, reasons, len(selected), min_spread,
                            outlier_threshold)
    raw = peak_energy if user_weights is None and weights == "energy" else (
        np.ones(nf) if user_weights is None else user_weights)
    angles, unc, w = _weighted_mean(per_bin, used, raw)
    for a in per_bin, w, peak_energy, used, frequencies:
        a.setflags(write=False)
    return OrientationResult(
        theta_x=float(angles[0]), theta_y=float(angles[1]), theta_z=float(angles[2]),
        u_theta_x=float(unc[0]), u_theta_y=float(unc[1]), u_theta_z=float(unc[2]),
        frequencies=frequencies,
        per_bin=per_bin, weights=w, peak_energy=peak_energy, used=used,
        reasons=tuple(reasons))


def _check_inputs(spectrum: NDArray, frequencies: NDArray, grid: PlaneGrid,
                  spectrum_weighting: str, theta_z_bounds_deg: tuple[float, float],
                  theta_z_step_deg: float, energy_threshold: float, pad_factor: int,
                  weights: str | ArrayLike) -> tuple[float, float, NDArray | None]:
    """InputError for any argument of :func:`estimate_orientation` that is wrong; the θz
    bounds in degrees and the user's weights (None for ``"energy"``/``"uniform"``)."""
    nx, ny = grid.shape
    if frequencies.ndim != 1 or frequencies.size == 0:
        raise InputError(f"expected a non-empty 1-D array of frequencies in Hz, got shape "
                         f"{frequencies.shape}", field="frequencies")
    nf = frequencies.size
    if spectrum.shape != (nx, ny, nf):
        raise InputError(f"expected shape (nx, ny, nf) = ({nx}, {ny}, {nf}) from the grid and "
                         f"the frequencies, got {spectrum.shape}", field="spectrum")
    if nx < 4 or ny < 4:
        raise InputError(f"expected at least 4 × 4 scan points, got {nx} × {ny}", field="grid")
    if not np.all(np.isfinite(frequencies)) or np.any(frequencies <= 0):
        raise InputError("expected finite frequencies > 0 Hz (drop the DC bin)",
                         field="frequencies")
    if not np.all(np.isfinite(spectrum)):
        raise InputError("contains NaN or inf", field="spectrum")
    if spectrum_weighting not in ("velocity", "pressure"):
        raise InputError(f"expected 'velocity' or 'pressure', got {spectrum_weighting!r}",
                         field="spectrum_weighting")
    lo_deg, hi_deg = (float(v) for v in theta_z_bounds_deg)
    if not (np.isfinite(lo_deg) and np.isfinite(hi_deg) and lo_deg < hi_deg):
        raise InputError(f"expected (low, high) with low < high, got {theta_z_bounds_deg!r}",
                         field="theta_z_bounds_deg")
    if not theta_z_step_deg > 0:
        raise InputError("expected a positive step in degrees", field="theta_z_step_deg")
    if not 0 < energy_threshold <= 1:
        raise InputError(f"expected a fraction in (0, 1], got {energy_threshold!r}",
                         field="energy_threshold")
    if int(pad_factor) < 1:
        raise InputError("expected an integer ≥ 1", field="pad_factor")
    if isinstance(weights, str):
        if weights not in ("energy", "uniform"):
            raise InputError(f"expected 'energy', 'uniform' or an array, got {weights!r}",
                             field="weights")
        user_weights = None
    else:
        user_weights = np.asarray(weights, dtype=float)
        if user_weights.shape != (nf,) or not np.all(np.isfinite(user_weights)) \
                or np.any(user_weights < 0):
            raise InputError(f"expected {nf} finite non-negative weights, got shape "
                             f"{user_weights.shape}", field="weights")

    return lo_deg, hi_deg, user_weights


def _select_bins(spectrum: NDArray, frequencies: NDArray, band: tuple[float, float] | None,
                 energy_threshold: float) -> tuple[NDArray[np.intp], list[str]]:
    """The bins with signal (inside ``band``, energy ≥ threshold × the strongest), and
    for every bin the reason it was left out (``""`` when selected)."""
    nf = frequencies.size
    energy = bin_energy(spectrum)
    reasons = [""] * nf
    candidate = np.ones(nf, dtype=bool)
    if band is not None:
        f_lo, f_hi = (float(v) for v in band)
        outside = (frequencies < f_lo) | (frequencies > f_hi)
        for i in np.flatnonzero(outside):
            reasons[i] = "outside band"
        candidate &= ~outside
    if not np.any(candidate) or not np.max(energy[candidate]) > 0:
        raise FitError("no frequency bin with signal (all zero or outside the band)",
                         field="spectrum")
    threshold = energy_threshold * np.max(energy[candidate])
    weak = candidate & (energy < threshold)
    for i in np.flatnonzero(weak):
        reasons[i] = "energy below threshold"
    candidate &= ~weak
    selected = np.flatnonzero(candidate)

    return selected, reasons


def _reject_outliers(per_bin: NDArray, analysed: NDArray, reasons: list[str], n_selected: int,
                     min_spread: NDArray | float, outlier_threshold: float) -> NDArray:
    """Robust outlier rejection (median and MAD of the per-bin estimates); fills
    ``reasons``; returns the bins used."""
    nf = per_bin.shape[0]
    idx = np.flatnonzero(analysed)
    if idx.size == 0:
        raise FitError("no frequency bin gave an orientation estimate "
                         f"({n_selected} bins with signal analysed)", field="spectrum")
    est = per_bin[idx]
    centre = np.median(est, axis=0)
    spread = np.maximum(mad_sigma(est, axis=0), min_spread)
    score = np.abs(est - centre) / spread
    for n, i in enumerate(idx):
        if np.any(score[n] > outlier_threshold):
            worst = "xyz"[int(np.argmax(score[n]))]
            reasons[i] = (f"outlier: theta_{worst} {score[n].max():.1f} robust spreads "
                          "from the median")
    return np.array([analysed[i] and not reasons[i] for i in range(nf)])


def _weighted_mean(per_bin: NDArray, used: NDArray, raw: NDArray
                   ) -> tuple[NDArray, NDArray, NDArray]:
    """Weighted mean angles of the used bins, their standard uncertainties (weighted
    scatter) and the normalised weights."""
    w = np.where(used, raw, 0.0)
    w = np.where(np.isfinite(w), w, 0.0)
    if not w.sum() > 0:
        raise FitError("all usable bins have zero weight", field="weights")
    w = w / w.sum()
    angles = np.einsum("f,fa->a", w, np.where(used[:, None], per_bin, 0.0))
    sum_w2 = float(np.sum(w ** 2))
    if used.sum() >= 2 and sum_w2 < 1.0:
        resid = np.where(used[:, None], per_bin - angles, 0.0)
        scatter = np.einsum("f,fa->a", w, resid ** 2) / (1.0 - sum_w2)
        unc = np.sqrt(scatter * sum_w2)
    else:
        unc = np.full(3, np.nan)
    return angles, unc, w
