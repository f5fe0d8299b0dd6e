"""Reusable projection plans: the scan's angular spectrum computed once, projected many times.

The fast path of DESIGN.md ("Propagation: the fast path and the exact path"):
the field P(u, v; ω) on a source plane with pose (R, r0) is zero-padded and
Fourier transformed to its angular spectrum P̂(κu, κv). Every propagating
component (|κ| < k) is a plane wave with wave vector k' = (κu, κv, +kz) in plane
coordinates, k = R k' in transducer coordinates, so for any point r

    p(r) = Σ_κ [P̂(κ) e^{−i k·r0} Δκu Δκv / 4π²] e^{i k·r},

and the normal velocity on a surface with unit normal n is the same sum with
each term multiplied by (k·n)/(k ρ0 c0). For targets on a uniform grid of a
plane this is a 2-D type-1 non-uniform FFT; for arbitrary points a 3-D type-3
NUFFT (finufft). The sum is exact for planar source data without evanescent
waves, the same assumption as the backward Rayleigh integral, so it agrees with
the dense Rayleigh oracle to the NUFFT tolerance.

A :class:`ProjectionPlan` follows finufft's two tiers (one-call function, reusable
plan): it holds the padded angular spectrum of one data set (only the square
|κu|, |κv| < k of each frequency, which holds every propagating wave) and projects
it onto any number of targets — the transmit iterations, the virtual sensor —
without re-padding or re-transforming the data. ``project()`` is the one-call
form. ``ProjectionPlan.adjoint`` applies the exact adjoint of the discrete
operator (PyLops' ``rmatvec``); between parallel planes with the same padded grid
the backward projection *is* that adjoint (its plane waves are the conjugates of
the forward ones), which the dot tests in ``tests/test_project_plan.py`` check.

Padding rule
------------
Zero padding to a period L makes the discrete angular spectrum describe the
data repeated every L. An image of the data at lateral distance L influences a
target at distance |w| from the source plane only through waves travelling at
angles θ with |w|·tan θ ≥ the gap between image and target. The padded period
along each in-plane axis is therefore chosen as

    L ≥ (extent of the union of the data and the target, projected on the
         source plane) + 2 |w|_max tan(guard_angle) + one step,

rounded up to a fast FFT length, with ``guard_angle`` (default 80°) a keyword.
Energy travelling at larger angles (rare in a measurement that captures the
field) can still alias; raise ``guard_angle`` or pass ``padding`` explicitly. A
plan reuses its spectra for a later target whose rule asks for no larger a
period (more padding never hurts), and recomputes them otherwise.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Iterator
from typing import Any, Literal

import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

from holoprobe._progress import progress_iter
from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose, Surface
from holoprobe.signal import Threads, next_fast_length, workers

__all__ = ["ProjectionPlan", "image_taper_range", "padded_shape"]

Quantity = Literal["pressure", "normal_velocity"]

_PLANE_TOL = 1e-9  # m: a target closer than this to the source plane lies on it


def _validate_field(field: ArrayLike, source: PlaneGrid, frequencies: ArrayLike
                    ) -> tuple[NDArray, NDArray[np.float64]]:
    if not isinstance(source, PlaneGrid):
        raise InputError("expected a holoprobe.PlaneGrid for the source plane", field="source")
    freqs = np.atleast_1d(np.asarray(frequencies, dtype=float))
    if freqs.ndim != 1:
        raise InputError(f"expected a 1-D vector of frequencies, got shape {freqs.shape}",
                         field="frequencies")
    if not np.all(np.isfinite(freqs)) or np.any(freqs <= 0):
        raise InputError("expected finite, positive frequencies in Hz", field="frequencies")
    arr = np.asarray(field)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    expected = (*source.shape, freqs.size)
    if arr.shape != expected:
        raise InputError(
            f"expected shape (nx, ny, nf) = {expected} to match the source grid and the "
            f"frequencies, got {arr.shape}",
            field="field",
        )
    if not np.all(np.isfinite(arr)):
        raise InputError("contains NaN or inf", field="field")
    if source.x.size < 2 or source.y.size < 2:
        raise InputError("the source grid needs at least 2 points along x and y",
                         field="source")
    return arr, freqs


def _check_sampling(source: PlaneGrid, freqs: NDArray, medium: Medium,
                    allow_undersampled: bool) -> None:
    wavelength = medium.sound_speed / freqs.max()
    step = max(source.dx, source.dy)
    if step > wavelength / 2 * (1 + 1e-9) and not allow_undersampled:
        raise InputError(
            f"scan step {step * 1e3:.4g} mm is coarser than λ/2 = {wavelength / 2 * 1e3:.4g} mm "
            f"at the highest frequency {freqs.max() / 1e6:.4g} MHz; lower the band or pass "
            "allow_undersampled=True",
            field="source",
        )


def _check_target(target: object) -> None:
    if not isinstance(target, PlaneGrid | Surface):
        raise InputError("expected a holoprobe.PlaneGrid or holoprobe.Surface", field="target")


def _target_local(source: PlaneGrid, target: PlaneGrid | Surface) -> NDArray[np.float64]:
    """Target points in source-plane coordinates (u, v, w), shape (n, 3)."""
    points = target.points() if isinstance(target, PlaneGrid) else target.points
    return source.pose.to_local(points)


def _target_bounds(source: PlaneGrid, target: PlaneGrid | Surface) -> NDArray[np.float64]:
    """Target points in source-plane coordinates that hold the extremes of every
    coordinate (u, v, w) over the target: a grid's four corners (affine in its points),
    all points of a surface; shape (n, 3)."""
    if isinstance(target, PlaneGrid):
        return source.pose.to_local(target.corners())
    return _target_local(source, target)


def _direction(local: NDArray[np.float64]) -> Literal["forward", "backward", "on_plane"]:
    w = local[:, 2]
    if np.all(np.abs(w) <= _PLANE_TOL):
        return "on_plane"
    if np.all(w >= -_PLANE_TOL):
        return "forward"
    if np.all(w <= _PLANE_TOL):
        return "backward"
    raise InputError(
        f"the target straddles the source plane (its points lie from w = {w.min() * 1e3:.4g} "
        f"to {w.max() * 1e3:.4g} mm along the source normal); split it into the parts in front "
        "of and behind the plane",
        field="target",
    )


def padded_shape(source: PlaneGrid, target: PlaneGrid | Surface, *,
                 guard_angle: float = np.deg2rad(80.0),
                 padding: float | tuple[int, int] | None = None) -> tuple[int, int]:
    """Zero-padded grid size for projecting from ``source`` onto ``target``.

    Parameters
    ----------
    source : PlaneGrid
        The plane holding the data.
    target : PlaneGrid or Surface
        Where the field is wanted.
    guard_angle : float
        Largest propagation angle (rad) whose periodic images are kept away from the
        target (see the module notes).
    padding : float or (int, int), optional
        Override: a factor applied to the source size, or an explicit shape.

    Returns
    -------
    (int, int)
        Padded size (npx, npy), at least the source size, FFT friendly.
    """
    nx, ny = source.shape
    if padding is not None:
        values = np.asarray(padding, dtype=float).reshape(-1)
        if np.ndim(padding) == 0:
            factor = float(values[0])
            if not factor >= 1:
                raise InputError("a padding factor must be ≥ 1", field="padding")
            sizes = [int(np.ceil(nx * factor)), int(np.ceil(ny * factor))]
        else:
            sizes = [int(v) for v in values]
            if len(sizes) != 2 or sizes[0] < nx or sizes[1] < ny:
                raise InputError(f"expected (npx, npy) ≥ {(nx, ny)}, got {padding}",
                                 field="padding")
        return (next_fast_length(sizes[0]), next_fast_length(sizes[1]))
    if not 0 <= guard_angle < np.pi / 2:
        raise InputError("expected an angle in [0, π/2) rad", field="guard_angle")
    local = _target_bounds(source, target)
    w_max = np.max(np.abs(local[:, 2]))
    guard = 2.0 * w_max * np.tan(guard_angle)
    sizes = []
    for axis, coords, step in ((0, source.x, source.dx), (1, source.y, source.dy)):
        # an image of the data shifted by L must stay `guard` away from the target:
        # L ≥ (extent of data ∪ target) + guard
        union = max(coords[-1], local[:, axis].max()) - min(coords[0], local[:, axis].min())
        n_min = int(np.ceil((union + guard) / step)) + 1
        sizes.append(next_fast_length(max(n_min, coords.size)))
    return (sizes[0], sizes[1])


def image_taper_range(source: PlaneGrid, target: PlaneGrid | Surface,
                      shape: tuple[int, int]) -> tuple[float, float] | None:
    """Directions (sin θ from the source normal) between which a plan with
    ``image_taper`` fades its plane waves out for ``target`` at the padded ``shape``.

    The field of the data reaches a target point along directions no steeper than
    ``s_in``, the largest sin θ of a line from a data point to a target point; the
    nearest periodic image of the padded data (one period L away along x or y) reaches
    it along directions no shallower than ``s_out`` = g/√(g² + w_max²), g = L − (extent
    of data ∪ target) the smallest lateral gap. Waves steeper than ``s_out`` carry only
    images (and edge waves that miss the target), so a taper from 1 at ``s_in`` to 0 at
    ``s_out`` removes the images without touching the field the target sees.

    Parameters
    ----------
    source : PlaneGrid
        The data plane.
    target : PlaneGrid or Surface
        The target.
    shape : (int, int)
        Padded size (npx, npy).

    Returns
    -------
    (float, float) or None
        (s_in, s_out); None when they do not leave room for a taper (s_in ≥ s_out) or
        the target lies on the source plane.
    """
    local = _target_bounds(source, target)
    w = np.abs(local[:, 2])
    if w.min() <= _PLANE_TOL:
        return None
    gaps, reach = [], []
    for axis, coords, step, n in ((0, source.x, source.dx, shape[0]),
                                  (1, source.y, source.dy, shape[1])):
        t = local[:, axis]
        reach.append(max(t.max() - coords[0], coords[-1] - t.min()))
        gaps.append(n * step - (max(coords[-1], t.max()) - min(coords[0], t.min())))
    lateral, gap = float(np.hypot(*reach)), float(min(gaps))
    s_in = lateral / math.hypot(lateral, float(w.min()))
    s_out = gap / math.hypot(gap, float(w.max())) if gap > 0 else 0.0
    return (s_in, s_out) if s_in < s_out else None


def _taper_weights(block: _Block, taper: tuple[float, float]
                   ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """Rows and columns of ``block`` inside |κ| < k·s_out and the raised-cosine weight
    (1 up to |κ| = k·s_in, 0 from k·s_out) of each of their waves."""
    s_in, s_out = taper
    k_out = block.k * s_out
    r = np.flatnonzero(np.abs(block.kx) < k_out)
    c = np.flatnonzero(np.abs(block.ky) < k_out)
    s = np.hypot(block.kx[r][:, None], block.ky[c][None, :]) / block.k
    x = np.clip((s - s_in) / (s_out - s_in), 0.0, 1.0)
    return r, c, 0.5 + 0.5 * np.cos(np.pi * x)


def _tapered_block(block: _Block, taper: tuple[float, float] | None) -> _Block:
    """``block`` cut to |κ| < k·s_out with its values faded out (:func:`_taper_weights`);
    ``block`` itself without a taper."""
    if taper is None:
        return block
    r, c, weight = _taper_weights(block, taper)
    values = (block.values[np.ix_(r, c)] * weight).astype(block.values.dtype, copy=False)
    return _Block(block.n, block.k, block.rows[r], block.cols[c], block.kx[r], block.ky[c],
                  values)


def _fused_taper(transforms: list, taper: tuple[float, float] | None
                 ) -> tuple[float, float] | None:
    """Hand the image taper to plane-grid transforms, which fade the waves while forming
    them (:func:`~holoprobe.propagation._project_numba.plane_wave_terms`: no cut copy of
    each block, 0.075 s CPU per full-size receive prediction); returns what is left for
    :func:`_tapered_block` (the taper for point transforms, None otherwise)."""
    if taper is None or not all(isinstance(t, _PlaneTransform) for t in transforms):
        return taper
    for t in transforms:
        t.taper = taper
    return None


def _wave_vectors(kx: NDArray, ky: NDArray, k: float
                  ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """Indices and kz of the propagating components |κ| < k of a (kx, ky) grid."""
    kr2 = kx[:, None] ** 2 + ky[None, :] ** 2
    ix, iy = np.nonzero(kr2 < k * k)
    kz = np.sqrt(k * k - kr2[ix, iy])
    return ix, iy, kz


class _Block:
    """The square |κx|, |κy| < k of one frequency's padded spectrum.

    ``rows``/``cols`` index the full padded grid (FFT order); ``kx``/``ky`` are their
    wave numbers in rad/m; ``values`` (len(rows), len(cols)) the spectrum there.
    """

    __slots__ = ("cols", "k", "kx", "ky", "n", "rows", "values")

    def __init__(self, n: int, k: float, rows: NDArray, cols: NDArray, kx: NDArray,
                 ky: NDArray, values: NDArray):
        self.n, self.k, self.rows, self.cols = n, k, rows, cols
        self.kx, self.ky, self.values = kx, ky, values


class _PlaneTransform:
    """Σ_j c_j exp(i k_j · r) on the points r of a target plane grid (2-D type-1 NUFFT).

    The plane waves are those of a padded angular spectrum on the source plane; the
    strengths and NUFFT coordinates come from one fused numba pass over the spectrum
    (:func:`holoprobe.propagation._project_numba.plane_wave_terms`). One instance per
    thread: it owns single-threaded finufft plans (threads work on different
    frequencies, which scales better than finufft's own threads on small problems).
    """

    def __init__(self, source: PlaneGrid, target: PlaneGrid, eps: float, dtype: type, *,
                 velocity: bool, time_origin: float, impedance: float, scale: float):
        nxt, nyt = target.shape
        dxt = target.dx if nxt > 1 else 1.0
        dyt = target.dy if nyt > 1 else 1.0
        # finufft's output index m carries mode m − n//2: reference the phase there
        ref = np.array([target.x[0] + (nxt // 2) * dxt, target.y[0] + (nyt // 2) * dyt, 0.0])
        rs, rt = source.pose.rotation, target.pose.rotation
        to_target = rt.T @ rs  # local source wave vector → components along the target axes
        # phase of each plane wave: −κ·(x0, y0) on the source grid, −k·r0_s for the source
        # pose, +k·r0_t + q·ref for the target grid; all linear in k' = (κx, κy, kz)
        self.phase_vector = (-np.array([source.x[0], source.y[0], 0.0])
                             + rs.T @ (target.pose.origin_array - source.pose.origin_array)
                             + to_target.T @ ref)
        self.time_origin = time_origin
        self.x_map = to_target[0] * dxt
        self.y_map = to_target[1] * dyt
        self.velocity = velocity
        self.velocity_vector = rs.T @ target.pose.normal / impedance
        self.scale = scale
        self.dtype = dtype
        self.real = np.float32 if dtype == np.complex64 else np.float64
        self.modes = (nxt, nyt)
        self.eps = eps
        # the image taper (s_in, s_out) applied while the waves are formed (forward only)
        self.taper: tuple[float, float] | None = None
        self.plans: dict[int, Any] = {}
        self._size = 0
        self.c: NDArray[np.complexfloating] = np.empty(0, dtype)
        self.xs: NDArray[np.floating] = np.empty(0, self.real)
        self.ys: NDArray[np.floating] = np.empty(0, self.real)
        self.ii: NDArray[np.int32] = np.empty(0, np.int32)
        self.jj: NDArray[np.int32] = np.empty(0, np.int32)

    def _buffers(self, size: int) -> None:
        if size > self._size:
            self._size = size
            self.c = np.empty(size, self.dtype)
            self.xs = np.empty(size, self.real)
            self.ys = np.empty(size, self.real)
            self.ii = np.empty(size, np.int32)
            self.jj = np.empty(size, np.int32)

    def _terms(self, values: NDArray, block: _Block) -> int:
        from holoprobe.propagation._project_numba import plane_wave_terms

        self._buffers(values.size)
        k = block.k
        s_in, s_out = (2.0, 2.0) if self.taper is None else self.taper
        count = plane_wave_terms(values, block.kx, block.ky, k, self.phase_vector,
                                 -k * self.time_origin, self.x_map, self.y_map,
                                 self.velocity_vector / k, self.velocity, self.scale,
                                 self.c, self.xs, self.ys, self.ii, self.jj, s_in, s_out)
        if count == 0:
            return 0
        xs, ys = self.xs[:count], self.ys[:count]
        if max(np.abs(xs).max(), np.abs(ys).max()) >= 3 * np.pi:  # finufft wants [−3π, 3π)
            np.mod(xs + np.pi, 2 * np.pi, out=xs)
            xs -= np.pi
            np.mod(ys + np.pi, 2 * np.pi, out=ys)
            ys -= np.pi
        return int(count)

    def _plan(self, kind: int):
        import finufft

        if kind not in self.plans:
            # the plane waves come in lattice order, which maps to a raster on the
            # target: finufft's bin sort of the type-1 points only costs (−15 % CPU of a
            # full-size back-projection; the sums' order changes the float32 rounding
            # only, 5e-7 of the peak)
            sort = {"spread_sort": 0} if kind == 1 else {}
            self.plans[kind] = finufft.Plan(kind, self.modes, eps=self.eps,
                                            isign=1 if kind == 1 else -1, dtype=self.dtype,
                                            nthreads=1, **sort)
        return self.plans[kind]

    def __call__(self, block: _Block) -> NDArray | None:
        count = self._terms(block.values, block)
        if count == 0:
            return None
        plan = self._plan(1)
        plan.setpts(self.xs[:count], self.ys[:count])
        return plan.execute(self.c[:count])

    def adjoint(self, values: NDArray, block: _Block) -> NDArray:
        """A^H of ``__call__``: target-grid values (nxt, nyt) → spectrum block."""
        ones: NDArray[np.complexfloating] = np.ones(block.values.shape, dtype=self.dtype)
        count = self._terms(ones, block)  # c_j = (velocity factor)·scale·e^{iφ_j}
        out = np.zeros(block.values.shape, dtype=np.complex128)
        if count == 0:
            return out
        plan = self._plan(2)
        plan.setpts(self.xs[:count], self.ys[:count])
        t = plan.execute(np.ascontiguousarray(values, dtype=self.dtype))
        out[self.ii[:count], self.jj[:count]] = np.conj(self.c[:count]) * t
        return out


class _ReducedTransform(_PlaneTransform):
    """Weighted sums of a target plane grid's field without the grid (1-D NUFFTs).

    ``out[g] = Σ_k a_k Σ_j b_j P(x_{g·m+k}, y_j)`` for groups g of ``m`` consecutive
    columns (kernel ``a``, shape (m,)) and row weights ``b`` (shape (ny,), per
    frequency). A plane wave of NUFFT coordinates (ξ, η) contributes
    ``c e^{iξ(g m + k − nx//2)} e^{iη(j − ny//2)}``, so its sum factors into the row
    sum ``Σ_j b_j e^{iη(j − ny//2)}`` (a 1-D type-2 NUFFT), the kernel polynomial
    ``Σ_k a_k e^{iξk}`` (Horner) and the group phase ``e^{i g m ξ}`` summed over the
    waves by a 1-D type-1 NUFFT with one mode per group: O(waves × kernel width)
    instead of the 2-D spreading and FFT of the whole grid.
    """

    def __init__(self, source: PlaneGrid, target: PlaneGrid, eps: float, dtype: type, *,
                 velocity: bool, time_origin: float, impedance: float, scale: float,
                 kernel: NDArray, row_weights: NDArray):
        super().__init__(source, target, eps, dtype, velocity=velocity,
                         time_origin=time_origin, impedance=impedance, scale=scale)
        self.kernel = np.asarray(kernel, dtype=np.complex128)
        self.row_weights = row_weights  # (nf, ny), indexed by the block's frequency
        nx = target.shape[0]
        self.groups = nx // self.kernel.size
        # e^{iξ(gm + k − nx//2)} = e^{i(g − G//2) mξ} e^{iξk} e^{iξ(G//2·m − nx//2)}
        self.shift = (self.groups // 2) * self.kernel.size - nx // 2
        self.plans_1d: dict[int, Any] = {}

    def _plan_1d(self, kind: int, modes: int):
        import finufft

        if kind not in self.plans_1d:
            self.plans_1d[kind] = finufft.Plan(kind, (modes,), eps=self.eps, isign=1,
                                               dtype=self.dtype, nthreads=1)
        return self.plans_1d[kind]

    def __call__(self, block: _Block) -> NDArray | None:
        from holoprobe.propagation._project_numba import group_terms

        count = self._terms(block.values, block)
        if count == 0:
            return None
        xs, ys = self.xs[:count], self.ys[:count]  # in [−3π, 3π) (_terms)
        rows = self._plan_1d(2, self.modes[1])
        rows.setpts(ys)
        weights: NDArray[Any] = np.ascontiguousarray(self.row_weights[block.n],
                                                     dtype=self.dtype)
        c = self.c[:count]
        c *= rows.execute(weights)
        phase = self.xs[:count]  # ξ → m ξ (mod 2π) in place, once read
        group_terms(c, xs, self.kernel, self.shift, self.kernel.size, phase)
        groups = self._plan_1d(1, self.groups)
        groups.setpts(phase)
        return groups.execute(c)


class _PointTransform:
    """Σ_j c_j exp(i k_j · r) at arbitrary points r (3-D type-3 NUFFT) and its adjoint."""

    def __init__(self, source: PlaneGrid, target: Surface, eps: float, dtype: type, *,
                 velocity: bool, time_origin: float, impedance: float, scale: float):
        points = target.points
        self.centre = 0.5 * (points.max(axis=0) + points.min(axis=0))
        self.real = np.float32 if dtype == np.complex64 else np.float64
        self.shifted = np.ascontiguousarray((points - self.centre).T, dtype=self.real)
        self.normals = np.asarray(target.normals, dtype=float)
        self.dtype, self.eps = dtype, eps
        self.velocity, self.time_origin = velocity, time_origin
        self.impedance, self.scale = impedance, scale
        self.rot = source.pose.rotation
        self.r0 = source.pose.origin_array
        self.grid0 = (source.x[0], source.y[0])

    def _waves(self, block: _Block):
        """Propagating waves of the block: indices, wave vectors, strengths without data."""
        k = block.k
        ix, iy, kz = _wave_vectors(block.kx, block.ky, k)
        kvec = np.stack([block.kx[ix], block.ky[iy], kz], axis=-1) @ self.rot.T
        # P̂(κ) = Σ P(x_i, y_j) e^{−iκ·(x_i, y_j)} dx dy (the grid's own coordinates),
        # the plane origin r0 and the time origin enter as phases
        phase = -(block.kx[ix] * self.grid0[0] + block.ky[iy] * self.grid0[1]
                  + kvec @ self.r0 + k * self.time_origin)
        factor = self.scale * np.exp(1j * (phase + kvec @ self.centre))
        return ix, iy, kvec, factor

    def _plan(self, kvec: NDArray, isign: int, n_trans: int):
        import finufft

        plan = finufft.Plan(3, 3, n_trans=n_trans, eps=self.eps, isign=isign,
                            dtype=self.dtype, nthreads=1)
        kt = np.ascontiguousarray(kvec.T, dtype=self.real)
        s = self.shifted
        if isign > 0:
            plan.setpts(kt[0], kt[1], kt[2], s[0], s[1], s[2])
        else:
            plan.setpts(s[0], s[1], s[2], kt[0], kt[1], kt[2])
        return plan

    def __call__(self, block: _Block) -> NDArray | None:
        ix, iy, kvec, factor = self._waves(block)
        if ix.size == 0:
            return None
        coef = block.values[ix, iy] * factor
        if not self.velocity:
            plan = self._plan(kvec, 1, 1)
            return plan.execute(np.ascontiguousarray(coef, dtype=self.dtype))
        stacked = (kvec.T / (block.k * self.impedance)) * coef[None, :]
        plan = self._plan(kvec, 1, 3)
        result = plan.execute(np.ascontiguousarray(stacked, dtype=self.dtype))
        return np.einsum("dn,nd->n", result, self.normals)

    def adjoint(self, values: NDArray, block: _Block) -> NDArray:
        """A^H of ``__call__``: values at the points (n,) → spectrum block."""
        ix, iy, kvec, factor = self._waves(block)
        out = np.zeros(block.values.shape, dtype=np.complex128)
        if ix.size == 0:
            return out
        if self.velocity:
            weighted = self.normals.T * values[None, :]  # (3, n)
            t = self._plan(kvec, -1, 3).execute(np.ascontiguousarray(weighted, self.dtype))
            t = np.einsum("dn,nd->n", t, kvec / (block.k * self.impedance))
        else:
            t = self._plan(kvec, -1, 1).execute(np.ascontiguousarray(values, self.dtype))
        out[ix, iy] = np.conj(factor) * t
        return out


class ProjectionPlan:
    """Angular spectrum of one plane's data, computed once and projected onto many targets.

    finufft's ``Plan`` pattern for :func:`project`: build the plan from the data, then
    call :meth:`project` for every target (the transmit iterations, the virtual
    sensor, any number of field planes or point sets); the padded FFT of the data is
    done once (the square |κx|, |κy| < k of each frequency is kept, which holds every
    propagating wave). :meth:`adjoint` applies the adjoint of the same discrete
    operator.

    Parameters
    ----------
    field : array_like, complex, shape (nx, ny, nf)
        Pressure (Pa·s, holoprobe's Fourier convention) on the source plane; the waves
        travel along ``source.pose.normal``.
    source : PlaneGrid
        The measurement plane (uniform grid, any pose).
    frequencies : array_like, shape (nf,)
        Frequencies in Hz (positive).
    medium : Medium, optional
        Propagation medium (default water at 20 °C).
    eps : float
        Relative tolerance of the non-uniform FFTs.
    guard_angle : float
        Padding rule parameter in rad (see the module notes).
    padding : float or (int, int), optional
        Override the automatic padding (a factor or an explicit shape).
    allow_undersampled : bool
        Allow a scan step coarser than λ/2 at the highest frequency.
    single_precision : bool
        Run the FFTs of the data and the non-uniform FFTs in complex64 (about twice as
        fast; relative accuracy floors near 1e-5).
    max_memory : int
        Bytes allowed for the FFT work buffer.
    cache : bool
        Keep the spectra between calls (the point of a plan; ``project()`` passes
        False for a single call, which streams them with bounded memory). Memory:
        about 16 bytes × Σ_f (2k/Δκx)(2k/Δκy) (8 with ``single_precision``).
    max_cache_bytes : int, optional
        Most bytes of spectra kept: the frequencies are kept in their order while they fit
        (for an ascending axis the lowest ones, whose blocks are the smallest while
        every frequency costs the same FFT), the others are transformed again at every
        projection. Default: no limit.
    exact_padding : bool
        Pad every target to exactly the padding rule's size, so that each projection
        gives the same numbers as :func:`project` would (the spectra are reused while
        that size stays the same and recomputed when it changes). By default a later
        target whose rule asks for no larger a period reuses the larger cached spectra.
    image_taper : bool
        Fade the plane waves out (raised cosine in sin θ) between the steepest direction
        from the data to each target and the shallowest one from the data's nearest
        periodic image (:func:`image_taper_range`): the images of the padding then do
        not reach a target far from a small scan even where the guard angle lets their
        steep waves through, at no cost (fewer waves are projected). No effect where
        those directions leave no room, nor on :func:`project_cylinder`.

    Examples
    --------
    >>> import numpy as np
    >>> from holoprobe.geometry import PlaneGrid, Pose
    >>> src = PlaneGrid.centered(32, 32, 0.3e-3)
    >>> data = np.zeros((32, 32, 1), complex); data[16, 16, 0] = 1.0
    >>> plan = ProjectionPlan(data, src, [1e6])
    >>> far = PlaneGrid.centered(8, 8, 0.3e-3, pose=Pose(origin=(0.0, 0.0, 5e-3)))
    >>> near = PlaneGrid.centered(8, 8, 0.3e-3, pose=Pose(origin=(0.0, 0.0, 2e-3)))
    >>> plan.project(far).shape, plan.project(near).shape   # one FFT of the data
    ((8, 8, 1), (8, 8, 1))
    """

    def __init__(self, field: ArrayLike, source: PlaneGrid, frequencies: ArrayLike,
                 medium: Medium | None = None, *, eps: float = 1e-6,
                 guard_angle: float = np.deg2rad(80.0),
                 padding: float | tuple[int, int] | None = None,
                 allow_undersampled: bool = False, single_precision: bool = False,
                 max_memory: int = 1 << 30, cache: bool = True,
                 max_cache_bytes: int | None = None, exact_padding: bool = False,
                 image_taper: bool = False):
        self.medium = Medium() if medium is None else medium
        self.field, self.frequencies = _validate_field(field, source, frequencies)
        if not 1e-15 < eps < 1e-1:
            raise InputError("expected a tolerance between 1e-15 and 0.1", field="eps")
        if padding is None and not 0 <= guard_angle < np.pi / 2:
            raise InputError("expected an angle in [0, π/2) rad", field="guard_angle")
        _check_sampling(source, self.frequencies, self.medium, allow_undersampled)
        self.source = source
        self.eps = float(eps)
        self.guard_angle = float(guard_angle)
        self.padding = padding
        self.single_precision = bool(single_precision)
        self._spectrum_only = False  # True for from_spectrum: no data to transform again
        self.max_memory = int(max_memory)
        self.cache = bool(cache)
        self.exact_padding = bool(exact_padding)
        self.image_taper = bool(image_taper)
        if max_cache_bytes is not None and not max_cache_bytes >= 0:
            raise InputError("expected a byte count ≥ 0", field="max_cache_bytes")
        self.max_cache_bytes = None if max_cache_bytes is None else int(max_cache_bytes)
        # shared with the plans made by with_pose (the spectra do not depend on the pose)
        self._cache: dict[str, object] = {"shape": None, "blocks": None}

    @classmethod
    def from_spectrum(cls, blocks: list[tuple[NDArray, NDArray, NDArray]],
                      source: PlaneGrid, frequencies: ArrayLike,
                      medium: Medium | None = None, *, eps: float = 1e-6) -> ProjectionPlan:
        """A plan from the padded angular spectrum itself, without the data in space.

        For a model known by its spectrum (the window models of
        :func:`holoprobe.characterize.window_round_trip`): the same plan as one made from
        ``ifft2`` of that spectrum on ``source`` padded to exactly ``source.shape``, but
        neither that inverse FFT nor the plan's forward FFT is done.

        Parameters
        ----------
        blocks : list of (rows, cols, values)
            Per frequency: row and column indices (FFT order of the ``source.shape``
            lattice) and ``values[i, j]``, the unnormalised DFT ``Σ p e^{−iκ·(r − r_0)}``
            of the data at (rows[i], cols[j]); the DFT is zero everywhere else. Every
            propagating wave that is not zero must lie in these rows and columns.
        source : PlaneGrid
            The data plane; its shape is the padded period (no further padding).
        frequencies : array_like, shape (nf,)
            Frequencies in Hz, one per block.
        medium : Medium, optional
            Propagation medium (default water at 20 °C).
        eps : float
            Relative tolerance of the non-uniform FFTs.

        Returns
        -------
        ProjectionPlan
            Its :meth:`project` and :meth:`adjoint` work for any target (the period
            is ``source.shape`` whatever the padding rule asks).
        """
        f = np.atleast_1d(np.asarray(frequencies, dtype=float))
        if len(blocks) != f.size:
            raise InputError(f"expected one block per frequency ({f.size}), got "
                             f"{len(blocks)}", field="blocks")
        shape = (int(source.shape[0]), int(source.shape[1]))
        if (next_fast_length(shape[0]), next_fast_length(shape[1])) != shape:
            raise InputError(f"expected an FFT-friendly period (next_fast_length), got "
                             f"{shape}", field="source")
        zeros = np.broadcast_to(np.zeros((), np.complex128), (*shape, f.size))
        plan = cls(zeros, source, f, medium, eps=eps, padding=shape,
                   allow_undersampled=True)
        plan._spectrum_only = True
        kx = 2 * np.pi * np.fft.fftfreq(shape[0], source.dx)
        ky = 2 * np.pi * np.fft.fftfreq(shape[1], source.dy)
        c0 = plan.medium.sound_speed
        plan._cache.update(shape=shape, blocks=[
            _Block(n, 2 * np.pi * f[n] / c0, rows, cols, kx[rows], ky[cols],
                   np.ascontiguousarray(values, dtype=np.complex128))
            for n, (rows, cols, values) in enumerate(blocks)])
        return plan

    def with_pose(self, pose: Pose) -> ProjectionPlan:
        """The same data on the source plane moved to ``pose``, sharing the cached spectra.

        The angular spectrum of the data in the grid's own coordinates does not depend on
        where the plane is: iterations that refine the scan pose reuse it.
        """
        other = copy.copy(self)
        other.source = self.source.with_pose(pose)
        return other

    def with_medium(self, medium: Medium) -> ProjectionPlan:
        """The same data in another ``medium``, sharing the cached spectra where they
        hold its waves.

        The padded FFT of the data does not depend on the medium, only which of its
        waves propagate (|κ| < k = ω/c): for a sound speed no lower, each frequency's
        cached square |κx|, |κy| < k holds the new, smaller square, and its waves beyond
        k are evanescent there and left out as in a plan made for ``medium`` (the same
        numbers). For a lower sound speed the other plan transforms the data again.
        """
        other = copy.copy(self)
        other.medium = medium
        c, blocks = medium.sound_speed, self._blocks
        if blocks is None or not c >= self.medium.sound_speed:
            if self._spectrum_only:
                raise InputError(
                    f"a plan made from a spectrum cannot move to a slower medium ({c} m/s "
                    f"< {self.medium.sound_speed} m/s): it has no data to transform again; "
                    f"expected a sound speed no lower", field="medium")
            other._cache = {"shape": None, "blocks": None}
        else:  # new wave numbers, the same arrays
            other._cache = {"shape": self.shape, "blocks": [
                _Block(b.n, 2 * np.pi * self.frequencies[b.n] / c, b.rows, b.cols, b.kx, b.ky,
                       b.values) for b in blocks]}
        return other

    @property
    def shape(self) -> tuple[int, int] | None:
        """Padded size of the cached spectra (None before the first projection)."""
        return self._cache["shape"]  # type: ignore[return-value]  # set by _chunks only

    @property
    def _blocks(self) -> list[_Block] | None:
        return self._cache["blocks"]  # type: ignore[return-value]  # set by _chunks only

    # ------------------------------------------------------------------ spectra
    def padded_shape(self, target: PlaneGrid | Surface) -> tuple[int, int]:
        """Padded size this plan uses for ``target`` (≥ the padding rule's size)."""
        _check_target(target)
        need = padded_shape(self.source, target, guard_angle=self.guard_angle,
                            padding=self.padding)
        if (not self.exact_padding and self.shape is not None and self.shape[0] >= need[0]
                and self.shape[1] >= need[1]):
            return self.shape
        return need

    def prepare(self, target: PlaneGrid | Surface, *, progress: bool | None = False
                ) -> tuple[int, int]:
        """Compute and keep the padded spectra for ``target`` now (finufft's ``setpts``).

        Later projections that use the same padded size reuse them, also from several
        threads at once (the cached spectra are only read). Does nothing when they are
        already cached or when the plan does not cache.

        Returns
        -------
        (int, int)
            The padded size, as :meth:`padded_shape`.
        """
        shape = self.padded_shape(target)
        if self.cache and not (self._blocks is not None and shape == self.shape):
            for _ in self._chunks(shape, progress):
                pass
        return shape

    @property
    def nbytes(self) -> int:
        """Bytes held by the cached spectra (0 before the first projection)."""
        return 0 if self._blocks is None else sum(b.values.nbytes for b in self._blocks)

    def _chunks(self, shape: tuple[int, int], progress: bool | None
                ) -> Iterator[list[_Block]]:
        """The spectrum blocks of every frequency, a few frequencies at a time."""
        if self._blocks is not None and shape == self.shape:
            step = 8 * workers()
            blocks = self._blocks
            for start in progress_iter(range(0, len(blocks), step), description="projecting",
                                       enabled=progress):
                yield blocks[start:start + step]
            if len(blocks) < self.frequencies.size:  # the frequencies beyond the budget
                yield from self._transform(shape, progress, first=len(blocks))
            return
        if self.cache:  # drop spectra of another size first: never hold two sets
            self._cache.update(shape=None, blocks=None)
        kept: list[_Block] = []
        room = float("inf") if self.max_cache_bytes is None else self.max_cache_bytes
        for chunk in self._transform(shape, progress):
            for block in chunk if self.cache else ():
                if len(kept) == block.n and block.values.nbytes <= room:  # a prefix
                    kept.append(block)
                    room -= block.values.nbytes
            yield chunk
        if self.cache:
            self._cache.update(shape=shape, blocks=kept)

    def _transform(self, shape: tuple[int, int], progress: bool | None, first: int = 0
                   ) -> Iterator[list[_Block]]:
        # padded spectra a few frequencies at a time: the y-transform of the data rows
        # (zero padded to npy by the FFT), then, per frequency, the x-transform (zero
        # padded to npx) of only the columns |κy| < k — the others hold no propagating
        # wave — of which the rows |κx| < k are kept. Each 1-D transform sees the same
        # input as a transform of the whole zero-padded grid would. A single-precision
        # plan transforms in complex64, the type its blocks are kept in (3.5e-7 of the
        # block's peak from a complex128 FFT on a full-size scan, under the NUFFTs' floor;
        # half the CPU: 58 bins 0.37 -> 0.12-0.23 s).
        if self._spectrum_only:  # its field is a placeholder of zeros
            raise InputError(
                f"this plan was made from a spectrum (ProjectionPlan.from_spectrum) and has "
                f"no data to transform for a padded size {shape}; expected a target its "
                f"period {self.padding} serves", field="target")
        npx, npy = shape
        src, field, freqs = self.source, self.field, self.frequencies
        kx = 2 * np.pi * np.fft.fftfreq(npx, src.dx)
        ky = 2 * np.pi * np.fft.fftfreq(npy, src.dy)
        n_threads = workers()
        cdtype = np.complex64 if self.single_precision else np.complex128
        chunk = int(max(1, min(4 * n_threads, self.max_memory // (16 * npx * npy), freqs.size)))
        for start in progress_iter(range(first, freqs.size, chunk), description="projecting",
                                   enabled=progress):
            stop = min(start + chunk, freqs.size)
            data = np.moveaxis(field[:, :, start:stop], 2, 0).astype(cdtype, copy=False)
            rows_y = scipy.fft.fft(data, n=npy, axis=2, workers=n_threads)  # (c, nx, npy)
            del data
            out = []
            for j, n in enumerate(range(start, stop)):
                k = 2 * np.pi * freqs[n] / self.medium.sound_speed
                # the kernel keeps κx² + κy² < k²: every such wave lies in this square
                rows = np.flatnonzero(kx * kx < k * k)
                cols = np.flatnonzero(ky * ky < k * k)
                full_x = scipy.fft.fft(rows_y[j][:, cols], n=npx, axis=0, workers=n_threads)
                values = np.ascontiguousarray(full_x[rows], dtype=cdtype)
                out.append(_Block(n, k, rows, cols, kx[rows], ky[cols], values))
            yield out

    # ------------------------------------------------------------------ operators
    def _transforms(self, target: PlaneGrid | Surface, shape: tuple[int, int],
                    quantity: Quantity, time_origin: float) -> list:
        _check_target(target)
        if quantity not in ("pressure", "normal_velocity"):
            raise InputError("expected 'pressure' or 'normal_velocity'", field="quantity")
        _direction(_target_bounds(self.source, target))
        npx, npy = shape
        dx, dy = self.source.dx, self.source.dy
        scale = dx * dy * (2 * np.pi / (npx * dx)) * (2 * np.pi / (npy * dy)) / (4 * np.pi**2)
        cdtype = np.complex64 if self.single_precision else np.complex128
        kind = _PlaneTransform if isinstance(target, PlaneGrid) else _PointTransform
        # (type: ignore below) the transform class matches the target type (isinstance above)
        return [kind(self.source, target, self.eps, cdtype,  # type: ignore[arg-type]
                     velocity=quantity == "normal_velocity", time_origin=time_origin,
                     impedance=self.medium.impedance, scale=scale)
                for _ in range(workers())]

    def taper_range(self, target: PlaneGrid | Surface, shape: tuple[int, int]
                    ) -> tuple[float, float] | None:
        """(s_in, s_out) of the image taper for ``target`` at the padded ``shape``
        (:func:`image_taper_range`); None without ``image_taper`` or without room."""
        return image_taper_range(self.source, target, shape) if self.image_taper else None

    def _values_shape(self, target: PlaneGrid | Surface) -> tuple[int, ...]:
        nf = self.frequencies.size
        if isinstance(target, PlaneGrid):
            return (*target.shape, nf)
        return (target.size, nf)

    def project(self, target: PlaneGrid | Surface, *, quantity: Quantity = "pressure",
                time_origin: float = 0.0, progress: bool | None = False,
                dtype: type = np.complex128) -> NDArray[Any]:
        """Field of the plan's data on ``target`` (the forward operator A).

        Parameters
        ----------
        target : PlaneGrid or Surface
            Where the field is wanted, entirely on one side of the source plane.
        quantity : {"pressure", "normal_velocity"}
            Pressure (Pa·s), or the normal velocity (m/s·s) along the target plane's
            normal or the surface's ``normals``.
        time_origin : float
            Distance r0 in m: results are multiplied by ``exp(−i k r0)``.
        progress : bool or None
            ``True`` shows a progress bar, ``None`` only on a terminal.
        dtype : {numpy.complex128, numpy.complex64}
            Type of the result. ``complex64`` holds the same numbers as ``complex128``
            when the plan runs in ``single_precision`` (its transforms are complex64),
            in half the memory and without a conversion per frequency.

        Returns
        -------
        ndarray, complex (``dtype``)
            (nx_t, ny_t, nf) on a PlaneGrid target, (n, nf) on a Surface.
        """
        if np.dtype(dtype) not in (np.dtype(np.complex64), np.dtype(np.complex128)):
            raise InputError(f"expected complex64 or complex128, got {np.dtype(dtype)}",
                             field="dtype")
        shape = self.padded_shape(target)
        transforms = self._transforms(target, shape, quantity, time_origin)
        out: NDArray[Any] = np.zeros(self._values_shape(target), dtype=dtype)
        taper = _fused_taper(transforms, self.taper_range(target, shape))

        def work(transform, block: _Block) -> None:
            result = transform(_tapered_block(block, taper))
            if result is not None:
                out[..., block.n] = result

        self._run(transforms, work, shape, progress)
        return out

    def project_reduced(self, target: PlaneGrid, kernel: ArrayLike, row_weights: ArrayLike,
                        *, quantity: Quantity = "pressure", time_origin: float = 0.0,
                        progress: bool | None = False) -> NDArray[np.complex128]:
        """Weighted sums of the field on a target plane grid, without the grid.

        ``out[g, f] = Σ_k kernel[k] Σ_j row_weights[f, j] P_f(x_{g·m+k}, y_j)`` for the
        ``G = nx/m`` groups of ``m = kernel.size`` consecutive columns of ``target``
        (e.g. the element averages of an array's sensor, with a lens phase per row):
        the same numbers as summing :meth:`project`'s grid (to the NUFFT tolerance),
        but each plane wave is reduced by two 1-D non-uniform FFTs (the rows, then one
        mode per group) instead of being spread onto the 2-D grid, and the grid
        (nx × ny × nf values) is never held.

        Parameters
        ----------
        target : PlaneGrid
            The grid whose field is summed (nx a multiple of ``kernel.size``).
        kernel : array_like, shape (m,)
            Weights of the columns of one group (e.g. 0 for the points in a kerf).
        row_weights : array_like, complex, shape (nf, ny)
            Weights of the rows, per frequency of the plan.
        quantity, time_origin, progress
            As in :meth:`project`.

        Returns
        -------
        ndarray, complex128, shape (G, nf)
        """
        if not isinstance(target, PlaneGrid):
            raise InputError("expected a PlaneGrid target", field="target")
        a = np.asarray(kernel).reshape(-1)
        nx, ny = target.shape
        if a.size == 0 or nx % a.size:
            raise InputError(f"expected a kernel whose size divides the target's {nx} "
                             f"columns, got {a.size}", field="kernel")
        b = np.asarray(row_weights)
        nf = self.frequencies.size
        if b.shape != (nf, ny):
            raise InputError(f"expected row weights of shape {(nf, ny)}, got {b.shape}",
                             field="row_weights")
        shape = self.padded_shape(target)
        base = self._transforms(target, shape, quantity, time_origin)[0]
        transforms = [_ReducedTransform(self.source, target, self.eps, base.dtype,
                                        velocity=base.velocity, time_origin=time_origin,
                                        impedance=self.medium.impedance, scale=base.scale,
                                        kernel=a, row_weights=b)
                      for _ in range(workers())]
        out = np.zeros((nx // a.size, nf), dtype=np.complex128)
        taper = _fused_taper(transforms, self.taper_range(target, shape))

        def work(transform, block: _Block) -> None:
            result = transform(_tapered_block(block, taper))
            if result is not None:
                out[:, block.n] = result

        self._run(transforms, work, shape, progress)
        return out

    def adjoint(self, values: ArrayLike, target: PlaneGrid | Surface, *,
                quantity: Quantity = "pressure", time_origin: float = 0.0,
                progress: bool | None = False) -> NDArray[np.complex128]:
        """Adjoint A^H of :meth:`project` for ``target``: target values → source plane.

        ``vdot(plan.project(target) , y) == vdot(x, plan.adjoint(y, target))`` for the
        plan's data x, to the NUFFT tolerance. Between parallel planes with the same
        padded grid, the backward projection of y onto the source plane equals
        A^H y; in general it does not (the adjoint sums over the target points, the
        backward projection integrates over a plane).

        Parameters
        ----------
        values : array_like, complex, shape (nx_t, ny_t, nf) or (n, nf)
            Values on the target (its C order for a PlaneGrid).
        target, quantity, time_origin, progress
            As in :meth:`project`.

        Returns
        -------
        ndarray, complex128, shape (nx, ny, nf)
            On the source grid.
        """
        shape = self.padded_shape(target)
        transforms = self._transforms(target, shape, quantity, time_origin)
        nf = self.frequencies.size
        expected = self._values_shape(target)
        y = np.asarray(values)
        if y.shape != expected:
            raise InputError(f"expected shape {expected}, got {y.shape}", field="values")
        npx, npy = shape
        nx, ny = self.source.shape
        out = np.zeros((nx, ny, nf), dtype=np.complex128)
        taper = self.taper_range(target, shape)

        def work(transform, block: _Block) -> None:
            full = np.zeros((npx, npy), dtype=np.complex128)
            if taper is None:
                full[np.ix_(block.rows, block.cols)] = transform.adjoint(y[..., block.n],
                                                                         block)
            else:  # the taper's weights are real: A^H = W · (adjoint of the cut block)
                r, c, weight = _taper_weights(block, taper)
                full[np.ix_(block.rows[r], block.cols[c])] = weight * transform.adjoint(
                    y[..., block.n], _tapered_block(block, taper))
            # adjoint of "zero-pad, then forward FFT": inverse FFT × size, then crop
            out[:, :, block.n] = scipy.fft.ifft2(full, workers=1)[:nx, :ny] * (npx * npy)

        self._run(transforms, work, shape, progress)
        return out

    def _run(self, transforms: list, work, shape: tuple[int, int],
             progress: bool | None) -> None:
        n_threads = len(transforms)
        with Threads(n_threads) as threads:
            for chunk in self._chunks(shape, progress):
                def worker(index: int, chunk=chunk) -> None:
                    for block in chunk[index::n_threads]:
                        work(transforms[index], block)

                threads.map(worker, range(n_threads))
