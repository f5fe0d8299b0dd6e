"""Synthesis of the reflector experiment (the receive half of the digital twin)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from holoprobe._progress import progress_task
from holoprobe.errors import InputError
from holoprobe.geometry import Medium, Pose, Surface, plate_plane
from holoprobe.measurement import EchoRecording
from holoprobe.signal import (
    continuous_spectrum,
    frequency_axis,
    next_fast_length,
    to_frequency,
    to_time,
)
from holoprobe.simulate._array import ArrayModel, SourceSampling
from holoprobe.simulate._noise import add_noise, quantize
from holoprobe.simulate._scan import _model_arrays, _source_time_extent, distance_bounds
from holoprobe.simulate._spectra import (
    SynthesisWindow,
    radiate,
    signal_band,
)
from holoprobe.simulate._truth import (
    SimulationTruth,
    medium_parameters,
    model_parameters,
    pose_parameters,
)

__all__ = ["mirror_points", "plate_plane", "simulate_echo", "virtual_sensor_pose"]

DEFAULT_VIRTUAL_TILT = math.radians(3.1672532951380172)
"""Default virtual-sensor tilt θy' (rad): the published P4-1 value (reference_spec 4)."""


def mirror_points(points: NDArray, distance: float, virtual_tilt: float,
                  virtual_tilt_x: float = 0.0) -> NDArray:
    """Mirror images of points across the plate face (the image method), shape (n, 3);
    ``virtual_tilt_x``: a matrix array's second tilt θx' (:func:`plate_plane`)."""
    p0, n = plate_plane(distance, virtual_tilt, virtual_tilt_x)
    points = np.asarray(points, dtype=float)
    return points - 2.0 * ((points - p0) @ n)[:, None] * n[None, :]


def virtual_sensor_pose(distance: float, virtual_tilt: float) -> Pose:
    """Pose of the virtual sensor: x0' = d sin θy', z0' = d(1 + cos θy'), tilt θy'.

    Its in-plane point (u, v, 0) is the mirror image of the transducer point (u, v, 0)
    (the mirror also flips the normal, which the pose's rotation does not describe).
    """
    return Pose(0.0, virtual_tilt, 0.0,
                (distance * math.sin(virtual_tilt), 0.0,
                 distance * (1.0 + math.cos(virtual_tilt))))


