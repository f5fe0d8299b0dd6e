"""Band-limited resampling and fractional delays (holoprobe.signal._resample)."""

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.signal import fractional_delay, resample

FS = 25e6
N = 200
T = N / FS


def periodic(t, harmonics=((3, 1.0, 0.3), (41, 0.5, -1.0))):
    """A band-limited signal, periodic over the record (harmonic k of 1/T)."""
    return sum(a * np.cos(2 * np.pi * k / T * t + ph) for k, a, ph in harmonics)


@pytest.mark.parametrize("new_rate", [250e6, 100e6, 37.3e6, 60e6])
def test_upsampling_reproduces_the_analytic_band_limited_signal(new_rate):
    x = periodic(np.arange(N) / FS)
    y = resample(x, FS, new_rate)
    assert y.size == int(np.ceil(N * new_rate / FS - 1e-9))
    np.testing.assert_allclose(y, periodic(np.arange(y.size) / new_rate), atol=1e-9)


@pytest.mark.parametrize("new_rate", [8e6, 9.7e6])
def test_downsampling_removes_components_above_the_new_nyquist(new_rate):
    x = periodic(np.arange(N) / FS)  # 41/T = 5.125 MHz > new Nyquist
    y = resample(x, FS, new_rate)
    low = periodic(np.arange(y.size) / new_rate, harmonics=((3, 1.0, 0.3),))
    np.testing.assert_allclose(y, low, atol=1e-9)


def test_resample_along_any_axis_and_polyphase_agrees_inside_the_record():
    x = periodic(np.arange(N) / FS)
    stack = np.stack([x, 2 * x])
    y = resample(stack.T, FS, 100e6, axis=0)
    np.testing.assert_allclose(y[:, 1], 2 * resample(x, FS, 100e6), atol=1e-12)
    poly = resample(x, FS, 100e6, method="polyphase")
    ref = periodic(np.arange(poly.size) / 100e6)
    # polyphase is not periodic: compare away from the record ends
    np.testing.assert_allclose(poly[100:-100], ref[100:-100], atol=2e-2)


def test_fractional_delay_moves_a_band_limited_signal_by_non_integer_times():
    t = np.arange(N) / FS
    x = periodic(t)
    for delay in (13.7e-9, -0.31e-6, 2.5 / FS):
        np.testing.assert_allclose(fractional_delay(x, delay, FS), periodic(t - delay),
                                   atol=1e-12)
    traces = np.stack([x, x, x])
    delays = np.array([1e-8, -3e-8, 0.0])
    out = fractional_delay(traces, delays, FS)
    for row, d in zip(out, delays, strict=True):
        np.testing.assert_allclose(row, periodic(t - d), atol=1e-12)


def test_fractional_delay_with_padding_does_not_wrap_a_pulse_around():
    t = np.arange(N) / FS
    pulse = np.exp(-((t - 7.5e-6) / 0.1e-6) ** 2)  # near the end of an 8 µs record
    circular = fractional_delay(pulse, 1e-6, FS)
    padded = fractional_delay(pulse, 1e-6, FS, pad=True)
    assert circular[:20].max() > 0.5  # wrapped to the start
    assert np.abs(padded).max() < 1e-6  # left the record instead


def test_bad_arguments_raise_input_error():
    with pytest.raises(InputError):
        resample(np.ones(10), FS, -1.0)
    with pytest.raises(InputError):
        resample(np.ones(10), FS, 10e6, axis=3)
    with pytest.raises(InputError):
        fractional_delay(np.ones((3, 10)), np.ones(4), FS)
