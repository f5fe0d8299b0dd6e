"""The 2-D matrix-array twin (issue 16): exact rectangles, element variation, truth."""

from __future__ import annotations

import json

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, Pose, Surface
from holoprobe.io import read_scan
from holoprobe.simulate import ArrayModel, radiate, simulate_scan, write_simulation

MEDIUM = Medium(998.0, 1481.0)


def _model() -> ArrayModel:
    return ArrayModel.matrix(4, 3, 0.3e-3, pitch_y=0.35e-3, kerf=0.04e-3).with_element_variation(
        amplitude_rms=0.1, delay_rms=20e-9, dead=(5,), seed=3)


def test_matrix_model_geometry_and_quadrature():
    m = _model()
    assert m.element_count == 12 and m.array.grid_shape == (4, 3)
    # element index iy·n_x + ix, x fastest; centred grid
    np.testing.assert_allclose(m.array.positions[1] - m.array.positions[0], [0.3e-3, 0, 0])
    np.testing.assert_allclose(m.array.positions[4] - m.array.positions[0], [0, 0.35e-3, 0])
    assert m.aperture_width == pytest.approx(3 * 0.3e-3 + 0.26e-3)
    assert m.aperture_height == pytest.approx(2 * 0.35e-3 + 0.31e-3)
    s = m.sample_surface(0.05e-3)
    # exact element areas, Gauss–Legendre nodes (not the midpoint grid of the estimator)
    areas = np.bincount(s.element, weights=s.surface.weights)
    np.testing.assert_allclose(areas, 0.26e-3 * 0.31e-3, rtol=1e-12)
    x0 = s.surface.points[s.element == 0, 0] - m.array.positions[0, 0]
    assert np.unique(np.round(x0, 12)).size >= 3
    assert not np.allclose(np.diff(np.unique(np.round(x0, 12))), np.diff(
        np.unique(np.round(x0, 12)))[0])  # not equally spaced: not a midpoint rule
    assert m.dead_elements == [5]
    with pytest.raises(InputError, match="no lens"):
        m.replace(lens_focus=0.05)


def test_matrix_radiation_matches_per_element_fraunhofer():
    """The twin's field, far from every element, against the analytic sum of the
    elements' rectangular far fields (sinc × sinc, absolute amplitude)."""
    m = _model()
    f = np.array([2.5e6, 3.0e6, 4.0e6])
    s = m.sample_surface(MEDIUM.sound_speed / f.max() / 4)
    rng = np.random.default_rng(0)
    pts = np.c_[rng.uniform(-8e-3, 8e-3, (12, 2)), np.full(12, 40e-3)]
    targets = Surface(pts, np.tile([0, 0, 1.0], (12, 1)), np.ones(12))
    p = radiate(m, s, targets, f, MEDIUM, dtype=np.float64)
    # analytic: Σ_e a_e e^{iωτ_e} U(f) (−ikρc/2π) w h sinc sinc e^{ikR}/R
    from holoprobe.signal import continuous_spectrum

    u = continuous_spectrum(m.surface_velocity(MEDIUM), m.ir_sampling_rate, f)
    k = 2 * np.pi * f / MEDIUM.sound_speed
    d = pts[:, None, :] - m.array.positions[None, :, :]
    r = np.linalg.norm(d, axis=-1)[..., None]
    w, h = m.element_width, m.element_height
    sx = np.sinc(k * d[..., 0:1] / r * w / (2 * np.pi))
    sy = np.sinc(k * d[..., 1:2] / r * h / (2 * np.pi))
    amp = (np.asarray(m.apodization)[:, None] * np.exp(
        2j * np.pi * np.outer(m.delays, f)))[None]
    expected = np.sum(amp * w * h * sx * sy * np.exp(1j * k * r) / r, axis=1) \
        * (-1j * k * MEDIUM.impedance / (2 * np.pi)) * u
    np.testing.assert_allclose(np.abs(p), np.abs(expected), rtol=0.01)
    np.testing.assert_allclose(np.angle(p / expected), 0.0, atol=0.01)


def test_matrix_scan_truth_and_file_round_trip(tmp_path):
    m = ArrayModel.matrix(3, 2, 0.3e-3).with_element_variation(dead=(4,), seed=1)
    pose = Pose.from_degrees(1.0, -0.5, 2.0, (0.1e-3, 0.0, 2e-3))
    scan, truth = simulate_scan(m, pose=pose, size=(2e-3, 2e-3), step=(0.25e-3, 0.25e-3),
                                sampling_rate=40e6, n_samples=256, snr_db=None,
                                calibration=None, points_per_wavelength=2)
    assert scan.probe.array is not None and scan.probe.is_matrix
    write_simulation(tmp_path, scan, truth)
    back = read_scan(tmp_path / "scan.h5")
    np.testing.assert_array_equal(back.probe.array.positions, m.array.positions)
    assert back.probe.array.grid_shape == (3, 2) and back.probe.array.kind == "matrix"
    np.testing.assert_array_equal(back.probe.array.grid_position, m.array.grid_position)
    params = json.loads((tmp_path / "truth.json").read_text())
    arr = params["probe"]["array"]
    assert arr["kind"] == "matrix" and arr["grid_shape"] == [3, 2]
    assert np.allclose(arr["element_positions_m"], m.array.positions)
    assert params["probe"]["dead_elements"] == [4]
    assert params["probe"]["aperture_height_m"] == pytest.approx(0.3e-3 + 0.27e-3)
    assert np.max(np.abs(scan.data)) > 0
