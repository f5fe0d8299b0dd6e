"""Source surfaces: quadrature areas vs closed forms, normals, on-axis fields vs analytic."""

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose, SourceGeometry, Surface
from holoprobe.propagation import rayleigh_integral

MEDIUM = Medium()
F = 1.0e6
LAM = MEDIUM.sound_speed / F
K = 2 * np.pi / LAM


def _cap_area(aperture, roc, opening=0.0):
    def sag(d):
        return roc - np.sqrt(roc**2 - (d / 2) ** 2)
    return 2 * np.pi * roc * (sag(aperture) - sag(opening))


@pytest.mark.parametrize("layout", ["grid", "rings"])
@pytest.mark.parametrize("opening", [0.0, 12e-3])
def test_cap_area_converges_to_2_pi_r_h(layout, opening):
    s = Surface.spherical_cap(40e-3, 40e-3, spacing=0.5e-3, opening_diameter=opening,
                              layout=layout)
    assert s.area == pytest.approx(_cap_area(40e-3, 40e-3, opening), rel=1e-4)


@pytest.mark.parametrize("layout", ["grid", "rings"])
def test_disc_and_rectangle_areas(layout):
    assert Surface.disc(30e-3, spacing=0.4e-3, layout=layout).area == pytest.approx(
        np.pi * 15e-3**2, rel=1e-4)
    assert Surface.rectangle(20e-3, 7e-3, spacing=0.3e-3).area == pytest.approx(140e-6,
                                                                                 rel=1e-12)


def test_cap_points_lie_on_the_sphere_with_normals_towards_the_centre():
    roc = 40e-3
    s = Surface.spherical_cap(40e-3, roc, spacing=1e-3, layout="rings", order=2)
    centre = np.array([0.0, 0.0, roc])
    assert np.allclose(np.linalg.norm(s.points - centre, axis=1), roc, atol=1e-12)
    assert np.allclose(s.normals, (centre - s.points) / roc, atol=1e-12)
    assert np.all(np.hypot(s.points[:, 0], s.points[:, 1]) <= 20e-3 + 1e-12)


def test_segmented_bowl_labels_split_area_evenly_and_kerf_removes_strips():
    roc, ap = 40e-3, 40e-3
    s = Surface.spherical_cap(ap, roc, spacing=0.5e-3, sectors=6, layout="rings")
    areas = np.bincount(s.element, weights=s.weights)
    assert areas.size == 6
    assert np.allclose(areas, _cap_area(ap, roc) / 6, rtol=1e-9)
    kerf = 1e-3
    g = Surface.spherical_cap(ap, roc, spacing=0.5e-3, sectors=6, kerf=kerf)
    # six radial strips of width kerf and length ~a (projected), stretched by the slope
    lost = _cap_area(ap, roc) - g.area
    assert lost == pytest.approx(6 * kerf * 20e-3, rel=0.05)
    a2 = Surface.spherical_cap(ap, roc, spacing=0.5e-3, rings=2, sectors=4, layout="rings")
    assert set(np.unique(a2.element)) == set(range(8))
    r = np.hypot(a2.points[:, 0], a2.points[:, 1])
    assert np.all((r < 10e-3) == (a2.element < 4))


def test_linear_array_and_mesh():
    arr = Surface.linear_array(8, 0.3e-3, 0.25e-3, 5e-3, spacing=0.1e-3)
    assert arr.area == pytest.approx(8 * 0.25e-3 * 5e-3, rel=1e-12)
    assert np.allclose(np.bincount(arr.element, weights=arr.points[:, 0]) /
                       np.bincount(arr.element), (np.arange(8) - 3.5) * 0.3e-3)
    # a unit square as two triangles, facing +z, subdivided
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float) * 1e-3
    m = Surface.from_mesh(v, [[0, 1, 2], [0, 2, 3]], spacing=0.2e-3)
    assert m.area == pytest.approx(1e-6, rel=1e-12)
    assert np.allclose(m.normals, [0, 0, 1])
    assert np.allclose(np.average(m.points, axis=0, weights=m.weights), [0.5e-3, 0.5e-3, 0])
    with pytest.raises(InputError, match="faces"):
        Surface.from_mesh(v, [[0, 1, 7]])


