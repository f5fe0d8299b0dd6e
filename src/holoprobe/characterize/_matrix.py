"""Element map of a 2-D matrix array from its back-projected surface velocity (issue 16).

The back-projected normal velocity ``V(x, y; f)`` on z = 0 carries the propagating part
of the source, ``|k| < k``, of which a scan of finite size keeps only the waves that
stay inside its footprint. In the angular spectrum ``V̂(k) = ∫ V e^{−i k·r} dr`` an
``n_x × n_y`` lattice of rectangular elements (centre ``r_c``, lattice vectors
``a₁ = p_x (cos θ, sin θ)``, ``a₂ = p_y (−sin θ, cos θ)``) is

    V̂(k; f) = S(k) Σ_e c_e(f) e^{−i k·r_e},     S(k) = w h sinc(k'_x w/2π) sinc(k'_y h/2π) D(k)

with ``k'`` the wave vector in the lattice frame and ``D = exp(−i (k_z − k) δ)`` the
defocus between z = 0 and the array face, which lies δ in front of it (towards the scan;
δ > 0 when the transmit pipeline's onset convention puts z = 0 behind the face, as for
1-D arrays in :mod:`._elements`). The fit uses the bins of ``V̂`` inside
``|k| < k sin θ_c``, the largest angle that every point of the aperture keeps inside the
scan footprint. On a regular lattice the normal matrix ``BᴴB`` depends only on index
differences (block-Toeplitz): one small matrix product per bin gives it, and ``Bᴴ V̂``
another (separable exponentials); it is factorised densely (Cholesky, ≤ 2500 elements)
or inverted by FFT-preconditioned conjugate gradients.

For fixed ``(x_c, y_c, θ, δ)`` the coefficients follow per bin by ridge-regularised
least squares; the non-linear parameters are refined by Gauss–Newton steps of the
variable-projection problem (Kaufman's Jacobian: the derivative of the model projected
off what the coefficients can absorb). Holding the coefficients instead (alternating
steps) leaves δ short, because each element's coefficients absorb most of a defocus
change: on the 32 × 32 twin δ stopped 35 µm off and the amplitudes took a bias
proportional to the element delays (0.24 %/ns). δ starts from a coarse search. Each
element's coefficients are then ``A_e U(f) e^{iωτ_e}`` (relative amplitude, delay;
:func:`._elements._amplitudes_and_delays`, the 1-D rule), each bin weighted by the
element's own noise gain (the diagonal of ``(BᴴB + ridge)⁻¹ BᴴB (BᴴB + ridge)⁻¹``, larger
at the lattice's edges and corners). The amplitudes are then refitted to all the bins at
once with those delays held (:func:`_joint_amplitudes`, dense path): one real amplitude
per element across the band separates neighbours better than any single bin.

The twin (:meth:`holoprobe.simulate.ArrayModel.matrix`) integrates its exact rectangles
with Gauss–Legendre cells and a dense Rayleigh sum, this estimator uses the analytic
rectangle spectrum and the angular spectrum: different discretisations.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.characterize._aperture_bias import SpectrumModel, window_round_trip
from holoprobe.characterize._elements import ElementMap, _amplitudes_and_delays
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import ArrayGeometry, PlaneGrid
from holoprobe.signal import blas_threads

__all__ = [
    "MatrixElementMap",
    "fit_matrix_map",
    "lattice_aperture",
    "lattice_pose_correction",
    "lattice_pose_uncertainty",
    "lattice_spectrum",
    "matrix_aperture",
    "matrix_capture_angle",
    "matrix_map_options",
    "matrix_window_bias",
    "remove_lattice_bias",
]


@dataclass(frozen=True)
class MatrixElementMap(ElementMap):
    """An :class:`ElementMap` of a 2-D matrix array (element order of its geometry:
    ``iy·n_x + ix``, x fastest).

    Beyond :class:`ElementMap`, whose ``center_x``, ``pitch`` and ``element_width`` are
    the x values, it holds the attributes below.

    Attributes
    ----------
    center_y : float
        Lattice centre y on the source frame (m).
    pitch_y, element_height : float
        m.
    rotation : float
        Rotation (rad, about +z, from x towards y) of the lattice on the source frame:
        the residual θz of the scan-plane orientation.
    grid_shape : (int, int)
        ``(n_x, n_y)``.
    grid_position : ndarray of int, shape (N, 2)
        ``(ix, iy)`` of every element.
    positions : ndarray, shape (N, 2)
        Element centres on the source frame (m).
    max_angle : float
        The capture angle θ_c (rad) the fit used.
    rotation_uncertainty : float
        Standard uncertainty of ``rotation`` (rad) from the Gauss–Newton normal matrix
        and the misfit of the non-linear fit.
    pitch_uncertainty, pitch_y_uncertainty, width_uncertainty, height_uncertainty : float
        Standard uncertainties (m) of ``pitch``, ``pitch_y``, ``element_width`` and
        ``element_height`` (same origin; 0 where they were not fitted but taken from the
        file).
    focus_offset_uncertainty : float
        Standard uncertainty (m) of ``focus_offset`` δ (same origin; NaN when unknown).
        δ places the array face: it lies δ in front of the back-projection plane z = 0,
        whose distance from the scan is the onset convention's z0 (the transmit IR's
        onset delay, ≈ c0 × 0.4 µs on the 3 MHz twins, is in z0, not in δ's plane).
    """

    center_y: float = 0.0
    pitch_y: float = float("nan")
    element_height: float = float("nan")
    rotation: float = 0.0
    grid_shape: tuple[int, int] = (0, 0)
    grid_position: NDArray[np.int64] | None = None
    positions: NDArray[np.float64] | None = None
    max_angle: float = float("nan")
    rotation_uncertainty: float = float("nan")
    pitch_uncertainty: float = 0.0
    pitch_y_uncertainty: float = 0.0
    width_uncertainty: float = 0.0
    height_uncertainty: float = 0.0
    focus_offset_uncertainty: float = float("nan")

    @property
    def active_width(self) -> float:
        """Outer-edge x extent (m) of the non-dead elements."""
        return self._extent(0, self.pitch, self.element_width)

    @property
    def active_height(self) -> float:
        """Outer-edge y extent (m) of the non-dead elements."""
        return self._extent(1, self.pitch_y, self.element_height)

    def _extent(self, axis: int, pitch: float, size: float) -> float:
        if self.grid_position is None:
            return float("nan")
        alive = np.setdiff1d(np.arange(self.count), self.dead)
        if alive.size == 0:
            return 0.0
        idx = self.grid_position[alive, axis]
        return float((idx.max() - idx.min()) * pitch + size)

    @property
    def layout(self) -> str:
        """``"sparse"`` when the map holds fewer elements than its grid's positions,
        else ``"full"``."""
        nx, ny = self.grid_shape
        return "sparse" if self.count < nx * ny else "full"

    def amplitude_grid(self) -> NDArray[np.float64]:
        """Relative amplitudes on the grid, shape (n_y, n_x) (NaN where no element)."""
        out = np.full(self.grid_shape[::-1], np.nan)
        if self.grid_position is not None:
            out[self.grid_position[:, 1], self.grid_position[:, 0]] = self.relative_amplitude
        return out


@dataclass(frozen=True)
class _Lattice:
    """Element lattice on the source frame and the k-space samples of one bin."""

    grid_position: NDArray[np.int64]   # (N, 2) ix, iy
    shape: tuple[int, int]             # n_x, n_y
    pitch: tuple[float, float]
    size: tuple[float, float]          # element width, height

    @functools.cached_property
    def offset_index(self) -> NDArray[np.intp]:
        """(N, N) flat index of ``(ix − ix', iy − iy')`` into a (2n_x−1, 2n_y−1) table."""
        ix, iy = self.grid_position[:, 0], self.grid_position[:, 1]
        nx, ny = self.shape
        return ((ix[:, None] - ix[None, :] + nx - 1) * (2 * ny - 1)
                + (iy[:, None] - iy[None, :] + ny - 1))

    def centred(self) -> tuple[NDArray, NDArray]:
        """``u = ix − (n_x − 1)/2``, ``v = iy − (n_y − 1)/2`` per element."""
        nx, ny = self.shape
        return (self.grid_position[:, 0] - 0.5 * (nx - 1),
                self.grid_position[:, 1] - 0.5 * (ny - 1))


@dataclass
class _Bin:
    """The masked angular-spectrum samples of one frequency bin."""

    kx: NDArray[np.float64]
    ky: NDArray[np.float64]
    kz_minus_k: NDArray[np.float64]
    data: NDArray[np.complex128]
    frequency: float


def _bins(velocity: NDArray, grid: PlaneGrid, frequencies: NDArray, sound_speed: float,
          max_angle: float) -> list[_Bin]:
    """``V̂(k)`` of each bin on the FFT grid of the source plane, inside the capture disc.

    (Weighting data and model by ``k/k_z``, which whitens the scan noise in ``V̂``, was
    tried on the 32 × 32 twin: no less noise in the amplitudes, twice the model error.)"""
    nx, ny = grid.shape
    dx, dy = grid.dx, grid.dy
    kx = 2 * np.pi * np.fft.fftfreq(nx, dx)
    ky = 2 * np.pi * np.fft.fftfreq(ny, dy)
    kxx, kyy = np.meshgrid(kx, ky, indexing="ij")
    kr = np.hypot(kxx, kyy)
    spectra = np.fft.fft2(np.asarray(velocity), axes=(0, 1)) * (dx * dy)
    # origin of the grid: V̂(k) = e^{−i k·r0} dx dy FFT
    shift = np.exp(-1j * (kxx * grid.x[0] + kyy * grid.y[0]))
    out = []
    for j, f in enumerate(frequencies):
        k = 2 * np.pi * f / sound_speed
        mask = kr < k * np.sin(max_angle)
        kz = np.sqrt(np.maximum(k**2 - kr[mask] ** 2, 0.0))
        out.append(_Bin(kxx[mask], kyy[mask], kz - k, spectra[:, :, j][mask] * shift[mask],
                        float(f)))
    return out


def _phases(b: _Bin, lat: _Lattice, params: NDArray) -> tuple[NDArray, NDArray, NDArray,
                                                                NDArray]:
    """``S(k)``, ``φ₁ = k·a₁``, ``φ₂ = k·a₂`` and ``φ₀ = k·r_(0,0)`` of one bin."""
    xc, yc, theta, delta, sx, sy, sw, sh = params
    px, py = lat.pitch[0] * (1.0 + sx), lat.pitch[1] * (1.0 + sy)
    w, h = lat.size[0] * (1.0 + sw), lat.size[1] * (1.0 + sh)
    kxl, kyl = _lattice_frame(b, theta)
    shape = w * h * np.sinc(kxl * w / (2 * np.pi)) * np.sinc(kyl * h / (2 * np.pi))
    shape = shape * np.exp(-1j * b.kz_minus_k * delta)
    phi1 = px * kxl
    phi2 = py * kyl
    nx, ny = lat.shape
    phi0 = b.kx * xc + b.ky * yc - 0.5 * (nx - 1) * phi1 - 0.5 * (ny - 1) * phi2
    return shape, phi1, phi2, phi0


def _lattice_frame(b: _Bin, theta: float) -> tuple[NDArray, NDArray]:
    """The bin's wave vectors in the lattice frame (turned by −θ)."""
    c, s = np.cos(theta), np.sin(theta)
    return c * b.kx + s * b.ky, -s * b.kx + c * b.ky


