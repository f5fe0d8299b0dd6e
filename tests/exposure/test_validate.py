"""Validation against a measured field: least-squares scale, error, file format, CLI."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from holoprobe.errors import InputError
from holoprobe.exposure import (
    MeasuredField,
    least_squares_scale,
    plot_validation,
    read_measured_field,
    validate_field,
    write_measured_field,
)
from holoprobe.geometry import PlaneGrid, Pose
from holoprobe.transducer import TransmitSetting, VirtualTransducer, burst


@pytest.fixture(scope="module")
def small_probe():
    vt = VirtualTransducer.from_preset("p4-1").replace(element_count=8)
    tx = TransmitSetting.focused((0.0, 0.0, 0.02), drive=burst(2.5e6, 2, 10.0))
    return vt, tx


def test_least_squares_scale_matches_numpy_lstsq():
    rng = np.random.default_rng(0)
    y = rng.normal(size=(20, 50))
    x = 0.7 * y + 0.1 * rng.normal(size=y.shape)
    s, err = least_squares_scale(x, y)
    s_ref = np.linalg.lstsq(y.reshape(-1, 1), x.reshape(-1), rcond=None)[0][0]
    assert s == pytest.approx(s_ref, rel=1e-12)
    assert err == pytest.approx(np.linalg.norm(x - s_ref * y) / np.linalg.norm(x), rel=1e-12)
    assert least_squares_scale(2 * y, y) == pytest.approx((2.0, 0.0), abs=1e-12)


def test_scaled_noisy_twin_field_gives_scale_1_2(small_probe, tmp_path):
    """The "measured" field is the twin's (holoprobe.simulate: sub-element quadrature,
    dense Rayleigh sum), not the prediction that validate_field computes itself."""
    from holoprobe.simulate import ArrayModel, simulate_field

    vt, tx = small_probe
    model = ArrayModel.from_preset("p4-1", element_count=8)
    model = model.replace(drive=tx.drive,
                          delays=tx.element_delays(vt.element_centers(),
                                                   vt.medium.sound_speed))
    z = np.linspace(5e-3, 40e-3, 36)
    pts = np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=1)
    fs, t0 = 40e6, 0.0
    _, twin = simulate_field(model, pts, sampling_rate=fs, start_time=t0, n_samples=1600)
    rng = np.random.default_rng(1)
    noise = 0.05 * np.abs(twin).max() * rng.normal(size=twin.shape)
    measured = MeasuredField(pts, 1.2 * twin + noise, fs, t0)
    path = write_measured_field(tmp_path / "field.h5", measured)
    result = validate_field(vt, tx, path)
    assert result.scale == pytest.approx(1.2, rel=0.03)
    # the residual is the noise (plus the small model difference): ‖noise‖ / ‖1.2 p + noise‖
    expected = np.linalg.norm(noise) / np.linalg.norm(measured.pressure)
    assert expected * 0.95 <= result.normalised_error <= expected * 1.5
    assert result.profile_axis == "z"
    np.testing.assert_array_equal(result.profile_index, np.arange(z.size))
    png = plot_validation(result, tmp_path / "profiles.png")
    assert png.stat().st_size > 1000


def test_measured_field_file_round_trip_with_plane_grid(tmp_path):
    grid = PlaneGrid(np.linspace(-2e-3, 2e-3, 5), np.linspace(-1e-3, 1e-3, 3),
                     Pose(0.0, 0.1, 0.0, (0.0, 0.0, 0.03)))
    p = np.random.default_rng(2).normal(size=(15, 64))
    field = MeasuredField(grid.points(), p, 25e6, 1e-5, grid, "test")
    write_measured_field(tmp_path / "g.h5", field)
    with h5py.File(tmp_path / "g.h5") as f:
        assert f["pressure"].shape == (5, 3, 64)
    back = read_measured_field(tmp_path / "g.h5")
    np.testing.assert_array_equal(back.pressure, p)
    np.testing.assert_allclose(back.points, grid.points(), atol=1e-15)
    assert back.grid.pose.theta_y == 0.1 and back.start_time == 1e-5
    assert back.description == "test"


def test_measured_field_file_errors_name_file_and_field(tmp_path):
    with h5py.File(tmp_path / "bad.h5", "w") as f:
        f.attrs["format"] = "holoprobe-measured-field"
        f.attrs["sampling_rate"] = 1e6
        f.attrs["start_time"] = 0.0
        f["pressure"] = np.zeros((3, 8))
    with pytest.raises(InputError, match=r"bad\.h5.*points"):
        read_measured_field(tmp_path / "bad.h5")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = 1
    with pytest.raises(InputError, match="format"):
        read_measured_field(tmp_path / "other.h5")


def test_validate_cli_writes_json_and_plot(small_probe, tmp_path):
    from holoprobe.cli import app
    from holoprobe.transducer import predict_field

    vt, tx = small_probe
    vt_path = vt.save(tmp_path / "vt.h5")
    (tmp_path / "tx.toml").write_text(
        '[delays]\nkind = "focused"\npoint = [0.0, 0.0, 0.02]\n'
        '[drive]\nkind = "burst"\nfrequency = 2.5e6\ncycles = 2\namplitude = 10.0\n')
    pts = np.stack([np.zeros(12), np.zeros(12), np.linspace(0.01, 0.03, 12)], axis=1)
    truth = predict_field(vt, tx, pts, sampling_rate=40e6, start_time=0.0)
    write_measured_field(tmp_path / "m.h5", MeasuredField(pts, 0.8 * truth.pressure, 40e6))
    res = CliRunner().invoke(app, ["validate", str(vt_path), "--transmit",
                                   str(tmp_path / "tx.toml"), "--measured",
                                   str(tmp_path / "m.h5"), "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "out" / "validation.json").read_text())
    assert summary["scale"] == pytest.approx(0.8, rel=1e-6)
    assert (tmp_path / "out" / "validation_profiles.png").is_file()