def simulate_echo(
    model: ArrayModel | None = None,
    *,
    plate_distance: float = 44.8978e-3,
    virtual_tilt: float = DEFAULT_VIRTUAL_TILT,
    virtual_tilt_x: float = 0.0,
    reflection_coefficient: float = 0.78,
    back_wall: bool = True,
    plate_thickness: float = 12.7e-3,
    plate_sound_speed: float = 5900.0,
    back_wall_amplitude: float | None = None,
    sampling_rate: float = 62.5e6,
    n_samples: int | None = None,
    start_time: float = 0.0,
    medium: Medium | None = None,
    recorded_medium: Medium | None = None,
    snr_db: float | None = 40.0,
    seed: int | None = 0,
    quantization_bits: int | None = None,
    full_scale: float | None = None,
    feedthrough: float | None = None,
    feedthrough_decay: float = 1e-6,
    band: tuple[float, float] | None = None,
    band_threshold_db: float = -30.0,
    points_per_wavelength: float = 4.0,
    dtype: type = np.float32,
    chunk_points: int = 4096,
    progress: bool | None = False,
) -> tuple[EchoRecording, SimulationTruth]:
    """Simulate the element RF of the flat-reflector experiment, with its truth.

    Image method (paper section III B): the pressure incident on the array is
    ``Rp`` times the field of the transmitting array evaluated at the mirror images of
    the receiving points across the plate face (dense frequency-domain Rayleigh,
    paper eq. rayleigh-fwd-vp, from the fine source quadrature to the fine receiver
    quadrature). Each element integrates it over its face after the exact receive lens
    delays (paper eq. lens-delays); the element pressure is convolved with the receive
    impulse response (paper eq. receive-impulse-response) and sampled at the scanner's
    rate. A back-wall echo is the same field delayed by ``2·thickness/c_plate`` with
    amplitude ``back_wall_amplitude`` (plane-wave approximation).

    Parameters
    ----------
    model : ArrayModel, optional
        The probe; default the ``p4-1`` preset. All elements transmit (its apodization
        and delays), each receives.
    plate_distance : float
        Distance d in m from the transducer centre to the plate face along z.
    virtual_tilt : float
        Virtual-sensor tilt θy' in rad; the plate itself is tilted by θy'/2.
    virtual_tilt_x : float
        Second tilt θx' in rad (for a 2-D matrix array; the plate turned by θx'/2 about
        x, :func:`holoprobe.geometry.plate_plane`).
    reflection_coefficient : float
        Pressure reflection coefficient Rp of the front face (angle independent).
    back_wall : bool
        Add the back-wall echo.
    plate_thickness, plate_sound_speed : float
        m and m/s (default a 12.7 mm steel plate, 5900 m/s).
    back_wall_amplitude : float, optional
        Amplitude of the back-wall echo relative to the incident wave; default
        ``−Rp(1 − Rp²)`` (into the plate, reflected at the back face, out again).
    sampling_rate : float
        Hz (default 62.5 MHz, Verasonics).
    n_samples : int, optional
        Record length; default up to 10 µs after the back-wall echo.
    start_time : float
        Time of sample 0 after the transmit event, s.
    medium : Medium, optional
        The true water (default 998 kg/m³, 1481 m/s).
    recorded_medium : Medium, optional
        The medium written into the measurement (what the lab believed, e.g. the wrong
        temperature); default ``medium``. The truth records both.
    snr_db, seed, quantization_bits, full_scale
        Noise and quantisation (peak SNR over all channels, see
        :func:`holoprobe.simulate.noise_std_for_snr`).
    feedthrough : float, optional
        Add a transmit feed-through (the drive coupling electrically into every receive
        channel, as in every real system) of this peak amplitude relative to the peak
        of the clean echo RF: the drive convolved with the receive IR, starting at the
        emission (t = 0) and dying out with ``feedthrough_decay`` (s, exponential
        envelope), the same on every element with a ±10 % spread of amplitude. It is
        part of ``rf_clean`` (the truth's ``feedthrough`` array holds it alone).
    band, band_threshold_db, points_per_wavelength, dtype, chunk_points, progress
        As for :func:`holoprobe.simulate.simulate_scan` (the band is that of the surface
        velocity, so that the element pressure in the truth is complete too).

    Returns
    -------
    (EchoRecording, SimulationTruth)
        RF of shape (N, n_samples) in ADCL; the truth holds the clean element pressure
        (``element_pressure``, Pa) and clean RF (``rf_clean``).
    """
    t_start = time.perf_counter()
    medium = medium or Medium()
    model = model if model is not None else ArrayModel.from_preset("p4-1")
    _check_echo_inputs(model, plate_distance=plate_distance, sampling_rate=sampling_rate,
                       plate_thickness=plate_thickness, plate_sound_speed=plate_sound_speed,
                       virtual_tilt=max(abs(virtual_tilt), abs(virtual_tilt_x)),
                       reflection_coefficient=reflection_coefficient)
    rp = float(reflection_coefficient)
    if back_wall_amplitude is None:
        back_wall_amplitude = -rp * (1.0 - rp**2)
    bw_amp = float(back_wall_amplitude) if back_wall else 0.0
    bw_delay = 2.0 * plate_thickness / plate_sound_speed
    if band is None:
        band = signal_band(model, medium, threshold_db=band_threshold_db)
    band = (float(band[0]), min(float(band[1]), 0.5 * sampling_rate))
    rx = _ReceiverImages.build(model, medium, band, points_per_wavelength, plate_distance,
                               virtual_tilt, virtual_tilt_x)
    t_src0, t_src1 = _source_time_extent(model, rx.sampling, medium)
    near, far = distance_bounds(rx.images, rx.sampling)
    ir_len = model.receive_ir.size / model.ir_sampling_rate
    c0 = medium.sound_speed
    first = t_src0 + near.min() / c0
    # the window holds the front-face echo of the incident pressure only; the back wall
    # (a delayed copy) and the receive IR are applied afterwards on the whole record
    last = t_src1 + far.max() / c0 + float(rx.tau.max())
    if n_samples is None:
        end = last + ir_len + (bw_delay if bw_amp else 0.0) + 10e-6
        n_samples = math.ceil((end - start_time) * sampling_rate)
    n_samples = int(n_samples)
    if n_samples < 2:
        raise InputError(f"expected at least 2 samples, got {n_samples}", field="n_samples")
    win = SynthesisWindow.build(first, last, start_time, sampling_rate, n_samples, band,
                                guard=8.0 / sampling_rate)
    p_el = _incident_pressure(model, rx, win, medium, chunk_points=chunk_points, dtype=dtype,
                              progress=progress)
    pressure, rf_clean = _element_records(model, p_el, win, sampling_rate, n_samples,
                                          reflection=(rp, bw_amp, bw_delay), dtype=dtype)
    feed = _feedthrough(model, model.element_count, n_samples, sampling_rate, start_time,
                        feedthrough, feedthrough_decay, float(np.max(np.abs(rf_clean))), seed)
    if feed is not None:
        rf_clean = rf_clean + feed * (np.asarray(model.receive_gains) != 0)[:, None]
    rf_clean = rf_clean.astype(dtype)
    rf = rf_clean.copy()
    rng = np.random.default_rng(seed)
    rf, sigma = add_noise(rf, snr_db, rng)
    rf, lsb = quantize(rf, quantization_bits, full_scale)
    rec = EchoRecording(rf, sampling_rate, start_time, "ADCL", model.drive,
                        model.probe_info(), recorded_medium or medium, source="simulated")
    params = _echo_parameters(
        model, medium, recorded_medium, rx, plate_distance=plate_distance,
        virtual_tilt=virtual_tilt, virtual_tilt_x=virtual_tilt_x, rp=rp, back_wall=back_wall,
        plate_thickness=plate_thickness,
        plate_sound_speed=plate_sound_speed, bw_delay=bw_delay, bw_amp=bw_amp,
        sampling_rate=sampling_rate, n_samples=n_samples, start_time=start_time, band=band,
        band_threshold_db=band_threshold_db, points_per_wavelength=points_per_wavelength,
        dtype=dtype)
    params["noise"] = {"snr_db": snr_db, "snr_definition": "20*log10(max|clean| / sigma)",
                       "sigma": sigma, "clean_peak": float(np.max(np.abs(rf_clean))),
                       "seed": seed, "quantization_bits": quantization_bits,
                       "quantization_step": lsb, "unit": "ADCL"}
    params["elapsed_s"] = time.perf_counter() - t_start
    arrays = _model_arrays(model, medium)
    arrays["element_pressure"] = pressure
    arrays["rf_clean"] = rf_clean
    if feed is not None:
        arrays["feedthrough"] = feed.astype(dtype)
        params["feedthrough"] = {"relative_amplitude": float(feedthrough or 0.0),
                                 "decay_s": float(feedthrough_decay),
                                 "model": "drive ⊛ receive IR × exp(−t/decay) from t = 0, "
                                          "±10 % per element"}
    return rec, SimulationTruth(params, arrays)


