"""Which element offsets a field prediction needs: direct, or interpolated from the element lattice.

Element superposition (:func:`holoprobe.transducer.predict_field`) writes the field of the
array as ``p(r) = Σ_e w_e(ω) G(r − x_e)``: one element's response G at the offsets
between targets and element centres. Arbitrary targets see every element from a
different offset, N_el per point. Targets sharing (y, z) — a line along x, as in any
xz plane, volume grid or list of such points — can instead be computed on the
**element lattice** ``x_j = x_0 + j·p/m`` (x_0 the first element centre, p the pitch,
m an integer): there the offsets ``|x_j − x_e| = |j − e m|·p/m`` repeat across
elements and nodes, so one line of n_x targets needs about (its length + the array
length)/(p/m) element responses instead of n_x·N_el.

The field along such a line is band-limited: at a depth z it holds lateral
wavenumbers up to k (propagating waves) plus evanescent ones that have decayed by
``e^{−z√(κ²−k²)}``. With a lattice step ``h ≤ λ_min/3.2`` (at least 1.6 times the
Nyquist rate of the highest frequency, :func:`lattice_step`) a Kaiser-windowed sinc of
16 or 20 taps interpolates it from the lattice nodes to any x: its error on
band-limited functions is ≤ 2e-8 (``k h/π ≤ 0.45``, 16 taps) or 5e-7 (``k h/π ≤
0.625``, 20 taps) of the sum of the plane-wave amplitudes (measured); targets closer to the
array face than the depth where waves beyond the kernel's accurate band
(``κ > k (1 + b)/(2b)``, ``b = k h/π``) have decayed by 1e-6 are evaluated
directly, as are lines where the lattice would not save work.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit, prange
from numpy.typing import ArrayLike, NDArray

import holoprobe._numba  # noqa: F401  (threading layer, before any kernel runs)
from holoprobe.errors import InputError
from holoprobe.geometry import Surface
from holoprobe.transducer._model import VirtualTransducer

__all__ = ["ElementPlan", "column_tables_field", "element_plan", "lattice_kernel",
           "lattice_step", "unique_pairs"]

#: decay (1e-6) that waves outside the interpolation kernel's band must have reached
_EVANESCENT_DECAY = math.log(1e6)


@dataclass(frozen=True)
class ElementPlan:
    """The element offsets a set of targets needs, and how to get the targets from them.

    Attributes
    ----------
    offsets : ndarray, shape (n_offsets, 3)
        Distinct element offsets (|u|, |v|, z) in m at which the element response is
        evaluated (:func:`holoprobe.transducer.element_field`).
    index : ndarray of int, shape (n_el, n_nodes)
        Row of ``offsets`` seen by element ``elements[j]`` from node i.
    columns : ndarray of int, shape (n_points, W)
        Nodes that make up each target (a direct target: its own node, repeated).
    weights : ndarray, shape (n_points, W)
        Their weights (a direct target: 1, 0, …, 0).
    step : float
        Lattice step p/m in m (NaN when nothing is interpolated).
    interpolated : int
        Number of targets interpolated from lattice nodes.
    """

    offsets: NDArray[np.float64]
    index: NDArray[np.int64]
    columns: NDArray[np.int64]
    weights: NDArray[np.float64]
    step: float
    interpolated: int

    def apply(self, node_spectra: NDArray) -> NDArray:
        """Target spectra (n_points, nf) from the node spectra (n_nodes, nf), same dtype."""
        if self.interpolated == 0 and self.columns.shape[1] == 1 and np.array_equal(
                self.columns[:, 0], np.arange(node_spectra.shape[0])):
            return node_spectra
        out = np.empty((self.columns.shape[0], node_spectra.shape[1]),
                       dtype=node_spectra.dtype)
        real = np.empty(0, dtype=node_spectra.real.dtype).dtype
        _combine(np.ascontiguousarray(node_spectra).view(real), self.columns,
                 self.weights.astype(real), out.view(real))
        return out


@njit(parallel=True, cache=True)
def _combine(nodes, columns, weights, out):  # pragma: no cover - compiled
    """out[i, :] = Σ_t weights[i, t] · nodes[columns[i, t], :] (parallel over targets;
    complex spectra as their real views: a real weight scales re and im alike)."""
    n, taps = columns.shape
    nf = nodes.shape[1]
    for i in prange(n):
        acc = np.zeros(nf, dtype=out.dtype)
        for t in range(taps):
            w = weights[i, t]
            if w != 0:
                row = columns[i, t]
                for b in range(nf):
                    acc[b] += w * nodes[row, b]
        out[i, :] = acc


def unique_pairs(keys: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.int64],
                                          NDArray[np.int64]]:
    """Distinct rows of an integer array of pairs, as ``np.unique(keys, axis=0, ...)``.

    Parameters
    ----------
    keys : array_like of int, shape (n, 2)
        Integer keys (e.g. (y, z) in units of a tolerance).

    Returns
    -------
    first, inverse, counts : ndarray of int
        Index of the first row of each distinct pair (pairs in lexicographic order),
        the pair of every row (shape (n,)) and how many rows share each pair: what
        ``np.unique(keys, axis=0, return_index=True, return_inverse=True,
        return_counts=True)`` returns after the pairs, from one int64 key per row (a
        1-D sort, ~10x faster than sorting rows) whenever the pairs' ranges fit in it.
    """
    k = np.asarray(keys).astype(np.int64, copy=False).reshape(-1, 2)
    if k.shape[0] == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    lo = k.min(axis=0)
    span = k.max(axis=0) - lo + 1
    if int(span[0]) <= (2**62) // int(span[1]):
        flat = (k[:, 0] - lo[0]) * span[1] + (k[:, 1] - lo[1])
        _, first, inverse, counts = np.unique(flat, return_index=True, return_inverse=True,
                                              return_counts=True)
    else:
        _, first, inverse, counts = np.unique(k, axis=0, return_index=True,
                                              return_inverse=True, return_counts=True)
    return first, inverse.reshape(-1), counts


def lattice_kernel(distance: ArrayLike, taps: int, band: float) -> NDArray[np.float64]:
    """Kaiser-windowed sinc interpolation weights.

    Parameters
    ----------
    distance : array_like
        Distance from the target to each node in lattice steps (|distance| ≤ taps/2).
    taps : int
        Kernel length W (even).
    band : float
        Highest wavenumber of the interpolated function as a fraction of the lattice's
        Nyquist wavenumber π/h (0 < band < 1); the window's shape parameter is
        ``β = π W (1 − band)/2``.

    Returns
    -------
    ndarray
        Weights, the shape of ``distance``.
    """
    d = np.asarray(distance, dtype=float)
    out = np.empty(d.size)
    _kaiser_sinc(np.ascontiguousarray(d).reshape(-1), float(taps),
                 window_coefficients(taps, band), out)
    return out.reshape(d.shape)


def window_coefficients(taps: int, band: float) -> NDArray[np.float64]:
    """Power-series coefficients of the Kaiser window in ``a = 1 − (2d/W)²``.

    ``I0(β √a)/I0(β) = Σ_k c_k a^k`` with ``c_k = (β²/4)^k/(k!)² / I0(β)`` and ``β = π W
    (1 − band)/2`` (:func:`lattice_kernel`), up to the first term below 1e-17 of the sum:
    the window in one Horner pass (:func:`_window`), to rounding.
    """
    beta = math.pi * taps * (1.0 - band) / 2.0
    y = 0.25 * beta * beta
    coef = [1.0]
    while coef[-1] > 1e-17 * sum(coef):
        k = len(coef)
        coef.append(coef[-1] * y / (k * k))
    return np.asarray(coef) / float(np.i0(beta))


@njit(cache=True)
def _window(a, coef):  # pragma: no cover - compiled
    """Σ_k coef[k] a^k (Horner)."""
    acc = 0.0
    for k in range(coef.size - 1, -1, -1):
        acc = acc * a + coef[k]
    return acc


@njit(cache=True)
def _kaiser_weight(d, taps, coef):  # pragma: no cover - compiled
    """sinc(d) I0(β √(1 − (2d/W)²)) / I0(β) (0 outside |d| ≤ W/2)."""
    a = 1.0 - (2.0 * d / taps) ** 2
    sinc = 1.0 if d == 0.0 else math.sin(math.pi * d) / (math.pi * d)
    return sinc * _window(a if a > 0.0 else 0.0, coef)


@njit(parallel=True, cache=True)
def _kaiser_sinc(d, taps, coef, out):  # pragma: no cover - compiled
    """out = the Kaiser-windowed sinc at d (:func:`_kaiser_weight`), elementwise."""
    for n in prange(d.size):
        out[n] = _kaiser_weight(d[n], taps, coef)


@njit(parallel=True, cache=True)
def _column_sums(table, rho, row0, step, taps, coef, out):  # pragma: no cover - compiled
    """out[o, :] = Σ_i Σ_t K(s − j_t) table[row0[o] + j_t, :] with s = rho[o, i]/step.

    The column-table interpolation of :func:`column_tables_field` in one pass: the
    ``taps`` nodes j_t around each s and their Kaiser-windowed sinc weights K
    (:func:`_kaiser_weight`, rounded to the table's dtype) computed on the fly
    (parallel over offsets o). Complex tables as their real views (re, im pairs).
    """
    n, nx = rho.shape
    nf = table.shape[1]
    half = taps // 2
    for o in prange(n):
        acc = np.zeros(nf, dtype=out.dtype)
        w = np.empty(taps, dtype=table.dtype)
        for i in range(nx):
            s = rho[o, i] / step
            j0 = math.floor(s) - half + 1
            for t in range(taps):
                w[t] = _kaiser_weight(s - (j0 + t), float(taps), coef)
            for t in range(taps):
                row = row0[o] + j0 + t
                for b in range(nf):
                    acc[b] += w[t] * table[row, b]
        out[o, :] = acc


def element_plan(vt: VirtualTransducer, points: NDArray, elements: ArrayLike, f_max: float,
                 *, lattice: bool = True, element_samples: int = 1,
                 tolerance: float = 1e-9) -> ElementPlan:
    """Plan the element offsets for targets ``points``: lattice lines where it pays, else direct.

    Parameters
    ----------
    vt : VirtualTransducer
        Element centres, pitch, medium.
    points : ndarray, shape (n, 3)
        Targets in m.
    elements : array_like of int, shape (n_el,)
        Indices of the elements that radiate.
    f_max : float
        Highest frequency to propagate in Hz (sets the lattice step and kernel).
    lattice : bool
        False: every target is evaluated directly (the exact element superposition).
    element_samples : int
        Sub-samples per element of the element response (its cost per offset relative
        to one assembly term, used to decide where the lattice pays).
    tolerance : float
        Targets whose (y, z) agree to this (m) form one line; offsets closer than this
        are merged.

    Returns
    -------
    ElementPlan
    """
    from holoprobe.transducer._field import element_offsets

    el = np.asarray(elements, dtype=np.int64).reshape(-1)
    n = points.shape[0]
    # the lattice is a 1-D row along x: a 2-D layout (vt.array) is evaluated directly
    chosen = (_lattice_targets(vt, points, el, f_max, element_samples, tolerance)
              if lattice and vt.element_count > 1 and vt.array is None else None)
    if chosen is None:
        offsets, index = element_offsets(vt, points, el, tolerance=tolerance)
        return ElementPlan(offsets, index, np.arange(n)[:, None], np.ones((n, 1)),
                           math.nan, 0)
    use, line_of, j_taps, weights, h, m = chosen
    taps = j_taps.shape[1]
    # nodes: distinct (line, j) pairs of the interpolated targets, sorted by line then j
    j_min = int(j_taps.min())
    span = int(j_taps.max()) - j_min + 1
    key = line_of[use][:, None] * span + (j_taps - j_min)
    node_key, node_of = np.unique(key.reshape(-1), return_inverse=True)
    node_line, node_j = np.divmod(node_key, span)
    node_j += j_min
    starts = np.flatnonzero(np.r_[True, node_line[1:] != node_line[:-1]])
    lo, hi = _offset_range(node_j[starts], np.r_[node_j[starts[1:] - 1], node_j[-1]],
                           int(el.min()) * m, int(el.max()) * m)
    counts = hi - lo + 1
    base = np.concatenate([[0], np.cumsum(counts)[:-1]]) - lo
    per_node = np.repeat(np.arange(starts.size), np.diff(np.r_[starts, node_j.size]))
    index = np.empty((el.size, node_j.size), dtype=np.int32)
    _node_offsets(node_j.astype(np.int32), (el * m).astype(np.int32),
                  base[per_node].astype(np.int32), index)
    yz = points[_first_of(line_of, node_line[starts])][:, 1:3]
    line_row = np.repeat(np.arange(starts.size), counts)
    u_rows = np.arange(int(counts.sum())) - base[line_row]
    yc = vt.aperture_center[1]
    offsets = np.stack([u_rows * h, np.abs(yz[line_row, 0] - yc), yz[line_row, 1]], axis=-1)
    columns = np.empty((n, taps), dtype=np.int64)
    weight = np.zeros((n, taps))
    columns[use] = node_of.reshape(-1, taps)
    weight[use] = weights
    direct = np.flatnonzero(~use)
    if direct.size:
        off_d, idx_d = element_offsets(vt, points[direct], el, tolerance=tolerance)
        index = np.concatenate([index, (idx_d + offsets.shape[0]).astype(np.int32)], axis=1)
        offsets = np.concatenate([offsets, off_d])
        columns[direct] = (node_key.size + np.arange(direct.size))[:, None]
        weight[direct, 0] = 1.0
    return ElementPlan(offsets, index, columns, weight, h, int(use.sum()))


@njit(parallel=True, cache=True)
def _node_offsets(node_j, em, base, out):  # pragma: no cover - compiled
    """out[e, i] = |node_j[i] − em[e]| + base[i]: the offset row element e sees from node i
    (one pass into one int32 array instead of three (n_el, n_nodes) temporaries)."""
    for e in prange(em.size):
        for i in range(node_j.size):
            out[e, i] = abs(node_j[i] - em[e]) + base[i]


def _offset_range(j_min: NDArray, j_max: NDArray, e_lo: int, e_hi: int
                  ) -> tuple[NDArray, NDArray]:
    """Smallest and largest |j − e m|: nodes j in [j_min, j_max], element nodes in [e_lo, e_hi]."""
    hi = np.maximum(np.abs(j_max - e_lo), np.abs(j_min - e_hi))
    lo = np.where((j_max >= e_lo) & (j_min <= e_hi), 0,
                  np.minimum(np.abs(j_min - e_hi), np.abs(j_max - e_lo)))
    return lo, hi


def _first_of(line_of: NDArray, lines: NDArray) -> NDArray[np.int64]:
    """Index of the first target of each line in ``lines``."""
    order = np.argsort(line_of, kind="stable")
    first = order[np.searchsorted(line_of[order], lines)]
    return first


def _lattice_targets(vt: VirtualTransducer, points: NDArray, el: NDArray, f_max: float,
                     element_samples: int, tolerance: float):
    """Targets to interpolate (mask), their line, tap nodes and weights; None if none pays."""
    if not (math.isfinite(f_max) and f_max > 0):
        raise InputError(f"expected a positive frequency in Hz, got {f_max!r}", field="f_max")
    m, h, band, taps = lattice_step(vt.pitch, vt.medium.sound_speed / f_max)
    k = 2 * math.pi * f_max / vt.medium.sound_speed
    kappa_ok = k * (1.0 + band) / (2.0 * band)
    z_min = _EVANESCENT_DECAY / math.sqrt(kappa_ok**2 - k**2)
    x0 = float(vt.element_centers()[0, 0])
    s = (points[:, 0] - x0) / h
    on_node = np.abs(s - np.rint(s)) * h <= tolerance
    yz = np.rint(points[:, 1:3] / tolerance).astype(np.int64)
    line_of = unique_pairs(yz)[1]
    j_taps = np.floor(s).astype(np.int64)[:, None] + np.arange(1 - taps // 2, taps // 2 + 1)
    # a target on a node is that node (weight 1): the exact element superposition
    j_taps[on_node] = np.rint(s[on_node]).astype(np.int64)[:, None]
    n_lines = int(line_of.max()) + 1
    per_line = np.bincount(line_of, minlength=n_lines)
    j_min = np.full(n_lines, np.iinfo(np.int64).max)
    j_max = np.full(n_lines, np.iinfo(np.int64).min)
    np.minimum.at(j_min, line_of, j_taps[:, 0])
    np.maximum.at(j_max, line_of, j_taps[:, -1])
    lo, hi = _offset_range(j_min, j_max, int(el.min()) * m, int(el.max()) * m)
    n_nodes = np.minimum(j_max - j_min + 1, per_line * taps)
    lattice_cost = (hi - lo + 1) + n_nodes * el.size / max(1, element_samples)
    good = lattice_cost < 0.5 * per_line * el.size
    use = good[line_of] & (points[:, 2] >= z_min)
    if not np.any(use):
        return None
    weights = lattice_kernel(s[use, None] - j_taps[use], taps, band)
    on = on_node[use]
    weights[on] = 0.0
    weights[on, 0] = 1.0
    return use, line_of, j_taps[use], weights, h, m


def lattice_step(pitch: float, wavelength: float) -> tuple[int, float, float, int]:
    """Element-lattice step and interpolation kernel for the shortest wavelength.

    Parameters
    ----------
    pitch : float
        Element pitch in m.
    wavelength : float
        Shortest wavelength of the band in m.

    Returns
    -------
    (m, h, band, taps)
        ``h = pitch/m`` with the smallest m that gives ``h ≤ wavelength/3.2``; ``band
        = k h/π = 2h/λ`` (≤ 0.625); the kernel length: 16 taps for band ≤ 0.5, else 20
        (worst-case interpolation error ≤ 2e-8 resp. 5e-7 of the sum of plane-wave
        amplitudes, measured).
    """
    m = max(1, math.ceil(pitch / (wavelength / 3.2) - 1e-9))
    h = pitch / m
    band = 2.0 * h / wavelength
    return m, h, band, (16 if band <= 0.5 else 20)


def column_tables_field(vt: VirtualTransducer, offsets: NDArray, frequencies: NDArray, *,
                        points_per_wavelength: float = 4.0, lens: bool = True,
                        dtype: type = np.float64, tolerance: float = 1e-9
                        ) -> NDArray[np.complexfloating] | None:
    """The element response at ``offsets`` from tables over ρ, or None where that saves nothing.

    The element's sub-samples form nx columns along y (at x offsets ux_i, each with the
    lens delays and the same y samples as :func:`holoprobe.transducer.element_field`;
    on a convex element the columns lie on its arc, :func:`element_profile`).
    A column's response at a target depends on the target only through its elevation v
    and ``ρ = √((u − ux_i)² + z²)``: ``C_v(ρ) = Σ_y a_y e^{ikR}/R``, ``R = √(ρ² + (v −
    y)²)``, whose local wavenumber in ρ is ``kρ/R ≤ k``. One table of C_v over ρ at a
    step λ_min/3.2 per distinct v, interpolated with the Kaiser-windowed sinc of
    :func:`lattice_kernel` (20 taps), gives G = Σ_i C_v(ρ_i) for every offset with that
    v at nx·20 multiply-adds per frequency instead of nx·ny kernel evaluations.
    Offsets nearer the face than 3 λ_min (where 1/R varies within a wavelength) are
    left out (the caller evaluates them directly).

    Returns
    -------
    ndarray, shape (n, nf), or None
        G like ``element_field`` (Pa/(m/s)) with NaN rows for the offsets left out; None
        when the tables would not save work.
    """
    from holoprobe.propagation import rayleigh_integral
    from holoprobe.transducer._field import _element_grid, element_profile

    f = np.asarray(frequencies, dtype=float).reshape(-1)
    f_max = float(f.max())
    ux, uy, tau_lens = _element_grid(vt, f_max, points_per_wavelength, lens)
    wavelength = vt.medium.sound_speed / f_max
    step = wavelength / 3.2
    band, taps = 2.0 * step / wavelength, 20
    ok = offsets[:, 2] >= 3.0 * wavelength
    v_key = np.rint(offsets[:, 1] / tolerance).astype(np.int64)
    keys, v_of = np.unique(v_key[ok], return_inverse=True)
    if keys.size == 0:
        return None
    along, depth = element_profile(vt, ux)  # the columns' (u, w) on a curved element
    rho = np.sqrt((offsets[ok, 0][:, None] - along[None, :]) ** 2
                  + (offsets[ok, 2][:, None] - depth[None, :]) ** 2)
    lo = np.full(keys.size, np.inf)
    hi = np.full(keys.size, -np.inf)
    np.minimum.at(lo, v_of, rho.min(axis=1))
    np.maximum.at(hi, v_of, rho.max(axis=1))
    start = np.floor(lo / step) - taps // 2
    counts = (np.ceil(hi / step) + taps // 2 - start + 1).astype(np.int64)
    n_ok = int(ok.sum())
    if counts.sum() * uy.size + n_ok * ux.size * taps / 3 >= 0.5 * n_ok * ux.size * uy.size:
        return None
    base = np.concatenate([[0], np.cumsum(counts)[:-1]])
    v_vals = offsets[ok, 1][np.unique(v_of, return_index=True)[1]]
    row_v = np.repeat(np.arange(keys.size), counts)
    rho_grid = (np.repeat(start, counts) + np.arange(int(counts.sum())) - np.repeat(base, counts)
                ) * step
    column = Surface(np.stack([np.zeros(uy.size), uy, np.zeros(uy.size)], axis=-1),
                     np.tile([0.0, 0.0, 1.0], (uy.size, 1)),
                     np.full(uy.size, vt.element_width / ux.size * vt.element_height / uy.size))
    targets = Surface(np.stack([np.zeros(rho_grid.size), v_vals[row_v], rho_grid], axis=-1),
                      np.tile([0.0, 0.0, 1.0], (rho_grid.size, 1)), np.ones(rho_grid.size))
    velocity = np.exp((2j * np.pi) * tau_lens[:, None] * f[None, :])
    table = rayleigh_integral(velocity, column, targets, f, vt.medium, kernel="fwd_vp",
                              baffle="rigid", dtype=dtype)
    # table row of node j of each offset's v table (ρ = (start + j)·step), then one pass
    row0 = (base - start.astype(np.int64))[v_of]
    out = np.full((offsets.shape[0], f.size), np.nan, dtype=table.dtype)
    part = np.empty((n_ok, f.size), dtype=table.dtype)
    real = table.real.dtype
    _column_sums(table.view(real), np.ascontiguousarray(rho), row0, step, taps,
                 window_coefficients(taps, band), part.view(real))
    out[ok] = part
    return out
