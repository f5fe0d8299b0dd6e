"""Back-projection of a hologram onto the aligned surface of a bowl or a flat piston.

The source surface is sampled on an *unrolled* grid (u, v): for a spherical cap the
azimuthal-equidistant map (arc length s = Rθ from the apex along the azimuth φ), for a
flat source the plane's own coordinates. The complex normal velocity on it comes from
:func:`holoprobe.propagation.project` (``quantity="normal_velocity"``, the fast NUFFT path).

Effective radius of curvature (phase flattening). On a trial cap of radius R with a fixed
apex, a wave converging to a centre displaced by δR along the axis and δ⊥ across it has the
phase ψ = ψ0 + k δR (1 − cos θ) + k sin θ (δ⊥ · ê_φ) to first order, so a weighted
least-squares fit of the reconstructed phase on (1, 1 − cos θ, sin θ cos φ, sin θ sin φ)
updates R and the centre; a few updates make the phase flattest. For a flat source the fit
on (1, u, v) gives the tilt of its normal (k·α = the phase gradient).

Aperture: the outermost radius where the azimuthally averaged amplitude falls to
``edge_level`` of its plateau (the midpoint of a band-limited step), sub-sample by linear
interpolation, plus the shift w²/(2s) by which blurring a circular edge of arc radius s with
the back-projection's resolution (Gaussian-equivalent width w, from the edge's 25–75 %
rise) moves its half level inwards; per-sector estimates give its uncertainty.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal, overload

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from holoprobe.characterize._alignment import orthonormal_frame
from holoprobe.characterize._hologram_config import HologramConfig
from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Surface
from holoprobe.propagation import ProjectionPlan
from holoprobe.signal import MAD_TO_SIGMA, Threads

__all__ = [
    "SourcePlacement",
    "SourceReconstruction",
    "Uniformity",
    "UnrolledSurface",
    "backproject_source",
    "fit_apex",
    "fit_source_surface",
    "hologram_plan",
    "rim_capture_angle",
    "rim_offset",
    "surface_flux",
    "uniformity",
    "unrolled_surface",
]

_KINDS = ("spherical-cap", "flat-disc", "flat-rectangle")
_MAX_POLAR = np.deg2rad(85.0)


@dataclass(frozen=True)
class SourcePlacement:
    """Placement and shape of a single-element source (scan coordinates, m).

    Attributes
    ----------
    kind : {"spherical-cap", "flat-disc", "flat-rectangle"}
    apex : ndarray, shape (3,)
        The cap's apex, or the flat source's centre.
    axis : ndarray, shape (3,)
        Unit normal at the apex, pointing into the medium (towards the scan plane).
    radius_of_curvature : float or None
        R of a cap, ``None`` for flat sources.
    aperture : (float, float)
        Diameter (both equal) of a circular source, (width along e1, height along e2) of a
        rectangle; for a cap the chord diameter 2R sin θ_edge.
    hole_diameter : float
        Diameter of a central opening (0: none).
    """

    kind: str
    apex: NDArray[np.float64]
    axis: NDArray[np.float64]
    radius_of_curvature: float | None
    aperture: tuple[float, float]
    hole_diameter: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in _KINDS:
            raise InputError(f"expected one of {_KINDS}, got {self.kind!r}", field="source")
        axis = np.asarray(self.axis, float)
        object.__setattr__(self, "axis", axis / np.linalg.norm(axis))
        object.__setattr__(self, "apex", np.asarray(self.apex, float))
        if self.kind == "spherical-cap":
            r = self.radius_of_curvature
            if r is None or not r > 0:
                raise InputError(f"expected a positive radius of curvature in m, got {r!r}",
                                 field="radius_of_curvature")
            if not self.aperture[0] <= 2 * r:
                raise InputError(f"aperture {self.aperture[0]:g} m exceeds the sphere's "
                                 f"diameter 2R = {2 * r:g} m", field="aperture")
        if not min(self.aperture) > 0:
            raise InputError(f"expected a positive aperture in m, got {self.aperture}",
                             field="aperture")

    @property
    def centre(self) -> NDArray[np.float64] | None:
        """Centre of curvature (the geometric focus) of a cap, m."""
        if self.radius_of_curvature is None:
            return None
        return self.apex + self.radius_of_curvature * self.axis


@dataclass(frozen=True)
class UnrolledSurface:
    """A source surface sampled on an unrolled grid.

    Attributes
    ----------
    geometry : SourcePlacement
    u, v : ndarray, shape (nu,), (nv,)
        Unrolled coordinates in m (arc length along e1, e2 for a cap).
    mask : ndarray of bool, shape (nu, nv)
        Nodes on the surface (inside the reconstruction radius).
    surface : Surface
        The masked nodes (C order of the grid), normals into the medium, area weights.
    polar : ndarray, shape (nu, nv)
        Polar angle θ on the sphere (caps) or 0 (flat).
    radius : ndarray, shape (nu, nv)
        Lateral distance from the axis, m (R sin θ for caps).
    azimuth : ndarray, shape (nu, nv)
        φ in rad from e1 towards e2.
    e1, e2 : ndarray, shape (3,)
        The in-plane directions of the unrolled map.
    """

    geometry: SourcePlacement
    u: NDArray[np.float64]
    v: NDArray[np.float64]
    mask: NDArray[np.bool_]
    surface: Surface
    polar: NDArray[np.float64]
    radius: NDArray[np.float64]
    azimuth: NDArray[np.float64]
    e1: NDArray[np.float64]
    e2: NDArray[np.float64]

    def to_map(self, values: NDArray, fill: complex = np.nan) -> NDArray:
        """Values on the masked nodes → an (nu, nv) map (``fill`` elsewhere)."""
        out = np.full(self.mask.shape, fill, dtype=np.result_type(values, type(fill)))
        out[self.mask] = values
        return out


def unrolled_surface(geometry: SourcePlacement, step: float, margin: float) -> UnrolledSurface:
    """Sample the source on an unrolled grid of step ``step`` (m), ``margin`` beyond it.

    The grid extends to (1 + margin) times the half-aperture (caps: in lateral radius,
    capped at θ = 85°).
    """
    g = geometry
    e1, e2 = orthonormal_frame(g.axis)
    half = 0.5 * np.array(g.aperture) * (1 + margin)
    if g.kind == "spherical-cap":
        # (type: ignore below) a spherical cap has a radius (SourceGeometry checks it)
        r = float(g.radius_of_curvature)  # type: ignore[arg-type]
        s_max = r * min(np.arcsin(min(half[0] / r, 1.0)), _MAX_POLAR)
        half = np.array([s_max, s_max])
    n = np.ceil(half / step).astype(int)
    u = np.arange(-n[0], n[0] + 1) * step
    v = np.arange(-n[1], n[1] + 1) * step
    uu, vv = np.meshgrid(u, v, indexing="ij")
    s = np.hypot(uu, vv)
    phi = np.arctan2(vv, uu)
    if g.kind == "spherical-cap":
        # (type: ignore below) a spherical cap has a radius (SourceGeometry checks it)
        r = float(g.radius_of_curvature)  # type: ignore[arg-type]
        mask = s <= half[0] + 1e-12
        theta = s / r
        lateral = r * np.sin(theta)
        sinc = np.where(s > 0, r * np.sin(theta) / np.where(s > 0, s, 1.0), 1.0)
        radial = np.cos(phi)[..., None] * e1 + np.sin(phi)[..., None] * e2
        pts = (g.apex + (r * (1 - np.cos(theta)))[..., None] * g.axis
               + lateral[..., None] * radial)
        normals = (g.centre - pts) / r
        weights = step * step * sinc
    else:
        mask = np.ones(uu.shape, bool) if g.kind == "flat-rectangle" else s <= half[0] + 1e-12
        theta = np.zeros_like(s)
        lateral = s
        pts = g.apex + uu[..., None] * e1 + vv[..., None] * e2
        normals = np.broadcast_to(g.axis, pts.shape)
        weights = np.full(s.shape, step * step)
    surface = Surface(pts[mask], normals[mask], weights[mask])
    return UnrolledSurface(g, u, v, mask, surface, theta, lateral, phi, e1, e2)


def hologram_plan(pressure: NDArray, grid: PlaneGrid, frequencies: NDArray, medium: Medium,
                  *, guard_angle: float, eps: float = 1e-6) -> ProjectionPlan:
    """The :class:`~holoprobe.propagation.ProjectionPlan` of a hologram for
    :func:`backproject_source`: double precision, the padding rule's exact size for
    every target (the numbers :func:`holoprobe.propagation.project` gives), the padded
    spectra kept while that size stays the same.

    Parameters
    ----------
    pressure : ndarray, complex, shape (nx, ny, nf)
        Hologram (Pa) on ``grid`` (scan coordinates).
    grid : PlaneGrid
    frequencies : ndarray, shape (nf,)
        Hz.
    medium : Medium
    guard_angle : float
        Padding rule angle in rad.
    eps : float
        Relative tolerance of the type-3 NUFFTs.

    Returns
    -------
    ProjectionPlan
    """
    return ProjectionPlan(pressure, grid, frequencies, medium, guard_angle=guard_angle,
                          allow_undersampled=True, exact_padding=True, eps=eps)


@overload
def backproject_source(pressure: NDArray, grid: PlaneGrid, frequencies: NDArray,
                       medium: Medium, unrolled: UnrolledSurface, *, guard_angle: float,
                       with_pressure: Literal[True], progress: bool | None = False,
                       plan: ProjectionPlan | None = None, eps: float = 1e-6
                       ) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]: ...


@overload
def backproject_source(pressure: NDArray, grid: PlaneGrid, frequencies: NDArray,
                       medium: Medium, unrolled: UnrolledSurface, *, guard_angle: float,
                       with_pressure: Literal[False] = False, progress: bool | None = False,
                       plan: ProjectionPlan | None = None, eps: float = 1e-6
                       ) -> tuple[NDArray[np.complex128], None]: ...


def backproject_source(pressure: NDArray, grid: PlaneGrid, frequencies: NDArray,
                       medium: Medium, unrolled: UnrolledSurface, *, guard_angle: float,
                       with_pressure: bool = False, progress: bool | None = False,
                       plan: ProjectionPlan | None = None, eps: float = 1e-6
                       ) -> tuple[NDArray[np.complex128], NDArray[np.complex128] | None]:
    """Normal velocity (and optionally pressure) on the source surface.

    Parameters
    ----------
    pressure : ndarray, complex, shape (nx, ny, nf)
        Hologram (Pa, exp(−iωt)) on ``grid`` (scan coordinates).
    grid : PlaneGrid
    frequencies : ndarray, shape (nf,)
        Hz.
    medium : Medium
    unrolled : UnrolledSurface
        Target surface (behind the scan plane).
    guard_angle : float
        Padding rule angle in rad (:func:`holoprobe.propagation.padded_shape`).
    with_pressure : bool
        Also return the pressure on the surface.
    progress : bool or None
        Progress bar.
    plan : ProjectionPlan, optional
        A plan of these data (:func:`hologram_plan`) to reuse its padded spectra across
        calls (iterations over trial surfaces); default a plan for this call, whose
        spectra serve both quantities.
    eps : float
        Relative tolerance of the type-3 NUFFTs of the plan made here (a given ``plan``
        keeps its own).

    Returns
    -------
    (ndarray, ndarray or None)
        Normal velocity in m/s, shape (n_surface, nf), along the normals (into the medium),
        and the pressure in Pa (or None).
    """
    if np.any(unrolled.surface.points[:, 2] >= 0):
        raise InputError("the source surface reaches the scan plane or lies in front of it "
                         f"(largest z = {unrolled.surface.points[:, 2].max() * 1e3:.4g} mm); "
                         "the hologram must be in front of the source", field="zPosition")

    if plan is None:
        plan = hologram_plan(pressure, grid, frequencies, medium, guard_angle=guard_angle,
                             eps=eps)
    # the padded spectra once (both quantities, and later calls with the same padding)
    plan.prepare(unrolled.surface, progress=progress)

    def run(quantity: Literal["normal_velocity", "pressure"]) -> NDArray[np.complex128]:
        return plan.project(unrolled.surface, quantity=quantity, progress=progress)

    if not with_pressure:
        return run("normal_velocity"), None
    # one frequency keeps one thread of the plan busy: run both quantities side by side
    # (finufft releases the GIL; the cached spectra are only read)
    both: tuple[Literal["normal_velocity"], Literal["pressure"]] = ("normal_velocity",
                                                                    "pressure")
    with Threads(2) as threads:
        vel, prs = threads.map(run, both)
    return vel, prs


def _relative_change(new: float | None, old: float | None) -> float:
    """|new − old| / old of a spherical cap's radius of curvature (both set: SourceGeometry
    checks that a cap has one)."""
    assert new is not None and old is not None
    return abs(new - old) / old


def _weighted_lstsq(basis: NDArray, values: NDArray, weights: NDArray) -> NDArray:
    sw = np.sqrt(weights)
    coef, *_ = np.linalg.lstsq(basis * sw[:, None], values * sw, rcond=None)
    return coef


def _flat_phase(vel: NDArray, weights: NDArray) -> NDArray:
    """Phase relative to the weighted mean phasor (−π, π]."""
    mean = np.sum(weights * vel)
    return np.angle(vel * np.conj(mean))


def _robust_phase_fit(basis: NDArray, psi: NDArray, w: NDArray, outlier: float
                      ) -> tuple[NDArray, NDArray[np.bool_]]:
    """Weighted least squares of the phase, refitted without the nodes whose residual
    exceeds ``outlier`` rad (a phase defect would otherwise bend R and the tilt).
    Returns the terms and the nodes kept."""
    a = _weighted_lstsq(basis, psi, w)
    keep = np.ones(psi.size, bool)
    for _ in range(2):
        new = np.abs(np.angle(np.exp(1j * (psi - basis @ a)))) <= outlier
        if new.all() or new.sum() < 0.5 * new.size:
            break
        keep = new
        a = _weighted_lstsq(basis[keep], psi[keep], w[keep])
    return a, keep


def _phase_system(unrolled: UnrolledSurface, vel: NDArray, inside: NDArray
                  ) -> tuple[NDArray, NDArray, NDArray]:
    """Basis, flattened phase and weights |v|² of the phase fit on the nodes ``inside``.

    Caps: (1, 1 − cos θ, sin θ cos φ, sin θ sin φ); flat sources: (1, u, v)."""
    m = unrolled.mask
    theta, phi = unrolled.polar[m][inside], unrolled.azimuth[m][inside]
    w = np.abs(vel[inside]) ** 2
    psi = _flat_phase(vel[inside], w)
    if unrolled.geometry.kind == "spherical-cap":
        basis = np.stack([np.ones_like(theta), 1 - np.cos(theta), np.sin(theta) * np.cos(phi),
                          np.sin(theta) * np.sin(phi)], axis=1)
    else:
        rr = unrolled.radius[m][inside]
        basis = np.stack([np.ones_like(rr), rr * np.cos(phi), rr * np.sin(phi)], axis=1)
    return basis, psi, w


def _phase_update(unrolled: UnrolledSurface, vel: NDArray, k: float,
                  inside: NDArray, outlier: float = np.pi) -> tuple[SourcePlacement, NDArray]:
    """One phase-flattening update of the geometry; returns it and the fitted terms.

    Nodes whose phase departs from the fit by more than ``outlier`` rad (phase defects)
    are left out of a second fit.
    """
    g = unrolled.geometry
    a, _ = _robust_phase_fit(*_phase_system(unrolled, vel, inside), outlier)
    if g.kind == "spherical-cap":
        # (type: ignore below) a spherical cap has a radius (SourceGeometry checks it)
        r = float(g.radius_of_curvature) + a[1] / k  # type: ignore[arg-type]
        centre = g.centre + (a[2] * unrolled.e1 + a[3] * unrolled.e2) / k
        axis = centre - g.apex
        return replace(g, radius_of_curvature=r, axis=axis / np.linalg.norm(axis)), a
    axis = g.axis + (a[1] * unrolled.e1 + a[2] * unrolled.e2) / k
    return replace(g, axis=axis / np.linalg.norm(axis)), a


def _ring_profile(radius: NDArray, amp: NDArray, step: float, hole: float
                  ) -> tuple[NDArray, NDArray]:
    """Ring-averaged amplitude (relative to the inner plateau) and the rings' mean radii."""
    edges = np.arange(0.0, radius.max() + step, step)
    idx = np.digitize(radius, edges) - 1
    counts = np.bincount(idx, None, edges.size)
    ok = counts > 0
    profile = np.bincount(idx, amp, edges.size)[ok] / counts[ok]
    centres = np.bincount(idx, radius, edges.size)[ok] / counts[ok]  # mean radius per ring
    inner = centres < 0.6 * centres.max()
    inner &= centres > 0.5 * hole + 2 * step
    plateau = np.median(profile[inner]) if np.any(inner) else profile.max()
    return centres, profile / plateau