def _check_echo_inputs(model: object, *, virtual_tilt: float, reflection_coefficient: float,
                       **positive: float) -> None:
    if not isinstance(model, ArrayModel):
        raise InputError("expected a holoprobe.simulate.ArrayModel", field="model")
    for name, value in positive.items():
        if not (np.isfinite(value) and value > 0):
            raise InputError(f"expected a positive number, got {value!r}", field=name)
    if not abs(virtual_tilt) < math.pi / 4:
        raise InputError(f"expected |θy'| < 45° (in rad), got {virtual_tilt!r}",
                         field="virtual_tilt")
    if not np.isfinite(reflection_coefficient) or abs(reflection_coefficient) > 1:
        raise InputError(f"expected |Rp| ≤ 1, got {reflection_coefficient!r}",
                         field="reflection_coefficient")


@dataclass(frozen=True)
class _ReceiverImages:
    """The fine receiver quadrature of the array and its mirror images across the plate."""

    sampling: SourceSampling  # the model's surface sampling (ArrayModel.sample_surface)
    index: NDArray[np.intp]  # active points of the sampling
    per_element: int
    images: NDArray[np.float64]  # (n, 3) mirrored receiver points, m
    tau: NDArray[np.float64]  # (n,) receive lens delays, s
    weights: NDArray[np.float64]  # (n,) quadrature weights, m²

    @classmethod
    def build(cls, model: ArrayModel, medium: Medium, band: tuple[float, float],
              points_per_wavelength: float, distance: float, virtual_tilt: float,
              virtual_tilt_x: float = 0.0) -> _ReceiverImages:
        spacing = medium.sound_speed / band[1] / points_per_wavelength
        sampling = model.sample_surface(spacing)
        rx = np.nonzero(sampling.active)[0]
        rx_pts = sampling.surface.points[rx]
        return cls(sampling, rx, rx.size // model.element_count,
                   mirror_points(rx_pts, distance, virtual_tilt, virtual_tilt_x),
                   model.lens_delays(sampling.y[rx], medium), sampling.surface.weights[rx])


