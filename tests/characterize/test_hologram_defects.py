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


def test_rim_circle_fit_takes_estimate_and_covariance_from_one_kept_set():
    """Review: rim_offset's robust circle fit returned the coefficients of one pass and
    the covariance of the next pass's kept set. 16 sector edges on a circle (10 + 0.3 cos φ
    − 0.1 sin φ, noise 0.01), one gross outlier (+3) that masks a moderate one (+0.12):
    the first pass keeps the moderate one, the second drops it. The old code's centre was
    the first pass's (off by 0.013 = 7 σ); now both come from the converged kept set, equal
    to a plain least-squares fit of the 14 good edges."""
    from holoprobe.characterize._source_surface import _robust_circle

    ang = -np.pi + (np.arange(16) + 0.5) * 2 * np.pi / 16
    truth = np.array([10.0, 0.3, -0.1])
    basis = np.stack([np.ones(16), np.cos(ang), np.sin(ang)], axis=1)
    edges = basis @ truth + 0.01 * np.random.default_rng(1).standard_normal(16)
    edges[3] += 3.0
    edges[9] += 0.12
    fit = _robust_circle(ang, edges, 1e-3)
    assert fit is not None
    coef, cov = fit
    good = np.ones(16, bool)
    good[[3, 9]] = False
    want, *_ = np.linalg.lstsq(basis[good], edges[good], rcond=None)
    resid = edges[good] - basis[good] @ want
    want_cov = np.linalg.inv(basis[good].T @ basis[good]) * np.sum(resid**2) / (good.sum() - 3)
    assert np.allclose(coef, want, rtol=0, atol=1e-12)
    assert np.allclose(cov, want_cov, rtol=1e-9, atol=0)
    assert np.all(np.abs(coef - truth) < 3 * np.sqrt(np.diag(cov)))
