"""The receive characterization pipeline (paper section III B, Fig. 7; reference_spec R1–R6).

element RF of the reflector echo → virtual receiver (echo arrivals, robust arrival line,
θy' = −asin(s c0), onset t0 of the tilt-aligned average, exact z0', d, x0') → reflection
coefficient Rp from the echo train (or the user's) → forward projection of the
measured, tilt-corrected scan pressure onto the sampled virtual sensor (NUFFT fast path)
→ receive lens reversal and average over each element (per-element receive pressure)
→ model-based refinement of θy' (every element's RF against its predicted pressure,
re-projected at the refined pose) → tilt alignment and average over the usable
elements → receive IR by one regularised deconvolution (× Rp, × the drive ratio
E_echo(f)/E_scan(f), noise from the data), its onset moved (not cut) to the pre-onset
margin, truncated before the back-wall echo, at the output rate → optional
per-element sensitivity.

Every step is a function of another module; this one glues them with the knobs of
:class:`~holoprobe.characterize.ReceiveConfig` (the ``receive`` section of
:class:`~holoprobe.characterize.CharacterizationConfig`).

Time axes
---------
The scan's record (sample 0 at ``scan.start_time`` after the emission) is zero-padded
so that the projected record does not wrap: by the longest geometric spread between the
scan and the virtual sensor, ``(r_far − r_near)/c0``, plus the largest receive lens
delay and ``record_guard``. The projection's ``time_origin`` is the
nearest distance between the scan plane and the virtual sensor (the perpendicular
distance of the nearest sensor point), so the projected pressure starts at
``scan.start_time + r_near/c0`` on the scan clock. The scan clock and the echo clock
are both taken as time from the emission: a trigger latency between the two
instruments ends up in the receive IR's delay.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import pickle
import time
import warnings as _warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

from holoprobe.characterize._config import CharacterizationConfig, WarningConfig
from holoprobe.characterize._elements import ElementMap, with_steering
from holoprobe.characterize._matrix import MatrixElementMap
from holoprobe.characterize._pipeline import TransmitResult, _pressure, _Timer
from holoprobe.characterize._receive import ReceiveConfig
from holoprobe.characterize._receive_ir import (
    DriveRatio,
    ElementSensitivity,
    ReceiveImpulseResponse,
    element_receive_pressure,
    element_sensitivity,
    receive_impulse_response,
)
from holoprobe.characterize._reflection import (
    ReflectionEstimate,
    echo_train_peaks,
    fitted_amplitudes,
    reflection_coefficient_from_peaks,
)
from holoprobe.characterize._source_band import (
    _LADDER,
    _MIN_BINS,
    folded_energy_outside,
    pulse_window,
)
from holoprobe.characterize._virtual_receiver import (
    SensorLayout,
    VirtualReceiver,
    aligned_average,
    echo_search_window,
    estimate_virtual_receiver,
    fit_arrival_line,
    tilt_aligned_average,
)
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import PlaneGrid, Pose, Surface
from holoprobe.measurement import EchoRecording, HydrophoneCalibration, HydrophoneScan, ProbeInfo
from holoprobe.signal import (
    SpectrumSummary,
    estimate_offset_and_noise,
    fractional_delay,
    frequency_axis,
    mad_sigma,
    next_fast_length,
    spectrum_summary,
    to_frequency,
    to_time,
)

if TYPE_CHECKING:
    from holoprobe.propagation import ProjectionPlan

# the step functions are exported by holoprobe.characterize
__all__ = ["ReceiveResult", "characterize_receive", "predictor_options", "refine_receiver_tilt",
           "sensor_grid"]



@dataclass(frozen=True)
class ReceiveResult:
    """Everything the receive characterization found (SI units, radians).

    Attributes
    ----------
    receiver : VirtualReceiver
        Pose (θy', x0', z0'), onset t0, reflector distance d, per-element arrivals,
        used elements, the tilt-aligned averaged RF.
    reflection_coefficient : float
        Rp used (estimated, given by the user, or the configured fallback).
    reflection_uncertainty : float
        Standard uncertainty of Rp (noise of the echo-train peaks; 0 when given).
    reflection : ReflectionEstimate or None
        The echo-train estimate (None when the user gave Rp).
    drive_ratio : float
        |E_echo(f)/E_scan(f)| at the pressure's spectral peak (1 when a drive is
        unknown); the pressure is scaled by the complex ratio at every frequency
        (:class:`DriveRatio`).
    impulse_response : ReceiveImpulseResponse
        h_R in ``<unit>/(Pa·s)`` at ``config.receive.output_rate``, t = 0 at zero lag
        on the common clock; the spectra of the deconvolution (paper Fig. 7e).
    ir_spectrum : SpectrumSummary
        Peak frequency and −6 dB band of h_R.
    element_x : ndarray, shape (n_el,)
        Lateral element centres (m) used for the line fit and the sensor.
    element_pressure : ndarray, shape (n_el, nt_p)
        Receive pressure per element (Pa, × Rp × E_echo/E_scan) after lens reversal and
        element averaging, sample n at ``pressure_start_time + n / pressure_rate``.
    averaged_pressure : ndarray, shape (nt_p,)
        Tilt-aligned average of ``element_pressure`` over the used elements (Pa).
    pressure_start_time, pressure_rate : float
        Time axis of the pressure records (s from the emission, Hz).
    sensor_points : int
        Number of points on the sampled virtual sensor.
    sensitivity : ElementSensitivity or None
        Per-element receive amplitude and delay (``element_sensitivity``).
    rf_unit : str
        Unit of the echo RF.
    uncertainties : dict of str to float
        Standard uncertainties by name (SI, radians).
    warnings : list of str
    timings : dict of str to float
        Seconds per step.
    config : ReceiveConfig
    source : str
        Where the echo recording came from.
    rf : ndarray, shape (n_el, nt) or None
        The element RF (a reference to the echo's array, for the report).
    extras : dict
        Diagnostics (RF noise σ, projection size, scan–sensor distances).
    """

    receiver: VirtualReceiver
    reflection_coefficient: float
    reflection_uncertainty: float
    reflection: ReflectionEstimate | None
    drive_ratio: float
    impulse_response: ReceiveImpulseResponse
    ir_spectrum: SpectrumSummary
    element_x: NDArray[np.float64]
    element_pressure: NDArray[np.float64]
    averaged_pressure: NDArray[np.float64]
    pressure_start_time: float
    pressure_rate: float
    sensor_points: int
    sensitivity: ElementSensitivity | None
    rf_unit: str
    uncertainties: dict[str, float]
    warnings: list[str]
    timings: dict[str, float]
    config: ReceiveConfig
    source: str = ""
    rf: NDArray | None = None
    extras: dict[str, Any] = field(default_factory=dict)


def _receive_config(config: CharacterizationConfig | ReceiveConfig | None) -> ReceiveConfig:
    if config is None:
        return ReceiveConfig()
    if isinstance(config, ReceiveConfig):
        return config
    if isinstance(config, CharacterizationConfig):
        return config.receive
    raise InputError("expected a CharacterizationConfig or a ReceiveConfig", field="config")


def _checked_inputs(echo: object, transmit: object, scan: object,
                    config: CharacterizationConfig | ReceiveConfig | None,
                    record_guard: float | None, guard_angle_deg: float | None
                    ) -> tuple[ReceiveConfig, CharacterizationConfig, float, float]:
    """Check the types of the inputs of :func:`characterize_receive`.

    Returns
    -------
    receive : ReceiveConfig
        The receive section.
    config : CharacterizationConfig
        ``config`` when it is one, else the transmit's (its projection knobs).
    record_guard, guard_angle_deg : float
        The arguments, or the receive section's defaults (s, degrees).
    """
    if not isinstance(echo, EchoRecording):
        raise InputError("expected a holoprobe.measurement.EchoRecording", field="echo")
    if not isinstance(transmit, TransmitResult):
        raise InputError("expected a TransmitResult from characterize_transmit",
                         field="transmit")
    if not isinstance(scan, HydrophoneScan):
        raise InputError("expected a holoprobe.measurement.HydrophoneScan", field="scan")
    rc = _receive_config(config)
    record_guard = rc.record_guard if record_guard is None else record_guard
    guard_angle_deg = rc.guard_angle_deg if guard_angle_deg is None else guard_angle_deg
    full_cfg = config if isinstance(config, CharacterizationConfig) else transmit.config
    return rc, full_cfg, record_guard, guard_angle_deg


def sensitivity_step(echo: EchoRecording, pressure: NDArray, pressure_rate: float,
                     pressure_start: float, receiver: VirtualReceiver, config: ReceiveConfig,
                     transmit: TransmitResult | None = None,
                     predict: SensorPredictor | None = None,
                     prediction_noise: bool | tuple[NDArray, NDArray] = True,
                     ) -> ElementSensitivity:
    """Step 7: per-element sensitivity (:func:`element_sensitivity`) from the echo RF
    (its channel means removed) and the predicted element pressure.

    Parameters
    ----------
    echo : EchoRecording
        The echo, RF shape (n_el, nt) at ``echo.sampling_rate``.
    pressure : ndarray, shape (n_el, n_p)
        Element receive pressure × Rp (Pa) at ``pressure_rate`` (Hz), first sample at
        ``pressure_start`` (s).
    receiver : VirtualReceiver
        The pose ``pressure`` was predicted at; its ``used`` elements enter the
        reference transfer.
    config : ReceiveConfig
        ``sensitivity_band_db``, ``steering_uncertainty``, ``distance_uncertainty``.
    transmit : TransmitResult, optional
        Its element map gives the steering the transmit fit cannot see
        (:func:`steering_prediction`).
    predict : SensorPredictor, optional
        With ``receive.distance_uncertainty`` and a receiver moved by its IR onset
        (``onset_shift`` ≠ 0: the pose refinement's sensor shift,
        :func:`refine_pose_step`): the pressure is predicted again with that move
        undone, at the onset distance of the same θy'. A receiver that was not moved
        (``receive.refine_pose`` off) costs no projection: the term is zero.
        The echo tells the receive IR's own delay from the sensor's distance only through
        the wavefront's curvature, so the sensor may sit anywhere between the two; the
        change of every gain joins its σ (full-size twin: 1.16 mm, 0.37 % rms, which
        is most of the prediction's 0.42 % rms part of the gain errors).

    prediction_noise : bool or (ndarray, ndarray)
        The predicted pressure's noise in the gains' σ (:func:`element_sensitivity`;
        the pipeline passes the projected scan noise,
        :meth:`SensorPredictor.noise_uncertainty`).

    Returns
    -------
    ElementSensitivity
        Its uncertainties include the noise of each element's own predicted pressure
        (``prediction_noise``), common to all bins of that element, and the change of
        each amplitude that the hidden steering's standard uncertainty gives (a smooth
        trend across the array that no data here tell from the gains; its σ_ε in
        ``steering_uncertainty``), and, with a ``predict`` and the transmit's sound-speed
        uncertainty u_c (``extras['sound_speed_uncertainty']``), the change of each
        amplitude when the pressure is predicted at c0 + u_c
        (:func:`sound_speed_prediction`: the beam's diffraction over the scan-to-sensor
        distance).
    """
    rf = echo.rf - echo.rf.mean(axis=1, keepdims=True)
    kw: dict[str, Any] = {"pressure_rate": pressure_rate, "rf_start_time": echo.start_time,
                          "pressure_start_time": pressure_start, "used": receiver.used,
                          "band_db": config.sensitivity_band_db}
    sens = element_sensitivity(rf, pressure, echo.sampling_rate,
                               prediction_noise=prediction_noise, **kw)
    steered = None if transmit is None else steering_prediction(
        pressure, pressure_rate, receiver, transmit.element_map,
        transmit.medium.sound_speed, config)
    changes = []
    if steered is not None:
        changes.append(element_sensitivity(rf, steered[0], echo.sampling_rate, **kw))
    if predict is not None and config.distance_uncertainty and receiver.onset_shift != 0.0:
        far, start = predict(_shift_receiver(receiver, -receiver.onset_shift, predict.focus,
                                             predict.height, predict.medium.sound_speed))
        changes.append(element_sensitivity(rf, far, echo.sampling_rate,
                                           **{**kw, "pressure_start_time": start}))
    u_c = 0.0 if transmit is None else float(transmit.extras.get("sound_speed_uncertainty", 0))
    if isinstance(predict, SensorPredictor) and u_c > 0:
        moved, start = sound_speed_prediction(predict, receiver, u_c)
        changes.append(element_sensitivity(rf, moved, echo.sampling_rate,
                                           **{**kw, "pressure_start_time": start}))
    if not changes or sens.amplitude_uncertainty is None:
        return sens
    u = sens.amplitude_uncertainty
    for other in changes:
        u = np.hypot(u, np.nan_to_num(np.abs(other.amplitude - sens.amplitude)))
    return dataclasses.replace(sens, amplitude_uncertainty=u, steering_uncertainty=(
        0.0 if steered is None else steered[1]))


def sound_speed_prediction(predict: SensorPredictor, receiver: VirtualReceiver,
                           uncertainty: float) -> tuple[NDArray, float]:
    """The element pressure predicted as if the water's c0 were ``uncertainty`` (m/s)
    faster: every length the pipeline read from times or phases re-read at c1 = c0 + u_c.

    A wrong c0 does not move the prediction's timing (distances and the propagation
    scale together) but its diffraction: the scan-to-sensor distance (from arrival
    times, ∝ c0) grows by c1/c0 while the wavenumber shrinks by c0/c1, so the beam
    reaches the sensor as from (c1/c0)² farther, laterally (scan, elements) fixed. Here
    the scan plane's distance from the source (the transmit's z0) and the sensor's z0'
    (hence d, x0') scale by c1/c0, sin θy' (−s·c0 from the arrival slope) too, and the
    lens focus (F ∝ 1/c0 from the phase curvature) by c0/c1, which keeps the lens delays
    (times). Its change of the receive gains is their sound-speed term
    (:func:`sensitivity_step`).

    Returns
    -------
    (ndarray, float)
        Pressure (n_el, record_length) and its start time (s), as ``predict(receiver)``.
    """
    c0 = predict.medium.sound_speed
    r = (c0 + uncertainty) / c0
    pose = predict.scan_grid.pose
    x, y, z = pose.origin
    medium = dataclasses.replace(predict.medium, sound_speed=c0 + uncertainty)
    moved_pose = dataclasses.replace(pose, origin=(x, y, z * r))
    other = dataclasses.replace(predict, medium=medium,
                                scan_grid=predict.scan_grid.with_pose(moved_pose),
                                focus=predict.focus / r)
    # the plan's spectra are shared (:meth:`ProjectionPlan.with_medium`: c0 + u_c > c0)
    other.__dict__["plan"] = predict.plan.with_medium(medium).with_pose(moved_pose)
    sin_theta = float(np.clip(math.sin(receiver.theta_y) * r, -1.0, 1.0))
    moved = _at_distance(dataclasses.replace(receiver, theta_y=math.asin(sin_theta)),
                         receiver.z0 * r)
    return other(moved)


STEERING_REACH = math.sqrt(7.0 / 3.0)
"""Sensor shift per d·σ_ε that :func:`steering_prediction` predicts at: the rms of
``2 − f`` over f ∈ [0, 1], f the fraction of the hidden turn the pose refinement puts
into θy' (measured: a pure 0.1° steering of a 24-element twin turned θy' by 0.085° and
the receive-gain trend by 0.0050/mm, between the 0.0038 of d·ε and the 0.0076 of 2d·ε)."""


def steering_prediction(pressure: NDArray, pressure_rate: float, receiver: VirtualReceiver,
                        element_map: ElementMap | None, sound_speed: float,
                        config: ReceiveConfig) -> tuple[NDArray, float] | None:
    """The element pressure on the sensor moved by the steering that the array's
    element delays may hide (``receive.steering_uncertainty``).

    The transmit fit puts any linear trend of the element delays (a steering by ε) into
    the scan's tilt, so the measured field sits turned by ε on the model's frame: on the
    sensor, 2d away (d: the reflector distance), by ``2d·ε`` beside where it matches the
    echo. The pose refinement turns the sensor's θy' by a fraction f of ε (it fits the
    turned wavefront: f ≈ 0.85 on a 24-element twin), which moves the sensor by ``f·d·ε``
    along; what is left, ``(2 − f)·d·ε``, makes the predicted element pressures carry the
    slope of the beam profile over it (−1 … +2 % across a 24-element P4-1 at 20 mm for
    ε = 0.09°) and the receive gains the opposite trend. Scan and echo cannot tell that
    from a smooth trend of the gains, so it is an uncertainty: this is the pressure at
    ``x0' + √(7/3)·d·σ_ε`` (σ_ε: :func:`steering_uncertainty` of the map's live delays;
    √(7/3) the rms of 2 − f for f anywhere in [0, 1]), interpolated along the array (a
    cubic spline through the element pressures aligned by the arrival slope: the field
    at the sensor is smooth over a pitch, and a shift of a fraction of a pitch costs no
    projection).

    Parameters
    ----------
    pressure : ndarray, shape (n_el, n)
        Predicted element pressure at the receiver's pose (any scale).
    pressure_rate : float
        Its rate (Hz).
    receiver : VirtualReceiver
        The pose (``distance``, ``slope``).
    element_map : ElementMap or None
        The transmit map (its pitch and the live elements' delays).
    sound_speed : float
        c0 (m/s).
    config : ReceiveConfig
        ``steering_uncertainty`` (off: None).

    Returns
    -------
    (pressure, sigma) or None
        The moved pressure (n_el, n) and σ_ε (rad); None when off, without a 1-D element
        map of ``n_el`` elements, or with σ_ε = 0.
    """
    p = np.asarray(pressure, dtype=float)
    if (not config.steering_uncertainty or not isinstance(element_map, ElementMap)
            or isinstance(element_map, MatrixElementMap) or element_map.count != p.shape[0]
            or element_map.count < 4):
        return None
    x = element_map.offsets
    _, sigma = with_steering(element_map, sound_speed)  # σ_ε of the live delays
    if not sigma > 0:
        return None
    shift, slope = STEERING_REACH * receiver.distance * sigma, receiver.slope
    aligned = fractional_delay(p, -slope * x, pressure_rate)  # circular, undone below
    moved = CubicSpline(x, aligned, axis=0)(x + shift)
    return fractional_delay(moved, slope * (x + shift), pressure_rate), sigma


def _probe(echo: EchoRecording, scan: HydrophoneScan, transmit: TransmitResult) -> ProbeInfo:
    """Element layout: the echo's (or scan's) probe with the fitted pitch and width."""
    probe = echo.probe if echo.probe is not None else scan.probe
    n_ch = echo.rf.shape[0]
    el = transmit.elements
    if probe is None:
        if el.count != n_ch:
            raise InputError(f"the echo has {n_ch} channels but no probe description, and "
                             f"the transmit fit found {el.count} element(s); expected one "
                             f"channel per element", field="rf")
        return ProbeInfo(el.count, el.pitch, min(el.width, el.pitch),
                         transmit.aperture.height, 1e6, transmit.lens_focus, "")
    if probe.element_count != n_ch:
        raise InputError(f"expected {probe.element_count} channels (one per element), got "
                         f"{n_ch}", field="rf")
    if el.count == probe.element_count and el.count > 1 and 0 < el.width <= el.pitch:
        return dataclasses.replace(probe, pitch=float(el.pitch),
                                   element_width=float(min(el.width, el.pitch)))
    return probe


def _reflection_uncertainty(estimate: ReflectionEstimate, sigma: float) -> float:
    """Standard uncertainty of Rp = √(1 − p2/p1) from independent noise on p1, p2:
    σ times the amplitudes' noise gain (:func:`echo_amplitudes`) with ``sigma`` the
    trace's noise σ per sample."""
    p = np.abs(estimate.peak_amplitudes)
    rp = estimate.coefficient
    if estimate.method != "echo_train" or p.size < 2 or rp <= 0 or not sigma > 0:
        return float("nan")
    ratio = p[1] / p[0]
    s = sigma * estimate.amplitude_noise_gain
    return float(0.5 / rp * ratio * math.hypot(s / p[0], s / p[1]))


