"""A bowl with a dead sector and a phase defect: the source is placed on its own axis.

A dead sector tilts the focal lobe's axis (0.5° here) away from the bowl's; the source
surface used to be placed on the lobe axis, so its apex was ~0.4 mm off and the aperture
0.12 mm small, and the phase defect bent the phase-flattest radius by −3 % (σ 10 %).
"""

from __future__ import annotations

import numpy as np
import pytest

from holoprobe.characterize import HologramConfig, characterize_hologram, hologram_summary
from holoprobe.geometry import SourceGeometry
from holoprobe.simulate import VelocityMap, simulate_hologram

GEOMETRY = SourceGeometry("spherical-cap", 0.02, 0.02, 0.03)


@pytest.fixture(scope="module")
def defective():
    vmap = VelocityMap(dead_sectors=((np.radians(20), np.radians(65)),),
                       phase_patches=((-4e-3, -3e-3, 2e-3, np.pi / 2),))
    holo, truth = simulate_hologram(GEOMETRY, frequency=1e6, z_position=0.018,
                                    tilt=(0.01, -0.02), offset=(0.5e-3, -0.3e-3),
                                    shape=(49, 49), velocity=vmap, power=False, focus=False)
    result = characterize_hologram(holo, HologramConfig(monte_carlo=0))
    return hologram_summary(result), truth.parameters


def test_the_source_sits_on_its_geometric_axis_not_the_tilted_lobe(defective):
    s, truth = defective
    geometric = np.array(truth["alignment"]["geometric_axis"])
    normal = np.array(s["alignment"]["source_normal"])
    assert np.degrees(np.arccos(min(normal @ geometric, 1.0))) < 0.05      # was 0.57°
    apex = np.array(s["alignment"]["source_apex"]) - truth["alignment"]["apex_position"]
    assert np.linalg.norm(apex) < 20e-6                                     # was 390 µm
    assert abs(s["source"]["aperture_diameter"] - 0.02) < 30e-6            # was −125 µm


def test_a_phase_defect_does_not_bend_the_radius_of_curvature(defective):
    s, _ = defective
    err = s["source"]["radius_of_curvature"] - 0.03
    assert abs(err) < 0.002 * 0.03                                         # was −3.2 %
    assert abs(err) <= 2 * s["uncertainty"]["radius_of_curvature"]
    assert s["uncertainty"]["radius_of_curvature"] < 0.005 * 0.03           # was 9.8 %
    # both defects are still reported where they are
    (dead,) = s["uniformity"]["dead_regions"]
    assert dead["azimuth_deg"] == pytest.approx(42.5, abs=5)
    (patch,) = s["uniformity"]["phase_defects"]
    assert np.hypot(patch["unrolled"][0] + 4e-3, patch["unrolled"][1] + 3e-3) < 0.5e-3