def _size_derivatives(b: _Bin, lat: _Lattice, params: NDArray) -> tuple[NDArray, NDArray]:
    """``∂ ln S / ∂s_w`` and ``∂ ln S / ∂s_h`` (element width ``w₀(1 + s_w)``, height
    ``h₀(1 + s_h)``): ``∂_w [sin(k'_x w/2)/(k'_x/2)] = cos(k'_x w/2)``."""
    kxl, kyl = _lattice_frame(b, params[2])
    out = []
    for kl, size0, scale in ((kxl, lat.size[0], params[6]), (kyl, lat.size[1], params[7])):
        size = size0 * (1.0 + scale)
        out.append(size0 * np.cos(0.5 * kl * size) / (size * np.sinc(kl * size / (2 * np.pi))))
    return out[0], out[1]


def _powers(phase: NDArray, n: int) -> NDArray[np.complex128]:
    """``e^{i m φ}`` for m = 0 … n−1, shape (n, len(φ)) (by repeated products)."""
    out = np.empty((n, phase.size), complex)
    out[0] = 1.0
    if n > 1:
        out[1] = np.exp(1j * phase)
        for m in range(2, n):
            np.multiply(out[m - 1], out[1], out=out[m])
    return out


def _pcg(toeplitz: NDArray, rhs: NDArray, mask: NDArray[np.bool_], ridge: float, *,
         tol: float = 1e-7, max_iter: int = 500) -> tuple[NDArray, float]:
    """Solve ``(A + ridge) c = rhs`` on the elements of ``mask`` (shape (n_x, n_y)),
    ``A`` block-Toeplitz with ``A[e, e'] = toeplitz[ix − ix', iy − iy']``, by conjugate
    gradients: products by FFT on a (2n_x, 2n_y) circulant embedding, preconditioned by
    that circulant's inverse. Returns the solution (zero off the mask) and the noise
    gain ``⟨Λ/(Λ + ridge)²⟩`` of the circulant approximation (the diagonal of
    ``(A + ridge)⁻¹ A (A + ridge)⁻¹`` away from the edges)."""
    nx, ny = mask.shape
    mx, my = 2 * nx, 2 * ny
    spec, lam = _circulant(toeplitz, mask.shape)

    def embed(x: NDArray) -> NDArray:
        pad = np.zeros((mx, my), complex)
        pad[:nx, :ny] = x
        return np.fft.fft2(pad)

    def matvec(x: NDArray) -> NDArray:
        return (np.fft.ifft2(embed(x) * spec)[:nx, :ny] + ridge * x) * mask

    def precondition(r: NDArray) -> NDArray:
        return np.fft.ifft2(embed(r) / (lam + ridge))[:nx, :ny] * mask

    x = np.zeros((nx, ny), complex)
    r = rhs * mask
    z = precondition(r)
    p = z.copy()
    rz = np.vdot(r, z)
    norm = max(float(np.linalg.norm(r)), 1e-300)
    for _ in range(max_iter):
        q = matvec(p)
        alpha = rz / np.vdot(p, q)
        x += alpha * p
        r -= alpha * q
        if float(np.linalg.norm(r)) < tol * norm:
            break
        z = precondition(r)
        rz_new = np.vdot(r, z)
        p = z + (rz_new / rz) * p
        rz = rz_new
    return x, float(np.mean(lam / (lam + ridge) ** 2))


