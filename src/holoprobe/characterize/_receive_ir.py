"""Per-element receive pressure, receive impulse response, per-element sensitivity.

Receive half of the pipeline, paper section III B (reference_spec 1 R5–R6, 2.9).

The receive lens
----------------
On receive the lens delays the wave reaching the point v of an element by
``τ(v) = (√((H/2)² + F²) − √(v² + F²))/c0`` (paper eq. lens-delays) before it reaches the
piezo-element, which integrates over its surface. So the element pressure is
``p_e(t) = ⟨p(u, v, t − τ(v))⟩_element``: in holoprobe's conjugate convention each point's
spectrum is multiplied by ``e^{+iωτ(v)}``. This is what "reversing the lens delays" of
the virtual sensor means (the receive path is the transmit path run backwards), it is
what the published code does (PROTEUS ``compute_RF_data``: ``e^{−2πifτ}`` in the plain FFT
convention, a delay) and it is the receive lens delay counted in the t0 relation of
paper section III B. A wave from the lens focus then reaches the piezo-element in phase
over the whole height. (Multiplying by ``e^{−iωτ}``, as on transmit, would instead
double the lens's defocus.)
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg
import scipy.optimize
from numpy.typing import ArrayLike, NDArray

from holoprobe.characterize._receive import ReceiveConfig
from holoprobe.characterize._reflection import echo_train_peaks
from holoprobe.characterize._virtual_receiver import SensorLayout
from holoprobe.errors import FitError, InputError
from holoprobe.lens import lens_delays
from holoprobe.measurement import DriveSignal
from holoprobe.signal import (
    blas_threads,
    continuous_spectrum,
    detect_onset,
    envelope,
    fractional_delay,
    frequency_axis,
    next_fast_length,
    noise_floor,
    noise_sigma,
    resample,
    to_frequency,
    to_time,
)

__all__ = [
    "DriveRatio",
    "ElementSensitivity",
    "ReceiveImpulseResponse",
    "TransferFunctionEstimate",
    "drive_amplitude_ratio",
    "element_receive_pressure",
    "element_sensitivity",
    "receive_impulse_response",
    "spectral_window",
    "transfer_function_estimate",
]


def _focus(lens: Any) -> float:
    if hasattr(lens, "focus"):
        return float(lens.focus)
    try:
        return float(lens)
    except (TypeError, ValueError):
        raise InputError("expected a focus in m or an object with .focus (e.g. LensFit)",
                         field="lens") from None


PRESSURE_CHUNK = 2**20  # values (points × bins) per pass of element_receive_pressure


def element_receive_pressure(pressure: ArrayLike, layout: SensorLayout, frequencies: ArrayLike,
                             lens: Any, *, sound_speed: float = 1481.0,
                             center_y: float | None = None) -> NDArray[np.complex128]:
    """Per-element receive pressure from the pressure on the sampled virtual sensor.

    ``P_e(ω) = Σ_j w_j P_j(ω) e^{+iωτ(v_j − y_L)} / Σ_j w_j`` over the points j of
    element e: the exact receive lens delay (paper eq. lens-delays, see the module notes
    for the sign) and the area-weighted average over the element's surface.

    Parameters
    ----------
    pressure : array_like, complex, shape (n, nf)
        Pressure (conjugate convention) on the points of
        :func:`~holoprobe.characterize.virtual_sensor_surface`, element-major, e.g. from
        :func:`holoprobe.propagation.project` (× Rp, or scale later).
    layout : SensorLayout
        The points' element membership, elevations and weights.
    frequencies : array_like, shape (nf,)
        Hz.
    lens : float or LensFit
        Focus F in m (``inf``: no lens), or an object with ``.focus``.
    sound_speed : float
        c0 in m/s.
    center_y : float, optional
        Lens centre in the sensor's in-plane coordinates (m); default the layout's
        element centre (the lens is centred on the aperture, as in the transmit step
        and the exported model; a fitted ``LensFit.center_y`` is in the coordinates
        of the transmit source grid and is not used).

    Returns
    -------
    ndarray, complex, shape (n_el, nf)
    """
    if not isinstance(layout, SensorLayout):
        raise InputError("expected a SensorLayout from virtual_sensor_surface", field="layout")
    p = np.asarray(pressure)
    f = np.asarray(frequencies, dtype=float).reshape(-1)
    n = layout.element_count * layout.points_per_element
    if p.ndim == 1:
        p = p[:, None]
    if p.shape != (n, f.size):
        raise InputError(f"expected shape ({n}, {f.size}) (points × frequencies), got "
                         f"{np.shape(pressure)}", field="pressure")
    focus = _focus(lens)
    yl = layout.center_y if center_y is None else float(center_y)
    if math.isinf(focus):
        tau = np.zeros(n)
    else:
        tau = lens_delays(layout.v - yl, focus, layout.height, sound_speed)
    w = layout.weights
    out = np.empty((layout.element_count, f.size), complex)
    step = max(1, int(PRESSURE_CHUNK // max(n, 1)))
    # the points share a few elevations: each distinct delay's phasors once, then gathered
    tau_u, which = np.unique(tau, return_inverse=True)
    for i in range(0, f.size, step):
        ff = f[i:i + step]
        ph = np.exp(1j * 2 * np.pi * ff[None, :] * tau_u[:, None])[which.reshape(-1)]
        v = (p[:, i:i + step] * ph * w[:, None]).reshape(layout.element_count,
                                                          layout.points_per_element, -1)
        out[:, i:i + step] = v.sum(axis=1)
    wsum = w.reshape(layout.element_count, -1).sum(axis=1)
    return out / wsum[:, None]


def drive_amplitude_ratio(receive_drive: DriveSignal, transmit_drive: DriveSignal) -> float:
    """Peak drive voltage of the echo experiment over that of the scan (reference_spec
    2.9 step 2). Right only when both drives have the same shape; see
    :class:`DriveRatio` for the general case."""
    for name, d in (("receive_drive", receive_drive), ("transmit_drive", transmit_drive)):
        if not isinstance(d, DriveSignal):
            raise InputError("expected a holoprobe.measurement.DriveSignal", field=name)
    if transmit_drive.peak == 0:
        raise InputError("the transmit drive is zero", field="transmit_drive")
    return receive_drive.peak / transmit_drive.peak


@dataclass(frozen=True)
class DriveRatio:
    """Spectral ratio of the echo experiment's drive to the scan's, ``E_echo(f)/E_scan(f)``.

    The incident pressure of the echo experiment is the scan's field times this ratio
    (a linear, time-invariant probe): unlike the ratio of peak voltages it is right when
    the two drives differ in shape (a burst and a 12 ns pulse). Evaluated as
    ``E_echo E_scan* / (|E_scan|² + ε²)`` with ``ε = 10^(floor_db/20) · max|E_scan|``, so
    that notches of the scan drive's spectrum do not blow up (the scan field carries no
    information there anyway). Both drives start at their experiment's emission (t = 0).

    Attributes
    ----------
    receive_drive, transmit_drive : DriveSignal
        Drive of the echo experiment and of the hydrophone scan (V).
    floor_db : float
        Regularisation level (dB re the peak of ``|E_scan|``, negative).
    """

    receive_drive: DriveSignal
    transmit_drive: DriveSignal
    floor_db: float = -40.0

    def __post_init__(self) -> None:
        for name in ("receive_drive", "transmit_drive"):
            if not isinstance(getattr(self, name), DriveSignal):
                raise InputError("expected a holoprobe.measurement.DriveSignal", field=name)
        if not self.transmit_drive.peak > 0:
            raise InputError("the transmit drive is zero", field="transmit_drive")
        if not (math.isfinite(self.floor_db) and self.floor_db < 0):
            raise InputError(f"expected a negative level in dB, got {self.floor_db!r}",
                             field="floor_db")

    def __call__(self, frequencies: ArrayLike) -> NDArray[np.complex128]:
        """The ratio (dimensionless, complex) at ``frequencies`` (Hz, shape (nf,))."""
        f = np.asarray(frequencies, dtype=float).reshape(-1)
        e_r = continuous_spectrum(self.receive_drive.voltage,
                                  self.receive_drive.sampling_rate, f)
        e_t = continuous_spectrum(self.transmit_drive.voltage,
                                  self.transmit_drive.sampling_rate, f)
        v = self.transmit_drive.voltage
        peak = float(np.max(np.abs(np.fft.rfft(v, 8 * v.size)))) / \
            self.transmit_drive.sampling_rate
        eps2 = (peak * 10 ** (self.floor_db / 20)) ** 2
        return e_r * np.conj(e_t) / (np.abs(e_t) ** 2 + eps2)


@dataclass(frozen=True)
class ReceiveImpulseResponse:
    """Result of :func:`receive_impulse_response`.

    Attributes
    ----------
    ir : ndarray, shape (m,)
        Receive impulse response in ``unit``. Its onset (the rise of the first lobe) is
        at ``onset`` (the pre-onset margin): nothing before it is cut away.
    sampling_rate : float
        Hz.
    unit : str
        ``"<voltage unit>/(Pa·s)"``.
    truncation_time : float
        s (``inf``: not truncated): the IR keeps ``t < onset + truncation_time``.
    frequencies : ndarray, shape (nb,)
        Hz, bins of the deconvolution.
    voltage_spectrum, pressure_spectrum, transfer_function : ndarray, complex, shape (nb,)
        Y (unit·s), P (Pa·s, scaled) and H (unit/Pa) as regularised, conjugate
        convention, on the input clock (paper Fig. 7e).
    voltage_noise, pressure_noise : ndarray, shape (nb,)
        Noise powers per bin (scaling of ``|to_frequency|²``), from the data.
    gain : ndarray, shape (nb,)
        The spectral window applied to Y/P (1 inside the band, see
        :func:`receive_impulse_response`).
    onset : float
        Time (s) of the IR's onset in ``ir`` (= the requested margin).
    shift : float
        Delay (s) applied to the IR against the input clock to put its onset at
        ``onset``: the geometry absorbs it (the pressure, and the virtual sensor, are
        ``shift`` earlier: ``z0' − c0·shift``).
    warnings : tuple of str
    snr : ndarray, shape (nb,), optional
        Power SNR of the kept IR per bin (the per-bin SNR of Y/P times n/L, L of the n
        samples kept): the band decision's, and the noise of
        :func:`transfer_function_estimate` when ``magnitude_variance`` is None.
    magnitude_variance : ndarray, shape (nb,), optional
        Noise variance of |H_R(f)| of the returned IR per bin ((unit/Pa)²): the
        per-bin noise of Y/P propagated through the time-limited fit
        (:func:`_fit_noise_variance`); None for a band-limited IR.
    """

    ir: NDArray[np.float64]
    sampling_rate: float
    unit: str
    truncation_time: float
    frequencies: NDArray[np.float64]
    voltage_spectrum: NDArray[np.complex128]
    pressure_spectrum: NDArray[np.complex128]
    transfer_function: NDArray[np.complex128]
    voltage_noise: NDArray[np.float64]
    pressure_noise: NDArray[np.float64]
    gain: NDArray[np.float64] | None = None
    onset: float = 0.0
    shift: float = 0.0
    warnings: tuple[str, ...] = ()
    snr: NDArray[np.float64] | None = None
    magnitude_variance: NDArray[np.float64] | None = None


def _trace(x: ArrayLike, name: str) -> NDArray[np.float64]:
    a = np.asarray(x)
    if a.ndim != 1 or a.size < 8 or np.iscomplexobj(a) or not np.issubdtype(a.dtype, np.number):
        raise InputError(f"expected a real 1-D trace of at least 8 samples, got shape "
                         f"{a.shape} and dtype {a.dtype}", field=name)
    a = a.astype(float)
    if not np.all(np.isfinite(a)):
        raise InputError("contains NaN or inf", field=name)
    return a


def _on_clock(p: NDArray, fs_p: float, t_p: float, fs: float, t_y: float, n: int) -> NDArray:
    """Band-limited pressure (time along the last axis) resampled to fs and placed on a
    length-n record from t_y."""
    m = p.shape[-1]
    pr = p if fs_p == fs else resample(p, fs_p, fs, n_out=math.ceil(m * fs / fs_p))
    if pr.shape[-1] > n:
        raise InputError(f"the pressure record ({pr.shape[-1]} samples at the voltage rate) "
                         f"is longer than the deconvolution length {n}", field="pressure")
    out = np.zeros((*pr.shape[:-1], n))
    out[..., :pr.shape[-1]] = pr
    return fractional_delay(out, t_p - t_y, fs)


def _auto_noise_window(x: NDArray, fs: float, guard: float, threshold: float,
                       ) -> tuple[float, float] | None:
    try:
        onset = detect_onset(x, fs, threshold=threshold, allow_wrap=False)
    except FitError:
        return None
    stop = onset - guard
    return (0.0, stop) if stop * fs >= 8 else None


def spectral_window(snr: ArrayLike, *, pass_db: float = 10.0,
                    stop_db: float = 0.0) -> NDArray[np.float64]:
    """Data-driven band of a deconvolution: 1 where the estimate is informative, 0 where
    it is noise over noise, a raised cosine (in dB of SNR) in between.

    Inside the band the estimate is left untouched: no Wiener shrinkage, whose factor
    ``1/(1 + 1/SNR)`` biases the gain low wherever the SNR is moderate.

    Parameters
    ----------
    snr : array_like, shape (nb,)
        Per-bin power SNR of the estimate (linear, ≥ 0).
    pass_db, stop_db : float
        Edges of the roll-off (dB, pass > stop): 1 above ``pass_db``, 0 below
        ``stop_db``.

    Returns
    -------
    ndarray, shape (nb,)
    """
    s = np.asarray(snr, dtype=float).reshape(-1)
    if not pass_db > stop_db:
        raise InputError(f"expected pass_db > stop_db, got {pass_db!r} ≤ {stop_db!r}",
                         field="pass_db")
    level = 10 * np.log10(np.maximum(s, np.finfo(float).tiny))
    x = np.clip((level - stop_db) / (pass_db - stop_db), 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * x)


def _ratio_snr(sy: NDArray, sp: NDArray, ny: NDArray, npow: NDArray,
               bins: int) -> NDArray:
    """Per-bin SNR of Y/P: ``1/SNR = N_Y/(|H|² |P|²) + N_P/|P|²``.

    ``|H|²`` is smooth over the kept IR's ``bins`` (a short response): it is estimated
    as ``⟨|Y|² − N_Y⟩ / ⟨|P|²⟩`` (moving averages over ``bins``); ``|P|²`` is the bin's
    own, so that a bin where P is nearly zero (a band edge of the projected pressure,
    where Y/P is noise amplified) gets the low SNR it has, not that of its neighbours.
    """
    k = max(1, int(bins))

    def smooth(x: NDArray) -> NDArray:
        x = np.broadcast_to(x, sy.shape)
        return np.convolve(np.pad(x, k // 2, mode="edge"), np.ones(k) / k,
                           mode="valid")[:sy.size]

    ey = np.maximum(smooth(sy) - smooth(ny), 0.0)
    sp_s = smooth(sp)
    h2 = np.where(sp_s > 0, ey / np.where(sp_s > 0, sp_s, 1.0), 0.0)
    ny_b, np_b = np.broadcast_to(ny, sy.shape), np.broadcast_to(npow, sy.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where((h2 > 0) & (sp > 0), ny_b / (h2 * sp) + np_b / sp, np.inf)
    return 1.0 / inv


def _contiguous_band(gain: NDArray, snr: NDArray) -> NDArray:
    """``gain`` kept on the contiguous run of non-zero bins around the bin of highest
    SNR, zero elsewhere: an isolated bin where P is nearly zero (a band edge of the
    projected pressure) and |Y|² happens to exceed its noise estimate is noise over
    noise, not signal."""
    peak = int(np.argmax(snr))
    if not gain[peak] > 0:
        return np.zeros_like(gain)
    inside = gain > 0
    lo = peak - int(np.argmin(inside[peak::-1])) + 1 if not np.all(inside[:peak + 1]) else 0
    hi = peak + int(np.argmin(inside[peak:])) if not np.all(inside[peak:]) else gain.size
    out = np.zeros_like(gain)
    out[lo:hi] = gain[lo:hi]
    return out


def _ir_onset(h: NDArray, fs: float, threshold: float, fraction: float,
              search: float) -> float:
    """Onset (s) of a circular IR: the rise of its first lobe.

    The envelope's first crossing of ``max(threshold σ, fraction · peak)`` within
    ``search`` s before the peak (σ: robust scatter of the IR; circular, so an IR that
    starts before zero lag is found too), then back down the rising envelope to the last
    sample still above the noise (2σ) or a local minimum: the lobe's foot, not its peak.
    Returns a time in (−n/2, n/2]/fs relative to sample 0.
    """
    n = h.size
    k = int(np.argmax(np.abs(h)))
    x = np.roll(h, n // 2 - k)  # peak at n/2
    env = envelope(x, pad=False)
    sigma = 1.482602218505602 * float(np.median(np.abs(x - np.median(x))))
    level = max(threshold * sigma, fraction * float(env.max()))
    i0 = max(0, n // 2 - int(search * fs))
    above = np.nonzero(env[i0:n // 2 + 1] >= level)[0]
    i = i0 + int(above[0]) if above.size else n // 2
    floor = 2.0 * sigma
    while i > 0 and env[i - 1] < env[i] and env[i - 1] > floor:
        i -= 1
    j = (i - (n // 2 - k)) % n
    return (j - n if j > n // 2 else j) / fs


def _ratio_variance(ratio: NDArray, sp: NDArray, ny: NDArray, npow: NDArray,
                    bins: int) -> NDArray:
    """Noise variance of Y/P per bin, ``(N_Y + |H|² N_P)/|P|²`` (|H|² smoothed over
    ``bins``, made odd; infinite where P is 0)."""
    k = max(1, int(bins))
    k += 1 - k % 2  # odd: the smoothing centred on each bin (even k shifted it half a bin)
    h2 = np.convolve(np.pad(np.abs(ratio) ** 2, k // 2, mode="edge"), np.ones(k) / k,
                     mode="valid")[:ratio.size]
    return np.asarray((ny + h2 * npow) / np.where(sp > 0, sp, np.inf), dtype=float)


def _fit_weights(ratio: NDArray, gain: NDArray, sp: NDArray, ny: NDArray, npow: NDArray,
                 bins: int, out_of_band: float) -> NDArray:
    """Weights of the time-limited fit: in the band, the window over the variance of
    Y/P per bin, ``(N_Y + |H|² N_P)/|P|²`` (|H|² smoothed over ``bins``, made odd),
    relative to the best bin; ``out_of_band`` (relative, target 0) elsewhere."""
    if not (math.isfinite(out_of_band) and out_of_band >= 0):
        raise InputError(f"expected a relative weight >= 0, got {out_of_band!r}",
                         field="out_of_band_weight")
    var = _ratio_variance(ratio, sp, ny, npow, bins)
    w = np.where(gain > 0, gain / np.maximum(var, np.finfo(float).tiny), 0.0)
    peak = float(w.max())
    return np.where(gain > 0, w / peak if peak > 0 else 0.0, out_of_band)


def _time_limited_fit(h: NDArray, weight: NDArray, start: int, length: int, lead: int,
                      reg: float) -> NDArray:
    """The IR of ``length`` samples from circular sample ``start`` whose spectrum fits
    that of the band-limited IR ``h`` (circular, length n) in the weighted least
    squares sense, ``Σ w |FT(h') − FT(h)|² + λ‖h‖²`` (``λ = reg · n · max w``); ``h'``
    is ``h`` kept from ``lead`` samples before ``start`` to the end of the support (the
    later echoes of the record are not part of the IR). Returned as a length-n circular
    trace, zero off the support.

    The band window multiplies Y/P by a function of frequency; the IR of that product
    rings before its onset (more so where the window's edges fall on a significant |H|,
    i.e. at low SNR), and cutting the ringing away at the IR's start biased every
    frequency (a ripple whose period is the inverse of the cut's distance from the main
    lobe: ±1–3 % at 25 dB). The truth is time-limited: the time-limited IR that fits
    the in-band bins reproduces their spectrum instead, and λ only settles what the band
    does not see. The normal equations are Toeplitz (the weights' inverse transform)."""
    n = h.size
    length = min(int(length), n - int(lead))
    kept = np.roll(h, int(lead) - int(start))
    kept[int(lead) + length:] = 0.0
    w = np.asarray(weight, dtype=float)
    c = to_time(w, n)[:length] * n
    c[0] += float(reg) * n * float(np.max(w))  # Szegő: the eigenvalues are ≈ n·w(f)
    r = (to_time(w * to_frequency(kept), n) * n)[int(lead):int(lead) + length]
    out = np.zeros(n)
    out[:length] = scipy.linalg.solve_toeplitz(c, r)
    return np.roll(out, int(start))


#: noise draws propagated through the time-limited fit (:func:`_fit_noise_variance`):
#: the variance per bin to ~12 % (128 degrees of freedom), smoothed further over the
#: IR's resolution by :func:`transfer_function_estimate`
FIT_NOISE_DRAWS = 64


def _fit_noise_variance(variance: NDArray, gain: NDArray, weight: NDArray, start: int,
                        length: int, lead: int, reg: float, n: int, fs: float,
                        full: int | None = None) -> tuple[NDArray, NDArray]:
    """Noise variance of |FT| of the time-limited IR per bin (``|H|`` units²): draws of
    the per-bin noise of Y/P (``variance``, complex Gaussian, a fixed seed) through the
    band window and :func:`_time_limited_fit` with its weights and support, the half in
    phase with H (``E|ΔG|²/2``). With ``full`` (the support before the noise tail cut
    it to ``length``): also that of the part of the ``full``-sample fit past ``length``
    (what the cut removed), else zeros.

    The fit is linear in the data; it leans on the bins of low noise, so its noise at a
    frequency is not the truncation's (the band's bins averaged over the IR's
    resolution): on the full-size P4-1 twin that average made σ(|H_R|) 1.7× too large
    at 1–2 MHz and 1.2× too small at 2–3 MHz; propagated, the ratio of error to σ is
    flat over the band (benchmarks/RESULTS.md "(session 12, hr)")."""
    rng = np.random.default_rng(0)
    ok = np.isfinite(variance) & (gain > 0)
    amp = np.where(ok, np.sqrt(np.where(ok, np.maximum(variance, 0.0), 0.0) / 2) * gain, 0.0)
    acc, cut = np.zeros(n // 2 + 1), np.zeros(n // 2 + 1)
    for _ in range(FIT_NOISE_DRAWS):
        noise = to_time(amp * (rng.standard_normal(amp.size)
                               + 1j * rng.standard_normal(amp.size)), n) * fs
        acc += np.abs(to_frequency(_time_limited_fit(noise, weight, start, length, lead,
                                                     reg)) / fs) ** 2
        if full is not None and full > length:
            cut += np.abs(to_frequency(_omitted(_time_limited_fit(
                noise, weight, start, full, lead, reg), start, length, full)) / fs) ** 2
    return acc / (2 * FIT_NOISE_DRAWS), cut / (2 * FIT_NOISE_DRAWS)


def _omitted(h: NDArray, start: int, length: int, full: int) -> NDArray:
    """The circular trace ``h`` kept only from ``start + length`` to ``start + full``."""
    out = np.zeros_like(h)
    idx = np.arange(start + length, start + full) % h.size
    out[idx] = h[idx]
    return out


def _centre_frequency(f: NDArray, H: NDArray) -> float:
    """Power-weighted mean frequency (Hz) of the transfer function ``H`` on ``f``."""
    p = np.abs(H) ** 2
    total = float(np.sum(p))
    return float(np.sum(f * p) / total) if total > 0 else float(f[-1])


#: rms (in noise σ) of a window after the IR's peak that keeps the IR going past any
#: quieter window before it: band-limited noise over a window (≈ 3 degrees of
#: freedom) reaches 3σ in < 1e-4 of windows
LATE_LOBE = 3.0


def _noise_end(h: NDArray, start: int, length: int, sigma: float, threshold: float,
               window: int) -> int:
    """Length (samples from circular sample ``start``) of the fitted IR ``h`` up to where
    it has fallen into its noise for good: the first window of ``window`` samples after
    its peak whose rms is below ``threshold · sigma`` and after which no window reaches
    ``LATE_LOBE · sigma`` (a later lobe, e.g. a matching layer's reverberation, after a
    quiet gap) ends the IR (that window is kept); at most ``length``. ``sigma``: the IR's
    noise per sample."""
    x = np.roll(h, -int(start))[:int(length)]
    w = max(1, int(window))
    if not (threshold > 0 and sigma > 0) or x.size <= w:
        return int(length)
    rms = np.sqrt(np.convolve(x**2, np.ones(w) / w, mode="valid"))  # rms of x[i:i + w]
    k = int(np.argmax(np.abs(x)))
    strong = np.nonzero(rms[k:] >= max(LATE_LOBE, threshold) * sigma)[0]
    after = int(strong[-1]) + 1 if strong.size else 0  # past the last strong window
    below = np.nonzero(rms[k + after:] < threshold * sigma)[0]
    return int(length) if below.size == 0 else min(int(length),
                                                   k + after + int(below[0]) + w)


def _segment(x: NDArray, window: tuple[float, float] | None, fs: float, n: int,
             ) -> tuple[NDArray[np.complex128], int]:
    """Spectrum (length-n transform) of ``x`` kept inside ``window`` (s from its first
    sample; mean removed there, zero elsewhere), and the number of samples kept."""
    i0 = i1 = 0
    if window is not None:
        i0 = max(0, math.ceil(window[0] * fs - 1e-9))
        i1 = min(x.size, math.floor(window[1] * fs + 1e-9) + 1)
    if i1 - i0 < 2:
        return np.zeros(n // 2 + 1, complex), 0
    seg = np.zeros(x.size)
    seg[i0:i1] = x[i0:i1] - np.mean(x[i0:i1])
    return to_frequency(seg, n=n), i1 - i0


def _ir_noise_sigma(y_noise: tuple[NDArray, int], p_noise: tuple[NDArray, int],
                    ratio: NDArray, P: NDArray, gain: NDArray, n: int, fs: float) -> float:
    """Noise σ per sample of the band-limited IR ``to_time(gain · Y/P, n) · fs`` from the
    records' noise-only segments (spectra and lengths from :func:`_segment`, the
    pressure's scaled as P): each deconvolved alone as the IR is, ``gain · Y_n/P`` and
    ``−gain · (Y/P) · P_n/P``; the energy of the result over the segment's length is the
    variance per sample of stationary noise.

    Not the scatter of the IR over its whole record: on a clean echo train the IR's
    copies (one per echo) are most of its samples, and their scatter is not noise (a
    slow ringing was cut where it fell below 1.5 × that); the zero padding of the
    deconvolution holds no noise at all; and lags near the IR hold the ringing of the
    band window. Only noise is deconvolved here."""
    sp = np.abs(P) ** 2
    inv = np.where(sp > 0, gain * np.conj(P) / np.where(sp > 0, sp, 1.0), 0.0)
    var = 0.0
    for (spectrum, m), factor in ((y_noise, inv), (p_noise, -inv * ratio)):
        if m:
            var += float(np.sum((to_time(factor * spectrum, n) * fs) ** 2)) / m
    return math.sqrt(var)


def receive_impulse_response(
    voltage: ArrayLike, pressure: ArrayLike, sampling_rate: float, *,
    pressure_rate: float | None = None, voltage_start_time: float = 0.0,
    pressure_start_time: float = 0.0, noise_window: tuple[float, float] | None = None,
    pressure_noise_window: tuple[float, float] | None = None,
    reflection_coefficient: float = 1.0, drive_ratio: float | DriveRatio = 1.0,
    truncate_before: float | None = None, output_rate: float = 250e6,
    voltage_unit: str = "ADCL", noise_guard: float = ReceiveConfig.noise_guard,
    onset_threshold: float = 5.0,
    peak_fraction: float = 0.2, segment_length: int = 256, pressure_floor_db: float = 60.0,
    smooth_bins: int = 9, pass_db: float = 10.0, stop_db: float = 0.0,
    onset_margin: float = 0.25e-6, onset_fraction: float = 0.1,
    time_limited: bool = True, out_of_band_weight: float = 1e-3,
    fit_regularization: float = 1e-5, noise_tail: float = 1.5,
    noise_tail_window: float = 0.25e-6,
) -> ReceiveImpulseResponse:
    """Receive impulse response by one regularised deconvolution (paper eq.
    deconvolution-receive; reference_spec 2.9 steps 2–7).

    ``H = w(f) · Y/P`` with Y the (tilt-aligned, averaged) echo voltage and P the
    (tilt-aligned, averaged) receive pressure × ``reflection_coefficient`` ×
    ``drive_ratio``, both on the voltage's clock, and ``w`` the data-driven band of
    :func:`spectral_window` from the per-bin SNR of the ratio,
    ``1/SNR = N_Y/|Y|² + N_P/|P|²`` — the two noise terms of the paper's modified
    Wiener filter, counted once. The paper's factor ``1/(1 + 1/SNR)`` applied to every
    bin shrinks the in-band gain wherever the SNR is moderate (0.26–0.68 of the truth at
    the band edge at 25–40 dB); here the gain is 1 inside the band, so the in-band
    estimate is unbiased, and 0 where the bins hold noise over noise. The noise powers
    come from the data: Welch spectra (:func:`holoprobe.signal.noise_floor`) of
    pre-echo segments. The band is decided on the SNR of the IR that is kept (L of the
    n samples of the deconvolution: n/L times the per-bin SNR, the truncation drops
    the rest of the noise) and is the contiguous run of bins around the best one.

    The IR is not cut at an onset estimate: its onset (the rise of the first lobe,
    found on the whole circular IR, before or after zero lag) is moved to
    ``onset_margin`` and the IR keeps ``onset_margin`` before it; the delay moved is
    returned as ``shift`` (the geometry absorbs it). It is resampled to ``output_rate``
    and truncated before the back-wall echo.

    Parameters
    ----------
    voltage : array_like, shape (n,)
        Echo voltage (ADCL or V), e.g. ``VirtualReceiver.averaged_rf``.
    pressure : array_like, shape (m,)
        Incident receive pressure in Pa (not yet × Rp), e.g. the tilt-aligned average of
        :func:`element_receive_pressure` back in the time domain.
    sampling_rate : float
        Voltage sampling rate in Hz (the deconvolution runs at it).
    pressure_rate : float, optional
        Pressure sampling rate in Hz (default ``sampling_rate``); band-limited resampling.
    voltage_start_time, pressure_start_time : float
        Times (s, transmit clock) of the first samples.
    noise_window : (float, float), optional
        Signal-free interval of the voltage (s, transmit clock). Default: from the first
        sample to ``noise_guard`` before the voltage's onset
        (:func:`holoprobe.signal.detect_onset` at ``onset_threshold``).
    pressure_noise_window : (float, float), optional
        Same for the pressure. When no such segment exists (a short projected record)
        only the floor ``pressure_floor_db`` is used, with a warning.
    reflection_coefficient : float
        Rp (:func:`~holoprobe.characterize.estimate_reflection_coefficient`).
    drive_ratio : float or DriveRatio
        Echo-experiment drive over scan drive: a number, or the spectral ratio
        ``E_echo(f)/E_scan(f)`` (:class:`DriveRatio`) when the drives differ in shape.
    truncate_before : float, optional
        Longest IR after its onset (s; ``noise_tail`` may end it earlier). Default: the
        echo-train period of the voltage
        (:func:`~holoprobe.characterize.echo_train_peaks`, ``peak_fraction``); no
        truncation (with a warning) when the train shows fewer than two echoes.
    output_rate : float
        Sampling rate of the returned IR in Hz.
    voltage_unit : str
        Unit of ``voltage`` (for ``unit``).
    noise_guard, onset_threshold : float
        Automatic noise windows (s, σ units); ``onset_threshold`` is also the level (in
        the IR's noise σ) of its onset.
    peak_fraction : float
        See ``truncate_before``.
    segment_length : int
        Welch segment length (samples).
    pressure_floor_db : float
        Least pressure noise assumed in every bin (dB below its spectral peak).
    smooth_bins : int
        Least width (bins) of the moving average of the powers in the SNR (at least
        the n/L bins over which the spectrum of the kept IR is smooth anyway).
    pass_db, stop_db : float
        Band edges in SNR of the kept IR (:func:`spectral_window`).
    onset_margin : float
        Time (s) kept before the IR's onset.
    onset_fraction : float
        The IR's onset level is at least this fraction of its envelope peak.
    time_limited : bool
        Return the time-limited IR (``onset_margin`` before the onset to the
        truncation) whose spectrum fits the in-band bins of ``Y/P`` by weighted least
        squares (weights: inverse variance per bin × the band window; the Toeplitz
        normal equations of :func:`scipy.linalg.solve_toeplitz`), instead of the
        band-limited IR cut to that length: the band window's ringing before the onset
        was cut away with it, a same-sign ripple of ±1–3 % of |H| at 25 dB on P4-1
        twins (benchmarks/receive_ir_bias.py). The band-limited IR, kept from half the
        truncation before the onset (no later echo), is what is fitted.
    out_of_band_weight : float
        Weight of the bins outside the band (relative to the best in-band bin, target
        zero) in that fit.
    fit_regularization : float
        λ of that fit (``λ‖h‖²``) relative to ``n · max w``, the largest eigenvalue of
        its normal equations: what the weights see less than this is settled by λ.
    noise_tail : float
        The time-limited IR ends where it has fallen into its noise for good: at the
        end of the first window (``noise_tail_window`` s, at least half a period of
        the IR's centre frequency) after its peak whose rms is below ``noise_tail`` × the
        IR's noise σ (the noise windows of the voltage and the pressure deconvolved
        alone, as the IR is: only noise; the scatter of the IR over its whole record took
        a clean echo train's IR copies for noise and missed the noise of the zero
        padding) and after which no window reaches 3σ (a later lobe after a
        quiet gap is kept), and is fitted again on that support; ``truncation_time`` and
        ``snr`` follow. Below 1.5σ a window's signal energy is about its noise energy or
        less: keeping it adds more error than cutting it. Up to the echo-train period
        the rest is noise (and the leakage of the back-wall echo's edge): on the
        full-size P4-1 twin at 25 dB (true IR 2 µs, period 4.3 µs) it doubled the noise
        of |H_R| at the band edges; the −6 dB band was within ±5 % in 6 of 8 draws
        (0.945 … 1.053), now in 12 of 12 (0.964 … 1.032; benchmarks/RESULTS.md
        "Issue 10 acceptance (session 11, acc10)"). 0: the IR keeps the whole
        truncation.

    Returns
    -------
    ReceiveImpulseResponse
    """
    y = _trace(voltage, "voltage")
    p = _trace(pressure, "pressure")
    fs = _positive_rate(sampling_rate, "sampling_rate")
    fs_p = fs if pressure_rate is None else _positive_rate(pressure_rate, "pressure_rate")
    scale = float(reflection_coefficient) * (1.0 if isinstance(drive_ratio, DriveRatio)
                                             else float(drive_ratio))
    if not (np.isfinite(scale) and scale != 0):
        raise InputError("expected a finite, non-zero reflection_coefficient × drive_ratio",
                         field="reflection_coefficient")
    notes: list[str] = []
    t_y, t_p = float(voltage_start_time), float(pressure_start_time)
    n_pres = math.ceil(p.size * fs / fs_p)
    n = next_fast_length(max(y.size, n_pres + math.ceil(abs(t_p - t_y) * fs) + 1))
    f = frequency_axis(n, fs)
    p_on = _on_clock(p, fs_p, t_p, fs, t_y, n) * scale
    Y: NDArray[np.complex128] = to_frequency(y, n=n)
    P: NDArray[np.complex128] = to_frequency(p_on)
    if isinstance(drive_ratio, DriveRatio):
        P = P * drive_ratio(f)
    ny, npow, win, pwin = _noise_powers(y, p, P, fs, fs_p, n, n_pres, t_y, t_p, scale,
                                        notes, noise_window, pressure_noise_window,
                                        noise_guard, onset_threshold, segment_length,
                                        pressure_floor_db)
    t_cut = _truncation(y, fs, truncate_before, peak_fraction, notes)
    # the spectrum of the kept IR (length L) is smooth over n/L bins: the powers in
    # the SNR of the band decision are averaged over that many bins; keeping L of the n
    # samples keeps L/n of the (spread) noise, so the kept IR's SNR is n/L times the
    # per-bin SNR of Y/P
    keep = min(1.0, (t_cut + float(onset_margin)) * fs / n) if math.isfinite(t_cut) else 1.0
    sp = np.abs(P) ** 2
    snr = _ratio_snr(np.abs(Y) ** 2, sp, ny, npow, max(int(smooth_bins), round(1 / keep)))
    snr = snr / keep
    gain = _contiguous_band(spectral_window(snr, pass_db=pass_db, stop_db=stop_db), snr)
    ratio = np.where(sp > 0, Y * np.conj(P) / np.where(sp > 0, sp, 1.0), 0.0)
    H = ratio * gain
    h = to_time(H, n) * fs
    margin = float(onset_margin)
    if not (np.isfinite(margin) and margin >= 0):
        raise InputError(f"expected a non-negative time in s, got {onset_margin!r}",
                         field="onset_margin")
    search = 0.5 * (t_cut if math.isfinite(t_cut) else n / fs)  # no wrapped late echo
    onset = _ir_onset(h, fs, onset_threshold, onset_fraction, search)
    shift = margin - onset
    mag_var = None
    if time_limited and math.isfinite(t_cut):
        w = _fit_weights(ratio, gain, sp, ny, npow, max(int(smooth_bins), round(1 / keep)),
                         float(out_of_band_weight))
        start, length = round((onset - margin) * fs), math.ceil((t_cut + margin) * fs) + 1
        lead, reg = round(0.5 * t_cut * fs), float(fit_regularization)
        h_band, h = h, _time_limited_fit(h, w, start, length, lead, reg)
        half_period = 0.5 * fs / _centre_frequency(f, H)  # sin² averages to ½ over it
        pn, m = _segment(p if fs_p == fs else resample(p, fs_p, fs, n_out=n_pres), pwin,
                         fs, n)
        pn = pn * scale * (drive_ratio(f) if isinstance(drive_ratio, DriveRatio) else 1.0)
        sigma = _ir_noise_sigma(_segment(y, win, fs, n), (pn, m), ratio, P, gain, n, fs)
        end = _noise_end(h, start, length, sigma, float(noise_tail),
                         max(round(float(noise_tail_window) * fs), round(half_period)))
        variance = _ratio_variance(ratio, sp, ny, npow, max(int(smooth_bins), round(1 / keep)))
        mag_var, cut_noise = _fit_noise_variance(variance, gain, w, start, min(end, length),
                                                 lead, reg, n, fs, full=length)
        if end < length:
            # what the cut removes: the response's tail (a bias of the kept IR) and
            # noise; the tail's power (in phase: half) goes into the variance
            cut = np.abs(to_frequency(_omitted(h, start, end, length)) / fs) ** 2 / 2
            mag_var = mag_var + np.maximum(cut - cut_noise, 0.0)
            h = _time_limited_fit(h_band, w, start, end, lead, reg)
            snr, t_cut = snr * (length / end), (end - 1) / fs - margin
    fo = _positive_rate(output_rate, "output_rate")
    h_out = resample(fractional_delay(h, shift, fs), fs, fo)
    m = h_out.size // 2 if math.isinf(t_cut) else min(h_out.size,
                                                       math.ceil((t_cut + margin) * fo))
    for note in notes:
        warnings.warn(note, UserWarning, stacklevel=2)
    return ReceiveImpulseResponse(
        ir=h_out[:m], sampling_rate=fo, unit=f"{voltage_unit}/(Pa·s)", truncation_time=t_cut,
        frequencies=f, voltage_spectrum=Y / fs, pressure_spectrum=P / fs,
        transfer_function=H, voltage_noise=np.broadcast_to(ny, Y.shape).copy(),
        pressure_noise=np.broadcast_to(npow, Y.shape).copy(), gain=gain, onset=margin,
        shift=float(shift), warnings=tuple(notes), snr=snr, magnitude_variance=mag_var)


@dataclass(frozen=True)
class TransferFunctionEstimate:
    """|H_R(f)| of a receive IR with its standard uncertainty per frequency
    (:func:`transfer_function_estimate`).

    Attributes
    ----------
    frequencies : ndarray, shape (nf,)
        Hz: the IR's own frequency resolution (1/its duration) inside the band where the
        deconvolution's window is 1.
    magnitude : ndarray, shape (nf,)
        |H_R(f)| in ``unit`` (the continuous Fourier transform of the reported IR).
    uncertainty : ndarray, shape (nf,)
        Standard uncertainty of ``magnitude`` in ``unit``.
    unit : str
        ``"<voltage unit>/Pa"``.
    """

    frequencies: NDArray[np.float64]
    magnitude: NDArray[np.float64]
    uncertainty: NDArray[np.float64]
    unit: str


def transfer_function_estimate(ir: ReceiveImpulseResponse, *, scale_uncertainty: float = 0.0,
                               relative_floor: float = 0.0,
                               max_relative_uncertainty: float = 0.1,
                               ) -> TransferFunctionEstimate:
    """|H_R(f)| of the reported receive IR and its standard uncertainty per frequency.

    The time-limited IR carries ``ir.magnitude_variance``: the per-bin noise of Y/P
    propagated through its weighted fit, plus the power of the response's tail that the
    noise tail cut away (a bias, less the noise of that part); it is averaged over the
    kernel's main lobe (± 1/T). Otherwise (a band-limited IR) the noise is that of the
    plain truncation, as follows. The IR keeps L of the n samples of the deconvolution
    ``H = Y/P``; its spectrum at f
    is the deconvolution's spectrum smoothed by the truncation kernel
    ``sinc²((f − f_i)·T)`` (T = L/rate, the IR's duration). Each bin's noise is
    ``|H|²/SNR_i`` (``1/SNR = N_Y/(|H|²|P|²) + N_P/|P|²``, the noise powers measured
    on the data); the kept IR's bins carry L/n of it, i.e. ``1/ir.snr`` (the kept IR's
    SNR), averaged over the kernel. The magnitude takes the half in phase with H:
    ``σ(|H|)/|H| = √(⟨1/ir.snr⟩/2)``, combined in quadrature with
    ``scale_uncertainty`` (relative, e.g. σ(Rp)/Rp, which scales the whole IR) and
    ``relative_floor`` (the errors the noise does not hold, see below).

    Frequencies are those of the IR's own resolution 1/T where the deconvolution's
    window is 1 over the kernel's main lobe (± 1/T): in the roll-off the window shrinks
    the estimate on purpose (a bias, so no σ is given there); and where the noise σ is
    at most ``max_relative_uncertainty`` of |H|: beyond ~10 % the magnitude's error is
    no longer Gaussian (on 30 draws of a synthetic echo its scatter grew to 1.6–2× the
    σ at σ ≥ 10 %, 0.9–1.25× below), and the band's edge was chosen on the same noise.

    Not in the noise term, hence ``relative_floor`` (``receive.transfer_function_floor``):
    the errors of the projected pressure and the truncation's leakage of the band edges;
    on 30 P4-1 twins (time-limited IR) the mean error per band is within ±0.6 % but
    +1.0 % at 3.1–3.5 MHz (benchmarks/RESULTS.md "Session 9").

    Parameters
    ----------
    ir : ReceiveImpulseResponse
        From :func:`receive_impulse_response` (with its ``snr`` and ``gain``).
    scale_uncertainty : float
        Relative standard uncertainty of a factor common to every frequency (≥ 0).
    relative_floor : float
        Relative standard uncertainty of every frequency on top of the noise (≥ 0).
    max_relative_uncertainty : float
        Largest relative noise σ of a reported frequency (> 0).

    Returns
    -------
    TransferFunctionEstimate
    """
    if ir.snr is None or ir.gain is None:
        raise InputError("the receive IR carries no per-bin SNR or window (made by an "
                         "older version?)", field="ir")
    u_scale, u_max = float(scale_uncertainty), float(max_relative_uncertainty)
    u_floor = float(relative_floor)
    for name, value in (("scale_uncertainty", u_scale), ("relative_floor", u_floor)):
        if not (math.isfinite(value) and value >= 0):
            raise InputError(f"expected a relative uncertainty >= 0, got {value!r}",
                             field=name)
    if not u_max > 0:
        raise InputError(f"expected a relative uncertainty > 0, got "
                         f"{max_relative_uncertainty!r}", field="max_relative_uncertainty")
    fo = float(ir.sampling_rate)
    duration = ir.ir.size / fo
    f_dec = np.asarray(ir.frequencies, dtype=float)
    step = 1.0 / duration
    grid = np.arange(1, int(f_dec[-1] / step)) * step
    lobe = np.abs(grid[:, None] - f_dec[None, :]) <= step
    passed = np.all(~lobe | (ir.gain[None, :] >= 1.0 - 1e-9), axis=1) & lobe.any(axis=1)
    f = grid[passed]
    k = np.sinc((f[:, None] - f_dec[None, :]) * duration) ** 2
    mag = np.abs(continuous_spectrum(ir.ir, fo, f))
    if ir.magnitude_variance is not None:  # propagated through the fit: its main lobe
        k[np.abs(f[:, None] - f_dec[None, :]) > step] = 0.0
        var = (k * ir.magnitude_variance).sum(axis=1) / np.maximum(k.sum(axis=1),
                                                                   np.finfo(float).tiny)
        noise = np.sqrt(var) / np.maximum(mag, np.finfo(float).tiny)
    else:
        inv = np.where(ir.snr > 0, 1.0 / np.maximum(ir.snr, np.finfo(float).tiny), np.inf)
        k[np.abs(f[:, None] - f_dec[None, :]) > 3 * step] = 0.0
        inside = ir.gain > 0  # the window removed the noise of the other bins
        mean_inv = (k * np.where(inside, inv, 0.0)).sum(axis=1) / np.maximum(
            (k * inside).sum(axis=1), np.finfo(float).tiny)
        noise = np.sqrt(0.5 * mean_inv)
    keep = noise <= u_max
    f, noise, mag = f[keep], noise[keep], mag[keep]
    rel = np.sqrt(noise**2 + u_scale**2 + u_floor**2)
    unit = ir.unit.replace("/(Pa·s)", "/Pa")
    return TransferFunctionEstimate(frequencies=f, magnitude=mag, uncertainty=rel * mag,
                                    unit=unit)


def _positive_rate(value: float, name: str) -> float:
    v = float(value)
    if not (np.isfinite(v) and v > 0):
        raise InputError(f"expected a positive rate in Hz, got {value!r}", field=name)
    return v


def _noise_powers(y, p, P, fs, fs_p, n, n_pres, t_y, t_p, scale, notes, noise_window,
                  pressure_noise_window, noise_guard, onset_threshold, segment_length,
                  pressure_floor_db) -> tuple[NDArray, NDArray, tuple[float, float],
                                              tuple[float, float] | None]:
    """Noise powers per bin of the voltage and of the (scaled) pressure, from the data,
    and the noise windows (s from each record's first sample) they came from."""
    if noise_window is None:
        win = _auto_noise_window(y, fs, noise_guard, onset_threshold)
        if win is None:
            raise FitError("no pre-echo segment for the voltage noise: the echo starts "
                             "within the first samples or never leaves the noise; give "
                             "noise_window", field="noise_window")
    else:
        win = (float(noise_window[0]) - t_y, float(noise_window[1]) - t_y)
    ny = noise_floor(y, win, sampling_rate=fs, n=n, segment_length=segment_length)
    p_rs = p if fs_p == fs else resample(p, fs_p, fs, n_out=n_pres)
    if pressure_noise_window is None:
        pwin = _auto_noise_window(p_rs, fs, noise_guard, onset_threshold)
    else:
        pwin = (float(pressure_noise_window[0]) - t_p, float(pressure_noise_window[1]) - t_p)
    # a floor below the pressure's spectral peak always applies: outside the band of the
    # pressure record (e.g. above the scan's Nyquist frequency) P and its noise are zero
    peak = float(np.max(np.abs(P)))
    npow = np.full(n // 2 + 1, (peak * 10 ** (-pressure_floor_db / 20)) ** 2)
    if pwin is not None:
        npow = np.maximum(npow, noise_floor(p_rs, pwin, sampling_rate=fs, n=n,
                                            segment_length=segment_length) * scale**2)
    else:
        notes.append(f"no pre-arrival segment in the pressure record: pressure noise floor "
                     f"set {pressure_floor_db:g} dB below its spectral peak")
    # Welch removes each segment's mean: below one bin of the segment length its noise
    # power is unreliable (zero at DC); hold the value of that bin
    low = frequency_axis(n, fs) < 2 * fs / segment_length
    if np.any(~low):
        i = int(np.argmin(low))
        ny = np.broadcast_to(ny, low.shape).copy()
        ny[low] = ny[i]
        npow[low] = npow[i]
    return ny, npow, win, pwin


def _truncation(y: NDArray, fs: float, truncate_before: float | None, peak_fraction: float,
                notes: list[str]) -> float:
    """IR length after its onset: the user's, else the echo-train period (or inf)."""
    if truncate_before is not None:
        t_cut = float(truncate_before)
        if not t_cut > 0:
            raise InputError("expected a positive time in s", field="truncate_before")
        return t_cut
    times, _ = echo_train_peaks(y, fs, fraction=peak_fraction, count=2)
    if times.size >= 2:
        return float(times[1] - times[0])
    notes.append("no second echo found: the receive IR is not truncated")
    return float("inf")


@dataclass(frozen=True)
class ElementSensitivity:
    """Relative receive sensitivity of each element (:func:`element_sensitivity`).

    Attributes
    ----------
    amplitude : ndarray, shape (n_el,)
        Gain relative to the element average (1: average).
    delay : ndarray, shape (n_el,)
        Extra delay of each element relative to the average in s.
    band : (float, float)
        Frequency band used (Hz).
    amplitude_uncertainty, delay_uncertainty : ndarray, shape (n_el,), optional
        Standard uncertainties from the scatter of the per-bin transfer about the fitted
        ``a e^{iωδ}`` (noise and any frequency-dependent model error; None when not
        computed), with the terms the pipeline adds (the predicted pressure's noise; the
        hidden steering, amplitude only: ``steering_uncertainty``).
    steering_uncertainty : float
        σ_ε (rad) of the steering hidden in the transmit map's delays whose effect is in
        ``amplitude_uncertainty`` (:func:`~holoprobe.characterize.steering_prediction`;
        0: not included).
    """

    amplitude: NDArray[np.float64]
    delay: NDArray[np.float64]
    band: tuple[float, float]
    amplitude_uncertainty: NDArray[np.float64] | None = None
    delay_uncertainty: NDArray[np.float64] | None = None
    steering_uncertainty: float = 0.0


def element_sensitivity(rf: ArrayLike, pressure: ArrayLike, sampling_rate: float, *,
                        pressure_rate: float | None = None, rf_start_time: float = 0.0,
                        pressure_start_time: float = 0.0, used: ArrayLike | None = None,
                        band_db: float = -12.0, max_delay: float | None = None,
                        prediction_noise: bool | tuple[ArrayLike, ArrayLike] = False,
                        ) -> ElementSensitivity:
    """Relative amplitude and delay of every element from its RF and its receive pressure.

    Per element the transfer ``G_e = Y_e P_e* / |P_e|²`` is divided by the average
    transfer ``Σ Y_e P_e* / Σ |P_e|²`` (used elements) and ``a_e e^{iωδ_e}`` is fitted to
    that ratio in least squares over the band where the mean pressure spectrum is within
    ``band_db`` of its peak, weighted by ``|P_e|²`` (δ from a grid search over
    ±``max_delay``, then refined; no phase unwrapping). Tilt and geometric delays cancel in
    the ratio because RF and pressure carry the same ones.

    Parameters
    ----------
    rf : array_like, shape (n_el, n)
        Element RF.
    pressure : array_like, shape (n_el, m)
        Per-element receive pressure in the time domain (× Rp), Pa.
    sampling_rate : float
        RF rate in Hz.
    pressure_rate : float, optional
        Pressure rate (default ``sampling_rate``).
    rf_start_time, pressure_start_time : float
        First-sample times (s, common clock).
    used : array_like of bool, shape (n_el,), optional
        Elements forming the reference average (default all).
    band_db : float
        Band level (negative dB re the peak of the mean pressure spectrum).
    max_delay : float, optional
        Largest element delay searched (s); default half a period at the band centre.
    prediction_noise : bool or (array_like, array_like)
        Add to the uncertainties, in quadrature, the noise of each element's own
        ``pressure``: a pressure predicted from a noisy scan carries one noise
        realisation per element on a short (zero-padded) record, shared by neighbouring
        bins, which the per-bin scatter misses. True: measured on the record before its
        pulse (:func:`prediction_uncertainty`); a pair: the relative-amplitude and delay
        (s) uncertainties per element, shape (n_el,) each, from the projected scan noise
        (:meth:`~holoprobe.characterize.SensorPredictor.noise_uncertainty`).

    Returns
    -------
    ElementSensitivity
    """
    y = np.asarray(rf, dtype=float)
    pr = np.asarray(pressure, dtype=float)
    if y.ndim != 2 or pr.ndim != 2 or y.shape[0] != pr.shape[0]:
        raise InputError(f"expected rf (n_el, n) and pressure (n_el, m) with the same n_el, "
                         f"got {y.shape} and {pr.shape}", field="pressure")
    fs = float(sampling_rate)
    fs_p = fs if pressure_rate is None else float(pressure_rate)
    n_pres = math.ceil(pr.shape[1] * fs / fs_p)
    lag = abs(pressure_start_time - rf_start_time) * fs
    n = next_fast_length(max(y.shape[1], n_pres + math.ceil(lag) + 1))
    p_on = _on_clock(pr, fs_p, pressure_start_time, fs, rf_start_time, n)
    Y = to_frequency(y, n=n)
    P = to_frequency(p_on)
    m = np.ones(y.shape[0], bool) if used is None else np.asarray(used, bool).reshape(-1)
    f = frequency_axis(n, fs)
    pm = np.mean(np.abs(P[m]) ** 2, axis=0)
    idx = np.nonzero(pm >= pm.max() * 10 ** (band_db / 10))[0]
    band = np.zeros(pm.size, bool)
    band[idx.min():idx.max() + 1] = True  # contiguous: uniform bin spacing for the slope
    g_ref = np.sum(Y[m][:, band] * np.conj(P[m][:, band]), axis=0) / np.sum(
        np.abs(P[m][:, band]) ** 2, axis=0)
    omega = 2 * np.pi * f[band]
    if max_delay is None:
        max_delay = 0.5 / float(np.mean(f[band]))
    grid = np.linspace(-0.5 * max_delay, 0.5 * max_delay, 129) * 2
    fit = _element_transfers(Y[:, band] * np.conj(P[:, band]), np.abs(P[:, band]) ** 2,
                             g_ref, omega, grid)
    # zero padding makes neighbouring bins share their noise: fewer independent bins
    padding = math.sqrt(max(n / y.shape[1], 1.0))
    u_amp, u_delay = fit[:, 2] * padding, fit[:, 3] * padding
    if isinstance(prediction_noise, tuple) or bool(prediction_noise):
        pair = (prediction_uncertainty(pr, fs_p) if not isinstance(prediction_noise, tuple)
                else (np.broadcast_to(np.asarray(u, dtype=float), (pr.shape[0],))
                      for u in prediction_noise))
        u_rel, u_pd = (np.nan_to_num(u) for u in pair)
        u_amp, u_delay = np.hypot(u_amp, np.abs(fit[:, 0]) * u_rel), np.hypot(u_delay, u_pd)
    return ElementSensitivity(amplitude=fit[:, 0], delay=fit[:, 1],
                              band=(float(f[band].min()), float(f[band].max())),
                              amplitude_uncertainty=u_amp, delay_uncertainty=u_delay)


def prediction_uncertainty(pressure: ArrayLike, sampling_rate: float
                           ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Uncertainty that a predicted element pressure's own noise gives its element's
    relative amplitude and delay (:func:`element_sensitivity`).

    The predicted pressure is a projection of the noisy scan: its noise is one
    realisation per element, shared by every bin of that element's transfer (the record
    is a zero-padded scan, so its bins are not independent), and the per-bin scatter of
    the transfer misses most of it. Its level is measured on the record itself
    (:func:`~holoprobe.signal.noise_sigma` of the samples before the pulse rises above a
    tenth of its envelope peak: the projected pre-signal noise of the scan with the
    projection's noise gain). For noise
    of per-sample variance σ² confined to the fraction β of the band 0…fs/2 that the
    record occupies (its power spectrum σ²/β), a least-squares fit of an amplitude and a
    delay to the pulse ``p`` has the variances ``σ²/(β Σ p²)`` (relative amplitude) and
    ``σ²/(β Σ ṗ²)`` (delay, s²).

    Parameters
    ----------
    pressure : array_like, shape (n_el, n)
        Predicted element pressure (any unit) on its full record, the pulse inside it.
    sampling_rate : float
        Its rate in Hz.

    Returns
    -------
    relative_amplitude, delay : ndarray, shape (n_el,)
        Standard uncertainties (relative; s); NaN for an element without pressure.
    """
    p = np.asarray(pressure, dtype=float)
    if p.ndim != 2 or p.shape[1] < 2:
        raise InputError(f"expected pressure (n_el, n), got shape {p.shape}", field="pressure")
    fs = float(sampling_rate)
    power = np.sum(np.abs(to_frequency(p)) ** 2, axis=0)
    beta = float(np.count_nonzero(power > 1e-12 * power.max())) / power.size if (
        power.max() > 0) else 1.0
    sigma2 = np.array([_pre_pulse_noise(row, fs) ** 2 for row in p]) / max(beta, 1e-12)
    energy = np.sum(p**2, axis=1)
    slope = np.sum(np.gradient(p, 1.0 / fs, axis=1) ** 2, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        return (np.where(energy > 0, np.sqrt(sigma2 / energy), np.nan),
                np.where(slope > 0, np.sqrt(sigma2 / slope), np.nan))


def _pre_pulse_noise(row: NDArray, fs: float) -> float:
    """σ of the samples before ``row``'s envelope first reaches a tenth of its peak,
    then (a second pass, so that the pulse's leading edge is left out) before it first
    reaches 4σ; ``noise_sigma`` of the samples before the peak when fewer than 16
    precede the onset."""
    env = envelope(row)
    sigma = noise_sigma(row, fs)
    for level in (0.1 * env.max(), None):
        level = 4.0 * sigma if level is None else level
        onset = int(np.argmax(env >= level)) if env.max() > level else 0
        if onset < 16:
            break
        sigma = noise_sigma(row, fs, noise_window=(0.0, (onset - 1) / fs))
    return sigma


def _element_transfers(cross: NDArray, w: NDArray, g_ref: NDArray, omega: NDArray,
                       grid: NDArray) -> NDArray[np.float64]:
    """``a e^{iωδ}`` fitted to every element's transfer ``q = Y P* / |P|² / g_ref``
    (rows of ``cross`` and of the weights ``w = |P|²``, shape (n_el, nb)): δ from a
    grid search over the delays ``grid`` (s, uniform) refined by Newton steps on the
    weighted real part within one grid step (bisection where a step leaves it), a the
    weighted real part; their standard uncertainties from the scatter of the per-bin
    values about the fit (``nb/(nb − 1)`` corrected). Returns (n_el, 4): a, δ, u(a),
    u(δ)."""
    wq = cross / np.where(w > 0, w, 1.0) / g_ref * w  # w q
    with blas_threads(1):
        vals = np.real(wq @ np.exp(-1j * grid[:, None] * omega[None, :]).T)
    j = np.argmax(vals, axis=1)
    step = grid[1] - grid[0]
    lo, hi = grid[j] - step, grid[j] + step
    delay = grid[j].astype(float)
    for _ in range(40):  # maximise f(δ) = Re Σ w q e^{−iωδ}: f' = Im Σ ω w q e^{−iωδ}
        e = wq * np.exp(-1j * omega * delay[:, None])
        d1 = np.sum(omega * e.imag, axis=1)
        d2 = -np.sum(omega**2 * e.real, axis=1)
        lo, hi = np.where(d1 > 0, delay, lo), np.where(d1 > 0, hi, delay)
        newton = delay - d1 / np.where(d2 < 0, d2, -np.inf)
        inside = (d2 < 0) & (newton > lo) & (newton < hi)
        new = np.where(inside, newton, 0.5 * (lo + hi))
        done = np.all(np.abs(new - delay) <= 1e-15)
        delay = new
        if done:
            break
    sw = np.sum(w, axis=1)
    amp = np.real(np.sum(wq * np.exp(-1j * omega * delay[:, None]), axis=1)) / sw
    q = cross / np.where(w > 0, w, 1.0) / g_ref
    r = q * np.exp(-1j * omega * delay[:, None]) - amp[:, None]
    nb = omega.size
    corr = nb / max(nb - 1, 1)
    u_amp = np.sqrt(np.sum(w**2 * r.real**2, axis=1) * corr) / sw
    wo = w * omega
    u_delay = (np.sqrt(np.sum(wo**2 * r.imag**2, axis=1) * corr)
               / np.maximum(np.abs(amp), 1e-300) / np.sum(wo * omega, axis=1))
    return np.stack([amp, delay, u_amp, u_delay], axis=1)
