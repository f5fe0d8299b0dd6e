"""Convex (curvilinear) arrays: back-projection onto the cylindrical face and its fit.

Source frame of a convex array (:meth:`holoprobe.geometry.ArrayGeometry.convex`): the
apex (middle of the active arc) at the origin, the centre of curvature C at (0, 0, −R),
the cylinder axis along y. The face is sampled on its *unrolled* grid (s, y): arc length
s from the apex (positive towards +x) and elevation y, so that every estimation step of
a flat array (aperture, element map, lens, mean velocity) runs unchanged on the map
``v(s, y, f)``. The cylinder is developable: the grid cells have the exact area ds·dy.

Centre of curvature from the phase. Each element radiates along its own normal, the
radius through C; on a trial cylinder whose centre misses the true one by
δ = (δx, 0, δz) the distance to the true centre is ``R − δx sin φ − δz cos φ`` to first
order (φ = s/R), so the reconstructed phase (delays are positive phases in holoprobe's
Fourier convention) is

    ψ(φ) = ψ0 + k δz (1 − cos φ) − k δx sin φ,

and a weighted least-squares fit of the phase on (1, 1 − cos φ, sin φ) gives δ. δx
tilts the array about its apex (the orientation angle θy of the apex plane), δz changes
R at a fixed apex. Where the apex lies along the radius comes, as for a flat array, from
the onset of the mean surface velocity (R −= c0·t0), and where it lies along the arc from
the centre of the aperture (a rotation about C).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import FitError, InputError
from holoprobe.geometry import ArrayGeometry, PlaneGrid, Pose, Surface, rotation_matrix

__all__ = [
    "ArcCenterFit",
    "ConvexTransmitResult",
    "ElementLattice",
    "arc_element_views",
    "arc_footprint",
    "cylinder_surface",
    "element_lattice",
    "element_line_tilt",
    "fit_arc_center",
    "move_source_frame",
    "pose_from_matrix",
    "project_on_cylinder",
    "unrolled_grid",
]


def pose_from_matrix(rotation: NDArray, origin: NDArray) -> Pose:
    """The :class:`Pose` of a rotation matrix ``Rz(θz) Ry(θy) Rx(θx)`` and an origin
    (:meth:`Pose.from_matrix`)."""
    return Pose.from_matrix(rotation, origin)


def move_source_frame(pose: Pose, *, angle: float = 0.0, pivot: NDArray | None = None,
                      apex: NDArray | None = None, rotation: NDArray | None = None) -> Pose:
    """The scan pose in a new source frame: the array turned and/or moved.

    The new frame's axes are the old ones turned by ``angle`` (rad) about the y axis;
    its origin (the new apex) is ``apex`` (old coordinates) or, when ``pivot`` is
    given, the old apex turned about ``pivot`` (e.g. the centre of curvature: a shift
    along the arc).

    Parameters
    ----------
    pose : Pose
        Scan plane in the old source frame.
    angle : float
        Rotation about +y in rad (positive turns +z towards +x).
    pivot, apex : array_like, shape (3,), optional
        See above; neither: the apex stays.
    rotation : array_like, shape (3, 3), optional
        Any turn of the axes (columns: the new axes in old coordinates) instead of
        ``angle`` about y.
    """
    q = (rotation_matrix(0.0, angle, 0.0) if rotation is None
         else np.asarray(rotation, dtype=float))
    if pivot is not None:
        c = np.asarray(pivot, dtype=float)
        a = c + q @ (-c)
    elif apex is not None:
        a = np.asarray(apex, dtype=float)
    else:
        a = np.zeros(3)
    return pose_from_matrix(q.T @ pose.rotation, q.T @ (pose.origin_array - a))


def _corners_on_arc(scan_grid: PlaneGrid, pose: Pose, radius: float
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Arc positions s (m) under which the scan's corners are seen from the centre of
    curvature, and the corners themselves (source frame), shapes (4,), (4, 3)."""
    corners = np.array([[u, v, 0.0] for u in (scan_grid.x[0], scan_grid.x[-1])
                        for v in (scan_grid.y[0], scan_grid.y[-1])])
    pts = pose.to_global(corners)
    phi = np.arctan2(pts[:, 0], pts[:, 2] + radius)
    return np.clip(phi, -0.5 * np.pi, 0.5 * np.pi) * radius, pts


