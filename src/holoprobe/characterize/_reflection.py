"""Reflection coefficient of the plate from the echo train (reference_spec 2.9 step 4).

Model: a plate immersed in water, pressure reflection coefficient Rp at its front face
(water → plate) and ``−Rp`` for a wave inside the plate meeting either face. Relative to
the incident wave the echo train is

    p1 = Rp,   p2 = −(1 − Rp²) Rp e^{−α},   p3 = −(1 − Rp²) Rp³ e^{−2α}, …

(α: round-trip attenuation in the plate). Without attenuation
``A = |p1/p2| = 1/(1 − Rp²)``, so ``Rp = √(1 − 1/A)``, which the published code writes as
``Rp = (x − 1)/(x + 1)``, ``x = 2A − 1 + 2√(A² − A)`` (the same number). With
attenuation ``A = |p3/p2| / |p2/p1| = Rp²/(1 − Rp²)``, so ``Rp = √(A/(1 + A))``
(published: ``x = 1 + 2A + 2√(A² + A)``). The published code returns a complex Rp when
the second echo is larger than the first and crashes when the envelope never falls
below the peak fraction (reference_spec 7 item 6); here both give a clear
:class:`~holoprobe.errors.InputError`, or a warning and a user-given fallback.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import FitError, InputError
from holoprobe.signal import envelope

__all__ = [
    "ReflectionEstimate",
    "echo_amplitudes",
    "echo_train_peaks",
    "estimate_reflection_coefficient",
    "reflection_coefficient_from_peaks",
]


def reflection_coefficient_from_peaks(peaks: ArrayLike, *, attenuating: bool = False) -> float:
    """Rp from the amplitudes of the first echoes of the train (see module notes).

    Parameters
    ----------
    peaks : array_like, shape (m,)
        Amplitudes (signed or envelope) of the front-face echo and the following
        reverberations; m ≥ 2 (m ≥ 3 with ``attenuating``).
    attenuating : bool
        Use the ratio of ratios ``|p3/p2| / |p2/p1|``, which cancels a round-trip
        attenuation in the plate.

    Returns
    -------
    float
        Rp in [0, 1).

    Raises
    ------
    InputError
        Too few peaks, a zero or non-finite peak, or (without attenuation) a second echo
        not smaller than the first (the train does not follow the plate model).

    Examples
    --------
    >>> round(reflection_coefficient_from_peaks([2.553626, 1]), 6)
    0.78
    """
    p = np.abs(np.asarray(peaks, dtype=float).reshape(-1))
    need = 3 if attenuating else 2
    if p.size < need or not np.all(np.isfinite(p[:need])) or np.any(p[:need] == 0):
        raise InputError(f"expected at least {need} finite, non-zero echo amplitudes, got "
                         f"{np.asarray(peaks).tolist()!r}", field="peaks")
    if attenuating:
        a = p[0] * p[2] / p[1] ** 2
        return math.sqrt(a / (1.0 + a))
    a = p[0] / p[1]
    if not a > 1.0:
        raise FitError(f"the second echo ({p[1]:.4g}) is not smaller than the first "
                       f"({p[0]:.4g}): the echo train does not give a real reflection "
                       f"coefficient (expected |p1/p2| = 1/(1 − Rp²) > 1); give the "
                       f"reflection coefficient explicitly", field="peaks")
    return math.sqrt(1.0 - 1.0 / a)


def echo_train_peaks(signal: ArrayLike, sampling_rate: float, *, start_time: float = 0.0,
                     search_from: float | None = None, fraction: float = 0.2,
                     count: int = 5, min_snr: float = 4.0,
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Successive envelope peaks of an echo train, in order of arrival.

    The envelope is ``|hilbert(signal − mean)|``. Each echo starts where the envelope
    first reaches ``fraction`` of the largest envelope value still ahead, and ends where
    the envelope falls below ``fraction`` of its running maximum; its peak is the
    maximum in between (parabolic sub-sample refinement). The next search starts once the
    tail of that echo has fallen below ``fraction`` of the largest envelope value ahead,
    and no earlier than one echo duration (above ``fraction``) after its peak. The first
    echo is thus the first one in time, not the largest (a second echo larger than the
    first stays visible). The search stops after ``count`` echoes, when the envelope
    never falls below the fraction again, or when a peak is less than ``min_snr`` times
    the median envelope before the first echo (noise).

    Parameters
    ----------
    signal : array_like, shape (n,)
        A trace (e.g. the tilt-aligned average RF).
    sampling_rate : float
        Hz.
    start_time : float
        Time of the first sample in s.
    search_from : float, optional
        Where the first echo may start (s, same clock); default the first sample.
    fraction : float
        Fall-off that separates two echoes (0 < fraction < 1).
    count : int
        Largest number of peaks.
    min_snr : float
        Smallest accepted peak over the pre-echo median envelope.

    Returns
    -------
    times : ndarray, shape (m,)
        Peak times in s, m ≤ count.
    amplitudes : ndarray, shape (m,)
        Envelope values at the peaks.

    Notes
    -----
    A peak below the noise level (``min_snr``) is skipped and the search goes on: it
    used to end the train, so that at 25 dB a noise bump between the receive IR's tail
    lobe (0.05–0.09 of the front echo, above ``fraction`` of the back wall ahead) and
    the back-wall echo left the tail lobe as the "second echo": Rp 0.95 instead of
    0.876 and the receive IR truncated after 1 µs (2 of 4 draws on a 32-element twin).
    """
    x = np.asarray(signal, dtype=float).reshape(-1)
    if x.size < 8 or not np.all(np.isfinite(x)):
        raise InputError(f"expected a finite 1-D trace of at least 8 samples, got shape "
                         f"{np.shape(signal)}", field="signal")
    fs = float(sampling_rate)
    if not (np.isfinite(fs) and fs > 0):
        raise InputError(f"expected a positive sampling rate, got {sampling_rate!r}",
                         field="sampling_rate")
    if not 0 < fraction < 1:
        raise InputError(f"expected 0 < fraction < 1, got {fraction!r}", field="fraction")
    env = envelope(x - x.mean(), pad=False)
    i = 0 if search_from is None else int(max(0, math.ceil((search_from - start_time) * fs)))
    times: list[float] = []
    amps: list[float] = []
    floor = 0.0
    while len(times) < int(count) and i < env.size - 2:
        rest = env[i:]
        j0 = int(np.argmax(rest >= fraction * rest.max()))
        if not times and j0 >= 8:
            floor = float(min_snr) * float(np.median(rest[:j0]))
        run = np.maximum.accumulate(rest[j0:])
        below = np.nonzero(rest[j0:] < fraction * run)[0]
        end = j0 + (int(below[0]) if below.size else rest.size - j0)
        k = i + j0 + int(np.argmax(rest[j0:end]))
        if not times or env[k] > floor:  # a bump of noise is passed over, not an end
            times.append(start_time + _refined_peak(env, k)[0] / fs)
            amps.append(_refined_peak(env, k)[1])
        if not below.size:
            break
        span = end - j0
        i += end
        if i >= env.size - 2:
            break
        # skip the tail of this echo: wait until the envelope is below the detection level
        # of the next one
        drop = np.nonzero(env[i:] < fraction * env[i:].max())[0]
        if not drop.size:
            break
        i = max(i + int(drop[0]), k + span)  # echoes last about as long as each other
    return np.asarray(times), np.asarray(amps)


