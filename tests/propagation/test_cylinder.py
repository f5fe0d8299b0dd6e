"""project_cylinder (the cylinder's symmetry) against the 3-D type-3 projection."""

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose, Surface
from holoprobe.propagation import ProjectionPlan, project_cylinder

RADIUS = 4e-3


def _surface(s, y):
    ss, yy = np.meshgrid(s / RADIUS, y, indexing="ij")
    sn, cs = np.sin(ss.ravel()), np.cos(ss.ravel())
    pts = np.stack([RADIUS * sn, yy.ravel(), RADIUS * (cs - 1.0)], axis=-1)
    return Surface(pts, np.stack([sn, np.zeros_like(sn), cs], axis=-1), np.ones(sn.size))


def _point_sources(scan: PlaneGrid, pose: Pose, freqs, medium):
    """Pressure on the scan of monopoles on the cylinder (a field that decays off axis)."""
    pts = pose.to_global(scan.points())
    ang = np.linspace(-0.6, 0.6, 5)
    src = np.stack([RADIUS * np.sin(ang), 0.3e-3 * np.cos(3 * ang),
                    RADIUS * (np.cos(ang) - 1)], -1)
    d = np.linalg.norm(pts[:, None, :] - src[None], axis=-1)[..., None]
    k = 2 * np.pi * freqs / medium.sound_speed
    return np.sum(np.exp(1j * k * d) / d, axis=1).reshape(*scan.shape, -1)


@pytest.mark.parametrize("quantity", ["pressure", "normal_velocity"])
def test_a_plane_along_the_axis_gives_the_type3_numbers(quantity):
    """Scan plane turned about the axis only: the lattices coincide, so both transforms
    sum the same waves (random data: every wave as strong as any)."""
    rng = np.random.default_rng(3)
    scan = PlaneGrid.centered(32, 14, 0.2e-3, 0.2e-3)
    f = np.array([2.5e6, 3.5e6])
    data = rng.standard_normal((32, 14, 2)) + 1j * rng.standard_normal((32, 14, 2))
    pose = Pose.from_degrees(0.0, -3.0, 0.0, (0.2e-3, 0.1e-3, 3e-3))
    plan = ProjectionPlan(data, scan, f, eps=1e-9, guard_angle=np.radians(45)).with_pose(pose)
    s, y = np.arange(-30, 31) * 0.15e-3, np.arange(-12, 13) * 0.2e-3
    ref = plan.project(_surface(s, y), quantity=quantity).reshape(s.size, y.size, -1)
    got = project_cylinder(plan, RADIUS, s, y, quantity=quantity)
    assert np.abs(got - ref).max() < 1e-6 * np.abs(ref).max()


def test_the_plans_image_taper_applies_on_the_cylinder_too():
    """A plan with ``image_taper`` fades its steep waves out in ``project``; the
    cylinder's path ignored it (session 9: the convex receive's two prediction paths
    then differed by 1.1 % of the peak). Now both sum the same tapered waves."""
    rng = np.random.default_rng(4)
    scan = PlaneGrid.centered(32, 14, 0.2e-3, 0.2e-3)
    f = np.array([2.5e6, 3.5e6])
    data = rng.standard_normal((32, 14, 2)) + 1j * rng.standard_normal((32, 14, 2))
    pose = Pose.from_degrees(0.0, -3.0, 0.0, (0.2e-3, 0.1e-3, 3e-3))
    s, y = np.arange(-10, 11) * 0.15e-3, np.arange(-6, 7) * 0.2e-3
    out = {}
    for taper in (False, True):
        plan = ProjectionPlan(data, scan, f, eps=1e-9, guard_angle=np.radians(45),
                              image_taper=taper).with_pose(pose)
        ref = plan.project(_surface(s, y), quantity="normal_velocity")
        got = project_cylinder(plan, RADIUS, s, y)
        assert np.abs(got.reshape(ref.shape) - ref).max() < 1e-6 * np.abs(ref).max()
        out[taper] = got
    # s_in 0.88, s_out 0.90 here: the taper removes a visible part of random data
    assert plan.taper_range(_surface(s, y), plan.padded_shape(_surface(s, y))) is not None
    assert np.abs(out[True] - out[False]).max() > 1e-2 * np.abs(out[False]).max()


def test_a_tilted_turned_scan_gives_the_type3_numbers_up_to_the_padding_images():
    """Scan tilted about x and turned about its normal: the wave lattice along the axis
    is not the scan's, so the two sums repeat the data along different axes; they agree
    up to those images, which fade as the padding grows (guard angle 60° → 80°: max
    difference 1.5e-3 → 1.9e-4 of the peak, 1.5e-5 at 87°), not by a tilt bias."""
    medium = Medium()
    scan = PlaneGrid.centered(64, 40, 0.15e-3, 0.15e-3)
    f = np.array([2.5e6, 4.0e6])
    pose = Pose.from_degrees(0.4, -2.0, 0.9, (0.1e-3, -0.1e-3, 3e-3))
    data = _point_sources(scan, pose, f, medium)
    s, y = np.arange(-20, 21) * 0.15e-3, np.arange(-15, 16) * 0.15e-3
    errors = []
    for guard in (60, 80):
        plan = ProjectionPlan(data, scan, f, medium, eps=1e-9,
                              guard_angle=np.radians(guard)).with_pose(pose)
        ref = plan.project(_surface(s, y), quantity="normal_velocity")
        got = project_cylinder(plan, RADIUS, s, y)
        errors.append(np.abs(got.reshape(ref.shape) - ref).max() / np.abs(ref).max())
    assert errors[0] < 3e-3
    assert errors[1] < 5e-4


def test_bad_radius_or_arc_is_refused():
    scan = PlaneGrid.centered(8, 8, 0.2e-3, 0.2e-3, pose=Pose(origin=(0.0, 0.0, 2e-3)))
    plan = ProjectionPlan(np.ones((8, 8, 1)), scan, [1e6])
    with pytest.raises(InputError, match="radius"):
        project_cylinder(plan, -1.0, [0.0], [0.0])
    with pytest.raises(InputError, match="πR/2"):
        project_cylinder(plan, 1e-3, [2e-3], [0.0])
