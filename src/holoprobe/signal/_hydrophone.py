"""Deconvolution of a hydrophone waveform with a complex calibration, with GUM uncertainty.

IEC 62127-1 (Annex on hydrophone deconvolution) and Eichstädt & Wilkens (2016): the
pressure is ``p = F⁻¹{ L(f) · U(f) / M(f) }`` with ``U`` the DFT of the offset-free
voltage, ``M`` the complex sensitivity (V/Pa) and ``L`` a regularising low-pass filter.
The uncertainty of the voltage (white noise, measured in the quiet part of the record,
plus the uncertainty of the removed DC offset) and of the calibration (magnitude and phase
standard uncertainties) is propagated with PyDynamic (``AmpPhase2DFT``, ``DFT_deconv``,
``DFT_multiply``; the white-noise DFT covariance of ``GUM_DFT`` in closed form,
:func:`voltage_dft`), frequency bin by frequency bin.

Convention: PyDynamic works with numpy's forward FFT (``exp(−i2πft)``), like calibration
certificates; holoprobe's spectra are the conjugates (``docs/conventions.md``). The FFT
phase is taken from :attr:`HydrophoneCalibration.phase_fft` (the one conversion); the
pressure comes back through :func:`holoprobe.signal.to_time` of the conjugated result.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.measurement import HydrophoneCalibration
from holoprobe.signal._calibration import sensitivity_response
from holoprobe.signal._fourier import frequency_axis, to_frequency, to_time
from holoprobe.signal._phase import minimum_phase
from holoprobe.signal._robust import mad_sigma

__all__ = [
    "DeconvolvedPressure",
    "HydrophoneDeconvolutionConfig",
    "auto_cutoff",
    "deconvolve_hydrophone",
    "deconvolve_records",
    "estimate_offset_and_noise",
    "lowpass_response",
    "regularised_inverse",
    "voltage_dft",
    "with_phase",
]


@dataclass(frozen=True)
class HydrophoneDeconvolutionConfig:
    """Knobs of :func:`deconvolve_hydrophone` (TOML section ``[hydrophone]``).

    Attributes
    ----------
    cutoff_hz : float or None
        −3 dB frequency of the regularising low-pass filter in Hz. None: chosen from
        the data (where the smoothed voltage power spectrum falls to ``snr_cutoff_db``
        above the noise power), at most the highest calibrated frequency and 0.8 × the
        Nyquist frequency.
    filter_order : int
        Order n of the low-pass ``|L(f)| = 1 / sqrt(1 + (f/f_c)^(2n))`` (a Butterworth
        magnitude, applied with zero phase so the pulse is not shifted).
    snr_cutoff_db : float
        Signal-to-noise power ratio (dB) at the automatic cut-off.
    smooth_bins : int
        Moving-average length (bins) of the power spectrum for the automatic cut-off
        (9 bins: smoothed white noise exceeds 4× its mean with probability ~1e-9).
    outside : {"hold", "extrapolate"}
        The calibration outside its frequency range: held at the edge values, or the
        PCHIP curve extrapolated (:func:`holoprobe.signal.sensitivity_response`).
    amplitude_only_phase : {"minimum", "zero"}
        Phase used for a calibration without one: Bode minimum phase or none.
    minimum_phase_extrapolation : {"constant", "slope"}
        How ``ln|M|`` continues beyond the calibrated band for the minimum phase
        (:func:`holoprobe.signal.minimum_phase`): the log-log slope of the edge points
        (default; a resonant hydrophone rolls off as f⁻² above its resonance) or held.
    remove_offset : bool
        Subtract the DC offset (mean of the quiet part of the record).
    quiet_threshold : float
        Samples further than this many robust standard deviations from the median mark
        the pulse; the pulse region is widened by its own length on each side and the
        rest of the record is "quiet" (offset and noise).
    block_bins : int
        Frequency bins per PyDynamic call (bounds memory: PyDynamic returns dense
        covariance blocks).
    """

    cutoff_hz: float | None = None
    filter_order: int = 8
    snr_cutoff_db: float = 6.0
    smooth_bins: int = 9
    outside: Literal["hold", "extrapolate"] = "hold"
    amplitude_only_phase: Literal["minimum", "zero"] = "minimum"
    minimum_phase_extrapolation: Literal["constant", "slope"] = "slope"
    remove_offset: bool = True
    quiet_threshold: float = 5.0
    block_bins: int = 32

    def __post_init__(self) -> None:
        if self.cutoff_hz is not None and not (math.isfinite(self.cutoff_hz)
                                               and self.cutoff_hz > 0):
            raise InputError(f"expected a positive frequency in Hz, got {self.cutoff_hz!r}",
                             field="cutoff_hz")
        if int(self.filter_order) < 1:
            raise InputError(f"expected an order ≥ 1, got {self.filter_order!r}",
                             field="filter_order")
        if self.outside not in ("hold", "extrapolate"):
            raise InputError(f"expected 'hold' or 'extrapolate', got {self.outside!r}",
                             field="outside")
        if self.amplitude_only_phase not in ("minimum", "zero"):
            raise InputError(f"expected 'minimum' or 'zero', got "
                             f"{self.amplitude_only_phase!r}", field="amplitude_only_phase")
        if not self.quiet_threshold > 0 or int(self.block_bins) < 2:
            raise InputError("expected quiet_threshold > 0 and block_bins ≥ 2",
                             field="quiet_threshold")


@dataclass(frozen=True)
class DeconvolvedPressure:
    """A deconvolved hydrophone pulse with its uncertainty (standard, k = 1).

    Attributes
    ----------
    time : ndarray, shape (n,)
        Sample times in s.
    pressure : ndarray, shape (n,)
        Pressure in Pa.
    u_pressure : ndarray, shape (n,)
        Standard uncertainty of each sample (noise, offset and calibration), Pa.
    u_pressure_noise : ndarray, shape (n,)
        The part from the voltage noise and offset alone, Pa (its square is the bias
        that noise adds to ``p²``).
    voltage : ndarray, shape (n,)
        The offset-free voltage in V.
    sampling_rate : float
        Hz.
    offset : float
        The removed DC offset in V (0 when not removed).
    noise_sigma : float
        Standard deviation of the voltage noise in V.
    cutoff_hz : float
        −3 dB frequency of the regularising low-pass filter, Hz.
    calibration : HydrophoneCalibration
        The calibration used (with the minimum phase when one was added).
    config : HydrophoneDeconvolutionConfig
        The settings.
    """

    time: NDArray[np.float64]
    pressure: NDArray[np.float64]
    u_pressure: NDArray[np.float64]
    u_pressure_noise: NDArray[np.float64]
    voltage: NDArray[np.float64]
    sampling_rate: float
    offset: float
    noise_sigma: float
    u_offset: float
    cutoff_hz: float
    calibration: HydrophoneCalibration
    config: HydrophoneDeconvolutionConfig

    def draws(self, n_draws: int, *, seed: int | None = 0) -> NDArray[np.float64]:
        """Monte Carlo pressures (GUM Supplement 1) for derived quantities.

        Each draw adds white noise (``noise_sigma``) and an offset error (``u_offset``)
        to the voltage, draws the calibration magnitude and phase at the calibration's
        own frequencies (independent between calibration points, then interpolated like
        the calibration, so neighbouring DFT bins share their error) and deconvolves
        with the same filter, in holoprobe's Fourier convention (an independent path
        from the PyDynamic one).

        Returns
        -------
        ndarray, shape (n_draws, n)
            Pressures in Pa.
        """
        rng = np.random.default_rng(seed)
        n = self.voltage.size
        cal = self.calibration
        noisy = (self.voltage + self.noise_sigma * rng.standard_normal((n_draws, n))
                 + self.u_offset * rng.standard_normal((n_draws, 1)))
        spec = to_frequency(noisy, axis=-1)
        f = frequency_axis(n, self.sampling_rate)
        for i in range(n_draws):
            mag, phase = cal.sensitivity, cal.phase
            if cal.u_sensitivity is not None:
                mag = np.maximum(mag + cal.u_sensitivity * rng.standard_normal(mag.size),
                                 1e-3 * mag)
            if phase is not None and cal.u_phase is not None:
                phase = phase + cal.u_phase * rng.standard_normal(phase.size)
            drawn = replace(cal, sensitivity=mag, phase=phase)
            spec[i] *= regularised_inverse(drawn, f, self.cutoff_hz, self.config)
        return to_time(spec, n, axis=-1)


# --------------------------------------------------------------------------- pieces
def estimate_offset_and_noise(voltage: ArrayLike, *, threshold: float = 5.0
                              ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """DC offset and noise of pulse records from their quiet parts.

    Samples further than ``threshold`` robust standard deviations (1.4826 × MAD) from
    the median mark the pulse; the region from the first to the last such sample is
    widened by its own length on each side, the rest is quiet. With fewer than 32 quiet
    samples the whole record is used (an acoustic pulse has zero mean; the noise is then
    over-estimated).

    Parameters
    ----------
    voltage : array_like, shape (..., n)
        Records in V, time last.
    threshold : float
        Pulse threshold in robust standard deviations.

    Returns
    -------
    offset, sigma, u_offset, n_quiet : ndarray, shape (...)
        Mean and standard deviation of the quiet samples (V), the offset's standard
        uncertainty ``sigma / sqrt(n_quiet)`` (V), and the number of quiet samples.
    """
    x = np.asarray(voltage, float)
    n = x.shape[-1]
    flat = x.reshape(-1, n)
    r = flat - np.median(flat, axis=-1, keepdims=True)
    scale = np.asarray(mad_sigma(flat, axis=-1))[:, None]
    loud = (np.abs(r) > threshold * scale) & (scale > 0)
    idx = np.arange(n)
    has = loud.any(axis=-1)
    first = np.where(has, np.argmax(loud, axis=-1), 0)
    last = np.where(has, n - 1 - np.argmax(loud[:, ::-1], axis=-1), -1)
    width = last - first + 1
    quiet = (idx < (first - width)[:, None]) | (idx > (last + width)[:, None])
    quiet[~has] = True
    n_quiet = quiet.sum(axis=-1)
    quiet[n_quiet < 32] = True
    n_quiet = quiet.sum(axis=-1)
    offset = np.sum(flat * quiet, axis=-1) / n_quiet
    sigma = np.sqrt(np.sum(((flat - offset[:, None]) * quiet) ** 2, axis=-1) / (n_quiet - 1))
    shape = x.shape[:-1]
    return (offset.reshape(shape), sigma.reshape(shape),
            (sigma / np.sqrt(n_quiet)).reshape(shape), n_quiet.reshape(shape))


def lowpass_response(frequency: ArrayLike, cutoff_hz: float, order: int) -> NDArray:
    """Zero-phase regularising low-pass ``1 / sqrt(1 + (f/f_c)^(2n))`` (−3 dB at f_c)."""
    f = np.asarray(frequency, float)
    return 1.0 / np.sqrt(1.0 + (f / cutoff_hz) ** (2 * int(order)))


def regularised_inverse(calibration: HydrophoneCalibration, frequency: ArrayLike,
                        cutoff_hz: float, config: HydrophoneDeconvolutionConfig
                        ) -> NDArray[np.complex128]:
    """``L(f) · polarity / M(f)`` in holoprobe's convention (Pa/V): the deconvolution
    filter that :func:`deconvolve_hydrophone` (and ``characterize`` with a complex
    calibration) applies to ``to_frequency(voltage)``."""
    inv = sensitivity_response(calibration, frequency, inverse=True, below=config.outside,
                               above=config.outside)
    return inv * lowpass_response(frequency, cutoff_hz, config.filter_order)


def with_phase(calibration: HydrophoneCalibration, config: HydrophoneDeconvolutionConfig
               ) -> HydrophoneCalibration:
    """The calibration with the Bode minimum phase when it has none (and the config asks)."""
    if calibration.phase is not None or config.amplitude_only_phase == "zero":
        return calibration
    phase = minimum_phase(calibration.frequency, calibration.sensitivity,
                          convention="holoprobe", extrapolation=config.minimum_phase_extrapolation)
    return replace(calibration, phase=phase)


def auto_cutoff(voltage: NDArray, sampling_rate: float, noise_sigma: float,
                calibration: HydrophoneCalibration,
                config: HydrophoneDeconvolutionConfig) -> float:
    """Cut-off from the data and the calibration's range.

    The highest frequency at which the voltage power spectrum (moving average over
    ``smooth_bins``) is still ``snr_cutoff_db`` above the white-noise power ``n σ²`` per
    bin (the last crossing, so that a notch between harmonics does not stop it), at most
    the highest calibrated frequency and 0.8 × Nyquist. Without noise: those limits.
    """
    n = voltage.size
    f = frequency_axis(n, sampling_rate)
    power = np.abs(to_frequency(voltage)) ** 2
    k = max(1, int(config.smooth_bins))
    smooth = np.convolve(power, np.ones(k) / k, mode="same")
    limit = min(float(calibration.frequency[-1]), 0.8 * 0.5 * sampling_rate)
    level = n * noise_sigma**2 * 10 ** (config.snr_cutoff_db / 10)
    above = np.flatnonzero(smooth[1:] > level)
    f_noise = float(f[1 + above[-1]]) if above.size else limit
    return min(f_noise, limit)


def _bin_uncertainties(calibration: HydrophoneCalibration, f: NDArray
                       ) -> tuple[NDArray, NDArray]:
    fc = calibration.frequency
    zeros = np.zeros_like(f)
    u_mag = zeros if calibration.u_sensitivity is None else np.interp(f, fc,
                                                                      calibration.u_sensitivity)
    u_ph = zeros if calibration.u_phase is None else np.interp(f, fc, calibration.u_phase)
    return u_mag, u_ph


def _time_variance(rr: NDArray, ri: NDArray, ii: NDArray, n: int) -> NDArray[np.float64]:
    """Diagonal of the covariance of ``irfft(R + iI, n)`` for independent bins with
    per-bin covariances (rr, ri, ii) of (Re, Im): the diagonal of PyDynamic's
    ``GUM_iDFT`` in O(n log n) (``cos² = (1 + cos 2β)/2`` etc. turn the sum into one
    inverse DFT at doubled frequency)."""
    m = rr.size
    w2 = np.full(m, 4.0)
    w2[0] = 1.0
    if n % 2 == 0:
        w2[-1] = 1.0
    const = np.sum(w2 * (rr + ii)) / 2.0
    c = np.zeros(n, complex)
    np.add.at(c, (2 * np.arange(m)) % n, w2 * ((rr - ii) / 2.0 + 1j * ri))
    osc = np.real(scipy.fft.ifft(c) * n)
    return np.maximum(const + osc, 0.0) / n**2


def voltage_dft(x: NDArray, sigma2: float) -> tuple[NDArray, NDArray]:
    """DFT of a record with white noise of variance ``sigma2``, in PyDynamic's layout.

    Returns ``[Re, Im]`` of numpy's ``rfft(x)`` (FFT convention; computed as the conjugate
    of :func:`holoprobe.signal.to_frequency`) and the variances of those parts: for white
    noise the DFT bins are uncorrelated with ``Var Re = Var Im = σ² n/2``, except the DC
    (and, for even n, Nyquist) bin, real with variance ``σ² n``. This is what
    ``PyDynamic.uncertainty.propagate_DFT.GUM_DFT(x, σ²)`` returns, in O(n log n)
    instead of its O(n²) loop (equal to it to rounding: ``tests/test_signal_hydrophone.py``).
    """
    n = x.size
    spec = np.conj(to_frequency(x))
    m = spec.size
    var_re = np.full(m, 0.5 * n * sigma2)
    var_im = np.full(m, 0.5 * n * sigma2)
    var_re[0], var_im[0] = n * sigma2, 0.0
    if n % 2 == 0:
        var_re[-1], var_im[-1] = n * sigma2, 0.0
    return np.r_[spec.real, spec.imag], np.r_[var_re, var_im]


def _pydynamic_deconvolution(x: NDArray, sigma2: float, u_offset: float, h_fft: NDArray,
                             u_mag: NDArray, u_phase: NDArray, lowpass: NDArray,
                             block: int) -> tuple[NDArray, NDArray, NDArray]:
    """PyDynamic chain per block of bins: returns the pressure spectrum (FFT convention)
    and the per-bin covariances (rr, ri, ii) with all contributions, and noise only."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # "archived since May 2024"
        from PyDynamic.uncertainty.propagate_DFT import AmpPhase2DFT, DFT_deconv, DFT_multiply
    n = x.size
    y, uy = voltage_dft(x, sigma2)
    m = y.size // 2
    uy[0] += (n * u_offset) ** 2  # the offset error is a constant: DC bin only
    out = np.zeros(2 * m)
    cov = np.zeros((2, 3, m))
    for s in range(0, m, block):
        e = min(m, s + block)
        b = e - s
        amp, ph = np.abs(h_fft[s:e]), np.angle(h_fft[s:e])
        h, uh = AmpPhase2DFT(amp, ph, np.r_[u_mag[s:e] ** 2, u_phase[s:e] ** 2],
                             keep_sparse=False)
        yb = np.r_[y[s:e], y[m + s:m + e]]
        uyb = np.r_[uy[s:e], uy[m + s:m + e]]
        lp = np.r_[lowpass[s:e], np.zeros(b)]
        for j, uh_j in enumerate((uh, np.zeros(2 * b))):
            xb, uxb = DFT_deconv(h, yb, uh_j, uyb)
            pb, upb = DFT_multiply(xb, lp, uxb)
            upb = np.asarray(upb)
            cov[j, 0, s:e] = np.diag(upb[:b, :b])
            cov[j, 1, s:e] = np.diag(upb[:b, b:])
            cov[j, 2, s:e] = np.diag(upb[b:, b:])
            if j == 0:
                out[s:e], out[m + s:m + e] = pb[:b], pb[b:]
    return out[:m] + 1j * out[m:], cov[0], cov[1]