@dataclass(frozen=True)
class _GridLayout(SensorLayout):
    extras_index: tuple = ()


def sensor_grid(receiver: VirtualReceiver, probe: ProbeInfo, height: float, *,
                spacing: float) -> tuple[PlaneGrid, _GridLayout]:
    """The virtual sensor sampled as a uniform grid of its plane, and the element layout.

    The same midpoint cells as :func:`virtual_sensor_surface` (each element split into
    ``m = ceil(pitch/spacing)`` columns per pitch, of which those inside the element
    width are kept, and ``ceil(H/spacing)`` rows), laid out as one uniform
    :class:`~holoprobe.PlaneGrid` on the sensor's pose: the element averages over its
    columns and rows are then taken wave by wave
    (:meth:`~holoprobe.propagation.ProjectionPlan.project_reduced`, as
    :func:`_sensor_pressure` does), the kerf columns with weight 0.

    Returns
    -------
    grid : PlaneGrid
        Shape (N·m, n_v), pose ``receiver.pose()``.
    layout : SensorLayout
        Element-major layout of the kept points; its ``extras_index`` (a pair of index
        arrays) picks them from the projected ``(nx, ny, nf)`` array.
    """
    n_el, pitch = probe.element_count, probe.pitch
    w = min(probe.element_width, pitch)
    if n_el > 1:
        m = max(1, math.ceil(pitch / spacing - 1e-9))
        offsets = (np.arange(m) + 0.5) / m * pitch - 0.5 * pitch
        keep = np.abs(offsets) <= 0.5 * w * (1 + 1e-9)
        if not np.any(keep):
            keep = np.abs(offsets) == np.abs(offsets).min()
        du = pitch / m
    else:
        m = max(1, math.ceil(w / spacing - 1e-9))
        offsets = (np.arange(m) + 0.5) / m * w - 0.5 * w
        keep = np.ones(m, bool)
        du = w / m
    nh = max(1, math.ceil(height / spacing - 1e-9))
    v = (np.arange(nh) + 0.5) / nh * height - 0.5 * height
    xe = probe.element_centers()
    u = (xe[:, None] + offsets[None, :]).reshape(-1)
    grid = PlaneGrid(u, v, receiver.pose())
    cols = (np.arange(n_el)[:, None] * m + np.nonzero(keep)[0][None, :])  # (n_el, m')
    ix = np.broadcast_to(cols[:, :, None], (n_el, cols.shape[1], nh)).reshape(-1)
    iy = np.broadcast_to(np.arange(nh)[None, None, :], (n_el, cols.shape[1], nh)).reshape(-1)
    layout = _GridLayout(element_count=n_el, points_per_element=int(cols.shape[1] * nh),
                         u=u[ix], v=v[iy].copy(), weights=np.full(ix.size, du * height / nh),
                         height=float(height), center_y=0.0, extras_index=(ix, iy))
    return grid, layout