def arc_footprint(scan_grid: PlaneGrid, pose: Pose, radius: float) -> tuple[float, float]:
    """Arc-length range (m) of the cylinder seen by the scan (from the centre of
    curvature): the ``footprint`` of :func:`fit_element_map` on the unrolled grid."""
    s, _ = _corners_on_arc(scan_grid, pose, radius)
    return float(s.min()), float(s.max())


def arc_element_views(scan_grid: PlaneGrid, pose: Pose, radius: float,
                      max_range: float | None = None
                      ) -> Callable[[NDArray], tuple[NDArray, NDArray, NDArray]]:
    """How each element of the arc sees the scan: the ``local`` view of
    :class:`~holoprobe.characterize.LineGeometry` for :func:`fit_element_map` on the
    unrolled grid.

    An element at arc position s (angle φ = s/R) faces along its radius, so it sees the
    scan's edges A, B (the scan's x ends at its middle y) under the angles
    α = atan2((P − X)·t, (P − X)·n) from its normal n (t the arc's tangent, X the
    element): far out on a C5-2's arc the outer edge lies 13° off the normal, where the
    flat model (one footprint at the scan's height, seen from the centre of curvature)
    put it 24° off — the end elements' outward waves it wrongly counted as measured.
    Its view is a scan parallel to it at its normal distance D to the scan plane, cut
    to ``[s + D tan α_A, s + D tan α_B]``; an edge at or behind the element's plane
    leaves that side open.

    ``max_range`` (m): the record holds an element's whole pulse only at scan points
    closer than this (c0 × (record end − onset − pulse length)); beyond it the scan's
    ends are moved in to where that distance is reached. On the 128-element C5-2 twin
    (20.5 µs records, 30 mm) the far ends of a 110 mm scan lie 32 mm from the end
    elements, of a 160 mm scan 54 mm: without this cut the end elements came out 8 %
    and 18 % off (the basis counted field the record had cut off), with it 2.5 % on
    the 160 mm scan.

    Returns
    -------
    callable
        ``centers (N,) m -> (lo, hi, distance)``, each (N,) in m.
    """
    ym = 0.5 * (float(scan_grid.y[0]) + float(scan_grid.y[-1]))
    ends = pose.to_global(np.array([[float(scan_grid.x[0]), ym, 0.0],
                                    [float(scan_grid.x[-1]), ym, 0.0]]))
    normal = pose.to_global(np.array([[0.0, 0.0, 1.0]]))[0] - pose.to_global(
        np.zeros((1, 3)))[0]
    origin = np.asarray(pose.origin, dtype=float)
    limit = np.tan(np.radians(89.0))

    def views(centers: NDArray) -> tuple[NDArray, NDArray, NDArray]:
        phi = np.asarray(centers, dtype=float) / radius
        sn, cs = np.sin(phi), np.cos(phi)
        pos = np.stack([radius * sn, np.zeros_like(phi), radius * (cs - 1.0)], axis=-1)
        n = np.stack([sn, np.zeros_like(phi), cs], axis=-1)
        distance = ((origin - pos) @ normal) / np.maximum(n @ normal, 1e-3)
        edges = []
        for end in _ends_in_range(ends, pos, max_range):
            rel = end - pos
            along, ahead = rel[:, 0] * cs - rel[:, 2] * sn, np.sum(rel * n, axis=1)
            slope = np.where(ahead > 0, along / np.maximum(ahead, 1e-300), np.sign(along)
                             * limit)
            edges.append(centers + distance * np.clip(slope, -limit, limit))
        lo, hi = np.minimum(*edges), np.maximum(*edges)
        return lo, hi, distance
    return views


def _ends_in_range(ends: NDArray, pos: NDArray, max_range: float | None
                   ) -> tuple[NDArray, NDArray]:
    """The scan line's ends (2, 3) per element (N, 3): moved in along the line to where
    it is ``max_range`` from the element (kept where the line never comes that close,
    or without ``max_range``)."""
    a, b = (np.broadcast_to(e, pos.shape).copy() for e in ends)
    if max_range is None:
        return a, b
    length = float(np.linalg.norm(ends[1] - ends[0]))
    e = (ends[1] - ends[0]) / length
    u0 = (pos - ends[0]) @ e  # foot of the perpendicular from the element
    half2 = max_range**2 - np.sum((pos - ends[0]) ** 2, axis=1) + u0**2
    ok = half2 > 0
    h = np.sqrt(np.where(ok, half2, 0.0))
    lo = np.clip(u0 - h, 0.0, length)
    hi = np.clip(u0 + h, 0.0, length)
    ok &= hi > lo
    a[ok] = ends[0] + lo[ok, None] * e
    b[ok] = ends[0] + hi[ok, None] * e
    return a, b


