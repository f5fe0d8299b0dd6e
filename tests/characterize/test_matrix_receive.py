"""Receive of a 2-D matrix array from a flat reflector (issue 16): the mirrored grid.

The geometry (the plate with two tilts, far-field echo paths, mirrored element faces) is
checked against closed forms written here. The twin: an 8 × 8 matrix (0.3 mm pitch,
3 MHz, no lens) with 5 % transmit amplitude / 2 ns delay / 5 % receive-gain variation
and one dead element, plate 10 mm away with θx' = 1.5°, θy' = −2°, Rp = 0.78 with a
6 mm steel back wall, 40 dB. The scan and the echo are the simulator's dense
frequency-domain Rayleigh sums (the echo by the image method onto the mirrored receiver
cells); the estimator forward-projects the noisy 0.15 mm scan with the type-3 NUFFT
onto its own cells of the mirrored faces: no inverse crime. The transmit side is given
as the truth (the matrix transmit fit is tested in test_matrix.py).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from _shared import delay_and_correlation
from holoprobe.characterize import (
    MatrixFace,
    ReceiveConfig,
    characterize_matrix_receive,
    matrix_echo_delays,
    matrix_mirrored_faces,
)
from holoprobe.errors import InputError
from holoprobe.geometry import ArrayGeometry, Pose, plate_plane
from holoprobe.simulate import ArrayModel, mirror_points, simulate_echo, simulate_scan

C0 = 1481.0
D, TX, TY = 10e-3, math.radians(1.5), math.radians(-2.0)
POSE = Pose.from_degrees(0.8, -0.6, 1.2, (0.1e-3, -0.05e-3, 2e-3))
BAND = (1.5e6, 4.5e6)
RP = 0.78


def _reflect(points, distance, tx, ty):
    """Mirror across the plane through (0, 0, d) whose normal is e_z turned by tx/2
    about x, then by ty/2 about y (written here, not plate_plane's formula)."""
    a, b = ty / 2, tx / 2
    rx = np.array([[1, 0, 0], [0, math.cos(b), -math.sin(b)], [0, math.sin(b), math.cos(b)]])
    n = rx @ np.array([0.0, 0.0, 1.0])
    n = np.array([math.sin(a) * n[2], n[1], math.cos(a) * n[2]])
    return points - 2 * ((points - [0.0, 0.0, distance]) @ n)[:, None] * n


def test_plate_with_two_tilts_echo_paths_and_mirrored_faces():
    geo = ArrayGeometry.matrix(4, 3, 0.3e-3, 0.4e-3, 0.27e-3, 0.36e-3)
    p0, n = plate_plane(D, TY, TX)
    np.testing.assert_array_equal(p0, [0.0, 0.0, D])
    assert np.isclose(np.linalg.norm(n), 1.0)
    np.testing.assert_allclose(plate_plane(D, TY)[1], plate_plane(D, TY, 0.0)[1])
    pts = geo.positions
    np.testing.assert_allclose(mirror_points(pts, D, TY, TX), _reflect(pts, D, TX, TY),
                               atol=1e-15)
    # untilted, far field (Fresnel number 0.04): the path from the centre to the image,
    # plus a constant (the aperture's mean extra path, ⟨x² + y²⟩/(4d): t_c holds it)
    path = matrix_echo_delays(geo, D, 0.0, 0.0, sound_speed=C0, band=BAND) * C0
    far = np.sqrt(4 * D**2 + np.sum(pts**2, axis=1))
    np.testing.assert_allclose(path - path.mean(), far - far.mean(), atol=1e-7)
    assert path.mean() - far.mean() == pytest.approx(np.mean(np.sum(pts**2, axis=1))
                                                     / (4 * D), rel=0.05)
    # tilted: the far-field arrivals slope towards the image of the centre,
    # M(0) = 2 d n_z n: −n_x along x, −n_y along y (half the tilts; plate_plane's n)
    t = matrix_echo_delays(geo, D, TX, TY, sound_speed=C0, band=BAND)
    coef = np.linalg.lstsq(np.c_[np.ones(geo.count), pts[:, :2], pts[:, :2] ** 2,
                                 pts[:, 0] * pts[:, 1]], t, rcond=None)[0]
    assert coef[1] * C0 == pytest.approx(-math.sin(TY / 2) * math.cos(TX / 2), rel=1e-2)
    assert coef[2] * C0 == pytest.approx(math.sin(TX / 2), rel=1e-2)
    # the faces: reflected back they are the real cells, element by element
    surf, layout = matrix_mirrored_faces(geo, D, TX, TY, spacing=0.05e-3)
    real = geo.surface(0.05e-3, layout="grid")
    back = _reflect(surf.points, D, TX, TY)
    for e in range(geo.count):
        mine, theirs = back[surf.element == e], real.points[real.element == e]
        order = [np.lexsort(np.round(x.T * 1e9)) for x in (mine, theirs)]
        np.testing.assert_allclose(mine[order[0]], theirs[order[1]], atol=1e-15)
    np.testing.assert_allclose(layout.u, back[:, 0], atol=1e-15)
    assert np.isclose(layout.weights.sum(), 12 * 0.27e-3 * 0.36e-3)
    assert np.all(surf.normals @ n < -0.99)  # the image faces look back at the array
    with pytest.raises(InputError, match="matrix"):
        matrix_echo_delays(ArrayGeometry.linear(4, 0.3e-3, 0.25e-3, 2e-3), D, 0, 0,
                           sound_speed=C0, band=BAND)


def test_matrix_echo_arrival_model_holds_in_the_near_field():
    """The benchmark's 32 × 32 matrix (9.6 mm) and a plate at 15 mm: Fresnel number
    ~1.5, between near and far field. The tilt columns of the arrival model against
    the band-averaged group delay of the dense Rayleigh sum (3 × 3 points per element
    face, exact distances, 12 frequencies) at the images of every 13th element: within
    10 % (0.924 and 0.949 measured, correlation 0.98; the model serves as the pose fit's
    Jacobian, the refinement compares predicted pressures). The old far-field model (|M|/c0, half
    the tilts: 0.46-0.49) put the benchmark's d at 0.32 m (the receive projection then
    padded to 5184²: > 4 min CPU)."""
    geo = ArrayGeometry.matrix(32, 32, 0.3e-3, 0.3e-3, 0.27e-3, 0.27e-3)
    d, sub = 15e-3, np.arange(0, 1024, 13)
    src = geo.surface(0.09e-3 * 1.0001, layout="grid").points

    def dense(tx, ty):
        p0, n = plate_plane(d, ty, tx)
        img = geo.mirrored(p0, n).positions[sub]
        r = np.linalg.norm(img[:, None, :] - src[None, :, :], axis=2)
        num = den = 0.0
        for f in np.linspace(*BAND, 12):
            g = np.exp(2j * np.pi * f / C0 * r) / r
            u, v = g.sum(axis=1), (r * g).sum(axis=1) / C0
            num, den = num + np.real(v * np.conj(u)), den + np.abs(u) ** 2
        return num / den

    def far(tx, ty):
        p0, n = plate_plane(d, ty, tx)
        return np.linalg.norm(geo.mirrored(p0, n).positions[sub], axis=1) / C0

    def model(tx, ty):
        return matrix_echo_delays(geo, d, tx, ty, sound_speed=C0, band=BAND)[sub]

    h = 1e-3
    for k in range(2):
        lo, hi = [TX, TY], [TX, TY]
        lo[k] -= h
        hi[k] += h
        cols = [(f(*hi) - f(*lo)) / (2 * h) for f in (dense, model, far)]
        ref, mine, old = (c - c.mean() for c in cols)
        print(f"tilt {k}: model/dense {mine @ ref / (ref @ ref):.4f}, "
              f"far-field/dense {old @ ref / (ref @ ref):.4f}")
        assert mine @ ref / (ref @ ref) == pytest.approx(1.0, abs=0.1)
        assert np.corrcoef(mine, ref)[0, 1] > 0.97
        assert old @ ref / (ref @ ref) < 0.65  # the far-field model's half tilts


@pytest.fixture(scope="module")
def twin():
    model = ArrayModel.matrix(8).with_element_variation(
        amplitude_rms=0.05, delay_rms=2e-9, receive_gain_rms=0.05, dead=(3,), seed=1)
    scan, _ = simulate_scan(model, pose=POSE, size=(9e-3, 9e-3), step=(0.15e-3, 0.15e-3),
                            sampling_rate=40e6, n_samples=512, snr_db=40.0, seed=2,
                            calibration=None, points_per_wavelength=2)
    echo, truth = simulate_echo(model, plate_distance=D, virtual_tilt=TY, virtual_tilt_x=TX,
                                reflection_coefficient=RP, back_wall=True,
                                plate_thickness=6e-3, snr_db=40, seed=3, band=BAND,
                                points_per_wavelength=2, start_time=8e-6, n_samples=640,
                                sampling_rate=40e6)
    face = MatrixFace(model.array_geometry(), POSE, BAND)
    return model, scan, echo, truth, face


def test_matrix_receive_recovers_plate_pose_receive_ir_and_gains(twin):
    model, scan, echo, truth, face = twin
    assert truth.parameters["reflector"]["virtual_tilt_x_deg"] == pytest.approx(1.5)
    rx = characterize_matrix_receive(echo, face, scan, progress=False)
    vr, u = rx.receiver, rx.uncertainties
    err_d, err_x, err_y = vr.distance - D, vr.theta_x - TX, vr.theta_y - TY
    print(f"d {err_d * 1e6:+.1f} µm (σ {vr.distance_uncertainty * 1e6:.1f}), θx' "
          f"{math.degrees(err_x):+.4f}° (σ {math.degrees(u['theta_x']):.4f}°), θy' "
          f"{math.degrees(err_y):+.4f}° (σ {math.degrees(u['theta_y']):.4f}°), Rp "
          f"{rx.reflection_coefficient - RP:+.4f} (σ {rx.reflection_uncertainty:.4f})")
    assert abs(err_d) < 3 * vr.distance_uncertainty and vr.distance_uncertainty < 0.1e-3
    for err, sig in ((err_x, u["theta_x"]), (err_y, u["theta_y"])):
        assert abs(err) < 3 * sig and abs(math.degrees(err)) < 0.02
    _, n = plate_plane(vr.distance, vr.theta_y, vr.theta_x)
    np.testing.assert_allclose([vr.x0, vr.y0, vr.z0], 2 * vr.distance * n[2] * n)
    assert abs(rx.reflection_coefficient - RP) < max(3 * rx.reflection_uncertainty, 0.01)
    # the receive IR in absolute units (ADCL/(Pa·s)), against the twin's; its onset was
    # moved by ir_shift: on the echo clock it is off by what the distance error explains
    ir = rx.impulse_response
    lag, corr = delay_and_correlation(ir.ir, model.receive_ir, ir.sampling_rate, upsample=4)
    k = round(lag * ir.sampling_rate)
    a, b = ir.ir[max(k, 0):], model.receive_ir[max(-k, 0):]
    m = min(a.size, b.size)
    amp = float(np.dot(a[:m], b[:m]) / np.dot(b[:m], b[:m]))
    late = lag - rx.extras["ir_shift"]
    print(f"IR corr {corr:.4f}, amplitude {amp:.4f}, time {late * 1e9:+.1f} ns "
          f"(−2δd/c0 {-2 * err_d / C0 * 1e9:+.1f} ns)")
    assert corr >= 0.995
    assert amp == pytest.approx(1.0, abs=0.03)
    assert abs(late + 2 * err_d / C0) < 3e-9
    # per-element receive gains: absolute (gain × the IR's amplitude = the twin's g_e)
    # and relative to the mean, within 2 % and their σ
    g = np.asarray(model.receive_gains)
    live = g > 0
    sens = rx.sensitivity
    np.testing.assert_allclose(sens.amplitude[live] * amp, g[live], rtol=0.03)
    _check_relative_gains(sens, g, "matrix")
    assert rx.extras["array"] == "matrix" and rx.element_pressure.shape[0] == 64
    np.testing.assert_allclose(rx.extras["element_y"], face.geometry.positions[:, 1])


def test_matrix_receive_pose_sigma_holds_the_scan_noise_of_the_prediction(twin):
    """The scan's noise, forward-projected within the 30° guard angle, is correlated
    over neighbouring image elements and moves the whole fitted pose; the arrivals'
    residual scatter misses it (it under-covered ~2× before). Six fresh noise draws
    of the simulator (white in time, at the twin's 40 dB) on the noise-free scan,
    the same echo: the spread of (d, θx', θy') over them against the Monte-Carlo σ
    of :func:`prediction_noise_pose` (noise drawn on the spectrum, its level from the
    evanescent part) of one run. One pose step per run (``pose_iterations=1``, for
    time: ~8 s CPU)."""
    import dataclasses

    from holoprobe.simulate import add_noise

    model, _, echo, _, face = twin
    clean, _ = simulate_scan(model, pose=POSE, size=(9e-3, 9e-3), step=(0.15e-3, 0.15e-3),
                             sampling_rate=40e6, n_samples=512, snr_db=None, seed=2,
                             calibration=None, points_per_wavelength=2)
    poses, sigma = [], None
    for k in range(6):
        data = np.array(clean.data, dtype=float)
        add_noise(data, 40.0, np.random.default_rng(20 + k))
        rx = characterize_matrix_receive(
            echo, face, dataclasses.replace(clean, data=data),
            ReceiveConfig(pose_noise_draws=8 if k == 0 else 0, pose_iterations=1),
            progress=False)
        vr = rx.receiver
        poses.append((vr.distance, vr.theta_x, vr.theta_y))
        if k == 0:
            sigma = np.array(rx.extras["pose_refinement"]["prediction_noise"])
            total = np.array([vr.distance_uncertainty, rx.uncertainties["theta_x"],
                              rx.uncertainties["theta_y"]])
    spread = np.std(poses, axis=0, ddof=1)
    ratio = spread / sigma
    print(f"scan-noise spread d {spread[0] * 1e6:.1f} µm, θx' {np.degrees(spread[1]):.4f}°, "
          f"θy' {np.degrees(spread[2]):.4f}°; Monte-Carlo σ {sigma[0] * 1e6:.1f} µm, "
          f"{np.degrees(sigma[1]):.4f}°, {np.degrees(sigma[2]):.4f}°; ratio {ratio}")
    assert 0.55 < float(np.sqrt(np.mean(ratio**2))) < 1.6
    assert np.all(spread < 2.0 * total)


def test_matrix_receive_refuses_bad_inputs(twin):
    _, scan, echo, _, face = twin
    from holoprobe.measurement import EchoRecording

    short = EchoRecording(echo.rf[:63], echo.sampling_rate, echo.start_time, echo.unit,
                          echo.drive, None, echo.medium)
    with pytest.raises(InputError, match="64 channels"):
        characterize_matrix_receive(short, face, scan, ReceiveConfig())
    with pytest.raises(InputError, match="matrix"):
        MatrixFace(ArrayGeometry.linear(8, 0.3e-3, 0.27e-3, 2e-3), POSE, BAND)
    with pytest.raises(InputError, match="no lens"):
        MatrixFace(face.geometry, POSE, BAND, focus=20e-3)


def test_characterize_with_an_echo_runs_the_matrix_receive(twin, tmp_path):
    """workflow.characterize(scan, echo=...) on a matrix scan: the transmit fit gives
    the grid and the pose (MatrixFace.from_transmit), the summary holds 'receive' and
    elements.receive_gain with σ, the virtual transducer the receive IR and gains.

    The face is placed by the element map's defocus δ, not at the transmit pose's
    z0 (the onset convention: 0.62 mm farther on this twin, c0 × the Gaussian IR's
    onset delay). Before, the virtual receiver inherited that offset: d was +381 µm
    off (σ 34 µm), θx' +0.028°, θy' −0.054°; now the scan-to-face distance is within
    a few µm of the twin's and d, θx', θy' as with the true face."""
    from holoprobe.characterize import MatrixFace
    from holoprobe.workflow import characterize

    model, scan, echo, _, _ = twin
    run = characterize(scan, echo=echo, progress=False)
    assert run.receive is not None and run.receive.extras["array"] == "matrix"
    s = run.summary
    vr, u = run.receive.receiver, run.receive.uncertainties
    face = MatrixFace.from_transmit(run.transmit)
    err_z = face.scan_pose.origin[2] - POSE.origin[2]
    print(f"workflow: face-to-scan {err_z * 1e6:+.2f} µm (σ {face.face_uncertainty * 1e6:.2f}), "
          f"transmit z0 {(run.transmit.pose.origin[2] - POSE.origin[2]) * 1e3:+.3f} mm; "
          f"d {(vr.distance - D) * 1e6:+.1f} µm (σ {vr.distance_uncertainty * 1e6:.1f}), θx' "
          f"{math.degrees(vr.theta_x - TX):+.4f}°, θy' {math.degrees(vr.theta_y - TY):+.4f}°")
    assert abs(err_z) < max(3 * face.face_uncertainty, 5e-6) and face.face_uncertainty < 10e-6
    assert abs(vr.distance - D) < 3 * vr.distance_uncertainty < 0.2e-3
    for err, sig in ((vr.theta_x - TX, u["theta_x"]), (vr.theta_y - TY, u["theta_y"])):
        assert abs(math.degrees(err)) < 0.03 and abs(err) < 3 * sig
    assert s["receive"]["theta_x_deg"] == pytest.approx(math.degrees(vr.theta_x))
    assert s["receive"]["sensor_y0"] == pytest.approx(vr.y0)
    assert s["uncertainty"]["receive"]["sensor_y0"] > 0
    assert s["uncertainty"]["receive"]["theta_x_deg"] > 0
    gain = np.asarray(s["elements"]["receive_gain"], dtype=float)
    u_gain = np.asarray(s["uncertainty"]["elements"]["receive_gain"], dtype=float)
    g = np.asarray(model.receive_gains)
    live = g > 0
    rel, want = gain / gain[live].mean(), g / g[live].mean()
    err = (rel - want)[live]
    print(f"workflow gains: rms {np.sqrt(np.mean(err**2)) * 100:.2f} %, max "
          f"{np.max(np.abs(err)) * 100:.2f} %")
    assert np.all(np.abs(err) < 0.02) and np.all(u_gain[live] > 0)
    # the grid page gains the receive gains as a fourth picture
    figs = dict(run.figures())["Element grid (matrix array)"]
    assert len(figs) == 4
    np.testing.assert_allclose(figs[3].axes[0].collections[0].get_array(),
                               run.receive.sensitivity.amplitude)
    vt = run.virtual_transducer
    assert vt.receive_impulse_response is not None
    assert vt.array is not None and vt.array.grid_shape == (8, 8)


def test_band_noise_has_the_statistics_of_white_noise_at_those_bins_without_the_samples():
    """The Monte-Carlo of prediction_noise_pose draws the scan noise directly on the
    delay fit's bins (review: it drew points × samples white noise and transformed it,
    ~1.3 GB per draw on large scans). Against white noise on the samples, zero-padded
    and transformed by to_frequency: the same covariance and pseudo-covariance of the
    bins (Monte-Carlo, 3 % of the diagonal), and a draw allocates ~points × 2 nb
    numbers, not points × samples."""
    import tracemalloc

    from holoprobe.characterize._matrix_receive import band_noise, band_noise_factor
    from holoprobe.signal import to_frequency

    nt, n_rec, bins = 200, 512, np.array([20, 21, 25, 40])
    scale = np.array([1.0, 0.5, 2.0, 1.5])
    factor = band_noise_factor(nt, n_rec, bins, scale)
    rng = np.random.default_rng(4)
    n = 40000
    new = band_noise(rng, n, factor)
    old = to_frequency(rng.standard_normal((n, nt)), n=n_rec)[:, bins] * scale
    bound = 0.03 * nt * np.outer(scale, scale)
    for conj in (np.conj, lambda v: v):  # covariance, pseudo-covariance
        got = np.einsum("ni,nj->ij", new, conj(new)) / n
        ref = np.einsum("ni,nj->ij", old, conj(old)) / n
        assert np.all(np.abs(got - ref) < bound)
    # E|X_b|² = nt scale_b² exactly for white noise
    np.testing.assert_allclose(np.mean(np.abs(new) ** 2, axis=0), nt * scale**2, rtol=0.03)
    big = 2048
    wide = band_noise_factor(big, 4096, bins, scale)
    tracemalloc.start()
    band_noise(rng, 5000, wide)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 5000 * 2 * bins.size * 8 * 4  # the old draw: 5000 × 2048 × 24 bytes


def test_matrix_receive_plate_in_the_near_field_has_an_honest_distance(twin):
    """The plate 1.5 mm from the 8 × 8 matrix: the image grid lies in its near field
    (Fresnel number 1.9), where the arrival pattern the element-delay estimator sees
    hardly depends on d and not as the arrival model's group delay does. The d column
    of the pose fit is then measured on a second prediction (and rescaled by the
    secant of the d steps); d within 3 σ, σ including the refinement's last step.
    Before, the model's column set σ(d) ≈ 30× too small for the d error."""
    from holoprobe.characterize._matrix_receive import fresnel_number

    model, scan, _, _, face = twin
    d_nf = 1.5e-3
    echo, _ = simulate_echo(model, plate_distance=d_nf, virtual_tilt=TY, virtual_tilt_x=TX,
                            reflection_coefficient=RP, back_wall=True, plate_thickness=6e-3,
                            snr_db=40, seed=5, band=BAND, points_per_wavelength=2,
                            start_time=-2e-6, n_samples=640, sampling_rate=40e6)
    assert fresnel_number(face.geometry, d_nf, BAND, C0) > 1.5
    # the echo arrives 3.7 µs after the emission: before echo_search_window's earliest
    # start, so the window is given (the back wall's echo at 5.7 µs left out)
    rx = characterize_matrix_receive(echo, face, scan, ReceiveConfig(
        pose_noise_draws=0, window=(-2e-6, 5e-6)), progress=False)
    vr, u = rx.receiver, rx.uncertainties
    err_d = vr.distance - d_nf
    ref = rx.extras["pose_refinement"]
    print(f"near field: d {err_d * 1e6:+.1f} µm (σ {vr.distance_uncertainty * 1e6:.1f}), "
          f"θx' {math.degrees(vr.theta_x - TX):+.4f}° (σ {math.degrees(u['theta_x']):.4f}°), "
          f"θy' {math.degrees(vr.theta_y - TY):+.4f}° (σ {math.degrees(u['theta_y']):.4f}°), "
          f"history {[(round((h[0] - d_nf) * 1e6, 1)) for h in ref['history']]}")
    assert ref.get("distance_column")
    assert abs(err_d) < 3 * vr.distance_uncertainty
    for err, sig in ((vr.theta_x - TX, u["theta_x"]), (vr.theta_y - TY, u["theta_y"])):
        assert abs(err) < 3 * sig and abs(math.degrees(err)) < 0.05


def test_matrix_receive_near_field_distance_does_not_depend_on_the_arrival_models_band(twin):
    """The arrival fit starts d from the Fresnel arrival model averaged over the face's
    band, which the transmit's noise sets: on the 8 × 8 at 1.5 mm it started d 0.65 mm
    long with a 1.5–4.5 MHz face and 1.8 mm long with 2–4 MHz, where the Fresnel
    number (< 1) sent the refinement down the far-field path (the model's d column): it
    ended 633 µm off at σ 28 µm (22 σ). The near-field test is now made at the current
    d, the d column measured again when d has moved a quarter of its chord, and the
    near-field path steps on while d moves by more than σ(d): both bands end within
    ~15 µm of the plate and of each other."""
    model, scan, _, _, face = twin
    d_nf = 1.5e-3
    echo, _ = simulate_echo(model, plate_distance=d_nf, virtual_tilt=TY, virtual_tilt_x=TX,
                            reflection_coefficient=RP, back_wall=True, plate_thickness=6e-3,
                            snr_db=40, seed=5, band=BAND, points_per_wavelength=2,
                            start_time=-2e-6, n_samples=640, sampling_rate=40e6)
    got = []
    for band in ((1.5e6, 4.5e6), (2.0e6, 4.0e6)):
        rx = characterize_matrix_receive(
            echo, MatrixFace(face.geometry, face.scan_pose, band), scan,
            ReceiveConfig(pose_noise_draws=0, window=(-2e-6, 5e-6)), progress=False)
        vr, ref = rx.receiver, rx.extras["pose_refinement"]
        err = vr.distance - d_nf
        print(f"band {band}: d {err * 1e6:+.1f} µm (σ {vr.distance_uncertainty * 1e6:.1f}), "
              f"history {[round((h[0] - d_nf) * 1e6, 1) for h in ref['history']]}")
        assert ref["distance_column"]
        assert abs(err) < 3 * vr.distance_uncertainty and abs(err) < 50e-6
        got.append(vr.distance)
    assert abs(got[0] - got[1]) < 20e-6


def test_matrix_receive_onset_does_not_hang_on_the_refined_poses_offset(twin):
    """After the model-based refinement the pose's common delay t_c belongs to its
    linearised model (a d column measured near the final d), not to the echo's absolute
    arrival: on the 32 × 32 seed 2 at 15 mm it put the echo 1.7 µs early, the onset's
    noise segment then held the record's first samples only and the onset search failed
    ("no zero crossing precedes the pulse"). The arrival is now the model at the pose
    plus the measured arrivals' median offset from it: the same receiver whatever the
    pose's offset."""
    from holoprobe.characterize import fit_matrix_echo_pose
    from holoprobe.characterize._matrix_receive import _receiver
    from holoprobe.characterize._virtual_receiver import echo_arrivals, echo_search_window

    _, _, echo, _, face = twin
    rc = ReceiveConfig()
    fs = echo.sampling_rate
    window = echo_search_window(echo.rf, fs, start_time=echo.start_time)
    arrivals = echo_arrivals(echo.rf, fs, start_time=echo.start_time, window=window,
                             method=rc.arrival_method, noise_guard=rc.noise_guard)
    pose = fit_matrix_echo_pose(face.geometry, *arrivals, sound_speed=C0, band=face.band)
    onsets = [_receiver(dataclasses.replace(pose, offset=pose.offset + shift), echo, face, C0,
                        window, rc, arrivals).onset for shift in (0.0, -1.7e-6, 1.0e-6)]
    print("onsets (µs)", np.round(np.array(onsets) * 1e6, 5))
    assert onsets[1] == onsets[0] and onsets[2] == onsets[0]


def test_matrix_prediction_on_the_mirrored_faces_holds_no_image_of_the_padded_scan(twin):
    """The element pressure predicted on the mirrored faces (plate 10 mm, both tilts)
    against the same scan projected with a 70° guard, i.e. its periodic images 4× as
    far (729² instead of 200² points), without the image taper, at NUFFT tolerance
    1e-6: a different discretisation of the same propagation. With the 30° guard the
    images reach the faces; the image taper (``receive.image_taper``, now used by the
    matrix receive) fades out the waves that only they send. Before, untapered: 4.6 %
    of the peak off, 7.2 % rms on the worst element; tapered 0.19 % and 0.34 %."""
    from holoprobe.characterize import CharacterizationConfig, matrix_sensor_predictor
    from holoprobe.characterize._convex_receive import _AtDistance, faces_sensor_predictor

    _, scan, echo, _, face = twin
    cfg = CharacterizationConfig()
    predict = matrix_sensor_predictor(echo, face, scan, D, config=cfg, receive=ReceiveConfig())
    spacing = predict.projection.spacing
    got, start = predict.on_surface(*matrix_mirrored_faces(face.geometry, D, TX, TY,
                                                           spacing=spacing))

    def sample(dist, step):
        return matrix_mirrored_faces(face.geometry, dist, 0.0, 0.0, spacing=step)

    wide = faces_sensor_predictor(echo, _AtDistance(face, D), scan, sample, config=cfg,
                                  receive=ReceiveConfig(guard_angle_deg=70.0, eps=1e-6))
    ref, ref_start = wide.on_surface(*matrix_mirrored_faces(face.geometry, D, TX, TY,
                                                           spacing=spacing))
    assert wide.plan.shape[0] > 3 * predict.plan.shape[0]
    assert start == pytest.approx(ref_start, abs=1e-12)
    diff = got - ref
    per_element = np.linalg.norm(diff, axis=1) / np.linalg.norm(ref, axis=1)
    print(f"prediction vs 70° guard: {np.abs(diff).max() / np.abs(ref).max():.2e} of the "
          f"peak, worst element {per_element.max():.2e} rms")
    assert np.abs(diff).max() < 0.01 * np.abs(ref).max()
    assert per_element.max() < 0.01


def test_sparse_matrix_receive_gains_within_two_percent():
    """A sparse matrix (40 of the 8 × 8 positions, density-tapered random layout, one
    dead) receives through the present elements' mirrored faces; the twin of the
    module with the holes. Per-element receive gains (relative) against the twin's
    within 2 % and 3 σ, the plate pose within 3 σ. Before the image taper of the
    matrix predictions the gains were 1.87 % rms, 5.14 % worst (3.7 σ) on this layout
    (1.1–1.9 % rms, 2.4–5.1 % worst on three layouts); now 0.59 / 1.33 %."""
    from holoprobe.geometry import sparse_layout

    mask = sparse_layout(8, 8, 40, layout="random", taper=0.5, seed=1)
    model = ArrayModel.matrix(8, active=mask).with_element_variation(
        amplitude_rms=0.05, delay_rms=2e-9, receive_gain_rms=0.05, dead=(3,), seed=1)
    scan, _ = simulate_scan(model, pose=POSE, size=(9e-3, 9e-3), step=(0.15e-3, 0.15e-3),
                            sampling_rate=40e6, n_samples=512, snr_db=40.0, seed=2,
                            calibration=None, points_per_wavelength=2)
    echo, _ = simulate_echo(model, plate_distance=D, virtual_tilt=TY, virtual_tilt_x=TX,
                            reflection_coefficient=RP, back_wall=True, plate_thickness=6e-3,
                            snr_db=40, seed=3, band=BAND, points_per_wavelength=2,
                            start_time=8e-6, n_samples=640, sampling_rate=40e6)
    face = MatrixFace(model.array_geometry(), POSE, BAND)
    assert face.geometry.layout == "sparse" and face.geometry.count == 40
    rx = characterize_matrix_receive(echo, face, scan, progress=False)
    vr, u = rx.receiver, rx.uncertainties
    for err, sig in ((vr.distance - D, vr.distance_uncertainty),
                     (vr.theta_x - TX, u["theta_x"]), (vr.theta_y - TY, u["theta_y"])):
        assert abs(err) < 3 * sig
    _check_relative_gains(rx.sensitivity, np.asarray(model.receive_gains), "sparse")


def test_matrix_receive_near_field_tilts_carry_the_hidden_steering_of_the_transmit_face():
    """A delay trend of the elements steers the beam like a tilt of the scan plane; the
    transmit puts it into the scan pose (the acoustic-axis convention), so a face from
    the transmit fit (:meth:`MatrixFace.from_transmit`) lies in a frame turned by the
    true delays' trend. A plate in the near field (1.5 mm from the 8 × 8, Fresnel
    number 1.9) reflects that beam: the fitted θx', θy' follow the frame. 10 ns rms
    element delays (trend +0.145°, −0.221° for this draw): θx' +0.18°, θy' −0.20° off
    the twin's plate. Before, σ (0.024° here) held none of it (7σ); now the face's
    hidden-steering σ (:func:`steering_uncertainty` of the map's delays along y and x)
    joins σ(θx'), σ(θy') on the near-field path."""
    from holoprobe.workflow import characterize

    model = ArrayModel.matrix(8).with_element_variation(
        amplitude_rms=0.05, delay_rms=10e-9, receive_gain_rms=0.05, dead=(3,), seed=1)
    scan, _ = simulate_scan(model, pose=POSE, size=(9e-3, 9e-3), step=(0.15e-3, 0.15e-3),
                            sampling_rate=40e6, n_samples=512, snr_db=40.0, seed=2,
                            calibration=None, points_per_wavelength=2)
    d_nf = 1.5e-3
    echo, _ = simulate_echo(model, plate_distance=d_nf, virtual_tilt=TY, virtual_tilt_x=TX,
                            reflection_coefficient=RP, back_wall=True, plate_thickness=6e-3,
                            snr_db=40, seed=5, band=BAND, points_per_wavelength=2,
                            start_time=-2e-6, n_samples=640, sampling_rate=40e6)
    face = MatrixFace.from_transmit(characterize(scan, progress=False).transmit)
    # the trend of independent 10 ns delays over 8 × 8 at 0.3 mm: c0·σ_τ/√Σ(x − x̄)²
    spread = C0 * 10e-9 / math.sqrt(64 * 0.3e-3**2 * 63 / 12)
    np.testing.assert_allclose(face.steering, spread, rtol=0.3)
    rx = characterize_matrix_receive(echo, face, scan, ReceiveConfig(
        pose_noise_draws=0, window=(-2e-6, 5e-6)), progress=False)
    vr, u = rx.receiver, rx.uncertainties
    assert rx.extras["pose_refinement"]["distance_column"]
    errs = (vr.theta_x - TX, vr.theta_y - TY)
    print(f"θx' {math.degrees(errs[0]):+.4f}° (σ {math.degrees(u['theta_x']):.4f}°), θy' "
          f"{math.degrees(errs[1]):+.4f}° (σ {math.degrees(u['theta_y']):.4f}°), steering σ "
          f"{np.degrees(face.steering)}")
    for err, sig in zip(errs, (u["theta_x"], u["theta_y"]), strict=True):
        assert abs(err) < 3 * sig


def _check_relative_gains(sens, gains, label: str) -> None:
    """Receive gains relative to the live elements' mean within 2 % and 3σ of the
    truth's; element 3 (dead in these twins) receives nothing."""
    live = gains > 0
    err = (sens.amplitude / sens.amplitude[live].mean() - gains / gains[live].mean())[live]
    print(f"{label} receive gains: rms {np.sqrt(np.mean(err**2)) * 100:.2f} %, max "
          f"{np.max(np.abs(err)) * 100:.2f} %, max |err|/σ "
          f"{np.max(np.abs(err) / sens.amplitude_uncertainty[live]):.2f}")
    assert np.all(np.abs(err) < 0.02)
    assert np.all(np.abs(err) < 3 * sens.amplitude_uncertainty[live])
    assert abs(sens.amplitude[3]) < 0.05  # the dead element receives nothing
