"""Receive of a convex array from a flat reflector (issue 16): the mirrored curved array.

The geometry (image arc, shortest echo paths, mirrored element faces) is checked against
closed forms and a brute-force minimum written here. The twin: 12 elements on a 10 mm
radius (±17°), lens F = 12 mm over H = 2 mm, 5 % transmit amplitude / 2 ns delay /
5 % receive-gain variation, a receive IR unlike the transmit IR (3.3 MHz with a
ringing copy), plate 8 mm from the apex tilted by 1° (θy' = 2°), Rp = 0.78 with a
6 mm steel back wall, 40 dB. The scan and the echo are the simulator's dense Rayleigh
sums from midpoint cells of the curved faces (the echo by the image method onto the
mirrored receiver cells); the estimator forward-projects the noisy 0.15 mm scan with
the type-3 NUFFT onto its own samples of the mirrored faces: no inverse crime. The
transmit side is given as the truth (the fitted arc, pose and F are tested in
test_convex.py), so the receive step is tested alone.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from _shared import delay_and_correlation, gaussian_ir
from holoprobe.characterize import (
    CharacterizationConfig,
    ConvexFace,
    ReceiveConfig,
    characterize_convex_receive,
    convex_sensor_predictor,
    echo_delays,
    echo_path_lengths,
    lens_path_offset,
    mirrored_faces,
    predict_element_pressure,
)
from holoprobe.errors import InputError
from holoprobe.geometry import ArrayGeometry, Pose
from holoprobe.simulate import ArrayModel, rectangular_pulse, simulate_echo, simulate_scan

C0 = 1481.0
D, TILT = 8e-3, math.radians(2.0)
POSE = Pose.from_degrees(0.4, -0.6, 1.0, (0.15e-3, -0.1e-3, 4e-3))
BAND = (1.5e6, 5.5e6)


def _reflect(points, tilt, distance):
    """Mirror images across the plane through (0, 0, d) with normal (sin t/2, 0, cos t/2)."""
    n = np.array([math.sin(tilt / 2), 0.0, math.cos(tilt / 2)])
    return points - 2 * ((points - [0.0, 0.0, distance]) @ n)[:, None] * n


def test_echo_paths_are_the_closed_form_and_the_brute_force_shortest_paths():
    r = 10e-3
    geo = ArrayGeometry.convex(16, 0.5e-3, r, 0.45e-3, 2e-3)
    phi = geo.element_angles
    # untilted plate: √((2d + R)² + 4R(R + d)(1 − cos φ)) − R, 2d at the apex
    want = np.sqrt((2 * D + r) ** 2 + 4 * r * (r + D) * (1 - np.cos(phi))) - r
    np.testing.assert_allclose(echo_path_lengths(geo, D, 0.0), want, rtol=1e-12)
    # tilted plate: the minimum over 200 001 points of the arc (edges included)
    edge = phi[-1] + 0.5 * 0.45e-3 / r
    arc = np.linspace(-edge, edge, 200_001)
    pts = np.stack([r * np.sin(arc), 0 * arc, r * np.cos(arc) - r], axis=-1)
    for tilt, dist in ((math.radians(6.0), D), (math.radians(-25.0), 3e-3)):
        images = _reflect(geo.positions, tilt, dist)
        brute = np.array([np.min(np.linalg.norm(pts - p, axis=1)) for p in images])
        got = echo_path_lengths(geo, dist, tilt)
        np.testing.assert_allclose(got, brute, atol=2e-9)
    # the delays add the lens path offset of two facing apertures
    t = echo_delays(geo, D, 0.0, focus=12e-3, sound_speed=C0)
    np.testing.assert_allclose(t * C0, want + lens_path_offset(want, 12e-3, 2e-3), rtol=1e-12)
    with pytest.raises(InputError, match="convex"):
        echo_path_lengths(ArrayGeometry.linear(4, 0.3e-3, 0.25e-3, 2e-3), D, 0.0)


def test_mirrored_faces_are_the_reflected_real_faces_with_their_real_elevations():
    geo = ArrayGeometry.convex(5, 0.6e-3, 6e-3, 0.5e-3, 1.5e-3)
    surf, layout = mirrored_faces(geo, D, TILT, spacing=0.1e-3)
    real = geo.surface(0.1e-3, layout="grid")
    assert layout.element_count == 5 and layout.points_per_element * 5 == surf.size
    # reflected back, the image points are the real face's cells, element by element
    back = _reflect(surf.points, TILT, D)
    for e in range(5):
        mine = back[surf.element == e]
        theirs = real.points[real.element == e]
        order = [np.lexsort(np.round(x.T * 1e9)) for x in (mine, theirs)]
        np.testing.assert_allclose(mine[order[0]], theirs[order[1]], atol=1e-15)
    # each image point knows the elevation (y) and arc position of the real point it
    # mirrors; the image is left-handed: its own height axis runs the other way
    np.testing.assert_allclose(layout.v, back[:, 1], atol=1e-15)
    assert np.isclose(np.ptp(layout.v), 1.5e-3 * (1 - 1 / 15))
    ang = np.arctan2(back[:, 0], back[:, 2] + 6e-3)
    np.testing.assert_allclose(layout.u, 6e-3 * ang, atol=1e-12)
    assert np.isclose(layout.weights.sum(), 5 * 0.5e-3 * 1.5e-3)
    # image normals point back towards the array (against the plate normal)
    n = np.array([math.sin(TILT / 2), 0.0, math.cos(TILT / 2)])
    assert np.all(surf.normals @ n < -0.9)


def _bandlimited(x, fs, t0, t):
    """Band-limited (Fourier) interpolation of x (sample 0 at t0, rate fs) at times t."""
    spec = np.fft.rfft(x)
    f = np.fft.rfftfreq(x.size, 1 / fs)
    spec[-1] *= 0.5 if x.size % 2 == 0 else 1.0
    w = np.where(f > 0, 2.0, 1.0) / x.size
    return np.real(np.exp(2j * np.pi * np.outer(t - t0, f)) @ (w * spec))


def _model():
    fs = 250e6
    tx = gaussian_ir(fs, 3.6e6, 0.15e-6, 0.6e-6) * 1e11
    rx = gaussian_ir(fs, 3.3e6, 0.18e-6, 0.7e-6) * 3e-3
    rx = rx + 0.25 * np.roll(rx, 40)  # a ringing copy 0.16 µs later
    model = ArrayModel(element_count=12, pitch=0.508e-3, element_width=0.45e-3,
                       element_height=2e-3, lens_focus=12e-3, transmit_ir=tx,
                       receive_ir=rx, ir_sampling_rate=fs,
                       drive=rectangular_pulse(sampling_rate=fs), center_frequency=3.6e6,
                       radius_of_curvature=10e-3)
    return model.with_element_variation(amplitude_rms=0.05, delay_rms=2e-9,
                                        receive_gain_rms=0.05, seed=3)


@pytest.fixture(scope="module")
def twin():
    model = _model()
    scan, _ = simulate_scan(model, pose=POSE, size=(12e-3, 4.5e-3), step=(0.15e-3, 0.15e-3),
                            sampling_rate=25e6, n_samples=160, snr_db=40, seed=1, band=BAND,
                            points_per_wavelength=2.5)
    echo, truth = simulate_echo(model, plate_distance=D, virtual_tilt=TILT,
                                reflection_coefficient=0.78, back_wall=True,
                                plate_thickness=6e-3, snr_db=40, seed=2, band=BAND,
                                points_per_wavelength=2.5, start_time=5e-6, n_samples=640)
    face = ConvexFace(model.array_geometry(), POSE, model.lens_focus, BAND)
    return model, scan, echo, truth, face


def test_predicted_element_pressure_is_the_twins_echo_in_pascal(twin):
    """The measured scan projected onto the mirrored faces at the true plate pose, lens
    reversed and element averaged, × Rp, against the twin's clean element pressure of
    the front echo (dense Rayleigh to the mirrored receiver cells)."""
    _, scan, echo, truth, face = twin
    rc = ReceiveConfig()
    predict = convex_sensor_predictor(echo, face, scan, D, config=CharacterizationConfig(),
                                      receive=rc)
    fs = echo.sampling_rate
    t_echo = echo.start_time + np.arange(echo.rf.shape[1]) / fs
    back = 2 * D / C0 + truth.parameters["reflector"]["back_wall_delay_s"] - 0.4e-6
    front = truth.arrays["element_pressure"][:, t_echo < back].astype(float)
    # the 3-D type-3 NUFFT onto the image cells, and the image cylinder's symmetry
    p, t_p = predict.on_surface(*mirrored_faces(face.geometry, D, TILT,
                                                spacing=predict.projection.spacing))
    p_cyl, t_cyl = predict_element_pressure(predict, face.geometry, D, TILT,
                                            method="cylindrical")
    assert t_cyl == t_p
    assert np.abs(p_cyl - p).max() < 3e-3 * np.abs(p).max()
    for e in range(12):
        pred = 0.78 * _bandlimited(p[e], predict.sampling_rate, t_p, t_echo[t_echo < back])
        lag, corr = delay_and_correlation(pred, front[e], fs, upsample=8)
        gain = np.dot(pred, front[e]) / np.dot(front[e], front[e])
        assert abs(lag) < 1.5e-9, e
        assert corr > 0.995, e
        assert gain == pytest.approx(1.0, abs=0.02), e


def test_convex_receive_recovers_plate_pose_receive_ir_gains_and_rp(twin):
    model, scan, echo, _, face = twin
    rx = characterize_convex_receive(echo, face, scan, progress=False)
    vr = rx.receiver
    err_d, err_t = vr.distance - D, vr.theta_y - TILT
    print(f"d {err_d * 1e6:+.1f} µm (σ {vr.distance_uncertainty * 1e6:.1f}), θy' "
          f"{math.degrees(err_t):+.4f}° (σ {math.degrees(vr.theta_y_uncertainty):.4f}°), "
          f"Rp {rx.reflection_coefficient - 0.78:+.4f} (σ {rx.reflection_uncertainty:.4f})")
    assert abs(err_d) < 3 * vr.distance_uncertainty and vr.distance_uncertainty < 0.1e-3
    assert abs(err_t) < 3 * vr.theta_y_uncertainty and abs(math.degrees(err_t)) < 0.03
    assert vr.x0 == pytest.approx(vr.distance * math.sin(vr.theta_y))
    assert vr.z0 == pytest.approx(vr.distance * (1 + math.cos(vr.theta_y)))
    assert abs(rx.reflection_coefficient - 0.78) < max(3 * rx.reflection_uncertainty, 0.01)
    # the receive IR in absolute units (ADCL/(Pa·s)): shape, amplitude and time; its
    # onset was moved by ir_shift, so on the echo clock it is lag − shift off the truth,
    # which the distance error explains (2 δd / c0)
    ir = rx.impulse_response
    lag, corr = delay_and_correlation(ir.ir, model.receive_ir, ir.sampling_rate, upsample=4)
    k = round(lag * ir.sampling_rate)
    a = ir.ir[max(k, 0):]
    b = model.receive_ir[max(-k, 0):]
    n = min(a.size, b.size)
    amp = float(np.dot(a[:n], b[:n]) / np.dot(b[:n], b[:n]))
    late = lag - rx.extras["ir_shift"]
    print(f"IR corr {corr:.4f}, amplitude {amp:.4f}, time {late * 1e9:+.1f} ns "
          f"(2δd/c0 {2 * err_d / C0 * 1e9:+.1f} ns)")
    assert corr >= 0.995
    assert amp == pytest.approx(1.0, abs=0.03)
    assert abs(late + 2 * err_d / C0) < 3e-9
    # receive gains relative to the element mean, within 2 % and their σ
    g = np.asarray(model.receive_gains) / np.mean(model.receive_gains)
    sens = rx.sensitivity
    got = sens.amplitude / np.mean(sens.amplitude)
    print("gain errors %", np.round((got - g) * 100, 2))
    assert np.all(np.abs(got - g) < 0.02)
    assert np.all(np.abs(got - g) < 3 * sens.amplitude_uncertainty)
    assert rx.element_pressure.shape[0] == 12 and rx.extras["array"] == "convex"
    np.testing.assert_allclose(rx.element_x, face.geometry.element_angles * 10e-3)


def test_a_dead_channel_is_left_out_and_named(twin):
    import dataclasses

    model, scan, echo, _, face = twin
    rf = echo.rf.copy()
    rf[3] = np.random.default_rng(5).standard_normal(rf.shape[1]) * np.std(rf[3, :100])
    rx = characterize_convex_receive(dataclasses.replace(echo, rf=rf), face, scan,
                                     ReceiveConfig(pose_iterations=2))
    assert not rx.receiver.used[3] and rx.receiver.used.sum() == 11
    assert any("channels [3]" in w for w in rx.warnings)
    live = np.arange(12) != 3
    g = np.asarray(model.receive_gains)[live]
    got = rx.sensitivity.amplitude[live]
    assert np.all(np.abs(got / got.mean() - g / g.mean()) < 0.02)
    assert abs(rx.sensitivity.amplitude[3]) < 0.05
    assert abs(rx.receiver.distance - D) < 3 * rx.receiver.distance_uncertainty


def test_a_noise_free_twin_has_a_receive_and_the_twins_plate():
    """Clean data (held-out twins may be noise-free): the twin above without noise in
    the scan or the echo. The high-passed echo average before the echo is a smooth
    drift far below the peak; the onset's noise σ (its MAD, ~0) made every pre-echo
    sample "above the noise" and the receive stopped with FitError "no zero crossing
    precedes the pulse" before σ had a floor 80 dB below the peak."""
    model = _model()
    scan, _ = simulate_scan(model, pose=POSE, size=(12e-3, 4.5e-3), step=(0.15e-3, 0.15e-3),
                            sampling_rate=25e6, n_samples=160, snr_db=None, seed=1,
                            band=BAND, points_per_wavelength=2.5)
    echo, _ = simulate_echo(model, plate_distance=D, virtual_tilt=TILT,
                            reflection_coefficient=0.78, back_wall=True,
                            plate_thickness=6e-3, snr_db=None, seed=2, band=BAND,
                            points_per_wavelength=2.5, start_time=5e-6, n_samples=640)
    face = ConvexFace(model.array_geometry(), POSE, model.lens_focus, BAND)
    rx = characterize_convex_receive(echo, face, scan, progress=False)
    vr = rx.receiver
    assert abs(vr.distance - D) < max(3 * vr.distance_uncertainty, 5e-6)  # −0.8 µm (σ 4)
    assert abs(math.degrees(vr.theta_y - TILT)) < 0.005  # −0.0021° (σ 0.0007: open)
    assert abs(rx.reflection_coefficient - 0.78) < 0.01  # −0.0039


