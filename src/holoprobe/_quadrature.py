"""Quadrature of source surfaces: points, unit normals, area weights, segment labels.

The builders behind the :class:`holoprobe.geometry.Surface` factories. Each returns
plain arrays ``(points (n, 3), normals (n, 3), weights (n,), element (n,))`` in the
source's own coordinates: the apex (the centre of the radiating face) at the origin,
the acoustic axis along +z, normals pointing into the medium (towards the centre of
curvature for a bowl).

A cell is a rectangle in a parameter plane (u, v) mapped onto the surface, with the
area element ``J(u, v) du dv``. The weight of a cell is the integral of J over the
part of the cell inside the aperture (an "inside" predicate: rim, central opening,
kerfs between segments), computed with s × s midpoint sub-samples; cells that the
predicate cuts are refined with a finer sub-sampling so that the area converges
without a staircase error. The quadrature point is the J-weighted centroid of the
inside sub-samples, mapped back onto the surface.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

__all__ = ["cap_cells", "cap_point", "linear_array_cells", "mesh_cells", "rectangle_cells"]

_COARSE = 4   # sub-samples per cell side to find the cells the aperture's border cuts
_FINE = 24    # sub-samples per cell side in those cells

Arrays = tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64],
               NDArray[np.int64]]


def cap_point(rho: NDArray, phi: NDArray, roc: float | None) -> tuple[NDArray, NDArray]:
    """Points and normals of a bowl (or, ``roc=None``, a plane) at projected (ρ, φ)."""
    x, y = rho * np.cos(phi), rho * np.sin(phi)
    if roc is None:
        z = np.zeros_like(rho)
        n = np.stack([np.zeros_like(rho), np.zeros_like(rho), np.ones_like(rho)], axis=-1)
    else:
        z = roc - np.sqrt(np.maximum(roc * roc - rho * rho, 0.0))
        n = np.stack([-x, -y, roc - z], axis=-1) / roc
    return np.stack([x, y, z], axis=-1), n


def _integrate_cells(u0: NDArray, v0: NDArray, du: NDArray, dv: NDArray,
                     jac: Callable[[NDArray, NDArray], NDArray],
                     inside: Callable[[NDArray, NDArray], NDArray], s: int
                     ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Weights, centroids (u, v) and 'fully inside' flags of cells by s × s midpoints."""
    t = (np.arange(s) + 0.5) / s
    uu = u0[:, None, None] + du[:, None, None] * t[None, :, None]
    vv = v0[:, None, None] + dv[:, None, None] * t[None, None, :]
    uu, vv = np.broadcast_arrays(uu, vv)
    ok = inside(uu, vv)
    w = np.where(ok, jac(uu, vv), 0.0) * (du * dv / (s * s))[:, None, None]
    total = w.sum(axis=(1, 2))
    safe = np.where(total > 0, total, 1.0)
    uc = (w * uu).sum(axis=(1, 2)) / safe
    vc = (w * vv).sum(axis=(1, 2)) / safe
    return total, uc, vc, np.asarray(ok.all(axis=(1, 2)))


def _classify(u0: NDArray, v0: NDArray, du: NDArray, dv: NDArray,
              inside: Callable[[NDArray, NDArray], NDArray], s: int) -> tuple[NDArray, NDArray]:
    """(all inside, all outside) per cell from a closed (s+1) × (s+1) grid incl. its edges."""
    t = np.arange(s + 1) / s
    uu = u0[:, None, None] + du[:, None, None] * t[None, :, None]
    vv = v0[:, None, None] + dv[:, None, None] * t[None, None, :]
    uu, vv = np.broadcast_arrays(uu, vv)
    ok = inside(uu, vv)
    return np.asarray(ok.all(axis=(1, 2))), np.asarray(~ok.any(axis=(1, 2)))