def _dominant_train(times: NDArray, amps: NDArray) -> NDArray[np.intp]:
    """Indices of the echo train proper among the envelope peaks: the first echo, then
    repeatedly the largest peak after the last one kept. A plate's reverberations
    decrease (|p_{n+1}| < |p_n| after the second echo), so a smaller peak between two
    kept ones is a tail lobe of the earlier echo (e.g. the ringing of the receive IR,
    which :func:`echo_train_peaks` counts as an echo when it exceeds ``fraction`` of
    the back-wall echo ahead)."""
    keep = [0]
    while keep[-1] + 1 < amps.size:
        keep.append(keep[-1] + 1 + int(np.argmax(amps[keep[-1] + 1:])))
    return np.asarray(keep, dtype=np.intp)


def _reflection_from_train(avg: NDArray, fs: float, start_time: float, search_from: float,
                           rc: ReceiveConfig, notes: list[str]) -> ReflectionEstimate:
    """Rp from the tilt-aligned average RF (reference_spec 2.9 step 4) with the
    dominant-train selection of :func:`_dominant_train`; errors name the field."""
    times, amps = echo_train_peaks(avg, fs, start_time=start_time,
                                   search_from=search_from,
                                   fraction=rc.peak_fraction, count=rc.peak_count,
                                   min_snr=rc.peak_min_snr)
    if times.size:
        idx = _dominant_train(times, amps)
        times, amps = times[idx], amps[idx]
    need = 3 if rc.attenuating else 2
    amps, gain = fitted_amplitudes(avg, fs, times, amps, start_time=start_time, fit=need)
    try:
        if times.size < need:
            raise FitError(
                f"found {times.size} echo(es) in the averaged RF: the envelope never falls "
                f"below {rc.peak_fraction:g} of the peak between echoes; expected at least "
                f"{need} (set receive.peak_fraction lower, or give the reflection "
                f"coefficient with --reflection-coefficient)", field="receive.peak_fraction")
        rp = reflection_coefficient_from_peaks(amps, attenuating=rc.attenuating)
        method = "echo_train_attenuating" if rc.attenuating else "echo_train"
    except (InputError, FitError) as err:
        if rc.reflection_fallback is None:
            raise type(err)(f"reflection coefficient from the echo train: {err.detail}",
                            field="receive.reflection_coefficient") from None
        notes.append(f"reflection coefficient from the echo train failed ({err.detail}); "
                     f"using the fallback {rc.reflection_fallback:g}")
        rp, method = float(rc.reflection_fallback), "fallback"
    period = float(times[1] - times[0]) if times.size >= 2 else float("nan")
    return ReflectionEstimate(coefficient=float(rp), method=method, period=period,
                              peak_times=times, peak_amplitudes=amps,
                              amplitude_noise_gain=gain)


def _shift_receiver(receiver: VirtualReceiver, shift: float, focus: float, height: float,
                    sound_speed: float) -> VirtualReceiver:
    """The receiver after a further ``shift`` (s) of the receive IR: z0' is solved for the
    onset ``t0 − onset_shift − shift`` (the sensor moves ≈ c0·shift towards the source
    along the ray from it), d and x0' follow at the same θy'; ``onset`` stays the
    measured t0 of the averaged echo, ``onset_shift`` accumulates and the uncertainties
    are unchanged."""
    if shift == 0.0:
        return receiver
    total = receiver.onset_shift + shift
    z0 = VirtualReceiver.from_geometry(receiver.theta_y, receiver.onset - total, focus,
                                       height, sound_speed).z0
    return _at_distance(receiver, z0, onset_shift=total)


def _at_distance(receiver: VirtualReceiver, z0: float, **changes: Any) -> VirtualReceiver:
    """The receiver at its θy' with the sensor distance z0' (m): d = z0'/(1 + cos θy'),
    x0' = d sin θy'."""
    d = z0 / (1 + math.cos(receiver.theta_y))
    return dataclasses.replace(receiver, x0=d * math.sin(receiver.theta_y), z0=z0,
                               distance=d, **changes)


def _sensor_pressure(plan: ProjectionPlan, receiver: VirtualReceiver, probe: ProbeInfo,
                     height: float, focus: float, spacing: float,
                     progress: bool | None) -> tuple[NDArray, float]:
    """Forward projection of the scan spectrum (``plan``'s data) onto the sensor of
    ``receiver``, lens reversal and element averages: (n_el, nf) complex pressure (unit
    reflection) and the projection's time origin (the nearest scan–sensor distance, m).

    The element averages of :func:`element_receive_pressure` over the points of
    :func:`sensor_grid` (equal weights; the lens phase ``e^{+iωτ(v)}`` per row, the
    kerf columns left out) are taken wave by wave
    (:meth:`~holoprobe.propagation.ProjectionPlan.project_reduced`): the same numbers
    to the NUFFT tolerance without the sensor grid's field (n_u × n_v × nf)."""
    from holoprobe.lens import lens_delays

    sensor, layout = sensor_grid(receiver, probe, height, spacing=spacing)
    near, _ = _scan_distances(plan.source, sensor.corners())  # extremes at the corners
    n_el, (nu, nv) = layout.element_count, sensor.shape
    m = nu // n_el
    ix, _ = layout.extras_index
    kernel = np.zeros(m)
    kernel[np.unique(ix[ix < m])] = 1.0
    kernel /= kernel.sum() * nv
    c0 = plan.medium.sound_speed
    tau = (np.zeros(nv) if math.isinf(focus) else
           lens_delays(sensor.y - layout.center_y, focus, layout.height, c0))
    rows = np.exp(2j * np.pi * plan.frequencies[:, None] * tau[None, :])
    try:
        p_el = plan.project_reduced(sensor, kernel, rows, quantity="pressure",
                                    time_origin=near, progress=progress)
    except InputError as err:
        raise InputError(f"forward projection onto the virtual sensor: {err.detail}",
                         field=err.field or "receive") from None
    return p_el, near


def refine_receiver_tilt(
    receiver: VirtualReceiver, rf: NDArray, pressure: NDArray, sampling_rate: float,
    element_x: NDArray, *, pressure_rate: float, rf_start_time: float,
    pressure_start_time: float, focus: float, height: float, sound_speed: float,
    band_db: float = -12.0, min_quality: float = 10.0, min_relative_quality: float = 0.25,
    outlier_threshold: float = 4.0, loss: str = "soft_l1", step_gain: float | None = None,
    prediction_noise: bool | tuple[NDArray, NDArray] = True,
) -> tuple[VirtualReceiver, NDArray, dict[str, float]]:
    """Model-based refinement of θy' (and x0', d) without the diffraction bias of the
    arrival line (issue 10 item 2).

    The arrival line of the echo ignores the diffraction of a finite aperture (edge
    elements see a curved, later wavefront), which biases θy' most for small arrays.
    The predicted per-element pressure — the measured field forward-projected onto the
    virtual sensor at the current pose, lens reversed, element averaged — carries the
    same diffraction. The delay of every element's RF against its own predicted
    pressure (:func:`element_sensitivity`: band-limited least squares of
    ``Y_e P_e*`` relative to the element average) is therefore the geometric mismatch
    alone: a constant (the receive IR's delay, part of the convention) plus
    ``x_e (sin θy'_0 − sin θy')/c0`` for a pose off by θy' − θy'_0. A robust weighted
    line through those delays (:func:`fit_arrival_line`) gives ``sin θy' = sin θy'_0 −
    c0 b`` and, from its residual covariance, σ(θy'). x0' and d follow from θy' and z0'
    (unchanged: the onset fixes the distance convention). The pressure is delayed by
    ``b·x_e`` per element so that it stands for the refined pose (a pure delay: the
    pose changes by a few hundredths of a degree).

    Parameters
    ----------
    receiver : VirtualReceiver
        Pose of the projection (θy'_0).
    rf : ndarray, shape (n_el, nt)
        Element RF of the echo (mean removed, nothing but the echo train: a transmit
        feed-through zeroed).
    pressure : ndarray, shape (n_el, m)
        Predicted per-element pressure at that pose (Pa).
    sampling_rate, pressure_rate : float
        Hz.
    rf_start_time, pressure_start_time : float
        s, common clock.
    focus, height, sound_speed : float
        F, H (m) and c0 (m/s) for z0' ↔ onset.
    band_db : float
        Band of the delay fit (see :func:`element_sensitivity`).
    min_quality, min_relative_quality, outlier_threshold, loss :
        See :func:`fit_arrival_line`; the element quality is the echo's peak SNR.
    step_gain : float, optional
        ``−d(sin θy')/db`` of the step (m/s); default ``c0`` (a plane wavefront). The
        delay slope of a finite aperture follows ``sin θy'`` with a smaller gain (the
        sensor also moves sideways with θy' at a fixed z0', across a curved wavefront:
        about half for a point source): :func:`_refine_pose` passes the gain measured
        between its last two predictions.
    prediction_noise : bool or (ndarray, ndarray)
        The predicted pressure's noise in the element delays' σ (see
        :func:`element_sensitivity`).

    Returns
    -------
    receiver : VirtualReceiver
        With the refined θy', x0', d and their uncertainties.
    pressure : ndarray, shape (n_el, m)
        The pressure delayed to the refined pose.
    info : dict
        ``theta_y_line`` (rad, the arrival-line value), ``slope_correction`` (s/m),
        ``delay_rms`` (s, residual scatter of the element delays).
    """
    quality = np.where(receiver.used, receiver.quality, 0.0)
    sens = element_sensitivity(rf, pressure, sampling_rate,
                               pressure_rate=pressure_rate, rf_start_time=rf_start_time,
                               pressure_start_time=pressure_start_time, used=receiver.used,
                               band_db=band_db, prediction_noise=prediction_noise)
    line = fit_arrival_line(element_x, sens.delay, quality, min_quality=min_quality,
                            min_relative_quality=min_relative_quality,
                            outlier_threshold=outlier_threshold, loss=loss,
                            uncertainty=sens.delay_uncertainty)
    theta0 = receiver.theta_y
    gain = sound_speed if step_gain is None else float(step_gain)
    sin_t = math.sin(theta0) - gain * line.slope
    if not abs(sin_t) < 1:
        raise FitError(f"the pose refinement gives sin θy' = {sin_t:.3g}",
                         field="receive.refine_pose")
    theta = math.asin(sin_t)
    sig_theta = abs(gain) * line.slope_uncertainty / math.cos(theta)
    z0 = receiver.z0  # the onset (and its onset_shift) fix z0'
    cos_t = math.cos(theta)
    sig_d = math.hypot(receiver.z0_uncertainty / (1 + cos_t),
                       z0 * abs(sin_t) / (1 + cos_t) ** 2 * sig_theta)
    sig_x0 = math.hypot(receiver.z0_uncertainty * math.tan(theta / 2),
                        z0 / (2 * math.cos(theta / 2) ** 2) * sig_theta)
    shift = line.slope * np.asarray(element_x, dtype=float)
    pressure = fractional_delay(pressure, shift - np.mean(shift), pressure_rate)
    out = _at_distance(dataclasses.replace(receiver, theta_y=theta), z0,
                       theta_y_uncertainty=sig_theta, x0_uncertainty=sig_x0,
                       distance_uncertainty=sig_d)
    return out, pressure, {"theta_y_line": float(theta0), "slope_correction": line.slope,
                           "delay_rms": line.residual_rms}


