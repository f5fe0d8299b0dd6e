"""Wiener deconvolution, noise floors and the transmit impulse response
(holoprobe.signal._deconvolution)."""

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.measurement import DriveSignal
from holoprobe.signal import (
    drive_is_delta_like,
    frequency_axis,
    noise_floor,
    to_frequency,
    to_time,
    transmit_impulse_response,
    wiener_deconvolve,
)

FS_HI = 250e6  # drive / truth rate
FS = 25e6  # response rate (hydrophone)
N = 500  # 20 µs response record
F0, S_ENV, T_C = 2.5e6, 0.25e-6, 3e-6


def true_ir(t):
    """Transmit IR in Pa/(V·s): a 2.5 MHz Gaussian-modulated pulse."""
    return 1e11 * np.exp(-((t - T_C) ** 2) / (2 * S_ENV**2)) * np.sin(2 * np.pi * F0 * (t - T_C))


def rect_drive():
    v = np.zeros(50)
    v[:3] = 30.0  # 12 ns, 30 V at 250 MS/s: area 0.36 µs·V (paper section III A)
    return DriveSignal(voltage=v, sampling_rate=FS_HI)


def burst_drive():
    t = np.arange(int(2 / F0 * FS_HI)) / FS_HI
    return DriveSignal(voltage=6.9 * np.sin(2 * np.pi * F0 * t), sampling_rate=FS_HI)


def measured_response(drive, noise, rng):
    """u = h ∗ E by direct time-domain convolution at 250 MS/s, then every 10th sample."""
    t_hi = np.arange(N * 10) / FS_HI
    u_hi = np.convolve(true_ir(t_hi), drive.voltage)[: N * 10] / FS_HI
    u = u_hi[::10]
    return u + noise * np.abs(u).max() * rng.standard_normal(N)


def band(x, fs, lo=0.5e6, hi=5e6):
    spec = to_frequency(x)
    f = frequency_axis(x.size, fs)
    spec[(f < lo) | (f > hi)] = 0
    return to_time(spec, x.size)


def correlation_in_band(est, truth, fs, mask):
    a, b = to_frequency(est), to_frequency(truth)
    a[~mask], b[~mask] = 0, 0
    a, b = to_time(a, est.size), to_time(b, truth.size)
    return np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), np.linalg.norm(a - b) / \
        np.linalg.norm(b)


def well_posed_band(drive, truth, fs, level=0.1):
    """Bins where the drive and the true IR both lie within 20 dB of their peaks."""
    f = frequency_axis(truth.size, fs)
    t = np.arange(drive.voltage.size) / drive.sampling_rate
    d = np.abs(np.exp(2j * np.pi * f[:, None] * t) @ drive.voltage)
    h = np.abs(to_frequency(truth))
    return (d >= level * d.max()) & (h >= level * h.max())


@pytest.mark.parametrize(("drive_fn", "method"), [(rect_drive, "area"),
                                                  (burst_drive, "wiener")])
def test_transmit_ir_recovered_from_noisy_response_for_pulse_and_burst_drives(drive_fn, method):
    rng = np.random.default_rng(3)
    drive = drive_fn()
    u = measured_response(drive, 1e-3, rng)
    noise = noise_floor(u, (0, 1.4e-6), sampling_rate=FS, segment_length=32)
    out = transmit_impulse_response(u, FS, drive, noise_response=noise)
    assert out.method == method
    assert out.sampling_rate == 250e6 and out.ir.size == N * 10
    truth = true_ir(np.arange(out.ir.size) / out.sampling_rate)
    corr, rel = correlation_in_band(out.ir, truth, out.sampling_rate,
                                    well_posed_band(drive, truth, out.sampling_rate))
    assert corr >= 0.99
    assert rel < 0.05  # the amplitude in Pa/(V·s) too


def test_excess_snr_suppresses_the_notches_of_a_burst_drive():
    rng = np.random.default_rng(3)
    drive = burst_drive()  # spectral notches near 1.2 and 3.9 MHz
    u = measured_response(drive, 1e-3, rng)
    noise = noise_floor(u, (0, 1.4e-6), sampling_rate=FS, segment_length=32)
    truth = true_ir(np.arange(N * 10) / FS_HI)
    f = frequency_axis(truth.size, FS_HI)
    wide = (f >= 0.5e6) & (f <= 5e6)
    corr = {snr: correlation_in_band(
        transmit_impulse_response(u, FS, drive, noise_response=noise, snr=snr).ir,
        truth, FS_HI, wide)[0] for snr in ("measured", "excess")}
    assert corr["excess"] >= 0.99
    assert corr["excess"] > corr["measured"]


def test_delta_like_test_accepts_a_12_ns_pulse_and_rejects_a_burst_and_a_long_pulse():
    u = measured_response(rect_drive(), 0.0, np.random.default_rng(0))
    assert drive_is_delta_like(rect_drive(), u, FS)
    assert not drive_is_delta_like(burst_drive(), u, FS)
    long_pulse = DriveSignal(voltage=np.r_[np.full(40, 30.0), np.zeros(10)], sampling_rate=FS_HI)
    assert not drive_is_delta_like(long_pulse, u, FS)  # 160 ns: sinc droops 10 % at 2 MHz


def test_wiener_deconvolution_recovers_a_known_filter_with_noise_on_both_signals():
    rng = np.random.default_rng(4)
    n, fs = 1024, 25e6
    t = np.arange(n) / fs
    p = np.exp(-((t - 4e-6) / 0.08e-6) ** 2)  # broadband input pulse
    h = true_ir(t) / 1e11
    y = np.convolve(h, p)[:n] / fs
    sy, sp = 1e-3 * np.abs(y).max(), 1e-3 * p.max()
    y_noisy = y + sy * rng.standard_normal(n)
    p_noisy = p + sp * rng.standard_normal(n)
    est = wiener_deconvolve(y_noisy, p_noisy, noise_output=n * sy**2, noise_input=n * sp**2,
                            sampling_rate=fs)
    a, b = band(est, fs), band(h, fs)
    assert np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b) > 0.995


def test_wiener_of_identical_signals_is_a_unit_delta_shrunk_by_the_regulariser():
    # reference_spec 8 item 15: y = p with floors −70 dB / −50 dB re the peak amplitude
    n, fs = 256, 25e6
    t = np.arange(n) / fs
    p = np.exp(-((t - 2e-6) / 0.1e-6) ** 2)
    peak = np.abs(to_frequency(p)).max()
    h = wiener_deconvolve(p, p, noise_output=(10 ** (-70 / 20) * peak) ** 2,
                          noise_input=(10 ** (-50 / 20) * peak) ** 2, sampling_rate=fs)
    H = to_frequency(h) / fs
    assert H[0].real == pytest.approx(1 / (1 + 1e-7 + 1e-5), rel=1e-12)


def test_noise_floor_of_white_noise_is_n_sigma_squared_per_bin():
    rng = np.random.default_rng(5)
    x = 0.3 * rng.standard_normal(4096)
    floor = noise_floor(x, (0, 4095 / 25e6), sampling_rate=25e6, n=1000)
    assert floor.shape == (501,)
    assert np.mean(floor) == pytest.approx(1000 * 0.09, rel=0.05)


def test_bad_noise_shape_and_method_raise_input_error():
    with pytest.raises(InputError, match="noise_output"):
        wiener_deconvolve(np.ones(16), np.ones(16), noise_output=np.ones(5), noise_input=1.0,
                          sampling_rate=1.0)
    with pytest.raises(InputError, match="method"):
        transmit_impulse_response(np.ones(16), FS, rect_drive(), method="magic")
