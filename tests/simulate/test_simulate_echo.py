"""Tests of holoprobe.simulate.simulate_echo (image method), its files and the CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from _shared import delay_and_correlation, gaussian_ir
from holoprobe.geometry import Medium
from holoprobe.measurement import DriveSignal
from holoprobe.simulate import (
    ArrayModel,
    mirror_points,
    simulate_echo,
    virtual_sensor_pose,
    write_simulation,
)

MEDIUM = Medium()
FS_IR = 50e6
FC, SIGMA, TC = 2.0e6, 0.4e-6, 2.0e-6
IR = gaussian_ir(FS_IR, FC, SIGMA, TC)


def velocity_derivative(t: np.ndarray) -> np.ndarray:
    """du/dt of u = IR/(fs ρ0c0) (one-sample unit drive), analytic, m/s²."""
    s = t - TC
    env = np.exp(-0.5 * (s / SIGMA) ** 2)
    d = env * (-s / SIGMA**2 * np.cos(2 * np.pi * FC * s)
               - 2 * np.pi * FC * np.sin(2 * np.pi * FC * s))
    return d / FS_IR / MEDIUM.impedance


def velocity(t: np.ndarray) -> np.ndarray:
    """u = IR/(fs ρ0c0) (one-sample unit drive), analytic, m/s."""
    s = t - TC
    return (np.exp(-0.5 * (s / SIGMA) ** 2) * np.cos(2 * np.pi * FC * s) / FS_IR
            / MEDIUM.impedance)


def make_model(**kw) -> ArrayModel:
    base = dict(element_count=4, pitch=0.5e-3, element_width=0.45e-3, element_height=2e-3,
                lens_focus=math.inf, transmit_ir=IR, receive_ir=IR,
                ir_sampling_rate=FS_IR, drive=DriveSignal([1.0], FS_IR))
    base.update(kw)
    return ArrayModel(**base)


def test_image_geometry_matches_virtual_sensor_pose():
    d, tilt = 0.045, math.radians(3.17)
    origin_image = mirror_points(np.zeros((1, 3)), d, tilt)[0]
    pose = virtual_sensor_pose(d, tilt)
    np.testing.assert_allclose(origin_image, pose.origin, atol=1e-15)
    assert pose.origin[0] == pytest.approx(d * math.sin(tilt))
    assert pose.origin[2] == pytest.approx(d * (1 + math.cos(tilt)))


def test_far_field_echo_arrives_at_two_d_over_c_with_analytic_amplitude():
    model = make_model()
    d, rp, fs = 0.03, 0.78, 250e6
    rec, truth = simulate_echo(model, plate_distance=d, virtual_tilt=0.0,
                               reflection_coefficient=rp, back_wall=False, snr_db=None,
                               sampling_rate=fs, dtype=np.float64)
    p_mean = truth.arrays["element_pressure"].mean(axis=0)
    t = np.arange(p_mean.size) / fs
    # Fraunhofer on axis of the image source: p = Rp ρ0 A u̇(t − 2d/c0) / (2π·2d)
    area = model.element_count * model.element_width * model.element_height
    ref = velocity_derivative(t)  # reference pulse starting at t = 0
    lag = delay_and_correlation(p_mean, ref, fs)[0]
    assert lag == pytest.approx(2 * d / MEDIUM.sound_speed, abs=10e-9)
    expected_peak = rp * MEDIUM.density * area * np.abs(ref).max() / (2 * math.pi * 2 * d)
    assert np.abs(p_mean).max() == pytest.approx(expected_peak, rel=0.03)
    assert truth.parameters["echo_time_normal_incidence_s"] == pytest.approx(
        2 * d / MEDIUM.sound_speed)
    assert rec.rf.shape == (4, p_mean.size)


def _wide_model() -> ArrayModel:
    return make_model(element_count=16, pitch=1e-3, element_width=0.9e-3,
                      element_height=1e-3)


def test_plate_tilt_gives_arrival_slope_sin_theta_over_c():
    model = _wide_model()
    tilt = math.radians(6.0)
    fs = 250e6
    _, truth = simulate_echo(model, plate_distance=5e-3, virtual_tilt=tilt, back_wall=False,
                             snr_db=None, sampling_rate=fs, dtype=np.float64)
    p = truth.arrays["element_pressure"]
    x = model.element_centers()
    central = np.abs(x) < 4e-3
    ref = velocity(np.arange(p.shape[1]) / fs)  # the emitted pulse shape
    lags = np.array([delay_and_correlation(row, ref, fs)[0] for row in p[central]])
    slope = np.polyfit(x[central], lags, 1)[0]
    # elements at +x are nearer the virtual sensor (x0' = d sin θy' > 0): earlier echo
    assert slope == pytest.approx(-math.sin(tilt) / MEDIUM.sound_speed, rel=0.05)


def test_untilted_plate_gives_symmetric_element_pressure():
    model = _wide_model()
    _, truth = simulate_echo(model, plate_distance=5e-3, virtual_tilt=0.0, snr_db=None,
                             dtype=np.float64)
    p = truth.arrays["element_pressure"]
    assert np.abs(p - p[::-1]).max() < 1e-6 * np.abs(p).max()
    _, tilted = simulate_echo(model, plate_distance=5e-3, virtual_tilt=math.radians(4),
                              snr_db=None, dtype=np.float64)
    q = tilted.arrays["element_pressure"]
    assert np.abs(q - q[::-1]).max() > 0.05 * np.abs(q).max()


def test_back_wall_echo_arrives_after_the_plate_transit_time():
    model = make_model()
    fs, d = 250e6, 0.03
    kw = dict(plate_distance=d, virtual_tilt=0.0, snr_db=None, sampling_rate=fs,
              dtype=np.float64, plate_thickness=5e-3, plate_sound_speed=5000.0)
    _, with_bw = simulate_echo(model, **kw)
    _, without = simulate_echo(model, back_wall=False, **kw)
    n = min(with_bw.arrays["element_pressure"].shape[1],
            without.arrays["element_pressure"].shape[1])
    first = without.arrays["element_pressure"][:, :n].mean(axis=0)
    second = with_bw.arrays["element_pressure"][:, :n].mean(axis=0) - first
    # the back-wall echo has the opposite sign (−Rp(1 − Rp²))
    lag, _ = delay_and_correlation(-second, first, fs)
    assert lag == pytest.approx(2 * 5e-3 / 5000.0, abs=5e-9)
    ratio = np.abs(second).max() / np.abs(first).max()
    assert ratio == pytest.approx((1 - 0.78**2), rel=5e-3)  # −Rp(1−Rp²) relative to Rp


def test_echo_noise_has_requested_peak_snr():
    model = make_model()
    kw = dict(plate_distance=0.01, virtual_tilt=0.0, seed=5)
    clean, _ = simulate_echo(model, snr_db=None, **kw)
    noisy, truth = simulate_echo(model, snr_db=25.0, **kw)
    noise = noisy.rf.astype(float) - clean.rf
    measured = 20 * np.log10(np.abs(clean.rf).max() / noise.std())
    assert abs(measured - 25.0) < 0.5
    assert truth.parameters["noise"]["unit"] == "ADCL"


@pytest.mark.parametrize("fmt", ["native", "reference-mat"])
def test_echo_files_round_trip_in_both_formats(tmp_path, fmt):
    from holoprobe.io import read_echo, read_reference_echo

    model = make_model()
    rec, truth = simulate_echo(model, plate_distance=0.01, virtual_tilt=0.02, seed=2)
    write_simulation(tmp_path, rec, truth, format=fmt)
    back = read_echo(tmp_path / "echo.h5") if fmt == "native" else read_reference_echo(
        tmp_path / "ReceiveData.mat")
    np.testing.assert_allclose(back.rf, rec.rf, rtol=1e-6, atol=0)
    assert back.sampling_rate == pytest.approx(rec.sampling_rate)
    assert back.rf.shape == (4, rec.n_samples)
    saved = json.loads((tmp_path / "truth.json").read_text())
    assert saved["virtual_sensor"]["theta_y_deg"] == pytest.approx(math.degrees(0.02))
    assert saved["reflector"]["plate_tilt_deg"] == pytest.approx(math.degrees(0.01))


def test_cli_scan_and_receive_write_measurement_and_truth(tmp_path):
    from typer.testing import CliRunner

    from holoprobe.cli import app
    from holoprobe.io import read_scan

    runner = CliRunner()
    res = runner.invoke(app, ["simulate", "scan", "--elements", "2", "--size-mm", "1", "1",
                              "--step-mm", "0.5", "0.5", "--n-samples", "256",
                              "--pose-deg", "1", "2", "3", "--origin-mm", "0.1", "0", "4",
                              "--seed", "9", "--quiet", "--out", str(tmp_path / "s")])
    assert res.exit_code == 0, res.output
    truth = json.loads((tmp_path / "s" / "truth.json").read_text())
    assert [truth["scan_pose"][k] for k in ("theta_x_deg", "theta_y_deg", "theta_z_deg")] \
        == pytest.approx([1, 2, 3])
    assert truth["scan_pose"]["z0_m"] == pytest.approx(4e-3)
    assert read_scan(tmp_path / "s" / "scan.h5").data.shape == (3, 3, 256)
    res = runner.invoke(app, ["simulate", "receive", "--elements", "2", "--distance-mm", "8",
                              "--format", "reference-mat", "--quiet",
                              "--out", str(tmp_path / "r")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "r" / "ReceiveData.mat").exists()
    truth = json.loads((tmp_path / "r" / "truth.json").read_text())
    assert truth["reflector"]["plate_distance_m"] == pytest.approx(8e-3)


def test_rf_is_element_pressure_convolved_with_the_receive_ir():
    model = make_model()
    rec, truth = simulate_echo(model, plate_distance=0.01, virtual_tilt=0.0, snr_db=None,
                               sampling_rate=FS_IR, dtype=np.float64)
    p = truth.arrays["element_pressure"]
    expected = np.stack([np.convolve(row, model.receive_ir)[:p.shape[1]] / FS_IR
                         for row in p])  # E_R = h_R ⊛ p_R, continuous convolution
    assert np.abs(rec.rf - expected).max() < 2e-3 * np.abs(expected).max()


def test_bad_parameters_raise_input_error_naming_the_field():
    from holoprobe.errors import InputError

    model = make_model()
    with pytest.raises(InputError, match="plate_distance"):
        simulate_echo(model, plate_distance=-1.0)
    with pytest.raises(InputError, match="reflection_coefficient"):
        simulate_echo(model, reflection_coefficient=1.5)
    with pytest.raises(InputError, match="apodization"):
        model.replace(apodization=[1.0, 2.0])
    with pytest.raises(InputError, match="element_width"):
        make_model(element_width=1e-3)


def test_receive_gains_scale_each_channel_and_a_dead_element_records_nothing():
    gains = [1.0, 1.1, 0.0, 0.9]
    kw = dict(plate_distance=5e-3, virtual_tilt=0.0, back_wall=False, snr_db=None,
              dtype=np.float64)
    _, ref = simulate_echo(make_model(), **kw)
    _, got = simulate_echo(make_model(receive_gains=gains), **kw)
    np.testing.assert_allclose(got.arrays["rf_clean"],
                               np.asarray(gains)[:, None] * ref.arrays["rf_clean"],
                               atol=1e-9 * np.abs(ref.arrays["rf_clean"]).max())
    assert got.parameters["probe"]["receive_gains"] == gains


def test_feedthrough_starts_at_the_emission_and_the_receiver_skips_it():
    # issue 10 item 9: every real system records the drive coupling into the receive
    # channels at the emission. With ReceiveConfig.window = None the old code took the
    # largest envelope of the record, the feed-through, for the echo.
    from holoprobe.characterize import echo_search_window, estimate_virtual_receiver

    model = make_model(element_count=8)
    d, tilt = 10e-3, math.radians(2.0)
    rec, truth = simulate_echo(model, plate_distance=d, virtual_tilt=tilt, back_wall=False,
                               snr_db=40.0, seed=5, start_time=0.0, sampling_rate=25e6,
                               feedthrough=3.0, feedthrough_decay=0.5e-6)
    feed = truth.arrays["feedthrough"]
    t = np.arange(rec.n_samples) / rec.sampling_rate
    env = np.abs(feed).max(axis=0)
    assert t[np.argmax(env > 0.01 * env.max())] < 1e-6  # it starts at the emission
    assert np.abs(feed).max() > 2.5 * np.abs(truth.arrays["rf_clean"] - feed).max()
    start, _ = echo_search_window(rec.rf, rec.sampling_rate, start_time=rec.start_time)
    echo_time = 2 * d / MEDIUM.sound_speed
    assert 2e-6 < start < echo_time - 2e-6
    rx = estimate_virtual_receiver(rec.rf, rec.sampling_rate, model.probe_info()
                                   .element_centers(), focus=math.inf,
                                   height=model.element_height, start_time=rec.start_time,
                                   noise_guard=1e-6)
    # the arrivals are those of the echo (IR peak at TC after the geometric arrival)
    assert np.all(np.abs(rx.arrival_times - (echo_time + 2 * TC)) < 1e-6)
