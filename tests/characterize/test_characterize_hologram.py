"""Hologram characterization of single-element sources against twins with known truth.

The twins (tests/_hologram_twin.py) are dense Rayleigh sums from sources sampled on
Gauss-Legendre rings; the estimator uses plane-wave sums and an unrolled Cartesian surface
grid (no inverse crime). Truth that the twin does not hold (the focal maximum) is computed
independently with the dense Rayleigh sum at points around the estimate.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.special import j1

from _hologram_twin import make_twin
from holoprobe.characterize import (
    HologramConfig,
    characterize_hologram,
    hologram_power,
    hologram_summary,
    orthonormal_frame,
)
from holoprobe.geometry import Surface
from holoprobe.propagation import rayleigh_integral

CFG = HologramConfig(monte_carlo=0)


@pytest.fixture(scope="module")
def bowl():
    twin = make_twin()
    return twin, characterize_hologram(twin.hologram, CFG)


def _angle_deg(a, b) -> float:
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0))))


def _rayleigh_at(twin, points):
    target = Surface(points, np.tile([0.0, 0.0, 1.0], (len(points), 1)), np.ones(len(points)))
    return rayleigh_integral(twin.velocity[:, None], twin.surface, target,
                             [twin.hologram.frequency], twin.hologram.medium,
                             kernel="fwd_vp")[:, 0]


def test_axis_of_a_tilted_offset_bowl_within_0p02_degrees(bowl):
    twin, result = bowl
    assert _angle_deg(result.alignment.axis, twin.axis) < 0.02
    # the power-weighted direction of a uniform bowl is the same axis, less sharply
    assert _angle_deg(result.alignment.power_direction, twin.axis) < 0.1


def test_focal_maximum_matches_dense_rayleigh_field_within_20_um(bowl):
    twin, result = bowl
    focus, axis = result.alignment.focus, result.alignment.axis
    e1, e2 = orthonormal_frame(axis)
    h = 0.15e-3
    for direction in (e1, e2, axis):
        pts = focus + np.array([-h, 0.0, h])[:, None] * direction
        a = np.abs(_rayleigh_at(twin, pts)) ** 2
        vertex = h * (a[0] - a[2]) / (2 * (a[0] - 2 * a[1] + a[2]))
        assert abs(vertex) < 20e-6, vertex
    # the focal pressure is the dense sum's, in Pa
    p_true = abs(_rayleigh_at(twin, focus[None, :])[0])
    assert result.focal.focal_pressure == pytest.approx(p_true, rel=0.01)


def test_radius_aperture_and_apex_of_the_bowl(bowl):
    twin, result = bowl
    g = result.reconstruction.geometry
    assert g.radius_of_curvature == pytest.approx(twin.radius, rel=0.002)
    assert abs(g.aperture[0] - twin.aperture) < 0.2e-3
    assert np.linalg.norm(g.apex - twin.apex) < 20e-6


def test_hologram_and_surface_power_agree_within_1_percent(bowl):
    _, result = bowl
    assert result.power_surface == pytest.approx(result.power_hologram, rel=0.01)
    assert 0.97 < result.inside_aperture_fraction <= 1.0


def test_surface_velocity_inside_the_aperture_within_3_percent(bowl):
    twin, result = bowl
    rec = result.reconstruction
    lateral = rec.unrolled.radius[rec.unrolled.mask]
    wavelength = twin.hologram.medium.sound_speed / twin.hologram.frequency
    sel = lateral < twin.aperture / 2 - wavelength  # the band-limited edge excluded
    v = rec.velocity[sel, 0]
    ref = 0.1 * np.exp(1j * np.angle(np.mean(v)))
    assert np.linalg.norm(v - ref) / np.linalg.norm(np.full(v.size, 0.1)) < 0.03
    assert result.uniformity.median_velocity == pytest.approx(0.1, rel=0.01)
    assert result.uniformity.dead_regions == []


def test_summary_keys_in_scan_coordinates(bowl):
    _, result = bowl
    s = json.loads(json.dumps(hologram_summary(result)))
    assert len(s["alignment"]["axis_direction"]) == 3
    assert len(s["alignment"]["focus_position"]) == 3
    assert s["alignment"]["focus_position"][2] > 0  # in front of the plane, away from the source
    assert s["source"]["kind"] == "spherical-cap"
    assert s["source"]["radius_of_curvature"] == pytest.approx(0.04, rel=0.002)
    assert set(s["acoustic_power"]) >= {"hologram", "surface", "inside_aperture_fraction"}


def test_flat_disc_tilt_offset_and_power_match_the_analytic_piston():
    u0, a, f = 0.05, 6e-3, 1.5e6
    twin = make_twin(radius=None, aperture=2 * a, frequency=f, z_position=8e-3,
                     tilt=(-0.03, 0.02), offset=(0.8e-3, 0.5e-3), n=111, step=0.4e-3, u0=u0)
    result = characterize_hologram(twin.hologram, CFG)
    g = result.reconstruction.geometry
    assert result.alignment is None
    assert _angle_deg(g.axis, twin.axis) < 0.05
    assert np.linalg.norm((g.apex - twin.apex)[:2]) < 50e-6
    assert abs(g.aperture[0] - 2 * a) < 0.2e-3
    medium = twin.hologram.medium
    ka = 2 * np.pi * f / medium.sound_speed * a
    analytic = 0.5 * medium.impedance * u0**2 * np.pi * a**2 * (1 - j1(2 * ka) / ka)
    assert result.power_surface == pytest.approx(analytic, rel=0.01)
    assert result.power_hologram == pytest.approx(analytic, rel=0.01)
    # the exact keys for an unfocused source: focus null, radius null
    s = json.loads(json.dumps(hologram_summary(result)))
    assert s["alignment"]["focus_position"] is None and len(s["alignment"]["axis_direction"]) == 3
    assert np.degrees(np.arccos(np.dot(s["alignment"]["axis_direction"], twin.axis))) < 0.05
    assert s["source"]["kind"] == "flat-disc" and s["source"]["radius_of_curvature"] is None
    assert s["source"]["aperture_diameter"] == pytest.approx(2 * a, abs=0.2e-3)
    pw = s["acoustic_power"]
    assert (pw["hologram"], pw["surface"]) == (result.power_hologram, result.power_surface)
    assert 0.97 < pw["inside_aperture_fraction"] <= 1.0


def test_dead_sector_is_located():
    def velocity(local):
        phi = np.arctan2(local[:, 1], local[:, 0])
        dead = (phi > 0.3) & (phi < 1.2)
        return np.where(dead, 0.0, 0.1).astype(complex)

    twin = make_twin(velocity=velocity, tilt=(0.0, 0.0), offset=(0.0, 0.0))
    result = characterize_hologram(twin.hologram, CFG)
    dead = result.uniformity.dead_regions
    assert len(dead) == 1
    # the sector spans azimuths 0.3–1.2 rad about the source's own x axis (= scan x here)
    assert np.radians(dead[0]["azimuth_deg"]) == pytest.approx(0.75, abs=0.1)
    sector_area = 0.9 / 2 * (twin.aperture / 2) ** 2
    assert dead[0]["area"] == pytest.approx(sector_area, rel=0.25)


def test_hologram_power_is_parseval_for_a_normal_plane_wave():
    from holoprobe.geometry import Medium, PlaneGrid

    medium = Medium()
    grid = PlaneGrid.centered(64, 64, 0.3e-3)
    p = np.full(grid.shape, 1e5, complex)
    # a uniform field is one normal plane wave: W = |p|² A / (2ρc)
    area = 64 * 64 * 0.3e-3**2
    assert hologram_power(p, grid, 1e6, medium) == pytest.approx(
        1e10 * area / (2 * medium.impedance), rel=1e-12)


def test_flat_rectangle_tilt_offset_and_sides():
    from holoprobe.geometry import Medium, PlaneGrid, Pose, SourceGeometry, rotation_matrix
    from holoprobe.measurement import Hologram

    medium, f = Medium(), 1.5e6
    local = Surface.rectangle(12e-3, 8e-3, spacing=medium.sound_speed / f / 6)
    rot = rotation_matrix(0.02, -0.01, 0.0)
    apex = np.array([0.7e-3, -0.4e-3, 0.0]) - 8e-3 * rot[:, 2]
    src = Surface(local.points @ rot.T + apex, local.normals @ rot.T, local.weights)
    grid = PlaneGrid.centered(101, 101, 0.4e-3)
    p = rayleigh_integral(np.full((src.size, 1), 0.05 + 0j), src, grid.to_surface(), [f],
                          medium, kernel="fwd_vp")[:, 0].reshape(grid.shape)
    holo = Hologram(p, grid.with_pose(Pose(origin=(0.0, 0.0, 8e-3))), medium, frequency=f,
                    geometry=SourceGeometry("flat-rectangle", 8e-3, 12e-3))
    g = characterize_hologram(holo, CFG).reconstruction.geometry
    assert _angle_deg(g.axis, rot[:, 2]) < 0.01
    assert np.linalg.norm(g.apex - apex) < 20e-6
    assert abs(g.aperture[0] - 12e-3) < 0.2e-3 and abs(g.aperture[1] - 8e-3) < 0.2e-3
