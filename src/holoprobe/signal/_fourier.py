"""The Fourier convention of holoprobe (paper eq. complex-conjugate-fourier).

A time signal p(t) becomes ``P(ω) = conj(FFT{p})``, so that plane waves read
``exp(i k·r − i ω t)``. Only non-negative frequencies are kept (``rfft`` then
``conj``); the way back is ``irfft(conj(P))``. These two helpers own the
convention: nothing else in holoprobe calls an FFT on time signals directly.
"""

from __future__ import annotations

import os

import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

__all__ = ["frequency_axis", "next_fast_length", "to_frequency", "to_time", "workers"]


def workers() -> int:
    """Number of threads handed to ``scipy.fft`` (all cores available to the process)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def next_fast_length(n: int) -> int:
    """The smallest length ≥ n that ``scipy.fft`` transforms quickly."""
    return int(scipy.fft.next_fast_len(int(n), real=True))


def to_frequency(signal: ArrayLike, *, n: int | None = None, axis: int = -1) -> NDArray:
    """Time → frequency with the conjugate convention, non-negative frequencies only.

    Parameters
    ----------
    signal : array_like, real
        Time signals; time along ``axis``.
    n : int, optional
        Transform length (zero-padding or truncation), default the signal length.
    axis : int
        The time axis.

    Returns
    -------
    ndarray, complex
        ``conj(rfft(signal, n))``: ``n // 2 + 1`` bins along ``axis`` (unscaled, like
        ``numpy.fft.rfft``). Multiply by the sample interval for a continuous-time
        Fourier transform in units·s.
    """
    signal = np.asarray(signal)
    if np.iscomplexobj(signal):
        raise TypeError("to_frequency expects real time signals")
    return np.conj(scipy.fft.rfft(signal, n=n, axis=axis, workers=workers()))


def to_time(spectrum: ArrayLike, n: int, *, axis: int = -1) -> NDArray:
    """Frequency → time: the inverse of :func:`to_frequency`.

    Parameters
    ----------
    spectrum : array_like, complex
        ``n // 2 + 1`` non-negative frequency bins along ``axis`` in the conjugate
        convention.
    n : int
        Number of time samples to return.
    axis : int
        The frequency axis.

    Returns
    -------
    ndarray, real
        ``irfft(conj(spectrum), n)``.
    """
    return scipy.fft.irfft(np.conj(np.asarray(spectrum)), n=n, axis=axis, workers=workers())


def frequency_axis(n: int, sampling_rate: float) -> NDArray[np.float64]:
    """Frequencies in Hz of the ``n // 2 + 1`` bins returned by :func:`to_frequency`."""
    return np.fft.rfftfreq(int(n), d=1.0 / float(sampling_rate))
