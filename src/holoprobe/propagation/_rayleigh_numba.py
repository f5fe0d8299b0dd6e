"""Numba kernels behind :mod:`holoprobe.propagation._rayleigh` (private).

Three pieces:

* a vectorisable, branch-free ``sincos`` (Cody–Waite reduction by π/2 in three
  parts, fdlibm minimax polynomials on [−π/4, π/4]). The PyPI llvmlite has no
  SVML, so ``math.sin``/``math.cos`` stay scalar calls; this inline version lets
  LLVM vectorise the inner loops (about 20× faster here, see DEPENDENCIES.md).
  Accuracy ~1e-16 absolute in float64 for |x| < 1e6 rad. The float32 variant
  reduces the argument in float64 (the phase kR reaches ~400 rad and more) and
  evaluates a shorter polynomial in float32 (~6e-8 absolute).
* the dense frequency-domain Rayleigh kernel :func:`rayleigh_kernel`, parallel
  over output points, tiled over input points, with the phasor recurrence over a
  uniform frequency grid;
* the time-domain delay-and-sum kernel :func:`delay_and_sum` (cubic Lagrange
  interpolation of an upsampled signal) and :func:`distance_range`.

The sincos helpers are compiled *without* ``reassoc``: a reassociating compiler
may fold ``(x − q·P1) − q·P2`` into ``x − q·(P1 + P2)`` and lose the exactness of
the reduction. The kernels that call them use ``fastmath=True`` so that the
reductions over source points vectorise; LLVM inlines the helpers and keeps
their stricter per-instruction flags.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange, types
from numba.extending import overload

import holoprobe._numba  # noqa: F401  (threading layer, before any kernel runs)

__all__ = [
    "BAFFLE_CODES",
    "KERNEL_CODES",
    "delay_and_sum",
    "distance_range",
    "rayleigh_kernel",
    "sincos64",
    "sincos_f32",
]

KERNEL_CODES = {"fwd_vp": 0, "fwd_pp": 1, "bwd_pp": 2, "bwd_pv": 3}
BAFFLE_CODES = {"rigid": 0, "soft": 1, "free": 2}

_STRICT = {"nnan", "ninf", "nsz", "contract"}

# Cody–Waite split of π/2 (fdlibm e_rem_pio2.c): 33 + 33 + 53 bits.
_TWO_OVER_PI = 6.36619772367581382433e-01
_PIO2_1 = 1.57079632673412561417e00
_PIO2_2 = 6.07710050630396597660e-11
_PIO2_3 = 2.02226624871116645580e-21
# fdlibm k_sin.c / k_cos.c minimax coefficients on [−π/4, π/4].
_S1 = -1.66666666666666324348e-01
_S2 = 8.33333333332248946124e-03
_S3 = -1.98412698298579493134e-04
_S4 = 2.75573137070700676789e-06
_S5 = -2.50507602534068634195e-08
_S6 = 1.58969099521155010221e-10
_C1 = 4.16666666666666019037e-02
_C2 = -1.38888888888741095749e-03
_C3 = 2.48015872894767294178e-05
_C4 = -2.75573143513906633035e-07
_C5 = 2.08757232129817482790e-09
_C6 = -1.13596475577881948265e-11
# Cephes sinf/cosf coefficients (single precision, [−π/4, π/4]).
_FS1 = np.float32(-1.6666654611e-1)
_FS2 = np.float32(8.3321608736e-3)
_FS3 = np.float32(-1.9515295891e-4)
_FC1 = np.float32(4.166664568298827e-2)
_FC2 = np.float32(-1.388731625493765e-3)
_FC3 = np.float32(2.443315711809948e-5)
_F_HALF = np.float32(0.5)
_F_ONE = np.float32(1.0)


@njit(fastmath=_STRICT, error_model="numpy", cache=True)
def _reduce(x):  # pragma: no cover - compiled
    """x = q·π/2 + r with |r| ≤ π/4; returns (r, quadrant q mod 4 as a float)."""
    # np.floor keeps q a float: math.floor returns an integer, and float ↔ int64
    # conversions do not vectorise on AVX2
    q = np.floor(x * _TWO_OVER_PI + 0.5)
    r = ((x - q * _PIO2_1) - q * _PIO2_2) - q * _PIO2_3
    j = q - 4.0 * np.floor(q * 0.25)
    return r, j


@njit(fastmath=_STRICT, error_model="numpy", cache=True)
def sincos64(x):  # pragma: no cover - compiled
    """(sin x, cos x) in float64, branch-free and vectorisable."""
    r, j = _reduce(x)
    z = r * r
    s = r + r * z * (_S1 + z * (_S2 + z * (_S3 + z * (_S4 + z * (_S5 + z * _S6)))))
    c = 1.0 - 0.5 * z + z * z * (_C1 + z * (_C2 + z * (_C3 + z * (_C4 + z * (_C5 + z * _C6)))))
    odd = j == 1.0 or j == 3.0
    sn = c if odd else s
    cs = s if odd else c
    sn = -sn if j >= 2.0 else sn
    cs = -cs if (j == 1.0 or j == 2.0) else cs
    return sn, cs


@njit(fastmath=_STRICT, error_model="numpy", cache=True)
def sincos_f32(x):  # pragma: no cover - compiled
    """(sin x, cos x) in float32 for a float64 argument (reduction in float64)."""
    r64, j = _reduce(x)
    r = np.float32(r64)
    z = r * r
    s = r + r * z * (_FS1 + z * (_FS2 + z * _FS3))
    c = _F_ONE - _F_HALF * z + z * z * (_FC1 + z * (_FC2 + z * _FC3))
    odd = j == 1.0 or j == 3.0
    sn = c if odd else s
    cs = s if odd else c
    sn = -sn if j >= 2.0 else sn
    cs = -cs if (j == 1.0 or j == 2.0) else cs
    return sn, cs


def _sincos_like(x, like):  # pragma: no cover - compiled code uses the overload below
    """(sin x, cos x) in the precision of ``like`` (pure-Python reference of the overload)."""
    dtype = np.asarray(like).dtype
    return np.sin(x).astype(dtype), np.cos(x).astype(dtype)


@overload(_sincos_like)
def _sincos_like_impl(x, like):  # pragma: no cover - compiled
    if like == types.float32:
        return lambda x, like: sincos_f32(x)
    return lambda x, like: sincos64(x)


@njit(parallel=True, fastmath=True, error_model="numpy", cache=True)
def rayleigh_kernel(src, src_n, src_off, wv_re, wv_im, dst, dst_n, k, k_real, dk, uniform,
                    resync, kind, baffle, sign, r0, tile, out_re, out_im,
                    n_zero):  # pragma: no cover
    """Dense Rayleigh sum for all output points (see ``_rayleigh.rayleigh_integral``).

    For output point j and frequency n::

        out[j, n] = Σ_i wv[n, i] · (g0 + k_n² g2 + i k_n g1)(i, j)
                    · exp(i k_n (sign·(R − r0) + off_i))

    with the geometric factors g0, g1, g2 of the kernel ``kind`` (the per-frequency
    prefactor is applied by the caller).

    Parameters
    ----------
    src, src_n : (3, ns) float64
        Input points and their unit normals, coordinate-major (structure of arrays,
        so that the loops over input points vectorise).
    src_off : (ns,) float64
        Extra path length per input point in m (a per-source delay times c0).
    wv_re, wv_im : (nf, ns) or (1, ns) real
        Real and imaginary parts of weight × value, frequency-major; a single row
        is shared by all frequencies (values that do not depend on frequency, read
        from cache instead of memory for every output point).
    dst, dst_n : (nt, 3) float64
        Output points and their unit normals.
    k : (nf,) float64
        Wavenumbers (phase arithmetic); ``k_real`` the same in the output precision.
    dk : float
        Wavenumber step when ``uniform``.
    uniform : bool
        Use the phasor recurrence exp(i k_{n+1} R) = exp(i k_n R)·exp(i Δk R).
    resync : int
        Re-evaluate the phasor directly every ``resync`` bins (bounds the drift).
    kind, baffle : int
        Codes of ``KERNEL_CODES`` and ``BAFFLE_CODES``.
    sign : float
        +1 forward (e^{+ikR}), −1 backward (e^{−ikR}).
    r0 : float
        Time-origin distance in m.
    tile : int
        Number of input points processed per tile (scratch stays in L1/L2).
    out_re, out_im : (nt, nf) float64
        Output sums (written).
    n_zero : (nt,) float64
        Number of input points at R = 0 from each output point (written).

    Notes
    -----
    Written so that LLVM vectorises every inner loop: structure-of-arrays inputs,
    no min/max reductions (a counter of R = 0 instead), ``error_model="numpy"``
    (no ZeroDivisionError branch), branch-free sincos.
    """
    nt = dst.shape[0]
    ns = src.shape[1]
    nf = k.shape[0]
    shared_row = wv_re.shape[0] == 1
    # fwd_vp with frequency-independent values: the term is (value·g0)·phasor, so the
    # product value·g0 is formed once per pair and each bin costs two complex products
    simple = shared_row and kind == 0
    like = k_real[0]
    # g0 = (b0 + b1 cf)/R · (q0 + q1/R), g1 = h1 cf/R for the kernels without g2
    b0, b1, q0, q1, h1 = 0.0, 1.0, 0.0, 1.0, 0.0
    if kind == 0:
        q0, q1 = 1.0, 0.0
        if baffle == 0:
            b0, b1 = 1.0, 0.0
        elif baffle == 2:
            b0, b1 = 0.5, 0.5
    elif kind == 1:
        h1 = -1.0
    elif kind == 2:
        h1 = 1.0
    for j in prange(nt):
        g0 = np.zeros(tile, k_real.dtype)
        g1 = np.zeros(tile, k_real.dtype)
        g2 = np.zeros(tile, k_real.dtype)
        ph_re = np.empty(tile, k_real.dtype)
        ph_im = np.empty(tile, k_real.dtype)
        st_re = np.empty(tile, k_real.dtype)
        st_im = np.empty(tile, k_real.dtype)
        c_re = np.empty(tile, k_real.dtype)
        c_im = np.empty(tile, k_real.dtype)
        dist = np.empty(tile, np.float64)
        acc_re = np.zeros(nf, np.float64)
        acc_im = np.zeros(nf, np.float64)
        xj = dst[j, 0]
        yj = dst[j, 1]
        zj = dst[j, 2]
        nxj = dst_n[j, 0]
        nyj = dst_n[j, 1]
        nzj = dst_n[j, 2]
        zeros = 0.0
        for i0 in range(0, ns, tile):
            m = min(tile, ns - i0)
            # geometry: u = (dst − src)/R, cf = u·n_src, ct = u·n_dst; one loop per
            # kernel so that each one vectorises
            if kind == 3:  # bwd_pv: {(n1·n2)(ik/R + 1/R²) + c1 c2 (3ik/R + 3/R² − k²)}/R
                for ii in range(m):
                    i = i0 + ii
                    ux = xj - src[0, i]
                    uy = yj - src[1, i]
                    uz = zj - src[2, i]
                    rr = math.sqrt(ux * ux + uy * uy + uz * uz)
                    zeros += 1.0 if rr == 0.0 else 0.0
                    dist[ii] = sign * (rr - r0) + src_off[i]
                    inv = 1.0 / rr
                    cf = (ux * src_n[0, i] + uy * src_n[1, i] + uz * src_n[2, i]) * inv
                    ct = -(ux * nxj + uy * nyj + uz * nzj) * inv  # m12·n1
                    nn = src_n[0, i] * nxj + src_n[1, i] * nyj + src_n[2, i] * nzj
                    cc = ct * cf
                    a = (nn + 3.0 * cc) * inv * inv
                    g0[ii] = a * inv
                    g1[ii] = a
                    g2[ii] = -cc * inv
            else:
                # fwd_vp: β/R with β = b0 + b1 cos θ; fwd_pp: (m12·n1)(−ik/R + 1/R²);
                # bwd_pp: (m21·n2)(ik/R + 1/R²)
                for ii in range(m):
                    i = i0 + ii
                    ux = xj - src[0, i]
                    uy = yj - src[1, i]
                    uz = zj - src[2, i]
                    rr = math.sqrt(ux * ux + uy * uy + uz * uz)
                    zeros += 1.0 if rr == 0.0 else 0.0
                    dist[ii] = sign * (rr - r0) + src_off[i]
                    inv = 1.0 / rr
                    cf = (ux * src_n[0, i] + uy * src_n[1, i] + uz * src_n[2, i]) * inv
                    g0[ii] = (b0 + b1 * cf) * inv * (q0 + q1 * inv)
                    g1[ii] = h1 * cf * inv
            if uniform:
                for ii in range(m):
                    s, c = _sincos_like(dk * dist[ii], like)
                    st_re[ii] = c
                    st_im[ii] = s
            if simple:
                for ii in range(m):
                    c_re[ii] = wv_re[0, i0 + ii] * g0[ii]
                    c_im[ii] = wv_im[0, i0 + ii] * g0[ii]
                for n in range(nf):
                    sr = like - like
                    si = like - like
                    if uniform and n % resync != 0:
                        for ii in range(m):
                            pr = ph_re[ii] * st_re[ii] - ph_im[ii] * st_im[ii]
                            pi = ph_re[ii] * st_im[ii] + ph_im[ii] * st_re[ii]
                            ph_re[ii] = pr
                            ph_im[ii] = pi
                            sr += c_re[ii] * pr - c_im[ii] * pi
                            si += c_re[ii] * pi + c_im[ii] * pr
                    else:
                        kp = k[n]
                        for ii in range(m):
                            pi, pr = _sincos_like(kp * dist[ii], like)
                            ph_re[ii] = pr
                            ph_im[ii] = pi
                            sr += c_re[ii] * pr - c_im[ii] * pi
                            si += c_re[ii] * pi + c_im[ii] * pr
                    acc_re[n] += sr
                    acc_im[n] += si
                continue
            for n in range(nf):
                kn = k_real[n]
                k2 = kn * kn
                kp = k[n]
                row = 0 if shared_row else n
                sr = like - like
                si = like - like
                if uniform and n % resync != 0:
                    for ii in range(m):
                        pr = ph_re[ii] * st_re[ii] - ph_im[ii] * st_im[ii]
                        pi = ph_re[ii] * st_im[ii] + ph_im[ii] * st_re[ii]
                        ph_re[ii] = pr
                        ph_im[ii] = pi
                        a = g0[ii] + k2 * g2[ii]
                        b = kn * g1[ii]
                        kr = a * pr - b * pi
                        ki = a * pi + b * pr
                        vr = wv_re[row, i0 + ii]
                        vi = wv_im[row, i0 + ii]
                        sr += vr * kr - vi * ki
                        si += vr * ki + vi * kr
                else:
                    for ii in range(m):
                        pi, pr = _sincos_like(kp * dist[ii], like)
                        ph_re[ii] = pr
                        ph_im[ii] = pi
                        a = g0[ii] + k2 * g2[ii]
                        b = kn * g1[ii]
                        kr = a * pr - b * pi
                        ki = a * pi + b * pr
                        vr = wv_re[row, i0 + ii]
                        vi = wv_im[row, i0 + ii]
                        sr += vr * kr - vi * ki
                        si += vr * ki + vi * kr
                acc_re[n] += sr
                acc_im[n] += si
        for n in range(nf):
            out_re[j, n] = acc_re[n]
            out_im[j, n] = acc_im[n]
        n_zero[j] = zeros


@njit(parallel=True, fastmath=True, error_model="numpy", cache=True)
def distance_range(a, b, out_min, out_max):  # pragma: no cover - compiled
    """Smallest and largest distance from each point of ``a`` (na, 3) to the points of ``b``."""
    for j in prange(a.shape[0]):
        lo = np.inf
        hi = 0.0
        for i in range(b.shape[0]):
            dx = a[j, 0] - b[i, 0]
            dy = a[j, 1] - b[i, 1]
            dz = a[j, 2] - b[i, 2]
            r = math.sqrt(dx * dx + dy * dy + dz * dz)
            lo = min(lo, r)
            hi = max(hi, r)
        out_min[j] = lo
        out_max[j] = hi


@njit(parallel=True, fastmath=True, error_model="numpy", cache=True)
def delay_and_sum(src, src_n, tgt, amp, delay, baffle, signal, row_of_src, pad, upsample,
                  rate_up, start_time, sound_speed, out):  # pragma: no cover - compiled
    """Add Σ_src amp·β/R · y(t − R/c0 − delay) to ``out`` (cubic Lagrange interpolation).

    Parameters
    ----------
    src, src_n : (ns, 3) float64
        Source points and unit normals.
    tgt : (nt, 3) float64
        Target points.
    amp : (ns,) float64
        Amplitude of each source (ρ0/(2π) · weight · apodisation).
    baffle : int
        Code of ``BAFFLE_CODES``: β = 1, cos θ or (1 + cos θ)/2.
    delay : (ns,) float64
        Extra delay per source in s.
    signal : (nrows, L) float64
        Upsampled signal rows (sample m at time (m − pad)/rate_up), zero-padded by
        ``pad`` ≥ 2 samples on both sides.
    row_of_src : (ns,) int64
        Row of ``signal`` each source uses.
    pad : int
        Zero samples in front of the signal.
    upsample : int
        Upsampled samples per output sample.
    rate_up : float
        Sampling rate of ``signal`` in Hz.
    start_time : float
        Time of output sample 0 in s.
    sound_speed : float
        c0 in m/s.
    out : (nt, n_out) float64
        Accumulated pressure (added to).
    """
    n_out = out.shape[1]
    length = signal.shape[1]
    for j in prange(tgt.shape[0]):
        for i in range(src.shape[0]):
            dx = tgt[j, 0] - src[i, 0]
            dy = tgt[j, 1] - src[i, 1]
            dz = tgt[j, 2] - src[i, 2]
            r = math.sqrt(dx * dx + dy * dy + dz * dz)
            a = amp[i] / r
            if baffle != 0:
                cos_t = (dx * src_n[i, 0] + dy * src_n[i, 1] + dz * src_n[i, 2]) / r
                a *= cos_t if baffle == 1 else 0.5 * (1.0 + cos_t)
            # position of output sample 0 in the padded upsampled signal
            x0 = (start_time - r / sound_speed - delay[i]) * rate_up + pad
            fl = math.floor(x0)
            mu = x0 - fl
            w0 = -mu * (mu - 1.0) * (mu - 2.0) / 6.0
            w1 = (mu + 1.0) * (mu - 1.0) * (mu - 2.0) * 0.5
            w2 = -(mu + 1.0) * mu * (mu - 2.0) * 0.5
            w3 = (mu + 1.0) * mu * (mu - 1.0) / 6.0
            base = np.int64(fl) - 1
            # output samples whose 4-point stencil lies inside [0, length)
            m_lo = 0
            if base < 0:
                m_lo = (-base + upsample - 1) // upsample
            last = length - 4 - base
            if last < 0:
                continue
            m_hi = min(n_out, last // upsample + 1)
            row = row_of_src[i]
            for mm in range(m_lo, m_hi):
                b = base + mm * upsample
                out[j, mm] += a * (w0 * signal[row, b] + w1 * signal[row, b + 1]
                                   + w2 * signal[row, b + 2] + w3 * signal[row, b + 3])