def test_convex_receive_refuses_a_channel_count_that_is_not_the_arrays(twin):
    _, scan, echo, _, face = twin
    from holoprobe.measurement import EchoRecording

    short = EchoRecording(echo.rf[:11], echo.sampling_rate, echo.start_time, echo.unit,
                          echo.drive, None, echo.medium)
    with pytest.raises(InputError, match="12 channels"):
        characterize_convex_receive(short, face, scan)
    with pytest.raises(InputError, match="convex"):
        ConvexFace(ArrayGeometry.linear(12, 0.5e-3, 0.45e-3, 2e-3), POSE, 12e-3, BAND)


def test_perturbed_faces_move_the_arc_by_one_sigma_each():
    geo = ArrayGeometry.convex(8, 0.5e-3, 10e-3, 0.45e-3, 2e-3)
    face = ConvexFace(geo, POSE, 12e-3, BAND, radius_uncertainty=0.1e-3,
                      angle_uncertainties=(1e-4, 2e-4, 3e-4), center_uncertainty=5e-6)
    moved = dict(face.perturbed())
    assert sorted(moved) == ["center", "radius", "theta_y"]
    # R + σ with the apex kept and the arc pitch kept
    bent = moved["radius"].geometry
    assert bent.radius_of_curvature == pytest.approx(10.1e-3)
    np.testing.assert_allclose(np.linalg.norm(bent.positions - [0, 0, -10.1e-3], axis=1),
                               10.1e-3, rtol=1e-12)
    np.testing.assert_allclose(np.diff(bent.element_angles) * 10.1e-3, 0.5e-3, rtol=1e-12)
    # the scan seen from an array turned by σ about its apex / about C (the points keep
    # their distance to the apex / to C)
    p = np.array([1e-3, 0.5e-3, 0.0])
    apex_dist = np.linalg.norm(POSE.to_global(p))
    assert np.linalg.norm(moved["theta_y"].scan_pose.to_global(p)) == pytest.approx(apex_dist)
    c = np.array([0.0, 0.0, -10e-3])
    assert np.linalg.norm(moved["center"].scan_pose.to_global(p) - c) == pytest.approx(
        np.linalg.norm(POSE.to_global(p) - c))
    assert ConvexFace(geo, POSE, 12e-3, BAND).perturbed() == []