def _outer_crossing(centres: NDArray, profile: NDArray, level: float) -> float:
    """Outermost radius where ``profile`` crosses ``level`` (linear interpolation)."""
    above = np.nonzero(profile >= level)[0]
    if above.size == 0 or above[-1] == profile.size - 1:
        return float("nan")
    i = above[-1]
    a0, a1 = profile[i], profile[i + 1]
    return float(centres[i] + (a0 - level) / (a0 - a1) * (centres[i + 1] - centres[i]))


def _edge_radius(radius: NDArray, amp: NDArray, level: float, step: float,
                 hole: float) -> float:
    """Outermost radius where the ring-averaged amplitude crosses ``level`` × plateau."""
    return _outer_crossing(*_ring_profile(radius, amp, step, hole), level)


def _edge_blur(radius: NDArray, amp: NDArray, step: float, hole: float) -> float:
    """Gaussian-equivalent width (m) of the reconstructed edge: its 25–75 % rise / 1.349."""
    centres, profile = _ring_profile(radius, amp, step, hole)
    return (_outer_crossing(centres, profile, 0.25)
            - _outer_crossing(centres, profile, 0.75)) / 1.349


def _annulus_blur(arc: NDArray, amp: NDArray, s_edge: float, band: float, step: float
                  ) -> float:
    """Gaussian-equivalent edge width (m) from the rings of an annulus around ``s_edge``.

    The plateau is the median ring amplitude inside ``s_edge − band/2``.
    """
    edges = np.arange(s_edge - band, s_edge + band + step, step)
    idx = np.digitize(arc, edges) - 1
    ok_pts = (idx >= 0) & (idx < edges.size - 1)
    counts = np.bincount(idx[ok_pts], None, edges.size - 1)
    ok = counts > 0
    profile = np.bincount(idx[ok_pts], amp[ok_pts], edges.size - 1)[ok] / counts[ok]
    centres = np.bincount(idx[ok_pts], arc[ok_pts], edges.size - 1)[ok] / counts[ok]
    inner = centres < s_edge - band / 2
    if not np.any(inner):
        return float("nan")
    profile = profile / np.median(profile[inner])
    return (_outer_crossing(centres, profile, 0.25)
            - _outer_crossing(centres, profile, 0.75)) / 1.349