def _circulant(toeplitz: NDArray, shape: tuple[int, int]) -> tuple[NDArray, NDArray]:
    """Spectrum of the (2n_x, 2n_y) circulant embedding of the block-Toeplitz normal
    matrix, and its eigenvalues clipped at 0."""
    nx, ny = shape
    mx, my = 2 * nx, 2 * ny
    kern = np.zeros((mx, my), complex)
    kern[np.ix_(np.arange(-(nx - 1), nx) % mx, np.arange(-(ny - 1), ny) % my)] = toeplitz
    spec = np.fft.fft2(kern)
    return spec, np.maximum(spec.real, 0.0)


_DENSE_MAX = 2500
"""Arrays of at most this many elements are solved by a dense Cholesky factorisation of
the normal matrix (exact, ≈ 0.05 s for 1024 elements); larger ones by :func:`_pcg`."""


def _dense_normal(toeplitz: NDArray, lat: _Lattice, ridge: float) -> NDArray:
    """The dense ``BᴴB + ridge`` over the lattice's elements (real when the k samples
    are symmetric about 0, as on the FFT grid inside a disc)."""
    scale = float(np.abs(toeplitz).max())
    t = toeplitz.real if np.abs(toeplitz.imag).max() <= 1e-9 * scale else toeplitz
    normal = np.ascontiguousarray(t).ravel().take(lat.offset_index)
    normal[np.diag_indices_from(normal)] += ridge
    return normal


class _Normal:
    """``(BᴴB + ridge)⁻¹`` of one bin: dense Cholesky (≤ :data:`_DENSE_MAX` elements)
    or FFT-preconditioned conjugate gradients on the grid."""

    def __init__(self, toeplitz: NDArray, lat: _Lattice, ridge: float) -> None:
        self.toeplitz, self.lat, self.ridge = toeplitz, lat, ridge
        self.mask = np.zeros(lat.shape, bool)
        self.mask[lat.grid_position[:, 0], lat.grid_position[:, 1]] = True
        self.factor = None
        if lat.grid_position.shape[0] <= _DENSE_MAX:
            from scipy.linalg import cho_factor  # lazy: start-up time

            self.normal = _dense_normal(toeplitz, lat, ridge)
            self.factor = cho_factor(self.normal, check_finite=False)

    def solve(self, rhs_grid: NDArray) -> tuple[NDArray, float]:
        """Coefficients (N,) for ``Bᴴx`` given on the (n_x, n_y) grid, and the mean noise
        gain of the circulant approximation (:func:`_pcg`; NaN on the dense path)."""
        ix, iy = self.lat.grid_position[:, 0], self.lat.grid_position[:, 1]
        if self.factor is None:
            grid, gain = _pcg(self.toeplitz, rhs_grid, self.mask, self.ridge)
            return grid[ix, iy], gain
        from scipy.linalg import cho_solve

        rhs = rhs_grid[ix, iy]
        if np.isrealobj(self.normal):  # real factor, complex right-hand side
            sol = cho_solve(self.factor, np.stack([rhs.real, rhs.imag], axis=1),
                            check_finite=False)
            return sol[:, 0] + 1j * sol[:, 1], float("nan")
        return cho_solve(self.factor, rhs, check_finite=False), float("nan")

    def noise_gain(self) -> NDArray[np.float64]:
        """Per-element noise gain: the diagonal of ``(A + ridge)⁻¹ A (A + ridge)⁻¹``
        (``A = BᴴB``), in units of the noise power per k sample."""
        if self.factor is None:  # the circulant approximation's mean (as _pcg)
            _, lam = _circulant(self.toeplitz, self.lat.shape)
            gain = float(np.mean(lam / (lam + self.ridge) ** 2))
            return np.full(self.lat.grid_position.shape[0], gain)
        from scipy.linalg import lapack

        upper, lower = self.factor
        potri = lapack.dpotri if np.isrealobj(upper) else lapack.zpotri
        half, info = potri(upper, lower=lower)
        if info != 0:
            raise FitError(f"the element normal matrix is singular (potri info {info})",
                           field="ridge")
        half = np.tril(half) if lower else np.triu(half)
        inverse = half + half.conj().T
        inverse[np.diag_indices_from(inverse)] *= 0.5
        # M⁻¹ A M⁻¹ = M⁻¹ − ridge M⁻²; diag(M⁻²) = Σ |M⁻¹|² by rows (M Hermitian)
        return np.real(np.diag(inverse)) - self.ridge * np.sum(np.abs(inverse) ** 2, axis=1)


@dataclass
class _Solve:
    """One bin's ridge least-squares solve and what the Gauss–Newton step reuses."""

    coef: NDArray[np.complex128]      # (N,) element coefficients
    misfit: float                     # ‖V̂ − model‖²
    total: float                      # ‖V̂‖²
    gain: float                       # noise gain of the solve (see _pcg)
    shape: NDArray[np.complex128]     # S(k)
    phi0: NDArray[np.float64]
    ex: NDArray[np.complex128]
    ey: NDArray[np.complex128]
    phi1: NDArray[np.float64]
    phi2: NDArray[np.float64]
    model: NDArray[np.complex128]     # S Σ c_e e^{−i k·r_e}
    normal: _Normal                   # (BᴴB + ridge)⁻¹

    def adjoint(self, lat: _Lattice, values: NDArray) -> NDArray[np.complex128]:
        """``Bᴴ x`` on the (n_x, n_y) grid for samples ``x`` at the bin's k."""
        return (self.ex * (np.conj(self.shape) * np.exp(1j * self.phi0) * values)) \
            @ self.ey.T

    def project_out(self, lat: _Lattice, values: NDArray) -> NDArray[np.complex128]:
        """``x − B (BᴴB + ridge)⁻¹ Bᴴ x``: the part of ``x`` that no change of the
        element coefficients can fit (the variable-projection Jacobian, Kaufman's
        approximation, of the coefficients eliminated by the ridge solve)."""
        coef, _ = self.normal.solve(self.adjoint(lat, values))
        fitted = _synthesize(coef, lat, self.shape, self.phi0, self.ex, self.ey)
        return values - fitted