def test_moved_surface_rotates_normals_and_keeps_weights():
    s = Surface.disc(10e-3, spacing=1e-3)
    pose = Pose.from_degrees(0.0, 30.0, 0.0, origin=(1e-3, 0.0, -5e-3))
    m = s.moved(pose)
    assert np.allclose(m.normals, pose.normal)
    assert np.allclose(m.points.mean(axis=0), pose.to_global(s.points).mean(axis=0))
    assert m.area == s.area


def _on_axis(surface, z):
    tgt = Surface(np.stack([0 * z, 0 * z, z], -1), np.tile([0, 0, 1.0], (z.size, 1)),
                  np.ones(z.size))
    return rayleigh_integral(np.ones(surface.size), surface, tgt, [F], MEDIUM,
                             kernel="fwd_vp")[:, 0]


def test_bowl_on_axis_field_matches_oneil_within_half_a_percent():
    roc, a = 40e-3, 20e-3
    h = roc - np.sqrt(roc**2 - a**2)
    z = np.array([10e-3, 20e-3, 30e-3, 38e-3, 45e-3, 60e-3, 80e-3])
    # O'Neil (1949): p = ρc u0 / (1 − z/R) · (e^{ikz} − e^{ik r_e}), r_e to the rim
    exact = MEDIUM.impedance / (1 - z / roc) * (
        np.exp(1j * K * z) - np.exp(1j * K * np.sqrt((z - h) ** 2 + a**2)))
    p = _on_axis(Surface.spherical_cap(2 * a, roc, spacing=LAM / 4, layout="rings", order=3), z)
    assert np.max(np.abs(p / exact - 1)) < 5e-3
    # the midpoint grid (the estimator's layout) converges as (k h)²: λ/16 beyond 20 mm
    p = _on_axis(Surface.spherical_cap(2 * a, roc, spacing=LAM / 16), z[1:])
    assert np.max(np.abs(p / exact[1:] - 1)) < 5e-3


def test_disc_on_axis_field_matches_the_piston_formula_within_half_a_percent():
    a = 20e-3
    z = np.array([10e-3, 20e-3, 40e-3, 80e-3, 150e-3])
    exact = MEDIUM.impedance * (np.exp(1j * K * z) - np.exp(1j * K * np.sqrt(z * z + a * a)))
    p = _on_axis(Surface.disc(2 * a, spacing=LAM / 4, layout="rings", order=3), z)
    assert np.max(np.abs(p / exact - 1)) < 5e-3


def test_bad_source_descriptions_are_one_clear_line():
    with pytest.raises(InputError, match="exceeds twice the radius"):
        Surface.spherical_cap(90e-3, 40e-3, spacing=1e-3)
    with pytest.raises(InputError, match="opening"):
        Surface.spherical_cap(40e-3, 40e-3, spacing=1e-3, opening_diameter=50e-3)
    with pytest.raises(InputError, match="radius of curvature"):
        SourceGeometry("spherical-cap", 40e-3, 40e-3)
    with pytest.raises(InputError, match="aperture_min"):
        SourceGeometry("flat-rectangle", 30e-3, 20e-3)
    g = SourceGeometry("spherical-cap", 40e-3, 40e-3, 40e-3)
    assert g.rim_depth == pytest.approx(40e-3 - np.sqrt(40e-3**2 - 20e-3**2))
    assert g.surface(1e-3).area == pytest.approx(_cap_area(40e-3, 40e-3), rel=1e-4)
    assert SourceGeometry("flat-rectangle", 10e-3, 20e-3).surface(1e-3).area == \
        pytest.approx(200e-6)


def test_plane_grid_corners_are_its_extreme_points_in_every_frame():
    grid = PlaneGrid(np.linspace(-3e-3, 5e-3, 7), np.linspace(1e-3, 2e-3, 4),
                     Pose.from_degrees(10.0, -25.0, 40.0, (1e-3, -2e-3, 30e-3)))
    points, corners = grid.points(), grid.corners()
    np.testing.assert_allclose(corners, points[[0, 3, 24, 27]], atol=1e-15)
    for frame in (np.eye(3), Pose.from_degrees(3.0, 50.0, -7.0, (0, 0, 0)).rotation):
        np.testing.assert_allclose(np.sort((corners @ frame)[:, 2])[[0, -1]],
                                   [(points @ frame)[:, 2].min(), (points @ frame)[:, 2].max()])
