"""Numba kernel behind :meth:`PlaneWaveField.derivatives` (private).

The alignment's Newton iterations evaluate, at one point at a time, the plane-wave sum
p = Σ c e^{ik·r} with its gradient and Hessian over 10⁵ waves (171² scans). One fused
pass (cos, sin and ten accumulations per wave, the waves split between the threads)
replaces the complex exponential, its real and imaginary copies and three matrix
products of the NumPy expression. numba's workqueue threading layer must not be entered
from two threads at once (it aborts the process): ``plane_wave_sums_serial`` is the same
kernel without threads, for callers on worker threads (the Monte-Carlo draws). The two
are two Python functions, not one compiled twice: numba's cache names its files by the
function's name and line and keys them by signature and bytecode, not by ``parallel``,
so one function compiled both ways would load either from the other's cache file.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

import holoprobe._numba  # noqa: F401  (threading layer, before any kernel runs)

__all__ = ["plane_wave_sums", "plane_wave_sums_serial"]

_CHUNKS = 16  # wave blocks summed in parallel (partial sums added in a fixed order)


@njit(nogil=True, cache=True)
def _block(kv, cre, cim, point, b):  # pragma: no cover - compiled
    """The 20 real sums of :func:`plane_wave_sums` over the waves of chunk ``b`` (of
    ``_CHUNKS`` equal runs of the waves)."""
    m = kv.shape[0]
    size = (m + _CHUNKS - 1) // _CHUNKS
    acc = np.zeros(20)
    x, y, z = point[0], point[1], point[2]
    for j in range(b * size, min(m, (b + 1) * size)):
        kx, ky, kz = kv[j, 0], kv[j, 1], kv[j, 2]
        ph = kx * x + ky * y + kz * z
        c, s = math.cos(ph), math.sin(ph)
        tr = cre[j] * c - cim[j] * s
        ti = cre[j] * s + cim[j] * c
        f = (1.0, kx, ky, kz, kx * kx, kx * ky, kx * kz, ky * ky, ky * kz, kz * kz)
        for q in range(10):
            acc[2 * q] += f[q] * tr
            acc[2 * q + 1] += f[q] * ti
    return acc


@njit(nogil=True, cache=True)
def _total(part):  # pragma: no cover - compiled
    """The chunks' partial sums added in a fixed order, as (10,) complex."""
    tot = np.zeros(20)
    for b in range(part.shape[0]):
        tot += part[b]
    out = np.empty(10, np.complex128)
    for q in range(10):
        out[q] = tot[2 * q] + 1j * tot[2 * q + 1]
    return out


@njit(parallel=True, nogil=True, cache=True)
def plane_wave_sums(kv, cre, cim, point):  # pragma: no cover - compiled
    """Σ_κ t_κ · (1, k_x, k_y, k_z, k_x k_x, k_x k_y, k_x k_z, k_y k_y, k_y k_z, k_z k_z)
    with t_κ = c_κ e^{i k_κ·point}.

    Parameters
    ----------
    kv : (m, 3) float64
        Wave vectors in rad/m.
    cre, cim : (m,) float64
        Real and imaginary parts of the coefficients.
    point : (3,) float64
        m.

    Returns
    -------
    (10,) complex128
    """
    part = np.zeros((_CHUNKS, 20))
    for b in prange(_CHUNKS):
        part[b] = _block(kv, cre, cim, point, b)
    return _total(part)


@njit(nogil=True, cache=True)
def plane_wave_sums_serial(kv, cre, cim, point):  # pragma: no cover - compiled
    """:func:`plane_wave_sums` on the calling thread only (the same chunks, the same sums)."""
    part = np.zeros((_CHUNKS, 20))
    for b in range(_CHUNKS):
        part[b] = _block(kv, cre, cim, point, b)
    return _total(part)