def _vertex(x: NDArray, y: NDArray) -> tuple[float, float]:
    """Vertex of the least-squares parabola through (x, y) and its standard error."""
    design = np.stack([np.ones_like(x), x, x * x], axis=1)
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    _, b, a = coef
    if not a > 0:
        return float("nan"), float("nan")
    resid = y - design @ coef
    dof = max(x.size - 3, 1)
    cov = np.linalg.inv(design.T @ design) * float(resid @ resid) / dof
    grad = np.array([0.0, -1 / (2 * a), b / (2 * a * a)])  # ∂(−b/2a)/∂(c, b, a)
    return float(-b / (2 * a)), float(np.sqrt(max(grad @ cov @ grad, 0.0)))


def rim_capture_angle(geometry: SourcePlacement, grid: PlaneGrid, n: int = 64) -> float:
    """Smallest angle (rad) outwards of the rim's normal at which the scan sees the rim.

    Around the rim of a circular source, the angle from the rim's normal (a cap's points
    to the centre of curvature, inwards by the cap's half-angle) to the line from the
    rim to the scan window's edge, outwards along the rim's radial direction; the
    smallest over the rim (negative when the window ends inside the normal's
    direction). The edge diffracts on both sides of its normal; a scan that keeps only
    a few degrees of the outward side reconstructs an edge whose sharpness no longer
    peaks on the true surface (:func:`fit_apex`).

    Parameters
    ----------
    geometry : SourcePlacement
        Spherical cap or flat disc (scan coordinates).
    grid : PlaneGrid
        The scan grid (identity pose).
    n : int
        Rim points.

    Returns
    -------
    float
    """
    g = geometry
    half = 0.5 * g.aperture[0]
    r = g.radius_of_curvature
    sag = 0.0 if r is None else r - np.sqrt(max(r * r - half * half, 0.0))
    e1 = np.cross(g.axis, [0.0, 1.0, 0.0] if abs(g.axis[1]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(g.axis, e1)
    phi = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    radial = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    rim = g.apex + sag * g.axis + half * radial
    normal = (np.broadcast_to(g.axis, rim.shape) if r is None
              else (g.apex + r * g.axis - rim) / r)
    out = radial[:, :2] / np.linalg.norm(radial[:, :2], axis=1, keepdims=True)
    lo = np.array([grid.x.min(), grid.y.min()])
    hi = np.array([grid.x.max(), grid.y.max()])
    with np.errstate(divide="ignore", invalid="ignore"):
        reach = np.where(out > 0, (hi - rim[:, :2]) / out, (lo - rim[:, :2]) / out)
    reach = np.where(np.abs(out) > 1e-12, reach, np.inf).min(axis=1)
    seen = np.arctan2(reach, -rim[:, 2])  # window edge, outwards from +z
    tilt = np.arctan2(np.sum(normal[:, :2] * out, axis=1), normal[:, 2])  # the normal's
    return float(np.min(seen - tilt))


def fit_apex(pressure: NDArray, grid: PlaneGrid, frequency: float, medium: Medium,
             geometry: SourcePlacement, *, guard_angle: float,
             cfg: HologramConfig | None = None) -> tuple[float, float]:
    """Position of a circular source along its axis from the sharpness of its edge.

    The phase of the back-projected velocity fixes a cap's centre of curvature, not how
    far along the axis its surface lies (a concentric sphere is as phase-flat). The
    velocity's edge is sharpest on the true surface: off it by δ, the edge blurs as
    w² = w0² + (αδ)². The edge width (25–75 % rise of the ring-averaged amplitude in an
    annulus around the edge) is measured on concentric trial surfaces (flat sources:
    parallel planes) and a parabola in δ fitted to w², twice (a wide then a narrow span).
    A scan that sees less than ``cfg.apex_min_capture_deg`` outwards of the rim's
    normal (:func:`rim_capture_angle`) loses the edge's outward waves, which biases the
    apex towards the medium (twins: +116 µm at 22.9°, +80 µm at 28.4°, +34 µm at 29.0°;
    −4…+14 µm at 35.5°, −3 µm at 40.4°): NaN then.

    Parameters
    ----------
    pressure : ndarray, complex, shape (nx, ny)
        CW hologram, Pa, on ``grid`` (scan coordinates).
    grid : PlaneGrid
    frequency : float
        Hz.
    medium : Medium
    geometry : SourcePlacement
        Current geometry (spherical cap or flat disc; centre of curvature already fitted).
    guard_angle : float
        Padding rule angle of the back-projection, rad.
    cfg : HologramConfig, optional
        ``apex_span_wavelengths`` (half-span of the first pass) and
        ``surface_step_wavelengths``.

    Returns
    -------
    (float, float)
        Shift δ (m) of the apex along the axis (towards the medium) and its standard
        uncertainty; the cap's radius becomes R − δ. NaN when no edge is found.
    """
    cfg = cfg or HologramConfig()
    g = geometry
    if g.kind not in ("spherical-cap", "flat-disc"):
        raise InputError(f"expected a spherical cap or a flat disc, got {g.kind!r}",
                         field="source")
    if np.degrees(rim_capture_angle(g, grid)) < cfg.apex_min_capture_deg:
        return float("nan"), float("nan")
    wavelength = float(medium.wavelength(frequency))
    step = cfg.surface_step_wavelengths * wavelength
    half = 0.5 * g.aperture[0]
    r = g.radius_of_curvature
    s_edge = half if r is None else r * np.arcsin(min(half / r, 1.0))
    band = 3 * wavelength
    # one padded FFT of the hologram for every trial surface
    # (single precision: the edge width needs ~1e-3, not 1e-6)
    plan = ProjectionPlan(pressure[:, :, None], grid, [frequency], medium,
                          guard_angle=guard_angle, allow_undersampled=True, eps=1e-4,
                          single_precision=True)

    def blur(delta: float) -> float:
        trial = replace(g, apex=g.apex + delta * g.axis,
                        radius_of_curvature=None if r is None else r - delta)
        surf = unrolled_surface(trial, step, cfg.surface_margin)
        arc = np.hypot(*np.meshgrid(surf.u, surf.v, indexing="ij"))[surf.mask]
        near = np.abs(arc - s_edge) <= band
        vel = plan.project(surf.surface.subset(near), quantity="normal_velocity")[:, 0]
        return _annulus_blur(arc[near], np.abs(vel), s_edge, band, step / 2)

    # a wide pass, then a narrow one around its vertex: the final parabola is fitted to
    # the trials within half the wide span of that vertex (more than the narrow five:
    # a narrow span alone is at the mercy of the noise, a wide one bends away from a
    # parabola)
    span = cfg.apex_span_wavelengths * wavelength
    deltas = np.linspace(-1, 1, 5) * span
    widths = np.array([blur(float(d)) for d in deltas])
    ok = np.isfinite(widths)
    if ok.sum() < 4:
        return float("nan"), float("nan")
    vertex, u = _vertex(deltas[ok], widths[ok] ** 2)
    if not np.isfinite(vertex):
        return float("nan"), float("nan")
    centre = float(np.clip(vertex, -span, span))
    extra = centre + np.linspace(-1, 1, 4) * span / 3
    deltas = np.concatenate([deltas, extra])
    widths = np.concatenate([widths, [blur(float(d)) for d in extra]])
    near = np.isfinite(widths) & (np.abs(deltas - centre) <= 0.55 * span)
    if near.sum() < 5:
        return float("nan"), float("nan")
    vertex, u = _vertex(deltas[near], widths[near] ** 2)
    if not np.isfinite(vertex):
        return float("nan"), float("nan")
    return float(np.clip(vertex, deltas.min(), deltas.max())), u


def _aperture(unrolled: UnrolledSurface, vel: NDArray, cfg: HologramConfig, step: float
              ) -> tuple[tuple[float, float], float]:
    """Aperture (diameter or width, height) and its standard uncertainty (m)."""
    g = unrolled.geometry
    m = unrolled.mask
    amp = np.abs(vel)
    if g.kind == "flat-rectangle":
        uu, vv = np.meshgrid(unrolled.u, unrolled.v, indexing="ij")
        sizes, spread = [], []
        for along, across, half in ((uu[m], vv[m], g.aperture[1]), (vv[m], uu[m], g.aperture[0])):
            band = np.abs(across) < 0.25 * half
            ends = [_edge_radius(np.abs(along[band & (along * sgn > 0)]),
                                 amp[band & (along * sgn > 0)], cfg.edge_level, step, 0.0)
                    for sgn in (-1, 1)]
            sizes.append(ends[0] + ends[1])
            spread.append(abs(ends[0] - ends[1]) / 2)
        return (sizes[0], sizes[1]), float(np.hypot(spread[0], spread[1]) / np.sqrt(2))
    arc = np.hypot(*np.meshgrid(unrolled.u, unrolled.v, indexing="ij"))[m]
    phi = unrolled.azimuth[m]
    s_edge = _edge_radius(arc, amp, cfg.edge_level, step / 2, g.hole_diameter)
    # interpolation error of the crossing: half-width rings against full-width ones
    u_interp = abs(s_edge - _edge_radius(arc, amp, cfg.edge_level, step, g.hole_diameter))
    edges = []
    for j in range(8):
        sel = (phi >= -np.pi + j * np.pi / 4) & (phi < -np.pi + (j + 1) * np.pi / 4)
        edges.append(_edge_radius(arc[sel], amp[sel], cfg.edge_level, step, g.hole_diameter))
    sectors = np.array(edges)
    sectors = sectors[np.isfinite(sectors)]
    mad = MAD_TO_SIGMA * np.median(np.abs(sectors - np.median(sectors))) if sectors.size else 0.0
    # a circular edge blurred by the back-projection's resolution (Gaussian-equivalent
    # width w) crosses half its plateau w²/(2 s) inside the true edge: add it back, half
    # of it as its uncertainty (the blur is not exactly Gaussian)
    blur = _edge_blur(arc, amp, step / 2, g.hole_diameter)
    curvature = blur**2 / (2 * s_edge) if np.isfinite(blur) and s_edge > 0 else 0.0
    s_edge += curvature
    u_s = float(np.sqrt((mad / np.sqrt(max(sectors.size, 1))) ** 2 + u_interp**2
                        + (0.5 * curvature) ** 2))
    if g.kind == "spherical-cap":
        # (type: ignore below) a spherical cap has a radius (SourceGeometry checks it)
        r = float(g.radius_of_curvature)  # type: ignore[arg-type]
        d = 2 * r * np.sin(s_edge / r)
        u_d = 2 * np.cos(s_edge / r) * u_s
    else:
        d, u_d = 2 * s_edge, 2 * u_s
    return (float(d), float(d)), float(u_d)


def rim_offset(unrolled: UnrolledSurface, velocity: NDArray, cfg: HologramConfig,
               step: float, sectors: int = 16) -> tuple[NDArray[np.float64], float]:
    """Where the reconstructed rim of a circular source is centred, relative to its apex.

    The edge (``cfg.edge_level`` of the plateau) is found in ``sectors`` azimuthal
    sectors of the unrolled map and a circle s(φ) = s0 + a cos φ + b sin φ is fitted to
    them. Sectors whose plateau is not within 0.7–1.4 of the whole aperture's (a dead or
    hot sector, a weak segment) are left out, and so are edges more than 3 robust
    standard deviations from the circle: a defect moves its own sector's edge, not the
    rim's centre (an amplitude-weighted centroid would move with it).

    Parameters
    ----------
    unrolled : UnrolledSurface
        The surface (spherical cap or flat disc) the velocity lives on.
    velocity : ndarray, complex, shape (n_surface,)
        Normal velocity on its masked nodes.
    cfg : HologramConfig
    step : float
        Ring width of the edge profiles, m.
    sectors : int
        Number of azimuthal sectors.

    Returns
    -------
    offset : ndarray, shape (3,)
        The rim's centre minus the apex along the surface (arc length for a cap), as the
        vector a e1 + b e2 in m (scan coordinates).
    uncertainty : float
        Standard uncertainty of that offset's length, m (nan: fewer than 6 sectors).
    """
    g, m = unrolled.geometry, unrolled.mask
    arc = np.hypot(*np.meshgrid(unrolled.u, unrolled.v, indexing="ij"))[m]
    phi, amp = unrolled.azimuth[m], np.abs(velocity)
    s_edge = _edge_radius(arc, amp, cfg.edge_level, step, g.hole_diameter)
    core = (arc < 0.6 * s_edge) & (arc > 0.5 * g.hole_diameter + 2 * step)
    nan = (np.full(3, np.nan), float("nan"))
    if not (np.isfinite(s_edge) and np.any(core)):
        return nan
    plateau = float(np.median(amp[core]))
    width = 2 * np.pi / sectors
    angles, edges = [], []
    for j in range(sectors):
        sel = np.mod(phi + np.pi - j * width, 2 * np.pi) < width
        own = amp[sel & core]
        if own.size < 4 or not 0.7 <= np.median(own) / plateau <= 1.4:
            continue
        edge = _edge_radius(arc[sel], amp[sel], cfg.edge_level, step, g.hole_diameter)
        if np.isfinite(edge):
            angles.append(-np.pi + (j + 0.5) * width)
            edges.append(edge)
    fit = _robust_circle(np.array(angles), np.array(edges), 0.05 * step)
    if fit is None:
        return nan
    coef, cov = fit
    # a sector's mean edge sees a cos φ reduced by sinc of its half-width
    shrink = np.sin(width / 2) / (width / 2)
    offset = (coef[1] * unrolled.e1 + coef[2] * unrolled.e2) / shrink
    return offset, float(np.sqrt(cov[1, 1] + cov[2, 2]) / shrink)


def _robust_circle(angles: NDArray, radii: NDArray, floor: float
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """Robust least-squares fit of r(φ) = c0 + c1 cos φ + c2 sin φ and its covariance.

    Points more than 3 robust standard deviations (``MAD_TO_SIGMA`` × median |residual|,
    at least ``floor``) from the fit are left out, iterated until the kept set no longer
    changes (at most 5 passes); the coefficients and their covariance (residual variance
    × (BᵀB)⁻¹) both come from that final kept set.

    Parameters
    ----------
    angles : ndarray, shape (n,)
        Azimuths φ, rad.
    radii : ndarray, shape (n,)
        r at each azimuth (any length unit).
    floor : float
        Smallest robust scale (same unit as ``radii``): exact data keep every point.

    Returns
    -------
    (coef, cov) : ndarray (3,), ndarray (3, 3), or None
        None when fewer than 6 points are kept.
    """
    basis = np.stack([np.ones(angles.size), np.cos(angles), np.sin(angles)], axis=1)
    keep = np.ones(angles.size, bool)
    for _ in range(5):
        if keep.sum() < 6:
            return None
        coef, *_ = np.linalg.lstsq(basis[keep], radii[keep], rcond=None)
        resid = radii - basis @ coef
        scale = max(MAD_TO_SIGMA * float(np.median(np.abs(resid[keep]))), floor)
        new_keep = np.abs(resid) <= 3 * scale
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    else:
        if keep.sum() < 6:
            return None
        coef, *_ = np.linalg.lstsq(basis[keep], radii[keep], rcond=None)
        resid = radii - basis @ coef
    b = basis[keep]
    dof = max(int(keep.sum()) - 3, 1)
    cov = np.linalg.inv(b.T @ b) * float(np.sum(resid[keep] ** 2)) / dof
    return coef, cov


def _inside(unrolled: UnrolledSurface, geometry: SourcePlacement) -> NDArray[np.bool_]:
    """Surface nodes inside the aperture (and outside the central opening)."""
    m = unrolled.mask
    if geometry.kind == "flat-rectangle":
        uu, vv = np.meshgrid(unrolled.u, unrolled.v, indexing="ij")
        return ((np.abs(uu[m]) <= geometry.aperture[0] / 2)
                & (np.abs(vv[m]) <= geometry.aperture[1] / 2))
    lateral = unrolled.radius[m]
    return (lateral <= geometry.aperture[0] / 2) & (lateral >= geometry.hole_diameter / 2)


@dataclass(frozen=True)
class SourceReconstruction:
    """The source surface fitted to a hologram and its complex normal velocity.

    Attributes
    ----------
    geometry : SourcePlacement
        Final (effective) geometry.
    unrolled : UnrolledSurface
        The sampled surface the velocity lives on.
    velocity : ndarray, complex, shape (n_surface, nf)
        Normal velocity in m/s (exp(−iωt)).
    pressure : ndarray, complex, shape (n_surface, nf)
        Pressure on the surface in Pa.
    inside : ndarray of bool, shape (n_surface,)
        Nodes inside the aperture.
    radius_uncertainty : float or None
        Standard uncertainty of the radius of curvature, m.
    aperture_uncertainty : float
        Standard uncertainty of the aperture, m.
    phase_terms : ndarray
        Last phase-fit coefficients (rad): caps (ψ0, k δR, k δx, k δy), flat (ψ0, k αx, k αy).
    iterations : int
        Geometry updates made.
    tilt_uncertainty : float or None
        Flat sources: standard uncertainty of the normal's direction, rad.
    apex_shift : float
        Where the data put the apex along the axis relative to where the fit started (the
        file's ``zPosition``), m, towards the medium (:func:`fit_apex`; 0: not fitted).
        ``geometry`` holds the data's apex only with ``apex_from_data``.
    apex_uncertainty : float or None
        Standard uncertainty of the apex along the axis, m (None: not fitted).
    data_apex : ndarray, shape (3,) or None
        The apex where the data put it (m, scan coordinates; None: not fitted).
    """

    geometry: SourcePlacement
    unrolled: UnrolledSurface
    velocity: NDArray[np.complex128]
    pressure: NDArray[np.complex128]
    inside: NDArray[np.bool_]
    radius_uncertainty: float | None
    aperture_uncertainty: float
    phase_terms: NDArray[np.float64]
    iterations: int
    tilt_uncertainty: float | None = None
    apex_shift: float = 0.0
    apex_uncertainty: float | None = None
    data_apex: NDArray[np.float64] | None = None


def fit_source_surface(pressure: NDArray, grid: PlaneGrid, frequency: float, medium: Medium,
                       geometry: SourcePlacement, *, guard_angle: float,
                       cfg: HologramConfig | None = None, fit_curvature: bool = True,
                       fit_aperture: bool = True, fit_tilt: bool = True,
                       fit_apex: bool = True, progress: bool | None = False,
                       plan: ProjectionPlan | None = None) -> SourceReconstruction:
    """Back-project onto the source, make its phase flattest, find its aperture edge.

    Parameters
    ----------
    pressure : ndarray, complex, shape (nx, ny)
        CW hologram in Pa on ``grid`` (scan coordinates).
    grid : PlaneGrid
    frequency : float
        Hz.
    medium : Medium
    geometry : SourcePlacement
        Starting geometry (apex on the aligned axis, nominal R and aperture).
    guard_angle : float
        Padding rule angle in rad.
    cfg : HologramConfig, optional
    fit_curvature : bool
        Update R (caps) by phase flattening; else keep it.
    fit_aperture : bool
        Measure the aperture from the velocity; else keep the nominal one.
    fit_tilt : bool
        Flat sources: update the normal by phase flattening.
    fit_apex : bool
        Circular sources: find where along its axis the source's edge is sharpest
        (:func:`fit_apex`, when ``cfg.fit_apex``) and move it there when
        ``cfg.apex_from_data``.
    progress : bool or None
    plan : ProjectionPlan, optional
        :func:`hologram_plan` of ``pressure`` at ``frequency`` (reused by a caller that
        fits again); default one for this fit, shared by every trial surface.

    Returns
    -------
    SourceReconstruction
    """
    cfg = cfg or HologramConfig()
    k = float(medium.wavenumber(frequency))
    step = cfg.surface_step_wavelengths * 2 * np.pi / k
    p3 = pressure[:, :, None]
    f = np.array([frequency])
    if plan is None:
        plan = hologram_plan(p3, grid, f, medium, guard_angle=guard_angle)
    g = geometry
    terms = np.zeros(4)
    u_r = None
    iterations = 0
    update = (fit_curvature if g.kind == "spherical-cap" else fit_tilt)
    coarse = max(step, cfg.fit_step_wavelengths * 2 * np.pi / k)
    for iterations in range(1, cfg.curvature_iterations + 1 if update else 1):  # noqa: B007
        surf = unrolled_surface(g, coarse, cfg.surface_margin)
        vel, _ = backproject_source(p3, grid, f, medium, surf, guard_angle=guard_angle,
                                    plan=plan)
        inside = _inside(surf, g)
        new, terms = _phase_update(surf, vel[:, 0], k, inside, cfg.phase_defect_rad)
        change = (_relative_change(new.radius_of_curvature, g.radius_of_curvature)
                  if g.kind == "spherical-cap" else np.linalg.norm(new.axis - g.axis))
        g = new
        if change < cfg.curvature_tolerance:
            break
    shift, u_apex, data_apex = 0.0, None, None
    if fit_apex and cfg.fit_apex and g.kind in ("spherical-cap", "flat-disc"):
        moved, shift, u_apex = _moved_apex(pressure, grid, frequency, medium, g,
                                           guard_angle, cfg)
        data_apex = moved.apex if u_apex is not None else None
        g = moved if cfg.apex_from_data else g
    surf = unrolled_surface(g, step, cfg.surface_margin)
    vel, prs = backproject_source(p3, grid, f, medium, surf, guard_angle=guard_angle,
                                  with_pressure=True, progress=progress, plan=plan)
    aperture, u_ap = g.aperture, 0.0
    if fit_aperture:
        aperture, u_ap = _aperture(surf, vel[:, 0], cfg, step)
        if np.all(np.isfinite(aperture)):
            g = replace(g, aperture=aperture)
        else:
            u_ap = float("nan")
    inside = _inside(surf, g)
    u_tilt = None
    if update and g.kind == "spherical-cap":
        # R = |centre − apex|: a data apex's uncertainty along the axis adds in
        u_r = float(np.hypot(_sector_uncertainty(surf, vel[:, 0], k, inside,
                                                     cfg.phase_defect_rad),
                             (u_apex or 0.0) if cfg.apex_from_data else 0.0))
    elif update:
        u_tilt = _sector_uncertainty(surf, vel[:, 0], k, inside, cfg.phase_defect_rad)
    return SourceReconstruction(g, surf, vel, prs, inside, u_r, u_ap, terms, iterations,
                                u_tilt, shift, u_apex, data_apex)


def _moved_apex(pressure: NDArray, grid: PlaneGrid, frequency: float, medium: Medium,
                g: SourcePlacement, guard_angle: float, cfg: HologramConfig
                ) -> tuple[SourcePlacement, float, float | None]:
    """The geometry moved along its axis by :func:`fit_apex` (unchanged if it fails)."""
    delta, u = fit_apex(pressure, grid, frequency, medium, g, guard_angle=guard_angle,
                        cfg=cfg)
    if not (np.isfinite(delta) and np.isfinite(u)):
        return g, 0.0, None
    r = g.radius_of_curvature
    return (replace(g, apex=g.apex + delta * g.axis,
                    radius_of_curvature=None if r is None else r - delta), delta, u)


def _sector_uncertainty(surf: UnrolledSurface, vel: NDArray, k: float,
                        inside: NDArray, outlier: float = np.pi) -> float:
    """Standard uncertainty from the phase fit repeated on 8 azimuthal sectors.

    Caps: the radius update a₁/k (m); flat sources: the tilt |(a₁, a₂)|/k (rad). Each
    sector's estimate scatters about the whole-aperture one (zero after convergence). A
    sector more than half of whose nodes are below a third of the median amplitude (a
    dead sector) is left out: its phase fit rests on a sliver. Nodes the whole
    aperture's fit leaves out (phase defects, ``outlier``) are left out of each sector's.
    """
    phi = surf.azimuth[surf.mask][inside]
    idx = np.nonzero(inside)[0]
    amp = np.abs(vel[inside])
    live = amp > np.median(amp) / 3
    # a phase defect (with a wavelength around it: its band-limited edge) is left out of
    # every sector's fit as it is of the whole one's
    _, kept = _robust_phase_fit(*_phase_system(surf, vel, inside), outlier)
    if not kept.all():
        bad = np.zeros(inside.size, bool)
        bad[idx[~kept]] = True
        reach = int(np.ceil(2 * np.pi / k / (surf.u[1] - surf.u[0])))
        disc = np.hypot(*np.mgrid[-reach:reach + 1, -reach:reach + 1]) <= reach
        kept = ~ndimage.binary_dilation(surf.to_map(bad, fill=False), disc)[surf.mask][inside]
    estimates = []
    for j in range(8):
        part = (phi >= -np.pi + j * np.pi / 4) & (phi < -np.pi + (j + 1) * np.pi / 4)
        if (part & kept).sum() < 10 or np.mean(live[part]) < 0.5:
            continue
        sel = np.zeros(inside.size, bool)
        sel[idx[part & kept]] = True
        _, a = _phase_update(surf, vel, k, sel, outlier)
        estimates.append(a[1:2] / k if surf.geometry.kind == "spherical-cap" else a[1:3] / k)
    est = np.array(estimates)
    if est.shape[0] < 2:
        return float("nan")
    n = est.shape[0]
    return float(np.sqrt(np.sum(np.mean(est**2, axis=0)) / n
                         + np.sum(np.var(est, axis=0, ddof=1)) / n))


def surface_flux(pressure: NDArray, velocity: NDArray, weights: NDArray) -> NDArray:
    """Power leaving each surface node, ½ Re(p v*) dS, summed over frequencies (W).

    Parameters
    ----------
    pressure, velocity : ndarray, complex, shape (n, nf)
        Pa and m/s (per frequency bin: Pa·s, m/s·s, then the sum is a spectral density).
    weights : ndarray, shape (n,)
        Areas dS in m².

    Returns
    -------
    ndarray, shape (n,)
    """
    return 0.5 * np.sum(np.real(pressure * np.conj(velocity)), axis=1) * weights


@dataclass(frozen=True)
class Uniformity:
    """Uniformity figures of the reconstructed velocity inside the aperture.

    Attributes
    ----------
    fraction_above : float
        Fraction of the aperture area whose amplitude is above ``uniformity_db`` relative
        to the median amplitude.
    median_velocity : float
        Median amplitude inside the aperture, m/s.
    hot_spots, dead_regions, phase_defects : list of dict
        Connected regions: ``centre`` (scan coordinates, m), ``unrolled`` (u, v) position on
        the unrolled map (m), ``azimuth_deg`` (from e1 towards e2), ``area`` (m²),
        ``extreme`` (amplitude ratio to the median, or phase departure in rad, of the most
        extreme node).
    """

    fraction_above: float
    median_velocity: float
    hot_spots: list[dict]
    dead_regions: list[dict]
    phase_defects: list[dict]


def _regions(flag_map: NDArray[np.bool_], surf: UnrolledSurface, values: NDArray,
             min_area: float) -> list[dict]:
    """Connected regions of ``flag_map`` (unrolled grid) larger than ``min_area`` (m²)."""
    labels, count = ndimage.label(flag_map)
    node = np.full(surf.mask.shape, -1)
    node[surf.mask] = np.arange(surf.surface.size)
    uu, vv = np.meshgrid(surf.u, surf.v, indexing="ij")
    out = []
    for label in range(1, count + 1):
        sel = labels == label
        idx = node[sel]
        idx = idx[idx >= 0]
        area = float(np.sum(surf.surface.weights[idx]))
        if idx.size == 0 or area < min_area:
            continue
        u_c, v_c = float(np.mean(uu[sel])), float(np.mean(vv[sel]))
        vals = values[idx]
        out.append({"centre": surf.surface.points[idx].mean(axis=0).tolist(),
                    "unrolled": [u_c, v_c],
                    "azimuth_deg": float(np.degrees(np.arctan2(v_c, u_c))),
                    "area": area,
                    "extreme": float(vals[np.argmax(np.abs(vals))])})
    return out


def uniformity(reconstruction: SourceReconstruction, cfg: HologramConfig | None = None
               ) -> Uniformity:
    """Fraction above −6 dB, hot spots, dead regions and phase defects (first frequency)."""
    cfg = cfg or HologramConfig()
    rec = reconstruction
    surf, inside = rec.unrolled, rec.inside
    vel = rec.velocity[:, 0]
    amp = np.abs(vel)
    median = float(np.median(amp[inside]))
    ratio = amp / median
    w = surf.surface.weights
    level = 10 ** (cfg.uniformity_db / 20)
    fraction = float(np.sum(w[inside & (ratio >= level)]) / np.sum(w[inside]))
    ref = np.sum(vel[inside] * amp[inside])
    phase = np.angle(vel * np.conj(ref))
    step = surf.u[1] - surf.u[0]
    wavelength = step / cfg.surface_step_wavelengths
    min_area = cfg.min_region_area_wavelengths * wavelength**2
    inside_map = surf.to_map(inside, fill=False).astype(bool)

    def flagged(condition: NDArray[np.bool_]) -> NDArray[np.bool_]:
        return inside_map & surf.to_map(condition, fill=False).astype(bool)

    hot = _regions(flagged(ratio > cfg.hot_spot_ratio), surf, ratio, min_area)
    dead = _regions(flagged(ratio < cfg.dead_ratio), surf, ratio, min_area)
    defects = _regions(flagged((np.abs(phase) > cfg.phase_defect_rad)
                               & (ratio >= cfg.dead_ratio)), surf, phase, min_area)
    return Uniformity(fraction, median, hot, dead, defects)
