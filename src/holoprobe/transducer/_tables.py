"""Fields at scattered points from one table of the element's column response.

Every element of a flat 1-D array is sampled (as in :func:`surface_velocity`) as ``nx``
columns along y at x offsets ``ux_i`` from its centre, each column carrying the same
``ny`` lens-delayed point sources. A column's pressure at a target depends on the
target only through its elevation ``v = |y − y_c|`` (the lens is symmetric) and its
distance from the column's line, ``ρ = √((x − X_c)² + z²)``::

    C(ρ, v; ω) = Σ_y (−ikρ0c0/2π) ΔA e^{iωτ_L(y)} e^{ikR}/R,   R = √(ρ² + (v − y)²)

(paper eq. rayleigh-fwd-vp, rigid baffle). ``C`` is band-limited along ρ and v (local
wavenumbers kρ/R and k|v − y|/R, both ≤ k), so ONE table of it on a (v, ρ) grid of step
λ_min/5 gives the field of the whole array at any target,

    p(r; ω) = Σ_e w_e(ω) Σ_i C(ρ_{e,i}(r), v(r); ω),   w_e = a_e E(ω) e^{iωτ_e},

by a separable 8-tap interpolation (least-squares weights for the highest wavenumber of
each block of frequencies, :func:`interpolation_weights`): first along v for the
target's whole ρ range, then along ρ with the taps of an element's sub-columns merged.
That is ``8 × (ρ range / step) + N_el × ~14`` multiply-adds per target and frequency
instead of N_el × nx × ny kernel evaluations: the same quadrature as the dense
Rayleigh sum, only the interpolation (≈ 1e-5 of the peak pressure) separates the two.
The table does not depend on the transmit: settings with any delays and apodization
share it. Targets nearer the face than 3 λ_min (where 1/R varies within a wavelength)
are left to the caller.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

import holoprobe._numba  # noqa: F401  (threading layer, before any kernel runs)
from holoprobe.errors import InputError
from holoprobe.geometry import Surface
from holoprobe.signal import interpolation_weights
from holoprobe.transducer._model import VirtualTransducer

__all__ = ["ColumnTable", "column_table", "interpolation_weights", "shared_table",
           "table_extent", "table_field", "table_handle", "table_spectra", "table_targets",
           "target_rows", "use_table"]

#: interpolation taps per axis, table steps per shortest wavelength, nearest target
#: distance from the face in shortest wavelengths
TAPS, STEPS_PER_WAVELENGTH, NEAREST = 8, 5.0, 3.0
#: largest table (bytes) held at once; wider frequency bands are done in blocks
MAX_TABLE_BYTES = 256 << 20


@dataclass(frozen=True)
class ColumnTable:
    """The column response ``C(ρ, v; ω)`` of one element column on a regular (v, ρ) grid.

    Attributes
    ----------
    values : ndarray, complex, shape (nv, nrho, nf)
        ``C`` in Pa per (m/s·s) at ``v = v0 + j·step``, ``ρ = rho0 + i·step``.
    v0, rho0, step : float
        Grid origin and step in m.
    frequencies : ndarray, shape (nf,)
        Hz.
    columns : ndarray, shape (nx,)
        x offsets of an element's columns from its centre in m.
    sound_speed : float
        m/s (with ``step``, sets the band of each frequency on the grid).
    """

    values: NDArray[np.complexfloating]
    v0: float
    rho0: float
    step: float
    frequencies: NDArray[np.float64]
    columns: NDArray[np.float64]
    sound_speed: float

    @property
    def band(self) -> NDArray[np.float64]:
        """Wavenumber of each frequency as a fraction of the grid's Nyquist π/step."""
        return 2.0 * self.step * self.frequencies / self.sound_speed


def table_targets(vt: VirtualTransducer, points: NDArray, f_max: float) -> NDArray[np.bool_]:
    """Targets the table can serve: a flat 1-D array, at least 3 λ_min from the face."""
    centers = vt.element_centers()
    if vt.is_curved or (vt.array is not None and vt.array.kind != "linear") or not (
            np.allclose(centers[:, 1], vt.aperture_center[1], rtol=0, atol=1e-9)
            and np.allclose(centers[:, 2], 0.0, rtol=0, atol=1e-9)):
        return np.zeros(points.shape[0], dtype=bool)
    return points[:, 2] >= NEAREST * vt.medium.sound_speed / f_max


