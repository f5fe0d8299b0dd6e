"""The NumPy Butterworth high-pass and zero-phase filter against scipy.signal and the
Butterworth response."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

from holoprobe.errors import InputError
from holoprobe.signal import butter_highpass_sos, sosfiltfilt


def _response(sos: np.ndarray, f: np.ndarray, fs: float) -> np.ndarray:
    z = np.exp(-2j * np.pi * f / fs)
    h = np.ones(f.shape, dtype=complex)
    for b0, b1, b2, a0, a1, a2 in sos:
        h *= (b0 + b1 * z + b2 * z**2) / (a0 + a1 * z + a2 * z**2)
    return h


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5, 6, 8])
@pytest.mark.parametrize(("cutoff", "fs"), [(0.1e6, 25e6), (2e6, 20e6), (0.3, 10.0),
                                            (8e6, 25e6), (12.4e6, 25e6), (0.45, 1.0)])
def test_butter_highpass_has_scipys_transfer_function_and_the_butterworth_magnitude(
        order, cutoff, fs):
    """The same transfer function as scipy.signal.butter (its frequency response and its
    zero-phase filtering of a record), cut-offs up to 0.45 fs (where scipy orders an odd
    order's zeros otherwise, review A: the sections themselves differ there)."""
    sos = butter_highpass_sos(order, cutoff, fs)
    ref = scipy.signal.butter(order, cutoff, "highpass", fs=fs, output="sos")
    assert sos.shape == ref.shape
    f = np.linspace(0.002, 0.498, 200) * fs
    np.testing.assert_allclose(_response(sos, f, fs),
                               scipy.signal.sosfreqz(ref, f, fs=fs)[1], rtol=0, atol=1e-12)
    x = np.random.default_rng(order).normal(size=600) + 1.0
    want = scipy.signal.sosfiltfilt(ref, x)
    np.testing.assert_allclose(sosfiltfilt(sos, x), want, rtol=0,
                               atol=1e-12 * np.abs(want).max())
    # |H|² = 1 / (1 + (tan(πfc/fs) / tan(πf/fs))^(2N)) for the bilinear Butterworth
    f = np.array([0.3, 1.0, 3.0, 10.0]) * cutoff
    f = f[f < 0.5 * fs]
    ratio = np.tan(np.pi * cutoff / fs) / np.tan(np.pi * f / fs)
    np.testing.assert_allclose(np.abs(_response(sos, f, fs)) ** 2,
                               1 / (1 + ratio ** (2 * order)), rtol=1e-9)


@pytest.mark.parametrize("order", [1, 3, 4, 7])
def test_sosfiltfilt_matches_scipy(order):
    rng = np.random.default_rng(order)
    x = rng.normal(size=4800) + np.linspace(0.0, 3.0, 4800) + 2.0  # offset and drift
    sos = scipy.signal.butter(order, 0.1e6, "highpass", fs=25e6, output="sos")
    got = sosfiltfilt(sos, x)
    np.testing.assert_allclose(got, scipy.signal.sosfiltfilt(sos, x), rtol=0,
                               atol=1e-12 * np.abs(x).max())


def test_sosfiltfilt_is_zero_phase_and_removes_the_offset():
    fs, f0 = 25e6, 3e6
    t = np.arange(6000) / fs
    x = 5.0 + np.sin(2 * np.pi * f0 * t)  # an offset and a tone far above the cut-off
    y = sosfiltfilt(butter_highpass_sos(3, 0.1e6, fs), x)
    mid = slice(1000, 5000)  # away from the ends' transients
    gain = 1 / (1 + (np.tan(np.pi * 0.1e6 / fs) / np.tan(np.pi * f0 / fs)) ** 6)  # |H|²
    np.testing.assert_allclose(y[mid], gain * np.sin(2 * np.pi * f0 * t[mid]), atol=1e-5)


def test_bad_arguments_are_refused():
    with pytest.raises(InputError, match="highpass_order"):
        butter_highpass_sos(0, 1e5, 25e6)
    with pytest.raises(InputError, match="highpass_cutoff"):
        butter_highpass_sos(3, 13e6, 25e6)
    # a cut-off so low that the poles round onto z = 1 (review A: a raw LinAlgError from
    # the filtering before; fails on the old code)
    with pytest.raises(InputError, match=r"highpass_cutoff.*\[0\.001, 50\) Hz.*got 1e-07"):
        butter_highpass_sos(4, 1e-7, 100.0)
    assert butter_highpass_sos(4, 1e-3, 100.0).shape == (2, 6)  # the smallest allowed
    with pytest.raises(InputError, match="samples"):
        sosfiltfilt(butter_highpass_sos(3, 1e5, 25e6), np.ones(12))
