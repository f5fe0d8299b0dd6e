"""A CW hologram as a sum of propagating plane waves: the field anywhere, its derivatives, power.

The complex pressure P(x, y) measured on the scan plane z = 0 (scan coordinates: z along
the plane's normal, away from the source) has the angular spectrum
P̂(κ) = Σ P(x_i, y_j) e^{−iκ·(x_i, y_j)} Δx Δy. Every propagating component (|κ| < k) is a
plane wave with wave vector k = (κx, κy, √(k² − |κ|²)), so at any point r

    p(r) = Σ_κ c_κ e^{i k·r},   c_κ = P̂(κ) Δκx Δκy / 4π²

(the fast path of DESIGN.md, the same sum as :func:`holoprobe.propagation.project`, here
kept as an object so that the field, its gradient and Hessian at a continuous point are
available to an optimiser). Evanescent components are excluded (the hologram is taken a
few wavelengths from the source). The time-averaged power through the plane is the
angular-spectrum integral W = Σ |c_κ|² (k_z/k) 4π²/(2ρ0c0 Δκx Δκy).
"""

from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass

import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Surface
from holoprobe.propagation import padded_shape, plane_power
from holoprobe.signal import workers

__all__ = ["BandField", "PlaneWaveField", "hologram_grid", "hologram_power", "plane_wave_field",
           "propagation_guard_angle"]

# points × components above which the type-3 NUFFT is used (it pays off for volumes only)
_DIRECT_LIMIT = 2_000_000
_CHUNK = 2_000_000  # elements of one block of phases in the direct sum


def hologram_grid(x: ArrayLike, y: ArrayLike, pressure: ArrayLike, *, file: str | None = None
                  ) -> tuple[PlaneGrid, NDArray[np.complex128]]:
    """The scan grid with increasing axes and the pressure reordered to match.

    Parameters
    ----------
    x, y : array_like, shape (nx,), (ny,)
        Grid coordinates in m, uniform, increasing or decreasing (positions are the
        grid's values, never indices).
    pressure : array_like, complex, shape (nx, ny) or (nx, ny, nf)
        Complex pressure in Pa (holoprobe's exp(−iωt) convention).
    file : str, optional
        Named in error messages.

    Returns
    -------
    (PlaneGrid, ndarray)
        The grid (identity pose: scan coordinates) and the pressure, shape (nx, ny, nf).
    """
    xs = np.asarray(x, dtype=float).reshape(-1)
    ys = np.asarray(y, dtype=float).reshape(-1)
    p = np.asarray(pressure)
    if p.ndim == 2:
        p = p[:, :, None]
    if p.ndim != 3 or p.shape[:2] != (xs.size, ys.size):
        raise InputError(f"expected pressure of shape ({xs.size}, {ys.size}[, nf]) to match "
                         f"the grid, got {np.shape(pressure)}", file=file, field="pressure")
    if xs.size > 1 and xs[-1] < xs[0]:
        xs, p = xs[::-1], p[::-1]
    if ys.size > 1 and ys[-1] < ys[0]:
        ys, p = ys[::-1], p[:, ::-1]
    if not np.all(np.isfinite(p)):
        raise InputError("contains NaN or inf", file=file, field="pressure")
    return PlaneGrid(xs, ys), np.ascontiguousarray(p, dtype=np.complex128)