# --------------------------------------------------------------------------- main
def deconvolve_hydrophone(voltage: ArrayLike, sampling_rate: float,
                          calibration: HydrophoneCalibration, *,
                          config: HydrophoneDeconvolutionConfig | None = None,
                          start_time: float = 0.0) -> DeconvolvedPressure:
    """Pressure and its GUM uncertainty from one hydrophone record (IEC 62127-1).

    Steps: DC offset and noise from the quiet part of the record
    (:func:`estimate_offset_and_noise`); the calibration completed with its minimum
    phase when it has none (option); the regularised inverse
    ``L(f) · polarity / M(f)`` (:func:`regularised_inverse`; calibration held or
    extrapolated outside its range; ``L`` zero-phase with its −3 dB point at
    ``config.cutoff_hz`` or :func:`auto_cutoff`); uncertainty propagated with PyDynamic
    bin by bin (white voltage noise, offset, calibration magnitude and phase; bins
    treated as uncorrelated, as in Eichstädt & Wilkens 2016) and back to the time domain
    (the diagonal of ``GUM_iDFT``). The deconvolution is circular over the record
    (the pulse should not touch the record's ends).

    Parameters
    ----------
    voltage : array_like, shape (n,)
        Hydrophone output in V, uniformly sampled.
    sampling_rate : float
        Hz.
    calibration : HydrophoneCalibration
        Complex (or magnitude-only) sensitivity, V/Pa.
    config : HydrophoneDeconvolutionConfig, optional
        Settings (defaults documented there).
    start_time : float
        Time of the first sample, s.

    Returns
    -------
    DeconvolvedPressure

    References
    ----------
    S. Eichstädt and V. Wilkens, "GUM2DFT — a software tool for uncertainty evaluation
    of transient signals in the frequency domain", Meas. Sci. Technol. 27, 055001
    (2016), doi:10.1088/0957-0233/27/5/055001. IEC 62127-1:2022, Annex D.
    """
    cfg = HydrophoneDeconvolutionConfig() if config is None else config
    v = np.asarray(voltage, dtype=float)
    if v.ndim != 1 or v.size < 16 or not np.all(np.isfinite(v)):
        raise InputError(f"expected a finite 1-D record of ≥ 16 samples, got shape {v.shape}",
                         field="voltage")
    fs = float(sampling_rate)
    if not (math.isfinite(fs) and fs > 0):
        raise InputError(f"expected a positive rate in Hz, got {sampling_rate!r}",
                         field="sampling_rate")
    offset, sigma, u_offset = (float(a) for a in estimate_offset_and_noise(
        v, threshold=cfg.quiet_threshold)[:3])
    if not cfg.remove_offset:
        offset, u_offset = 0.0, 0.0
    x = v - offset
    cal = with_phase(calibration, cfg)
    cutoff = cfg.cutoff_hz if cfg.cutoff_hz is not None else auto_cutoff(x, fs, sigma, cal,
                                                                          cfg)
    n = x.size
    f = frequency_axis(n, fs)
    # PyDynamic's convention is numpy's FFT: M_fft = conj(M_holoprobe) (one conversion)
    h_fft = np.conj(sensitivity_response(cal, f, inverse=False, below=cfg.outside,
                                         above=cfg.outside))
    u_mag, u_ph = _bin_uncertainties(cal, f)
    p_fft, cov_all, cov_noise = _pydynamic_deconvolution(
        x, sigma**2, u_offset, h_fft, u_mag, u_ph, lowpass_response(f, cutoff,
                                                                    cfg.filter_order),
        int(cfg.block_bins))
    pressure = to_time(np.conj(p_fft), n)
    return DeconvolvedPressure(
        time=start_time + np.arange(n) / fs, pressure=pressure,
        u_pressure=np.sqrt(_time_variance(cov_all[0], cov_all[1], cov_all[2], n)),
        u_pressure_noise=np.sqrt(_time_variance(cov_noise[0], cov_noise[1], cov_noise[2], n)),
        voltage=x, sampling_rate=fs, offset=offset, noise_sigma=sigma, u_offset=u_offset,
        cutoff_hz=float(cutoff), calibration=cal, config=cfg)