def unrolled_grid(scan_grid: PlaneGrid, pose: Pose, radius: float, margin: float,
                  *, step: float | None = None) -> PlaneGrid:
    """Unrolled (s, y) grid of the cylinder covering the scan footprint plus a margin.

    The footprint along the arc is the angle under which the scan plane's corners are
    seen from the centre of curvature; steps are the scan's (``step``: both).
    """
    s, pts = _corners_on_arc(scan_grid, pose, radius)
    ds = scan_grid.dx if step is None else step
    dy = scan_grid.dy if step is None else step
    is0 = int(np.floor((s.min() - margin) / ds + 1e-9))
    is1 = int(np.ceil((s.max() + margin) / ds - 1e-9))
    iy0 = int(np.floor((pts[:, 1].min() - margin) / dy + 1e-9))
    iy1 = int(np.ceil((pts[:, 1].max() + margin) / dy - 1e-9))
    return PlaneGrid(np.arange(is0, is1 + 1, dtype=float) * ds,
                     np.arange(iy0, iy1 + 1, dtype=float) * dy, Pose())


def cylinder_surface(grid: PlaneGrid, radius: float) -> Surface:
    """Points of the unrolled grid (s, y) on the cylinder of ``radius`` (m).

    ``(s, y) → (R sin(s/R), y, R cos(s/R) − R)``, radial normals, weights ds·dy; the
    points are in the grid's C order (s slowest), so values reshape to ``grid.shape``.
    """
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"expected a positive radius of curvature in m, got {radius!r}",
                         field="radius_of_curvature")
    ss, yy = np.meshgrid(grid.x, grid.y, indexing="ij")
    ang = ss.ravel() / radius
    sn, cs = np.sin(ang), np.cos(ang)
    pts = np.stack([radius * sn, yy.ravel(), radius * (cs - 1.0)], axis=-1)
    normals = np.stack([sn, np.zeros_like(sn), cs], axis=-1)
    return Surface(pts, normals, np.full(pts.shape[0], grid.cell_area))


def project_on_cylinder(plan: Any, pose: Pose, grid: PlaneGrid, radius: float, *,
                        method: str = "cylindrical", patch_angle: float = 0.0,
                        progress: bool | None = False) -> NDArray[np.complex128]:
    """Normal velocity of a scan's plan on the cylinder (unrolled grid).

    ``method="cylindrical"`` (default): by the cylinder's symmetry
    (:func:`holoprobe.propagation.project_cylinder`: per column of a wave lattice along
    the axis, a circular convolution along the arc by 1-D NUFFTs), ~5× cheaper per bin
    than the 3-D transform on a C5-2's face. ``method="type3"``: the 3-D type-3 NUFFT
    of ``ProjectionPlan.project``, patch by patch:

    The cylinder's columns (arc positions s) are split into patches at most
    ``patch_angle`` (rad) wide; each patch is projected in a frame turned about y so
    that its middle normal is +z (scan pose and points turned together: the projected
    field does not change), which keeps the bounding box of its points — and with it
    the fine grid of the type-3 NUFFT — thin. Every patch uses the padded size the whole
    surface needs, so the plan's cached spectra are computed once.

    Parameters
    ----------
    plan : ProjectionPlan
        The scan's plan (any pose).
    pose : Pose
        Scan plane in the source frame (apex at the origin, centre at (0, 0, −R)).
    grid : PlaneGrid
        Unrolled grid (s, y) of the cylinder, m.
    radius : float
        R in m.
    method : {"cylindrical", "type3"}
        See above (``convex.projection``).
    patch_angle : float
        ``type3`` only: largest patch in rad; 0: the count that a cost model of the NUFFTs says is
        cheapest (:func:`_patch_count`: one for a short arc, 4 for a C5-2).
    progress : bool or None
        Progress bars of the projections.

    Returns
    -------
    ndarray, complex, shape (ns, ny, nf)
        Normal (radial) velocity in m/s·s.
    """
    if method == "cylindrical":
        from holoprobe.propagation import project_cylinder

        return project_cylinder(plan.with_pose(pose), radius, grid.x, grid.y,
                                quantity="normal_velocity", progress=progress)
    if method != "type3":
        raise InputError(f"expected 'cylindrical' or 'type3', got {method!r}",
                         field="convex.projection")
    surf = cylinder_surface(grid, radius)
    plan_pose = plan.with_pose(pose)
    shape = plan_pose.padded_shape(surf)
    ns, ny = grid.shape
    span = float(grid.x[-1] - grid.x[0]) / radius
    count = (max(1, int(np.ceil(span / patch_angle - 1e-9))) if patch_angle > 0
             else _patch_count(plan, shape, grid, radius))
    count = min(count, ns)
    if count == 1:
        v = plan_pose.project(surf, quantity="normal_velocity", progress=progress)
        return v.reshape(ns, ny, -1)
    out = np.empty((ns, ny, plan.frequencies.size), dtype=np.complex128)
    for cols in np.array_split(np.arange(ns), count):
        phi = 0.5 * (grid.x[cols[0]] + grid.x[cols[-1]]) / radius
        q = rotation_matrix(0.0, -phi, 0.0)  # the patch's middle normal → +z
        sub = plan.with_pose(pose_from_matrix(q @ pose.rotation, q @ pose.origin_array))
        sub.padding = shape  # the whole surface's padded size: spectra computed once
        rows = slice(cols[0] * ny, (cols[-1] + 1) * ny)
        patch = Surface(surf.points[rows] @ q.T, surf.normals[rows] @ q.T,
                        surf.weights[rows])
        out[cols] = sub.project(patch, quantity="normal_velocity",
                                progress=progress).reshape(cols.size, ny, -1)
    return out


