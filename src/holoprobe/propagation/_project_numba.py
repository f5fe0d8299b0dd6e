"""Numba kernel behind :mod:`holoprobe.propagation._project` (private).

For one frequency it turns the propagating part of a padded angular spectrum into
the non-uniform points and strengths of a type-1 NUFFT onto a target plane, in one
pass over the spectrum in memory order: kz, the phase of every plane wave (grid
origin, plane poses, time origin, all linear in the wave vector), the optional
normal-velocity factor and the in-plane target coordinates. Fusing these replaces
about ten NumPy passes over the components.
"""

from __future__ import annotations

import math

from numba import njit

import holoprobe._numba  # noqa: F401  (threading layer, before any kernel runs)
from holoprobe.propagation._rayleigh_numba import sincos64

__all__ = ["group_terms", "plane_wave_terms"]


@njit(nogil=True, fastmath=True, error_model="numpy", cache=True)
def plane_wave_terms(spectrum, kx, ky, k, phase_vector, phase_const, x_map, y_map,
                     velocity_vector, use_velocity, scale, out_c, out_x,
                     out_y, out_i, out_j, s_in=2.0, s_out=2.0):  # pragma: no cover - compiled
    """Strengths and target-plane coordinates of the propagating plane waves (κ² < k²),
    faded out by the image taper between ``s_in`` and ``s_out``.

    Parameters
    ----------
    spectrum : (npx, npy) complex128
        Padded FFT of the data at this frequency (read row by row, contiguously).
    kx, ky : (npx,), (npy,) float64
        In-plane wave numbers of the source plane (FFT order).
    k : float
        Wave number in rad/m.
    phase_vector : (3,) float64
        G with phase = G · (κx, κy, kz) + ``phase_const``.
    x_map, y_map : (3,) float64
        Rows of the map from the local wave vector to the NUFFT coordinates on the
        target plane (target step included).
    velocity_vector : (3,) float64
        Target normal in source-plane coordinates over (k ρ0 c0), if ``use_velocity``.
    scale : float
        Constant factor (quadrature weights and 1/4π²).
    out_c : (npx·npy,) complex
        Strengths (the first ``count`` are written).
    out_x, out_y : (npx·npy,) real
        NUFFT coordinates in rad (the first ``count`` are written).
    out_i, out_j : (npx·npy,) int32
        Row and column of each wave in ``spectrum`` (for the adjoint's scatter).
    s_in, s_out : float
        The image taper (:func:`~holoprobe.propagation.image_taper_range`): the waves of
        sin θ = |κ|/k ≥ ``s_out`` (< 1) are left out, those between ``s_in`` and
        ``s_out`` weighted by the raised cosine ``½ + ½ cos(π (sin θ − s_in)/(s_out −
        s_in))``. Default (2, 2): no taper.

    Returns
    -------
    int
        ``count``, the number of waves written.
    """
    k2 = k * k
    cut = s_out < 1.0
    k_out2 = k2 * s_out * s_out  # with a cut: the waves kept have |κ|² < k_out2
    tapered = s_in < s_out
    count = 0
    for i in range(kx.shape[0]):
        a = kx[i]
        rest = k2 - a * a
        if rest <= 0.0 or (cut and a * a >= k_out2):
            continue
        for j in range(ky.shape[0]):
            b = ky[j]
            c2 = rest - b * b
            if c2 <= 0.0:
                continue
            amp = scale
            if cut or tapered:
                kr2 = a * a + b * b
                if cut and kr2 >= k_out2:
                    continue
                sin_t = math.sqrt(kr2) / k
                if tapered and sin_t > s_in:
                    amp *= 0.5 + 0.5 * math.cos(math.pi * (sin_t - s_in) / (s_out - s_in))
            c = math.sqrt(c2)
            s, co = sincos64(phase_vector[0] * a + phase_vector[1] * b + phase_vector[2] * c
                             + phase_const)
            if use_velocity:
                amp *= velocity_vector[0] * a + velocity_vector[1] * b + velocity_vector[2] * c
            v = spectrum[i, j] * amp
            out_c[count] = v * complex(co, s)
            out_x[count] = x_map[0] * a + x_map[1] * b + x_map[2] * c
            out_y[count] = y_map[0] * a + y_map[1] * b + y_map[2] * c
            out_i[count] = i
            out_j[count] = j
            count += 1
    return count


@njit(nogil=True, fastmath=True, error_model="numpy", cache=True)
def group_terms(c, xs, kernel, shift, m, out_phase):  # pragma: no cover - compiled
    """Plane-wave strengths summed over a group of target columns, in place.

    ``c[n] *= Σ_q kernel[q] e^{iξ_n (q + shift)}`` (Horner in ``e^{iξ}``) and
    ``out_phase[n] = m ξ_n`` wrapped to [−π, π): the coordinates of a type-1 NUFFT
    with one mode per group of ``m`` columns
    (:meth:`holoprobe.propagation.ProjectionPlan.project_reduced`).

    Parameters
    ----------
    c : (n,) complex
        Strengths (overwritten).
    xs : (n,) real
        NUFFT coordinates ξ (rad) along the target's columns.
    kernel : (m,) complex128
        Column weights of one group.
    shift : int
        Mode offset of the group's first column.
    m : int
        Columns per group.
    out_phase : (n,) real
        Written: the group coordinates.
    """
    two_pi = 2.0 * math.pi
    top = kernel.shape[0] - 1
    for n in range(c.shape[0]):
        x = float(xs[n])
        s, co = sincos64(x)
        z = complex(co, s)
        acc = kernel[top]
        for q in range(top - 1, -1, -1):
            acc = acc * z + kernel[q]
        if shift != 0:  # 0 for an even number of groups
            s, co = sincos64(shift * x)
            acc = acc * complex(co, s)
        c[n] = c[n] * acc
        g = m * x + math.pi
        out_phase[n] = g - two_pi * math.floor(g / two_pi) - math.pi