def deconvolve_records(voltage: ArrayLike, sampling_rate: float,
                       calibration: HydrophoneCalibration, *,
                       config: HydrophoneDeconvolutionConfig | None = None,
                       chunk_traces: int = 4096) -> tuple[NDArray, float]:
    """Many records (a scan) deconvolved the way :func:`deconvolve_hydrophone` does one,
    without the uncertainty: per-trace DC offset removed (option), the calibration
    completed with its minimum phase when it has none (option), and the same
    :func:`regularised_inverse`; the automatic cut-off comes from the strongest trace.

    Parameters
    ----------
    voltage : array_like, shape (..., nt)
        Hydrophone output in V, time last.
    sampling_rate : float
        Hz.
    calibration : HydrophoneCalibration
        Sensitivity.
    config : HydrophoneDeconvolutionConfig, optional
        Settings.
    chunk_traces : int
        Traces transformed at once.

    Returns
    -------
    pressure : ndarray, shape of ``voltage``
        Pa (float32 for float32 input).
    cutoff_hz : float
        The −3 dB frequency used.
    """
    cfg = HydrophoneDeconvolutionConfig() if config is None else config
    x = np.asarray(voltage)
    out_dtype = np.float32 if x.dtype == np.float32 else np.float64
    nt = x.shape[-1]
    flat = x.reshape(-1, nt)
    cal = with_phase(calibration, cfg)
    f = frequency_axis(nt, sampling_rate)
    out = np.empty(flat.shape, out_dtype)
    sigmas = np.empty(flat.shape[0])
    for s in range(0, flat.shape[0], max(1, int(chunk_traces))):
        block = flat[s:s + chunk_traces].astype(float)
        offset, sigmas[s:s + chunk_traces] = estimate_offset_and_noise(
            block, threshold=cfg.quiet_threshold)[:2]
        out[s:s + chunk_traces] = block - offset[:, None] if cfg.remove_offset else block
    cutoff = cfg.cutoff_hz
    if cutoff is None:
        k = int(np.argmax(np.einsum("ij,ij->i", out, out)))
        cutoff = auto_cutoff(out[k].astype(float), sampling_rate, float(sigmas[k]), cal, cfg)
    transfer = regularised_inverse(cal, f, cutoff, cfg)
    for s in range(0, flat.shape[0], max(1, int(chunk_traces))):
        spec = to_frequency(out[s:s + chunk_traces], axis=-1) * transfer
        out[s:s + chunk_traces] = to_time(spec, nt, axis=-1)
    return out.reshape(x.shape), float(cutoff)
