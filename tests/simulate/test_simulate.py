"""Tests of holoprobe.simulate: the synthetic scan against analytic fields and an
independent Rayleigh sum, the lens, the edge mode, the noise and the files."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.integrate import quad

from _shared import gaussian_ir
from holoprobe.geometry import Medium, PlaneGrid, Pose, Surface
from holoprobe.measurement import DriveSignal
from holoprobe.simulate import (
    ArrayModel,
    EdgeMode,
    noise_std_for_snr,
    simulate_scan,
    write_simulation,
)

MEDIUM = Medium()
FS_IR = 50e6
FC, SIGMA, TC = 1.5e6, 0.3e-6, 2.0e-6  # Gaussian test pulse: carrier, std, centre
IR = gaussian_ir(FS_IR, FC, SIGMA, TC)


def velocity_spectrum(f: np.ndarray, fc: float = FC, sigma: float = SIGMA,
                      tc: float = TC) -> np.ndarray:
    """Analytic continuous spectrum (conjugate convention) of u = IR·(1/fs)/(ρ0c0),
    i.e. the IR convolved with a one-sample unit drive: the test's own truth."""
    g = sigma * math.sqrt(2 * math.pi) / 2 * (np.exp(-2 * (np.pi * sigma * (f - fc)) ** 2)
                                              + np.exp(-2 * (np.pi * sigma * (f + fc)) ** 2))
    return g * np.exp(2j * np.pi * f * tc) / FS_IR / MEDIUM.impedance


def test_model(**kw) -> ArrayModel:
    base = dict(element_count=1, pitch=2e-3, element_width=2e-3, element_height=0.3e-3,
                lens_focus=math.inf, transmit_ir=IR, receive_ir=IR,
                ir_sampling_rate=FS_IR, drive=DriveSignal([1.0], FS_IR))
    base.update(kw)
    return ArrayModel(**base)


test_model.__test__ = False  # a factory, not a test


def record_spectrum(data: np.ndarray, fs: float, start_time: float, f: float) -> np.ndarray:
    """Continuous spectrum of records (..., nt) at f, computed here with numpy.fft."""
    n = data.shape[-1]
    k = round(f * n / fs)
    assert abs(k * fs / n - f) < 1e-6
    return np.conj(np.fft.rfft(data, axis=-1)[..., k]) / fs * np.exp(2j * np.pi * f
                                                                      * start_time)


def test_single_element_far_field_follows_sinc_directivity():
    model = test_model()
    w, h = model.element_width, model.element_height
    z = 0.1
    x = np.linspace(-0.05, 0.05, 21)
    grid = PlaneGrid(x, [0.0], Pose(origin=(0.0, 0.0, z)))
    fs, n, t0 = 20e6, 800, 60e-6
    scan, _ = simulate_scan(model, grid=grid, sampling_rate=fs, n_samples=n, start_time=t0,
                            calibration=None, snr_db=None, dtype=np.float64)
    p = record_spectrum(scan.data[:, 0, :], fs, t0, FC)
    k = 2 * np.pi * FC / MEDIUM.sound_speed
    r = np.hypot(x, z)
    s = x / r
    # Fraunhofer: |P| = k ρ0c0 |U| w h /(2π R) · |sinc(k w sinθ / 2)|  (rigid baffle)
    expected = (k * MEDIUM.impedance * abs(velocity_spectrum(np.array(FC))[()]) * w * h
                / (2 * np.pi * r) * np.abs(np.sinc(k * w * s / 2 / np.pi)))
    assert np.max(np.abs(np.abs(p) - expected)) < 0.01 * expected.max()
    main = np.abs(k * w * s / 2) < 2.0
    np.testing.assert_allclose(np.abs(p[main]), expected[main], rtol=0.01)


def _edge_wave_integral(z: float, a: float, b: float, k: float) -> complex:
    """On-axis field of a baffled rectangular piston / (ρ0c0U), exact (edge-wave form):
    e^{ikz} − (1/2π) ∫ e^{ik√(z² + ρmax(φ)²)} dφ, ρmax = min(a/|cos φ|, b/|sin φ|)."""
    phi_c = math.atan2(b, a)

    def edge(phi: float, part) -> float:
        rho = a / math.cos(phi) if phi < phi_c else b / math.sin(phi)
        return part(np.exp(1j * k * math.hypot(z, rho)))

    total = 0j
    for part, unit in ((np.real, 1), (np.imag, 1j)):
        for lo, hi in ((0.0, phi_c), (phi_c, math.pi / 2)):
            total += unit * quad(edge, lo, hi, args=(part,), limit=400, epsabs=1e-12)[0]
    return complex(np.exp(1j * k * z) - 4 * total / (2 * math.pi))


