"""Synthesis of a hydrophone raster scan (the transmit half of the digital twin)."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from holoprobe._progress import progress_task
from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose, Surface
from holoprobe.measurement import HydrophoneCalibration, HydrophoneScan
from holoprobe.signal import default_calibration, sensitivity_response, to_time
from holoprobe.simulate._array import ArrayModel, SourceSampling
from holoprobe.simulate._noise import add_noise, quantize
from holoprobe.simulate._spectra import SynthesisWindow, radiate, signal_band
from holoprobe.simulate._truth import (
    SimulationTruth,
    medium_parameters,
    model_parameters,
    pose_parameters,
)

__all__ = ["DEFAULT_SCAN_POSE", "distance_bounds", "simulate_scan", "synthesize_pressure"]

DEFAULT_SCAN_POSE = Pose.from_degrees(-0.0793, 0.6505, -0.7735,
                                      (-0.306e-3, -0.064e-3, 3.569e-3))
"""Default scan-plane pose: the one the published P4-1 characterization found
(reference_spec section 4, ``transformation_scan_plane.mat``)."""


def distance_bounds(points: NDArray, sampling: SourceSampling) -> tuple[NDArray, NDArray]:
    """Smallest and largest distance (m) from each point to the sampled source face.

    Bounds over the bounding box of the source points (exact for the largest distance
    to a box corner, a lower bound for the smallest one; flat or curved faces).
    """
    p = sampling.surface.points
    lo, hi = p.min(axis=0), p.max(axis=0)
    near_d = np.maximum(0.0, np.maximum(lo - points, points - hi))
    far_d = np.maximum(np.abs(points - lo), np.abs(points - hi))
    return np.linalg.norm(near_d, axis=1), np.linalg.norm(far_d, axis=1)


def _source_time_extent(model: ArrayModel, sampling: SourceSampling, medium: Medium
                        ) -> tuple[float, float]:
    """Earliest and latest time (s) at which any source point moves (t = 0: drive start)."""
    u = model.surface_velocity(medium)
    e = sampling.element
    delays = np.asarray(model.delays)
    tau = np.where(sampling.active, model.lens_delays(sampling.y, medium), 0.0) + delays[e]
    t_first = float(tau.min())
    t_last = float(tau.max()) + u.size / model.ir_sampling_rate
    em = model.edge_mode
    if em is not None and em.amplitude != 0:
        path = np.abs(np.abs(sampling.y) - 0.5 * model.element_height)
        t_em = em.delay + path.max() / em.phase_speed + float(delays.max())
        t_last = max(t_last, t_em + em.waveform_offset)
        t_first = min(t_first, em.delay - em.waveform_offset + float(delays.min()))
    return t_first, t_last


def synthesize_pressure(model: ArrayModel, sampling: SourceSampling, targets: Surface, *,
                        sampling_rate: float, n_samples: int, start_time: float,
                        band: tuple[float, float], medium: Medium,
                        calibration: HydrophoneCalibration | None = None,
                        dtype: type = np.float32, chunk_points: int = 2048,
                        groups: Sequence[NDArray] | None = None,
                        max_memory: int = 1 << 29, progress: bool | None = False,
                        description: str = "field") -> NDArray:
    """Time signals at target points by dense frequency-domain Rayleigh (fwd_vp).

    For each chunk of target points the record window that holds the signal is found
    from the source–target distance bounds, the source spectra are evaluated on that
    window's frequency bins inside ``band`` and propagated with
    :func:`holoprobe.propagation.rayleigh_integral` (paper eq. rayleigh-fwd-vp, rigid
    baffle), optionally multiplied by the hydrophone sensitivity ``S(f)``, and brought
    back to time.

    ``groups`` (lists of target indices, e.g. compact tiles of a scan) replaces the
    default consecutive chunks of ``chunk_points``: compact groups need shorter windows.

    Returns
    -------
    ndarray, shape (targets.size, n_samples), ``dtype``
        Pressure in Pa (voltage in V when ``calibration`` is given).
    """
    out: NDArray = np.zeros((targets.size, n_samples), dtype=dtype)
    t_src0, t_src1 = _source_time_extent(model, sampling, medium)
    c0 = medium.sound_speed
    cdtype = np.complex64 if dtype == np.float32 else np.complex128
    if groups is None:
        step = max(1, int(chunk_points))
        groups = [np.arange(i, min(i + step, targets.size))
                  for i in range(0, targets.size, step)]
    with progress_task(targets.size, description=description, enabled=progress) as advance:
        for sel in groups:
            pts = targets.points[sel]
            near, far = distance_bounds(pts, sampling)
            first = t_src0 + near.min() / c0
            last = t_src1 + far.max() / c0
            if first > start_time + n_samples / sampling_rate or last < start_time:
                advance(len(pts))
                continue
            win = SynthesisWindow.build(first, last, start_time, sampling_rate, n_samples,
                                        band, guard=8.0 / sampling_rate)
            chunk = Surface(pts, targets.normals[sel], targets.weights[sel])
            spec = radiate(model, sampling, chunk, win.frequencies, medium,
                           time_origin=c0 * win.origin, dtype=dtype, max_memory=max_memory)
            if calibration is not None:
                spec *= sensitivity_response(calibration, win.frequencies,
                                             inverse=False).astype(cdtype)
            full = np.zeros((len(pts), win.n_fft // 2 + 1), dtype=cdtype)
            full[:, win.bins] = spec * sampling_rate  # continuous spectrum → DFT scaling
            sig = to_time(full, win.n_fft, axis=-1)
            m = min(win.n_valid, n_samples - win.offset)
            out[sel, win.offset:win.offset + m] = sig[:, :m]
            advance(len(pts))
    return out


def _tiles(shape: tuple[int, int], chunk_points: int) -> list[NDArray]:
    """Indices (C order) of square-ish tiles of at most ``chunk_points`` grid points."""
    nx, ny = shape
    side = max(1, math.isqrt(max(1, int(chunk_points))))
    tx = min(nx, side)
    ty = min(ny, max(1, int(chunk_points) // tx))
    idx = np.arange(nx * ny).reshape(nx, ny)
    return [idx[i:i + tx, j:j + ty].ravel() for i in range(0, nx, tx)
            for j in range(0, ny, ty)]


def _grid(pose: Pose, size: Sequence[float], step: Sequence[float]) -> PlaneGrid:
    sizes = np.broadcast_to(np.asarray(size, float), (2,))
    steps = np.broadcast_to(np.asarray(step, float), (2,))
    if not (np.all(np.isfinite(sizes)) and np.all(sizes >= 0)):
        raise InputError(f"expected two sizes ≥ 0 in m, got {sizes}", field="size")
    if not (np.all(np.isfinite(steps)) and np.all(steps > 0)):
        raise InputError(f"expected two positive steps in m, got {steps}", field="step")
    nx, ny = (round(s / d) + 1 for s, d in zip(sizes, steps, strict=True))
    return PlaneGrid.centered(nx, ny, float(steps[0]), float(steps[1]), pose)


def simulate_scan(
    model: ArrayModel | None = None,
    *,
    pose: Pose | None = None,
    grid: PlaneGrid | None = None,
    size: Sequence[float] = (36e-3, 24e-3),
    step: Sequence[float] = (0.15e-3, 0.15e-3),
    sampling_rate: float = 25e6,
    n_samples: int = 1024,
    start_time: float = 0.0,
    medium: Medium | None = None,
    recorded_medium: Medium | None = None,
    position_jitter: float | Sequence[float] = 0.0,
    calibration: HydrophoneCalibration | str | None = "default",
    snr_db: float | None = 40.0,
    seed: int | None = 0,
    quantization_bits: int | None = None,
    full_scale: float | None = None,
    band: tuple[float, float] | None = None,
    band_threshold_db: float = -30.0,
    points_per_wavelength: float = 4.0,
    dtype: type = np.float32,
    chunk_points: int = 2048,
    record_pose: bool = False,
    progress: bool | None = False,
) -> tuple[HydrophoneScan, SimulationTruth]:
    """Simulate a hydrophone raster scan of the transmitted field, with its truth.

    The array (``model``, default the ``p4-1`` preset) is sampled by midpoint quadrature
    at ≤ λ/``points_per_wavelength`` of the highest simulated frequency; its surface
    velocity (exact lens delays, paper eq. lens-delays; element apodization and delays;
    optional edge mode) is propagated to every scan point by the dense frequency-domain
    Rayleigh integral (paper eq. rayleigh-fwd-vp); the hydrophone sensitivity turns
    pressure into voltage; white Gaussian noise at a peak SNR (see
    :func:`holoprobe.simulate.noise_std_for_snr`) and quantisation are added.

    Parameters
    ----------
    model : ArrayModel, optional
        The probe; default ``ArrayModel.from_preset("p4-1")``.
    pose : Pose, optional
        True pose of the scan plane (default :data:`DEFAULT_SCAN_POSE`).
    grid : PlaneGrid, optional
        Full scan grid (its pose is the true pose); overrides ``pose``, ``size``, ``step``.
    size, step : (float, float)
        Extent and step of the scan along the plane's u (x) and v (y) axes, in m.
    sampling_rate : float
        Hz (oscilloscope rate).
    n_samples : int
        Record length nt.
    start_time : float
        Time of sample 0 after the transmit event (drive start), in s.
    medium : Medium, optional
        The true water (default 998 kg/m³, 1481 m/s).
    recorded_medium : Medium, optional
        The medium written into the measurement (what the lab believed, e.g. water 2 °C
        colder than it was); default ``medium``. The truth records both.
    position_jitter : float or (float, float, float)
        Rms scan-positioning error in m along the plane's u, v and normal axes (one
        value: the same on all three). Every scan point is recorded where the stage
        really was (its nominal position plus an independent Gaussian offset, seeded by
        ``seed``) while the measurement keeps the nominal grid; the offsets are in
        ``truth.h5`` (``position_errors``, shape (nx, ny, 3), plane axes).
    calibration : HydrophoneCalibration, "default" or None
        Hydrophone sensitivity; ``"default"``: the packaged real curve; None: record
        pressure in Pa (``quantity="pressure"``).
    snr_db : float or None
        Peak SNR of the additive white noise in dB; None: no noise.
    seed : int or None
        Seed of the noise generator.
    quantization_bits, full_scale
        Optional quantisation (see :func:`holoprobe.simulate.quantize`).
    band : (float, float), optional
        Simulated band in Hz; default from the source spectrum (``band_threshold_db``).
    band_threshold_db : float
        Level below the spectral peak that delimits the band (default −30 dB).
    points_per_wavelength : float
        Source quadrature steps are ≤ λ_min / this (default 4: λ/4).
    dtype : numpy.float32 or numpy.float64
        Precision of the Rayleigh sums and of the stored data.
    chunk_points : int
        Scan points per Rayleigh call (bounds the memory).
    record_pose : bool
        Store the true pose in the measurement's grid (default: identity, as for a real
        scan whose pose is unknown; the truth always holds it).
    progress : bool or None
        Show a progress bar (None: on a terminal).

    Returns
    -------
    (HydrophoneScan, SimulationTruth)
        Data of shape (nx, ny, n_samples) in V (or Pa) and every true parameter.
    """
    t_start = time.perf_counter()
    medium = medium or Medium()
    model = model if model is not None else ArrayModel.from_preset("p4-1")
    if not isinstance(model, ArrayModel):
        raise InputError("expected a holoprobe.simulate.ArrayModel", field="model")
    if grid is None:
        grid = _grid(pose if pose is not None else DEFAULT_SCAN_POSE, size, step)
    elif not isinstance(grid, PlaneGrid):
        raise InputError("expected a holoprobe.PlaneGrid", field="grid")
    n_samples = int(n_samples)
    if n_samples < 2:
        raise InputError(f"expected at least 2 samples, got {n_samples}", field="n_samples")
    calibration, band = _scan_options(model, medium, sampling_rate=sampling_rate, dtype=dtype,
                                      calibration=calibration, band=band,
                                      band_threshold_db=band_threshold_db,
                                      points_per_wavelength=points_per_wavelength)
    spacing = medium.sound_speed / band[1] / points_per_wavelength
    sampling = model.sample_surface(spacing)

    # target weights are not used by fwd_vp (and PlaneGrid.to_surface gives NaN for a
    # grid one point wide), so build the surface directly
    pts = grid.points()
    rng = np.random.default_rng(seed)
    jitter = _position_errors(position_jitter, grid, rng)
    if jitter is not None:
        pts = pts + jitter.reshape(-1, 3) @ np.asarray(grid.pose.rotation).T
    targets = Surface(pts, np.broadcast_to(grid.pose.normal, pts.shape), np.ones(len(pts)))
    # process compact tiles of the scan, so that each Rayleigh call needs only the short
    # record window (few frequency bins) of nearby points
    data = synthesize_pressure(model, sampling, targets, sampling_rate=sampling_rate,
                               n_samples=n_samples, start_time=start_time, band=band,
                               medium=medium, calibration=calibration, dtype=dtype,
                               groups=_tiles(grid.shape, chunk_points), progress=progress,
                               description="simulate scan")
    clean_peak = float(np.max(np.abs(data)))
    data, sigma = add_noise(data, snr_db, rng)
    data, lsb = quantize(data, quantization_bits, full_scale)
    data = data.reshape(*grid.shape, n_samples)
    quantity: Literal["voltage", "pressure"] = (
        "pressure" if calibration is None else "voltage")
    stored_grid = grid if record_pose else grid.with_pose(Pose())
    scan = HydrophoneScan(data, stored_grid, sampling_rate, start_time, quantity,
                          recorded_medium or medium,
                          calibration, model.probe_info(), model.drive, source="simulated")

    params = _scan_parameters(model, medium, recorded_medium, grid, sampling, calibration,
                              record_pose=record_pose, jitter=jitter,
                              position_jitter=position_jitter, sampling_rate=sampling_rate,
                              n_samples=n_samples, start_time=start_time, quantity=quantity,
                              band=band, band_threshold_db=band_threshold_db,
                              points_per_wavelength=points_per_wavelength, dtype=dtype)
    params["noise"] = {"snr_db": snr_db, "snr_definition": "20*log10(max|clean| / sigma)",
                       "sigma": sigma, "clean_peak": clean_peak, "seed": seed,
                       "quantization_bits": quantization_bits, "quantization_step": lsb,
                       "unit": "V" if calibration is not None else "Pa"}
    params["elapsed_s"] = time.perf_counter() - t_start
    arrays = _model_arrays(model, medium)
    if jitter is not None:
        arrays["position_errors"] = jitter
    return scan, SimulationTruth(params, arrays)


def _scan_options(model: ArrayModel, medium: Medium, *, sampling_rate: float, dtype: type,
                  calibration: HydrophoneCalibration | str | None,
                  band: tuple[float, float] | None, band_threshold_db: float,
                  points_per_wavelength: float
                  ) -> tuple[HydrophoneCalibration | None, tuple[float, float]]:
    """The checked synthesis options: the calibration (``"default"``: the packaged
    curve) and the band (default from the model, capped at fs/2)."""
    if not (np.isfinite(sampling_rate) and sampling_rate > 0):
        raise InputError(f"expected a positive rate in Hz, got {sampling_rate!r}",
                         field="sampling_rate")
    if dtype not in (np.float32, np.float64):
        raise InputError("expected numpy.float32 or numpy.float64", field="dtype")
    if isinstance(calibration, str):
        if calibration != "default":
            raise InputError(f"expected 'default', a HydrophoneCalibration or None, got "
                             f"{calibration!r}", field="calibration")
        calibration = default_calibration()
    if band is None:
        band = signal_band(model, medium, threshold_db=band_threshold_db)
    band = (float(band[0]), min(float(band[1]), 0.5 * sampling_rate))
    if not 0 < band[0] < band[1]:
        raise InputError(f"expected 0 < f_lo < f_hi ≤ fs/2, got {band}", field="band")
    if not points_per_wavelength > 0:
        raise InputError("expected a positive number", field="points_per_wavelength")
    return calibration, band


def _scan_parameters(model: ArrayModel, medium: Medium, recorded_medium: Medium | None,
                     grid: PlaneGrid, sampling: SourceSampling,
                     calibration: HydrophoneCalibration | None, *, record_pose: bool,
                     jitter: NDArray | None, position_jitter: float | Sequence[float],
                     sampling_rate: float, n_samples: int, start_time: float, quantity: str,
                     band: tuple[float, float], band_threshold_db: float,
                     points_per_wavelength: float, dtype: type) -> dict[str, Any]:
    """truth.json of the scan (without ``noise`` and ``elapsed_s``)."""
    return {
        "kind": "hydrophone_scan",
        "probe": model_parameters(model, medium),
        "scan_pose": pose_parameters(grid.pose),
        "scan_grid": {
            "nx": grid.shape[0], "ny": grid.shape[1], "dx_m": grid.dx if grid.shape[0] > 1
            else None, "dy_m": grid.dy if grid.shape[1] > 1 else None,
            "u0_m": float(grid.x[0]), "v0_m": float(grid.y[0]),
            "pose_stored_in_measurement": bool(record_pose),
            "position_jitter_rms_m": None if jitter is None else
            [float(v) for v in np.sqrt(np.mean(jitter.reshape(-1, 3) ** 2, axis=0))],
            "position_jitter_requested_m": [float(v) for v in
                                            np.broadcast_to(position_jitter, (3,))],
        },
        "record": {"sampling_rate_hz": float(sampling_rate), "n_samples": n_samples,
                   "start_time_s": float(start_time), "quantity": quantity},
        "medium": medium_parameters(medium, recorded_medium),
        "hydrophone": None if calibration is None else {
            "name": calibration.name, "polarity": calibration.polarity},
        "synthesis": {
            "method": "dense frequency-domain Rayleigh integral (fwd_vp, rigid baffle)",
            "band_hz": list(band), "band_threshold_db": band_threshold_db,
            "source_spacing_m": sampling.spacing, "n_source_points": sampling.surface.size,
            "points_per_wavelength": points_per_wavelength,
            "precision": np.dtype(dtype).name,
        },
    }


def _position_errors(rms: float | Sequence[float], grid: PlaneGrid,
                     rng: np.random.Generator) -> NDArray | None:
    """Gaussian stage-position offsets (u, v, w) in m, shape (nx, ny, 3); None if all 0."""
    sigma = np.broadcast_to(np.asarray(rms, dtype=float), (3,)).copy()
    if not (np.all(np.isfinite(sigma)) and np.all(sigma >= 0) and np.all(sigma < 1e-3)):
        raise InputError(f"expected rms errors in [0, 1 mm) in m, got {rms!r}",
                         field="position_jitter")
    if not np.any(sigma > 0):
        return None
    return rng.standard_normal((*grid.shape, 3)) * sigma


def _model_arrays(model: ArrayModel, medium: Medium) -> dict[str, NDArray]:
    geo = model.array_geometry()
    return {
        "element_positions": np.asarray(geo.positions),
        "element_normals": np.asarray(geo.normals),
        "transmit_ir": np.asarray(model.transmit_ir),
        "receive_ir": np.asarray(model.receive_ir),
        "drive_voltage": np.asarray(model.drive.voltage),
        "surface_velocity": model.surface_velocity(medium),
        "apodization": np.asarray(model.apodization),
        "element_delays": np.asarray(model.delays),
        "receive_gains": np.asarray(model.receive_gains),
        "ir_sampling_rate": np.asarray(model.ir_sampling_rate),
    }