def echo_amplitudes(
    signal: ArrayLike,
    sampling_rate: float,
    times: ArrayLike,
    *,
    start_time: float = 0.0,
    fit: int = 2,
) -> tuple[NDArray[np.float64], float]:
    """Amplitudes of the echoes of a train as multiples of one common waveform.

    Each echo is cut from ``signal`` over the same window relative to its peak time,
    ``[t_k − T/4, t_k + 0.6 T)`` (``T = t_2 − t_1``), shifted by its sub-sample
    remainder onto a common grid (band-limited shift, zero padding outside the record),
    and the first ``fit`` echoes are fitted as one waveform times one amplitude each:
    the rank-1 least-squares fit (largest singular pair of the window matrix). White
    or stationary noise adds the same energy to every window, σ²·L·I to the windows'
    Gram matrix, which leaves its eigenvectors, and so the amplitude ratios, unbiased;
    the envelope maximum of a noisy echo is biased high (about one noise σ: +0.5 % on
    the first echo, +1.9 % on the second of the full-size P4-1 twin at its noise, Rp
    −0.34 %). Further echoes are projected onto the fitted waveform.

    Parameters
    ----------
    signal : array_like, shape (n,)
        The echo trace (any unit u).
    sampling_rate : float
        Hz.
    times : array_like, shape (m,)
        Peak times of the echoes in s (:func:`echo_train_peaks`), m ≥ 2.
    start_time : float
        Time of the first sample in s.
    fit : int
        How many of the first echoes share the fit (2 ≤ fit ≤ m).

    Returns
    -------
    amplitudes : ndarray, shape (m,)
        Envelope peak of the fitted waveform times each echo's |amplitude| (u).
    noise_gain : float
        σ of each amplitude per unit noise σ of ``signal`` (white noise): the envelope
        peak of the unit-energy waveform.
    """
    x = np.asarray(signal, dtype=float).reshape(-1)
    t = np.asarray(times, dtype=float).reshape(-1)
    fs = float(sampling_rate)
    if t.size < 2 or not 2 <= fit <= t.size:
        raise InputError(
            f"expected at least 2 echo times and 2 <= fit <= {t.size}, got "
            f"{t.size} times and fit={fit!r}",
            field="times",
        )
    period = (t[1] - t[0]) * fs
    if not period > 2:
        raise InputError(f"expected increasing echo times, got {t.tolist()!r}", field="times")
    n = max(4, round(0.85 * period))
    pos = (t - start_time) * fs - 0.25 * period
    first = np.floor(pos).astype(int)
    n_pad = 2 * n
    windows = np.zeros((t.size, n_pad))
    for k, i0 in enumerate(first):
        lo, hi = max(i0, 0), min(i0 + n, x.size)
        if hi > lo:
            windows[k, lo - i0 : hi - i0] = x[lo:hi]
    # each window's own mean: an offset goes, a_k·h keeps its shape in every window
    windows[:, :n] -= windows[:, :n].mean(axis=1, keepdims=True)
    freqs = np.fft.rfftfreq(n_pad)
    spectra = np.fft.rfft(windows, axis=1) * np.exp(2j * np.pi * np.outer(pos - first, freqs))
    # the envelope's flat top leaves the peak times samples apart at low SNR: align the
    # echoes' energy centroids, then each echo on its cross-correlation with the first
    # (the carrier's phase) within ±0.2 of its mean period
    power = np.abs(spectra) ** 2
    carrier = float(np.sum(power[0] * freqs) / np.sum(power[0]))  # cycles per sample
    energy = np.fft.irfft(spectra, n_pad, axis=1) ** 2
    centroid = energy @ np.arange(n_pad) / energy.sum(axis=1)
    spectra[1:] *= np.exp(2j * np.pi * np.outer(centroid[1:] - centroid[0], freqs))
    up = 16
    lags = np.fft.fftfreq(n_pad * up, 1.0 / n_pad)  # in samples
    near = np.flatnonzero(np.abs(lags) <= 0.2 / carrier)
    near = near[np.argsort(lags[near])]
    xc = np.abs(np.fft.irfft(spectra[1:] * spectra[0].conj(), n_pad * up, axis=1)[:, near])
    best = np.argmax(xc, axis=1)
    inner = np.clip(best, 1, near.size - 2)
    a, b, c = (xc[np.arange(best.size), inner + j] for j in (-1, 0, 1))
    den = a - 2 * b + c
    frac = np.where(den < 0, 0.5 * (a - c) / np.where(den < 0, den, 1.0), 0.0)
    lag = lags[near][inner] + np.clip(frac, -0.5, 0.5) / up
    spectra[1:] *= np.exp(2j * np.pi * np.outer(lag, freqs))
    aligned = np.fft.irfft(spectra, n_pad, axis=1)
    u_mat, s, vt = np.linalg.svd(aligned[:fit].T, full_matrices=False)
    wave = u_mat[:, 0]  # unit energy
    coef = np.abs(aligned @ wave)
    coef[:fit] = s[0] * np.abs(vt[0])
    gain = float(envelope(wave, pad=True).max())
    return coef * gain, gain


