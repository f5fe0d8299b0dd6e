"""Tests of the receive half (holoprobe.characterize._virtual_receiver, _reflection,
_receive_ir, _receive): virtual receiver pose, reflection coefficient, receive IR.

The synthetic echo is built here in the time domain, not with the code under test: a
known causal receive IR h_R and a known causal incident pulse g are convolved on a
0.25 ns grid; every element gets the plate's echo train (front face Rp, back-wall
reverberations of an immersed plate) at its exact geometric arrival for a plate
tilted by θy'/2, is sampled at 62.5 MHz by interpolation and gets Gaussian noise
(30 dB peak SNR per element). One element is dead and one carries a spurious early
echo.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from holoprobe.characterize import (
    ReceiveConfig,
    VirtualReceiver,
    echo_arrivals,
    echo_train_peaks,
    element_receive_pressure,
    element_sensitivity,
    estimate_reflection_coefficient,
    estimate_virtual_receiver,
    fit_arrival_line,
    lens_path_offset,
    receive_impulse_response,
    reflection_coefficient_from_peaks,
    sensor_distance_from_onset,
    tilt_aligned_average,
    tilt_from_slope,
    transfer_function_estimate,
    virtual_sensor_surface,
)
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import Pose
from holoprobe.measurement import ProbeInfo
from holoprobe.signal import continuous_spectrum, detect_onset

C0 = 1481.0
F_REF = 0.1806689295  # stored ElevationFocus (reference_spec 4)
H_REF = 0.0142790297  # stored ElementHeight
PROBE = ProbeInfo(96, 2.977648e-4, 2.477648e-4, H_REF, 2.5e6, F_REF, "P4-1")
FS = 62.5e6
T_START = 50e-6
NT = 2048
DT_FINE = 0.25e-9


def paper_onset(z0: float, focus: float, height: float, c0: float) -> float:
    """t0 of paper section III B, written out (valid for z0 < F)."""
    a = height / 2
    return ((1 + z0 / focus) * math.hypot(a, focus)
            - math.sqrt((1 - z0 / focus) ** 2 * a * a + focus * focus)) / c0


def true_receive_ir(t: np.ndarray) -> np.ndarray:
    """h_R in ADCL/(Pa·s): causal, starts smoothly at t = 0."""
    tt = np.maximum(t, 0.0)
    return np.where(t >= 0, 4e6 * (tt / 0.2e-6) * np.exp(-tt / 0.2e-6)
                    * np.sin(2 * np.pi * 2.6e6 * tt + 0.3) * (1 - np.exp(-tt / 30e-9)), 0.0)


def incident_pulse(t: np.ndarray) -> np.ndarray:
    """g in Pa: the incident pressure at the sensor, causal, short (broadband)."""
    tt = np.maximum(t, 0.0)
    return np.where(t >= 0, 5e4 * (tt / 0.12e-6) ** 2 * np.exp(-tt / 0.12e-6)
                    * np.sin(2 * np.pi * 2.5e6 * tt), 0.0)


def echo_amplitudes(rp: float, n: int = 4) -> np.ndarray:
    """Immersed plate: p1 = Rp, p_k = −(1 − Rp²) Rp^(2k−3) (k ≥ 2)."""
    return np.array([rp] + [-(1 - rp**2) * rp ** (2 * k - 3) for k in range(2, n + 1)])


def synthetic_echo(theta: float, distance: float, rp: float, *, period: float = 4.5e-6,
                   snr_db: float = 30.0, seed: int = 0, gains=None, extra_delays=None,
                   dead=(), spurious=()):
    """Element RF (n_el, NT) from T_START at FS, and the truth."""
    rng = np.random.default_rng(seed)
    tf = np.arange(0, 6e-6, DT_FINE)
    w = np.convolve(true_receive_ir(tf), incident_pulse(tf))[:tf.size] * DT_FINE  # ADCL
    z0 = distance * (1 + math.cos(theta))
    t0 = paper_onset(z0, F_REF, H_REF, C0)
    x = PROBE.element_centers()
    t_el = t0 - x * math.sin(theta) / C0  # plane wavefront along z reaching the image
    if extra_delays is not None:
        t_el = t_el + extra_delays
    t = T_START + np.arange(NT) / FS
    amps = echo_amplitudes(rp)
    rf = np.zeros((x.size, NT))
    for e in range(x.size):
        for k, a in enumerate(amps):
            rf[e] += a * np.interp(t - t_el[e] - k * period, tf, w, left=0.0, right=0.0)
    if gains is not None:
        rf *= np.asarray(gains)[:, None]
    clean_peak = np.max(np.abs(rf))
    for e in spurious:
        rf[e] += 0.9 * clean_peak * np.interp(t - t_el[e] + 1.5e-6, tf, w / np.abs(w).max(),
                                              left=0.0, right=0.0) * 2.0
        rf[e] -= 0.9 * clean_peak * np.interp(t - t_el[e], tf, w / np.abs(w).max(),
                                              left=0.0, right=0.0) * rp
    for e in dead:
        rf[e] = 0.0
    sigma = clean_peak / 10 ** (snr_db / 20)
    rf += rng.normal(0.0, sigma, rf.shape)
    truth = {"t0": t0, "z0": z0, "t_el": t_el, "x": x}
    return rf, truth


@pytest.fixture(scope="module")
def echo():
    theta, d, rp = math.radians(3.0), 45e-3, 0.78
    rf, truth = synthetic_echo(theta, d, rp, dead=(3,), spurious=(50,))
    truth.update(theta=theta, d=d, rp=rp)
    return rf, truth


@pytest.fixture(scope="module")
def receiver(echo):
    rf, _ = echo
    return estimate_virtual_receiver(rf, FS, PROBE.element_centers(), focus=F_REF,
                                     height=H_REF, sound_speed=C0, start_time=T_START)


# ----------------------------------------------------------------- regression (reference)
def test_lens_path_offset_matches_published_compute_lens_offset_values():
    d = np.array([0.05, 0.25, 0.5])
    expected = np.array([1.062607e-4, 2.820230e-4, 2.208132e-4])
    np.testing.assert_allclose(lens_path_offset(d, F_REF, H_REF), expected, rtol=2e-6)
    # at c0 t0 = 0.0899026 m the spec lists 1.755750e-4, but the stored z0' (8.97270449e-2,
    # reproduced to all digits by the published step) implies c0 t0 − z0' = 1.755791e-4
    ct = 60.704e-6 * C0
    assert float(lens_path_offset(ct, F_REF, H_REF)) == pytest.approx(ct - 8.97270449e-2,
                                                                      abs=5e-11)
    assert lens_path_offset(0.1, math.inf, H_REF) == 0.0


def test_published_receiver_geometry_reproduced_and_exact_solution_differs_by_sub_micron():
    t0, theta = 60.704e-6, math.radians(3.1672532951)
    # the published fixed-point step, written out: z0' = c0 t0 − Δ(c0 t0)
    ct = C0 * t0
    z_fixed = ct - float(lens_path_offset(ct, F_REF, H_REF))
    assert z_fixed == pytest.approx(8.97270449e-2, abs=5e-11)
    z_exact = sensor_distance_from_onset(t0, F_REF, H_REF, C0)
    # the exact root satisfies the paper's t0 relation ...
    assert paper_onset(z_exact, F_REF, H_REF, C0) == pytest.approx(t0, abs=1e-15)
    # ... and lies 0.27 µm beyond the fixed-point step
    assert 0.2e-6 < z_exact - z_fixed < 0.35e-6
    assert round(z_exact * 1e3, 3) == 89.727
    rec = VirtualReceiver.from_geometry(theta, t0, F_REF, H_REF, C0)
    assert round(rec.x0 * 1e3, 3) == 2.481
    assert rec.x0 == pytest.approx(2.4806423e-3, abs=1e-8)
    # the exact z0' moves d by +0.14 µm from the published 0.0448978 m
    assert rec.distance == pytest.approx(0.0448978, abs=2e-7)
    # x0' = z0' sin θ / (1 + cos θ) (reference_spec 2.9)
    assert rec.x0 == pytest.approx(rec.z0 * math.sin(theta) / (1 + math.cos(theta)), rel=1e-12)


def test_sensor_distance_without_lens_is_the_straight_path():
    assert sensor_distance_from_onset(60e-6, math.inf, H_REF, C0) == pytest.approx(60e-6 * C0)


@pytest.mark.parametrize("z0", [0.02, 0.2, 0.45])
def test_sensor_distance_inverts_the_lens_path_in_every_regime(z0):
    # F ≤ D < 2F and D ≥ 2F use the other branches of the path offset
    a = H_REF / 2
    if z0 < F_REF:
        path = paper_onset(z0, F_REF, H_REF, C0) * C0
    elif z0 < 2 * F_REF:
        path = z0 + 2 * math.hypot(a, F_REF) - 2 * F_REF
    else:
        path = math.hypot(a, F_REF) + math.hypot(F_REF - z0, a)
    assert sensor_distance_from_onset(path / C0, F_REF, H_REF, C0) == pytest.approx(z0,
                                                                                   abs=1e-10)


def test_published_reflection_coefficient_examples_and_the_plate_model_behind_them():
    assert reflection_coefficient_from_peaks([2.553626, 1]) == pytest.approx(0.78, abs=1e-6)
    assert reflection_coefficient_from_peaks([1, -0.5]) == pytest.approx(0.707107, abs=1e-6)
    # those are front / back-wall echoes of an immersed plate: p2/p1 = −(1 − Rp²)
    for rp in (0.3, 0.78, 0.95):
        amps = echo_amplitudes(rp)
        assert reflection_coefficient_from_peaks(amps[:2]) == pytest.approx(rp, abs=1e-12)
        # attenuating variant: a round-trip loss e^{−α} per reverberation cancels
        att = amps * np.exp(-0.4 * np.arange(amps.size))
        assert reflection_coefficient_from_peaks(att[:3], attenuating=True) == pytest.approx(
            rp, abs=1e-12)


# ----------------------------------------------------------------- geometry
def test_tilt_uses_sin_of_the_arrival_slope():
    theta = math.radians(3.0)
    assert tilt_from_slope(-math.sin(theta) / C0, C0) == pytest.approx(theta, abs=1e-15)
    with pytest.raises(InputError, match="slope"):
        tilt_from_slope(-1.2 / C0, C0)


def test_virtual_sensor_points_are_mirror_images_of_the_elements():
    theta, d = math.radians(3.0), 45e-3
    rec = VirtualReceiver.from_geometry(theta, paper_onset(d * (1 + math.cos(theta)), F_REF,
                                                           H_REF, C0), F_REF, H_REF, C0)
    assert rec.distance == pytest.approx(d, abs=1e-12)
    surf, lay = virtual_sensor_surface(rec, PROBE, H_REF, spacing=0.15e-3)
    assert lay.points_per_element * PROBE.element_count == surf.size
    assert surf.area == pytest.approx(PROBE.element_count * PROBE.element_width * H_REF)
    # image method across the plate face through (0, 0, d), normal rotated by θ/2
    n = np.array([math.sin(theta / 2), 0.0, math.cos(theta / 2)])
    src = np.stack([lay.u, lay.v, np.zeros(lay.u.size)], axis=1)
    image = src - 2 * ((src - [0, 0, d]) @ n)[:, None] * n
    np.testing.assert_allclose(surf.points, image, atol=1e-12)
    # element-major: element 0 owns the first block, centred on its x position
    block = lay.u[:lay.points_per_element]
    assert block.mean() == pytest.approx(PROBE.element_centers()[0], abs=1e-12)
    # normals face the source (the origin)
    assert np.all(np.sum(surf.normals * (surf.points - 0.0), axis=1) < 0)


def test_receive_lens_brings_a_wave_from_the_focus_into_phase():
    # sensor at z = 0 facing +z; point source on each element's axis at the focus
    pose = Pose(0.0, 0.0, 0.0, (0.0, 0.0, 0.0))
    _, lay = virtual_sensor_surface(pose, PROBE, H_REF, spacing=0.05e-3)
    f = np.array([2e6, 4e6])
    k = 2 * np.pi * f / C0
    xe = np.repeat(PROBE.element_centers(), lay.points_per_element)
    r = np.sqrt((lay.u - xe) ** 2 + lay.v**2 + F_REF**2)
    p = np.exp(1j * k[None, :] * r[:, None]) / r[:, None]
    pe = element_receive_pressure(p, lay, f, F_REF, sound_speed=C0)
    mean_abs = np.abs(p).reshape(PROBE.element_count, -1, f.size).mean(axis=1)
    assert np.all(np.abs(pe) / mean_abs > 0.999)
    # without the lens the same wave adds up incoherently along the elevation
    plain = np.abs(p.reshape(PROBE.element_count, -1, f.size).mean(axis=1)) / mean_abs
    assert np.all(plain[:, 1] < 0.85)


def test_receive_lens_is_centred_on_the_aperture_not_on_a_fitted_lens_centre():
    # issue 10 item 4: a LensFit's centre_y lives in the transmit source grid's
    # coordinates; the receive lens is centred on the element (the model's centre).
    # The old code took lens.center_y and put the lens 1 mm off: the focus wave lost
    # its phase coherence.
    from types import SimpleNamespace

    pose = Pose(0.0, 0.0, 0.0, (0.0, 0.0, 0.0))
    _, lay = virtual_sensor_surface(pose, PROBE, H_REF, spacing=0.05e-3)
    f = np.array([4e6])
    k = 2 * np.pi * f / C0
    xe = np.repeat(PROBE.element_centers(), lay.points_per_element)
    r = np.sqrt((lay.u - xe) ** 2 + lay.v**2 + F_REF**2)
    p = np.exp(1j * k[None, :] * r[:, None]) / r[:, None]
    fit = SimpleNamespace(focus=F_REF, center_y=1e-3)
    pe = element_receive_pressure(p, lay, f, fit, sound_speed=C0)
    mean_abs = np.abs(p).reshape(PROBE.element_count, -1, f.size).mean(axis=1)
    assert np.all(np.abs(pe) / mean_abs > 0.999)


# ----------------------------------------------------------------- arrivals and line
@pytest.mark.parametrize(("method", "spread"), [("envelope", 60e-9), ("xcorr", 2e-9)])
def test_echo_arrivals_follow_the_geometric_delays(echo, method, spread):
    rf, truth = echo
    t, q = echo_arrivals(rf, FS, start_time=T_START, method=method)
    good = np.ones(rf.shape[0], bool)
    good[[3, 50]] = False
    rel = (t - truth["t_el"])[good]
    # a constant offset (pulse peak vs onset) is allowed; the spread is not. The
    # envelope peak of a ~1 µs pulse at 30 dB jitters by tens of ns; the correlation
    # uses the phase and does 50× better.
    assert np.std(rel) < spread
    assert q[3] < 0.2 * np.median(q[good]) and np.median(q[good]) > 20


def test_arrival_line_rejects_dead_and_spurious_elements_and_recovers_the_slope():
    rng = np.random.default_rng(1)
    x = PROBE.element_centers()
    s_true = -math.sin(math.radians(3)) / C0
    t = 61e-6 + s_true * x + rng.normal(0, 2e-9, x.size)
    q = np.full(x.size, 30.0)
    t[[5, 40, 41]] += [0.2e-6, -0.4e-6, 0.2e-6]  # half-period jumps
    q[[0, 95]] = 2.0  # weak edge elements
    line = fit_arrival_line(x, t, q)
    assert not line.used[[0, 5, 40, 41, 95]].any()
    assert line.used.sum() == x.size - 5
    assert abs(line.slope - s_true) < 4 * line.slope_uncertainty
    assert line.slope_uncertainty < 2e-9 / np.std(x) / np.sqrt(80)


def test_weighted_arrival_line_uses_each_delay_by_its_uncertainty_and_covers_the_slope():
    # The element delays of the θy' refinement on a tilted sensor are far from equally
    # good (the weak end of a 32-element twin at −4.9° has 4–5× the delay noise): the
    # unweighted fit with the common residual scatter both wastes the good delays and,
    # rejecting the noisy ones against the good ones' scatter, reports too small a σ
    # (slope σ / actual scatter 0.79 on that twin). With the per-element uncertainties
    # the slope is weighted least squares with an honest σ (Birge ratio ≥ 1).
    rng = np.random.default_rng(5)
    x = (np.arange(32) - 15.5) * 0.3e-3
    u = np.geomspace(2e-9, 0.35e-9, x.size)  # 6× from one end to the other
    q = np.full(x.size, 50.0)
    s_true = 2e-7
    z_w, z_u, spread = [], [], []
    for _ in range(120):
        t = 1e-9 + s_true * x + rng.normal(0.0, u)
        w = fit_arrival_line(x, t, q, uncertainty=u)
        o = fit_arrival_line(x, t, q)
        z_w.append((w.slope - s_true) / w.slope_uncertainty)
        z_u.append((o.slope - s_true) / o.slope_uncertainty)
        spread.append((w.slope, o.slope))
    sw, so = np.std(np.array(spread), axis=0)
    assert sw < 0.8 * so  # the weighted slope scatters less
    assert np.mean(np.abs(z_w) <= 2) >= 0.93  # ≈ 95 % expected
    assert 0.85 < np.std(z_w) < 1.2
    assert np.std(z_u) > 1.2  # the unweighted σ does not cover its own scatter
    # a bad delay is still rejected, on the normalised residual
    t = 1e-9 + s_true * x + rng.normal(0.0, u)
    t[30] += 20 * u[30]
    line = fit_arrival_line(x, t, q, uncertainty=u)
    assert not line.used[30] and line.used.sum() == x.size - 1


def test_virtual_receiver_recovers_tilt_and_distance(echo, receiver):
    _, truth = echo
    assert abs(math.degrees(receiver.theta_y - truth["theta"])) <= 0.05
    # The onset rule (last zero crossing before the signal leaves the noise) sees a
    # smoothly starting pulse late by the time it needs to rise out of the noise: that
    # delay δ belongs to the IR/geometry split (DESIGN: move it back into the distance).
    # δ: holoprobe.signal.detect_onset on the average aligned with the TRUE tilt.
    rf, _ = echo
    x = truth["x"]
    s_true = -math.sin(truth["theta"]) / C0
    tt = np.arange(NT) / FS
    keep = [e for e in range(x.size) if e not in (3, 50)]
    stack = np.mean([np.interp(tt + x[e] * s_true, tt, rf[e] - rf[e].mean()) for e in keep],
                    axis=0)
    sigma_avg = float(np.std(stack[:300]))
    delta = T_START + detect_onset(stack, FS, noise=sigma_avg, threshold=5.0) - truth["t0"]
    assert -5e-9 <= delta < 100e-9  # 30 dB per element: about 55 ns for this pulse
    z_expected = sensor_distance_from_onset(truth["t0"] + delta, F_REF, H_REF, C0)
    d_expected = z_expected / (1 + math.cos(truth["theta"]))
    assert abs(receiver.distance - d_expected) <= 20e-6
    assert abs(receiver.onset - (truth["t0"] + delta)) <= 27e-9
    assert not receiver.used[3] and not receiver.used[50]
    assert receiver.pose().origin == pytest.approx((receiver.x0, 0.0, receiver.z0))
    assert receiver.x0 == pytest.approx(receiver.distance * math.sin(receiver.theta_y))
    assert 0 < receiver.theta_y_uncertainty < math.radians(0.05)


def test_a_digitally_zero_channel_is_left_out_not_taken_for_the_best_one(echo, receiver):
    # review: a disconnected channel that records exact zeros had noise σ 0 and an
    # infinite echo quality; the arrival line's threshold (a share of the best quality)
    # then became infinite and rejected every other element ("only 1 elements ...").
    rf, _ = echo
    zeroed = rf.copy()
    zeroed[20] = 0.0
    rx = estimate_virtual_receiver(zeroed, FS, PROBE.element_centers(), focus=F_REF,
                                   height=H_REF, sound_speed=C0, start_time=T_START)
    assert not rx.used[20] and rx.used.sum() == receiver.used.sum() - 1
    assert abs(math.degrees(rx.theta_y - receiver.theta_y)) < 3 * math.degrees(
        receiver.theta_y_uncertainty)


def test_tilt_aligned_average_stacks_the_echo_at_the_centre_arrival(echo, receiver):
    rf, truth = echo
    avg = tilt_aligned_average(rf, FS, truth["x"], receiver.slope, used=receiver.used)
    single = rf[48]  # element next to the centre
    assert np.max(np.abs(avg)) > 0.95 * np.max(np.abs(single))
    # the noise drops by about √(number of elements averaged)
    pre = slice(0, 300)
    assert np.std(avg[pre]) < 2.0 * np.std(single[pre]) / math.sqrt(receiver.used.sum())


# ----------------------------------------------------------------- reflection
def test_echo_train_passes_over_a_noise_bump_and_finds_the_back_wall():
    # issue 10 (c), session 5: on a 32-element twin at 25 dB the averaged echo shows the
    # receive IR's tail lobe (0.09 of the front echo, +1.05 µs), a noise bump and the
    # back wall (0.23, +4.3 µs). The tail lobe passes as an echo (above the noise and
    # above 0.2 of the back wall ahead); the bump, below the noise level, ended the
    # search, so the tail lobe was "the second echo": Rp 0.95 instead of 0.876 and the
    # receive IR cut after 1 µs (its gain 10 % low) in 2 of 4 draws.
    fs = 62.5e6
    t = np.arange(1000) / fs

    def pulse(t0, a):
        return a * np.exp(-(((t - t0) / 0.25e-6) ** 2)) * np.cos(2 * np.pi * 2.5e6 * (t - t0))

    trace = pulse(5e-6, 1.0) + pulse(6.05e-6, 0.09) + pulse(6.9e-6, 0.05) + pulse(9.3e-6, -0.23)
    pre = t < 4.3e-6  # the noise before the echo sets the floor: 4 × ~0.018 envelope
    trace[pre] += np.random.default_rng(2).normal(0.0, 0.015, pre.sum())
    times, amps = echo_train_peaks(trace, fs, fraction=0.2, count=5, min_snr=4.0)
    assert times[0] == pytest.approx(5e-6, abs=20e-9)
    assert np.any(np.abs(times - 9.3e-6) < 20e-9)  # old: [5.0, 6.05] µs only
    assert not np.any(np.abs(times - 6.9e-6) < 0.1e-6)  # the bump is not an echo
    back = amps[np.argmin(np.abs(times - 9.3e-6))] / amps[0]
    assert back == pytest.approx(0.23, rel=0.03)


def test_reflection_coefficient_is_unbiased_on_a_noisy_echo_train():
    # issue 10, session 12 (rp): Rp from the envelope maxima of a noisy train is biased
    # low (each maximum is about one noise σ high, the weaker second echo relatively
    # more: full-size P4-1 twin −0.34 ± 0.06 %). A plate train of a ringing pulse, Rp 0.78,
    # white noise σ = 0.01 of the first echo's peak, 200 draws: the envelope maxima give
    # −0.57 % (≈ 12 × their σ/√N; the old estimate); the fitted common waveform −0.02 ±
    # 0.02 %, and its σ (_reflection_uncertainty, 0.0023) matches the scatter (0.0024).
    from holoprobe.characterize._receive_pipeline import _reflection_uncertainty

    fs, rp, period, sigma = 62.5e6, 0.78, 4.3e-6, 0.01
    t = np.arange(1600) / fs

    def pulse(t0):
        s = t - t0
        return (np.exp(-((s / 0.22e-6) ** 2)) * np.cos(2 * np.pi * 2.5e6 * s)
                + 0.03 * np.exp(-(((s - 1.0e-6) / 0.3e-6) ** 2)) * np.sin(2 * np.pi * 2e6 * s))

    t1 = 8.1e-6 + 0.37 / fs  # off the sample grid
    amps = [rp] + [-(1 - rp**2) * rp ** (2 * n - 1) for n in range(1, 4)]
    clean = sum(a * pulse(t1 + n * period) for n, a in enumerate(amps)) / rp
    rng = np.random.default_rng(11)
    new, old, unc = [], [], []
    for _ in range(200):
        trace = clean + rng.normal(0.0, sigma, t.size)
        est = estimate_reflection_coefficient(trace, fs, count=4)
        new.append(est.coefficient)
        unc.append(_reflection_uncertainty(est, sigma))
        old.append(reflection_coefficient_from_peaks(echo_train_peaks(trace, fs, count=2)[1]))
    new_a, old_a = np.asarray(new), np.asarray(old)
    se = new_a.std() / math.sqrt(new_a.size)
    clean_rp = estimate_reflection_coefficient(clean, fs, count=4).coefficient
    assert clean_rp == pytest.approx(rp, abs=1e-6)
    assert abs(new_a.mean() - rp) < 3 * se  # old code: −0.57 %, ≈ 26 se
    assert old_a.mean() - rp < -8 * old_a.std() / math.sqrt(old_a.size)  # the test's power
    assert np.mean(unc) == pytest.approx(new_a.std(), rel=0.2)


def test_reflection_coefficient_from_the_echo_train_of_the_average(echo, receiver):
    _, truth = echo
    est = estimate_reflection_coefficient(receiver.averaged_rf, FS, start_time=T_START)
    assert abs(est.coefficient - truth["rp"]) <= 0.02
    assert est.period == pytest.approx(4.5e-6, abs=80e-9)
    assert np.iscomplexobj(np.asarray(est.coefficient)) is False


def test_second_echo_larger_than_the_first_is_a_clear_error_never_complex():
    with pytest.raises(FitError, match="not smaller than the first"):
        reflection_coefficient_from_peaks([1.0, 2.0])
    t = np.arange(2000) / FS
    burst = np.sin(2 * np.pi * 2.5e6 * t) * np.exp(-((t - 5e-6) / 0.3e-6) ** 2)
    train = 0.5 * burst + 1.0 * np.roll(burst, 300)
    with pytest.raises(FitError, match="not smaller"):
        estimate_reflection_coefficient(train, FS)
    with pytest.warns(UserWarning, match="failed"):
        est = estimate_reflection_coefficient(train, FS, fallback=0.78)
    assert est.coefficient == 0.78 and est.method == "fallback"


def test_envelope_that_never_falls_below_the_fraction_is_a_clear_error():
    t = np.arange(4000) / FS
    tone = np.sin(2 * np.pi * 2.5e6 * t) * (1 + 0.1 * np.sin(2 * np.pi * 1e4 * t))
    times, _ = echo_train_peaks(tone, FS)
    assert times.size == 1
    with pytest.raises(FitError, match="never falls below"):
        estimate_reflection_coefficient(tone, FS)


def test_no_echo_above_the_noise_is_a_clear_error():
    rng = np.random.default_rng(3)
    noise = rng.normal(0, 1.0, (96, NT))
    with pytest.raises(FitError, match="peak SNR"):
        estimate_virtual_receiver(noise, FS, PROBE.element_centers(), focus=F_REF,
                                  height=H_REF, start_time=T_START)


def test_no_onset_threshold_crossing_is_a_clear_error(echo):
    rf, _ = echo
    with pytest.raises(FitError, match="receive onset"):
        estimate_virtual_receiver(rf, FS, PROBE.element_centers(), focus=F_REF,
                                  height=H_REF, start_time=T_START, onset_threshold=1e6)


# ----------------------------------------------------------------- receive IR
def test_receive_impulse_response_recovers_the_true_ir(echo, receiver):
    _, truth = echo
    est = estimate_reflection_coefficient(receiver.averaged_rf, FS, start_time=T_START)
    fs_p, tp0 = 25e6, 55e-6
    tp = tp0 + np.arange(600) / fs_p
    rng = np.random.default_rng(7)
    p = incident_pulse(tp - truth["t0"])
    p = p + rng.normal(0, np.abs(p).max() * 2e-3, p.size)  # 54 dB (1 %: corr 0.972)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = receive_impulse_response(
            receiver.averaged_rf, p, FS, pressure_rate=fs_p, voltage_start_time=T_START,
            pressure_start_time=tp0, reflection_coefficient=est.coefficient)
    assert res.sampling_rate == 250e6
    assert res.unit == "ADCL/(Pa·s)"
    # the IR ends where it falls into its noise (``noise_tail``): after the truth's
    # 99.9 % of energy (54 dB here), at the latest at the echo-train period (4.5 µs)
    t = np.arange(2000) / 250e6
    energy = np.cumsum(true_receive_ir(t) ** 2)
    t_999 = t[np.searchsorted(energy, 0.999 * energy[-1])]
    assert t_999 <= res.truncation_time <= 4.5e-6 + 80e-9
    assert res.ir.size == math.ceil((res.truncation_time + res.onset) * 250e6)
    # the IR's onset was moved to res.onset: est(t) = truth(t − shift)
    m = 500  # first 2 µs (the IR is zero after its end)
    truth_ir = true_receive_ir(np.arange(m) / 250e6 - res.shift)
    est_ir = np.pad(res.ir, (0, max(0, m - res.ir.size)))[:m]
    corr = float(est_ir @ truth_ir / np.sqrt((est_ir @ est_ir) * (truth_ir @ truth_ir)))
    assert corr >= 0.98
    gain = float(est_ir @ truth_ir / (truth_ir @ truth_ir))
    assert gain == pytest.approx(1.0, abs=0.05)


def _in_band_gain(res, truth_shift=0.0, level=0.5):
    """|H_est/H_true| over the band where |H_true| ≥ level · its peak (−6 dB: 0.5)."""
    n = 8192
    f = np.fft.rfftfreq(n, 1 / res.sampling_rate)
    est = np.fft.rfft(res.ir, n)
    t = np.arange(n) / res.sampling_rate
    true = np.fft.rfft(true_receive_ir(t - res.shift - truth_shift), n)
    band = np.abs(true) >= level * np.abs(true).max()
    return f[band], np.abs(est[band] / true[band])


@pytest.mark.parametrize("snr_db", [25.0, 32.0, 40.0])
def test_receive_ir_gain_is_unbiased_inside_the_band(snr_db):
    # issue 10 item 1: the old Wiener filter followed by a spectral-subtraction gain
    # counted the noise twice: |H_est/H_true| fell to 0.26–0.68 towards the band edge.
    # One regularised deconvolution leaves the in-band gain within ±5 % of the truth.
    theta, d, rp = math.radians(2.0), 45e-3, 0.78
    rf, truth = synthetic_echo(theta, d, rp, snr_db=snr_db, seed=int(snr_db))
    rx = estimate_virtual_receiver(rf, FS, PROBE.element_centers(), focus=F_REF,
                                   height=H_REF, sound_speed=C0, start_time=T_START)
    tp = T_START + np.arange(NT) / FS
    p = incident_pulse(tp - truth["t0"])
    res = receive_impulse_response(rx.averaged_rf, p, FS, voltage_start_time=T_START,
                                   pressure_start_time=T_START, reflection_coefficient=rp,
                                   truncate_before=4e-6,
                                   pressure_noise_window=(T_START, T_START + 5e-6))
    f, ratio = _in_band_gain(res)
    assert f.min() < 2.2e6 and f.max() > 3.2e6  # the −6 dB band of the truth
    assert np.all(np.abs(ratio - 1) <= 0.05), (snr_db, ratio.min(), ratio.max())


def test_receive_ir_band_is_decided_on_the_kept_response_not_on_single_bins():
    # issue 10 (full-size P4-1 at 25 dB: correlation 0.9926): the band of the
    # deconvolution was decided on the per-bin SNR of Y/P, although the IR keeps only
    # L of the n samples (n/L times less noise), and with |P|² averaged over
    # neighbouring bins (a bin where P is nearly zero passed for signal). Long record
    # (n/L ≈ 14), one echo train, the pressure band-limited like a projected scan
    # (zero outside 0.4–5.5 MHz). Old code: correlation 0.985–0.991 over 5 seeds.
    rng = np.random.default_rng(0)
    nt, ta = 4096, T_START + 10e-6
    tf = np.arange(0, 6e-6, DT_FINE)
    w = np.convolve(true_receive_ir(tf), incident_pulse(tf))[:tf.size] * DT_FINE
    t = T_START + np.arange(nt) / FS
    y = sum(a * np.interp(t - ta - k * 4.5e-6, tf, w, left=0.0, right=0.0)
            for k, a in enumerate(echo_amplitudes(0.78)))
    y = y + rng.normal(0.0, np.abs(y).max() / 100.0, nt)  # 40 dB peak SNR
    spec = np.fft.rfft(incident_pulse(t - ta))
    f = np.fft.rfftfreq(nt, 1 / FS)
    spec[(f < 0.4e6) | (f > 5.5e6)] = 0.0
    res = receive_impulse_response(y, np.fft.irfft(spec, nt), FS, voltage_start_time=T_START,
                                   pressure_start_time=T_START, reflection_coefficient=0.78,
                                   truncate_before=4.5e-6,
                                   noise_window=(T_START, T_START + 9e-6))
    m = 500  # first 2 µs (the IR is zero after its end)
    truth_ir = true_receive_ir(np.arange(m) / 250e6 - res.shift)
    est = np.pad(res.ir, (0, max(0, m - res.ir.size)))[:m]
    assert float(est @ truth_ir / np.sqrt((est @ est) * (truth_ir @ truth_ir))) >= 0.993
    _, ratio = _in_band_gain(res)
    assert np.all(np.abs(ratio - 1) <= 0.05), (ratio.min(), ratio.max())


def _echo_train(nt: int, ta: float, period: float = 4.5e-6, rp: float = 0.78):
    """Time axis (s) and the noise-free echo train of the plate (``rp``) arriving at
    ``ta`` (truth on the DT_FINE grid, linearly interpolated: another discretisation
    than the estimator's)."""
    tf = np.arange(0, 6e-6, DT_FINE)
    nf = 2 * tf.size
    w = np.fft.irfft(np.fft.rfft(true_receive_ir(tf), nf) * np.fft.rfft(incident_pulse(tf), nf),
                     nf)[:tf.size] * DT_FINE
    t = T_START + np.arange(nt) / FS
    return t, sum(a * np.interp(t - ta - k * period, tf, w, left=0.0, right=0.0)
                  for k, a in enumerate(echo_amplitudes(rp)))


TRAIN_PERIOD = 4.5e-6


def _echo_train_draws(snr_db: float, draws: int = 16):
    """Receive IRs of the synthetic echo train (period 4.5 µs) with white noise at
    ``snr_db`` (peak) on the RF and 60 dB on the pressure, seeds 0 … draws − 1."""
    nt, ta = 2048, T_START + 10e-6
    t, y0 = _echo_train(nt, ta, TRAIN_PERIOD)
    p0 = incident_pulse(t - ta)
    for seed in range(draws):
        rng = np.random.default_rng(seed)
        y = y0 + rng.normal(0.0, np.abs(y0).max() / 10 ** (snr_db / 20), nt)
        p = p0 + rng.normal(0.0, np.abs(p0).max() / 1e3, nt)
        yield receive_impulse_response(y, p, FS, voltage_start_time=T_START,
                                       pressure_start_time=T_START, reflection_coefficient=0.78,
                                       truncate_before=TRAIN_PERIOD,
                                       noise_window=(T_START, ta - 1e-6),
                                       pressure_noise_window=(T_START, ta - 1e-6))


def test_receive_transfer_function_sigma_covers_the_gain_error_per_frequency():
    # issue 10: summary.json gives |H_R(f)| with a σ per frequency. Synthetic echo train
    # (truth on a 0.25 ns grid, linearly interpolated: another discretisation than the
    # estimator's), 30 dB voltage SNR, 60 dB pressure SNR, 16 noise draws: the σ from
    # the deconvolution's own noise powers covers the error of |H| at every reported
    # frequency (pooled ≥ 85 % within 2σ; 89 % on 30 draws) without being inflated.
    fine = np.arange(0, 8e-6, 1e-9)
    z, freqs = [], []
    for res in _echo_train_draws(30.0):
        est = transfer_function_estimate(res)
        assert est.unit == "ADCL/Pa"
        truth = np.abs(continuous_spectrum(true_receive_ir(fine), 1e9, est.frequencies))
        z.append((est.magnitude - truth) / est.uncertainty)
        freqs.append(est.frequencies)
        assert np.all(est.uncertainty <= 0.1 * est.magnitude + 1e-30)
    zz = np.concatenate(z)
    assert np.mean(np.abs(zz) <= 2) >= 0.85, np.mean(np.abs(zz) <= 2)
    assert 0.4 <= np.median(np.abs(zz)) <= 1.0  # not inflated (Gaussian: 0.67)
    f_all = np.concatenate(freqs)
    assert f_all.min() < 2.0e6 and f_all.max() > 3.3e6  # the truth's band is reported
    # a common scale (σ(Rp)/Rp) and a relative floor add in quadrature
    scaled = transfer_function_estimate(res, scale_uncertainty=0.05, relative_floor=0.01)
    np.testing.assert_allclose(scaled.uncertainty ** 2, est.uncertainty ** 2
                               + (0.05 ** 2 + 0.01 ** 2) * est.magnitude ** 2)
    with pytest.raises(InputError, match="scale_uncertainty"):
        transfer_function_estimate(res, scale_uncertainty=-0.1)
    with pytest.raises(InputError, match="relative_floor"):
        transfer_function_estimate(res, relative_floor=math.nan)


def test_receive_ir_ends_where_it_falls_into_its_noise():
    # issue 10 acceptance (session 11): the IR was kept to the echo-train period (4.5 µs
    # here) although the response lasts ~1.5 µs: the rest is noise, which doubled the
    # noise of |H_R| at the band edges (full-size P4-1 twin at 25 dB: the −6 dB band
    # missed ±5 % in 2 of 8 draws, worst 0.947 / 1.053). The IR now ends at the first
    # 0.25 µs whose rms is below 1.5 × its noise σ (the segment's signal energy is then
    # below its noise energy: cutting it lowers the error). Synthetic echo train at
    # 25 dB, 16 draws: the rms in-band error 5.78 → 4.23 %, the median over the draws
    # of the worst in-band error 15.3 → 7.1 % (at 30 dB: 3.30 → 2.89 %, 40 dB: 1.02 →
    # 0.94 %). With the σ from the noise windows (session 12): rms 4.11 / 2.56 / 0.80 %,
    # median worst 8.8 / 4.7 / 1.4 % at 25 / 30 / 40 dB.
    period = TRAIN_PERIOD
    tt = np.arange(2000) / 250e6
    energy = np.cumsum(true_receive_ir(tt) ** 2)
    t_9999 = tt[np.searchsorted(energy, 0.9999 * energy[-1])]
    worst, lengths, errors = [], [], []
    for res in _echo_train_draws(25.0):
        _, gain = _in_band_gain(res)
        worst.append(float(np.abs(gain - 1).max()))
        errors.append(gain - 1)
        lengths.append(res.truncation_time)
        assert res.ir.size == math.ceil((res.truncation_time + res.onset) * 250e6)
    assert np.median(worst) <= 0.10, np.median(worst)
    assert np.sqrt(np.mean(np.concatenate(errors) ** 2)) <= 0.05
    # the IR is cut where its signal has fallen below the noise, after most of it. Since
    # the noise σ comes from the noise windows (session 12; the whole-record scatter was
    # ~1.17× the noise here, the IR copies), a few draws keep a noise window ≥ 3σ late
    # (the noise is narrowband at the band edges): 4 of 16 past half the period
    assert 0.7 * t_9999 <= np.median(lengths) < 0.5 * period
    assert np.mean(np.asarray(lengths) < 0.5 * period) >= 0.7, lengths


def test_receive_ir_is_moved_not_cut_when_the_pressure_arrives_late():
    # issue 10 item 1: a virtual sensor placed too far (an onset found on the second
    # lobe) makes the pressure late against the voltage; the old IR, cut at zero lag,
    # lost the start of its first lobe. Now the IR's onset is moved to res.onset and
    # nothing of the response is lost.
    theta, d, rp = math.radians(2.0), 45e-3, 0.78
    rf, truth = synthetic_echo(theta, d, rp, snr_db=40.0, seed=3)
    rx = estimate_virtual_receiver(rf, FS, PROBE.element_centers(), focus=F_REF,
                                   height=H_REF, sound_speed=C0, start_time=T_START)
    tp = T_START + np.arange(NT) / FS
    late = 0.3e-6
    p = incident_pulse(tp - truth["t0"] - late)
    res = receive_impulse_response(rx.averaged_rf, p, FS, voltage_start_time=T_START,
                                   pressure_start_time=T_START, reflection_coefficient=rp,
                                   pressure_noise_window=(T_START, T_START + 5e-6))
    # the response rises at t ≈ 0 of the truth: est(t) = truth(t − shift + late)
    assert res.shift - late == pytest.approx(res.onset, abs=0.15e-6)
    m = round(2e-6 * res.sampling_rate)
    t = np.arange(m) / res.sampling_rate
    truth_ir = true_receive_ir(t - res.shift + late)
    est = np.pad(res.ir, (0, max(0, m - res.ir.size)))[:m]  # zero after its end
    corr = float(est @ truth_ir / np.sqrt((est @ est) * (truth_ir @ truth_ir)))
    assert corr >= 0.99
    assert float(est @ truth_ir / (truth_ir @ truth_ir)) == pytest.approx(1.0, abs=0.03)


def test_drive_ratio_by_spectra_turns_the_pulse_field_into_the_burst_field():
    # issue 10 item 3: scan driven by a 12 ns pulse, echo experiment by a 2-cycle
    # burst. The pressure of the echo experiment is the scan's times E_echo/E_scan;
    # the ratio of peak voltages is wrong by far.
    from holoprobe.characterize import DriveRatio, drive_amplitude_ratio
    from holoprobe.measurement import DriveSignal

    fs = 250e6
    t = np.arange(2048) / fs
    h_t = np.where(t > 0, (t / 0.15e-6) ** 2 * np.exp(-t / 0.15e-6)
                   * np.sin(2 * np.pi * 2.5e6 * t), 0.0) * 1e12  # Pa/(V·s)
    pulse = DriveSignal(np.where(np.arange(40) < 3, 30.0, 0.0), fs)  # 12 ns, 30 V
    burst = DriveSignal(6.9 * np.sin(2 * np.pi * 2.5e6 * np.arange(200) / fs)
                        * (np.arange(200) < 200), fs)  # 2 cycles at 2.5 MHz, 6.9 V
    p_scan = np.convolve(h_t, pulse.voltage)[:t.size] / fs
    p_echo = np.convolve(h_t, burst.voltage)[:t.size] / fs
    f = np.fft.rfftfreq(t.size, 1 / fs)
    ratio = DriveRatio(burst, pulse)(f)
    predicted = np.fft.irfft(np.conj(np.conj(np.fft.rfft(p_scan)) * ratio), t.size)
    err = np.linalg.norm(predicted - p_echo) / np.linalg.norm(p_echo)
    assert err < 0.01
    peak = drive_amplitude_ratio(burst, pulse) * p_scan
    assert np.linalg.norm(peak - p_echo) / np.linalg.norm(p_echo) > 0.5


def test_receive_ir_uses_the_spectral_drive_ratio():
    # the same through receive_impulse_response: the voltage is h_R ⊛ p_echo, the
    # pressure given is the scan's (pulse-driven) field; the IR comes out right
    from holoprobe.characterize import DriveRatio
    from holoprobe.measurement import DriveSignal

    tp = T_START + np.arange(NT) / FS
    t0 = T_START + 10e-6
    pulse = DriveSignal(np.where(np.arange(40) < 3, 30.0, 0.0), 250e6)
    burst = DriveSignal(6.9 * np.sin(2 * np.pi * 2.5e6 * np.arange(200) / 250e6), 250e6)
    tf = np.arange(0, 8e-6, DT_FINE)
    k = np.floor(tf * 250e6).astype(int)  # sample and hold, as the drives' spectra
    e_b = np.where(k < 200, burst.voltage[np.minimum(k, 199)], 0.0)
    e_p = np.where(k < 40, pulse.voltage[np.minimum(k, 39)], 0.0)
    # g, the field per unit drive: the scan's field is g ⊛ e_p, the echo's g ⊛ e_b
    g = incident_pulse(tf) * 1e8  # Pa/(V·s)
    p_fine = np.convolve(g, e_p)[:tf.size] * DT_FINE
    p_echo = np.convolve(g, e_b)[:tf.size] * DT_FINE
    y_fine = np.convolve(true_receive_ir(tf), p_echo)[:tf.size] * DT_FINE
    y = np.interp(tp - t0, tf, y_fine, left=0.0, right=0.0)
    y = y + np.random.default_rng(4).normal(0, np.abs(y).max() * 10 ** (-40 / 20), y.size)
    p = np.interp(tp - t0, tf, p_fine, left=0.0, right=0.0)
    res = receive_impulse_response(y, p, FS, voltage_start_time=T_START,
                                   pressure_start_time=T_START,
                                   drive_ratio=DriveRatio(burst, pulse), truncate_before=4e-6,
                                   pressure_noise_window=(T_START, T_START + 5e-6))
    _f, ratio = _in_band_gain(res)
    assert np.all(np.abs(ratio - 1) <= 0.05), (ratio.min(), ratio.max())


def test_receive_impulse_response_scales_with_reflection_and_drive_ratio(echo, receiver):
    _, truth = echo
    tp = T_START + np.arange(NT) / FS
    p = incident_pulse(tp - truth["t0"])
    kw = {"voltage_start_time": T_START, "pressure_start_time": T_START,
          "truncate_before": 2e-6, "pressure_noise_window": (T_START, T_START + 5e-6)}
    a = receive_impulse_response(receiver.averaged_rf, p, FS, reflection_coefficient=0.78,
                                 **kw)
    b = receive_impulse_response(receiver.averaged_rf, p, FS, reflection_coefficient=0.78,
                                 drive_ratio=2.0, **kw)
    assert b.ir.size == a.ir.size == math.ceil((a.truncation_time + a.onset) * 250e6)
    assert a.truncation_time <= 2e-6  # at most the requested length (noise_tail)
    np.testing.assert_allclose(b.ir, a.ir / 2, atol=1e-9 * np.abs(a.ir).max())


def test_element_sensitivity_recovers_gains_and_delays():
    rng = np.random.default_rng(5)
    gains = 1 + 0.2 * rng.standard_normal(PROBE.element_count)
    delays = 10e-9 * rng.standard_normal(PROBE.element_count)
    rf, truth = synthetic_echo(math.radians(2.0), 40e-3, 0.78, gains=gains,
                               extra_delays=delays, snr_db=40, seed=2)
    t = T_START + np.arange(NT) / FS
    # pressure per element without the extra delays and gains (what projection gives)
    pressure = np.stack([sum(a * incident_pulse(t - te - k * 4.5e-6)
                             for k, a in enumerate(echo_amplitudes(0.78)))
                         for te in truth["t_el"] - delays])
    sens = element_sensitivity(rf, pressure, FS)
    rel_g = gains / np.mean(gains)
    np.testing.assert_allclose(sens.amplitude / np.mean(sens.amplitude), rel_g, rtol=0.02)
    err = (sens.delay - np.mean(sens.delay)) - (delays - np.mean(delays))
    assert np.max(np.abs(err)) < 1.5e-9
    # review (session 11): a NumPy bool (np.bool_) took the tuple branch (TypeError)
    a = element_sensitivity(rf, pressure, FS, prediction_noise=True)
    b = element_sensitivity(rf, pressure, FS, prediction_noise=np.bool_(True))
    np.testing.assert_array_equal(a.amplitude_uncertainty, b.amplitude_uncertainty)


@pytest.mark.parametrize("snr_db", [20.0, 40.0])
def test_element_sensitivity_uncertainty_covers_the_gain_error(snr_db):
    """u(gain) from the per-bin scatter against the actual error of 96 elements."""
    rng = np.random.default_rng(7)
    gains = 1 + 0.05 * rng.standard_normal(PROBE.element_count)
    rf, truth = synthetic_echo(math.radians(2.0), 40e-3, 0.78, gains=gains, snr_db=snr_db,
                               seed=4)
    t = T_START + np.arange(NT) / FS
    pressure = np.stack([sum(a * incident_pulse(t - te - k * 4.5e-6)
                             for k, a in enumerate(echo_amplitudes(0.78)))
                         for te in truth["t_el"]])
    sens = element_sensitivity(rf, pressure, FS)
    u = sens.amplitude_uncertainty
    assert u is not None and np.all(u > 0)
    err = sens.amplitude / np.mean(sens.amplitude) - gains / np.mean(gains)
    z = err / (u / np.mean(sens.amplitude))
    assert 0.5 < np.sqrt(np.mean(z**2)) < 2.0
    assert np.max(np.abs(z)) < 4.5


def test_element_sensitivity_uncertainty_covers_the_noise_of_a_predicted_pressure():
    """A pressure predicted from a noisy scan: one band-limited noise realisation per
    element on a short record (the zero-padded scan's), shared by neighbouring bins of
    the longer RF record. The per-bin scatter alone misses it (rms error/σ 1.7, up to
    5.5σ, before issue 11 session 4); with ``prediction_noise`` σ covers it."""
    fs, n_rf, m, n_el = 40e6, 1000, 400, 32
    rng = np.random.default_rng(4)
    f = np.fft.rfftfreq(m, 1 / fs)
    band = (f > 1e6) & (f < 4e6)

    def band_limited(x):
        spec = np.fft.rfft(x, axis=-1)
        spec[..., ~band] = 0
        return np.fft.irfft(spec, m, axis=-1)

    t = np.arange(m) / fs - 6e-6
    p0 = band_limited(np.exp(-(t / 0.5e-6) ** 2) * np.sin(2 * np.pi * 2.5e6 * t))
    gains = 1 + 0.05 * rng.standard_normal(n_el)
    z_old, z_new = [], []
    for _ in range(20):
        pressure = p0 + band_limited(0.03 * rng.standard_normal((n_el, m)))
        rf = 1e-4 * rng.standard_normal((n_el, n_rf))
        rf[:, 100:100 + m] += gains[:, None] * p0
        err = None
        for noise, z in ((False, z_old), (True, z_new)):
            sens = element_sensitivity(rf, pressure, fs, pressure_start_time=100 / fs,
                                       prediction_noise=noise)
            a = sens.amplitude
            err = a / a.mean() - gains / gains.mean() if err is None else err
            z.extend(err / (sens.amplitude_uncertainty / a.mean()))
    z_old, z_new = np.abs(z_old), np.abs(z_new)
    assert np.sqrt(np.mean(z_old**2)) > 1.4  # the scatter alone: far too small
    assert 0.7 < np.sqrt(np.mean(z_new**2)) < 1.2
    assert np.mean(z_new <= 2.0) > 0.93 and np.max(z_new) < 4.0


def test_receive_config_defaults_match_the_function_defaults():
    import inspect

    cfg = ReceiveConfig()
    sig = inspect.signature(estimate_virtual_receiver).parameters
    for name, value in cfg.virtual_receiver_options().items():
        assert sig[name].default == value, name
    assert inspect.signature(receive_impulse_response).parameters[
        "output_rate"].default == cfg.output_rate


@pytest.mark.parametrize("time_limited", [True, False])
def test_receive_ir_keeps_the_ringing_of_its_band_not_a_ripple(time_limited):
    # issue 10 (session 9): |H_est/H_true| carried a same-sign ripple (±1–3 % at 25 dB on
    # every P4-1 twin). The band window's edges fall where |H| is still significant; the
    # band-limited IR rings before its onset, and the old IR, that response cut to its
    # length, lost the ringing: a ripple whose period is the inverse of the cut's
    # distance from the main lobe (here: +2.8 % @1.9, −1.2 % @2.8, +2.5 % @3.4 MHz).
    # The time-limited IR fitted to the in-band bins keeps their spectrum (≤ 0.9 %).
    # Echo and pressure share a smooth band (0.8–5 MHz, raised-cosine edges 1.2 MHz
    # wide, as a transducer's): Y/P = H wherever the band is not zero.
    nt, ta, period = 2048, T_START + 10e-6, 4.5e-6
    t, y = _echo_train(nt, ta, period)
    f = np.fft.rfftfreq(nt, 1 / FS)
    band = ((0.5 - 0.5 * np.cos(np.pi * np.clip((f - 0.8e6) / 1.2e6, 0, 1)))
            * (0.5 - 0.5 * np.cos(np.pi * np.clip((5.0e6 - f) / 1.2e6, 0, 1))))
    y = np.fft.irfft(np.fft.rfft(y) * band, nt)
    y = y + np.random.default_rng(0).normal(0.0, np.abs(y).max() * 1e-3, nt)  # 60 dB
    p = np.fft.irfft(np.fft.rfft(incident_pulse(t - ta)) * band, nt)
    res = receive_impulse_response(y, p, FS, voltage_start_time=T_START,
                                   pressure_start_time=T_START, reflection_coefficient=0.78,
                                   truncate_before=period, noise_window=(T_START, ta - 1e-6),
                                   time_limited=time_limited)
    fj = np.arange(1.9e6, 3.35e6, 0.05e6)
    truth = np.abs(continuous_spectrum(true_receive_ir(np.arange(0, 8e-6, 1e-9)), 1e9, fj))
    err = np.abs(continuous_spectrum(res.ir, res.sampling_rate, fj)) / truth - 1
    if time_limited:
        assert np.abs(err).max() <= 0.01, np.abs(err).max()
    else:  # the old IR, still available: the ripple this test is about
        assert np.abs(err).max() > 0.02, np.abs(err).max()


def test_the_noise_tail_keeps_a_later_lobe_and_a_slow_ringing():
    """Review (session 11): the IR ended at the first quiet window after its peak, so a
    later lobe after a quiet gap (a matching layer's reverberation: here half the first
    lobe, 1.5 µs later) was cut in 20 of 20 noise draws (20 % of the IR's energy), and a
    0.5 MHz ringing was cut at a zero crossing of a 0.25 µs window (6.8 %). The end is
    now past the last window that reaches 3σ, with windows of at least half a period."""
    from holoprobe.characterize._receive_ir import _noise_end

    fs = 50e6
    t = np.arange(int(6e-6 * fs)) / fs
    rng = np.random.default_rng(1)

    def lobe(f, t0, tau):
        return np.exp(-(((t - t0) / tau) ** 2)) * np.cos(2 * np.pi * f * (t - t0))

    two_lobes = 30 * lobe(2.5e6, 1e-6, 0.3e-6) + 15 * lobe(2.5e6, 2.5e-6, 0.3e-6)
    decay = np.clip(t - 0.5e-6, 0, None)
    ringing = 20 * np.exp(-decay / 1.5e-6) * np.sin(2 * np.pi * 0.5e6 * decay) * (t > 0.5e-6)
    for h, window in ((two_lobes, round(0.25e-6 * fs)), (ringing, round(0.5 * fs / 0.5e6))):
        lost = []
        for _ in range(20):
            end = _noise_end(h + rng.standard_normal(h.size), 0, h.size, 1.0, 1.5, window)
            lost.append(np.sum(h[end:] ** 2) / np.sum(h**2))
        assert max(lost) < 0.02, lost
    # pure noise after a single lobe still ends the IR soon after it
    ends = [_noise_end(30 * lobe(2.5e6, 1e-6, 0.3e-6) + rng.standard_normal(t.size), 0,
                       t.size, 1.0, 1.5, round(0.4e-6 * fs)) / fs for _ in range(20)]
    assert np.median(ends) < 2.5e-6


def _ringing_train(amp: float, f0: float, t: np.ndarray, arrival: float,
                   amplitudes, period: float):
    """The true IR plus a slow ringing (``amp`` ADCL/(Pa·s) at ``f0``, 1.5 µs decay), and
    its noise-free echo train on ``t``: echoes of ``amplitudes`` every ``period`` from
    ``arrival`` (DT_FINE grid, linearly interpolated)."""

    def ir(tt):
        u = np.maximum(tt, 0.0)
        ring = amp * np.sin(2 * np.pi * f0 * u) * np.exp(-u / 1.5e-6) * (1 - np.exp(-u / 0.3e-6))
        return true_receive_ir(tt) + np.where(tt >= 0, ring, 0.0)

    tf = np.arange(0, 3 * period, DT_FINE)
    nf = 2 * tf.size
    w = np.fft.irfft(np.fft.rfft(ir(tf), nf) * np.fft.rfft(incident_pulse(tf), nf),
                     nf)[:tf.size] * DT_FINE
    y = sum(a * np.interp(t - arrival - k * period, tf, w, left=0.0, right=0.0)
            for k, a in enumerate(amplitudes))
    return ir, y


def test_the_noise_tail_takes_its_sigma_where_there_is_only_noise():
    """Review (session 11): the noise σ of the IR's tail was the MAD of the band-limited
    deconvolution over the whole record. On a clean echo train whose copies fill most of
    the record (a reverberating layer: 12 echoes, each −0.9 × the one before) that MAD
    is the copies' (1.1 % of the peak), and a slow ringing (1.8 MHz, 1.5 µs decay) was
    cut at 3.1 µs of the 4.5 µs period: |H_est/H_true| 0.934 … 1.036 over the −6 dB
    band. The σ now comes from the noise windows of the voltage and the pressure,
    deconvolved alone (nearly 0 here): the IR keeps the period, 0.994 … 1.007."""
    period, pre = 4.5e-6, 10e-6
    t = np.arange(int((pre + 12 * period) * FS)) / FS
    ir, y = _ringing_train(0.2e6, 1.8e6, t, pre, 0.78 * (-0.9) ** np.arange(12), period)
    res = receive_impulse_response(y, incident_pulse(t - pre), FS, reflection_coefficient=0.78,
                                   truncate_before=period, noise_window=(0.0, pre - 1e-6),
                                   pressure_noise_window=(0.0, pre - 1e-6))
    assert res.truncation_time >= period - 0.1e-6
    n = 8192
    t_ir = np.arange(n) / res.sampling_rate - res.shift
    true = np.fft.rfft(np.where(t_ir < period, ir(t_ir), 0.0), n)  # the period is all there is
    band = np.abs(true) >= 0.5 * np.abs(true).max()
    gain = np.abs(np.fft.rfft(res.ir, n)[band] / true[band])
    assert np.abs(gain - 1).max() <= 0.02, (gain.min(), gain.max())


def test_transfer_function_sigma_holds_the_tail_the_noise_tail_cuts():
    """Session 12 (hr): σ(|H_R|) was the per-bin noise averaged over the IR's resolution.
    Where the noise tail ends the IR before a weak, slow ringing has died out (here 7 %
    of the peak at 2 MHz, 1.5 µs decay, cut at ~1.8 µs at 30 dB), the cut is a bias that
    σ did not hold: 81 % of the errors within 2σ (63 % within 0.4 MHz of the ringing).
    Now σ is the noise propagated through the time-limited fit plus the power of what
    the cut removed (less its noise): 96 % (89 %)."""
    period = TRAIN_PERIOD
    nt, ta = 2048, T_START + 10e-6
    t = T_START + np.arange(nt) / FS
    ir, y0 = _ringing_train(0.1e6, 2e6, t, ta, echo_amplitudes(0.78), period)
    p0 = incident_pulse(t - ta)
    fine = np.arange(0, 3 * period, 1e-9)
    z, lengths = [], []
    for seed in range(16):
        rng = np.random.default_rng(seed)
        res = receive_impulse_response(
            y0 + rng.normal(0.0, np.abs(y0).max() / 10 ** 1.5, nt),
            p0 + rng.normal(0.0, np.abs(p0).max() / 1e3, nt), FS, voltage_start_time=T_START,
            pressure_start_time=T_START, reflection_coefficient=0.78, truncate_before=period,
            noise_window=(T_START, ta - 1e-6), pressure_noise_window=(T_START, ta - 1e-6))
        lengths.append(res.truncation_time)
        est = transfer_function_estimate(res)
        truth = np.abs(continuous_spectrum(ir(fine), 1e9, est.frequencies))
        z.append((est.magnitude - truth) / est.uncertainty)
    assert np.median(lengths) < 0.5 * period  # the noise tail cut it
    z = np.concatenate(z)
    assert np.mean(np.abs(z) <= 2) >= 0.9, np.mean(np.abs(z) <= 2)
