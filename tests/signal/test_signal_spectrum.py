"""Spectrum summary of a pulse (holoprobe.signal._spectrum)."""

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.signal import spectrum_summary


def test_gaussian_pulse_has_analytic_peak_and_minus_6_db_band():
    fs, n = 50e6, 1024
    f0, s = 2.5e6, 0.25e-6
    t = (np.arange(n) - n // 2) / fs
    x = np.exp(-t**2 / (2 * s**2)) * np.cos(2 * np.pi * f0 * t)
    # |X(f)| ∝ exp(−(2π(f − f0))² s² / 2): −6 dB at f0 ± sqrt(2 ln(1/a)) / (2π s)
    half = np.sqrt(2 * np.log(1 / 10 ** (-6 / 20))) / (2 * np.pi * s)
    out = spectrum_summary(x, fs)
    assert out.peak_frequency == pytest.approx(f0, rel=1e-4)
    assert out.f_low == pytest.approx(f0 - half, rel=1e-3)
    assert out.f_high == pytest.approx(f0 + half, rel=1e-3)
    assert out.bandwidth == pytest.approx(2 * half, rel=2e-3)
    assert out.center_frequency == pytest.approx(f0, rel=1e-3)
    assert out.fractional_bandwidth == pytest.approx(2 * half / f0, rel=2e-3)


def test_sub_bin_peak_between_bins_of_a_short_record():
    fs, n = 25e6, 64  # 0.39 MHz bins before padding
    f0, s = 3.1e6, 0.3e-6
    t = (np.arange(n) - n // 2) / fs
    x = np.exp(-t**2 / (2 * s**2)) * np.sin(2 * np.pi * f0 * t + 0.4)
    assert spectrum_summary(x, fs, pad_factor=16).peak_frequency == pytest.approx(f0, rel=2e-3)


def test_zero_signal_raises_input_error():
    with pytest.raises(InputError):
        spectrum_summary(np.zeros(16), 1e6)