def _solve_bin(b: _Bin, lat: _Lattice, params: NDArray, ridge: float) -> _Solve:
    """Ridge LS coefficients of one bin at the non-linear parameters ``params``."""
    shape, phi1, phi2, phi0 = _phases(b, lat, params)
    nx, ny = lat.shape
    ex, ey = _powers(phi1, nx), _powers(phi2, ny)
    g = np.conj(shape) * np.exp(1j * phi0) * b.data
    rhs = (ex * g) @ ey.T                            # (nx, ny): Bᴴ V̂ on the grid
    w2 = np.abs(shape) ** 2
    fx = np.concatenate([np.conj(ex[:0:-1]), ex])  # e^{i m φ1}, m = −(nx−1) … nx−1
    fy = np.concatenate([np.conj(ey[:0:-1]), ey])
    toeplitz = (fx * w2) @ fy.T                    # (2nx−1, 2ny−1): BᴴB by index offset
    diagonal = float(toeplitz[nx - 1, ny - 1].real)
    if not diagonal > 0:
        raise FitError("no signal in the element normal equations", field="frequencies")
    normal = _Normal(toeplitz, lat, ridge * diagonal)
    coef, gain = normal.solve(rhs)
    total = float(np.sum(np.abs(b.data) ** 2))
    model = _synthesize(coef, lat, shape, phi0, ex, ey)
    misfit = float(np.sum(np.abs(b.data - model) ** 2))
    return _Solve(coef, misfit, total, gain, shape, phi0, ex, ey, phi1, phi2, model,
                  normal)


def _synthesize(coef: NDArray, lat: _Lattice, shape: NDArray, phi0: NDArray, ex: NDArray,
                ey: NDArray) -> NDArray[np.complex128]:
    """``S(k) Σ_e c_e e^{−i k·r_e}`` at the bin's k samples."""
    grid = np.zeros(lat.shape, complex)
    grid[lat.grid_position[:, 0], lat.grid_position[:, 1]] = coef
    # Σ_{ix,iy} C e^{−i ix φ1} e^{−i iy φ2} for every k
    total = np.einsum("xk,xk->k", np.conj(ex), grid @ np.conj(ey))
    return shape * np.exp(-1j * phi0) * total


def _gauss_newton_step(bins: list[_Bin], lat: _Lattice, params: NDArray, ridge: float,
                       fit: NDArray[np.bool_]) -> tuple[NDArray, float, NDArray]:
    """One variable-projection step: coefficients per bin, then a Gauss–Newton update of
    the free non-linear parameters with the Jacobian projected off the coefficients'
    span. Returns (new params, relative residual,
    standard uncertainties of the parameters from the normal matrix and the misfit)."""
    jtj = np.zeros((8, 8))
    jtr = np.zeros(8)
    res = tot = 0.0
    samples = 0
    u, v = lat.centred()
    px, py = lat.pitch[0] * (1.0 + params[4]), lat.pitch[1] * (1.0 + params[5])
    free = np.flatnonzero(fit)
    for b in bins:
        sol = _solve_bin(b, lat, params, ridge)
        res += sol.misfit
        tot += sol.total
        samples += b.data.size
        r = b.data - sol.model
        model, phi1, phi2 = sol.model, sol.phi1, sol.phi2
        mu = _synthesize(sol.coef * u, lat, sol.shape, sol.phi0, sol.ex, sol.ey)
        mv = _synthesize(sol.coef * v, lat, sol.shape, sol.phi0, sol.ex, sol.ey)
        jac = np.stack([-1j * b.kx * model, -1j * b.ky * model,
                        -1j * ((px / py) * phi2 * mu - (py / px) * phi1 * mv),
                        -1j * b.kz_minus_k * model,
                        -1j * phi1 / (1.0 + params[4]) * mu,
                        -1j * phi2 / (1.0 + params[5]) * mv,
                        *(d * model for d in _size_derivatives(b, lat, params))], axis=1)
        for j in free:  # what the coefficients cannot absorb (variable projection)
            jac[:, j] = sol.project_out(lat, jac[:, j])
        jtj += np.real(jac.conj().T @ jac)
        jtr += np.real(jac.conj().T @ r)
    step = np.zeros(8)
    sub = jtj[np.ix_(free, free)]
    sub = sub + 1e-9 * np.trace(sub) / free.size * np.eye(free.size)
    step[free] = np.linalg.solve(sub, jtr[free])
    sigma2 = res / max(samples - free.size, 1)  # misfit power per complex sample
    unc = np.full(8, np.nan)
    unc[free] = np.sqrt(np.maximum(0.5 * sigma2 * np.diag(np.linalg.inv(sub)), 0.0))
    return params + step, res / max(tot, 1e-300), unc


def _residual(bins: list[_Bin], lat: _Lattice, params: NDArray, ridge: float) -> float:
    res = tot = 0.0
    for b in bins:
        sol = _solve_bin(b, lat, params, ridge)
        res += sol.misfit
        tot += sol.total
    return res / max(tot, 1e-300)


def matrix_capture_angle(footprint: tuple[float, float, float, float],
                         aperture: tuple[float, float, float, float], distance: float,
                         max_angle: float, inset: float = 0.0) -> float:
    """Largest angle (rad) at which every aperture point still radiates into the scan;
    with ``inset`` every point at least that fraction of the aperture's half-size in
    from its edges (the outer elements' steepest waves then partly miss the scan: the
    window correction, :func:`matrix_window_bias`, models that).

    Parameters
    ----------
    footprint : (x_lo, x_hi, y_lo, y_hi)
        Scan footprint on the source frame (m).
    aperture : (x_lo, x_hi, y_lo, y_hi)
        The array's extent (m).
    distance : float
        Back-projection distance z0 (m).
    max_angle : float
        Upper bound (rad).
    inset : float
        Fraction of the half-size (0: the whole aperture; 1: its centre).
    """
    hx, hy = 0.5 * (aperture[1] - aperture[0]), 0.5 * (aperture[3] - aperture[2])
    margin = min(aperture[0] - footprint[0] + inset * hx, footprint[1] - aperture[1] + inset * hx,
                 aperture[2] - footprint[2] + inset * hy, footprint[3] - aperture[3] + inset * hy)
    if margin <= 0 or distance <= 0:
        return 0.0
    return float(min(np.arctan(margin / distance), max_angle))


