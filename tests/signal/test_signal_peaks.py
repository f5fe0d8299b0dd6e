"""Peaks of band-limited records between samples (holoprobe.signal.band_limited_peaks)."""

import numpy as np
import pytest

from holoprobe.errors import InputError
from holoprobe.signal import band_limited_peaks


def _pulses(n: int, fs: float, f_top: float, count: int, seed: int):
    """Random periodic band-limited records (spectrum up to f_top) and their true extremes
    from the same trigonometric series evaluated at 64 times the rate."""
    rng = np.random.default_rng(seed)
    f = np.fft.rfftfreq(n, 1 / fs)
    inside = (f > 0) & (f <= f_top)
    spec = np.zeros((count, f.size), complex)
    delay = rng.uniform(0, n / fs, count)
    shape = np.exp(-(((f[inside] - 0.55 * f_top) / (0.25 * f_top)) ** 2))
    spec[:, inside] = (shape * np.exp(-2j * np.pi * f[inside] * delay[:, None])
                       * (1 + 0.3 * rng.standard_normal((count, inside.sum()))))
    dense = np.fft.irfft(spec, 64 * n) * 64
    return np.fft.irfft(spec, n), dense.max(axis=1), -dense.min(axis=1)


@pytest.mark.parametrize(("fs_over_top", "dtype", "tol"),
                         [(8.0, np.float64, 2e-5), (8.0, np.float32, 2e-5),
                          (4.0, np.float64, 1e-4)])
def test_peaks_match_the_densely_evaluated_series(fs_over_top, dtype, tol):
    n, f_top = 900, 4.5e6
    rec, top, bottom = _pulses(n, fs_over_top * f_top, f_top, 400, seed=3)
    pos, neg = band_limited_peaks(rec.astype(dtype), 2.0 / fs_over_top)
    scale = np.abs(rec).max(axis=1)
    assert np.max(np.abs(pos - top) / scale) < tol
    assert np.max(np.abs(neg - bottom) / scale) < tol
    # the raw samples miss the extremes by far more than that
    assert np.max((top - rec.max(axis=1)) / scale) > 100 * tol


def test_peaks_of_a_pulse_across_the_record_end_and_of_zero_records():
    n = 64
    t = np.arange(n)
    # a 2-cycle pulse centred 0.3 samples before the first sample (it wraps around)
    x = (t - n - 0.3 + n / 2) % n - n / 2
    pulse = np.cos(2 * np.pi * x / 10.0) * np.exp(-((x / 6.0) ** 2))
    fine = (np.linspace(0, n, 64 * n, endpoint=False) - n - 0.3 + n / 2) % n - n / 2
    true = np.cos(2 * np.pi * fine / 10.0) * np.exp(-((fine / 6.0) ** 2))
    pos, neg = band_limited_peaks(np.stack([pulse, np.zeros(n)]), 0.45)
    assert pos[0] == pytest.approx(true.max(), abs=2e-4)
    assert neg[0] == pytest.approx(-true.min(), abs=2e-4)
    assert pos[1] == 0 and neg[1] == 0


@pytest.mark.parametrize(("records", "band", "field"),
                         [(np.zeros(8), 0.3, "records"), (np.zeros((2, 32), complex), 0.3,
                                                          "records"),
                          (np.zeros(32), 0.7, "band"), (np.zeros(32), 0.0, "band")])
def test_bad_inputs_name_the_field(records, band, field):
    with pytest.raises(InputError, match=field):
        band_limited_peaks(records, band)