def test_rectangular_piston_on_axis_matches_exact_edge_wave_integral():
    w, h = 4e-3, 3e-3
    model = test_model(pitch=w, element_width=w, element_height=h)
    z = np.array([3e-3, 6e-3, 12e-3])
    pts = np.stack([np.zeros(3), np.zeros(3), z], axis=-1)
    grid_p = [PlaneGrid([0.0], [0.0], Pose(origin=tuple(p))) for p in pts]
    fs, n = 20e6, 400
    k = 2 * np.pi * FC / MEDIUM.sound_speed
    u = velocity_spectrum(np.array(FC))[()]
    for zi, g in zip(z, grid_p, strict=True):
        scan, _ = simulate_scan(model, grid=g, sampling_rate=fs, n_samples=n,
                                calibration=None, snr_db=None, dtype=np.float64)
        p = record_spectrum(scan.data[0, 0], fs, 0.0, FC)
        exact = MEDIUM.impedance * u * _edge_wave_integral(zi, w / 2, h / 2, k)
        assert abs(p - exact) < 0.01 * abs(exact), (zi, p, exact)


def test_scan_agrees_with_independent_dense_rayleigh_sum():
    from holoprobe.propagation import rayleigh_integral

    F = 0.03
    model = test_model(element_count=2, pitch=1.2e-3, element_width=1.0e-3,
                       element_height=4e-3, lens_focus=F, apodization=[1.0, 0.5],
                       delays=[0.0, 0.2e-6])
    pose = Pose.from_degrees(3.0, -5.0, 10.0, (0.4e-3, -0.3e-3, 4e-3))
    grid = PlaneGrid.centered(5, 4, 1e-3, 1.5e-3, pose)
    fs, n = 20e6, 400
    scan, truth = simulate_scan(model, grid=grid, sampling_rate=fs, n_samples=n,
                                calibration=None, snr_db=None, dtype=np.float64)
    # independent source: a different (finer, offset-free) midpoint grid built here
    step = truth.parameters["synthesis"]["source_spacing_m"] / 2.3
    pts, vel_tau, amp = [], [], []
    for e, xc in enumerate([-0.6e-3, 0.6e-3]):
        nx, ny = math.ceil(1.0e-3 / step), math.ceil(4e-3 / step)
        xs = xc + ((np.arange(nx) + 0.5) / nx - 0.5) * 1.0e-3
        ys = ((np.arange(ny) + 0.5) / ny - 0.5) * 4e-3
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        pts.append(np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], -1))
        tau = (math.hypot(2e-3, F) - np.hypot(Y.ravel(), F)) / MEDIUM.sound_speed
        vel_tau.append(tau + [0.0, 0.2e-6][e])
        amp.append(np.full(X.size, [1.0, 0.5][e]) * (1e-3 / nx) * (4e-3 / ny))
    pts, tau, area = np.concatenate(pts), np.concatenate(vel_tau), np.concatenate(amp)
    src = Surface(pts, np.tile([0, 0, 1.0], (len(pts), 1)), area)
    f = np.array([1.0e6, 1.5e6, 2.0e6])
    v = velocity_spectrum(f)[None, :] * np.exp(2j * np.pi * np.outer(tau, f))
    ref = rayleigh_integral(v, src, grid.to_surface(), f, MEDIUM, kernel="fwd_vp",
                            backend="numpy")
    got = np.stack([record_spectrum(scan.data.reshape(-1, n), fs, 0.0, fi) for fi in f], -1)
    err = np.abs(got - ref).max() / np.abs(ref).max()
    assert err < 5e-3


def test_edge_mode_is_antisymmetric_in_elevation_and_silent_on_the_midplane():
    grid = PlaneGrid.centered(3, 5, 0.8e-3, 0.8e-3, Pose(origin=(0, 0, 2e-3)))
    # a pulse without DC content, so that the band edges carry nothing and the two runs
    # (whose synthesis windows differ) give the same field without the mode
    ir = gaussian_ir(FS_IR, 2.0e6, 0.4e-6, 2.0e-6)
    base = test_model(element_count=2, pitch=1e-3, element_width=0.9e-3, element_height=3e-3,
                      transmit_ir=ir, receive_ir=ir)
    kw = dict(grid=grid, sampling_rate=20e6, n_samples=300, calibration=None, snr_db=None,
              dtype=np.float64, band=(0.1e6, 6e6))
    clean, _ = simulate_scan(base, **kw)
    em = EdgeMode(amplitude=0.3, frequency=3.3e6, cycles=3, phase_speed=1000.0,
                  delay=1e-6, outside_extent=0.5e-3)
    with_mode, truth = simulate_scan(base.replace(edge_mode=em), **kw)
    d = with_mode.data - clean.data
    assert np.abs(d).max() > 0.05 * np.abs(clean.data).max()
    assert np.abs(d[:, 2]).max() < 1e-5 * np.abs(d).max()  # the plane y = 0
    np.testing.assert_allclose(d[:, ::-1], -d, atol=1e-5 * np.abs(d).max())
    assert truth.parameters["probe"]["edge_mode"]["frequency_hz"] == 3.3e6
    # its spectrum peaks near the 3.3 MHz carrier
    spec = np.abs(np.fft.rfft(d, axis=-1)).sum(axis=(0, 1))
    f_peak = np.argmax(spec) * 20e6 / 300
    assert abs(f_peak - 3.3e6) < 0.3e6


