"""Summary numbers of a pulse's amplitude spectrum: peak, −6 dB band, centre frequency."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from holoprobe.errors import InputError
from holoprobe.signal._fourier import frequency_axis, next_fast_length, to_frequency
from holoprobe.signal._resample import _positive, _real_signal

__all__ = ["SpectrumSummary", "spectrum_summary"]


@dataclass(frozen=True)
class SpectrumSummary:
    """Amplitude-spectrum summary of a pulse (all in Hz except the fraction).

    Attributes
    ----------
    peak_frequency : float
        Frequency of the spectral maximum.
    f_low, f_high : float
        Edges of the band around the peak where the amplitude is within ``level_db`` of
        the maximum.
    bandwidth : float
        ``f_high − f_low``.
    center_frequency : float
        ``(f_low + f_high) / 2``.
    fractional_bandwidth : float
        ``bandwidth / center_frequency``.
    level_db : float
        The level that defines the band (dB re the peak amplitude).
    """

    peak_frequency: float
    f_low: float
    f_high: float
    bandwidth: float
    center_frequency: float
    fractional_bandwidth: float
    level_db: float


def spectrum_summary(signal: ArrayLike, sampling_rate: float, *, pad_factor: int = 8,
                     level_db: float = -6.0) -> SpectrumSummary:
    """Peak frequency and band of a pulse's amplitude spectrum.

    The record is zero-padded to ``pad_factor`` times its length; the peak is refined
    below the bin spacing by a parabola through the three largest dB values (exact for a
    Gaussian spectrum); the band edges are where the amplitude, linearly interpolated in
    dB between bins, falls to ``level_db`` below the peak, walking outwards from the peak
    (the contiguous band containing it). An edge that is not reached is DC or Nyquist.

    Parameters
    ----------
    signal : array_like, shape (n,)
        The pulse (e.g. an impulse response).
    sampling_rate : float
        Sampling rate in Hz.
    pad_factor : int
        Zero-padding factor (≥ 1).
    level_db : float
        Band level in dB re the peak (negative), −6 dB by default.

    Returns
    -------
    SpectrumSummary
    """
    x = _real_signal(signal).astype(float, copy=False)
    if x.ndim != 1 or x.size < 2:
        raise InputError(f"expected a 1-D record of at least 2 samples, got shape {x.shape}",
                         field="signal")
    fs = _positive(sampling_rate, "sampling_rate")
    if int(pad_factor) < 1:
        raise InputError("expected an integer ≥ 1", field="pad_factor")
    if not level_db < 0:
        raise InputError(f"expected a negative level in dB, got {level_db!r}",
                         field="level_db")
    n = next_fast_length(x.size * int(pad_factor))
    mag = np.abs(to_frequency(x, n=n))
    if not np.any(mag > 0):
        raise InputError("the signal is zero: no spectrum to summarise", field="signal")
    f = frequency_axis(n, fs)
    df = f[1] - f[0]
    with np.errstate(divide="ignore"):
        db = 20 * np.log10(mag / mag.max())
    k = int(np.argmax(mag))
    if 0 < k < mag.size - 1 and np.all(np.isfinite(db[k - 1:k + 2])):
        a, b, c = db[k - 1], db[k], db[k + 1]
        den = a - 2 * b + c
        delta = 0.5 * (a - c) / den if den != 0 else 0.0
        peak = f[k] + delta * df
        peak_db = b - 0.25 * (a - c) * delta
    else:
        peak, peak_db = f[k], db[k]
    level = peak_db + level_db

    def edge(direction: int) -> float:
        i = k
        while 0 <= i + direction < mag.size:
            j = i + direction
            if db[j] < level:
                lo, hi = db[j], db[i]
                frac = (hi - level) / (hi - lo) if np.isfinite(lo) else 0.0
                return float(f[i] + direction * frac * df)
            i = j
        return float(f[i])

    f_low, f_high = edge(-1), edge(+1)
    bw = f_high - f_low
    fc = 0.5 * (f_low + f_high)
    return SpectrumSummary(peak_frequency=float(peak), f_low=f_low, f_high=f_high,
                           bandwidth=bw, center_frequency=fc,
                           fractional_bandwidth=bw / fc if fc > 0 else float("nan"),
                           level_db=float(level_db))
