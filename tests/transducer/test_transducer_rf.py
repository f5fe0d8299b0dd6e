"""RF of point scatterers: arrival times, the receive hyperbola and the far-field amplitude.

Checked against closed forms computed here with NumPy's own FFT: travel times
from the geometry, and the far field of a small baffled element on transmit and
receive (p = ρ0 A/(2πR) du/dt, a spherical echo a/R, E_R = h_R ⊛ p_R).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import hilbert

from holoprobe.errors import InputError
from holoprobe.geometry import Medium
from holoprobe.transducer import (
    TransmitSetting,
    VirtualTransducer,
    burst,
    simulate_rf,
)

FS = 100e6
C0 = 1481.0
MEDIUM = Medium()


def _pulse(n, fc, tc, sigma, a):
    t = np.arange(n) / FS
    return a * np.exp(-(((t - tc) / sigma) ** 2)) * np.sin(2 * np.pi * fc * (t - tc))


def _model(n=16, width=0.25e-3, height=1e-3, pitch=0.3e-3, focus=np.inf):
    return VirtualTransducer(
        element_count=n, pitch=pitch, element_width=width, element_height=height,
        transmit_impulse_response=_pulse(300, 2e6, 0.8e-6, 0.3e-6, 1e11),
        transmit_sampling_rate=FS, lens_focus=focus, medium=MEDIUM,
        receive_impulse_response=_pulse(300, 2e6, 0.7e-6, 0.3e-6, 1e6),
        receive_sampling_rate=FS, receive_units="V/(Pa*s)")


def _shift(signal, delay, n):
    """signal(t − delay) on n samples (NumPy's FFT convention, independent of holoprobe)."""
    f = np.fft.rfftfreq(n, 1 / FS)
    return np.fft.irfft(np.fft.rfft(signal, n) * np.exp(-2j * np.pi * f * delay), n)


def test_echo_of_an_on_axis_scatterer_arrives_on_the_round_trip_hyperbola():
    depth = 20e-3
    height = 2e-3
    vt = _model(n=16, focus=depth, height=height)  # lens focused at the scatterer depth
    target = np.array([[0.0, 0.0, depth]])
    tx = TransmitSetting.focused(target[0], drive=burst(2e6, 1, 10.0, sampling_rate=FS))
    rf = simulate_rf(vt, tx, target, [1e-4], sampling_rate=FS)
    assert rf.shape[0] == 16
    xe = vt.element_centers()[:, 0]
    r = np.hypot(xe, depth)
    tau = (r.max() - r) / C0
    # transmit focused on the scatterer: every element arrives at max(τ_e + R_e/c0);
    # the lens makes every elevation path to its focus as long as its rim path, both ways
    lens = (np.hypot(height / 2, depth) - depth) / C0
    expected = (tau + r / C0).max() + r / C0 + 2 * lens
    # the pulse shape: second derivative of h_T ⊛ E ⊛ h_R (far field on both ways)
    s = np.convolve(np.convolve(vt.transmit_impulse_response, tx.drive.voltage),
                    vt.receive_impulse_response)
    s = np.gradient(np.gradient(s))
    es = np.abs(hilbert(np.pad(s, (0, 2000))))
    j = int(np.argmax(es))
    t_pulse = (j + 0.5 * (es[j - 1] - es[j + 1]) / (es[j - 1] - 2 * es[j] + es[j + 1])) / FS
    env = np.abs(hilbert(rf, axis=1))
    i = np.argmax(env, axis=1)
    y0, y1, y2 = (env[np.arange(16), i + d] for d in (-1, 0, 1))
    t_peak = (i + 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2)) / FS
    np.testing.assert_allclose(t_peak - t_pulse, expected, atol=5e-9)
    assert 2 * lens > 20e-9  # the lens delay is resolved too
    # relative arrivals by sub-sample cross-correlation with the centre element
    ref = rf[8]
    lags = []
    for e in range(16):
        xc = np.correlate(rf[e], ref, mode="full")
        i = int(np.argmax(xc))
        y0, y1, y2 = xc[i - 1], xc[i], xc[i + 1]
        lags.append((i - (rf.shape[1] - 1) + 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2)) / FS)
    np.testing.assert_allclose(lags, (r - r[8]) / C0, atol=3e-9)
    assert (r.max() - r.min()) / C0 > 20e-9  # the hyperbola is resolved


def test_single_small_element_echo_matches_the_far_field_closed_form():
    width = height = 0.1e-3
    vt = _model(n=1, width=width, height=height)
    tx = TransmitSetting(burst(2e6, 1, 5.0, sampling_rate=FS))
    z, a = 15e-3, 2e-4
    n = 4096
    rf = simulate_rf(vt, tx, [[0.0, 0.0, z]], [a], sampling_rate=FS, n_samples=n,
                     band_threshold_db=-80.0)[0]
    # u = h_T ⊛ E/(ρ0c0); p_inc = ρ0 A/(2πz) du/dt(t − z/c0); p_R = a/z p_inc(t − z/c0)
    u = np.convolve(vt.transmit_impulse_response, tx.drive.voltage) / FS / MEDIUM.impedance
    du = np.gradient(u, 1 / FS)
    p_r = a / z * MEDIUM.density * width * height / (2 * np.pi * z) * du
    expected = _shift(np.convolve(p_r, vt.receive_impulse_response)[:n] / FS, 2 * z / C0, n)
    err = np.max(np.abs(rf - expected)) / np.max(np.abs(expected))
    assert err < 0.02, err


def test_rf_is_linear_in_the_scatterers():
    vt = _model(n=4)
    tx = TransmitSetting(burst(2e6, 1, 5.0, sampling_rate=FS))
    s1, s2 = [0.2e-3, 0.0, 8e-3], [-0.5e-3, 0.1e-3, 11e-3]
    kw = {"sampling_rate": FS, "n_samples": 2048}
    both = simulate_rf(vt, tx, [s1, s2], [1e-4, -3e-4], **kw)
    one = simulate_rf(vt, tx, [s1], [1e-4], **kw)
    two = simulate_rf(vt, tx, [s2], [-3e-4], **kw)
    np.testing.assert_allclose(both, one + two, atol=1e-9 * np.max(np.abs(both)))


def test_rf_without_receive_impulse_response_is_a_clear_error():
    vt = _model(n=2).replace(receive_impulse_response=None, receive_sampling_rate=None)
    tx = TransmitSetting(burst(2e6, 1, 5.0, sampling_rate=FS))
    with pytest.raises(InputError, match="receive impulse response"):
        simulate_rf(vt, tx, [[0, 0, 1e-2]], [1e-4])
    with pytest.raises(InputError, match="amplitudes"):
        simulate_rf(_model(n=2), tx, [[0, 0, 1e-2]], [1e-4, 2e-4])
