"""Deconvolution: Wiener deconvolution with noise on both signals, transmit impulse response.

Paper eq. deconvolution-receive, with the regulariser as the published code implements
it (the printed equation has ``1 + SNR_Y + SNR_P``; the correct form, used here, is
``1 + 1/SNR_Y + 1/SNR_P``)::

    H(f) = Y(f) / P(f) / (1 + 1/SNR_Y(f) + 1/SNR_P(f)),   SNR_X = |X|² / |N_X|².
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.measurement import DriveSignal
from holoprobe.signal._fourier import (
    continuous_spectrum,
    frequency_axis,
    next_fast_length,
    to_frequency,
    to_time,
)
from holoprobe.signal._resample import _positive, _real_signal, fractional_delay, resample

__all__ = [
    "TransmitImpulseResponse",
    "drive_is_delta_like",
    "noise_floor",
    "transmit_impulse_response",
    "wiener_deconvolve",
]


def _noise_power(noise: ArrayLike, nbins: int, field: str) -> NDArray:
    arr = np.asarray(noise, dtype=float)
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise InputError("expected non-negative finite noise powers", field=field)
    if arr.ndim > 0 and arr.shape[-1] not in (1, nbins):
        raise InputError(f"expected a scalar or {nbins} values (one per frequency bin), got "
                         f"shape {arr.shape}", field=field)
    return arr


def wiener_deconvolve(output: ArrayLike, input: ArrayLike, *, noise_output: ArrayLike,
                      noise_input: ArrayLike, sampling_rate: float,
                      n_fft: int | None = None,
                      snr: Literal["measured", "excess"] = "measured") -> NDArray:
    """Impulse response h with ``output = h ∗ input``, by Wiener deconvolution with noise on
    both signals (paper eq. deconvolution-receive, corrected regulariser).

    ``H = Y/P / (1 + 1/SNR_Y + 1/SNR_P)`` with ``SNR_X = S_X / |N_X|²``, evaluated as
    ``Y P* S_Y S_P / (|P|² (S_Y S_P + |N_Y|² S_P + |N_P|² S_Y))`` (zero where that is 0/0).
    ``snr="measured"`` (the paper's definition): ``S_X = |X|²`` of the noisy spectrum —
    at bins that hold only noise SNR ≈ 1, so they are only halved. ``snr="excess"``:
    ``S_X = max(|X|² − |N_X|², 0)``, the signal power above the noise, so bins at or below
    the noise floor are set to zero (better where the input spectrum has deep notches,
    e.g. a burst drive).

    Parameters
    ----------
    output : array_like, shape (..., n)
        Output signal y (time last), e.g. received voltage.
    input : array_like, shape (..., m)
        Input signal p (time last, broadcasts against ``output``), e.g. pressure. Both
        start at the same instant, which is the time origin of h.
    noise_output, noise_input : float or array_like, shape (n_fft // 2 + 1,)
        Noise power ``|N|²`` per frequency bin, in the scaling of
        ``|to_frequency(x, n=n_fft)|²`` (for white noise of variance σ²: ``n_fft · σ²``);
        a scalar is a flat spectral floor. See :func:`noise_floor`.
    sampling_rate : float
        Common sampling rate in Hz.
    n_fft : int, optional
        FFT length; default ``max(n, m)`` (circular deconvolution over that length).
    snr : {"measured", "excess"}
        How the signal power in the SNRs is estimated (see above).

    Returns
    -------
    ndarray, shape (..., n_fft)
        h in units of output / (input · s), sampled at ``sampling_rate``.
    """
    y = _real_signal(output, "output").astype(float, copy=False)
    p = _real_signal(input, "input").astype(float, copy=False)
    fs = _positive(sampling_rate, "sampling_rate")
    n = max(y.shape[-1], p.shape[-1]) if n_fft is None else int(n_fft)
    if n < max(y.shape[-1], p.shape[-1]):
        raise InputError("expected n_fft ≥ the lengths of both signals", field="n_fft")
    nb = n // 2 + 1
    ny = _noise_power(noise_output, nb, "noise_output")
    npow = _noise_power(noise_input, nb, "noise_input")
    Y = to_frequency(y, n=n)
    P = to_frequency(p, n=n)
    try:
        np.broadcast_shapes(Y.shape, P.shape)
    except ValueError:
        raise InputError(f"shapes {y.shape} and {p.shape} do not broadcast", field="input") \
            from None
    if snr not in ("measured", "excess"):
        raise InputError(f"expected 'measured' or 'excess', got {snr!r}", field="snr")
    p2 = np.abs(P) ** 2
    sy = np.abs(Y) ** 2
    sp = p2.copy()
    if snr == "excess":
        sy = np.maximum(sy - ny, 0.0)
        sp = np.maximum(sp - npow, 0.0)
    den = p2 * (sy * sp + ny * sp + npow * sy)
    num = Y * np.conj(P) * sy * sp
    H = np.divide(num, den, out=np.zeros(np.broadcast_shapes(num.shape, den.shape), complex),
                  where=den > 0)
    return to_time(H, n) * fs


def noise_floor(signal: ArrayLike, window: tuple[float, float], *, sampling_rate: float,
                n: int | None = None, segment_length: int = 256) -> NDArray:
    """Noise power per frequency bin, estimated from a signal-free part of a record.

    The power spectral density of the samples in ``window`` (Welch's method, Hann
    segments of ``segment_length`` samples, mean removed) scaled to the bins of a
    length-``n`` record: ``E|N(f_k)|² = n · fs · S(f_k)`` with S the two-sided density.
    For white noise of variance σ² this is ``n σ²`` in every bin.

    Parameters
    ----------
    signal : array_like, shape (N,)
        The record (e.g. a receive trace with its pre-echo part).
    window : (float, float)
        Signal-free interval (start, stop) in s relative to the first sample.
    sampling_rate : float
        Sampling rate in Hz.
    n : int, optional
        Record length whose bins the result describes; default ``N``.
    segment_length : int
        Welch segment length (shortened to the window when that is shorter).

    Returns
    -------
    ndarray, shape (n // 2 + 1,)
        Noise power per bin, in the scaling of ``|to_frequency(x, n=n)|²``; pass to
        :func:`wiener_deconvolve`.
    """
    import scipy.signal

    x = _real_signal(signal).astype(float, copy=False)
    if x.ndim != 1:
        raise InputError(f"expected a 1-D record, got shape {x.shape}", field="signal")
    fs = _positive(sampling_rate, "sampling_rate")
    try:
        start, stop = (float(v) for v in window)
    except (TypeError, ValueError):
        raise InputError("expected (start, stop) in s", field="window") from None
    i0 = max(0, int(np.ceil(start * fs - 1e-9)))
    i1 = min(x.size, int(np.floor(stop * fs + 1e-9)) + 1)
    seg = x[i0:i1]
    if seg.size < 8:
        raise InputError(f"the window ({start:g}, {stop:g}) s holds {seg.size} samples; "
                         f"expected at least 8", field="window")
    nper = int(min(seg.size, segment_length))
    f_w, psd = scipy.signal.welch(seg, fs=fs, nperseg=nper, return_onesided=True,
                                  scaling="density", detrend="constant")
    # one-sided → two-sided density (the DC and Nyquist bins are not doubled by welch)
    two = psd / 2.0
    two[0] = psd[0]
    if nper % 2 == 0:
        two[-1] = psd[-1]
    n = x.size if n is None else int(n)
    f = frequency_axis(n, fs)
    return n * fs * np.interp(f, f_w, two)


def _regrid_noise(noise: ArrayLike, n: int, fs: float, f_new: NDArray, field: str) -> NDArray:
    arr = np.asarray(noise, dtype=float)
    if arr.ndim == 0 or arr.size == 1:
        return _noise_power(arr.reshape(()), 1, field)
    if arr.ndim != 1 or arr.size != n // 2 + 1:
        raise InputError(f"expected a scalar or {n // 2 + 1} values (one per bin of the "
                         f"{n}-sample record), got shape {arr.shape}", field=field)
    arr = _noise_power(arr, arr.size, field)
    return np.interp(f_new, frequency_axis(n, fs), arr)


@dataclass(frozen=True)
class TransmitImpulseResponse:
    """Result of :func:`transmit_impulse_response`.

    Attributes
    ----------
    ir : ndarray, shape (n,)
        Transmit impulse response in Pa/(V·s) (of ρ0c0·u; divide by ρ0c0 for (m/s)/(V·s)),
        first sample at t = 0.
    sampling_rate : float
        Its sampling rate in Hz.
    method : {"area", "wiener"}
        The method used.
    drive_area : float
        Time integral of the drive voltage in V·s.
    """

    ir: NDArray[np.float64]
    sampling_rate: float
    method: str
    drive_area: float


def drive_is_delta_like(drive: DriveSignal, response: ArrayLike, response_rate: float, *,
                        band_db: float = -40.0, delta_tolerance: float = 0.05) -> bool:
    """Whether the drive acts as a delta pulse over the response's band (paper eq.
    deconvolution-transmit holds).

    True when the drive's area A is non-zero and ``| |E(f)| / |A| − 1 | ≤ delta_tolerance``
    at every frequency where the response spectrum is within ``band_db`` (amplitude dB)
    of its maximum. E(f) is the drive's continuous-time spectrum; its linear phase (the
    drive's delay) is not part of the test.

    Parameters
    ----------
    drive : DriveSignal
        Drive voltage.
    response : array_like, shape (n,)
        The response (e.g. ρ0c0 × mean surface velocity).
    response_rate : float
        Sampling rate of the response in Hz.
    band_db : float
        Level (dB re the peak amplitude, negative) that delimits the response's band.
    delta_tolerance : float
        Largest accepted relative deviation of |E(f)| from |A| in that band.
    """
    u = _real_signal(response, "response").astype(float, copy=False)
    fs = _positive(response_rate, "response_rate")
    area = drive.area
    if area == 0.0:
        return False
    U = np.abs(to_frequency(u))
    f = frequency_axis(u.size, fs)
    band = U >= U.max() * 10 ** (band_db / 20)
    E = continuous_spectrum(drive.voltage, drive.sampling_rate, f[band])
    return bool(np.max(np.abs(np.abs(E) / abs(area) - 1.0)) <= delta_tolerance)


def transmit_impulse_response(velocity_times_rho_c: ArrayLike, response_rate: float,
                              drive: DriveSignal, *,
                              method: Literal["auto", "area", "wiener"] = "auto",
                              output_rate: float = 250e6,
                              noise_response: ArrayLike | None = None,
                              noise_drive: ArrayLike | None = None,
                              response_floor_db: float = 60.0, drive_floor_db: float = 60.0,
                              band_db: float = -40.0, delta_tolerance: float = 0.05,
                              align_drive_centroid: bool = True,
                              active_fraction: float = 1.0,
                              snr: Literal["measured", "excess"] = "measured"
                              ) -> TransmitImpulseResponse:
    """Transmit impulse response from the mean surface response and the drive voltage.

    Paper eq. transmit-impulse-response ``u = h_T ∗ E`` solved for h_T:

    * ``"area"`` (paper eq. deconvolution-transmit): for a delta-like drive,
      ``h_T = u / ∫E dt``; with ``align_drive_centroid`` the result is also advanced by
      the drive's centroid time ``∫t E dt / ∫E dt`` (the first-order delay that the
      exact deconvolution removes; the published code does not).
    * ``"wiener"``: the drive, resampled to the response rate, is Wiener-deconvolved
      (:func:`wiener_deconvolve`).
    * ``"auto"``: ``"area"`` when :func:`drive_is_delta_like`, else ``"wiener"``.

    The result is resampled (band-limited) to ``output_rate``.

    Parameters
    ----------
    velocity_times_rho_c : array_like, shape (n,)
        ρ0c0 × mean normal surface velocity in Pa; first sample at the drive's first
        sample (t = 0).
    response_rate : float
        Its sampling rate in Hz.
    drive : DriveSignal
        The drive voltage (any sampling rate).
    method : {"auto", "area", "wiener"}
        See above.
    output_rate : float
        Sampling rate of the returned IR in Hz.
    noise_response, noise_drive : float or array_like, optional
        Noise powers per bin for the Wiener method (see :func:`wiener_deconvolve`): a
        scalar, or one value per bin of the unpadded record (``n // 2 + 1`` values for the
        response, e.g. from :func:`noise_floor`; the drive's bins are those of the drive
        resampled to ``response_rate``). Zero-padding adds no noise, so they are only
        interpolated onto the padded FFT grid. Default: a flat floor
        ``response_floor_db`` / ``drive_floor_db`` (amplitude dB) below the spectral peak.
    response_floor_db, drive_floor_db : float
        Default noise floors (dB below the peak amplitude), see above.
    band_db, delta_tolerance : float
        Delta-likeness test, see :func:`drive_is_delta_like`.
    align_drive_centroid : bool
        Area method: advance by the drive's centroid time (see above).
    active_fraction : float
        Fraction of the averaging area that radiates (e.g. ``N w / ((N−1) p + w)`` for an
        array with kerf); the IR is divided by it.
    snr : {"measured", "excess"}
        SNR estimate of the Wiener method, see :func:`wiener_deconvolve`.

    Returns
    -------
    TransmitImpulseResponse
        IR in Pa/(V·s) at ``output_rate``, the method used and the drive area.
    """
    u = _real_signal(velocity_times_rho_c, "velocity_times_rho_c").astype(float, copy=False)
    if u.ndim != 1:
        raise InputError(f"expected a 1-D signal, got shape {u.shape}",
                         field="velocity_times_rho_c")
    fs = _positive(response_rate, "response_rate")
    fo = _positive(output_rate, "output_rate")
    frac = _positive(active_fraction, "active_fraction")
    if not isinstance(drive, DriveSignal):
        raise InputError("expected a holoprobe.measurement.DriveSignal", field="drive")
    if method == "auto":
        method = ("area" if drive_is_delta_like(drive, u, fs, band_db=band_db,
                                                delta_tolerance=delta_tolerance)
                  else "wiener")
    area = drive.area
    n = u.size
    if method == "area":
        if area == 0.0:
            raise InputError("the drive has zero area; use method='wiener'", field="drive")
        h = u / area
        if align_drive_centroid:
            t = np.arange(drive.voltage.size) / drive.sampling_rate
            centroid = float(np.sum(t * drive.voltage) / np.sum(drive.voltage))
            h = fractional_delay(h, -centroid, fs, pad=True)
    elif method == "wiener":
        ratio = drive.sampling_rate / fs
        pad = math.ceil(8 * ratio)
        v = np.concatenate([drive.voltage, np.zeros(pad)])
        d = resample(v, drive.sampling_rate, fs)
        nfft = next_fast_length(n + d.size)
        f_pad = frequency_axis(nfft, fs)
        if noise_response is None:
            U = np.abs(to_frequency(u, n=nfft))
            noise_response = (U.max() * 10 ** (-response_floor_db / 20)) ** 2
        else:
            noise_response = _regrid_noise(noise_response, n, fs, f_pad, "noise_response")
        if noise_drive is None:
            D = np.abs(to_frequency(d, n=nfft))
            noise_drive = (D.max() * 10 ** (-drive_floor_db / 20)) ** 2
        else:
            noise_drive = _regrid_noise(noise_drive, d.size, fs, f_pad, "noise_drive")
        h = wiener_deconvolve(u, d, noise_output=noise_response, noise_input=noise_drive,
                              sampling_rate=fs, n_fft=nfft, snr=snr)[:n]
    else:
        raise InputError(f"expected 'auto', 'area' or 'wiener', got {method!r}",
                         field="method")
    h = h / frac
    out = resample(h, fs, fo)
    return TransmitImpulseResponse(ir=out, sampling_rate=fo, method=method,
                                   drive_area=area)
