"""Field prediction of a 2-D matrix-array virtual transducer (issue 16): element
positions from ``VirtualTransducer.array``, delays steering in both planes; each test
on a full 6 × 5 grid and on a sparse one (16 of its 30 positions)."""

from __future__ import annotations

import numpy as np
import pytest

from holoprobe.geometry import Medium, Surface
from holoprobe.simulate import ArrayModel, synthesize_pressure
from holoprobe.transducer import TransmitSetting, VirtualTransducer, predict_field

MEDIUM = Medium(998.0, 1481.0)
FOCUS = (1.2e-3, -0.9e-3, 8e-3)


@pytest.fixture(scope="module", params=["full", "sparse"])
def pair(request):
    from holoprobe.geometry import sparse_layout

    active = sparse_layout(6, 5, 16, taper=0.5) if request.param == "sparse" else None
    model = ArrayModel.matrix(6, 5, 0.3e-3, active=active).with_element_variation(
        amplitude_rms=0.1, dead=(7,), seed=4)
    assert model.array.layout == request.param
    vt = VirtualTransducer(
        element_count=model.element_count, pitch=model.pitch,
        element_width=model.element_width, element_height=model.element_height,
        transmit_impulse_response=model.transmit_ir,
        transmit_sampling_rate=model.ir_sampling_rate, medium=MEDIUM, array=model.array,
        element_transmit_amplitude=np.asarray(model.apodization))
    return model, vt


def test_matrix_focus_steers_in_both_planes(pair):
    model, vt = pair
    setting = TransmitSetting.focused(FOCUS, drive=model.drive)
    x = np.linspace(-1.5e-3, 4e-3, 23)
    y = np.linspace(-3.5e-3, 2e-3, 23)
    xx, yy = np.meshgrid(x, y, indexing="ij")
    pts = np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, FOCUS[2])], axis=-1)
    peak = predict_field(vt, setting, pts, sampling_rate=100e6).peak_positive.reshape(xx.shape)
    i, j = np.unravel_index(int(np.argmax(peak)), peak.shape)
    assert abs(x[i] - FOCUS[0]) <= 0.3e-3 and abs(y[j] - FOCUS[1]) <= 0.3e-3


def test_matrix_field_matches_the_twin_in_absolute_pressure(pair):
    """The model's field (midpoint sub-elements, its own Rayleigh sum) against the twin's
    (Gauss–Legendre rectangles, dense Rayleigh sum) for the same focusing delays."""
    model, vt = pair
    setting = TransmitSetting.focused(FOCUS, drive=model.drive)
    apod, tau = vt.transmit_weights(setting)
    twin = model.replace(delays=tau, apodization=apod)
    rng = np.random.default_rng(1)
    pts = np.c_[rng.uniform(-2e-3, 3e-3, (10, 2)), rng.uniform(5e-3, 10e-3, 10)]
    expected = synthesize_pressure(
        twin, twin.sample_surface(MEDIUM.sound_speed / 6e6 / 4),
        Surface(pts, np.tile([0, 0, 1.0], (10, 1)), np.ones(10)), sampling_rate=250e6,
        n_samples=2500, start_time=0.0, band=(0.3e6, 6e6), medium=MEDIUM,
        dtype=np.float64)
    got = predict_field(vt, setting, pts, sampling_rate=250e6)
    np.testing.assert_allclose(got.peak_positive, expected.max(axis=1), rtol=0.02)


def test_matrix_exports_carry_the_element_positions(pair, tmp_path):
    """UFF and Verasonics exports of a matrix model: every element at its (x, y);
    the k-Wave staircase mask labels each grid point with the element above it."""
    from holoprobe.export import kwave_grid_mask, uff_probe_dict, verasonics_trans

    _, vt = pair
    centers = vt.element_centers()
    uff = uff_probe_dict(vt)
    got = np.array([[e["transform"]["translation"][k] for k in "xyz"]
                    for e in uff["element"].values()])
    np.testing.assert_allclose(got, centers, atol=1e-15)
    pos = np.asarray(verasonics_trans(vt)["ElementPos"])[:, :3]  # in wavelengths
    scale = np.sum(pos * centers) / np.sum(centers**2)  # 1/λ
    np.testing.assert_allclose(pos, scale * centers, atol=1e-9 * scale * 1e-3)
    rows = len(np.unique(vt.array.grid_position[:, 1]))  # five (fewer on a sparse grid)
    assert len(np.unique(np.round(pos[:, 1], 6))) == rows
    mask, label = kwave_grid_mask(vt, (3, 41, 41), (0.05e-3, 0.05e-3, 0.05e-3))
    pts = np.argwhere(mask[1])
    y = (pts[:, 0] - 20) * 0.05e-3
    z = (pts[:, 1] - 20) * 0.05e-3
    assert set(label) == set(range(vt.element_count))
    assert np.all(np.abs(y - centers[label, 0]) <= 0.5 * vt.element_width + 1e-12)
    assert np.all(np.abs(z - centers[label, 1]) <= 0.5 * vt.element_height + 1e-12)
