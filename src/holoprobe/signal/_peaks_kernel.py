"""Numba kernel of :func:`holoprobe.signal.band_limited_peaks` (imported on first use, so
that ``import holoprobe.signal`` does not load numba)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

import holoprobe._numba  # noqa: F401  (threading layer, before any kernel runs)

__all__ = ["record_extremes"]


@njit(cache=True)
def _refine(p, i, sign, lut):  # pragma: no cover - compiled
    """Largest value of sign·p on the grid i−1 … i+1 (1/density steps), parabola-refined."""
    n = p.shape[0]
    density = lut.shape[0] - 1
    taps = lut.shape[1]
    first = 1 - taps // 2
    best, q_best = -1e300, 0
    y = np.empty(2 * density + 1)
    inside = i - 1 + first >= 0 and i + 1 + first + taps <= n
    for q in range(2 * density + 1):
        base = i - 1 + q // density + first
        row = q % density
        acc = 0.0
        if inside:
            for t in range(taps):
                acc += lut[row, t] * p[base + t]
        else:
            for t in range(taps):
                acc += lut[row, t] * p[(base + t) % n]
        acc *= sign
        y[q] = acc
        if acc > best:
            best, q_best = acc, q
    if 0 < q_best < 2 * density:
        ym, yp = y[q_best - 1], y[q_best + 1]
        curv = ym - 2.0 * best + yp
        if curv < 0.0:
            best -= 0.125 * (yp - ym) ** 2 / curv
    return best


@njit(parallel=True, cache=True, nogil=True)
def record_extremes(records, lut, margin, pos, neg):  # pragma: no cover - compiled
    """pos[r], neg[r] = max and −min of the band-limited interpolant of records[r]."""
    n_rec, n = records.shape
    for r in prange(n_rec):
        p = records[r]
        hi, lo, big = -1e300, 1e300, 0.0
        for i in range(n):
            v = float(p[i])
            hi = max(hi, v)
            lo = min(lo, v)
        big = max(hi, -lo)
        if big == 0.0:
            pos[r] = 0.0
            neg[r] = 0.0
            continue
        slack = margin * big
        best_hi, best_lo = hi, -lo
        for i in range(n):
            v = p[i]
            if v >= hi - slack:
                if v >= p[i - 1] and v >= p[(i + 1) % n]:
                    best_hi = max(best_hi, _refine(p, i, 1.0, lut))
            if v <= lo + slack:
                if v <= p[i - 1] and v <= p[(i + 1) % n]:
                    best_lo = max(best_lo, _refine(p, i, -1.0, lut))
        pos[r] = best_hi
        neg[r] = best_lo