def table_extent(vt: VirtualTransducer, points: NDArray, elements: NDArray
                 ) -> tuple[float, float, float]:
    """Largest |y − y_c| and the range of ρ (m) that ``points`` need from the columns."""
    xe = vt.element_centers()[elements, 0]
    hw = 0.5 * vt.element_width
    x_lo, x_hi = float(xe.min()) - hw, float(xe.max()) + hw
    x, z = points[:, 0], points[:, 2]
    near = np.clip(x, x_lo, x_hi) - x
    far = np.maximum(np.abs(x - x_lo), np.abs(x - x_hi))
    v = np.abs(points[:, 1] - vt.aperture_center[1])
    return (float(v.max()), float(np.sqrt(near**2 + z**2).min()),
            float(np.sqrt(far**2 + z**2).max()))


def column_table(vt: VirtualTransducer, frequencies: NDArray, v_max: float,
                 rho_min: float, rho_max: float, *, points_per_wavelength: float = 4.0,
                 lens: bool = True, dtype: type = np.float64,
                 f_max: float | None = None) -> ColumnTable:
    """Tabulate one element column's response for targets with |v| ≤ v_max, ρ in range.

    Parameters
    ----------
    vt : VirtualTransducer
        A flat model (element width, height, lens, medium).
    frequencies : ndarray, shape (nf,)
        Hz.
    v_max : float
        Largest target elevation |y − y_c| in m.
    rho_min, rho_max : float
        Range of target distances from the column lines in m (rho_min > 0).
    points_per_wavelength : float
        Sub-element sampling (as :func:`holoprobe.transducer.surface_velocity`).
    lens : bool
        Apply the lens delays.
    dtype : {numpy.float64, numpy.float32}
        Precision of the Rayleigh kernel and of the table.
    f_max : float, optional
        Highest frequency of the prediction in Hz (default: of ``frequencies``): sets
        the sub-element sampling and the grid step, so that tables of blocks of one band
        agree with one table of the whole band.

    Returns
    -------
    ColumnTable
    """
    from holoprobe.propagation import rayleigh_integral
    from holoprobe.transducer._field import _element_grid

    f = np.asarray(frequencies, dtype=float).reshape(-1)
    top = float(f.max()) if f_max is None else float(f_max)
    if not (rho_min > 0 and rho_max >= rho_min and v_max >= 0):
        raise InputError(f"expected 0 < rho_min <= rho_max and v_max >= 0, got "
                         f"{rho_min!r}, {rho_max!r}, {v_max!r}", field="points")
    step = vt.medium.sound_speed / top / STEPS_PER_WAVELENGTH
    half = TAPS // 2
    ux, uy, tau_lens = _element_grid(vt, top, points_per_wavelength, lens)
    v0 = -half * step
    nv = math.floor(v_max / step) + TAPS + 1
    rho0 = (math.floor(rho_min / step) - half - 1) * step  # nodes at multiples of step:
    # tables of any extent share their nodes, so chunks of a job interpolate alike
    nrho = math.ceil((rho_max - rho0) / step) + half + 2
    vv, rr = np.meshgrid(v0 + np.arange(nv) * step, rho0 + np.arange(nrho) * step,
                         indexing="ij")
    column = Surface(np.stack([np.zeros(uy.size), uy, np.zeros(uy.size)], axis=-1),
                     np.tile([0.0, 0.0, 1.0], (uy.size, 1)),
                     np.full(uy.size, vt.element_width / ux.size * vt.element_height / uy.size))
    targets = Surface(np.stack([np.zeros(vv.size), vv.ravel(), rr.ravel()], axis=-1),
                      np.tile([0.0, 0.0, 1.0], (vv.size, 1)), np.ones(vv.size))
    velocity = np.exp((2j * np.pi) * tau_lens[:, None] * f[None, :])
    values = rayleigh_integral(velocity, column, targets, f, vt.medium, kernel="fwd_vp",
                               baffle="rigid", dtype=dtype)
    return ColumnTable(values.reshape(nv, nrho, f.size), v0, rho0, step, f, ux,
                       vt.medium.sound_speed)