def fit_matrix_map(velocity: ArrayLike, grid: PlaneGrid, frequencies: ArrayLike, *,
                   array: ArrayGeometry, center: tuple[float, float], sound_speed: float,
                   max_angle: float, min_resolution: float = 1.1,
                   dead_threshold: float = 0.3, weak_threshold: float = 0.7,
                   ridge: float = 1e-4, iterations: int = 4, fit_bins: int = 8,
                   offset_range: float = 2.0, fit_pitch: bool = False,
                   fit_size: bool = False, map_bins: int = 12, start: MatrixElementMap | None = None
                   ) -> MatrixElementMap:
    """Fit the element map of a matrix array to its back-projected surface velocity.

    Parameters
    ----------
    velocity : array_like, complex, shape (nx, ny, nf)
        Normal velocity on z = 0 (back-projection, conjugate Fourier convention).
    grid : PlaneGrid
        The source-plane grid of ``velocity`` (uniform steps).
    frequencies : array_like, shape (nf,)
        Hz.
    array : ArrayGeometry
        Nominal layout (``kind == "matrix"``: grid shape, pitch, element sizes, grid
        positions of a sparse grid).
    center : (float, float)
        Starting lattice centre (m), e.g. the aperture fit's.
    sound_speed : float
        m/s (the back-projection's).
    max_angle : float
        Capture angle θ_c (rad, :func:`matrix_capture_angle`): only ``|k| < k sin θ_c``
        is fitted.
    min_resolution : float
        Bins with ``k sin θ_c · max(p_x, p_y) ≥ min_resolution·π`` take part.
    dead_threshold, weak_threshold, ridge
        As :class:`~holoprobe.characterize.ElementsConfig`.
    iterations : int
        Most variable-projection Gauss–Newton steps of the non-linear parameters.
    fit_bins : int
        Bins (spread over the band) used for the non-linear parameters.
    offset_range : float
        Half-range in wavelengths of the coarse search of δ.
    fit_pitch : bool
        Fit the x and y pitch too (else the geometry's are kept).
    fit_size : bool
        Fit the element width and height too (the curvature of the element spectrum
        ``S(k)`` across the capture disc; else the geometry's are kept).
    map_bins : int
        Most bins (spread over the usable band) whose coefficients make the map.
    start : MatrixElementMap, optional
        A map of the same array from a previous back-projection (the pipeline's
        iterations): its focus offset, pitches and element sizes start the fit (no
        coarse search of δ, a third of the Gauss–Newton steps); centre and rotation
        start from ``center`` and 0.

    Returns
    -------
    MatrixElementMap

    Raises
    ------
    InputError
        Not a matrix geometry.
    FitError
        Fewer than three bins resolve the elements within the capture angle.
    """
    if not isinstance(array, ArrayGeometry) or array.kind != "matrix" \
            or array.grid_shape is None or array.grid_position is None or array.pitch is None:
        raise InputError("expected a matrix ArrayGeometry (grid shape, grid positions, "
                         "pitch)", field="array")
    v = np.asarray(velocity)
    if v.ndim != 3 or v.shape[:2] != grid.shape:
        raise InputError(f"expected shape {grid.shape} + (nf,), got {v.shape}",
                         field="velocity")
    f = np.asarray(frequencies, dtype=float).reshape(-1)
    lat = _geometry_lattice(array)
    k_fit = 2 * np.pi * f / sound_speed * np.sin(max_angle)
    use = k_fit * max(lat.pitch) >= min_resolution * np.pi
    if use.sum() < 3:
        raise FitError(f"only {int(use.sum())} frequency bin(s) resolve the elements "
                         f"within the scan's capture angle {np.degrees(max_angle):.0f}° "
                         f"(k·sin θ_c·p ≥ {min_resolution:g}π): scan closer or wider",
                         field="frequencies")
    keep = np.flatnonzero(use)
    keep = keep[_spread(keep.size, map_bins)]
    freqs = f[keep]
    bins = _bins(v[:, :, keep], grid, freqs, sound_speed, max_angle)
    sub = [bins[i] for i in _spread(len(bins), fit_bins)]
    params, iterations = _start(sub, lat, center, start, iterations, ridge,
                                sound_speed / float(np.median(freqs)), offset_range)
    fit = np.array([True, True, True, True, fit_pitch, fit_pitch, fit_size, fit_size])
    tolerance = np.array([1e-7, 1e-7, 1e-6, 1e-7, 1e-6, 1e-6, 1e-5, 1e-5])
    unc = np.full(8, np.nan)
    for _ in range(max(1, int(iterations))):
        new, _, unc = _gauss_newton_step(sub, lat, params, ridge, fit)
        change = np.abs(new - params)
        params = new
        if np.all(change < tolerance):
            break
    emap = _map_from_params(bins, freqs, lat, params, ridge, dead_threshold,
                            weak_threshold, max_angle, sound_speed)
    scales = (lat.pitch[0], lat.pitch[1], lat.size[0], lat.size[1])
    u_geo = [float(u * a) if np.isfinite(u) else 0.0 for u, a in zip(unc[4:], scales, strict=True)]
    return dataclasses.replace(emap, rotation_uncertainty=float(unc[2]),
                               pitch_uncertainty=u_geo[0], pitch_y_uncertainty=u_geo[1],
                               width_uncertainty=u_geo[2], height_uncertainty=u_geo[3],
                               focus_offset_uncertainty=float(unc[3]))


def _spread(n: int, m: int) -> NDArray[np.intp]:
    """Indices of at most ``m`` of ``n`` items, evenly spread, first and last kept."""
    return np.unique(np.linspace(0, n - 1, min(m, n)).round().astype(np.intp))


