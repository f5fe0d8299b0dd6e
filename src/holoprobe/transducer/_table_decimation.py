"""Column-table spectra on every D-th frequency bin, interpolated to every bin.

A target's field spectrum is ``P(ω) = E(ω) G(ω)`` with the drive ``E`` known at every
bin and the spatial transfer function ``G(ω) = Σ_e a_e e^{iωτ_e} Σ_i C(ρ_{e,i}, v; ω)``
the spectrum of a sum of pulses that all arrive within the target's arrival bounds
``[t_min, t_max]`` (sources on the element rectangles, their delays and lens delays:
:func:`holoprobe.transducer._field._arrival_bounds`). Shifted to the middle of that
window, ``H(ω) = G(ω) e^{−iω t_c}`` is, as a function of frequency, band-limited to
the half-spread ``(t_max − t_min)/2``: on a grid of step ``D·Δf`` (``Δf = 1/T`` the
record's bin spacing) it is sampled at ``β = D (t_max − t_min)/T`` of its Nyquist
rate, and 16-tap least-squares weights (:func:`holoprobe.signal.interpolation_weights`,
≤ 2.3e-5 on plane waves for β ≤ 0.6) give it at every bin. A target whose arrivals
spread over ``s`` therefore needs the table kernel on only every ``D = ⌊0.6 T/s⌋``-th
bin (capped at :data:`MAX_ORDER`), plus 8 bins beyond each band edge (negative
frequencies by ``G(−ω) = conj G(ω)``; ``G(0) = 0``: the Rayleigh kernel carries a
factor ``−ik``). Unlike taking the record on every D-th bin, the interpolation
reproduces the band-limited record exactly, the ringing of its band edges
included (that ringing reaches 1.6e-3 of the peak pressure across a 500-sample record
of the P4-1 benchmark, so a plain D-fold shorter record does not hold 1e-4).

The table is made once for the union of the orders' bins (:func:`table_bins`) and split
into one table per order (:func:`order_tables`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from functools import lru_cache

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

import holoprobe._numba  # noqa: F401  (threading layer, before any kernel runs)
from holoprobe.errors import InputError
from holoprobe.signal import interpolation_weights
from holoprobe.transducer._model import VirtualTransducer
from holoprobe.transducer._tables import (
    MAX_TABLE_BYTES,
    ColumnTable,
    column_table,
    serving_handle,
    table_bytes,
    table_extent,
    table_field,
    target_rows,
)

__all__ = ["MAX_ORDER", "decimated_table_spectra", "decimation_orders", "largest_order",
           "order_bins",
           "order_tables", "table_bins", "table_frequencies", "unfold_spectra"]

#: largest decimation; interpolation taps; largest β = D·spread/T served
MAX_ORDER, TAPS, BETA = 4, 16, 0.6
#: highest table bin relative to the band's top: the table's step is λ_min/5 of the
#: band (:data:`holoprobe.transducer._tables.STEPS_PER_WAVELENGTH`), so 1.3 × its top
#: is 0.52 of the step's Nyquist, where the 8-tap weights still hold ≈ 2e-5 of the peak
TOP_MARGIN = 1.3
#: largest |H_T E_T| at the band's edge bins, relative to its peak, for which the
#: decimated path is taken: the table's bins beyond the band's top (≤ 1.3× it) are less
#: accurate, and the interpolation carries their error into the band weighted by the
#: drive there (a band cut at −12 dB read 1.4e-4 of the peak against the dense sum, at
#: −20/−30 dB 8–9.6e-5; the default −40 dB ≤ 2e-5). Wider bands take every bin.
EDGE_LEVEL = 10 ** (-35 / 20)


def largest_order(k_hi: int) -> int:
    """Largest decimation whose interpolation margin above the band's top bin k_hi
    stays within :data:`TOP_MARGIN` of it (1 when none does: short records)."""
    half = TAPS // 2
    ok = [d for d in range(2, MAX_ORDER + 1) if (k_hi // d + half) * d <= TOP_MARGIN * k_hi]
    return max(ok, default=1)


def decimation_orders(spread: NDArray, period: float, max_order: int = MAX_ORDER
                      ) -> NDArray[np.int64]:
    """Decimation D (1 … max_order) per target from its arrival spread (s) and the
    record period T (s): the largest D with ``D · spread ≤ 0.6 T``."""
    s = np.maximum(np.asarray(spread, dtype=float), 1e-30)
    return np.clip(np.floor(BETA * period / s), 1, max_order).astype(np.int64)


def order_bins(k_lo: int, k_hi: int, order: int) -> NDArray[np.int64]:
    """Positive bin indices (of the record's spacing) the table kernel evaluates for
    targets of decimation ``order`` whose band spans bins k_lo … k_hi."""
    if order == 1:
        return np.arange(k_lo, k_hi + 1, dtype=np.int64)
    half = TAPS // 2
    m = np.arange(k_lo // order - half + 1, k_hi // order + half + 1)
    return order * np.unique(np.abs(m[m != 0])).astype(np.int64)


def table_bins(k_lo: int, k_hi: int, max_order: int = MAX_ORDER) -> NDArray[np.int64]:
    """The table's bins: every bin from the lowest to the highest of :func:`order_bins`
    over the orders 1 … max_order. A uniform grid, so that the Rayleigh sum runs its
    phasor recurrence (the union alone, 129 of these 143 bins on the P4-1 benchmark,
    took 2.3× the CPU of the 103 band bins instead of 1.4×)."""
    every = np.concatenate([order_bins(k_lo, k_hi, d) for d in range(1, max_order + 1)])
    return np.arange(every.min(), every.max() + 1, dtype=np.int64)


def order_tables(table: ColumnTable, bins: NDArray, k_lo: int, k_hi: int,
                 max_order: int = MAX_ORDER) -> dict[int, ColumnTable]:
    """The table (made on ``bins``, :func:`table_bins`) split into one per order."""
    out = {}
    for d in range(1, max_order + 1):
        sel = np.searchsorted(bins, order_bins(k_lo, k_hi, d))
        out[d] = replace(table, values=np.ascontiguousarray(table.values[:, :, sel]),
                         frequencies=table.frequencies[sel])
    return out


@lru_cache(maxsize=8)
def _weights(order: int) -> NDArray[np.float64]:
    lut = interpolation_weights(TAPS, BETA, density=order)
    lut.setflags(write=False)
    return lut


def unfold_spectra(g: NDArray, order: int, k_lo: int, k_hi: int, df: float,
                   t_c: NDArray, drive: NDArray, *, out: NDArray | None = None,
                   rows: NDArray | None = None) -> NDArray[np.complexfloating]:
    """Spectra at every bin k_lo … k_hi from G on :func:`order_bins` (module doc).

    Parameters
    ----------
    g : ndarray, complex, shape (n, nb)
        ``G`` (without the drive) at ``order_bins(k_lo, k_hi, order)``.
    order : int
        Decimation D ≥ 2.
    k_lo, k_hi : int
        First and last bin of the band (bin k at k·df Hz).
    df : float
        Bin spacing in Hz.
    t_c : ndarray, shape (n,)
        Middle of each target's arrival window in s.
    drive : ndarray, complex, shape (k_hi − k_lo + 1,)
        The drive spectrum ``E`` at the band's bins.
    out : ndarray, complex, shape (N, k_hi − k_lo + 1), optional
        Written in place (g's dtype): target i goes to row ``rows[i]``.
    rows : ndarray of int, shape (n,), optional
        Rows of ``out`` (default ``0 … n − 1``).

    Returns
    -------
    ndarray, complex, shape (n, k_hi − k_lo + 1), or ``out``
        ``E(ω_k) G(ω_k)``, g's dtype.
    """
    bins = order_bins(k_lo, k_hi, order)
    if out is None:
        out = np.empty((g.shape[0], k_hi - k_lo + 1), dtype=g.dtype)
    if not (out.dtype == g.dtype and out.flags.c_contiguous and out.ndim == 2
            and out.shape[1] == k_hi - k_lo + 1):
        raise InputError(f"expected a C-contiguous {g.dtype} array of {k_hi - k_lo + 1} "
                         f"bins per row, got {out.dtype} {out.shape}", field="out")
    dst = target_rows(rows, g.shape[0], out)
    _unfold(np.ascontiguousarray(g), bins // order, order, k_lo, k_hi, 2 * math.pi * df,
            np.ascontiguousarray(t_c, dtype=float), _weights(order),
            np.ascontiguousarray(drive, dtype=np.complex128), dst, out)
    return out


@njit(parallel=True, cache=True, nogil=True)
def _unfold(g, m_pos, order, k_lo, k_hi, dw, t_c, lut, drive, dst, out
            ):  # pragma: no cover - compiled
    """out[dst[p], k − k_lo] = E_k e^{iω_k t_c} Σ_t lut[k mod D, t] H(⌊k/D⌋ − 7 + t),
    H(m) = G(m D) e^{−i m D dw t_c}, G at the positive coarse bins m_pos (ascending),
    G(−m) = conj G(m), G(0) = 0. The phasors by recurrence over m and k (one sincos pair
    each per target instead of one per bin: ≈ 1e-14 rad after 200 steps)."""
    taps = lut.shape[1]
    half = taps // 2
    m_first = k_lo // order - half + 1
    n_m = k_hi // order + half - m_first + 1
    where = np.full(m_pos[-1] + 1, -1, dtype=np.int64)
    for j in range(m_pos.size):
        where[m_pos[j]] = j
    for p in prange(g.shape[0]):
        tc = t_c[p]
        h = np.empty(n_m, dtype=np.complex128)
        rot = _phasor(-m_first * order * dw * tc)
        turn = _phasor(-order * dw * tc)
        for i in range(n_m):
            m = m_first + i
            if m == 0:
                h[i] = 0.0
            else:
                v = g[p, where[abs(m)]]
                h[i] = (v if m > 0 else v.conjugate()) * rot
            rot *= turn
        rot = _phasor(k_lo * dw * tc)
        turn = _phasor(dw * tc)
        for k in range(k_lo, k_hi + 1):
            m0 = k // order
            r = k - m0 * order
            base = m0 - half + 1 - m_first
            s = 0j
            for t in range(taps):
                s += lut[r, t] * h[base + t]
            out[dst[p], k - k_lo] = s * rot * drive[k - k_lo]
            rot *= turn


@njit(inline="always")
def _phasor(ph):  # pragma: no cover - compiled
    return complex(math.cos(ph), math.sin(ph))


def table_frequencies(frequencies: NDArray, period: float) -> tuple[NDArray, float] | None:
    """The table's bins (Hz, :func:`table_bins`) for a band of DFT bins of a record of
    ``period`` s, and the band's top (Hz); None when ``frequencies`` are not such bins or
    the record is too short to decimate (:func:`largest_order`)."""
    f = np.asarray(frequencies, dtype=float).reshape(-1)
    k = np.rint(f * period)
    if not (f.size >= 2 and k[0] >= 1 and np.array_equal(np.diff(k), np.ones(f.size - 1))
            and np.allclose(k / period, f, rtol=1e-9, atol=0)):
        return None
    top = largest_order(int(k[-1]))
    return None if top == 1 else (table_bins(int(k[0]), int(k[-1]), top) / period,
                                  float(f[-1]))


def decimated_table_spectra(vt: VirtualTransducer, points: NDArray, frequencies: NDArray,
                            period: float, elements: NDArray, amplitudes: NDArray,
                            delays: NDArray, drive: NDArray, bounds: tuple[NDArray, NDArray],
                            *, points_per_wavelength: float = 4.0, dtype: type = np.float64,
                            chunk: int = 1 << 16,
                            progress: Callable[[int, int], None] | None = None
                            ) -> NDArray[np.complexfloating] | None:
    """Column-table spectra at ``points`` computed on every D-th bin (module doc).

    Parameters
    ----------
    vt : VirtualTransducer
        A flat 1-D model.
    points : ndarray, shape (n, 3)
        Targets in m (served by the table: :func:`holoprobe.transducer.table_targets`).
    frequencies : ndarray, shape (nf,)
        The band's bins in Hz: consecutive multiples of 1/period.
    period : float
        Record length in s.
    elements : ndarray of int, shape (n_el,)
        Radiating elements.
    amplitudes, delays : ndarray, shape (n_el,)
        Apodization and delays (s) of ``elements``.
    drive : ndarray, complex, shape (nf,)
        Drive spectrum E at ``frequencies`` (:func:`holoprobe.transducer.drive_spectrum`).
    bounds : (ndarray, ndarray), shapes (n,)
        Earliest and latest arrival at each point in s (with the delays and lens).
    points_per_wavelength, dtype, chunk, progress
        As for :func:`holoprobe.transducer.table_spectra`.

    Returns
    -------
    ndarray, complex, shape (n, nf), or None
        The spectra (as :func:`table_spectra` with weights ``a_e E e^{iωτ_e}``); None
        when the bins are not a record's, the drive at the band's edges exceeds
        :data:`EDGE_LEVEL` of its peak, or the table would exceed the memory cap (the
        caller then takes every bin).
    """
    bins = table_frequencies(frequencies, period)
    level = np.abs(np.asarray(drive))
    if bins is None or max(level[0], level[-1]) > EDGE_LEVEL * level.max():
        return None
    f_tab, f_max = bins
    k_lo, k_hi = round(float(frequencies[0]) * period), round(float(frequencies[-1]) * period)
    cdtype = np.result_type(dtype, np.complex64)
    if table_bytes(vt, points, elements, f_max, np.dtype(cdtype).itemsize) * f_tab.size * 2 \
            > MAX_TABLE_BYTES:
        return None
    extent = table_extent(vt, points, elements)
    shared = serving_handle(vt, f_tab, extent, points_per_wavelength, dtype)
    parts = shared.parts if shared is not None else {}
    key = ("orders", k_lo, k_hi)
    top = largest_order(k_hi)
    if key not in parts:
        table = (shared.get() if shared is not None else column_table(
            vt, f_tab, *extent, points_per_wavelength=points_per_wavelength, dtype=dtype,
            f_max=f_max))
        parts[key] = order_tables(table, np.rint(f_tab * period).astype(np.int64), k_lo, k_hi,
                                  top)
        if shared is not None:
            shared.release()  # the split holds every bin this path reads
    tables = parts[key]
    t_min, t_max = bounds
    orders = decimation_orders(t_max - t_min, period, top)
    t_c = 0.5 * (t_min + t_max)
    out = np.empty((points.shape[0], frequencies.size), dtype=cdtype)
    n, done = points.shape[0], 0
    for d in np.unique(orders):
        sub = tables[int(d)]
        idx = np.flatnonzero(orders == d)
        w = amplitudes[:, None] * np.exp((2j * np.pi) * delays[:, None] * sub.frequencies)
        if d == 1:
            w = w * drive[None, :]
        for s0 in range(0, idx.size, max(1, chunk)):
            sel = idx[s0:s0 + max(1, chunk)]
            if d == 1:  # both kernels write their targets' rows of out (no copies)
                table_field(sub, vt, points[sel], elements, w, out=out, rows=sel)
            else:
                unfold_spectra(table_field(sub, vt, points[sel], elements, w), int(d), k_lo,
                               k_hi, 1.0 / period, t_c[sel], drive, out=out, rows=sel)
            done += sel.size
            if progress is not None:
                progress(done, n)
    return out