def table_bytes(vt: VirtualTransducer, points: NDArray, elements: NDArray, f_max: float,
                itemsize: int = 8) -> int:
    """Bytes of :func:`column_table` per frequency for ``points`` (to plan blocks)."""
    v_max, rho_min, rho_max = table_extent(vt, points, elements)
    step = vt.medium.sound_speed / f_max / STEPS_PER_WAVELENGTH
    return int((v_max / step + TAPS + 1) * ((rho_max - rho_min) / step + TAPS + 4) * itemsize)


def _blocks(table: ColumnTable, limits: tuple[float, ...] = (0.3,)
            ) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Frequency blocks (bin edges) and their interpolation weights, each designed for
    the block's highest wavenumber (a fraction of π/step). Two blocks at λ_min/5 (up to
    0.3, where 8 taps err ≲ 1.4e-5, and up to 0.4 at the top of the band, 1.6e-4, where
    the drive has little energy): 5.8e-6 of the peak on the P4-1 benchmark, against
    4.2e-6 with three blocks (0.2, 0.3, 0.4) at 27 % more CPU (short loops per block).
    The decimated path's bins above the band's top (its interpolation margin,
    :mod:`holoprobe.transducer._table_decimation`) join the second block, designed for
    the highest of them (≤ 0.52: 2.1e-5 of the peak on the benchmark; a third block
    costs more than the bins it saves)."""
    frac = table.band
    edges, designs = [0], []
    for lim in limits:
        k = int(np.searchsorted(frac, lim, side="right"))
        if k > edges[-1]:
            edges.append(k)
            designs.append(lim)
    if edges[-1] < frac.size:
        edges.append(frac.size)
        designs.append(float(frac.max()))
    return np.asarray(edges, dtype=np.int64), _luts(TAPS, tuple(designs))


@lru_cache(maxsize=32)
def _luts(taps: int, designs: tuple[float, ...]) -> NDArray[np.float64]:
    """Stacked :func:`interpolation_weights` per design band, made once per process
    (≈ 0.05 s each: every chunk of a streamed job asks for the same ones)."""
    luts = np.stack([interpolation_weights(taps, d) for d in designs])
    luts.setflags(write=False)
    return luts


def target_rows(rows: NDArray | None, n: int, out: NDArray) -> NDArray[np.int64]:
    """The rows of ``out`` that n targets go to (``rows``, or 0 … n − 1), checked.

    The kernels that scatter targets into ``out`` run without bounds checks: a row
    outside ``out`` would write outside the array.
    """
    dst = (np.arange(n, dtype=np.int64) if rows is None
           else np.ascontiguousarray(rows, dtype=np.int64).reshape(-1))
    if dst.size != n:
        raise InputError(f"expected one row per target ({n}), got {dst.size}", field="rows")
    if n and (dst.min() < 0 or dst.max() >= out.shape[0]):
        raise InputError(f"expected rows in [0, {out.shape[0]}) of out, got "
                         f"[{int(dst.min())}, {int(dst.max())}]", field="rows")
    return dst


def table_field(table: ColumnTable, vt: VirtualTransducer, points: NDArray,
                elements: NDArray, weights: NDArray, *, out: NDArray | None = None,
                rows: NDArray | None = None) -> NDArray[np.complexfloating]:
    """Field spectra at ``points`` of ``elements`` driven with ``weights`` (module doc).

    Parameters
    ----------
    table : ColumnTable
        From :func:`column_table`, covering the points (:func:`table_extent`).
    vt : VirtualTransducer
        The flat model the table was made for.
    points : ndarray, shape (n, 3)
        Targets in m.
    elements : ndarray of int, shape (n_el,)
        Radiating elements.
    weights : ndarray, complex, shape (n_el, nf)
        ``a_e E(ω) e^{iωτ_e}`` per element and frequency of the table.
    out : ndarray, complex, shape (N, nf), optional
        Written in place (C-contiguous, the table's dtype): the spectrum of
        ``points[i]`` goes to row ``rows[i]`` (the kernel scatters them: no copy).
    rows : ndarray of int, shape (n,), optional
        Rows of ``out`` (default ``0 … n − 1``).

    Returns
    -------
    ndarray, complex, shape (n, nf), or ``out``
        Pressure spectra (Pa·s for weights in m/s·s), the table's dtype.
    """
    pts = np.ascontiguousarray(points, dtype=float)
    xe = vt.element_centers()[elements, 0]
    col_x = (xe[:, None] + table.columns[None, :]).ravel()
    nf = table.values.shape[2]
    real = table.values.real.dtype
    w = np.asarray(weights, dtype=table.values.dtype).reshape(elements.size, nf)
    edges, luts = _blocks(table)
    spread = float(np.ptp(table.columns)) if table.columns.size else 0.0
    span = max(12, TAPS + math.ceil(spread / table.step) + 2)  # ≥ the fused 12 taps
    # targets in order of their v row, then depth: neighbours reuse the same table rows
    yc = float(vt.aperture_center[1])
    order = np.lexsort((pts[:, 2], np.floor(np.abs(pts[:, 1] - yc) / table.step)))
    if out is None:
        out = np.empty((pts.shape[0], nf), dtype=table.values.dtype)
    if not (out.dtype == table.values.dtype and out.flags.c_contiguous
            and out.ndim == 2 and out.shape[1] == nf):
        raise InputError(f"expected a C-contiguous {table.values.dtype} array of {nf} "
                         f"bins per row, got {out.dtype} {out.shape}", field="out")
    dst = target_rows(rows, pts.shape[0], out)[order]
    _table_sum(table.values.view(real), table.v0, table.step, table.rho0, luts.astype(real),
               edges, pts, order, dst, yc, col_x, table.columns.size,
               np.ascontiguousarray(w.real), np.ascontiguousarray(w.imag), span,
               out.view(real))
    return out


@njit(inline="always")
def _position(lut, s):  # pragma: no cover - compiled
    """First tap node of position s (in steps), its row q in the lut and the fraction r
    between rows q and q + 1 (the 8 taps: lut[q] + (lut[q + 1] − lut[q]) r)."""
    f = math.floor(s)
    a = (s - f) * (lut.shape[1] - 1)
    q = int(a)
    return int(f) - TAPS // 2 + 1, q, a - q


@njit(parallel=True, cache=True, fastmath=True, nogil=True)
def _table_sum(table, v0, step, rho0, luts, edges, pts, order, dst, yc, col_x, n_sub, wr, wi,
               span, out):  # pragma: no cover - compiled
    """out[dst[p]] = Σ_e w[e] Σ_i C(ρ_{e,i}, v) at pts[order[p]]: 2-D interpolation of
    the table (complex values as (re, im) pairs along the last axis), the v axis first
    (once per target and frequency block), then ρ with each element's sub-columns merged
    into one weight row. Both axes have exactly :data:`TAPS` (8) taps. A column's tap
    node and lut position are found once per target; the weight rows of every block are
    made in one pass (≈ 8.5 → 4 µs per target on the P4-1 benchmark)."""
    nr, n2 = table.shape[1], table.shape[2]
    n_col = col_x.size
    n_el = wr.shape[0]
    n_blk = edges.size - 1
    for p in prange(order.size):
        pt = pts[order[p]]
        x, z = pt[0], pt[2]
        c_i = np.empty(n_col, dtype=np.int64)
        c_q = np.empty(n_col, dtype=np.int64)
        c_r = np.empty(n_col, dtype=luts.dtype)
        lo, hi = nr, -1
        for j in range(n_col):
            dx = x - col_x[j]
            i, c_q[j], c_r[j] = _position(luts, (math.sqrt(dx * dx + z * z) - rho0) / step)
            c_i[j] = i
            lo = min(lo, i)
            hi = max(hi, i + TAPS - 1)
        m = hi - lo + 1
        first = np.empty(n_el, dtype=np.int64)
        width = np.empty(n_el, dtype=np.int64)
        for e in range(n_el):
            base, top = nr, -nr
            for q in range(n_sub):
                base, top = min(base, c_i[e * n_sub + q]), max(top, c_i[e * n_sub + q])
            first[e] = base - lo
            width[e] = top - base + TAPS
        j0, qv, rv = _position(luts, (abs(pt[1] - yc) - v0) / step)
        lam = np.empty((n_blk, TAPS), dtype=luts.dtype)
        row = np.zeros((n_blk, n_el, span), dtype=luts.dtype)
        for k in range(n_blk):  # one weight row per element over its sub-columns' taps
            lut = luts[k]
            for t in range(TAPS):
                lam[k, t] = lut[qv, t] + (lut[qv + 1, t] - lut[qv, t]) * rv
            for e in range(n_el):
                w_row = row[k, e]
                for q in range(n_sub):
                    j = e * n_sub + q
                    off = c_i[j] - lo - first[e]
                    l_a, l_b, r = lut[c_q[j]], lut[c_q[j] + 1], c_r[j]
                    for t in range(TAPS):
                        w_row[off + t] += l_a[t] + (l_b[t] - l_a[t]) * r
        f_line = np.empty((m, n2), dtype=out.dtype)
        col = np.empty(n2, dtype=out.dtype)
        for k in range(n_blk):
            b0, b1 = 2 * edges[k], 2 * edges[k + 1]
            n = b1 - b0  # 0-based loops over slices: LLVM vectorizes these
            l0, l1, l2, l3 = lam[k, 0], lam[k, 1], lam[k, 2], lam[k, 3]
            l4, l5, l6, l7 = lam[k, 4], lam[k, 5], lam[k, 6], lam[k, 7]
            for i in range(m):  # each row of f_line written once, its 8 taps summed in
                line = f_line[i, b0:b1]  # registers (1.4-2.2x faster than 8 passes)
                s0, s1 = table[j0, lo + i, b0:b1], table[j0 + 1, lo + i, b0:b1]
                s2, s3 = table[j0 + 2, lo + i, b0:b1], table[j0 + 3, lo + i, b0:b1]
                s4, s5 = table[j0 + 4, lo + i, b0:b1], table[j0 + 5, lo + i, b0:b1]
                s6, s7 = table[j0 + 6, lo + i, b0:b1], table[j0 + 7, lo + i, b0:b1]
                for b in range(n):
                    line[b] = (l0 * s0[b] + l1 * s1[b] + l2 * s2[b] + l3 * s3[b]
                              + l4 * s4[b] + l5 * s5[b] + l6 * s6[b] + l7 * s7[b])
            acc = out[dst[p], b0:b1]
            wr_k = wr[:, b0 // 2:b1 // 2]
            wi_k = wi[:, b0 // 2:b1 // 2]
            for b in range(n):
                acc[b] = 0
            for e in range(n_el):
                r0 = first[e]
                if width[e] <= 12:  # 12 taps summed in registers, one pass (rows past
                    # the element's own taps carry weight 0; clamped to f_line's rows;
                    # the row taken here: outside the branch the kernel ran 2x slower)
                    c = row[k, e]
                    s0, s1 = f_line[r0, b0:b1], f_line[min(r0 + 1, m - 1), b0:b1]
                    s2, s3 = f_line[min(r0 + 2, m - 1), b0:b1], f_line[min(r0 + 3, m - 1), b0:b1]
                    s4, s5 = f_line[min(r0 + 4, m - 1), b0:b1], f_line[min(r0 + 5, m - 1), b0:b1]
                    s6, s7 = f_line[min(r0 + 6, m - 1), b0:b1], f_line[min(r0 + 7, m - 1), b0:b1]
                    s8, s9 = f_line[min(r0 + 8, m - 1), b0:b1], f_line[min(r0 + 9, m - 1), b0:b1]
                    sa = f_line[min(r0 + 10, m - 1), b0:b1]
                    sb = f_line[min(r0 + 11, m - 1), b0:b1]
                    c0, c1, c2, c3, c4, c5 = c[0], c[1], c[2], c[3], c[4], c[5]
                    c6, c7, c8, c9, ca, cb = c[6], c[7], c[8], c[9], c[10], c[11]
                    for b in range(n):
                        col[b] = (c0 * s0[b] + c1 * s1[b] + c2 * s2[b] + c3 * s3[b]
                                  + c4 * s4[b] + c5 * s5[b] + c6 * s6[b] + c7 * s7[b]
                                  + c8 * s8[b] + c9 * s9[b] + ca * sa[b] + cb * sb[b])
                else:
                    for b in range(n):
                        col[b] = 0
                    for r in range(span):
                        w = row[k, e, r]
                        if w != 0:
                            src = f_line[r0 + r, b0:b1]
                            for b in range(n):
                                col[b] += w * src[b]
                we_r = wr_k[e]
                we_i = wi_k[e]
                for b in range(n // 2):
                    cr, ci = col[2 * b], col[2 * b + 1]
                    acc[2 * b] += we_r[b] * cr - we_i[b] * ci
                    acc[2 * b + 1] += we_r[b] * ci + we_i[b] * cr


def table_spectra(vt: VirtualTransducer, points: NDArray, frequencies: NDArray,
                  elements: NDArray, weights: list[NDArray], *,
                  points_per_wavelength: float = 4.0, dtype: type = np.float64,
                  chunk: int = 1 << 16, progress: Callable[[int, int], None] | None = None
                  ) -> list[NDArray[np.complexfloating]]:
    """Field spectra at ``points`` for one or several sets of element weights.

    The column table (:func:`column_table`, over the points' extent) is built once per
    block of frequencies (at most :data:`MAX_TABLE_BYTES` at a time) and shared by every
    set of weights; points go in chunks of ``chunk`` (bounded work memory, progress).

    Parameters
    ----------
    vt : VirtualTransducer
        A flat 1-D model.
    points : ndarray, shape (n, 3)
        Targets in m, at least 3 λ_min in front of the face (:func:`table_targets`).
    frequencies : ndarray, shape (nf,)
        Hz.
    elements : ndarray of int, shape (n_el,)
        Radiating elements (every set of weights refers to them).
    weights : list of ndarray, complex, shape (n_el, nf)
        ``a_e E(ω) e^{iωτ_e}`` of each transmit.
    points_per_wavelength : float
        Sub-element sampling (as :func:`holoprobe.transducer.surface_velocity`).
    dtype : {numpy.float64, numpy.float32}
        Precision of the table and the spectra.
    chunk : int
        Targets per call of the interpolation kernel.
    progress : callable(done, total), optional
        Called after each chunk.

    Returns
    -------
    list of ndarray, complex, shape (n, nf)
        Pressure spectra, one per set of weights.
    """
    f = np.asarray(frequencies, dtype=float).reshape(-1)
    f_max = float(f.max())
    cdtype = np.result_type(dtype, np.complex64)
    n = points.shape[0]
    per_freq = table_bytes(vt, points, elements, f_max, np.dtype(cdtype).itemsize)
    nb = max(1, min(f.size, MAX_TABLE_BYTES // max(per_freq, 1)))
    extent = table_extent(vt, points, elements)
    outs = [np.empty((n, f.size), dtype=cdtype) for _ in weights]
    shared = _SHARED.get()
    if shared is not None and not shared.serves(vt, f, extent, points_per_wavelength, dtype):
        shared = None
    if shared is not None:
        nb = f.size
    total = n * math.ceil(f.size / nb)
    done = 0
    for b0 in range(0, f.size, nb):
        sl = slice(b0, b0 + nb)
        table = (shared.get() if shared is not None else
                 column_table(vt, f[sl], *extent, points_per_wavelength=points_per_wavelength,
                              dtype=dtype, f_max=f_max))
        for s0 in range(0, n, max(1, chunk)):
            s1 = min(n, s0 + max(1, chunk))
            for out, w in zip(outs, weights, strict=True):
                if nb == f.size:  # the kernel writes the rows of out
                    table_field(table, vt, points[s0:s1], elements, w, out=out,
                                rows=np.arange(s0, s1))
                else:
                    out[s0:s1, sl] = table_field(table, vt, points[s0:s1], elements,
                                                 w[:, sl])
            done += s1 - s0
            if progress is not None:
                progress(done, total)
    return outs


class _SharedTable:
    """One column table for a whole job, built on first use (:func:`shared_table`)."""

    def __init__(self, vt: VirtualTransducer, frequencies: NDArray,
                 extent: tuple[float, float, float], points_per_wavelength: float,
                 dtype: type, f_max: float | None = None):
        self.vt, self.frequencies, self.extent = vt, frequencies, extent
        self.points_per_wavelength, self.dtype = points_per_wavelength, np.dtype(dtype)
        self.f_max = f_max
        self._table: ColumnTable | None = None
        self._lock = threading.Lock()
        #: tables derived from this one (the decimated path's split per order)
        self.parts: dict = {}

    def serves(self, vt: VirtualTransducer, frequencies: NDArray,
               extent: tuple[float, float, float], points_per_wavelength: float,
               dtype: type) -> bool:
        return (vt is self.vt and np.dtype(dtype) == self.dtype
                and points_per_wavelength == self.points_per_wavelength
                and np.array_equal(frequencies, self.frequencies)
                and extent[0] <= self.extent[0] and extent[1] >= self.extent[1]
                and extent[2] <= self.extent[2])

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_table"], state["_lock"], state["parts"] = None, None, {}
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()

    def release(self) -> None:
        """Forget the table (memory); a later :meth:`get` builds it again."""
        with self._lock:
            self._table = None

    def get(self) -> ColumnTable:
        with self._lock:
            if self._table is None:
                self._table = column_table(
                    self.vt, self.frequencies, *self.extent,
                    points_per_wavelength=self.points_per_wavelength, dtype=self.dtype.type,
                    f_max=self.f_max)
            return self._table


_SHARED: ContextVar[_SharedTable | None] = ContextVar("holoprobe_column_table", default=None)


def serving_handle(vt: VirtualTransducer, frequencies: NDArray,
                   extent: tuple[float, float, float], points_per_wavelength: float,
                   dtype: type) -> _SharedTable | None:
    """The active :func:`shared_table` handle when it serves these bins and targets."""
    shared = _SHARED.get()
    if shared is not None and shared.serves(vt, frequencies, extent, points_per_wavelength,
                                            dtype):
        return shared
    return None


def is_shared(vt: VirtualTransducer, frequencies: NDArray) -> bool:
    """Whether a :func:`shared_table` block for this model and these bins is active."""
    shared = _SHARED.get()
    return (shared is not None and shared.vt is vt
            and np.array_equal(np.asarray(frequencies, dtype=float), shared.frequencies))


def table_handle(vt: VirtualTransducer, points: NDArray, frequencies: NDArray,
                 elements: NDArray, *, points_per_wavelength: float = 4.0,
                 dtype: type = np.float64, f_max: float | None = None
                 ) -> _SharedTable | None:
    """A column table for the extent of ``points``, built on first use (:func:`use_table`).

    None unless ``method="auto"`` would send some of ``points`` to the table in one call
    (:func:`holoprobe.transducer._scattered.scattered_routes`: chunks of the job then
    route as the whole would), or when the table would exceed :data:`MAX_TABLE_BYTES`.
    The handle pickles without its table (a process that receives it builds its own).
    ``f_max`` (Hz, default the highest of ``frequencies``) sets the table's step and
    sub-element sampling (:func:`column_table`).
    """
    from holoprobe.transducer._field import _element_sampling
    from holoprobe.transducer._scattered import scattered_routes

    f = np.asarray(frequencies, dtype=float).reshape(-1)
    top = float(f.max()) if f_max is None else float(f_max)
    near = scattered_routes(vt, points, elements, f[f <= top], _element_sampling(
        vt, top, points_per_wavelength))[0]
    itemsize = np.dtype(np.result_type(dtype, np.complex64)).itemsize
    if not near.any() or table_bytes(vt, points[near], elements, top,
                                     itemsize) * f.size > MAX_TABLE_BYTES:
        return None
    return _SharedTable(vt, f, table_extent(vt, points[near], elements),
                        points_per_wavelength, dtype, f_max)


@contextmanager
def use_table(handle: _SharedTable | None) -> Iterator[None]:
    """Within the block, :func:`table_spectra` takes its table from ``handle`` when it
    serves (same model, bins, sampling and precision; the targets inside its extent)."""
    if handle is None:
        yield
        return
    token = _SHARED.set(handle)
    try:
        yield
    finally:
        _SHARED.reset(token)


@contextmanager
def shared_table(vt: VirtualTransducer, points: NDArray, frequencies: NDArray,
                 elements: NDArray, *, points_per_wavelength: float = 4.0,
                 dtype: type = np.float64, f_max: float | None = None) -> Iterator[None]:
    """Within the block, :func:`table_spectra` uses ONE table for the extent of ``points``.

    For predictions made chunk by chunk over a large set of points (the table is built
    on first use and covers every chunk; without this each chunk builds its own).
    Nothing is shared when that table would exceed :data:`MAX_TABLE_BYTES`, or for
    another model, band, sampling or precision.

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    points : ndarray, shape (n, 3)
        Every target of the job in m.
    frequencies : ndarray, shape (nf,)
        The job's frequency bins in Hz (all chunks share them).
    elements : ndarray of int
        Elements that may radiate.
    points_per_wavelength, dtype
        As for :func:`table_spectra`.
    f_max : float, optional
        As for :func:`table_handle`.
    """
    with use_table(table_handle(vt, points, frequencies, elements,
                                points_per_wavelength=points_per_wavelength, dtype=dtype,
                                f_max=f_max)):
        yield