def _incident_pressure(model: ArrayModel, rx: _ReceiverImages, win: SynthesisWindow,
                       medium: Medium, *, chunk_points: int, dtype: type,
                       progress: bool | None) -> NDArray[np.complex128]:
    """The field of the transmitting array at the mirrored receiver points (dense
    Rayleigh), receive lens delays, averaged over each element face: shape (N, nf),
    unit reflection, on the window's frequencies."""
    f = win.frequencies
    omega = 2 * np.pi * f
    c0 = medium.sound_speed
    n_el, per_el = model.element_count, rx.per_element
    images, rx_w = rx.images, rx.weights
    p_el = np.zeros((n_el, f.size), dtype=complex)
    els_per_chunk = max(1, int(chunk_points) // max(1, per_el))
    with progress_task(n_el, description="simulate echo", enabled=progress) as advance:
        for e0 in range(0, n_el, els_per_chunk):
            e1 = min(n_el, e0 + els_per_chunk)
            sl = slice(e0 * per_el, e1 * per_el)
            tgt = Surface(images[sl], np.broadcast_to([0.0, 0.0, -1.0], images[sl].shape),
                          rx_w[sl])
            spec = radiate(model, rx.sampling, tgt, f, medium, time_origin=c0 * win.origin,
                           dtype=dtype)
            # receive: exact lens delays, then the area average over each element face
            spec = spec * np.exp(1j * np.outer(rx.tau[sl], omega)) * rx_w[sl, None]
            spec = spec.reshape(e1 - e0, per_el, f.size).sum(axis=1)
            p_el[e0:e1] = spec / rx_w[sl].reshape(e1 - e0, per_el).sum(axis=1)[:, None]
            advance(e1 - e0)
    return p_el


def _element_records(model: ArrayModel, p_el: NDArray, win: SynthesisWindow,
                     sampling_rate: float, n_samples: int, *,
                     reflection: tuple[float, float, float], dtype: type
                     ) -> tuple[NDArray, NDArray[np.float64]]:
    """The element pressure (front echo × Rp + the back-wall copy) and the clean RF
    (receive IR, per-element receive gains) on the record, shape (N, n_samples) each.
    ``reflection`` is (Rp, back-wall amplitude, back-wall delay in s)."""
    rp, bw_amp, bw_delay = reflection
    n_el = p_el.shape[0]
    ir_len = model.receive_ir.size / model.ir_sampling_rate
    # incident pressure of the front echo (unit reflection) in time, on a record long
    # enough that the back-wall copy and the receive IR do not wrap
    full = np.zeros((n_el, win.n_fft // 2 + 1), dtype=complex)
    full[:, win.bins] = p_el * sampling_rate
    front = to_time(full, win.n_fft, axis=-1)[:, :win.n_valid]
    extra = math.ceil((bw_delay * (bw_amp != 0) + ir_len) * sampling_rate) + 16
    n_rec = next_fast_length(max(n_samples, win.offset + win.n_valid) + extra)
    record = np.zeros((n_el, n_rec))
    m = min(win.n_valid, n_rec - win.offset)
    record[:, win.offset:win.offset + m] = front[:, :m]
    spec = to_frequency(record, axis=-1)
    f_rec = frequency_axis(n_rec, sampling_rate)
    spec *= rp + bw_amp * np.exp(2j * np.pi * f_rec * bw_delay)
    pressure: NDArray = to_time(spec, n_rec, axis=-1)[:, :n_samples].astype(dtype)
    h_r = continuous_spectrum(model.receive_ir, model.ir_sampling_rate, f_rec)
    rf_clean = to_time(spec * h_r, n_rec, axis=-1)[:, :n_samples]  # E_R = h_R ⊛ p_R
    rf_clean *= np.asarray(model.receive_gains)[:, None]  # per-element receive gain g_e
    return pressure, rf_clean


def _echo_parameters(model: ArrayModel, medium: Medium, recorded_medium: Medium | None,
                     rx: _ReceiverImages, *, plate_distance: float, virtual_tilt: float,
                     virtual_tilt_x: float,
                     rp: float, back_wall: bool, plate_thickness: float,
                     plate_sound_speed: float, bw_delay: float, bw_amp: float,
                     sampling_rate: float, n_samples: int, start_time: float,
                     band: tuple[float, float], band_threshold_db: float,
                     points_per_wavelength: float, dtype: type) -> dict[str, Any]:
    """truth.json of the echo (without ``noise``, ``elapsed_s`` and ``feedthrough``)."""
    vs = virtual_sensor_pose(plate_distance, virtual_tilt)
    return {
        "kind": "echo_recording",
        "probe": model_parameters(model, medium),
        "reflector": {
            "plate_distance_m": plate_distance,
            "plate_tilt_deg": math.degrees(0.5 * virtual_tilt),
            "virtual_tilt_x_deg": math.degrees(virtual_tilt_x),
            "reflection_coefficient": rp,
            "back_wall": bool(back_wall), "plate_thickness_m": plate_thickness,
            "plate_sound_speed_m_s": plate_sound_speed, "back_wall_delay_s": bw_delay,
            "back_wall_amplitude": bw_amp,
            "model": "image method, angle-independent Rp; back wall as a delayed copy",
        },
        "virtual_sensor": pose_parameters(vs),
        "echo_time_normal_incidence_s": 2 * plate_distance / medium.sound_speed,
        "record": {"sampling_rate_hz": float(sampling_rate), "n_samples": n_samples,
                   "start_time_s": float(start_time), "unit": "ADCL"},
        "medium": medium_parameters(medium, recorded_medium),
        "synthesis": {
            "method": "image method + dense frequency-domain Rayleigh (fwd_vp) to the "
                      "mirrored fine receiver quadrature, exact receive lens delays",
            "band_hz": list(band), "band_threshold_db": band_threshold_db,
            "source_spacing_m": rx.sampling.spacing,
            "n_source_points": rx.sampling.surface.size,
            "n_receiver_points": int(rx.index.size),
            "points_per_wavelength": points_per_wavelength,
            "precision": np.dtype(dtype).name,
        },
    }


def _feedthrough(model: ArrayModel, n_el: int, n_samples: int, fs: float, start_time: float,
                 amplitude: float | None, decay: float, echo_peak: float,
                 seed: int | None) -> NDArray | None:
    """Transmit feed-through on every channel (see :func:`simulate_echo`), or None."""
    if amplitude is None or amplitude == 0:
        return None
    if not (np.isfinite(amplitude) and amplitude > 0):
        raise InputError(f"expected a positive relative amplitude, got {amplitude!r}",
                         field="feedthrough")
    if not (np.isfinite(decay) and decay > 0):
        raise InputError(f"expected a positive time in s, got {decay!r}",
                         field="feedthrough_decay")
    t = start_time + np.arange(n_samples) / fs
    f = frequency_axis(2 * n_samples, fs)
    drive = model.drive
    spec = (continuous_spectrum(drive.voltage, drive.sampling_rate, f)
            * continuous_spectrum(model.receive_ir, model.ir_sampling_rate, f))
    # the waveform on the record's clock: time 0 (the emission) at sample −start_time·fs
    wave = to_time(spec * np.exp(-2j * np.pi * f * start_time), 2 * n_samples)[:n_samples]
    wave = wave * fs * np.where(t >= 0, np.exp(-np.maximum(t, 0.0) / decay), 0.0)
    peak = float(np.max(np.abs(wave)))
    if peak == 0:
        raise InputError("the feed-through is outside the record (it starts at the "
                         "emission, t = 0)", field="start_time")
    gains = 1 + 0.1 * np.random.default_rng(None if seed is None else seed + 1).uniform(
        -1, 1, n_el)
    return gains[:, None] * (amplitude * echo_peak / peak) * wave[None, :]