def test_convex_prediction_honours_band_decimation(twin):
    """Review (issue 16): the convex receive's predictions take every D-th bin of the
    padded record (``receive.band_decimation``) as the flat receive does: the records
    of a D times shorter record, put back where the pulse arrives. Against the
    every-bin prediction (an independent sum over D× the bins) they differ by the
    energy folded from outside the shorter record (≲ √ε of the peak); the automatic
    ladder refuses D > 1 at the default tolerance on this small twin (its edge waves
    fold: ε 1.9e-4 at D = 2) and takes D = 2 at a looser one."""
    from holoprobe.characterize import decimated_element_pressure

    _, scan, echo, _, face = twin
    rc = ReceiveConfig()
    predict = convex_sensor_predictor(echo, face, scan, D, config=CharacterizationConfig(),
                                      receive=rc)
    assert predict.projection.record_length % 8 == 0  # every decimation's bins exist
    p1, t1 = predict_element_pressure(predict, face.geometry, D, TILT)
    auto, (pa, ta) = decimated_element_pressure(predict, face.geometry, D, TILT, rc)
    assert auto.decimation == 1 and ta == t1 and np.array_equal(pa, p1)
    loose = dataclasses.replace(rc, band_alias_tolerance=1e-3)
    for method in ("type3", "cylindrical"):
        chosen, (pd, td) = decimated_element_pressure(predict, face.geometry, D, TILT, loose,
                                                      method=method)
        assert chosen.decimation == 2 and td == t1
        assert np.count_nonzero(chosen.selected) * 2 <= predict.projection.bins.size + 2
        assert np.abs(pd - p1).max() < 0.02 * np.abs(p1).max()  # 1.4 % measured
    # the decimated predictor's later predictions (pose steps) are decimated too
    again, _ = predict_element_pressure(chosen, face.geometry, D, TILT, method="cylindrical")
    np.testing.assert_allclose(again, pd, atol=1e-12 * np.abs(pd).max())