def test_noise_has_the_requested_peak_snr_and_is_white():
    model = test_model()
    grid = PlaneGrid.centered(6, 5, 0.5e-3, 0.5e-3, Pose(origin=(0, 0, 3e-3)))
    kw = dict(grid=grid, sampling_rate=20e6, n_samples=512, calibration="default", seed=7)
    clean, _ = simulate_scan(model, snr_db=None, **kw)
    for snr in (20.0, 35.0):
        noisy, truth = simulate_scan(model, snr_db=snr, **kw)
        noise = noisy.data.astype(float) - clean.data
        measured = 20 * np.log10(np.abs(clean.data).max() / noise.std())
        assert abs(measured - snr) < 0.5
        assert truth.parameters["noise"]["sigma"] == pytest.approx(
            noise_std_for_snr(clean.data, snr))
        flat = noise.reshape(-1, 512)
        lag1 = np.mean(flat[:, 1:] * flat[:, :-1]) / np.mean(flat**2)
        assert abs(lag1) < 0.05
        assert abs(noise.mean()) < 5 * noise.std() / math.sqrt(noise.size)


def test_quantisation_steps_and_voltage_units():
    model = test_model()
    grid = PlaneGrid.centered(2, 2, 0.5e-3, 0.5e-3, Pose(origin=(0, 0, 3e-3)))
    scan, truth = simulate_scan(model, grid=grid, sampling_rate=20e6, n_samples=256,
                                snr_db=30, quantization_bits=8, seed=1)
    lsb = truth.parameters["noise"]["quantization_step"]
    levels = scan.data / lsb
    np.testing.assert_allclose(levels, np.round(levels), atol=1e-3)
    assert len(np.unique(np.round(levels))) <= 256
    assert scan.quantity == "voltage" and scan.calibration is not None


@pytest.mark.parametrize("fmt", ["native", "reference-mat"])
def test_scan_files_round_trip_in_both_formats(tmp_path, fmt):
    from holoprobe.io import read_reference_scan, read_scan

    model = test_model(element_count=2, pitch=1e-3, element_width=0.9e-3)
    grid = PlaneGrid.centered(4, 3, 0.5e-3, 0.4e-3, Pose(origin=(0, 0, 3e-3)))
    scan, truth = simulate_scan(model, grid=grid, sampling_rate=20e6, n_samples=128,
                                start_time=1e-6, seed=3)
    files = write_simulation(tmp_path, scan, truth, format=fmt)
    assert all(p.exists() for p in files)
    back = read_scan(tmp_path / "scan.h5") if fmt == "native" else read_reference_scan(
        tmp_path / "ScanData.mat")
    if fmt == "native":
        np.testing.assert_array_equal(back.data, scan.data)
        assert back.start_time == scan.start_time
    else:
        np.testing.assert_allclose(back.data, scan.data, rtol=1e-6, atol=0)
    np.testing.assert_allclose(back.grid.x, scan.grid.x)
    np.testing.assert_allclose(back.grid.y, scan.grid.y)
    assert back.sampling_rate == pytest.approx(scan.sampling_rate)
    assert back.probe.element_count == 2
    np.testing.assert_allclose(back.calibration.sensitivity, scan.calibration.sensitivity)
    saved = json.loads((tmp_path / "truth.json").read_text())
    assert saved["scan_pose"]["z0_m"] == pytest.approx(3e-3)
    assert saved["noise"]["seed"] == 3