def _patch_count(plan: Any, shape: tuple[int, int], grid: PlaneGrid, radius: float) -> int:
    """Number of patches that makes the type-3 NUFFTs onto the cylinder cheapest.

    Cost model per frequency (finufft type 3 in 3-D, kernel width w = ⌈log10(1/ε)⌉ + 1,
    upsampling 2): the FFT of the fine grid, whose size along each axis is
    ``max(4 X K / π, 2w)`` for the patch's extent X and the largest wavenumber K, and the
    spreading of the M plane waves of the scan's spectrum once per patch (w³ each).
    Relative weights measured on this machine's finufft (a C5-2-sized arc, 114 k waves:
    one patch 16 s, four 4 s, sixteen 7 s): 1.3e-9 s per fine-grid point per log2 of
    the grid size, 1e-8 s per wave and kernel point.
    """
    k = 2 * np.pi * float(np.max(plan.frequencies)) / plan.medium.sound_speed
    src = plan.source
    waves = np.pi * k * k / ((2 * np.pi / (shape[0] * src.dx)) * (2 * np.pi / (shape[1] * src.dy)))
    w = int(np.ceil(np.log10(1.0 / plan.eps))) + 1
    arc = float(grid.x[-1] - grid.x[0]) + grid.dx
    height = float(grid.y[-1] - grid.y[0]) + grid.dy

    def cost(p: int) -> float:
        chord = arc / p
        sides = np.array([chord, height, chord * chord / (8 * radius)])
        n = float(np.prod(np.maximum(4 * sides * k / np.pi, 2 * w)))
        return p * (1.3e-9 * n * np.log2(n) + 1e-8 * waves * w**3)

    counts = range(1, max(1, grid.x.size // 4) + 1)
    return min(counts, key=cost)


@dataclass(frozen=True)
class ArcCenterFit:
    """Offset of the true centre of curvature from the trial one (source frame, m).

    Attributes
    ----------
    dx, dz : float
        δx (across the axis, in the arc's plane) and δz (along the axis).
    dx_uncertainty, dz_uncertainty : float
        Standard uncertainties (m), from the scatter of the per-frequency fits.
    residual : float
        Rms phase residual (rad) of the fit.
    """

    dx: float
    dz: float
    dx_uncertainty: float
    dz_uncertainty: float
    residual: float


def fit_arc_center(velocity: NDArray, grid: PlaneGrid, frequencies: NDArray,
                   radius: float, sound_speed: float, *, support: NDArray | None = None,
                   correlation_length: float | None = None,
                   threshold_db: float = -20.0) -> ArcCenterFit:
    """Fit δ of the centre of curvature from the phase of the velocity along the arc.

    The phase of every bin (elevation sum, unwrapped along s from the strongest column)
    becomes a path ψ/k; the paths are averaged over the bins (power weights) and fitted
    on (1, 1 − cos φ, sin φ) by weighted least squares (see the module notes).

    Parameters
    ----------
    velocity : ndarray, complex, shape (ns, ny, nf)
        Normal velocity on the unrolled trial cylinder.
    grid : PlaneGrid
        The unrolled grid (s along x).
    frequencies : ndarray, shape (nf,)
        Hz.
    radius : float
        Trial radius R in m.
    sound_speed : float
        m/s.
    support : ndarray of bool, shape (ns,), optional
        Arc positions on the face (default: where the column power is within
        ``threshold_db`` of its maximum).
    correlation_length : float, optional
        Arc length (m) over which path errors are correlated (the pitch: element delays
        differ from element to element, not from sample to sample); sets the number of
        independent values behind the uncertainty. Default: the grid step.
    threshold_db : float
        Bins and columns weaker than this (dB below the strongest) are left out.

    Returns
    -------
    ArcCenterFit
        Uncertainties from the weighted residual scatter with one independent value per
        ``correlation_length``.
    """
    v = np.asarray(velocity)
    col = np.sum(v, axis=1)  # (ns, nf): elevation sum (the lens phase is common to all s)
    power = np.sum(np.abs(col) ** 2, axis=1)
    if support is None:
        support = power >= power.max() * 10 ** (threshold_db / 10)
    support = np.asarray(support, bool)
    bin_power = np.sum(np.abs(col[support]) ** 2, axis=0)
    use = np.flatnonzero(bin_power >= bin_power.max() * 10 ** (threshold_db / 10))
    if support.sum() < 4 or use.size == 0:
        raise FitError("too few arc positions or frequency bins with signal to fit the "
                       "centre of curvature", field="velocity")
    c = col[support][:, use]
    w = np.abs(c) ** 2
    ref = int(np.argmax(np.sum(w, axis=1)))
    psi = np.unwrap(np.angle(c * np.conj(c[ref])[None, :]), axis=0)
    k = 2 * np.pi * frequencies[use] / sound_speed
    path = np.sum(w * psi / k, axis=1) / np.sum(w, axis=1)
    wt = np.sum(w, axis=1) / np.sum(w)
    phi = grid.x[support] / radius
    basis = np.stack([np.ones_like(phi), 1.0 - np.cos(phi), np.sin(phi)], axis=-1)
    sw = np.sqrt(wt)
    coef, *_ = np.linalg.lstsq(basis * sw[:, None], path * sw, rcond=None)
    r = path - basis @ coef
    step = abs(grid.dx)
    n_eff = max(support.sum() * step / max(correlation_length or step, step), 4.0)
    s2 = float(np.sum(wt * r**2)) * n_eff / (n_eff - 3)
    cov = np.linalg.inv((basis * wt[:, None]).T @ basis) * s2 / n_eff
    return ArcCenterFit(dx=float(-coef[2]), dz=float(coef[1]),
                        dx_uncertainty=float(np.sqrt(cov[2, 2])),
                        dz_uncertainty=float(np.sqrt(cov[1, 1])),
                        residual=float(np.sqrt(np.sum(wt * r**2))))


def _weighted_slope(x: NDArray, y: NDArray, w: NDArray, n_eff: float
                    ) -> tuple[float, float]:
    """Slope of a weighted straight-line fit and its standard error (``n_eff``
    independent values behind the residual scatter)."""
    wt = w / np.sum(w)
    xm, ym = np.sum(wt * x), np.sum(wt * y)
    sxx = np.sum(wt * (x - xm) ** 2)
    if not sxx > 0:
        raise FitError("no spread to fit a slope on", field="velocity")
    slope = float(np.sum(wt * (x - xm) * (y - ym)) / sxx)
    res = y - ym - slope * (x - xm)
    n = max(n_eff, 3.0)
    s2 = float(np.sum(wt * res**2)) * n / (n - 2)
    return slope, float(np.sqrt(s2 / (n * sxx)))


def element_line_tilt(velocity: NDArray, grid: PlaneGrid, pitch: float, *,
                      support: NDArray | None = None, rows: NDArray | None = None
                      ) -> tuple[float, float]:
    """Tilt α of the element lines on the unrolled face: ``s_e(y) = s_e + α y``.

    The element pattern repeats at the pitch along s; its fundamental harmonic in each
    row, ``c(y) = Σ_s |v(s, y)| e^{−2πi s/p}`` (|v| summed over the bins), turns by
    ``−2π α y / p`` along y, so α = −p/(2π) · d arg c / dy (weighted straight line, |c|²
    weights, the phase unwrapped along y). A θz error of the scan pose about the apex
    normal tilts the lines by α ≈ −δθz (turn the source frame by Rz(−α)).

    Parameters
    ----------
    velocity : ndarray, complex, shape (ns, ny, nf)
    grid : PlaneGrid
        Unrolled grid (s, y), m.
    pitch : float
        Element pitch along the arc, m.
    support, rows : ndarray of bool, optional
        Arc positions (ns,) and rows (ny,) to use (default all).

    Returns
    -------
    (float, float)
        α and its standard error (one independent value per row).
    """
    mag = np.sum(np.abs(np.asarray(velocity)), axis=2)  # (ns, ny)
    cols = np.ones(mag.shape[0], bool) if support is None else np.asarray(support, bool)
    keep = np.ones(mag.shape[1], bool) if rows is None else np.asarray(rows, bool)
    # a Hann taper over the support: its fixed edges would otherwise add a pattern at
    # the pitch that does not move with the lines and pull the slope towards zero
    taper = np.hanning(int(cols.sum()) + 2)[1:-1]
    ph = taper * np.exp(-2j * np.pi * grid.x[cols] / pitch)
    c = ph @ mag[cols][:, keep]
    if c.size < 3:
        raise FitError("too few rows to fit the element-line tilt", field="velocity")
    psi = np.unwrap(np.angle(c))
    slope, u = _weighted_slope(grid.y[keep], psi, np.abs(c) ** 2, float(c.size))
    scale = -pitch / (2 * np.pi)
    return slope * scale, abs(u * scale)


@dataclass(frozen=True)
class ElementLattice:
    """Where the element pattern of a face repeats (:func:`element_lattice`).

    Attributes
    ----------
    pitch, pitch_uncertainty : float
        The pattern's period along s and its standard error, m.
    center : float
        The array centre (m) on the lattice nearest to the reference: an element centre
        (odd count) or the midpoint between two (even count).
    bins : int
        Frequency bins whose waves carry the pattern's period (k·p > 2π).
    """

    pitch: float
    pitch_uncertainty: float
    center: float
    bins: int


def element_lattice(velocity: NDArray, grid: PlaneGrid, frequencies: NDArray, *,
                    pitch: float, count: int, sound_speed: float,
                    support: NDArray | None = None, rows: NDArray | None = None,
                    reference: float = 0.0) -> ElementLattice:
    """The element pitch and the array centre from the period and phase of the element
    pattern on the unrolled face: no model of the elements' fields.

    A face of strips at pitch p, each w wide, has |v| ≈ ā (1 + 2 a₁ cos(2π(s − s_e)/p) +
    …) with a₁ = sinc(w/p) > 0: its fundamental peaks on the element centres s_e. That
    fundamental survives the back-projection in the bins with k·p > 2π (a propagating
    wave); ``|v|`` summed over those bins and the ``rows`` is demodulated at the
    nominal pitch p₀, ``z(s) = |v|(s) e^{−2πi s/p₀}``, low-passed by a Gaussian of
    1.5 p₀ (which removes the mean's rotating term to 1e-19), and its phase
    ``ψ(s) = 2π s (1/p − 1/p₀) − 2π s₀/p`` is fitted by a weighted straight line over
    the ``support`` (|z|² weights): the slope gives p, the intercept the lattice
    offset s₀. Cost ~0.01 s. Only on the face itself (on the true cylinder of the
    32-element C5-2 twin 508.20 µm for 508.00, the element map 508.13): off it the
    fundamental of every bin is defocused differently (on a cylinder 0.3 mm inside,
    495.0 µm for 504.9 and the centre half a pitch off), so the convex pipeline takes
    it as the start of the element map's pitch fit, whose residual has local minima
    one end-element hop (~1/(N/2) of the pitch) apart.

    Parameters
    ----------
    velocity : ndarray, complex, shape (ns, ny, nf)
    grid : PlaneGrid
        Unrolled grid (s, y), m.
    frequencies : ndarray, shape (nf,)
        Hz.
    pitch : float
        Nominal pitch p₀ along the arc, m.
    count : int
        Elements (their parity places the centre on an element or between two).
    sound_speed : float
        m/s.
    support, rows : ndarray of bool, optional
        Arc positions (ns,) and rows (ny,) to use (default all); keep the support
        ~2 pitches inside the array's ends.
    reference : float
        Arc position (m) near the array centre: of the lattice's candidate centres the
        nearest is returned (within ±p/2 of it).

    Returns
    -------
    ElementLattice

    Raises
    ------
    FitError
        No bin with k·p > 2π, or fewer than 4 pitches of support.
    """
    from scipy.ndimage import gaussian_filter1d

    k = 2 * np.pi * np.asarray(frequencies, dtype=float) / sound_speed
    use = k * pitch > 2 * np.pi
    if not use.any():
        raise FitError("no frequency bin carries the element pattern's period "
                       f"(k·p > 2π needs f > {sound_speed / pitch / 1e6:.3g} MHz)",
                       field="frequencies")
    mag = np.sum(np.abs(np.asarray(velocity)[:, :, use]), axis=2)  # (ns, ny)
    if rows is not None:
        mag = mag[:, np.asarray(rows, bool)]
    s = np.asarray(grid.x, dtype=float)
    sup = np.ones(s.size, bool) if support is None else np.asarray(support, bool)
    if sup.sum() * abs(grid.dx) < 4 * pitch:
        raise FitError("fewer than 4 pitches of the face to fit the element lattice on",
                       field="velocity")
    z = mag.sum(axis=1) * np.exp(-2j * np.pi * s / pitch)
    width = 1.5 * pitch / abs(grid.dx)
    env = gaussian_filter1d(z.real, width) + 1j * gaussian_filter1d(z.imag, width)
    psi = np.unwrap(np.angle(env[sup]))
    slope, u_slope = _weighted_slope(s[sup], psi, np.abs(env[sup]) ** 2,
                                     float(sup.sum() * abs(grid.dx) / pitch))
    wt = np.abs(env[sup]) ** 2
    intercept = float(np.sum(wt * (psi - slope * s[sup])) / np.sum(wt))
    p = 1.0 / (1.0 / pitch + slope / (2 * np.pi))
    # element centres at ψ(s) + 2πs/p₀ ≡ 0 (mod 2π): s₀ = −p·ψ(0)/(2π)
    s0 = -p * intercept / (2 * np.pi)
    center = s0 + (0.5 * (count - 1) % 1.0) * p
    center += p * np.round((reference - center) / p)
    u_p = p * p * u_slope / (2 * np.pi)
    return ElementLattice(float(p), float(u_p), float(center), int(use.sum()))


@dataclass(frozen=True)
class ConvexTransmitResult:
    """Transmit characterization of a convex array (source frame: apex at the origin,
    centre of curvature at (0, 0, −R); lengths in m, angles in rad).

    Attributes
    ----------
    pose : Pose
        The scan plane in the source frame (its angles: the orientation of the scan
        plane relative to the apex plane).
    radius_of_curvature, radius_uncertainty : float
        R and its standard uncertainty (centre from the phase along the arc, apex from
        the onset of the mean surface velocity).
    angle_uncertainties : (float, float, float)
        Standard uncertainties of (θx, θy, θz).
    aperture : ApertureFit
        On the unrolled grid: ``width`` is the arc length, ``center_x`` the arc position
        of the aperture centre left after the last update.
    arc_angle : float
        Angular extent of the aperture, width / R.
    element_count : int
        Elements that fit in the arc at the nominal pitch (the count check).
    element_map : ElementMap or None
    lens : LensFit or None
    lens_focus : float
        Elevation focus F (inf when not significant).
    geometry : ArrayGeometry
        The fitted element layout (nominal count and pitch on the fitted arc).
    grid : PlaneGrid
        Unrolled (s, y) grid of ``velocity``.
    velocity : ndarray, complex, shape (ns, ny, nf)
        Normal velocity on the face (onset at t = 0).
    frequencies : ndarray, shape (nf,)
    mean_velocity : ndarray, shape (nt,)
        Lens-corrected mean surface velocity (m/s), onset at sample 0's time.
    onset, onset_uncertainty : float
        s.
    impulse_response : TransmitImpulseResponse or None
    ir_spectrum : SpectrumSummary
        Peak frequency and −6 dB band of the IR (of ρ0c0·ū without a drive).
    history : list of dict
    warnings : list of str
    timings : dict
    window_bias : dict
        The flat model's scan-window bias (m): ``window_bias_height`` and
        ``window_bias_focus`` were subtracted from H and F, ``window_bias_width`` was
        added to the uncertainty of W (NaN: correction off or failed).
    """

    pose: Pose
    radius_of_curvature: float
    radius_uncertainty: float
    angle_uncertainties: tuple[float, float, float]
    aperture: Any
    arc_angle: float
    element_count: int
    element_map: Any
    lens: Any
    lens_focus: float
    geometry: ArrayGeometry
    grid: PlaneGrid
    velocity: NDArray[np.complex128]
    frequencies: NDArray[np.float64]
    mean_velocity: NDArray[np.float64]
    sampling_rate: float
    onset: float
    onset_uncertainty: float
    impulse_response: Any
    ir_spectrum: Any
    history: list[dict[str, Any]]
    warnings: list[str]
    timings: dict[str, float]
    window_bias: dict[str, float] = field(default_factory=dict)

    def summary(self) -> dict[str, Any]:
        """The summary.json tree: the keys of a flat array's (``scan_plane``, ``aperture``
        — ``width`` is the arc length —, ``elements``, ``lens_focus``, ``transmit``,
        ``uncertainty`` with the same layout) plus ``array`` (kind ``"convex"``),
        ``radius_of_curvature`` and ``aperture.arc_angle_deg``."""
        def num(v: Any) -> float | None:
            return float(v) if v is not None and np.isfinite(v) else None

        tx, ty, tz = self.pose.angles_deg
        ux, uy, uz = (float(v) for v in np.degrees(self.angle_uncertainties))
        ap, em, sp = self.aperture, self.element_map, self.ir_spectrum
        r = self.radius_of_curvature
        elements: dict[str, Any] = {"count": self.element_count,
                                    "pitch": num(self.geometry.pitch[0]
                                                 if self.geometry.pitch else None),
                                    "width": num(self.geometry.widths[0])}
        if em is not None:
            elements.update({
                "relative_amplitude": [float(v) for v in em.relative_amplitude],
                "delay": [float(v) for v in em.delay], "dead": list(em.dead)})
        return {
            "array": {"kind": "convex", "element_angles_deg": [
                float(v) for v in np.degrees(self.geometry.element_angles)]},
            "scan_plane": {"theta_x_deg": tx, "theta_y_deg": ty, "theta_z_deg": tz,
                           "x0": self.pose.origin[0], "y0": self.pose.origin[1],
                           "z0": self.pose.origin[2]},
            "radius_of_curvature": r,
            "aperture": {"width": ap.width, "height": ap.height, "center_x": ap.center_x,
                         "center_y": ap.center_y,
                         "arc_angle_deg": float(np.degrees(self.arc_angle))},
            "elements": elements,
            "lens_focus": num(self.lens_focus),
            "transmit": {"onset": self.onset,
                         "peak_frequency": None if sp is None else num(sp.peak_frequency),
                         "bandwidth_6db": None if sp is None else num(sp.bandwidth)},
            "uncertainty": {
                "scan_plane": {"theta_x_deg": ux, "theta_y_deg": uy, "theta_z_deg": uz},
                "radius_of_curvature": num(self.radius_uncertainty),
                "aperture": {"width": ap.width_uncertainty, "height": ap.height_uncertainty,
                             "center_x": ap.center_x_uncertainty,
                             "center_y": ap.center_y_uncertainty,
                             "arc_angle_deg": float(np.degrees(ap.width_uncertainty / r))},
                "elements": None if em is None else {
                    "relative_amplitude": [float(v) for v in em.amplitude_uncertainty],
                    "delay": [float(v) for v in em.delay_uncertainty]},
                "lens_focus": None if self.lens is None else num(self.lens.focus_uncertainty),
                "transmit": {"onset": num(self.onset_uncertainty)},
            },
            "timings": {k: float(v) for k, v in self.timings.items()},
            "warnings": list(self.warnings),
        }