def integrate_cells(u0: NDArray, v0: NDArray, du: NDArray, dv: NDArray,
                    jac: Callable[[NDArray, NDArray], NDArray],
                    inside: Callable[[NDArray, NDArray], NDArray]
                    ) -> tuple[NDArray, NDArray, NDArray]:
    """Cell weights and J-weighted centroids; cut cells are refined (see module notes).

    Cells are classified on a closed grid of sub-samples that includes their edges
    (a border that cuts a cell between two such samples leaves a sliver of relative
    area ~(h/s)²/(8 r_border), negligible); cells entirely inside are integrated with
    the coarse midpoints, cut cells with the fine ones, cells entirely outside dropped.
    """
    u0, v0, du, dv = (np.broadcast_to(np.asarray(a, float), np.shape(u0)).ravel().copy()
                      for a in (u0, v0, du, dv))
    full, empty = _classify(u0, v0, du, dv, inside, _COARSE)
    w = np.zeros(u0.size)
    uc, vc = np.zeros(u0.size), np.zeros(u0.size)
    for mask, s in ((full, _COARSE), (~full & ~empty, _FINE)):
        idx = np.flatnonzero(mask)
        step = max(1, (1 << 21) // (s * s))
        for start in range(0, idx.size, step):
            sel = idx[start:start + step]
            w[sel], uc[sel], vc[sel], _ = _integrate_cells(
                u0[sel], v0[sel], du[sel], dv[sel], jac, inside, s)
    keep = w > 0
    return w[keep], uc[keep], vc[keep]


def _segment_labels(rho: NDArray, phi: NDArray, edges: NDArray, sectors: int,
                    phi0: float) -> NDArray[np.int64]:
    ring = np.clip(np.searchsorted(edges, rho, side="right") - 1, 0, edges.size - 2)
    sector = np.floor(np.mod(phi - phi0, 2 * np.pi) / (2 * np.pi / sectors)).astype(np.int64)
    return (ring * sectors + np.clip(sector, 0, sectors - 1)).astype(np.int64)


def _cap_inside(roc: float | None, r_in: float, r_out: float, edges: NDArray, sectors: int,
                phi0: float, kerf: float) -> Callable[[NDArray, NDArray, NDArray], NDArray]:
    """Predicate on projected (x, y, ρ): within the annulus and outside every kerf."""
    half = 0.5 * kerf
    inner_edges = edges[1:-1]
    angles = phi0 + 2 * np.pi * np.arange(sectors) / sectors

    def inside(x: NDArray, y: NDArray, rho: NDArray) -> NDArray:
        ok = (rho >= r_in) & (rho <= r_out)
        if half > 0:
            for e in inner_edges:
                ok &= np.abs(rho - e) >= half
            if sectors > 1:
                for a in angles:
                    along = x * np.cos(a) + y * np.sin(a)
                    across = -x * np.sin(a) + y * np.cos(a)
                    ok &= (along < 0) | (np.abs(across) >= half)
        return ok
    return inside


def cap_cells(aperture_diameter: float, roc: float | None, spacing: float, *,
              opening_diameter: float = 0.0, rings: int = 1, sectors: int = 1,
              kerf: float = 0.0, phi0: float = 0.0, layout: str = "grid",
              order: int = 1, radial_edges: tuple[float, ...] = ()) -> Arrays:
    """Quadrature of a spherical cap (``roc``) or a flat disc (``roc=None``).

    Parameters
    ----------
    aperture_diameter, opening_diameter : float
        Outer and inner (central opening) diameters in m, projected on the plane
        normal to the axis.
    roc : float or None
        Radius of curvature in m (None: flat).
    spacing : float
        Largest distance between neighbouring points along the surface, in m.
    rings, sectors : int
        Segmentation: annuli of equal projected width between the opening and the
        rim, each split into equal sectors starting at angle ``phi0`` (rad).
        Element label = ring · sectors + sector.
    kerf : float
        Width in m of the inactive gaps between segments.
    layout : {"grid", "rings"}
        ``grid``: a Cartesian grid in projected (x, y) (images of the surface map
        directly onto it); ``rings``: rings of equal arc width split into sectors
        (exact cell areas, a different structure for synthesis without inverse crime).
    order : int
        ``rings`` only: Gauss–Legendre nodes across each ring (rings are then
        ``order`` × ``spacing`` wide, so the point density stays the same).
    radial_edges : tuple of float
        ``rings`` only: more projected radii (m) where ring borders must fall.
    """
    r_out, r_in = 0.5 * aperture_diameter, 0.5 * opening_diameter
    edges = np.linspace(r_in, r_out, rings + 1)
    inside_xy = _cap_inside(roc, r_in, r_out, edges, sectors, phi0, kerf)
    if layout == "grid":
        cos_max = 1.0 if roc is None else math.sqrt(1.0 - (r_out / roc) ** 2)
        n = max(1, math.ceil(2 * r_out / (spacing * cos_max)))
        h = 2 * r_out / n
        c = -r_out + h * np.arange(n)
        u0, v0 = np.meshgrid(c, c, indexing="ij")

        def jac(x: NDArray, y: NDArray) -> NDArray:
            if roc is None:
                return np.ones_like(x)
            return roc / np.sqrt(np.maximum(roc * roc - x * x - y * y, 1e-300))

        w, xc, yc = integrate_cells(u0, v0, np.full(u0.shape, h), np.full(u0.shape, h), jac,
                                    lambda x, y: inside_xy(x, y, np.hypot(x, y)))
        rho, phi = np.hypot(xc, yc), np.arctan2(yc, xc)
    elif layout == "rings":
        extra = [r for r in radial_edges if r_in < r < r_out]
        w, rho, phi = _ring_cells(r_in, r_out, roc, spacing, sectors, phi0, inside_xy,
                                  np.unique(np.r_[edges, extra]), kerf, order)
    else:  # pragma: no cover - validated by the caller
        raise ValueError(layout)
    pts, nrm = cap_point(rho, phi, roc)
    return pts, nrm, w, _segment_labels(rho, phi, edges, sectors, phi0)


def _ring_bounds(a0: float, a1: float, n_min: int, edges: NDArray) -> NDArray:
    """Ring boundaries in [a0, a1] that include every segment edge, ≥ n_min rings."""
    out = [a0]
    width = (a1 - a0) / n_min
    for lo, hi in itertools.pairwise(edges):
        n = max(1, math.ceil((hi - lo) / width - 1e-9))
        out.extend(np.linspace(lo, hi, n + 1)[1:])
    return np.asarray(out)


def _ring_cells(r_in: float, r_out: float, roc: float | None, spacing: float, sectors: int,
                phi0: float, inside_xy: Callable, edges: NDArray, kerf: float,
                order: int) -> tuple[NDArray, NDArray, NDArray]:
    """Ring/sector cells in (θ, φ) (bowl) or (ρ, φ) (flat); returns weights, ρ, φ.

    Without kerf the rings' borders fall on the rim, the opening and the segment
    edges, and each ring is integrated exactly in φ (uniform points on a periodic
    integrand) and with ``order`` Gauss–Legendre nodes across its width. With a kerf
    the cells are sub-sampled like the grid layout.
    """
    if roc is None:
        a0, a1, a_edges = r_in, r_out, edges

        def radius(a: NDArray) -> NDArray:
            return a

        def jac(a: NDArray, p: NDArray) -> NDArray:
            return a
    else:
        a0, a1 = math.asin(r_in / roc), math.asin(r_out / roc)
        a_edges = np.arcsin(np.clip(edges / roc, 0.0, 1.0))

        def radius(a: NDArray) -> NDArray:
            return roc * np.sin(a)

        def jac(a: NDArray, p: NDArray) -> NDArray:
            return roc * roc * np.sin(a)
    arc = (a1 - a0) * (1.0 if roc is None else roc)
    bounds = _ring_bounds(a0, a1, max(1, math.ceil(arc / (spacing * order))), a_edges)
    if kerf > 0:
        order = 1
    nodes, gw = np.polynomial.legendre.leggauss(order)
    u0, v0, du, dv, wts = [], [], [], [], []
    for lo, hi in itertools.pairwise(bounds):
        circumference = 2 * np.pi * float(radius(np.asarray(hi)))
        n_phi = sectors * max(1, math.ceil(circumference / spacing / sectors))
        d = 2 * np.pi / n_phi
        for x, g in zip(nodes, gw, strict=True):
            a = 0.5 * (lo + hi) + 0.5 * (hi - lo) * x
            u0.append(np.full(n_phi, a))
            du.append(np.full(n_phi, hi - lo))
            v0.append(phi0 + d * (np.arange(n_phi) + 0.5))
            dv.append(np.full(n_phi, d))
            area = float(jac(np.asarray(a), np.zeros(())))
            wts.append(np.full(n_phi, 0.5 * g * (hi - lo) * d * area))
    if kerf == 0:
        return np.concatenate(wts), radius(np.concatenate(u0)), np.concatenate(v0)

    def inside(a: NDArray, p: NDArray) -> NDArray:
        r = radius(a)
        return inside_xy(r * np.cos(p), r * np.sin(p), r)

    w, ac, pc = integrate_cells(np.concatenate(u0) - 0.5 * np.concatenate(du),
                                np.concatenate(v0) - 0.5 * np.concatenate(dv),
                                np.concatenate(du), np.concatenate(dv), jac, inside)
    return w, radius(ac), pc


def rectangle_cells(width: float, height: float, spacing: float) -> Arrays:
    """Midpoint grid of a flat rectangle width (x) × height (y) centred on the origin."""
    nx = max(1, math.ceil(width / spacing - 1e-9))
    ny = max(1, math.ceil(height / spacing - 1e-9))
    dx, dy = width / nx, height / ny
    x = (np.arange(nx) + 0.5) * dx - 0.5 * width
    y = (np.arange(ny) + 0.5) * dy - 0.5 * height
    xx, yy = np.meshgrid(x, y, indexing="ij")
    pts = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], axis=-1)
    nrm = np.broadcast_to([0.0, 0.0, 1.0], pts.shape).copy()
    return pts, nrm, np.full(xx.size, dx * dy), np.zeros(xx.size, np.int64)


