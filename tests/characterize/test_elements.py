"""Element map, dead elements and the array-aware aperture on a worn-probe twin (issue 11).

The twin (``holoprobe.simulate``) radiates a 24-element P4-1-like array with ±5 %
amplitude, 8 ns rms delays, two dead elements (one at the edge, one inside), 4 µm rms
scan-position jitter and 40 dB noise, by a dense Rayleigh sum from a λ/4 quadrature; the
pipeline back-projects on the scan grid (NUFFT) and fits a 1-D strip model: no inverse
crime. The full 96-element check is ``benchmarks/elements.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from holoprobe.characterize import CharacterizationConfig
from holoprobe.characterize._pipeline import characterize_transmit
from holoprobe.geometry import Pose
from holoprobe.simulate import ArrayModel, simulate_scan

POSE = Pose.from_degrees(0.5, -0.8, 0.6, (0.1e-3, -0.05e-3, 3.5e-3))
N, DEAD = 24, [0, 9]


@pytest.fixture(scope="module")
def worn():
    model = ArrayModel.from_preset("p4-1", element_count=N).with_element_variation(
        amplitude_rms=0.05, delay_rms=8e-9, receive_gain_rms=0.05, dead=DEAD, seed=2)
    scan, truth = simulate_scan(model, pose=POSE, size=(12e-3, 19.2e-3), n_samples=192,
                                snr_db=40.0, seed=1, position_jitter=4e-6)
    cfg = CharacterizationConfig().with_overrides(["onset.bootstrap=0"])
    return model, truth, characterize_transmit(scan, cfg, progress=False)


def _matching(emap, model):
    """The map, or its one-element shift when the edge ambiguity is reported."""
    if tuple(emap.dead) != tuple(model.dead_elements) and emap.ambiguous:
        for shift in (1, -1):
            if tuple(emap.shifted(shift).dead) == tuple(model.dead_elements):
                return emap.shifted(shift)
    return emap


def test_element_map_finds_dead_elements_amplitudes_and_delays(worn):
    model, _, result = worn
    emap = _matching(result.element_map, model)
    assert tuple(emap.dead) == tuple(DEAD) and emap.weak == ()
    true_a = np.asarray(model.apodization)
    live = true_a > 0
    true_a = true_a / true_a[live].mean()
    err = (emap.relative_amplitude - true_a)[live]
    assert np.max(np.abs(err)) < 0.02
    assert np.all(np.abs(err) <= 3 * emap.amplitude_uncertainty[live])
    # delays: common delay removed, and the linear trend across the array (a steering
    # that no field measurement separates from a tilt of the scan plane: it is in the
    # fitted angles) removed too
    x = model.element_centers()[live]
    d = emap.delay[live] - np.asarray(model.delays)[live]
    d -= np.polyval(np.polyfit(x, d, 1), x)
    assert np.max(np.abs(d)) < 3e-9


def test_dead_elements_leave_width_height_focus_and_ir_amplitude_intact(worn):
    model, truth, result = worn
    probe = truth.parameters["probe"]
    assert abs(result.aperture_width - probe["aperture_width_m"]) < 0.05e-3
    assert abs(result.aperture.height - probe["aperture_height_m"]) < 0.05e-3
    assert abs(result.lens_focus / probe["lens_focus_m"] - 1) < 0.03
    # absolute amplitude of h_T: the live elements' mean apodization is the reference
    ir, true = result.impulse_response, truth.arrays["transmit_ir"]
    fs_true = float(truth.arrays["ir_sampling_rate"])
    energy = np.sqrt(np.sum(ir.ir**2) / ir.sampling_rate / (np.sum(true**2) / fs_true))
    live_mean = np.mean(np.asarray(model.apodization)[np.asarray(model.apodization) > 0])
    assert energy == pytest.approx(live_mean, rel=0.03)
    text = " ".join(result.warnings)
    assert "disagrees with the nominal array width" in text and "dead elements" in text