def _refined_peak(env: NDArray, k: int) -> tuple[float, float]:
    """Sub-sample index and value of the envelope peak at sample ``k`` (parabola)."""
    if 0 < k < env.size - 1:
        a, b, c = env[k - 1], env[k], env[k + 1]
        den = a - 2 * b + c
        delta = float(np.clip(0.5 * (a - c) / den, -0.5, 0.5)) if den < 0 else 0.0
        return k + delta, float(b - 0.25 * (a - c) * delta)
    return float(k), float(env[k])


@dataclass(frozen=True)
class ReflectionEstimate:
    """Result of :func:`estimate_reflection_coefficient`.

    Attributes
    ----------
    coefficient : float
        Rp.
    method : str
        ``"echo_train"``, ``"echo_train_attenuating"`` or ``"fallback"``.
    period : float
        Spacing of the first two echo peaks in s: the front face to the first back-wall
        echo (``nan`` with fewer than 2 peaks).
    peak_times : ndarray, shape (m,)
        The envelope peaks found (s).
    peak_amplitudes : ndarray, shape (m,)
        The echoes' amplitudes (:func:`echo_amplitudes`: the fitted common waveform's
        envelope peak times each echo's amplitude; the envelope peaks with one echo).
    warnings : tuple of str
        What did not go as expected.
    amplitude_noise_gain : float
        σ of each amplitude per unit noise σ of the trace (:func:`echo_amplitudes`;
        ``nan`` with one echo).
    """

    coefficient: float
    method: str
    period: float
    peak_times: NDArray[np.float64]
    peak_amplitudes: NDArray[np.float64]
    warnings: tuple[str, ...] = ()
    amplitude_noise_gain: float = float("nan")