def test_position_jitter_shifts_each_trace_by_its_true_path_change():
    # single small element far away: a point-like source, so a stage offset δ changes
    # the phase by k·(r̂·δ) (r̂ the unit vector from the source to the scan point)
    model = test_model(pitch=0.2e-3, element_width=0.2e-3, element_height=0.2e-3)
    z = 0.02
    grid = PlaneGrid(np.linspace(-6e-3, 6e-3, 7), np.array([-3e-3, 0.0, 3e-3]),
                     Pose(origin=(0.0, 0.0, z)))
    fs, n, t0 = 20e6, 600, 5e-6
    kw = dict(grid=grid, sampling_rate=fs, n_samples=n, start_time=t0, calibration=None,
              snr_db=None, dtype=np.float64)
    clean, _ = simulate_scan(model, **kw)
    moved, truth = simulate_scan(model, position_jitter=(5e-6, 3e-6, 8e-6), seed=3, **kw)
    delta = truth.arrays["position_errors"]  # (nx, ny, 3) along u, v, w (= x, y, z here)
    assert delta.shape == (7, 3, 3)
    X, Y = np.meshgrid(grid.x, grid.y, indexing="ij")
    r = np.sqrt(X**2 + Y**2 + z**2)
    path = (X * delta[..., 0] + Y * delta[..., 1] + z * delta[..., 2]) / r
    k = 2 * np.pi * FC / MEDIUM.sound_speed
    ratio = record_spectrum(moved.data, fs, t0, FC) / record_spectrum(clean.data, fs, t0, FC)
    np.testing.assert_allclose(np.angle(ratio), k * path, atol=2e-3)
    rms = truth.parameters["scan_grid"]["position_jitter_rms_m"]
    assert len(rms) == 3 and 1e-6 < rms[2] < 20e-6
    np.testing.assert_array_equal(moved.grid.x, clean.grid.x)  # the file keeps the nominal grid


def test_dead_element_removes_exactly_its_own_field_and_truth_lists_it():
    base = test_model(element_count=3, pitch=1e-3, element_width=0.9e-3,
                      element_height=2e-3)
    grid = PlaneGrid.centered(5, 3, 1e-3, 1e-3, Pose(origin=(0.0, 0.0, 5e-3)))
    kw = dict(grid=grid, sampling_rate=20e6, n_samples=300, calibration=None, snr_db=None,
              dtype=np.float64)
    full, _ = simulate_scan(base, **kw)
    dead = base.with_element_variation(dead=[1])
    without, truth = simulate_scan(dead, **kw)
    only, _ = simulate_scan(base.replace(apodization=[0.0, 1.0, 0.0]), **kw)
    # linearity of the radiated field: all = (all but element 1) + (element 1 alone)
    np.testing.assert_allclose(without.data + only.data, full.data,
                               atol=1e-6 * np.abs(full.data).max())
    assert truth.parameters["probe"]["dead_elements"] == [1]
    assert truth.parameters["probe"]["receive_gains"] == [1.0, 0.0, 1.0]


def test_element_variation_has_the_requested_spread():
    model = ArrayModel.from_preset("p4-1")
    varied = model.with_element_variation(amplitude_rms=0.05, delay_rms=8e-9,
                                          receive_gain_rms=0.05, dead=[0, 40], seed=1)
    live = np.setdiff1d(np.arange(model.element_count), [0, 40])
    assert varied.dead_elements == [0, 40]
    assert np.std(varied.apodization[live]) == pytest.approx(0.05, rel=0.3)
    assert np.std(varied.receive_gains[live]) == pytest.approx(0.05, rel=0.3)
    assert np.std(varied.delays) == pytest.approx(8e-9, rel=0.3)
    with pytest.raises(Exception, match="dead"):
        model.with_element_variation(dead=[model.element_count])


def test_recorded_sound_speed_differs_from_the_true_one_that_sets_the_arrival():
    model = test_model(element_width=0.3e-3, pitch=0.3e-3, element_height=0.3e-3)
    z, fs = 0.03, 100e6
    grid = PlaneGrid(np.array([0.0]), np.array([0.0]), Pose(origin=(0.0, 0.0, z)))
    true = Medium(sound_speed=1487.0)
    scan, truth = simulate_scan(model, grid=grid, sampling_rate=fs, n_samples=4000,
                                medium=true, recorded_medium=Medium(sound_speed=1481.0),
                                calibration=None, snr_db=None, dtype=np.float64)
    assert scan.medium.sound_speed == 1481.0
    med = truth.parameters["medium"]
    assert med["sound_speed_m_s"] == 1487.0 and med["recorded_sound_speed_m_s"] == 1481.0
    # far-field pulse of a small piston is ∝ du/dt: its envelope peak comes TC + z/c late
    trace = scan.data[0, 0]
    env = np.abs(np.fft.ifft(np.fft.fft(trace) * (np.arange(trace.size) < trace.size // 2)))
    assert np.argmax(env) / fs == pytest.approx(TC + z / 1487.0, abs=20e-9)
