"""ArrayGeometry: the shared element layout of linear, convex and matrix arrays."""

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.geometry import ArrayGeometry, Pose


def test_convex_centres_normals_and_faces_lie_on_the_cylinder():
    r, pitch, w, h = 0.0496, 0.508e-3, 0.45e-3, 13.5e-3
    geo = ArrayGeometry.convex(9, pitch, r, w, h)
    centre = np.array([0.0, 0.0, -r])
    # element centres: radius R, consecutive arc length = pitch (chord 2R sin(p/2R))
    assert np.allclose(np.linalg.norm(geo.positions - centre, axis=1), r, rtol=1e-12)
    chord = np.linalg.norm(np.diff(geo.positions, axis=0), axis=1)
    assert np.allclose(chord, 2 * r * np.sin(pitch / (2 * r)), rtol=1e-12)
    assert np.allclose(geo.positions[4], 0.0, atol=1e-15)  # the apex
    assert np.allclose(geo.element_angles, (np.arange(9) - 4) * pitch / r)
    for layout in ("grid", "gauss"):
        surf = geo.surface(0.1e-3, layout=layout)
        rel = surf.points - centre
        rho = np.hypot(rel[:, 0], rel[:, 2])
        assert np.allclose(rho, r, rtol=1e-12)
        assert np.allclose(surf.normals[:, [0, 2]], rel[:, [0, 2]] / rho[:, None])
        # exact area of each element (the cylinder is developable)
        area = np.bincount(surf.element, surf.weights)
        assert np.allclose(area, w * h, rtol=1e-12)
        # each element spans exactly its arc: angle extent w/R about its centre
        ang = np.arctan2(rel[:, 0], rel[:, 2])
        first = ang[surf.element == 0] - geo.element_angles[0]
        assert np.all(np.abs(first) < 0.5 * w / r)
        assert np.all(np.abs(surf.points[:, 1]) < h / 2)


def test_gauss_and_grid_converge_to_the_exact_element_integral():
    # ∫ exp(ik x) dS over each curved element = H ∫ exp(ik R sin φ) R dφ (scipy quad)
    from scipy.integrate import quad

    r, w, h = 0.02, 0.9e-3, 4e-3
    geo = ArrayGeometry.convex(3, 1e-3, r, w, h)
    k = 2 * np.pi / 0.4e-3
    exact = 0.0j
    for phi0 in geo.element_angles:
        lo, hi = phi0 - 0.5 * w / r, phi0 + 0.5 * w / r
        exact += h * r * (quad(lambda p: np.cos(k * r * np.sin(p)), lo, hi, epsrel=1e-12)[0]
                          + 1j * quad(lambda p: np.sin(k * r * np.sin(p)), lo, hi,
                                      epsrel=1e-12)[0])
    area = 3 * w * h
    for layout, spacing, tol in (("gauss", 0.05e-3, 1e-5), ("grid", 0.01e-3, 3e-4)):
        s = geo.surface(spacing, layout=layout)
        val = np.sum(s.weights * np.exp(1j * k * s.points[:, 0]))
        assert abs(val - exact) < tol * area, layout


def test_matrix_indexing_and_sparse_grid():
    geo = ArrayGeometry.matrix(4, 3, 0.3e-3, 0.4e-3)
    assert geo.count == 12 and geo.grid_shape == (4, 3)
    e = 1 * 4 + 2  # iy=1, ix=2
    assert np.allclose(geo.positions[e], [(2 - 1.5) * 0.3e-3, 0.0, 0.0])
    assert tuple(geo.grid_position[e]) == (2, 1)
    mask = np.ones((3, 4), bool)
    mask[0, 0] = False
    sparse = ArrayGeometry.matrix(4, 3, 0.3e-3, 0.4e-3, active=mask)
    assert sparse.count == 11 and tuple(sparse.grid_position[0]) == (1, 0)
    assert np.isclose(sparse.surface(0.1e-3).area, 11 * 0.3e-3 * 0.4e-3)


def test_moved_keeps_shape_and_rejects_bad_input():
    geo = ArrayGeometry.convex(5, 1e-3, 0.03, 0.8e-3, 5e-3)
    pose = Pose.from_degrees(3.0, -2.0, 10.0, (1e-3, 2e-3, 30e-3))
    moved = geo.moved(pose)
    assert np.allclose(moved.positions, pose.to_global(geo.positions))
    assert np.allclose(np.linalg.norm(np.diff(moved.positions, axis=0), axis=1),
                       np.linalg.norm(np.diff(geo.positions, axis=0), axis=1))
    s0, s1 = geo.surface(0.2e-3), moved.surface(0.2e-3)
    assert np.allclose(s1.points, pose.to_global(s0.points))
    with pytest.raises(InputError, match="radius_of_curvature"):
        ArrayGeometry.convex(5, 1e-3, -0.03, 0.8e-3, 5e-3)
    with pytest.raises(InputError, match="widths"):
        ArrayGeometry(geo.positions, geo.normals, geo.width_directions, -1.0, 1.0)
    lin = ArrayGeometry.linear(4, 1e-3, 0.8e-3, 5e-3)
    assert np.allclose(lin.positions[:, 0], [-1.5e-3, -0.5e-3, 0.5e-3, 1.5e-3])


def test_mirrored_array_is_the_reflection_of_every_face_point():
    geo = ArrayGeometry.convex(5, 1e-3, 0.01, 0.8e-3, 2e-3)
    p0, n = np.array([0.0, 0.0, 4e-3]), np.array([np.sin(0.05), 0.0, np.cos(0.05)])
    img = geo.mirrored(p0, n)
    pts = geo.surface(0.2e-3).points
    want = pts - 2 * ((pts - p0) @ n)[:, None] * n
    got = img.surface(0.2e-3).points
    assert np.allclose(got[np.lexsort(np.round(got.T, 12))],
                       want[np.lexsort(np.round(want.T, 12))])
    # the normals of the image face back towards the real array
    assert np.all(img.normals @ n < 0)