def estimate_reflection_coefficient(signal: ArrayLike, sampling_rate: float, *,
                                    start_time: float = 0.0, search_from: float | None = None,
                                    fraction: float = 0.2, count: int = 5,
                                    min_snr: float = 4.0, attenuating: bool = False,
                                    fallback: float | None = None) -> ReflectionEstimate:
    """Rp and the echo-train period from a (tilt-aligned, averaged) echo trace.

    :func:`echo_train_peaks` finds the echoes, :func:`echo_amplitudes` measures them
    (a common waveform fitted to the echoes, not the envelope maxima, which noise biases
    high), then :func:`reflection_coefficient_from_peaks`.

    Parameters
    ----------
    signal, sampling_rate, start_time, search_from, fraction, count, min_snr :
        See :func:`echo_train_peaks`.
    attenuating : bool
        See :func:`reflection_coefficient_from_peaks`.
    fallback : float, optional
        When the echo train does not support an estimate (too few peaks, second echo
        larger than the first), warn and return this value instead of raising.

    Returns
    -------
    ReflectionEstimate

    Raises
    ------
    InputError
        When no estimate is possible and no fallback is given.
    """
    times, amps = echo_train_peaks(signal, sampling_rate, start_time=start_time,
                                   search_from=search_from, fraction=fraction, count=count,
                                   min_snr=min_snr)
    period = float(times[1] - times[0]) if times.size >= 2 else float("nan")
    notes: list[str] = []
    need = 3 if attenuating else 2
    amps, gain = fitted_amplitudes(signal, sampling_rate, times, amps,
                                   start_time=start_time, fit=need)
    try:
        if times.size < need:
            raise FitError(
                f"found {times.size} echo(es): the envelope never falls below {fraction:g} of "
                f"the peak after echo {times.size} (at {times[-1]:.6g} s); expected at least "
                f"{need} separate echoes of the plate (lower `fraction`, or give the "
                f"reflection coefficient explicitly)", field="signal")
        if times.size < int(count):
            notes.append(f"found {times.size} of {count} echoes of the train")
        rp = reflection_coefficient_from_peaks(amps, attenuating=attenuating)
        method = "echo_train_attenuating" if attenuating else "echo_train"
    except (InputError, FitError) as err:
        if fallback is None:
            raise
        notes.append(f"reflection coefficient from the echo train failed ({err.detail}); "
                     f"using {fallback:g}")
        rp, method = float(fallback), "fallback"
    for note in notes:
        warnings.warn(note, UserWarning, stacklevel=2)
    return ReflectionEstimate(coefficient=float(rp), method=method, period=period,
                              peak_times=times, peak_amplitudes=amps, warnings=tuple(notes),
                              amplitude_noise_gain=gain)


def fitted_amplitudes(
    signal: ArrayLike,
    sampling_rate: float,
    times: NDArray,
    peaks: NDArray,
    *,
    start_time: float,
    fit: int,
) -> tuple[NDArray[np.float64], float]:
    """:func:`echo_amplitudes` of the echoes at ``times`` (the first ``min(fit, m)``
    fitted together) when there are at least two; else the envelope ``peaks`` and a
    ``nan`` noise gain."""
    if times.size < 2:
        return peaks, float("nan")
    return echo_amplitudes(
        signal, sampling_rate, times, start_time=start_time, fit=min(fit, times.size)
    )