def _prediction_gain(previous: tuple[float, NDArray, float], now: tuple[float, NDArray, float],
                     ex: NDArray, used: NDArray, kw: dict[str, Any]) -> float | None:
    """``−Δ sin θy' / Δb`` between two predictions (sin θy', pressure, start time): the
    slope b of the delays of one predicted pressure against the other is what the
    echo would show for that change of pose. Both carry the same scan noise and none
    of the echo's, so the gain is exact to the model (a secant through the noisy echo
    delays is not, once the steps are as small as their noise). None when the two
    poses are too close or the delays give no line."""
    (s0, p0, t0), (s1, p1, t1) = previous, now
    if abs(s1 - s0) < 1e-7:
        return None
    rate = float(kw["pressure_rate"])
    sens = element_sensitivity(p1, p0, rate, pressure_rate=rate, rf_start_time=t1,
                               pressure_start_time=t0, used=used,
                               band_db=kw.get("band_db", -12.0))
    ok = used & np.isfinite(sens.delay)
    if ok.sum() < 3:
        return None
    b = float(np.polyfit(ex[ok], sens.delay[ok], 1)[0])
    return (s0 - s1) / b if b != 0 else None


def _refine_pose(receiver: VirtualReceiver, rf: NDArray, p_time: NDArray, t_p0: float,
                 fs: float, ex: NDArray, predict: Any, iterations: int, kw: dict[str, Any],
                 tolerance: float = 0.0,
                 ) -> tuple[VirtualReceiver, NDArray, float, dict[str, float]]:
    """Iterate :func:`refine_receiver_tilt` with a new prediction (``predict(receiver)``
    → pressure, start time) at every refined pose. The first step assumes a plane
    wavefront (gain c0); the later ones the gain measured between the last two
    predictions (:func:`_prediction_gain`; 0.5–2 c0 on P4-1 twins: the plane-wave step
    only halves a 1.45° error on 16 elements at 45 mm). The last gain also scales
    σ(θy'). At most ``iterations`` predictions; fewer once a step of θy' is at most
    ``tolerance`` × its σ (the next step would be that step × the relative error of its
    gain), never before a gain was measured. ``info``: ``predictions`` made, ``last_step`` (rad)."""
    c0 = float(kw["sound_speed"])
    theta_line = receiver.theta_y
    gain, previous = c0, None
    info: dict[str, float] = {}
    for i in range(max(1, iterations)):
        if i:
            p_time, t_p0 = predict(receiver)
        now = (math.sin(receiver.theta_y), p_time, t_p0)
        if previous is not None:
            g = _prediction_gain(previous, now, ex, receiver.used, kw)
            gain = g if g is not None and 0.25 * c0 < g < 10 * c0 else gain
        previous = now
        theta = receiver.theta_y
        receiver, p_time, info = refine_receiver_tilt(receiver, rf, p_time, fs, ex,
                                                      pressure_start_time=t_p0,
                                                      step_gain=gain, **kw)
        info.update(step_gain=float(gain), predictions=float(i + 1),
                    last_step=float(receiver.theta_y - theta))
        if i and abs(receiver.theta_y - theta) <= tolerance * receiver.theta_y_uncertainty:
            break  # converged (after a measured gain, which also scales σ(θy'))
    info["theta_y_line"] = float(theta_line)
    return receiver, p_time, t_p0, info


def _scan_distances(scan_grid, points: NDArray) -> tuple[float, float]:
    """Nearest (perpendicular) and farthest distance between the scan and the points."""
    pose = scan_grid.pose
    local = (points - np.asarray(pose.origin)) @ pose.rotation
    near = float(np.min(np.abs(local[:, 2])))
    corners = np.array([[u, v, 0.0] for u in (scan_grid.x[0], scan_grid.x[-1])
                        for v in (scan_grid.y[0], scan_grid.y[-1])])
    far = float(np.max(np.linalg.norm(points[:, None, :] - pose.to_global(corners)[None],
                                      axis=-1)))
    return near, far


# --------------------------------------------------------------------------------------
# The steps, in the order the echo and the scan go through them
# --------------------------------------------------------------------------------------
def locate_receiver(rf: NDArray, sampling_rate: float, start_time: float,
                    element_x: NDArray, *, focus: float, height: float, sound_speed: float,
                    config: ReceiveConfig, notes: list[str]
                    ) -> tuple[VirtualReceiver, tuple[float, float]]:
    """Step 1: the virtual receiver from the echo arrivals (:func:`estimate_virtual_receiver`
    with the transmit's F and H, ``receive`` section) and the echo search window (s,
    after any transmit feed-through: :func:`echo_search_window` unless
    ``receive.window`` is set)."""
    window = config.window if config.window is not None else echo_search_window(
        rf, sampling_rate, start_time=start_time)  # after the transmit feed-through
    if config.window is None and window[0] > start_time:
        notes.append(f"transmit feed-through at the start of the record: the echo is "
                     f"searched from {window[0] * 1e6:.3g} µs")
    options = {**config.virtual_receiver_options(), "window": window}
    receiver = estimate_virtual_receiver(rf, sampling_rate, element_x, focus=focus,
                                         height=height, sound_speed=sound_speed,
                                         start_time=start_time, **options)
    n_used = int(np.count_nonzero(receiver.used))
    if n_used < receiver.used.size:
        left = [int(i) for i in np.flatnonzero(~receiver.used)]
        notes.append(f"{receiver.used.size - n_used} of {receiver.used.size} elements left "
                     f"out of the arrival-line fit, the averages and the noise estimate "
                     f"(dead, weak or outlying echo): channels {left} (0-based)")
    return receiver, (float(window[0]), float(window[1]))


def reflection_step(receiver: VirtualReceiver, window: tuple[float, float],
                    sampling_rate: float, start_time: float, given: float | None,
                    config: ReceiveConfig, notes: list[str]
                    ) -> tuple[float, float, ReflectionEstimate | None, float]:
    """Step 2: the reflection coefficient Rp — ``given`` (the user's), else
    ``receive.reflection_coefficient``, else from the echo train of the tilt-aligned
    average RF (:func:`echo_train_peaks`, the dominant train,
    :func:`reflection_coefficient_from_peaks`; reference_spec 2.9 step 4).

    Returns
    -------
    rp, u_rp : float
        Rp and its standard uncertainty (0 when given).
    reflection : ReflectionEstimate or None
        The echo-train estimate (None when given).
    sigma_rf : float
        Noise σ of the averaged RF before the echo (MAD; NaN when < 8 samples).
    """
    fs, rc = sampling_rate, config
    avg = receiver.averaged_rf
    i_on = int((receiver.onset - receiver.start_time) * fs - rc.noise_guard * fs)
    i_lo = max(0, int((window[0] - start_time) * fs))
    pre = avg[i_lo:max(i_on, i_lo)]
    sigma_rf = float(mad_sigma(pre)) if pre.size >= 8 else float("nan")
    user_rp = given if given is not None else rc.reflection_coefficient
    if user_rp is not None:
        rp = float(user_rp)
        if not (math.isfinite(rp) and 0 < abs(rp) <= 1):
            raise InputError(f"expected 0 < |Rp| ≤ 1, got {user_rp!r}",
                             field="reflection_coefficient")
        return rp, 0.0, None, sigma_rf
    reflection = _reflection_from_train(avg, fs, receiver.start_time, window[0], rc, notes)
    return (reflection.coefficient, _reflection_uncertainty(reflection, sigma_rf), reflection,
            sigma_rf)


