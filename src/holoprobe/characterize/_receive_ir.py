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
import scipy.optimize
from numpy.typing import ArrayLike, NDArray

from holoprobe.characterize._reflection import echo_train_peaks
from holoprobe.characterize._virtual_receiver import SensorLayout
from holoprobe.errors import FitError, InputError
from holoprobe.lens import lens_delays
from holoprobe.measurement import DriveSignal
from holoprobe.signal import (
    detect_onset,
    fractional_delay,
    frequency_axis,
    next_fast_length,
    noise_floor,
    resample,
    to_frequency,
    to_time,
    wiener_deconvolve,
)

__all__ = [
    "ElementSensitivity",
    "ReceiveImpulseResponse",
    "drive_amplitude_ratio",
    "element_receive_pressure",
    "element_sensitivity",
    "receive_impulse_response",
]


def _focus_and_center(lens: Any) -> tuple[float, float]:
    if hasattr(lens, "focus"):
        return float(lens.focus), float(getattr(lens, "center_y", 0.0) or 0.0)
    try:
        return float(lens), 0.0
    except (TypeError, ValueError):
        raise InputError("expected a focus in m or an object with .focus (e.g. LensFit)",
                         field="lens") from None


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
        Focus F in m (``inf``: no lens), or an object with ``.focus`` (and
        ``.center_y``, the lens centre y_L).
    sound_speed : float
        c0 in m/s.
    center_y : float, optional
        Override the lens centre y_L (m); default ``lens.center_y`` or the layout's.

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
    focus, yl = _focus_and_center(lens)
    if center_y is not None:
        yl = float(center_y)
    elif not hasattr(lens, "center_y"):
        yl = layout.center_y
    if math.isinf(focus):
        tau = np.zeros(n)
    else:
        tau = lens_delays(layout.v - yl, focus, layout.height, sound_speed)
    w = layout.weights
    out = np.empty((layout.element_count, f.size), complex)
    step = max(1, int(2**22 // max(n, 1)))
    for i in range(0, f.size, step):
        ff = f[i:i + step]
        ph = np.exp(1j * 2 * np.pi * ff[None, :] * tau[:, None])
        v = (p[:, i:i + step] * ph * w[:, None]).reshape(layout.element_count,
                                                          layout.points_per_element, -1)
        out[:, i:i + step] = v.sum(axis=1)
    wsum = w.reshape(layout.element_count, -1).sum(axis=1)
    return out / wsum[:, None]


def drive_amplitude_ratio(receive_drive: DriveSignal, transmit_drive: DriveSignal) -> float:
    """Peak drive voltage of the echo experiment over that of the scan (reference_spec
    2.9 step 2): the projected scan pressure is multiplied by it."""
    for name, d in (("receive_drive", receive_drive), ("transmit_drive", transmit_drive)):
        if not isinstance(d, DriveSignal):
            raise InputError("expected a holoprobe.measurement.DriveSignal", field=name)
    if transmit_drive.peak == 0:
        raise InputError("the transmit drive is zero", field="transmit_drive")
    return receive_drive.peak / transmit_drive.peak


@dataclass(frozen=True)
class ReceiveImpulseResponse:
    """Result of :func:`receive_impulse_response`.

    Attributes
    ----------
    ir : ndarray, shape (m,)
        Receive impulse response in ``unit``, first sample at t = 0, truncated before
        ``truncation_time``.
    sampling_rate : float
        Hz.
    unit : str
        ``"<voltage unit>/(Pa·s)"``.
    truncation_time : float
        s (``inf``: not truncated).
    frequencies : ndarray, shape (nb,)
        Hz, bins of the deconvolution.
    voltage_spectrum, pressure_spectrum, transfer_function : ndarray, complex, shape (nb,)
        Y (unit·s), P (Pa·s, scaled) and H = Y/P regularised (unit/Pa), conjugate
        convention (paper Fig. 7e).
    voltage_noise, pressure_noise : ndarray, shape (nb,)
        Noise powers per bin used in the regulariser (scaling of ``|to_frequency|²``).
    warnings : tuple of str
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
    warnings: tuple[str, ...] = ()


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
    """Band-limited pressure resampled to fs and placed on a length-n record from t_y."""
    pr = p if fs_p == fs else resample(p, fs_p, fs, n_out=math.ceil(p.size * fs / fs_p))
    if pr.size > n:
        raise InputError(f"the pressure record ({pr.size} samples at the voltage rate) is "
                         f"longer than the deconvolution length {n}", field="pressure")
    out = np.zeros(n)
    out[:pr.size] = pr
    return fractional_delay(out, t_p - t_y, fs)


def _auto_noise_window(x: NDArray, fs: float, guard: float, threshold: float,
                       ) -> tuple[float, float] | None:
    try:
        onset = detect_onset(x, fs, threshold=threshold, allow_wrap=False)
    except FitError:
        return None
    stop = onset - guard
    return (0.0, stop) if stop * fs >= 8 else None


def receive_impulse_response(
    voltage: ArrayLike, pressure: ArrayLike, sampling_rate: float, *,
    pressure_rate: float | None = None, voltage_start_time: float = 0.0,
    pressure_start_time: float = 0.0, noise_window: tuple[float, float] | None = None,
    pressure_noise_window: tuple[float, float] | None = None,
    reflection_coefficient: float = 1.0, drive_ratio: float = 1.0,
    truncate_before: float | None = None, output_rate: float = 250e6,
    voltage_unit: str = "ADCL", noise_guard: float = 1e-6, onset_threshold: float = 5.0,
    peak_fraction: float = 0.2, segment_length: int = 256, pressure_floor_db: float = 60.0,
    smooth_bins: int = 9,
) -> ReceiveImpulseResponse:
    """Receive impulse response by modified Wiener deconvolution (paper eq.
    deconvolution-receive, corrected regulariser; reference_spec 2.9 steps 2–7).

    ``H = Y/P / (1 + 1/SNR_Y + 1/SNR_P)`` (:func:`holoprobe.signal.wiener_deconvolve`)
    with Y the (tilt-aligned, averaged) echo voltage and P the (tilt-aligned, averaged)
    receive pressure × ``reflection_coefficient`` × ``drive_ratio``, both on the
    voltage's clock. The noise powers are estimated from the data: Welch spectra
    (:func:`holoprobe.signal.noise_floor`) of pre-echo segments. The IR is computed over
    the whole record, resampled to ``output_rate`` and truncated before the back-wall
    echo.

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
        Times (s, transmit clock) of the first samples; the IR's t = 0 is zero lag on
        that common clock.
    noise_window : (float, float), optional
        Signal-free interval of the voltage (s, transmit clock). Default: from the first
        sample to ``noise_guard`` before the voltage's onset
        (:func:`holoprobe.signal.detect_onset` at ``onset_threshold``).
    pressure_noise_window : (float, float), optional
        Same for the pressure. When no such segment exists (a short projected record)
        only the flat floor below is used, with a warning.
    reflection_coefficient : float
        Rp (:func:`~holoprobe.characterize.estimate_reflection_coefficient`).
    drive_ratio : float
        Receive-experiment / scan drive amplitude (:func:`drive_amplitude_ratio`).
    truncate_before : float, optional
        Keep the IR for t < this (s). Default: the echo-train period of the voltage
        (:func:`~holoprobe.characterize.echo_train_peaks`, ``peak_fraction``); no
        truncation (with a warning) when the train shows fewer than two echoes.
    output_rate : float
        Sampling rate of the returned IR in Hz.
    voltage_unit : str
        Unit of ``voltage`` (for ``unit``).
    noise_guard, onset_threshold : float
        Automatic noise windows, see above (s, σ units).
    peak_fraction : float
        See ``truncate_before``.
    segment_length : int
        Welch segment length (samples).
    pressure_floor_db : float
        Pressure noise floor (dB below its spectral peak amplitude): the least noise
        power assumed in every bin (regularises bins outside the pressure's band).

    smooth_bins : int
        Width (bins) of the moving average in the spectral-subtraction gain
        ``(1 − N_Y/⟨|Y|²⟩)₊ (1 − N_P/⟨|P|²⟩)₊`` applied after the Wiener step (0: off),
        which removes the noise-over-noise bins outside the common band.

    Returns
    -------
    ReceiveImpulseResponse
    """
    y = _trace(voltage, "voltage")
    p = _trace(pressure, "pressure")
    fs = float(sampling_rate)
    if not (np.isfinite(fs) and fs > 0):
        raise InputError(f"expected a positive sampling rate, got {sampling_rate!r}",
                         field="sampling_rate")
    fs_p = fs if pressure_rate is None else float(pressure_rate)
    if not (np.isfinite(fs_p) and fs_p > 0):
        raise InputError(f"expected a positive sampling rate, got {pressure_rate!r}",
                         field="pressure_rate")
    scale = float(reflection_coefficient) * float(drive_ratio)
    if not (np.isfinite(scale) and scale != 0):
        raise InputError("expected a finite, non-zero reflection_coefficient × drive_ratio",
                         field="reflection_coefficient")
    notes: list[str] = []
    t_y, t_p = float(voltage_start_time), float(pressure_start_time)
    n_pres = math.ceil(p.size * fs / fs_p)
    lag = abs(t_p - t_y) * fs
    n = next_fast_length(max(y.size, n_pres + math.ceil(lag) + 1))
    p_on = _on_clock(p, fs_p, t_p, fs, t_y, n) * scale
    y_pad = np.zeros(n)
    y_pad[:y.size] = y
    # noise powers from the data
    if noise_window is None:
        win = _auto_noise_window(y, fs, noise_guard, onset_threshold)
        if win is None:
            raise InputError("no pre-echo segment for the voltage noise: the echo starts "
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
    peak = float(np.max(np.abs(to_frequency(p_on))))
    npow = np.full(n // 2 + 1, (peak * 10 ** (-pressure_floor_db / 20)) ** 2)
    if pwin is not None:
        npow = np.maximum(npow, noise_floor(p_rs, pwin, sampling_rate=fs, n=n,
                                            segment_length=segment_length) * scale**2)
    else:
        notes.append(f"no pre-arrival segment in the pressure record: pressure noise floor "
                     f"set {pressure_floor_db:g} dB below its spectral peak")
    h = wiener_deconvolve(y_pad, p_on, noise_output=ny, noise_input=npow, sampling_rate=fs,
                          n_fft=n)
    if smooth_bins and smooth_bins > 0:
        # where both spectra are at their noise level the Wiener ratio is noise over noise
        # (|H| ~ √(N_Y/N_P), not small): suppress it with the spectral-subtraction gain
        # (1 − N/⟨|X|²⟩)₊ of both signals, ⟨·⟩ a moving average over smooth_bins bins
        kern = np.ones(int(smooth_bins)) / int(smooth_bins)
        gain = np.ones(n // 2 + 1)
        for spec, noise in ((to_frequency(y_pad), ny), (to_frequency(p_on), npow)):
            power = np.convolve(np.abs(spec) ** 2, kern, mode="same")
            gain *= np.clip(1 - np.broadcast_to(noise, power.shape)
                            / np.maximum(power, np.finfo(float).tiny), 0.0, 1.0)
        h = to_time(to_frequency(h) * gain, n)
    # truncation before the back-wall echo
    if truncate_before is None:
        times, _ = echo_train_peaks(y, fs, fraction=peak_fraction, count=2)
        if times.size >= 2:
            t_cut = float(times[1] - times[0])
        else:
            t_cut = float("inf")
            notes.append("no second echo found: the receive IR is not truncated")
    else:
        t_cut = float(truncate_before)
        if not t_cut > 0:
            raise InputError("expected a positive time in s", field="truncate_before")
    fo = float(output_rate)
    if not (np.isfinite(fo) and fo > 0):
        raise InputError(f"expected a positive rate, got {output_rate!r}", field="output_rate")
    h_out = resample(h, fs, fo)
    m = h_out.size // 2 if math.isinf(t_cut) else min(h_out.size, math.ceil(t_cut * fo))
    for note in notes:
        warnings.warn(note, UserWarning, stacklevel=2)
    Y = to_frequency(y_pad) / fs
    P = to_frequency(p_on) / fs
    return ReceiveImpulseResponse(
        ir=h_out[:m], sampling_rate=fo, unit=f"{voltage_unit}/(Pa·s)", truncation_time=t_cut,
        frequencies=frequency_axis(n, fs), voltage_spectrum=Y, pressure_spectrum=P,
        transfer_function=to_frequency(h) / fs, voltage_noise=np.broadcast_to(ny, Y.shape)
        .copy(), pressure_noise=np.broadcast_to(npow, Y.shape).copy(), warnings=tuple(notes))


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
    """

    amplitude: NDArray[np.float64]
    delay: NDArray[np.float64]
    band: tuple[float, float]


def element_sensitivity(rf: ArrayLike, pressure: ArrayLike, sampling_rate: float, *,
                        pressure_rate: float | None = None, rf_start_time: float = 0.0,
                        pressure_start_time: float = 0.0, used: ArrayLike | None = None,
                        band_db: float = -12.0, max_delay: float | None = None,
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
    p_on = np.stack([_on_clock(row, fs_p, pressure_start_time, fs, rf_start_time, n)
                     for row in pr])
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
    amp = np.empty(y.shape[0])
    dly = np.empty(y.shape[0])
    for e in range(y.shape[0]):
        w = np.abs(P[e, band]) ** 2
        q = Y[e, band] * np.conj(P[e, band]) / np.where(w > 0, w, 1.0) / g_ref
        def cost(d: float, q: NDArray = q, w: NDArray = w) -> float:
            return -float(np.real(np.sum(w * q * np.exp(-1j * omega * d))))

        grid = np.linspace(-0.5 * max_delay, 0.5 * max_delay, 129) * 2
        vals = np.real(np.exp(-1j * grid[:, None] * omega[None, :]) @ (w * q))
        j = int(np.argmax(vals))
        step = grid[1] - grid[0]
        sol = scipy.optimize.minimize_scalar(cost, bounds=(grid[j] - step, grid[j] + step),
                                             method="bounded", options={"xatol": 1e-13})
        dly[e] = sol.x
        amp[e] = -sol.fun / float(np.sum(w))
    return ElementSensitivity(amplitude=amp, delay=dly,
                              band=(float(f[band].min()), float(f[band].max())))
