"""Forward Rayleigh integral at scattered points by a plane-wave (Weyl) expansion and NUFFTs.

The field of a velocity source on the plane z = 0 (rigid baffle, paper eq.
rayleigh-fwd-vp) at any point with z > 0 is, by Weyl's expansion of ``e^{ikR}/R``,

    p(r) = (kρ0c0/4π²) ∫∫ Û(k_t) e^{i(k_t·r_t + k_z z)} / k_z  d²k_t,
    Û(k_t) = Σ_q V_q ΔA_q e^{−i k_t·s_q},    k_z = √(k² − |k_t|²),

where s_q are the source points and ΔA_q their areas. The integral is split into

* the propagating part |k_t| < k, written on the hemisphere ``k_t = k sinθ (cos φ,
  sin φ)``: ``d²k_t/k_z = k sinθ dθ dφ`` removes the 1/k_z singularity, and a
  Gauss–Legendre rule in θ times the trapezoidal rule in φ converges spectrally once
  the nodes resolve the phase ``k k̂·(r − s)`` (about k·R nodes in θ and k·ρ sin θ in
  φ per ring, R and ρ the largest source–target distance and its lateral part);
* the evanescent part |k_t| > k, written with ``k_z = iκ``: ``d²k_t/k_z = −i dκ dφ``
  with ``|k_t| = √(k² + κ²)`` and the weight ``e^{−κz}``, truncated where that weight
  is below ``evanescent_decay``.

Û at the nodes is one 2-D type-3 NUFFT from the source points; the propagating part at
the targets is one 3-D type-3 NUFFT (nodes k → points r), the evanescent part 2-D type-3
NUFFTs in (x, y) whose ``e^{−κz}`` factor is interpolated in z (Chebyshev in each depth
slab: it is smooth and low-rank there).

Targets are grouped in depth slabs ``[z_a, ratio·z_a)``. For a slab far enough from the
face, every ray from the source to its targets makes an angle θ ≤ θ_geo = atan(ρ/z_a)
with the normal; the propagating integral is then windowed to θ ≤ θ_geo + 2δ with a C∞
taper over the last δ = ``window_margin``/√(k z_a) (a few Fresnel widths): the
directions it drops carry only non-stationary (cancelling) contributions at those
targets, so the evanescent part is dropped with them and the slab needs fewer nodes.
Slabs whose window would reach grazing use the whole hemisphere plus the evanescent
part. The quadrature is that of the sources given (the same point sources as a dense
Rayleigh sum), so the two agree to about the NUFFT tolerance: 2–4e-5 of the largest
pressure with the defaults (eps 1e-5; P4-1 model, 0.5–4.5 MHz, targets 0.5–100 mm), 2e-6
with eps 1e-6.

Cost per frequency: the nodes (≈ 2·10⁶ at 4.5 MHz for the P4-1 aperture and targets
within ±25 mm, 5–100 mm) plus ≈ 10 µs CPU per target (the 3-D kernel's w³ taps, and m
Chebyshev terms × w² for targets in slabs that need evanescent waves).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, DTypeLike, NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import Medium

__all__ = ["plane_wave_cost", "rayleigh_plane_waves"]

#: finufft upsampling factor of the 3-D transforms (1.25: smaller grids, wider kernels)
_UPSAMPFAC = 1.25


@dataclass(frozen=True)
class _Slab:
    """Targets in one depth slab and the geometry that sets its quadrature."""

    index: NDArray[np.int64]  # rows of the targets in this slab
    z_a: float  # shallowest depth of the slab (m)
    z_b: float  # deepest target depth (m)
    rho: float  # largest lateral source–target distance (m)


def _slabs(sources: NDArray, targets: NDArray, ratio: float) -> list[_Slab]:
    """Group targets in depth slabs [z_a, ratio·z_a) (sorted by depth)."""
    order = np.argsort(targets[:, 2], kind="stable")
    z = targets[order, 2]
    sx0, sx1 = float(sources[:, 0].min()), float(sources[:, 0].max())
    sy0, sy1 = float(sources[:, 1].min()), float(sources[:, 1].max())
    out = []
    start = 0
    while start < z.size:
        z_a = float(z[start])
        stop = int(np.searchsorted(z, z_a * ratio, side="left"))
        stop = max(stop, start + 1)
        idx = order[start:stop]
        t = targets[idx]
        dx = max(float(t[:, 0].max()) - sx0, sx1 - float(t[:, 0].min()))
        dy = max(float(t[:, 1].max()) - sy0, sy1 - float(t[:, 1].min()))
        out.append(_Slab(idx, z_a, float(z[stop - 1]), math.hypot(dx, dy)))
        start = stop
    return out


def _window(theta: NDArray, theta_geo: float, delta: float) -> NDArray:
    """Angular window: 1 up to θ_geo + δ, an erfc step of width σ = δ/4 centred 4.2 σ
    further (≤ 1e-9 from 1 before and from 0 after), 0 from θ_geo + 3.1 δ on.

    A Gaussian-edged window: a stationary direction θ0 ≤ θ_geo leaks through its edge
    like ``exp(−(kR (θ_mid − θ0) σ)²/2)`` (the Fourier transform of the edge), ≤ e^{−10}
    for δ = 3/√(k z_a) (the default 4: e^{−33}).
    """
    from scipy.special import erfc

    sigma = 0.25 * delta
    mid = theta_geo + delta + 4.2 * sigma
    return np.where(theta >= mid + 4.2 * sigma, 0.0, 0.5 * erfc((theta - mid) / sigma))


@lru_cache(maxsize=64)
def _gauss_legendre(n: int) -> tuple[NDArray, NDArray]:
    """Gauss–Legendre nodes and weights on [−1, 1] (scipy's O(n) rule; cached)."""
    from scipy.special import roots_legendre

    x, w = roots_legendre(n)
    return np.asarray(x), np.asarray(w)


def _rings(counts: NDArray) -> tuple[NDArray, NDArray]:
    """Azimuths (midpoint rule, 2π-periodic) of rings with ``counts`` nodes and ring index."""
    ring = np.repeat(np.arange(counts.size), counts)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    j = np.arange(int(counts.sum())) - starts[ring]
    return (j + 0.5) * (2 * math.pi / counts[ring]), ring


def _propagating_nodes(k: float, slab: _Slab, margin: float, oversampling: float
                       ) -> tuple[NDArray, NDArray, NDArray, NDArray, bool]:
    """Hemisphere nodes (kx, ky, kz), weights (with k sinθ dθ dφ) and whether windowed."""
    theta_geo = math.atan2(slab.rho, slab.z_a)
    delta = margin / math.sqrt(k * slab.z_a)
    theta_c = theta_geo + 3.1 * delta
    windowed = theta_c < 0.5 * math.pi
    if not windowed:
        theta_c = 0.5 * math.pi
    r_max = math.hypot(slab.rho, slab.z_b)
    n_theta = math.ceil(oversampling * k * r_max * theta_c / math.pi) + 20
    xg, wg = _gauss_legendre(n_theta)
    theta = (xg + 1) * (0.5 * theta_c)
    w_theta = wg * (0.5 * theta_c)
    if windowed:
        w_theta = w_theta * _window(theta, theta_geo, delta)
    n_phi = (np.ceil(oversampling * k * slab.rho * np.sin(theta)) + 24).astype(np.int64)
    phi, ring = _rings(n_phi)
    st = np.sin(theta)[ring]
    kx, ky, kz = k * st * np.cos(phi), k * st * np.sin(phi), k * np.cos(theta)[ring]
    weights = k * st * w_theta[ring] * (2 * math.pi / n_phi[ring])
    return kx, ky, kz, weights, windowed


def _node_count(k: float, slab: _Slab, margin: float, decay: float, oversampling: float
                ) -> tuple[int, bool]:
    """Number of wavenumber nodes of a slab (propagating + evanescent) and whether windowed."""
    theta_geo = math.atan2(slab.rho, slab.z_a)
    delta = margin / math.sqrt(k * slab.z_a)
    theta_c = min(theta_geo + 3.1 * delta, 0.5 * math.pi)
    windowed = theta_c < 0.5 * math.pi
    n_theta = math.ceil(oversampling * k * math.hypot(slab.rho, slab.z_b) * theta_c
                            / math.pi) + 20
    xg, _ = _gauss_legendre(n_theta)
    count = int(np.sum(np.ceil(oversampling * k * slab.rho * np.sin((xg + 1) * 0.5 * theta_c))
                       + 24))
    if not windowed:
        kappa_max = decay / slab.z_a
        kt_max = math.hypot(k, kappa_max)
        n_kappa = math.ceil(oversampling * slab.rho * (kt_max - k)) + 30
        xk, _ = _gauss_legendre(n_kappa)
        kt = np.sqrt(k * k + ((xk + 1) * 0.5 * kappa_max) ** 2)
        count += int(np.sum(np.ceil(oversampling * kt * slab.rho) + 24))
    return count, windowed


def plane_wave_cost(source_points: ArrayLike, targets: ArrayLike, frequencies: ArrayLike,
                    medium: Medium, *, slab_ratio: float = 2.0, window_margin: float = 4.0,
                    evanescent_decay: float = math.log(1e6), oversampling: float = 1.0,
                    samples: int = 4) -> tuple[float, float]:
    """Work of :func:`rayleigh_plane_waves`: wavenumber nodes and target terms, summed over bins.

    Counts the nodes of every slab at ``samples`` frequencies spread over
    ``frequencies`` and scales them by k² (the node count of a slab grows as k²) to
    all bins; target terms are one per target and bin plus, in slabs that need the
    evanescent part, one per Chebyshev term.

    Returns
    -------
    (float, float)
        Total nodes and total target terms over the bins (what the cost model of
        ``predict_field(method="auto")`` weighs).
    """
    src = np.asarray(source_points, dtype=float).reshape(-1, np.shape(source_points)[-1])
    pts = np.asarray(targets, dtype=float).reshape(-1, 3)
    f = np.sort(np.asarray(frequencies, dtype=float).reshape(-1))
    slabs = _slabs(src, pts, slab_ratio)
    pick = f[np.unique(np.linspace(0, f.size - 1, max(1, samples)).round().astype(int))]
    nodes = terms = 0.0
    for fp in pick:
        k = 2 * math.pi * fp / medium.sound_speed
        share = float(np.sum((f / fp) ** 2)) / pick.size  # bins this sample stands for, × k²
        for slab in slabs:
            count, windowed = _node_count(k, slab, window_margin, evanescent_decay,
                                          oversampling)
            nodes += share * count
            extra = 0 if windowed else math.ceil(
                0.6 * evanescent_decay * (slab.z_b - slab.z_a) / slab.z_a + 10)
            terms += (f.size / pick.size) * slab.index.size * (1 + extra)
    return nodes, terms


def _evanescent_nodes(k: float, slab: _Slab, decay: float, oversampling: float
                      ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Evanescent nodes (kx, ky), κ and weights (−i dκ dφ without the −i) for a slab."""
    kappa_max = decay / slab.z_a
    kt_max = math.hypot(k, kappa_max)
    n_kappa = math.ceil(oversampling * slab.rho * (kt_max - k)) + 30
    xg, wg = _gauss_legendre(n_kappa)
    kappa = (xg + 1) * (0.5 * kappa_max)
    w_kappa = wg * (0.5 * kappa_max)
    kt = np.sqrt(k * k + kappa * kappa)
    n_phi = (np.ceil(oversampling * kt * slab.rho) + 24).astype(np.int64)
    phi, ring = _rings(n_phi)
    ktr = kt[ring]
    return (ktr * np.cos(phi), ktr * np.sin(phi), kappa[ring],
            w_kappa[ring] * (2 * math.pi / n_phi[ring]))


def _chebyshev(depth: NDArray, z_a: float, z_b: float, kappa_span: float
               ) -> tuple[NDArray, NDArray]:
    """Chebyshev nodes in [z_a, z_b] and the interpolation weights (n_targets, m) at ``depth``.

    ``e^{−κ(z − z_a)}`` for κ ≤ ``kappa_span`` is interpolated to ≲ 1e-8 by m =
    ⌈0.6 a + 10⌉ Chebyshev points, a = κ (z_b − z_a) (measured for a ≤ 14; its Chebyshev
    coefficients decay like I_n(a/2) e^{−a/2}).
    """
    span = max(z_b - z_a, 0.0)
    m = math.ceil(0.6 * kappa_span * span + 10) if span > 0 else 1
    if m == 1:
        return np.array([z_a]), np.ones((depth.size, 1))
    j = np.arange(m)
    nodes = z_a + 0.5 * span * (1 - np.cos((2 * j + 1) * math.pi / (2 * m)))
    bary = (-1.0) ** j * np.sin((2 * j + 1) * math.pi / (2 * m))
    diff = depth[:, None] - nodes[None, :]
    exact = np.abs(diff) < 1e-300
    diff[exact] = 1.0
    w = bary[None, :] / diff
    w /= w.sum(axis=1, keepdims=True)
    hit = np.flatnonzero(exact.any(axis=1))
    if hit.size:
        w[hit] = exact[hit].astype(float)
    return nodes, w


def rayleigh_plane_waves(
    values: ArrayLike,
    source_points: ArrayLike,
    source_weights: ArrayLike,
    targets: ArrayLike,
    frequencies: ArrayLike,
    medium: Medium,
    *,
    eps: float = 1e-5,
    slab_ratio: float = 2.0,
    window_margin: float = 4.0,
    evanescent_decay: float = math.log(1e6),
    oversampling: float = 1.0,
    dtype: DTypeLike = np.complex128,
    progress: Callable[[int, int], None] | None = None,
) -> NDArray[np.complexfloating]:
    """Forward Rayleigh integral (``fwd_vp``, rigid baffle) at scattered points, by NUFFTs.

    The same sum as :func:`holoprobe.propagation.rayleigh_integral` with
    ``kernel="fwd_vp"`` for point sources on the plane z = 0 (``Σ_q V_q ΔA_q
    (−ikρ0c0/2π) e^{ikR}/R``), evaluated through Weyl's plane-wave expansion (see the
    module notes): per frequency one 2-D type-3 NUFFT (sources → wavenumber nodes) and,
    per depth slab of targets, one 3-D type-3 NUFFT (propagating waves) plus batched 2-D
    ones (evanescent waves, near the face). Its cost grows with (k·D)² per frequency
    (D the extent of sources and targets) and linearly with the number of targets, not
    with their product.

    Parameters
    ----------
    values : array_like, complex, shape (n_sources, nf)
        Normal velocity V in m/s·s (holoprobe's Fourier convention) at each source.
    source_points : array_like, shape (n_sources, 3) or (n_sources, 2)
        Source positions in m; z must be 0.
    source_weights : array_like, shape (n_sources,)
        Areas ΔA in m².
    targets : array_like, shape (n, 3)
        Points in m, z > 0.
    frequencies : array_like, shape (nf,)
        Positive frequencies in Hz.
    medium : Medium
        Sound speed and density.
    eps : float
        NUFFT tolerance (finufft ``eps``, relative to the sum of the plane-wave
        amplitudes): the error relative to the largest pressure is about ``eps``.
    slab_ratio : float
        Depth slabs span ``[z_a, slab_ratio·z_a)`` (> 1).
    window_margin : float
        Width δ of the angular window's taper in units of 1/√(k z_a) rad (the window
        passes θ ≤ atan(ρ/z_a) + δ, its erfc edge is centred at + 2.05 δ and it ends
        at + 3.1 δ); 4 leaks ≲ e^{−33}, 3 ≲ 1e-4 (measured on a point source).
    evanescent_decay : float
        Evanescent waves are kept while ``e^{−κ z} ≥ e^{−evanescent_decay}``.
    oversampling : float
        Factor on the numbers of quadrature nodes (1: below 1e-5 of the peak).
    dtype : {numpy.complex128, numpy.complex64}
        Output precision (the transforms run in double precision).
    progress : callable(done, total), optional
        Called after each frequency.

    Returns
    -------
    ndarray, complex, shape (n, nf)
        Pressure spectrum in Pa·s.
    """
    import finufft

    f = np.asarray(frequencies, dtype=float).reshape(-1)
    if f.size == 0 or not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise InputError("expected positive, finite frequencies in Hz", field="frequencies")
    src = np.asarray(source_points, dtype=float)
    if src.ndim != 2 or src.shape[1] not in (2, 3):
        raise InputError(f"expected source points of shape (n, 3), got {src.shape}",
                         field="source_points")
    if src.shape[1] == 3 and np.any(src[:, 2] != 0):
        raise InputError("expected sources on the plane z = 0", field="source_points")
    vals = np.asarray(values).reshape(src.shape[0], -1)
    if vals.shape[1] != f.size:
        raise InputError(f"expected values of shape ({src.shape[0]}, {f.size}), got "
                         f"{np.shape(values)}", field="values")
    area = np.asarray(source_weights, dtype=float).reshape(-1)
    pts = np.asarray(targets, dtype=float).reshape(-1, 3)
    if pts.size == 0 or not np.all(np.isfinite(pts)) or np.any(pts[:, 2] <= 0):
        raise InputError("expected finite target points with z > 0", field="targets")
    if not (slab_ratio > 1 and window_margin > 0 and evanescent_decay > 0 and eps > 0
            and oversampling > 0):
        raise InputError("expected slab_ratio > 1 and positive window_margin, "
                         "evanescent_decay, eps and oversampling", field="rayleigh_plane_waves")
    slabs = _slabs(src, pts, slab_ratio)
    out: NDArray[np.complexfloating] = np.empty((pts.shape[0], f.size), dtype=dtype)
    sx, sy = np.ascontiguousarray(src[:, 0]), np.ascontiguousarray(src[:, 1])
    for b, fb in enumerate(f):
        k = 2 * math.pi * fb / medium.sound_speed
        q = np.ascontiguousarray(vals[:, b] * area, dtype=np.complex128)
        scale = k * medium.density * medium.sound_speed / (4 * math.pi**2)
        out[:, b] = _one_frequency(k, q, sx, sy, pts, slabs, scale, eps, window_margin,
                                   evanescent_decay, oversampling, finufft)
        if progress is not None:
            progress(b + 1, f.size)
    return out


def _one_frequency(k: float, q: NDArray, sx: NDArray, sy: NDArray, pts: NDArray,
                   slabs: list[_Slab], scale: float, eps: float, margin: float,
                   decay: float, oversampling: float, finufft) -> NDArray:
    """Pressure at every target for one wavenumber k (see rayleigh_plane_waves)."""
    nodes = []
    for slab in slabs:
        kx, ky, kz, w, windowed = _propagating_nodes(k, slab, margin, oversampling)
        ev = None if windowed else _evanescent_nodes(k, slab, decay, oversampling)
        nodes.append((kx, ky, kz, w, ev))
    # the source spectrum Û at every node of every slab in one transform
    all_kx = np.concatenate([np.concatenate([n[0]] + ([n[4][0]] if n[4] else []))
                             for n in nodes])
    all_ky = np.concatenate([np.concatenate([n[1]] + ([n[4][1]] if n[4] else []))
                             for n in nodes])
    u_hat = finufft.nufft2d3(sx, sy, q, all_kx, all_ky, eps=0.1 * eps, isign=-1)
    result = np.empty(pts.shape[0], dtype=np.complex128)
    pos = 0
    for slab, (kx, ky, kz, w, ev) in zip(slabs, nodes, strict=True):
        t = pts[slab.index]
        tx, ty, tz = (np.ascontiguousarray(t[:, i]) for i in range(3))
        c = scale * u_hat[pos:pos + kx.size] * w
        pos += kx.size
        p = finufft.nufft3d3(kx, ky, kz, c, tx, ty, tz, eps=eps, isign=1, upsampfac=_UPSAMPFAC)
        if ev is not None:
            ekx, eky, kappa, ew = ev
            ce = (-1j * scale) * u_hat[pos:pos + ekx.size] * ew
            pos += ekx.size
            z_nodes, interp = _chebyshev(tz, slab.z_a, slab.z_b, decay / slab.z_a)
            batch = np.ascontiguousarray(ce[None, :] * np.exp(-kappa[None, :] * z_nodes[:, None]))
            pe = finufft.nufft2d3(ekx, eky, batch, tx, ty, eps=eps, isign=1)
            p = p + np.einsum("mn,nm->n", pe.reshape(z_nodes.size, -1), interp)
        result[slab.index] = p
    return result