@dataclass(frozen=True)
class SensorProjection:
    """The scan spectrum prepared for the forward projection onto the virtual sensor
    (step 3, :func:`scan_for_sensor`).

    Attributes
    ----------
    spectrum : ndarray, complex128, shape (nx, ny, nb)
        Scan pressure spectrum (Pa·s) of the zero-padded record in the transmit band.
    frequencies : ndarray, shape (nb,)
        Its frequencies (Hz).
    bins : ndarray of int, shape (nb,)
        Their indices in the padded record's one-sided axis.
    record_length : int
        Samples of the padded record (at the scan's rate).
    spacing : float
        Sampling step of the virtual sensor (m).
    distances : (float, float)
        Nearest and farthest scan–sensor distance (m).
    sensor_points : int
        Points kept on the sampled sensor.
    noise_sigma : float
        Noise σ per sample of the scan pressure (Pa; :func:`scan_noise_sigma`), 0 when
        unknown.
    """

    spectrum: NDArray[np.complex128]
    frequencies: NDArray[np.float64]
    bins: NDArray[np.intp]
    record_length: int
    spacing: float
    distances: tuple[float, float]
    sensor_points: int
    noise_sigma: float = 0.0

    @cached_property
    def strongest(self) -> tuple[int, int, float]:
        """The grid indices (ix, iy) of the scan point of the most energy in the band and
        the energy centroid of its band-limited record (samples of the padded record from
        its first sample): where the pulse comes from, whatever the scan's pose (computed
        once for every predictor of this projection)."""
        n_rec = self.record_length
        re, im = self.spectrum.real, self.spectrum.imag  # views: no complex copy
        energy = np.einsum("xyf,xyf->xy", re, re) + np.einsum("xyf,xyf->xy", im, im)
        ix, iy = np.unravel_index(int(np.argmax(energy)), energy.shape)
        full = np.zeros(n_rec // 2 + 1, complex)
        full[self.bins] = self.spectrum[ix, iy]
        e = to_time(full, n_rec) ** 2
        return int(ix), int(iy), float(np.sum(np.arange(n_rec) * e) / np.sum(e))


def scan_for_sensor(scan: HydrophoneScan, transmit: TransmitResult, receiver: VirtualReceiver,
                    probe: ProbeInfo, *, calibration: HydrophoneCalibration | None,
                    record_guard: float, config: CharacterizationConfig,
                    receive: ReceiveConfig, notes: list[str]) -> SensorProjection:
    """Step 3: the calibrated scan pressure, zero-padded in time (geometric spread
    between the scan and the sensor + the largest receive lens delay + ``record_guard``,
    see the module notes), transformed and cut to the transmit's band; the sensor
    sampled at ≤ λ_min / ``receive.points_per_wavelength``. ``config`` supplies the
    hydrophone deconvolution of a voltage scan (as the transmit step)."""
    from holoprobe.lens import lens_delays

    rc, c0 = receive, transmit.medium.sound_speed
    height, focus = transmit.aperture.height, transmit.lens_focus
    f_lo, f_hi = transmit.extras.get("band", (transmit.frequencies[0], transmit.frequencies[-1]))
    spacing = c0 / f_hi / rc.points_per_wavelength
    sensor, layout = sensor_grid(receiver, probe, height, spacing=spacing)
    near, far = _scan_distances(transmit.scan_grid, sensor.corners())
    tau_max = 0.0 if math.isinf(focus) else float(np.max(
        lens_delays(layout.v, focus, height, c0)))
    fs_s = scan.sampling_rate
    extra = (far - near) / c0 + tau_max + float(record_guard)
    step = max(_decimations(rc))  # every decimation's bins are bins of the record
    n_rec = step * next_fast_length(-(-(scan.n_samples + math.ceil(extra * fs_s)) // step))
    freqs = frequency_axis(n_rec, fs_s)
    bins = np.nonzero((freqs >= f_lo * (1 - 1e-12)) & (freqs <= f_hi * (1 + 1e-12))
                      & (freqs > 0))[0]
    if bins.size == 0:
        raise InputError(f"no frequency bin of the padded scan record in the transmit band "
                         f"{f_lo:g}–{f_hi:g} Hz", field="transmit")
    pressure = _pressure(scan, calibration, notes, config)
    return SensorProjection(_band_of(pressure, n_rec, bins, fs_s), freqs[bins], bins,
                            int(n_rec), float(spacing), (near, far), int(layout.u.size),
                            scan_noise_sigma(pressure))


def scan_noise_sigma(pressure: NDArray, max_records: int = 2048) -> float:
    """Noise σ per sample (Pa) of scan records (nx, ny, nt): the median over at most
    ``max_records`` records spread over the scan of the σ of each record's quiet
    samples (:func:`~holoprobe.signal.estimate_offset_and_noise`)."""
    flat = np.asarray(pressure).reshape(-1, np.shape(pressure)[-1])
    step = max(1, flat.shape[0] // int(max_records))
    _, sigma, _, _ = estimate_offset_and_noise(flat[::step])
    return float(np.median(sigma))


def band_spectrum(scan: HydrophoneScan, n_rec: int, bins: NDArray, *,
                  calibration: HydrophoneCalibration | None, config: CharacterizationConfig,
                  notes: list[str]) -> NDArray[np.complex128]:
    """The calibrated scan pressure's spectrum (Pa·s) of its record zero-padded to
    ``n_rec`` samples, at the one-sided ``bins`` only, shape (nx, ny, nb); computed a
    few scan rows at a time (never the whole padded spectrum: ≈ 0.4 GB for a full-size
    scan). ``config`` supplies the hydrophone deconvolution of a voltage scan."""
    return _band_of(_pressure(scan, calibration, notes, config), n_rec, bins,
                    scan.sampling_rate)


def _band_of(pressure: NDArray, n_rec: int, bins: NDArray, sampling_rate: float
             ) -> NDArray[np.complex128]:
    """:func:`band_spectrum` of calibrated pressure records (nx, ny, nt), a few rows
    (≈ 2^20 padded samples) at a time: blocks that stay in the cache and in the
    allocator's reused memory (2^25-sample blocks, 256 MB, cost 2.7× the CPU on a
    full-size scan, mostly zeroing fresh pages)."""
    spec_band = np.empty((*pressure.shape[:2], bins.size), np.complex128)
    rows = max(1, int(2**20 // max(1, pressure.shape[1] * n_rec)))
    for i in range(0, pressure.shape[0], rows):
        band = to_frequency(pressure[i:i + rows], n=n_rec)[:, :, bins]
        spec_band[i:i + rows] = np.asarray(band, dtype=np.complex128) / sampling_rate
    return spec_band


def drive_ratio(echo: EchoRecording, scan: HydrophoneScan, frequencies: NDArray,
                notes: list[str]) -> NDArray[np.complex128]:
    """E_echo(f)/E_scan(f) (:class:`DriveRatio`): the echo experiment's incident field is
    the scan's × this ratio; 1 (with a note) when either drive is unknown."""
    if echo.drive is not None and scan.drive is not None:
        return DriveRatio(echo.drive, scan.drive)(frequencies)
    notes.append("the drive of the echo experiment or of the scan is unknown: drive "
                 "ratio taken as 1")
    return np.ones(frequencies.size, complex)


@dataclass(frozen=True)
class SensorPredictor:
    """Step 4: the per-element incident pressure on the sensor of a receiver pose.

    Calling it with a :class:`VirtualReceiver` forward-projects the scan spectrum
    (NUFFT, through one :class:`~holoprobe.propagation.ProjectionPlan` built at the
    first call: the padded angular spectrum of the scan is computed once and reused by
    every pose of the θy' refinement while the padding rule gives the same size, so
    each call gives the numbers :func:`holoprobe.propagation.project` would), reverses
    the receive lens, averages each element and applies the drive ratio; it returns the
    pressure (Pa, shape (n_el, record_length), unit reflection) and the time of its first
    sample (s, scan clock). All the spectra would be 16 bytes × Σ_f (2k/Δκx)(2k/Δκy)
    (≈ 0.7 GB for a full-size P4-1 scan); ``max_cache_bytes`` in ``options``
    (``receive.plan_cache_mb``) keeps the lowest frequencies' within that budget for the
    predictor's lifetime and transforms the others again at each call.

    ``options`` are :class:`~holoprobe.propagation.ProjectionPlan` keywords (``eps``,
    ``guard_angle``, ``single_precision``, ``max_cache_bytes``, …) and ``progress`` (a
    progress bar).
    """

    projection: SensorProjection
    scan_grid: PlaneGrid
    medium: Any
    probe: ProbeInfo
    height: float
    focus: float
    ratio: NDArray[np.complex128]
    sampling_rate: float
    start_time: float
    options: dict[str, Any]
    decimation: int = 1
    taper_band: float = 0.0

    def guard_for(self, receiver: VirtualReceiver | Surface) -> float:
        """The guard angle (rad) the projection pads with for ``receiver``: the one of
        :func:`taper_guard` for its sensor with ``taper_band`` (0: the configured
        ``options['guard_angle']``). Computed for each pose from the configured guard:
        a sensor moved closer to the scan (the pose refinement's shift, the distance
        term's prediction) sees steeper directions and needs more padding."""
        return taper_guard(self, receiver, self.taper_band)

    @cached_property
    def selected(self) -> NDArray[np.bool_]:
        """Which bins of ``projection`` are projected: every ``decimation``-th bin of the
        padded record (all bins when 1)."""
        return self.projection.bins % self.decimation == 0

    @property
    def bins_info(self) -> dict[str, int]:
        """``projection_bins`` (bins projected) and ``band_decimation`` (D)."""
        return {"projection_bins": int(np.count_nonzero(self.selected)),
                "band_decimation": int(self.decimation)}

    @cached_property
    def plan(self) -> ProjectionPlan:
        """The projection plan of the scan spectrum (built once, on first use)."""
        from holoprobe.propagation import ProjectionPlan

        sp, sel = self.projection, self.selected
        kw = {k: v for k, v in self.options.items() if k != "progress"}
        spectrum = sp.spectrum if self.decimation == 1 else sp.spectrum[..., sel]
        try:
            return ProjectionPlan(spectrum, self.scan_grid, sp.frequencies[sel], self.medium,
                                  allow_undersampled=True, exact_padding=True, **kw)
        except InputError as err:
            raise InputError(f"forward projection onto the virtual sensor: {err.detail}",
                             field=err.field or "receive") from None

    def __call__(self, receiver: VirtualReceiver) -> tuple[NDArray, float]:
        return self._in_time(*self.band_pressure(receiver), receiver.pose().origin)

    def band_pressure(self, receiver: VirtualReceiver) -> tuple[NDArray, float]:
        """The element pressure on the projected bins (``selected``; unit reflection, no
        drive ratio), shape (n_el, nb), and the projection's time origin (m); padded
        with the guard angle :meth:`guard_for` ``receiver``."""
        self.plan.guard_angle = self.guard_for(receiver)
        return _sensor_pressure(self.plan, receiver, self.probe, self.height, self.focus,
                                self.projection.spacing, self.options.get("progress"))

    def noise_uncertainty(self, receiver: VirtualReceiver, pressure: NDArray,
                          seed: int = 0) -> tuple[NDArray, NDArray] | None:
        """What the scan's noise, projected with the field, gives each element's
        relative amplitude and delay (:func:`element_sensitivity`): standard
        uncertainties (relative; s), shape (n_el,) each; None when the scan's noise is
        unknown (``projection.noise_sigma`` 0). ``receiver`` and its predicted
        ``pressure``, (n_el, record_length); the answer is kept for the same
        ``receiver``, ``pressure`` and ``seed`` (another pose or pressure draws again).

        One draw of the scan's white noise (σ per sample ``projection.noise_sigma``)
        as stationary over the padded record (its bins independent, E|X|² = n σ²: the
        noise reaching the sensor with the pulse comes from scan samples that hold the
        pulse, i.e. at the full level), projected like the field (NUFFT tolerance
        ``NOISE_EPS``): N(f) per element and bin. To first order a pressure P + N moves
        an element's transfer relative to the used elements' (what
        :func:`element_sensitivity` fits) by δ = R − N/P per bin, R = Σ N P*/Σ |P|²
        over the used elements (the noise at the sensor is correlated over several
        elements: its common part cancels), so its amplitude by Re Σ |P|² δ/Σ |P|² and
        its delay by Σ ω |P|² Im δ/Σ ω² |P|²; with independent bins their variances are
        ½ Σ |P|⁴ |δ|²/(Σ |P|²)² and ½ Σ ω² |P|⁴ |δ|²/(Σ ω² |P|²)², the draw standing for
        the expectation (the sums run over the bins: one draw suffices). The elements'
        pre-pulse samples (:func:`prediction_uncertainty`) measure the projection's
        images and ringing instead."""
        kept = self.__dict__.setdefault("_noise", {})
        key = hashlib.blake2b(pickle.dumps((receiver, np.asarray(pressure), seed),
                                           protocol=5)).digest()
        if key in kept:
            return cast("tuple[NDArray, NDArray] | None", kept[key])
        sp, sel = self.projection, self.selected
        out = None
        if sp.noise_sigma > 0:
            rng = np.random.default_rng(seed)
            scale = sp.noise_sigma * math.sqrt(sp.record_length / 2) / self.sampling_rate
            shape = (*sp.spectrum.shape[:2], int(np.count_nonzero(sel)))
            noise = np.empty(shape, np.complex128)  # scale·(x + iy): no full-size temporaries
            noise.real = rng.standard_normal(shape)
            noise.real *= scale
            noise.imag = rng.standard_normal(shape)
            noise.imag *= scale
            draw = dataclasses.replace(
                self, decimation=1, ratio=self.ratio[sel], projection=dataclasses.replace(
                    sp, spectrum=noise, frequencies=sp.frequencies[sel], bins=sp.bins[sel]),
                options=noise_options(self.options))
            n_el, _ = draw.band_pressure(receiver)
            n_el = n_el * self.ratio[sel] * self.sampling_rate  # as to_frequency(pressure)
            p_el = to_frequency(np.asarray(pressure, float), n=sp.record_length)[:, sp.bins[sel]]
            w = np.abs(p_el) ** 2
            used = np.asarray(receiver.used, bool)
            used = used if used.shape == (w.shape[0],) else np.ones(w.shape[0], bool)
            w_ref = np.sum(w[used], axis=0)
            with np.errstate(divide="ignore", invalid="ignore"):
                ref = np.where(w_ref > 0, np.sum((n_el * np.conj(p_el))[used], axis=0)
                               / np.where(w_ref > 0, w_ref, 1.0), 0.0)
                change = w * ref[None, :] - n_el * np.conj(p_el)  # δq/q·|P|² per bin
                w2 = w * (2 * np.pi * sp.frequencies[sel]) ** 2
                omega = 2 * np.pi * sp.frequencies[sel]
                out = (np.sqrt(0.5 * np.sum(np.abs(change) ** 2, axis=1)) / np.sum(w, axis=1),
                       np.sqrt(0.5 * np.sum(np.abs(omega * change) ** 2, axis=1))
                       / np.sum(w2, axis=1))
        kept[key] = out
        return out

    def on_surface(self, sensor: Surface, layout: SensorLayout) -> tuple[NDArray, float]:
        """The same for any sampled sensor (e.g. the mirrored faces of a curved array,
        :func:`~holoprobe.characterize.mirrored_faces`): forward projection onto the
        points of ``sensor`` (type-3 NUFFT), receive lens reversal and element averages
        by ``layout`` (:func:`element_receive_pressure`), drive ratio; returns the
        pressure (Pa, shape (n_el, record_length), unit reflection) and the time of its
        first sample (s, scan clock)."""
        return self._in_time(*self.surface_band_pressure(sensor, layout))

    def surface_band_pressure(self, sensor: Surface, layout: SensorLayout
                              ) -> tuple[NDArray, float, NDArray]:
        """:meth:`on_surface` on the projected bins (``selected``; unit reflection, no
        drive ratio): element pressure (n_el, nb), the projection's time origin (m) and
        the sensor's centre (m, source frame: where a decimated record is put back)."""
        near, _ = _scan_distances(self.scan_grid, sensor.points)
        self.plan.guard_angle = self.guard_for(sensor)
        try:
            p = self.plan.project(sensor, quantity="pressure", time_origin=near,
                                  progress=self.options.get("progress"))
        except InputError as err:
            raise InputError(f"forward projection onto the virtual sensor: {err.detail}",
                             field=err.field or "receive") from None
        p_el = element_receive_pressure(p, layout, self.plan.frequencies, self.focus,
                                        sound_speed=self.medium.sound_speed)
        return p_el, near, np.mean(sensor.points, axis=0)

    def with_scan_pose(self, pose: Pose) -> SensorPredictor:
        """The same predictor with the scan plane at ``pose`` (source frame); the plan's
        spectra are shared (:meth:`ProjectionPlan.with_pose`)."""
        other = dataclasses.replace(self, scan_grid=self.scan_grid.with_pose(pose))
        other.__dict__["plan"] = self.plan.with_pose(pose)  # the cached_property's slot
        return other

    def _in_time(self, p_el: NDArray, dist: float, centre: ArrayLike | None = None
                 ) -> tuple[NDArray, float]:
        """(n_el, nb) band pressure × drive ratio → time records of the padded record's
        length and their start (s). Decimated (D > 1): the records of the D times shorter
        record, i.e. the prediction folded with that period, put back where the pulse
        arrives (:meth:`_unfold`; ``centre``: the sensor's centre, m, source frame)."""
        sp, n_rec, d = self.projection, self.projection.record_length, self.decimation
        start = self.start_time + dist / self.medium.sound_speed
        short = np.zeros((p_el.shape[0], n_rec // d // 2 + 1), complex)
        short[:, sp.bins[self.selected] // d] = p_el * self.ratio[None, self.selected]
        records = to_time(short, n_rec // d, axis=-1) * self.sampling_rate
        if d == 1:
            return records, start
        if centre is None:
            raise InputError("a decimated prediction needs the sensor's centre",
                             field="receive.band_decimation")
        return self._unfold(records, dist, np.asarray(centre, float)), start

    @cached_property
    def scan_arrival(self) -> tuple[NDArray, float]:
        """The scan point of the most energy (m, source frame) and the energy centroid
        of its band-limited record (samples of the padded record from its first sample)."""
        ix, iy, centroid = self.projection.strongest
        grid = self.scan_grid
        point = grid.pose.to_global(np.array([[grid.x[ix], grid.y[iy], 0.0]]))[0]
        return point, centroid

    def _unfold(self, records: NDArray, dist: float, centre: NDArray) -> NDArray:
        """Folded (n_el, L) records → (n_el, D·L), the L samples about the pulse where
        it arrives and zeros elsewhere. The pulse's place in the folded record is its
        best half-record window (:func:`pulse_window`); which of the D periods it falls in
        is the nearest to the arrival along the straight line from the scan's strongest
        point to the sensor's centre (its record's energy centroid + the path beyond the
        projection's time origin ``dist``): a guess good to half a period (L/2 samples:
        ≥ 2.7 µs at 25 MHz for 1080 samples and D = 4)."""
        n_el, short = records.shape
        n_rec = short * self.decimation
        first, _ = pulse_window(np.sum(records**2, axis=0))
        middle = first + short // 4
        point, t_scan = self.scan_arrival
        guess = t_scan + (float(np.linalg.norm(centre - point)) - dist) \
            / self.medium.sound_speed * self.sampling_rate
        lap = round((guess - middle) / short)
        idx = middle + lap * short - short // 2 + np.arange(short)
        out = np.zeros((n_el, n_rec))
        out[:, idx % n_rec] = records[:, idx % short]
        return out


NOISE_EPS = 1e-2  # NUFFT tolerance of the noise draws' projections


def noise_options(options: dict) -> dict:
    """A predictor's options for projecting noise draws: the NUFFT tolerance no finer
    than :data:`NOISE_EPS` (a σ from a few draws is good to ~1/√(2 draws) only)."""
    return {**options, "eps": max(NOISE_EPS, options.get("eps", 0.0))}


def taper_guard(predict: SensorPredictor, receiver: VirtualReceiver | Surface,
                band: float) -> float:
    """The guard angle (rad) whose padding leaves the image taper ``band`` in sin θ
    beyond the steepest direction s_in from the scan to the sensor; ``options``'
    guard angle when the predictor has no image taper, ``band`` is 0 or that is smaller
    (``receive.taper_band``: on the full-size P4-1 twin, s_in = 0.416, the predicted
    element pressure moves by 1.1e-3 / 1.8e-4 / 3.4e-5 / 5.5e-6 of its peak for bands
    of 0.067 / 0.184 / 0.278 / 0.355, guards 15° / 20° / 25° / 30°, against a 40° guard:
    benchmarks/RESULTS.md, issue 14).

    The padding rule keeps a gap g ≥ 2 w tan(guard) between the data and their nearest
    periodic image (w: the farthest sensor point's distance from the scan plane), so the
    images reach the sensor along sin θ ≥ 2 tan(guard)/√(4 tan²(guard) + 1)
    (:func:`~holoprobe.propagation.image_taper_range`): the taper fades the plane waves
    out between s_in and that, and the sensor sees no image. A plate far from a small
    scan (small s_in) needs less padding than the configured guard's: 20.4° instead of
    30° on the full-size P4-1 (2.3× fewer plane waves). ``receiver`` may also be the
    sampled sensor itself (a :class:`~holoprobe.geometry.Surface`: the mirrored faces
    of a convex or matrix array)."""
    from holoprobe.propagation import image_taper_range

    configured = float(predict.options["guard_angle"])
    if not predict.options.get("image_taper") or not band > 0:
        return configured
    sensor = receiver if isinstance(receiver, Surface) else sensor_grid(
        receiver, predict.probe, predict.height, spacing=predict.projection.spacing)[0]
    taper = image_taper_range(predict.scan_grid, sensor, (2**24, 2**24))  # no image: s_in
    if taper is None:
        return configured
    s = min(taper[0] + band, 0.99)
    return min(configured, math.atan(s / (2 * math.sqrt(1 - s * s))))


def _decimations(config: ReceiveConfig) -> tuple[int, ...]:
    """The decimations ``receive.band_decimation`` tries, largest first."""
    fixed = int(config.band_decimation)
    return (fixed,) if fixed else _LADDER


BandPressure = Callable[[SensorPredictor], tuple[NDArray, float, NDArray]]
"""A sensor's band pressure by a predictor: (n_el, nb) element pressure on its
``selected`` bins, the projection's time origin (m) and the sensor's centre (m)."""


def decimated_prediction(predict: SensorPredictor, receiver: VirtualReceiver | Surface,
                         config: ReceiveConfig, band: BandPressure | None = None
                         ) -> tuple[SensorPredictor, tuple[NDArray, float]]:
    """The predictor on the fewest bins that hold the predicted pulse, and its first
    prediction (``receive.band_decimation``, ``band_alias_tolerance``).

    Every D-th bin of the padded record are the bins of a record D times shorter: the
    prediction folded with that period, exact once put back where the pulse arrives
    when the pulse fits the shorter record (the element pressures last a few µs; the
    record must hold the scan's spread of arrivals: 1080 samples at 25 MHz for a
    full-size P4-1 scan, of which the pulse holds 99.99 % of its energy in 95). With
    ``band_decimation`` = 0, D is the largest of 8, 4, 2, 1 that keeps at least 16
    bins and whose prediction keeps its energy within half the shorter record
    (:func:`folded_energy_outside`, as the hologram's band); the pose refinement's
    and the gains' predictions use the same D. D = 8, seldom enough (full size: ε
    1.2e-3), is not projected: its bins are among those of D = 4 (every bin projects
    alone), so it is checked on the D = 4 projection (full size: one 29-bin projection,
    0.4 s CPU, saved). The predictor pads each pose for the
    image taper's band ``receive.taper_band`` (:meth:`SensorPredictor.guard_for`).
    A curved or 2-D array's sensor (convex, matrix: ``receiver`` its sampled mirrored
    faces) gives ``band``, its pressure by a predictor (e.g. from
    :meth:`SensorPredictor.surface_band_pressure`); default: the flat array's
    :meth:`SensorPredictor.band_pressure` of ``receiver``.

    Returns
    -------
    predictor : SensorPredictor
        With its ``decimation``.
    prediction : (ndarray, float)
        ``predictor(receiver)``: pressure (n_el, record_length), start time (s).
    """
    sp = predict.projection
    predict = dataclasses.replace(predict, taper_band=config.taper_band)
    ladder = _decimations(config)
    rungs = [d for d in ladder if not (sp.record_length % d or (
        len(ladder) > 1 and d > 1 and np.count_nonzero(sp.bins % d == 0) < _MIN_BINS))]
    checked = 0  # rungs[:checked] were refused
    first = 1 if len(rungs) > 1 and rungs[0] == _LADDER[0] else 0  # D = 8: on 4's bins
    for d in rungs[first:]:
        trial = dataclasses.replace(predict, decimation=d)
        if band is None:
            assert isinstance(receiver, VirtualReceiver)
            p_el, dist = trial.band_pressure(receiver)
            centre = np.asarray(receiver.pose().origin, float)
        else:
            p_el, dist, centre = band(trial)
        for coarse in rungs[checked:rungs.index(d) + 1]:
            checked += 1
            keep = sp.bins[trial.selected] % coarse == 0  # its bins among the trial's
            chosen = trial if coarse == d else dataclasses.replace(predict, decimation=coarse)
            if len(ladder) == 1 or coarse == 1 or folded_energy_outside(
                    p_el[:, keep] * chosen.ratio[chosen.selected], sp.bins[chosen.selected]
                    // coarse, sp.record_length // coarse) <= config.band_alias_tolerance:
                return chosen, chosen._in_time(p_el[:, keep], dist, centre)
    raise InputError(f"the padded scan record ({sp.record_length} samples) has no bins for "
                     f"receive.band_decimation = {ladder[0]}", field="receive.band_decimation")


def predictor_options(receive: ReceiveConfig, config: CharacterizationConfig,
                      guard_angle_deg: float | None = None, progress: bool | None = None
                      ) -> dict[str, Any]:
    """The :class:`SensorPredictor` options: the NUFFT tolerance ``receive.eps`` (else
    ``config.backprojection.eps``), the back-projection's precision, the guard angle
    (degrees; default ``receive.guard_angle_deg``), ``receive.image_taper``, the
    spectra kept (``receive.plan_cache_mb``) and the progress bar."""
    bp = config.backprojection
    guard = receive.guard_angle_deg if guard_angle_deg is None else guard_angle_deg
    return {"eps": bp.eps if receive.eps is None else receive.eps,
            "guard_angle": math.radians(guard), "image_taper": receive.image_taper,
            "single_precision": bp.single_precision, "progress": progress,
            "max_cache_bytes": int(receive.plan_cache_mb * 2**20)}


def _echo_rf(echo: EchoRecording, window: tuple[float, float]) -> NDArray:
    """The element RF with each channel's mean removed and the samples before the echo
    search window (a transmit feed-through) zeroed: nothing but the echo train."""
    rf = echo.rf - echo.rf.mean(axis=1, keepdims=True)
    rf[:, :max(0, int((window[0] - echo.start_time) * echo.sampling_rate))] = 0.0
    return rf


def refine_pose_step(receiver: VirtualReceiver, echo: EchoRecording, window: tuple[float, float],
                     pressure: NDArray, pressure_start: float, element_x: NDArray,
                     predict: SensorPredictor, config: ReceiveConfig,
                     reflection: ReflectionEstimate | None = None,
                     transmit: TransmitResult | None = None,
                     ) -> tuple[VirtualReceiver, NDArray, float, dict[str, float] | None]:
    """Step 4b: with ``receive.refine_pose``, the model-based θy' (:func:`_refine_pose`,
    ``pose_iterations`` predictions) against the echo RF with the feed-through zeroed;
    returns the receiver, the pressure and its start time at the refined pose and the
    refinement's diagnostics (None when off).

    The predictions are made where the sensor really is: z0' from the echo's onset t0
    lies ``c0·τ`` short of it, τ being the time from the start of the receive IR to the
    threshold crossing of the averaged echo (SNR dependent: 0.1–4 µs). An off-axis
    sensor (x0' ≠ 0) predicted at the wrong distance sees the wavefront turned by about
    ``x0' Δz/z0'²`` (0.02° per mm on a 32-element twin at 76 mm), which the refinement
    took for θy'. So the sensor is first moved by the onset of the receive IR
    deconvolved with the first prediction (:func:`receive_ir_step`, margin 0) and
    predicted again there; the receiver's ``onset_shift`` (and ``sensor_shift`` in the
    diagnostics) is that delay (s; the receive IR's own shift adds to it).

    With the ``transmit`` result, σ(θy') (and x0', d) also holds the scan pose's
    uncertainty (:func:`scan_pose_tilt`; ``scan_pose_tilt`` in the diagnostics, rad)."""
    rc = config
    if not rc.refine_pose:
        return receiver, pressure, pressure_start, None
    fs = echo.sampling_rate
    rf_echo = _echo_rf(echo, window)
    ir = receive_ir_step(receiver, tilt_aligned_average(pressure, predict.sampling_rate,
                                                        element_x, receiver.slope,
                                                        used=receiver.used),
                         echo, window, pressure_rate=predict.sampling_rate,
                         pressure_start=pressure_start, rp=1.0, reflection=reflection,
                         config=dataclasses.replace(rc, ir_onset_margin=0.0), notes=[],
                         element_x=element_x)
    receiver = _shift_receiver(receiver, ir.shift, predict.focus, predict.height,
                               predict.medium.sound_speed)
    if ir.shift != 0.0:
        pressure, pressure_start = predict(receiver)
    kw = {"pressure_rate": predict.sampling_rate, "rf_start_time": echo.start_time,
          "focus": predict.focus, "height": predict.height,
          "sound_speed": predict.medium.sound_speed, "band_db": rc.sensitivity_band_db,
          "min_quality": rc.min_quality, "min_relative_quality": rc.min_relative_quality,
          "outlier_threshold": rc.outlier_threshold, "loss": rc.loss,
          "prediction_noise": _noise_of(predict, receiver, pressure)}
    receiver, pressure, pressure_start, info = _refine_pose(
        receiver, rf_echo, pressure, pressure_start, fs, element_x, predict,
        int(rc.pose_iterations), kw, rc.pose_tolerance)
    info["sensor_shift"] = float(ir.shift)
    if transmit is not None and isinstance(predict, SensorPredictor):
        term = scan_pose_tilt(predict, receiver, (pressure, pressure_start), transmit,
                              element_x, info["step_gain"], rc.sensitivity_band_db)
        receiver, info["scan_pose_tilt"] = with_tilt_term(receiver, term), term
    return receiver, pressure, pressure_start, info


def _noise_of(predict: Any, receiver: VirtualReceiver, pressure: NDArray
              ) -> bool | tuple[NDArray, NDArray]:
    """The predicted pressure's noise for :func:`element_sensitivity`: the projected
    scan noise of a :class:`SensorPredictor` (:meth:`~SensorPredictor.noise_uncertainty`)
    when the scan's noise is known, else True (the pre-pulse samples)."""
    noise = predict.noise_uncertainty(receiver, pressure) if isinstance(
        predict, SensorPredictor) else None
    return True if noise is None else noise


def scan_pose_tilt(predict: SensorPredictor, receiver: VirtualReceiver,
                   prediction: tuple[NDArray, float], transmit: TransmitResult,
                   element_x: NDArray, step_gain: float, band_db: float = -12.0) -> float:
    """σ (rad) of the refined θy' from the transmit's scan-pose uncertainty.

    The predicted field is the scan placed at the transmit's pose: a scan tilted by δθy
    or moved by δx0 turns the predicted wavefront on the sensor, and the refinement
    turns θy' with it (a 32-element coverage twin: 0.76 δθy; −0.18°/mm of δx0; its
    transmit pose, 0.0048° and 3 µm off, put θy' 0.0041° off against 0.0002° from the
    true pose, with σ(θy') 0.0038°; θx, θz and the sensor's H and F move it by less than
    a tenth of that). x0 comes from the aperture centre at the face plane, so its error
    is the centre fit's own, δx_c, plus the angle lever z0·δθy (:func:`with_angle_lever`),
    which is θy's error seen from the scan origin: the two move together. So two
    independent moves are predicted again (the plan's spectra are shared:
    :meth:`SensorPredictor.with_scan_pose`): θy by its σ with x0 by z0 times that (the
    σ of θy without the steering σ_ε and the sound speed's term, which
    :func:`_with_steering` and :func:`_receive_uncertainties` add), and x0 by the centre
    fit's σ (``transmit.aperture.center_x_uncertainty``, without the lever). The slope b
    of the delays of each prediction against ``prediction`` ((pressure, start time) at
    ``receiver``) over the used elements gives ``step_gain·|b|/cos θy'``; the two add in
    quadrature."""
    u = transmit.uncertainties
    c0 = transmit.medium.sound_speed
    pose = predict.scan_grid.pose
    rel_c = float(transmit.extras.get("sound_speed_uncertainty", 0.0)) / c0
    u_ty = math.sqrt(max(float(u.get("theta_y", 0.0)) ** 2
                         - float(transmit.extras.get("steering_uncertainty", 0.0)) ** 2
                         - (math.tan(pose.theta_y) * rel_c) ** 2, 0.0))
    x, y, z = pose.origin
    u_xc = float(getattr(transmit.aperture, "center_x_uncertainty", 0.0))
    moves = []
    if math.isfinite(u_ty) and u_ty > 0:  # θy and, over the lever z0, x0 with it
        moves.append(dataclasses.replace(pose, theta_y=pose.theta_y + u_ty,
                                         origin=(x + z * u_ty, y, z)))
    if math.isfinite(u_xc) and u_xc > 0:
        moves.append(dataclasses.replace(pose, origin=(x + u_xc, y, z)))
    p0, t0 = prediction
    rate = predict.sampling_rate
    ex = np.asarray(element_x, dtype=float)
    total = 0.0
    for moved in moves:
        p1, t1 = predict.with_scan_pose(moved)(receiver)
        sens = element_sensitivity(p1, p0, rate, pressure_rate=rate, rf_start_time=t1,
                                   pressure_start_time=t0, used=receiver.used,
                                   band_db=band_db)
        ok = receiver.used & np.isfinite(sens.delay)
        if ok.sum() >= 3:
            b = float(np.polyfit(ex[ok], sens.delay[ok], 1)[0])
            total = math.hypot(total, step_gain * b / math.cos(receiver.theta_y))
    return total


def with_tilt_term(receiver: VirtualReceiver, sigma: float) -> VirtualReceiver:
    """The receiver with a further σ (rad) of θy' in quadrature, and what it gives x0'
    and d at the onset's z0' (which the onset holds): x0' = z0' tan(θy'/2) moves by
    ``z0'/(2 cos²(θy'/2))·σ`` (= d σ; not d cos θy'·σ, which is x0' = d sin θy' at a
    held d), d = z0'/(1 + cos θy') by ``z0' sin θy'/(1 + cos θy')²·σ``."""
    if not sigma > 0:
        return receiver
    th = receiver.theta_y
    return dataclasses.replace(
        receiver, theta_y_uncertainty=math.hypot(receiver.theta_y_uncertainty, sigma),
        x0_uncertainty=math.hypot(receiver.x0_uncertainty,
                                  receiver.z0 / (2 * math.cos(th / 2) ** 2) * sigma),
        distance_uncertainty=math.hypot(receiver.distance_uncertainty, receiver.z0 * abs(
            math.sin(th)) / (1 + math.cos(th)) ** 2 * sigma))


def receive_ir_step(receiver: VirtualReceiver, pressure_average: NDArray, echo: EchoRecording,
                    window: tuple[float, float], *, pressure_rate: float,
                    pressure_start: float, rp: float, reflection: ReflectionEstimate | None,
                    config: ReceiveConfig, notes: list[str],
                    element_x: NDArray | None = None,
                    delays: NDArray | None = None) -> ReceiveImpulseResponse:
    """Step 6: :func:`receive_impulse_response` (one regularised deconvolution of the
    averaged RF by the averaged pressure × Rp, ``receive`` section), the voltage noise
    from the pre-echo segment (after a feed-through, before the onset minus a guard),
    truncated before the back-wall echo (``receive.truncate_before``, default the echo
    train's period); its warnings become notes.

    The RF average deconvolved is ``E_R = h_R ⊛ p_R`` exactly: the echo RF
    (:func:`_echo_rf`) over the same elements with the same tilt delays as the pressure
    average (``element_x``, m: the element centres; default the echo's probe), not
    ``receiver.averaged_rf``, which is high-passed for the onset, the echo train and the
    report (P is not: the filter's transients at the record ends put power at
    0–0.2 MHz into Y that passes for signal). ``delays`` (s, one per element) replaces
    the tilt delays ``receiver.slope · element_x`` (a convex array's echo delays)."""
    rc = config
    truncate = rc.truncate_before
    if truncate is None and reflection is not None and math.isfinite(reflection.period):
        truncate = reflection.period
    if delays is None:
        if element_x is None:
            if echo.probe is None:
                raise InputError("expected the element positions (element_x) or an echo "
                                 "with a probe description", field="element_x")
            element_x = echo.probe.element_centers()
        delays = receiver.slope * np.asarray(element_x, dtype=float)
    y_avg = aligned_average(_echo_rf(echo, window), echo.sampling_rate, delays,
                            used=receiver.used)
    with _warnings.catch_warnings(record=True) as caught:
        _warnings.simplefilter("always")
        ir = receive_impulse_response(
            y_avg, pressure_average, echo.sampling_rate,
            noise_window=(window[0], receiver.onset - rc.noise_guard),
            pressure_rate=pressure_rate, voltage_start_time=echo.start_time,
            pressure_start_time=pressure_start, reflection_coefficient=rp,
            truncate_before=truncate, output_rate=rc.output_rate, voltage_unit=echo.unit,
            noise_guard=rc.noise_guard, onset_threshold=rc.onset_threshold,
            peak_fraction=rc.peak_fraction, segment_length=rc.segment_length,
            pressure_floor_db=rc.pressure_floor_db, smooth_bins=rc.smooth_bins,
            onset_margin=rc.ir_onset_margin, time_limited=rc.ir_time_limited,
            out_of_band_weight=rc.ir_out_of_band_weight, noise_tail=rc.ir_noise_tail)
    notes += [f"receive impulse response: {w.message}" for w in caught]
    return ir


def characterize_receive(
    echo: EchoRecording,
    transmit: TransmitResult,
    scan: HydrophoneScan,
    config: CharacterizationConfig | ReceiveConfig | None = None,
    *,
    reflection_coefficient: float | None = None,
    calibration: HydrophoneCalibration | None = None,
    record_guard: float | None = None,
    guard_angle_deg: float | None = None,
    progress: bool | None = None,
) -> ReceiveResult:
    """Characterize the receive side of a probe from a flat-reflector echo (paper III B).

    Parameters
    ----------
    echo : EchoRecording
        Element RF of the reflector experiment, shape (n_el, nt), with its drive.
    transmit : TransmitResult
        From :func:`characterize_transmit` on ``scan``: lens focus F, aperture height H,
        the final scan-plane pose (tilt-corrected scan) and the signal band.
    scan : HydrophoneScan
        The hydrophone scan the transmit result came from (its field is forward
        projected onto the virtual sensor).
    config : CharacterizationConfig or ReceiveConfig, optional
        Its ``receive`` section (defaults: ``ReceiveConfig()``); the projection uses the
        ``backprojection`` knobs (eps, guard angle, precision) of a
        CharacterizationConfig, else those of ``transmit.config``.
    reflection_coefficient : float, optional
        Rp given by the user (overrides ``receive.reflection_coefficient``); default
        from the echo train (:func:`estimate_reflection_coefficient`).
    calibration : HydrophoneCalibration, optional
        Hydrophone sensitivity of a voltage scan (as given to the transmit step).
    record_guard : float, optional
        Extra zero padding (s) of the scan record before the projection, on top of the
        geometric spread and the largest lens delay (see the module notes); default
        ``ReceiveConfig.record_guard``.
    guard_angle_deg : float, optional
        Guard angle of the projection's padding rule (degrees; see
        :func:`holoprobe.propagation.padded_shape`); default
        ``ReceiveConfig.guard_angle_deg`` (30°). The sensor is ~20 scan widths away:
        the transmit's 80° would pad the scan to ~1 m (2·w·tan 80°) for components that
        carry nothing at the sensor; the periodic images of the scan are kept out of
        the cone of half-angle ``guard_angle_deg`` around every sensor point.
    progress : bool or None
        Progress bar on the projection (None: on a terminal).

    Returns
    -------
    ReceiveResult

    Raises
    ------
    InputError
        Bad inputs, or data the steps cannot use: no usable echo, no onset threshold
        crossing, an echo train that does not give Rp (without a fallback), … Each
        message names the field.

    Notes
    -----
    1. :func:`estimate_virtual_receiver` with the transmit's F and H (paper section
       III B; θy' = −asin(s c0), z0' exact);
    2. Rp: the user's, else from the echo train of the tilt-aligned average RF
       (:func:`echo_train_peaks`, the dominant train, :func:`reflection_coefficient_from_peaks`;
       reference_spec 2.9 step 4); its period is the default truncation of the IR;
    3. the scan pressure (calibrated) at the transmit's band, zero-padded in time (see
       the module notes), is projected with :func:`holoprobe.propagation.project`
       (``quantity="pressure"``, NUFFT) onto :func:`virtual_sensor_surface` sampled at
       ≤ λ_min / ``points_per_wavelength``;
    4. :func:`element_receive_pressure`: receive lens delays (paper eq. lens-delays,
       lens centred on the aperture as in the transmit step and the exported model) and
       element averages, × :class:`DriveRatio` (E_echo(f)/E_scan(f)); with
       ``receive.refine_pose`` :func:`refine_receiver_tilt`, ``pose_iterations``
       predictions;
    5. :func:`tilt_aligned_average` over the used elements (slope of the arrival line);
    6. :func:`receive_impulse_response`: one regularised deconvolution (paper eq.
       deconvolution-receive) of the averaged RF by the averaged pressure × Rp, noise
       from the pre-echo segment after any feed-through, onset moved to
       ``receive.ir_onset_margin`` (z0', d, x0' absorb the delay), truncated, resampled;
    7. optionally :func:`element_sensitivity`.
    """
    t_total, timer, notes = time.perf_counter(), _Timer(), list[str]()
    rc, full_cfg, record_guard, guard_angle_deg = _checked_inputs(
        echo, transmit, scan, config, record_guard, guard_angle_deg)
    medium, fs, fs_s = transmit.medium, echo.sampling_rate, scan.sampling_rate
    height, focus = transmit.aperture.height, transmit.lens_focus
    probe = _probe(echo, scan, transmit)
    ex = probe.element_centers()
    with timer("virtual_receiver"):  # 1. virtual receiver
        receiver, window = locate_receiver(echo.rf, fs, echo.start_time, ex, focus=focus,
                                           height=height, sound_speed=medium.sound_speed,
                                           config=rc, notes=notes)
    with timer("reflection"):  # 2. reflection coefficient
        rp, u_rp, reflection, sigma_rf = reflection_step(
            receiver, window, fs, echo.start_time, reflection_coefficient, rc, notes)
    with timer("scan_spectrum"):  # 3. the scan, padded, in the transmit band
        sp = scan_for_sensor(scan, transmit, receiver, probe, calibration=calibration,
                             record_guard=record_guard, config=full_cfg, receive=rc,
                             notes=notes)
    with timer("forward_projection"):  # 4. forward projection onto the virtual sensor
        ratio_f = drive_ratio(echo, scan, sp.frequencies, notes)
        predict, (p_time, t_p0) = decimated_prediction(SensorPredictor(
            sp, transmit.scan_grid, medium, probe, height, focus, ratio_f, fs_s, scan.start_time,
            predictor_options(rc, full_cfg, guard_angle_deg, progress)), receiver, rc)
        kb = int(np.argmax(np.abs(to_frequency(p_time.mean(axis=0))[sp.bins])))
    with timer("element_pressure"):  # 4b. model-based θy'; 5. tilt alignment
        receiver, p_time, t_p0, refinement = refine_pose_step(
            receiver, echo, window, p_time, t_p0, ex, predict, rc, reflection, transmit)
        predicted_at = receiver  # p_time's pose (before step 6 moves the IR's onset)
        later = predict if _gains_predict(rc, predicted_at, transmit) else None
        gains = rc.element_sensitivity or transmit.element_map is not None  # noise: for them
        bins, noise = predict.bins_info, gains and _noise_of(predict, predicted_at, p_time)
        del predict
        p_avg = tilt_aligned_average(p_time, fs_s, ex, receiver.slope, used=receiver.used)
    with timer("receive_ir"):  # 6. receive impulse response
        ir = receive_ir_step(receiver, p_avg, echo, window, pressure_rate=fs_s,
                             pressure_start=t_p0, rp=rp, reflection=reflection, config=rc,
                             notes=notes, element_x=ex)
        # the IR's onset was moved to ir.onset: the virtual sensor absorbs the delay
        receiver = _shift_receiver(receiver, ir.shift, focus, height, medium.sound_speed)
    sens = None  # 7. per-element sensitivity
    if gains:
        with timer("element_sensitivity"):
            sens = sensitivity_step(echo, p_time * rp, fs_s, t_p0, predicted_at, rc,
                                    transmit, later, noise)
            receiver = _with_steering(receiver, sens)
    _sensor_tilt_warning(receiver, full_cfg.warnings, notes)
    timer.times["total"] = time.perf_counter() - t_total
    return ReceiveResult(
        receiver=receiver, reflection_coefficient=float(rp), reflection_uncertainty=u_rp,
        reflection=reflection, drive_ratio=float(np.abs(ratio_f[kb])), impulse_response=ir,
        ir_spectrum=spectrum_summary(ir.ir, ir.sampling_rate), element_x=ex,
        element_pressure=p_time * rp, averaged_pressure=p_avg * rp,
        pressure_start_time=float(t_p0),
        pressure_rate=float(fs_s), sensor_points=sp.sensor_points, sensitivity=sens,
        rf_unit=echo.unit, uncertainties=_receive_uncertainties(receiver, u_rp, transmit),
        warnings=notes, timings=dict(timer.times), config=rc, source=echo.source, rf=echo.rf,
        extras={"rf_noise_sigma": sigma_rf, "pose_refinement": refinement, **bins,
                "record_length": sp.record_length,
                "scan_sensor_distance": sp.distances, "sensor_spacing": sp.spacing})


def _gains_predict(config: ReceiveConfig, receiver: VirtualReceiver,
                   transmit: TransmitResult) -> bool:
    """Whether the gains (step 7) predict again: the distance term (a sensor moved by
    its IR onset) or the sound speed's (u_c > 0), for an array that has gains."""
    gains = config.element_sensitivity or transmit.element_map is not None
    return gains and ((config.distance_uncertainty and receiver.onset_shift != 0.0)
                      or transmit.extras.get("sound_speed_uncertainty", 0.0) > 0)


def _with_steering(receiver: VirtualReceiver, sens: ElementSensitivity | None
                   ) -> VirtualReceiver:
    """σ(θy') and σ(x0') with the steering σ_ε that the element delays may hide
    (``sens.steering_uncertainty``, :func:`steering_prediction`): the transmit fit puts
    it into the scan's tilt, the refined θy' holds it (2α + ε, α the plate's tilt) and
    x0' = z0' tan(θy'/2) moves by d·ε (z0' held). On a 24-element twin with 8 ns rms element
    delays θy' was 0.075–0.083° off (σ_ε 0.08°) with a fit σ of 0.007°."""
    eps = getattr(sens, "steering_uncertainty", None)
    return receiver if eps is None else with_tilt_term(receiver, float(eps))


def _sensor_tilt_warning(receiver: VirtualReceiver, config: WarningConfig,
                         notes: list[str]) -> None:
    tilt_deg = math.degrees(abs(receiver.theta_y))
    if tilt_deg > config.max_sensor_tilt_deg:
        notes.append(f"virtual-sensor tilt θy' = {tilt_deg:.2f}° is larger than expected "
                     f"({config.max_sensor_tilt_deg:g}°; the plate is tilted by half)")


def _receive_uncertainties(receiver: VirtualReceiver, u_rp: float,
                           transmit: TransmitResult) -> dict[str, float]:
    """The receiver's σ, with the sound speed's (``u_c``, m/s: the transmit result's
    ``extras['sound_speed_uncertainty']``, at its c0) in those c0 scales: θy'
    (``|tan θy'|·u_c/c0``: sin θy' = −s·c0 from the arrival slope s), z0' and d
    (distances from times), and x0' = d sin θy' twice (``2|x0'|·u_c/c0``)."""
    u_c = float(transmit.extras.get("sound_speed_uncertainty", 0.0))
    rel = u_c / transmit.medium.sound_speed if u_c > 0 else 0.0

    def term(sigma: float, value: float) -> float:
        return float(math.hypot(sigma, abs(value) * rel))

    return {"theta_y": term(receiver.theta_y_uncertainty, math.tan(receiver.theta_y)),
            "theta_x": float("nan"),  # x0' = d sin θy': both factors scale with c0
            "x0": term(receiver.x0_uncertainty, 2.0 * receiver.x0),
            "z0": term(receiver.z0_uncertainty, receiver.z0),
            "distance": term(receiver.distance_uncertainty, receiver.distance),
            "onset": receiver.onset_uncertainty, "reflection_coefficient": u_rp}