def linear_array_cells(count: int, pitch: float, width: float, height: float,
                       spacing: float) -> Arrays:
    """Midpoint grids of the elements of a flat 1-D array (element-major order)."""
    pts, nrm, w, _ = rectangle_cells(width, height, spacing)
    centers = (np.arange(count) - (count - 1) / 2) * pitch
    allp = (pts[None, :, :] + np.stack([centers, 0 * centers, 0 * centers], -1)[:, None, :])
    n = pts.shape[0]
    return (allp.reshape(-1, 3), np.tile(nrm, (count, 1)), np.tile(w, count),
            np.repeat(np.arange(count, dtype=np.int64), n))


def mesh_cells(vertices: NDArray, faces: NDArray, spacing: float | None) -> Arrays:
    """Centroids, normals and areas of a triangle mesh, subdivided to ``spacing``.

    Normals follow the vertex order (right-hand rule: (v1 − v0) × (v2 − v0)).
    Each triangle is split into m² congruent sub-triangles, m = ceil(longest edge /
    spacing), so the area is exact and the points are the sub-triangle centroids.
    """
    tri = vertices[faces]                                   # (nt, 3, 3)
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    cross = np.cross(e1, e2)
    area = 0.5 * np.linalg.norm(cross, axis=1)
    normal = cross / np.where(area > 0, 2 * area, 1.0)[:, None]
    longest = np.max(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2), axis=1)
    m = np.ones(len(faces), np.int64) if spacing is None else \
        np.maximum(1, np.ceil(longest / spacing - 1e-9)).astype(np.int64)
    pts, nrm, wts, lab = [], [], [], []
    for mm in np.unique(m):
        sel = np.flatnonzero(m == mm)
        bary = _subtriangle_centroids(int(mm))              # (mm², 2)
        p = (tri[sel, 0][:, None, :] + bary[None, :, 0:1] * e1[sel][:, None, :]
             + bary[None, :, 1:2] * e2[sel][:, None, :])
        pts.append(p.reshape(-1, 3))
        nrm.append(np.repeat(normal[sel], mm * mm, axis=0))
        wts.append(np.repeat(area[sel] / (mm * mm), mm * mm))
        lab.append(np.repeat(sel, mm * mm))
    order = np.argsort(np.concatenate(lab), kind="stable")
    return (np.concatenate(pts)[order], np.concatenate(nrm)[order],
            np.concatenate(wts)[order], np.concatenate(lab)[order].astype(np.int64))


def _subtriangle_centroids(m: int) -> NDArray[np.float64]:
    """Barycentric (s, t) centroids of the m² sub-triangles of the unit triangle."""
    out = []
    for i in range(m):
        for j in range(m - i):
            out.append(((i + 1 / 3) / m, (j + 1 / 3) / m))          # upright
            if j < m - i - 1:
                out.append(((i + 2 / 3) / m, (j + 2 / 3) / m))      # inverted
    return np.asarray(out)