@dataclass(frozen=True)
class PlaneWaveField:
    """The propagating plane waves of one CW hologram (scan coordinates).

    Attributes
    ----------
    wave_vectors : ndarray, shape (m, 3)
        k of each component in rad/m (k_z > 0: away from the source).
    coefficients : ndarray, complex, shape (m,)
        c of each component in Pa (the field is Σ c e^{ik·r}).
    frequency : float
        Hz.
    medium : Medium
        ρ0, c0.
    cell : float
        Δκx Δκy of the spectral grid in rad²/m².
    dropped_power : float
        Power (W) of the components dropped by pruning.
    """

    wave_vectors: NDArray[np.float64]
    coefficients: NDArray[np.complex128]
    frequency: float
    medium: Medium
    cell: float
    dropped_power: float = 0.0
    grid_shape: tuple[int, int] = (0, 0)
    padded_shape: tuple[int, int] = (0, 0)
    indices: NDArray[np.intp] | None = None
    factors: NDArray[np.complex128] | None = None

    @property
    def wavenumber(self) -> float:
        """k = 2πf/c0 in rad/m."""
        return float(self.medium.wavenumber(self.frequency))

    def with_coefficients(self, coefficients: NDArray[np.complex128]) -> PlaneWaveField:
        """The same plane waves with other strengths (e.g. plus a noise realisation)."""
        return dataclasses.replace(self, coefficients=coefficients)

    def noise_coefficients(self, sigma: float, rng: np.random.Generator, *,
                           window: NDArray | None = None) -> NDArray[np.complex128]:
        """Plane-wave strengths of one realisation of white complex noise on the hologram.

        ``sigma`` is the standard deviation (Pa) of each complex sample (real and imaginary
        parts σ/√2 each); the realisation goes through the same padding and component
        selection as the data, so its correlations are exact; ``window`` (nx, ny) is the
        taper the data were multiplied by.
        """
        if self.indices is None or self.factors is None:
            raise InputError("this expansion keeps no record of its spectral grid",
                             field="field")
        noise = sigma / np.sqrt(2) * (rng.standard_normal(self.grid_shape)
                                      + 1j * rng.standard_normal(self.grid_shape))
        if window is not None:
            noise = noise * window
        spec = scipy.fft.fft2(noise, s=self.padded_shape, workers=workers())
        return spec.ravel()[self.indices] * self.factors

    def power(self) -> float:
        """Time-averaged power through the scan plane in W (angular-spectrum integral)."""
        k = self.wavenumber
        weight = self.wave_vectors[:, 2] / k
        total = np.sum(np.abs(self.coefficients) ** 2 * weight)
        return float(total * 4 * np.pi**2 / self.cell / (2 * self.medium.impedance)
                     + self.dropped_power)

    def power_direction(self) -> NDArray[np.float64]:
        """Power-weighted mean propagation direction (unit vector, scan coordinates)."""
        k = self.wavenumber
        w = np.abs(self.coefficients) ** 2 * self.wave_vectors[:, 2] / k
        d = (w[:, None] * self.wave_vectors).sum(axis=0) / k
        return d / np.linalg.norm(d)

    def amplitude(self, points: ArrayLike) -> NDArray[np.float64]:
        """|p| (Pa) at points of shape (..., 3)."""
        return np.abs(self.pressure(points))

    def pressure(self, points: ArrayLike, *, eps: float = 1e-9) -> NDArray[np.complex128]:
        """Complex pressure in Pa at points of shape (..., 3) (m, scan coordinates)."""
        pts = np.asarray(points, dtype=float)
        out = self.pressure_local(np.zeros(3), np.eye(3), pts.reshape(-1, 3), eps=eps)
        return out.reshape(pts.shape[:-1])

    def pressure_local(self, origin: ArrayLike, axes: ArrayLike, local: ArrayLike, *,
                       eps: float = 1e-9) -> NDArray[np.complex128]:
        """Pressure at ``origin + local @ axes`` (a line, plane or volume), Pa.

        Parameters
        ----------
        origin : array_like, shape (3,)
            m.
        axes : array_like, shape (d, 3)
            Unit vectors spanning the line (d = 1), plane (2) or volume (3).
        local : array_like, shape (n, d)
            Coordinates along ``axes`` in m.
        eps : float
            Tolerance of the type-3 NUFFT used for many points.

        Returns
        -------
        ndarray, complex, shape (n,)
        """
        axes = np.atleast_2d(np.asarray(axes, dtype=float))
        local = np.asarray(local, dtype=float).reshape(-1, axes.shape[0])
        coef = self.coefficients * np.exp(1j * (self.wave_vectors @ np.asarray(origin, float)))
        kproj = self.wave_vectors @ axes.T  # (m, d)
        ticks = _regular_ticks(local)
        if ticks is not None and local.shape[0] * coef.size > _DIRECT_LIMIT:
            return grid_sums(kproj, coef[:, None], ticks, eps)[:, 0]
        if local.shape[0] * coef.size <= _DIRECT_LIMIT:
            out = np.empty(local.shape[0], np.complex128)
            rows = max(1, _CHUNK // max(coef.size, 1))
            for i in range(0, local.shape[0], rows):
                phase = local[i:i + rows] @ kproj.T
                out[i:i + rows] = np.cos(phase) @ coef + 1j * (np.sin(phase) @ coef)
            return out
        return _type3(kproj, coef, local, eps)

    def derivatives(self, point: ArrayLike
                    ) -> tuple[complex, NDArray[np.complex128], NDArray[np.complex128]]:
        """Pressure, gradient (3,) and Hessian (3, 3) at one point (Pa, Pa/m, Pa/m²)."""
        from holoprobe.characterize._plane_wave_numba import (
            plane_wave_sums,
            plane_wave_sums_serial,
        )

        kernel = plane_wave_sums if threading.current_thread() is threading.main_thread() \
            else plane_wave_sums_serial
        s = kernel(np.ascontiguousarray(self.wave_vectors, dtype=float),
                            np.ascontiguousarray(self.coefficients.real),
                            np.ascontiguousarray(self.coefficients.imag),
                            np.asarray(point, dtype=float).reshape(3))
        hess = -s[[4, 5, 6, 5, 7, 8, 6, 8, 9]].reshape(3, 3)
        return complex(s[0]), 1j * s[1:4], hess

    def intensity_derivatives(self, point: ArrayLike
                              ) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
        """|p|², its gradient and Hessian at one point."""
        p, g, h = self.derivatives(point)
        value = abs(p) ** 2
        grad = 2 * np.real(np.conj(p) * g)
        hess = 2 * np.real(np.outer(np.conj(g), g) + np.conj(p) * h)
        return value, grad, hess

    def amplitude_local(self, origin: ArrayLike, axes: ArrayLike, local: ArrayLike, *,
                        eps: float = 1e-9) -> NDArray[np.float64]:
        """|p| (Pa) at ``origin + local @ axes`` (see :meth:`pressure_local`)."""
        return np.abs(self.pressure_local(origin, axes, local, eps=eps))

    @property
    def parts(self) -> tuple[tuple[PlaneWaveField, float, float], ...]:
        """(field, weight, noise scale) of each bin: this one field, 1, 1."""
        return ((self, 1.0, 1.0),)


@dataclass(frozen=True)
class BandField:
    """The band energy of a transient hologram's bins: E(r) = Σ_j w_j |p_j(r)|².

    With w_j = 1 over every bin of the record's band, E is proportional to the
    pulse-pressure-squared integral ∫ p(r, t)² dt (Parseval), whose maximum is the focus
    of a pulsed field (:func:`holoprobe.characterize.align_band`). It offers what the
    alignment needs of a :class:`PlaneWaveField` (E in place of |p|², √E in place of |p|).

    Attributes
    ----------
    fields : tuple of PlaneWaveField
        One expansion per bin.
    weights : ndarray, shape (nb,)
        w_j (dimensionless).
    noise_scale : ndarray, shape (nb,)
        Noise standard deviation per hologram sample of each bin, relative to the
        reference level the uncertainties are scaled by.
    """

    fields: tuple[PlaneWaveField, ...]
    weights: NDArray[np.float64]
    noise_scale: NDArray[np.float64]

    @property
    def parts(self) -> tuple[tuple[PlaneWaveField, float, float], ...]:
        """(field, weight, noise scale) of each bin."""
        return tuple(zip(self.fields, self.weights.tolist(), self.noise_scale.tolist(),
                         strict=True))

    @property
    def coefficients(self) -> NDArray[np.complex128]:
        """Every bin's plane-wave strengths, concatenated (the functionals' layout)."""
        return np.concatenate([f.coefficients for f in self.fields])

    @property
    def grid_shape(self) -> tuple[int, int]:
        return self.fields[0].grid_shape

    def intensity_derivatives(self, point: ArrayLike
                              ) -> tuple[float, NDArray[np.float64], NDArray[np.float64]]:
        """E, its gradient and Hessian at one point."""
        value, grad, hess = 0.0, np.zeros(3), np.zeros((3, 3))
        for f, w, _ in self.parts:
            v, g, h = f.intensity_derivatives(point)
            value, grad, hess = value + w * v, grad + w * g, hess + w * h
        return value, grad, hess

    def amplitude_local(self, origin: ArrayLike, axes: ArrayLike, local: ArrayLike, *,
                        eps: float = 1e-9) -> NDArray[np.float64]:
        """√E at ``origin + local @ axes`` (Pa·s per √bin for a spectrum's bins)."""
        energy = sum(w * np.abs(f.pressure_local(origin, axes, local, eps=eps)) ** 2
                     for f, w, _ in self.parts)
        return np.sqrt(np.asarray(energy, dtype=float))

    def amplitude(self, points: ArrayLike) -> NDArray[np.float64]:
        """√E at points of shape (..., 3)."""
        pts = np.asarray(points, dtype=float)
        return self.amplitude_local(np.zeros(3), np.eye(3), pts.reshape(-1, 3)
                                    ).reshape(pts.shape[:-1])


def _regular_ticks(local: NDArray) -> list[tuple[float, float, int]] | None:
    """(start, step, n) per column when ``local`` (n, d) is the 'ij' meshgrid of equally
    spaced increasing axes raveled (a line, a plane or a volume of points), else None."""
    axes = [np.unique(local[:, i]) for i in range(local.shape[1])]
    if any(a.size < 2 for a in axes) or int(np.prod([a.size for a in axes])) != local.shape[0]:
        return None
    ticks = []
    for a in axes:
        step = (a[-1] - a[0]) / (a.size - 1)
        if not np.allclose(np.diff(a), step, rtol=1e-9, atol=0.0):
            return None
        ticks.append((float(a[0]), float(step), int(a.size)))
    mesh = np.meshgrid(*axes, indexing="ij")
    if not all(np.array_equal(m.ravel(), local[:, i]) for i, m in enumerate(mesh)):
        return None
    return ticks


def grid_sums(kproj: NDArray, columns: NDArray, ticks: list[tuple[float, float, int]],
              eps: float) -> NDArray[np.complex128]:
    """Σ_κ columns_κr e^{i kproj_κ·t} at the points t of a regular grid (type-1 NUFFT).

    On the grid t = start + n·step (per dimension, n = 0 … N−1, 'ij' order raveled) the
    sum is Σ_κ c'_κ e^{i n·x_κ} with x_κ = step·kproj_κ (taken modulo 2π: exact, n is an
    integer) and c'_κ = columns_κ e^{i kproj_κ·t_mid}, the phase of the grid point that
    finufft's mode 0 stands for: a type-1 NUFFT, O(m + N log N) instead of the m·N of the
    direct sum or a type-3 plan's set-up. One thread: these transforms take milliseconds,
    and a second OpenMP thread cost 2–7× their CPU time (its spin-waits) on a loaded
    2-core machine.

    Parameters
    ----------
    kproj : ndarray, shape (m, d)
        Wave vectors projected on the grid's axes (rad/m).
    columns : ndarray, complex, shape (m, r)
        r sets of coefficients.
    ticks : list of (start, step, n)
        The grid per dimension (m, m, count; step > 0).
    eps : float
        NUFFT tolerance.

    Returns
    -------
    ndarray, complex, shape (N1·…·Nd, r)
    """
    import finufft

    d = len(ticks)
    shape = tuple(n for _, _, n in ticks)
    mid = np.array([start + (n // 2) * step for start, step, n in ticks])
    steps = np.array([step for _, step, _ in ticks])
    x = np.mod(kproj * steps + np.pi, 2 * np.pi) - np.pi
    c = np.ascontiguousarray((columns * np.exp(1j * (kproj @ mid))[:, None]).T)
    names = ("x", "y", "z")[:d]
    plan = finufft.Plan(1, shape, n_trans=c.shape[0], eps=eps, isign=1,
                        dtype=np.complex128, nthreads=1)
    plan.setpts(**{name: np.ascontiguousarray(x[:, i]) for i, name in enumerate(names)})
    return plan.execute(c).reshape(c.shape[0], -1).T


def grid_adjoint(kproj: NDArray, left: NDArray, ticks: list[tuple[float, float, int]],
                 eps: float) -> NDArray[np.complex128]:
    """leftᵀ @ E for E_tκ = e^{i kproj_κ·t} on the grid of :func:`grid_sums`: a type-2
    NUFFT. ``left`` (N1·…·Nd, r); returns (r, m)."""
    import finufft

    d = len(ticks)
    shape = tuple(n for _, _, n in ticks)
    mid = np.array([start + (n // 2) * step for start, step, n in ticks])
    steps = np.array([step for _, step, _ in ticks])
    x = np.mod(kproj * steps + np.pi, 2 * np.pi) - np.pi
    f = np.ascontiguousarray(left.T.reshape(left.shape[1], *shape), dtype=np.complex128)
    names = ("x", "y", "z")[:d]
    plan = finufft.Plan(2, shape, n_trans=f.shape[0], eps=eps, isign=1,
                        dtype=np.complex128, nthreads=1)
    plan.setpts(**{name: np.ascontiguousarray(x[:, i]) for i, name in enumerate(names)})
    return plan.execute(f).reshape(f.shape[0], -1) * np.exp(1j * (kproj @ mid))[None, :]


def _type3(kvec: NDArray, coef: NDArray, points: NDArray, eps: float,
           threads: int | None = None) -> NDArray:
    """Σ_j coef_j e^{i kvec_j · r} at points r, shape (n, d), by a d-dimensional type-3 NUFFT
    (``coef`` (m,) or (t, m): t sums on one plan, result (n,) or (t, n))."""
    import finufft

    dim = points.shape[1]
    centre = 0.5 * (points.max(axis=0) + points.min(axis=0))
    kmid = 0.5 * (kvec.max(axis=0) + kvec.min(axis=0))
    c = np.ascontiguousarray(coef * np.exp(1j * (kvec @ centre)), dtype=np.complex128)
    s = np.ascontiguousarray((points - centre).T)
    kt = np.ascontiguousarray((kvec - kmid).T)
    plan = finufft.Plan(3, dim, n_trans=1 if c.ndim == 1 else c.shape[0], eps=eps, isign=1,
                        dtype=np.complex128, nthreads=threads or workers())
    names = ("x", "y", "z")[:dim], ("s", "t", "u")[:dim]
    plan.setpts(**dict(zip(names[0], kt, strict=True)), **dict(zip(names[1], s, strict=True)))
    return plan.execute(c) * np.exp(1j * ((points - centre) @ kmid))


def _guard_angle(spectrum_power: NDArray, kr: NDArray, k: float, energy: float,
                 margin: float) -> float:
    """Propagation angle holding ``energy`` of the power above the noise floor, + margin.

    White noise fills the whole disc |κ| < k; its floor (the median power in the outer
    annulus 0.9k < |κ| < k, where a captured beam holds little) is subtracted first, so
    that noise does not inflate the padding.
    """
    annulus = (kr > 0.9 * k) & (kr < k)
    floor = float(np.median(spectrum_power[annulus])) if np.any(annulus) else 0.0
    power = np.where(kr < k, np.clip(spectrum_power - floor, 0.0, None), 0.0)
    order = np.argsort(kr)
    cum = np.cumsum(power[order])
    if cum[-1] <= 0:
        return np.deg2rad(60.0)
    idx = min(int(np.searchsorted(cum, energy * cum[-1])), order.size - 1)
    angle = np.arcsin(min(kr[order][idx] / k, 1.0)) + margin
    return float(min(angle, np.deg2rad(85.0)))


def plane_wave_field(pressure: ArrayLike, grid: PlaneGrid, frequency: float,
                     medium: Medium | None = None, *, reach: ArrayLike | None = None,
                     prune_tolerance: float = 1e-5, guard_energy: float = 0.9999,
                     guard_margin_deg: float = 10.0) -> PlaneWaveField:
    """Expand a CW hologram in propagating plane waves.

    Parameters
    ----------
    pressure : array_like, complex, shape (nx, ny)
        Complex pressure amplitude in Pa on ``grid`` (exp(−iωt) convention).
    grid : PlaneGrid
        The scan grid, identity pose (scan coordinates).
    frequency : float
        Hz.
    medium : Medium, optional
        Default water at 20 °C.
    reach : array_like, shape (n, 3), optional
        Points (m) where the field will be evaluated (e.g. the source surface and the focal
        region): the zero padding keeps the periodic images of the scan away from them.
    prune_tolerance, guard_energy, guard_margin_deg
        See :class:`HologramConfig`.

    Returns
    -------
    PlaneWaveField
    """
    medium = Medium() if medium is None else medium
    p = np.asarray(pressure, dtype=np.complex128)
    if p.shape != grid.shape:
        raise InputError(f"expected shape {grid.shape}, got {p.shape}", field="pressure")
    if not frequency > 0:
        raise InputError(f"expected a positive frequency in Hz, got {frequency!r}",
                         field="frequency")
    k = float(medium.wavenumber(frequency))
    nx, ny = grid.shape
    dx, dy = grid.dx, grid.dy
    raw = scipy.fft.fft2(p, workers=workers())
    kx0 = 2 * np.pi * np.fft.fftfreq(nx, dx)
    ky0 = 2 * np.pi * np.fft.fftfreq(ny, dy)
    kr0 = np.hypot(kx0[:, None], ky0[None, :])
    guard = _guard_angle(np.where(kr0 < k, np.abs(raw) ** 2, 0.0).ravel(), kr0.ravel(), k,
                         guard_energy, np.deg2rad(guard_margin_deg))
    target = Surface(np.asarray(reach, float).reshape(-1, 3),
                     np.tile([0.0, 0.0, 1.0], (np.size(reach) // 3, 1)),
                     np.ones(np.size(reach) // 3)) if reach is not None else grid.to_surface()
    npx, npy = padded_shape(grid, target, guard_angle=guard)
    spec = scipy.fft.fft2(p, s=(npx, npy), workers=workers())
    kx = 2 * np.pi * np.fft.fftfreq(npx, dx)
    ky = 2 * np.pi * np.fft.fftfreq(npy, dy)
    ix, iy = np.nonzero(kx[:, None] ** 2 + ky[None, :] ** 2 < k * k)
    cell = (2 * np.pi / (npx * dx)) * (2 * np.pi / (npy * dy))
    kxs, kys = kx[ix], ky[iy]
    kz = np.sqrt(k * k - kxs**2 - kys**2)
    factors = np.exp(-1j * (kxs * grid.x[0] + kys * grid.y[0])) * dx * dy * cell / (4 * np.pi**2)
    coef = spec[ix, iy] * factors
    # drop the weakest components whose summed magnitude is below the tolerance
    mag = np.abs(coef)
    order = np.argsort(mag)
    cut = int(np.searchsorted(np.cumsum(mag[order]), prune_tolerance * mag.sum()))
    keep = np.sort(order[cut:])
    dropped = order[:cut]
    dropped_power = float(np.sum(mag[dropped] ** 2 * kz[dropped] / k) * 4 * np.pi**2 / cell
                          / (2 * medium.impedance))
    kvec = np.stack([kxs[keep], kys[keep], kz[keep]], axis=-1)
    return PlaneWaveField(kvec, coef[keep], float(frequency), medium, cell, dropped_power,
                          grid_shape=(nx, ny), padded_shape=(npx, npy),
                          indices=(ix * npy + iy)[keep], factors=factors[keep])


def hologram_power(pressure: ArrayLike, grid: PlaneGrid, frequency: float,
                   medium: Medium | None = None) -> float:
    """Time-averaged acoustic power through the scan plane (W), angular-spectrum integral.

    W = 1/(2ρ0c0) Σ_{|κ|<k} |P̂(κ)|² (k_z/k) Δκx Δκy / 4π² over the propagating waves of
    the unpadded spectrum (Parseval: without the k_z/k factor it is ∫|p|²/(2ρ0c0) dA):
    :func:`holoprobe.propagation.plane_power` with the point-sampled ``k_z/k``.

    Parameters
    ----------
    pressure : array_like, complex, shape (nx, ny)
        Complex pressure amplitude in Pa.
    grid : PlaneGrid
    frequency : float
        Hz.
    medium : Medium, optional

    Returns
    -------
    float
    """
    return plane_power(np.asarray(pressure, dtype=np.complex128), grid, frequency, medium,
                       padding=1.0, averaged=False)


def propagation_guard_angle(pressure: ArrayLike, grid: PlaneGrid, frequency: float,
                            medium: Medium | None = None, *, energy: float = 0.999,
                            margin_deg: float = 10.0) -> float:
    """Angle (rad) holding ``energy`` of the propagating power, plus a margin (padding rule)."""
    medium = Medium() if medium is None else medium
    p = np.asarray(pressure, dtype=np.complex128)
    k = float(medium.wavenumber(frequency))
    raw = scipy.fft.fft2(p, workers=workers())
    kx = 2 * np.pi * np.fft.fftfreq(p.shape[0], grid.dx)
    ky = 2 * np.pi * np.fft.fftfreq(p.shape[1], grid.dy)
    kr = np.hypot(kx[:, None], ky[None, :])
    return _guard_angle(np.where(kr < k, np.abs(raw) ** 2, 0.0).ravel(), kr.ravel(), k,
                        energy, np.deg2rad(margin_deg))