def _start(bins: list[_Bin], lat: _Lattice, center: tuple[float, float],
           start: MatrixElementMap | None, iterations: int, ridge: float,
           wavelength: float, offset_range: float) -> tuple[NDArray, int]:
    """Starting parameters ``(x_c, y_c, θ, δ, s_x, s_y, s_w, s_h)`` and the number of
    Gauss–Newton steps: from a previous map (δ, pitches, sizes; a third of the steps),
    else δ by a coarse search of the residual on the last bin (a defocus may exceed a
    wavelength, where Gauss–Newton would wrap) and the file's geometry."""
    params = np.array([center[0], center[1], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    if start is not None:
        params[3:] = (start.focus_offset, start.pitch / lat.pitch[0] - 1.0,
                      start.pitch_y / lat.pitch[1] - 1.0,
                      start.element_width / lat.size[0] - 1.0,
                      start.element_height / lat.size[1] - 1.0)
        return params, max(1, int(iterations) // 3)
    trial = wavelength * np.arange(-offset_range, offset_range + 1e-9, 0.25)
    trial = trial[np.argsort(np.abs(trial))]
    scores = []
    for d in trial:
        params[3] = d
        scores.append(_residual(bins[-1:], lat, params, ridge))
    params[3] = trial[int(np.argmin(scores))]
    return params, int(iterations)


def _map_from_params(bins, freqs, lat, params, ridge, dead_threshold, weak_threshold,
                     max_angle, sound_speed) -> MatrixElementMap:
    """Coefficients of every bin at the final parameters → the map."""
    n = lat.grid_position.shape[0]
    coef = np.zeros((n, len(bins)), complex)
    gain = np.zeros((n, len(bins)))
    res = tot = 0.0
    joint: list[tuple[NDArray, NDArray, float]] = []  # Bᴴ V̂, BᴴB by offset, noise
    for j, b in enumerate(bins):
        sol = _solve_bin(b, lat, params, ridge)
        coef[:, j] = sol.coef
        step = 2 * np.pi / max(np.ptp(b.kx), 1e-30)
        per_sample = sol.misfit / b.data.size \
            * max(1.0, 0.5 * sound_speed / b.frequency / step)
        gain[:, j] = per_sample * sol.normal.noise_gain()
        if n <= _DENSE_MAX:
            rhs = sol.adjoint(lat, b.data)[lat.grid_position[:, 0], lat.grid_position[:, 1]]
            joint.append((rhs, sol.normal.toeplitz, per_sample))
        res += sol.misfit
        tot += sol.total
    amp, u_amp, tau, u_tau, dead, weak = _amplitudes_and_delays(
        coef, gain, freqs, dead_threshold, weak_threshold, independent_bins=True)
    if joint:
        amp, u_amp, dead, weak = _joint_amplitudes(joint, lat, freqs, amp, tau, dead,
                                                   dead_threshold, weak_threshold)
        u_tau[list(dead)] = np.inf  # a silent element has no delay
    xc, yc, theta, delta = (float(p) for p in params[:4])
    px, py = lat.pitch[0] * (1.0 + params[4]), lat.pitch[1] * (1.0 + params[5])
    w, h = lat.size[0] * (1.0 + params[6]), lat.size[1] * (1.0 + params[7])
    pos = _lattice_positions(lat, xc, yc, theta, px, py)
    return MatrixElementMap(
        amp, u_amp, tau, u_tau, dead, weak, xc, float(px), float(w), delta,
        float("nan"), float("nan"), float(res / max(tot, 1e-300)), np.asarray(freqs),
        coef, False, center_y=yc, pitch_y=float(py), element_height=float(h),
        rotation=theta, grid_shape=lat.shape, grid_position=lat.grid_position,
        positions=pos, max_angle=float(max_angle))


def _joint_amplitudes(joint: list[tuple[NDArray, NDArray, float]], lat: _Lattice,
                      freqs: NDArray, amp: NDArray, tau: NDArray, dead: tuple[int, ...],
                      dead_threshold: float, weak_threshold: float, iterations: int = 2
                      ) -> tuple[NDArray, NDArray, tuple[int, ...], tuple[int, ...]]:
    """Element amplitudes by one least-squares fit of all the map's bins at once.

    The per-bin solves fit N complex coefficients per bin, then average them per element
    (:func:`._elements._amplitudes_and_delays`); near the lattice's Nyquist (pitch
    0.6 λ at 3 MHz) each bin alone separates neighbours poorly and its noise gain is
    large. Here the model ``c_e(f) = A_e U(f) e^{iωτ_e}`` is fitted directly to every
    bin's ``V̂``: N real amplitudes, the delays τ_e of the per-bin fit held, U(f) one
    complex scalar per bin (re-estimated from the amplitudes), each bin weighted by
    1/σ_f² (σ_f² its misfit power per k sample). The normal matrix is
    ``Σ_f Re(D_fᴴ (BᴴB)_f D_f)/σ_f²`` with ``D_f = diag(U(f) e^{iωτ_e})``; its inverse's
    diagonal is the amplitudes' variance. 32 × 32 twin of seed 1 (40 dB): amplitude
    errors 0.60 → 0.44 % rms, worst element 2.08 → 1.59 %.

    ``joint``: per bin ``(Bᴴ V̂ (N,), BᴴB by index offset, σ_f²)``. Returns the
    amplitudes (live mean 1), their standard uncertainties, dead and weak indices.
    """
    n = lat.grid_position.shape[0]
    omega = 2.0 * np.pi * np.asarray(freqs, float)
    live = np.ones(n, bool)
    live[list(dead)] = False
    a = np.asarray(amp, float).copy()
    normal = np.zeros((n, n))
    for _ in range(max(1, int(iterations))):
        normal[:] = 0.0
        rhs = np.zeros(n)
        for j, (bh_v, toeplitz, noise) in enumerate(joint):
            dense = _dense_normal(toeplitz, lat, 0.0)
            phase = np.exp(1j * omega[j] * tau)
            p = a * phase
            u = np.vdot(p, bh_v) / max(float(np.real(np.vdot(p, dense @ p))), 1e-300)
            p = u * phase
            if np.iscomplexobj(dense):
                normal += np.real(np.conj(p)[:, None] * dense * p[None, :]) / noise
            else:
                normal += dense * (np.outer(p.real, p.real) + np.outer(p.imag, p.imag)) / noise
            rhs += np.real(np.conj(p) * bh_v) / noise
        from scipy.linalg import cho_factor, cho_solve  # lazy: start-up time

        factor = cho_factor(normal, check_finite=False)
        a = cho_solve(factor, rhs, check_finite=False)
    variance = np.diag(cho_solve(factor, np.eye(n), check_finite=False))
    scale = float(np.mean(a[live])) if live.any() else float(np.mean(a))
    a, u_a = a / scale, np.sqrt(np.maximum(variance, 0.0)) / abs(scale)
    dead_idx = tuple(int(i) for i in np.flatnonzero(a < dead_threshold))
    weak_idx = tuple(int(i) for i in np.flatnonzero((a >= dead_threshold)
                                                    & (a < weak_threshold)))
    return a, u_a, dead_idx, weak_idx


def matrix_aperture(aperture, velocity: NDArray, source_grid: PlaneGrid,
                    frequencies: NDArray, *, probe, scan_grid: PlaneGrid, pose,
                    sound_speed: float, config, warnings: list[str],
                    previous: MatrixElementMap | None = None):
    """The aperture of a matrix array from its element map (the 2-D
    :func:`~holoprobe.characterize.array_aperture`).

    The map is fitted from the aperture fit's centre; the aperture becomes the
    lattice's band-limited envelope ``n_x p_x × n_y p_y`` (the convention of
    :class:`ApertureFit` for arrays) centred on the fitted lattice centre.

    ``previous`` (the map of the pipeline's previous iteration) starts the fit.

    Returns
    -------
    (ApertureFit, MatrixElementMap or None, float)
        The aperture, the map (None when it could not be fitted; a warning says why)
        and the profile-fitted envelope width (m).
    """
    profile_width = float(aperture.width)
    array = probe.array
    corners = np.array([[u, v, 0.0] for u in (scan_grid.x[0], scan_grid.x[-1])
                        for v in (scan_grid.y[0], scan_grid.y[-1])])
    pts = pose.to_global(corners)
    footprint = (pts[:, 0].min(), pts[:, 0].max(), pts[:, 1].min(), pts[:, 1].max())
    nx, ny = array.grid_shape
    px, py = array.pitch
    half = (0.5 * nx * px, 0.5 * ny * py)
    extent = (aperture.center_x - half[0], aperture.center_x + half[0],
              aperture.center_y - half[1], aperture.center_y + half[1])
    theta_c = matrix_capture_angle(footprint, extent, float(pose.origin[2]),
                                   np.deg2rad(config.matrix_max_angle_deg),
                                   config.matrix_capture_inset)
    try:
        with blas_threads(1):  # small products per bin: threads only cost (80× at load)
            emap = fit_matrix_map(
                velocity, source_grid, frequencies, array=array,
                center=(aperture.center_x, aperture.center_y), sound_speed=sound_speed,
                max_angle=theta_c, start=previous, **matrix_map_options(config))
    except (InputError, FitError) as exc:
        warnings.append(f"no element map: {exc.detail}")
        return aperture, None, profile_width
    return lattice_aperture(aperture, emap), emap, profile_width


def lattice_aperture(aperture, emap: MatrixElementMap):
    """``aperture`` (an :class:`ApertureFit`) as the map's band-limited envelope
    ``n_x p_x × n_y p_y`` centred on the lattice, with the map's uncertainties."""
    nx, ny = emap.grid_shape
    u_width = np.hypot((nx - 1) * emap.pitch_uncertainty, emap.width_uncertainty)
    u_height = np.hypot((ny - 1) * emap.pitch_y_uncertainty, emap.height_uncertainty)
    return dataclasses.replace(aperture, width=float(nx * emap.pitch),
                               height=float(ny * emap.pitch_y),
                               width_uncertainty=float(u_width),
                               height_uncertainty=float(u_height),
                               center_x=float(emap.center_x), center_y=float(emap.center_y))


def matrix_map_options(config) -> dict[str, Any]:
    """Keyword arguments of :func:`fit_matrix_map` set by an ``ElementsConfig`` (the
    pipeline's fit and the refit of its window model use the same)."""
    return dict(min_resolution=config.min_resolution, dead_threshold=config.dead_threshold,
                weak_threshold=config.weak_threshold, ridge=config.ridge,
                iterations=config.matrix_iterations,
                fit_pitch=config.fit_pitch or config.matrix_fit_pitch,
                fit_size=config.matrix_fit_element_size, map_bins=config.matrix_bins)


def _geometry_lattice(array: ArrayGeometry) -> _Lattice:
    """The nominal lattice of a matrix geometry (what :func:`fit_matrix_map` scales)."""
    assert array.grid_shape is not None and array.pitch is not None
    return _Lattice(np.asarray(array.grid_position), array.grid_shape, array.pitch,
                    (float(np.median(array.widths)), float(np.median(array.heights))))


def _map_params(emap: MatrixElementMap, lat: _Lattice) -> NDArray[np.float64]:
    """The non-linear parameters ``(x_c, y_c, θ, δ, s_x, s_y, s_w, s_h)`` of a map."""
    return np.array([emap.center_x, emap.center_y, emap.rotation, emap.focus_offset,
                     emap.pitch / lat.pitch[0] - 1.0, emap.pitch_y / lat.pitch[1] - 1.0,
                     emap.element_width / lat.size[0] - 1.0,
                     emap.element_height / lat.size[1] - 1.0])


def lattice_spectrum(emap: MatrixElementMap, array: ArrayGeometry, source: PlaneGrid,
                     sound_speed: float, bins: ArrayLike | None = None) -> SpectrumModel:
    """The fitted model of a map as a velocity spectrum for :func:`window_round_trip`.

    ``V̂(κ; f) = S(κ) Σ_e c_e(f) e^{−iκ·r_e}`` (the module's model: the map's lattice,
    element size, defocus δ and per-bin coefficients at ``emap.frequencies``) on the
    DFT lattice of a period ``shape × (dx, dy)`` of ``source``, zero outside the
    propagating disc ``|κ| < k`` (never radiated); ``bins`` picks some of the map's
    frequencies (indices; default all).
    """
    lat = _geometry_lattice(array)
    params = _map_params(emap, lat)
    pick = slice(None) if bins is None else np.asarray(bins)
    freqs = np.asarray(emap.frequencies, float)[pick]
    coef = np.asarray(emap.coefficients)[:, pick]
    nx, ny = lat.shape

    def spectrum(shape: tuple[int, int]) -> tuple[NDArray[np.complex128],
                                                   NDArray[np.float64], NDArray[np.float64]]:
        kx = np.asarray(2 * np.pi * np.fft.fftfreq(shape[0], source.dx), float)
        ky = np.asarray(2 * np.pi * np.fft.fftfreq(shape[1], source.dy), float)
        kxx, kyy = np.meshgrid(kx, ky, indexing="ij")
        kr2 = kxx**2 + kyy**2
        out = np.zeros((shape[0], shape[1], freqs.size), complex)
        for j, f in enumerate(freqs):
            k = 2 * np.pi * f / sound_speed
            disc = kr2 < k * k  # the propagating waves (the rest is never radiated)
            b = _Bin(kxx[disc], kyy[disc], np.sqrt(k * k - kr2[disc]) - k,
                     np.empty(0, complex), float(f))
            size, phi1, phi2, phi0 = _phases(b, lat, params)
            out[:, :, j][disc] = _synthesize(coef[:, j], lat, size, phi0,
                                             _powers(phi1, nx), _powers(phi2, ny))
        return out, kx, ky

    return spectrum


def matrix_window_bias(emap: MatrixElementMap, array: ArrayGeometry, source: PlaneGrid,
                       scan_grid: PlaneGrid, medium, *, options: dict[str, Any],
                       guard_angle: float = np.deg2rad(80.0), eps: float = 1e-6
                       ) -> MatrixElementMap:
    """:func:`fit_matrix_map` of the map's own model seen through the scan window.

    The fitted model (:func:`lattice_spectrum` of the map's lattice with its per-bin
    coefficients replaced by ``A_e U(f) e^{iωτ_e}``, :func:`_smooth_coefficients`, so
    that the refit's amplitudes and delays compare with the map's without the data's
    per-bin noise) is radiated onto the posed scan grid,
    cut to its window and back-projected onto ``source``
    (:func:`~holoprobe.characterize.window_round_trip`), then refitted from the map
    (``start=emap``) with the same ``options`` (:func:`matrix_map_options`), capture
    angle and the bins the data's lattice parameters came from (``fit_bins`` of the
    map's). The refit takes the steps a started fit takes (one, from the model's own
    parameters: on the 32 × 32 twin of seed 1 the correction is 1.5 % off the
    converged refit's, 1.6 s CPU less). Refit minus map is the bias the scan window
    leaves in the lattice parameters (the pitches +0.06 … +0.16 µm on the 32 × 32
    twins: the steep waves of the outer elements are missing from the scan).

    Returns
    -------
    MatrixElementMap
        The refit (compare its ``pitch``, ``pitch_y``, element sizes with ``emap``).
    """
    if emap.coefficients is None or emap.frequencies is None:
        raise FitError("the map has no coefficients to model", field="element_map")
    # the bins the data's fit took its lattice parameters from (fit_matrix_map's
    # fit_bins of its map bins): the refit of these alone uses the same bins
    pick = _spread(np.asarray(emap.frequencies).size, int(options.get("fit_bins", 8)))
    freqs = np.asarray(emap.frequencies, float)[pick]
    model_map = dataclasses.replace(emap, coefficients=_smooth_coefficients(emap))
    spectrum = lattice_spectrum(model_map, array, source, medium.sound_speed, bins=pick)
    with blas_threads(1):
        model = window_round_trip(scan_grid, source, freqs, medium, spectrum,
                                  guard_angle=guard_angle, eps=eps)
        steps = dict(options, iterations=int(options.get("iterations", 4)))
        return fit_matrix_map(model, source, freqs, array=array,
                              center=(emap.center_x, emap.center_y),
                              sound_speed=medium.sound_speed, max_angle=emap.max_angle,
                              start=emap, **steps)


def remove_lattice_bias(emap: MatrixElementMap, refit: MatrixElementMap,
                        fraction: float) -> MatrixElementMap:
    """``emap`` with refit − map of the pitches, element sizes and focus offset δ
    subtracted (element positions moved with them) and the per-element window bias of
    the amplitudes and delays removed (:func:`_remove_element_bias`); each uncertainty
    gains ``fraction`` × its correction in quadrature."""
    names = ("pitch", "pitch_y", "element_width", "element_height", "focus_offset")
    units = ("pitch_uncertainty", "pitch_y_uncertainty", "width_uncertainty",
             "height_uncertainty", "focus_offset_uncertainty")
    changes: dict[str, Any] = {}
    for name, unit in zip(names, units, strict=True):
        bias = float(getattr(refit, name) - getattr(emap, name))
        changes[name] = float(getattr(emap, name)) - bias
        changes[unit] = float(np.hypot(getattr(emap, unit), fraction * bias))
    out = _remove_element_bias(dataclasses.replace(emap, **changes), refit, fraction)
    if emap.grid_position is not None:
        lat = _Lattice(np.asarray(emap.grid_position), emap.grid_shape, (1.0, 1.0),
                       (1.0, 1.0))
        pos = _lattice_positions(lat, emap.center_x, emap.center_y, emap.rotation,
                                 out.pitch, out.pitch_y)
        out = dataclasses.replace(out, positions=pos)
    return out


def _remove_element_bias(emap: MatrixElementMap, refit: MatrixElementMap,
                         fraction: float) -> MatrixElementMap:
    """Per element: the amplitude divided by refit/map and the delay less refit − map
    (the refit of the map's noise-free model, :func:`_smooth_coefficients`, whose
    amplitudes and delays are the map's); the live mean of the delay shift is kept and
    the amplitudes renormalised to a live mean of 1. Dead elements keep theirs. The
    per-bin ``coefficients`` stay the fitted ones."""
    amp, ref = np.asarray(emap.relative_amplitude), np.asarray(refit.relative_amplitude)
    delay = np.asarray(emap.delay, float)
    live = np.ones(emap.count, bool)
    live[list(emap.dead)] = False
    live &= (amp > 0) & (ref > 0) & np.isfinite(ref) & np.isfinite(refit.delay)
    if not live.any():
        return emap
    new_amp, new_delay = amp.copy(), delay.copy()
    new_amp[live] = amp[live] * amp[live] / ref[live]
    new_amp[live] /= new_amp[live].mean()
    shift = np.asarray(refit.delay)[live] - delay[live]
    new_delay[live] -= shift - shift.mean()  # a common shift is no element's bias
    u_amp = np.hypot(emap.amplitude_uncertainty, fraction * np.abs(new_amp - amp))
    u_delay = np.hypot(emap.delay_uncertainty, fraction * np.abs(new_delay - delay))
    return dataclasses.replace(emap, relative_amplitude=new_amp, delay=new_delay,
                               amplitude_uncertainty=u_amp, delay_uncertainty=u_delay)


def _smooth_coefficients(emap: MatrixElementMap) -> NDArray[np.complex128]:
    """The map's per-bin coefficients as its model ``A_e U(f) e^{iωτ_e}`` (U: the mean
    over the live elements of ``c_e(f) e^{−iωτ_e} / A_e``): no noise of the data's
    bins, so a refit of it is compared with the map's own amplitudes and delays."""
    coef = np.asarray(emap.coefficients)
    amp, tau = np.asarray(emap.relative_amplitude), np.asarray(emap.delay, float)
    omega = 2.0 * np.pi * np.asarray(emap.frequencies, float)
    live = np.ones(emap.count, bool)
    live[list(emap.dead)] = False
    live &= amp > 0
    phase = np.exp(1j * np.outer(tau, omega))
    u = np.mean(coef[live] / phase[live] / amp[live, None], axis=0)
    return amp[:, None] * u[None, :] * phase


def _lattice_positions(lat: _Lattice, xc: float, yc: float, theta: float, px: float,
                       py: float) -> NDArray[np.float64]:
    """Element centres (N, 2) of the lattice at centre, rotation and pitches (m)."""
    u, v = lat.centred()
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([xc + u * px * c - v * py * s, yc + u * px * s + v * py * c], axis=-1)


def lattice_pose_correction(emap: MatrixElementMap, sound_speed: float
                            ) -> tuple[float, float, float]:
    """Orientation corrections (rad) that the element map of a matrix array asks for.

    A tilt of the scan-plane pose and a linear trend of the element delays change the
    back-projected field the same way, so a convention must pick one: the pose is the
    one for which the delays of the live elements have no linear trend (the acoustic
    axis of the array, what the angular-spectrum orientation estimates, here refined by
    the map). The delays ``τ_e = τ̄ + s_x x_e + s_y y_e`` (least squares weighted by
    ``A_e²``) give ``Δθ_y = −asin(c s_x)`` and ``Δθ_x = +asin(c s_y)``; the lattice
    rotation on the source frame gives ``Δθ_z = −rotation``.

    Returns
    -------
    (dθx, dθy, dθz) : tuple of float
        To add to the orientation's angles (rad).
    """
    live = emap.live
    if emap.positions is None or live.sum() < 3:
        return 0.0, 0.0, -float(emap.rotation)
    pos = emap.positions[live]
    w = np.clip(emap.relative_amplitude[live], 0.0, None)
    design = np.c_[np.ones(pos.shape[0]), pos] * w[:, None]
    coef = np.linalg.lstsq(design, emap.delay[live] * w, rcond=None)[0]
    sx, sy = np.clip(coef[1:] * sound_speed, -1.0, 1.0)
    return float(np.arcsin(sy)), float(-np.arcsin(sx)), -float(emap.rotation)


def lattice_pose_uncertainty(emap: MatrixElementMap, sound_speed: float
                             ) -> tuple[float, float, float]:
    """Standard uncertainties (rad) of θx, θy, θz set by :func:`lattice_pose_correction`:
    the weighted least-squares slopes of the delays with their uncertainties, and the
    lattice rotation's."""
    live = emap.live & np.isfinite(emap.delay_uncertainty) & (emap.delay_uncertainty > 0)
    if emap.positions is None or live.sum() < 3:
        return float("nan"), float("nan"), float(emap.rotation_uncertainty)
    x = np.c_[np.ones(int(live.sum())), emap.positions[live]]
    w = 1.0 / emap.delay_uncertainty[live] ** 2
    cov = np.linalg.inv(x.T @ (x * w[:, None]))
    u_sx, u_sy = np.sqrt(np.diag(cov)[1:]) * sound_speed
    return float(u_sy), float(u_sx), float(emap.rotation_uncertainty)
