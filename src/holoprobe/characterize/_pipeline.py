"""The transmit characterization pipeline (paper Fig. 4, sections II D, II F, III A).

scan (voltage) → pressure (hydrophone sensitivity) → conj-FFT → signal band from the
data → scan-plane orientation → iterate { pose (θ, x0, y0, z0) → back-projection onto
the source plane z = 0 (normal velocity, NUFFT fast path) → aperture fit (W, H, x_c,
y_c) → lens focus F → reversal of the exact lens delays → mean surface velocity → onset
t0 → x0 −= x_c, y0 −= y_c, z0 += c0 t0 } → transmit impulse response (ρ0c0·ū
deconvolved by the drive) → elements, uncertainties, warnings.

Every step is a function of another module; this one only glues them, with every knob
taken from :class:`~holoprobe.characterize.CharacterizationConfig`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from holoprobe._progress import progress_iter
from holoprobe.characterize._aperture import (
    ApertureFit,
    fit_aperture,
    mean_surface_velocity,
    select_signal_bins,
)
from holoprobe.characterize._bandlimit import band_limit_gain
from holoprobe.characterize._config import CharacterizationConfig
from holoprobe.characterize._elements import (
    ElementMap,
    array_aperture,
    sound_speed_from_data,
)
from holoprobe.characterize._jitter import positioning_noise
from holoprobe.characterize._lens import LensFit, fit_lens_focus, reverse_lens_delays
from holoprobe.characterize._orientation import OrientationResult, estimate_orientation
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose
from holoprobe.measurement import DriveSignal, HydrophoneCalibration, HydrophoneScan
from holoprobe.signal import (
    SpectrumSummary,
    TransmitImpulseResponse,
    deconvolve_records,
    default_calibration,
    detect_onset,
    frequency_axis,
    noise_sigma,
    pressure_from_voltage,
    spectrum_summary,
    to_frequency,
    to_time,
    transmit_impulse_response,
)

__all__ = ["ElementEstimate", "TransmitResult", "characterize_transmit"]


@dataclass(frozen=True)
class ElementEstimate:
    """Element geometry from the fitted width W and the datasheet kerf (reference_spec 2.7
    step 10): ``w = (W − (N−1)·kerf)/N``, ``p = (W − w)/(N − 1)`` (lengths in m).

    Attributes
    ----------
    count : int
        N (datasheet; 1 when the scan carries no probe description).
    pitch, width, kerf : float
        Element pitch p, width w and the datasheet kerf.
    pitch_uncertainty, width_uncertainty : float
        Standard uncertainties (``u(W)/N`` each).
    active_fraction : float
        ``N w / W``: fraction of the aperture that radiates (kerfs do not).
    """

    count: int
    pitch: float
    width: float
    kerf: float
    pitch_uncertainty: float
    width_uncertainty: float
    active_fraction: float


@dataclass(frozen=True)
class TransmitResult:
    """Everything the transmit characterization found (SI units, radians).

    Attributes
    ----------
    pose : Pose
        Final scan-plane pose (θx, θy, θz, origin (x0, y0, z0)).
    orientation : OrientationResult
        Angles with per-bin record and uncertainties.
    aperture : ApertureFit
        Aperture fit of the last iteration (its ``width`` is the band-limited
        envelope N·p of an array, see ``aperture_width``).
    lens : LensFit or None
        Lens fit of the last iteration (None when it failed; see ``warnings``).
    lens_focus : float
        F in m (``inf``: no significant lens). The lens is centred on the aperture
        (``aperture.center_y``; the model's ``aperture_center``) wherever its delays are
        reversed or applied: transmit, receive and the exported model use that one
        centre. ``extras["lens_center_offset"]`` is the fitted y_L minus it (m).
    onset : float
        Onset t0 (s, from the emission) of the lens-corrected mean surface velocity of
        the last iteration; z0 includes c0·t0 and the IR and ``mean_velocity`` are
        advanced by it (they start at t = 0 = the emission).
    onset_uncertainty : float
        Standard uncertainty of t0 (noise bootstrap), s.
    elements : ElementEstimate
    impulse_response : TransmitImpulseResponse or None
        h_T in Pa/(V·s) at ``config.transmit.output_rate`` (None without a drive).
    ir_spectrum : SpectrumSummary
        Peak frequency and −6 dB band of h_T (of ρ0c0·ū without a drive).
    mean_velocity : ndarray, shape (nt,)
        Lens-corrected mean normal surface velocity ū (m/s), sample n at n/fs.
    mean_velocity_raw : ndarray, shape (nt,)
        The same before the final alignment (sample n at start_time + n/fs).
    onset_threshold : float
        Detection threshold (m/s) of the last onset.
    sampling_rate : float
        Rate of the scan and of ``mean_velocity`` (Hz).
    start_time : float
        Time of the scan's first sample after the emission (s).
    source_grid : PlaneGrid
        Source-plane grid (z = 0) of the back-projection.
    source_velocity : ndarray, float32, shape (nx_s, ny_s, nt)
        Back-projected normal surface velocity (m/s) in the time domain, last
        iteration, advanced like ``mean_velocity`` (sample n at n/fs).
    frequencies : ndarray, shape (nb,)
        Frequencies (Hz) of the signal band that was back-projected.
    center_frequency : float
        Frequency (Hz) of the band bin with the most energy (for the figures).
    scan_field, source_field : ndarray, complex, shape (nx, ny), (nx_s, ny_s)
        Scan pressure (Pa·s) and ρ0c0 × source velocity (Pa·s) at ``center_frequency``.
    scan_grid : PlaneGrid
        The scan grid with the final pose.
    source_field_corrected : ndarray, complex, shape (nx_s, ny_s)
        The source field at ``center_frequency`` after lens reversal (Pa·s).
    history : list of dict
        Per iteration: pose, W, H, x_c, y_c, F, t0 and the update.
    uncertainties : dict
        Standard uncertainties (SI, radians) by name.
    warnings : list of str
    timings : dict of str to float
        Seconds per step.
    config : CharacterizationConfig
    medium : Medium
    source : str
        Where the scan came from.
    aperture_width : float
        Active aperture width W in m, outer edge to outer edge: ``(N−1)·p + w`` =
        fitted envelope − datasheet kerf for an array (the fitted width itself without
        a probe description).
    extras : dict
        Diagnostics (edge energy fraction, tilt, arrival time, band, the profile-fitted
        width and the live-element scale of ū).
    element_map : ElementMap or None
        Per-element relative amplitude and delay of an array (None for a single element
        or when ``elements.enabled`` is off).
    """

    pose: Pose
    orientation: OrientationResult
    aperture: ApertureFit
    lens: LensFit | None
    lens_focus: float
    onset: float
    onset_uncertainty: float
    elements: ElementEstimate
    impulse_response: TransmitImpulseResponse | None
    ir_spectrum: SpectrumSummary
    mean_velocity: NDArray[np.float64]
    mean_velocity_raw: NDArray[np.float64]
    onset_threshold: float
    sampling_rate: float
    start_time: float
    source_grid: PlaneGrid
    source_velocity: NDArray[np.float32]
    frequencies: NDArray[np.float64]
    center_frequency: float
    scan_field: NDArray[np.complex128]
    source_field: NDArray[np.complex128]
    source_field_corrected: NDArray[np.complex128]
    scan_grid: PlaneGrid
    history: list[dict[str, Any]]
    uncertainties: dict[str, float]
    warnings: list[str]
    timings: dict[str, float]
    config: CharacterizationConfig
    medium: Medium
    source: str = ""
    aperture_width: float = float("nan")
    extras: dict[str, Any] = field(default_factory=dict)
    element_map: ElementMap | None = None


class _Timer:
    def __init__(self) -> None:
        self.times: dict[str, float] = {}

    def add(self, name: str, start: float) -> None:
        self.times[name] = self.times.get(name, 0.0) + time.perf_counter() - start


def _pressure(scan: HydrophoneScan, calibration: HydrophoneCalibration | None,
              warnings: list[str], cfg: CharacterizationConfig) -> NDArray:
    if scan.quantity == "pressure":
        return np.asarray(scan.data, dtype=np.float32)
    cal = calibration if calibration is not None else scan.calibration
    if cal is None:
        cal = default_calibration()
        warnings.append("no hydrophone calibration given or stored with the scan: used the "
                        "packaged fibre-optic hydrophone curve (pass --sensitivity)")
    if cal.phase is not None:  # complex calibration: as `holoprobe hydrophone deconvolve`
        pressure, _ = deconvolve_records(np.asarray(scan.data, dtype=np.float32),
                                         scan.sampling_rate, cal, config=cfg.hydrophone)
        return pressure
    return pressure_from_voltage(np.asarray(scan.data, dtype=np.float32), scan.sampling_rate,
                                 cal)


def _signal_band(spectrum: NDArray, freqs: NDArray[np.float64], cfg: CharacterizationConfig
                 ) -> NDArray[np.intp]:
    """The contiguous run of bins around the strongest one whose energy ``Σ|P|²``
    (moving average over ``band.smooth_bins``) is within ``band.threshold_db`` of the
    peak and ``band.min_snr_db`` above the noise floor (the ``band.noise_percentile``
    percentile of the bin energies): isolated noise bins do not stretch the band."""
    candidates = select_signal_bins(spectrum, freqs, band=cfg.band.band,
                                    threshold_db=cfg.band.threshold_db)
    energy = np.einsum("ijf,ijf->f", spectrum, np.conj(spectrum)).real.astype(float)
    allowed = np.zeros(freqs.size, bool)
    allowed[candidates.min():candidates.max() + 1] = True
    allowed &= freqs > 0
    n_smooth = max(1, int(cfg.band.smooth_bins))
    smooth = np.convolve(energy, np.ones(n_smooth) / n_smooth, mode="same")
    smooth = np.where(allowed, smooth, 0.0)
    peak = int(np.argmax(smooth))
    # noise floor: a low percentile of the smoothed bin energies (white noise spreads
    # evenly over all bins, the signal does not); long records put the noise of every
    # bin close to the relative threshold, so both criteria apply
    floor = float(np.percentile(smooth[allowed], cfg.band.noise_percentile))
    level = max(smooth[peak] * 10.0 ** (-cfg.band.threshold_db / 10.0),
                floor * 10.0 ** (cfg.band.min_snr_db / 10.0))
    above = smooth >= level
    lo = hi = peak
    while lo > 0 and above[lo - 1]:
        lo -= 1
    while hi < freqs.size - 1 and above[hi + 1]:
        hi += 1
    return np.arange(lo, hi + 1)


def _initial_z0(spec_band: NDArray, bins: NDArray, nt: int, scan: HydrophoneScan,
                cfg: CharacterizationConfig, warnings: list[str]) -> tuple[float, float | None]:
    """Starting z0 = c0 × arrival time at the strongest trace (see IterationConfig)."""
    it = cfg.iterations
    if it.initial_z0 is not None:
        return float(it.initial_z0), None
    fs = scan.sampling_rate
    energy = np.sum(np.abs(spec_band) ** 2, axis=2)
    i, j = np.unravel_index(int(np.argmax(energy)), energy.shape)
    full = np.zeros(nt // 2 + 1, complex)
    full[bins] = spec_band[i, j]
    trace = to_time(full, nt)
    try:
        t_rel = detect_onset(trace, fs, threshold=cfg.onset.threshold,
                             upsample=cfg.onset.upsample, polarity=cfg.onset.polarity,
                             allow_wrap=False, min_noise_samples=cfg.onset.min_noise_samples)
    except FitError:
        t_rel = np.nan
    arrival = scan.start_time + t_rel
    z0 = scan.medium.sound_speed * arrival
    lo, hi = it.z0_range
    if not (np.isfinite(z0) and lo <= z0 <= hi):
        warnings.append(f"could not estimate the scan distance from the arrival time "
                        f"(got {z0 * 1e3:.3g} mm); started from z0 = "
                        f"{it.fallback_z0 * 1e3:.3g} mm")
        return float(it.fallback_z0), float(arrival) if np.isfinite(arrival) else None
    return float(z0), float(arrival)


def _source_grid(scan_grid: PlaneGrid, pose: Pose, margin: float) -> PlaneGrid:
    """Grid on z = 0 with the scan's steps, aligned on multiples of the step, covering
    the footprint of the (posed) scan plane plus ``margin``."""
    corners = np.array([[u, v, 0.0] for u in (scan_grid.x[0], scan_grid.x[-1])
                        for v in (scan_grid.y[0], scan_grid.y[-1])])
    pts = pose.to_global(corners)
    dx, dy = scan_grid.dx, scan_grid.dy
    ix0 = int(np.floor((pts[:, 0].min() - margin) / dx + 1e-9))
    ix1 = int(np.ceil((pts[:, 0].max() + margin) / dx - 1e-9))
    iy0 = int(np.floor((pts[:, 1].min() - margin) / dy + 1e-9))
    iy1 = int(np.ceil((pts[:, 1].max() + margin) / dy - 1e-9))
    return PlaneGrid(np.arange(ix0, ix1 + 1) * dx, np.arange(iy0, iy1 + 1) * dy, Pose())


def _noise_window(nt: int, fs: float, z0: float, c0: float, cfg: CharacterizationConfig
                  ) -> tuple[float, float] | None:
    if cfg.onset.noise_window is not None:
        return cfg.onset.noise_window
    duration = nt / fs
    length = cfg.onset.noise_window_fraction * z0 / c0
    if length * fs < cfg.onset.min_noise_samples or length >= 0.5 * duration:
        return None
    return (duration - length, duration)


def _edge_fraction(spec_band: NDArray, width: int) -> float:
    energy = np.sum(np.abs(spec_band) ** 2, axis=2)
    total = float(energy.sum())
    w = int(max(1, min(width, min(energy.shape) // 4)))
    inner = float(energy[w:-w, w:-w].sum())
    return (total - inner) / total if total > 0 else 0.0


def characterize_transmit(
    scan: HydrophoneScan,
    config: CharacterizationConfig | None = None,
    *,
    drive: DriveSignal | None = None,
    calibration: HydrophoneCalibration | None = None,
    progress: bool | None = None,
) -> TransmitResult:
    """Characterize the transmit side of a probe from a hydrophone scan (paper Fig. 4).

    Parameters
    ----------
    scan : HydrophoneScan
        The raster scan (voltage with a calibration, or pressure), shape (nx, ny, nt).
        Its time origin ``start_time`` is taken as the emission (the drive's first
        sample); a trigger latency ends up in z0 (reference_spec section 7, item 5).
    config : CharacterizationConfig, optional
        Every knob (defaults: :class:`CharacterizationConfig()`).
    drive : DriveSignal, optional
        Drive voltage (default ``scan.drive``). Without one, no impulse response is
        computed (a warning says so).
    calibration : HydrophoneCalibration, optional
        Hydrophone sensitivity (default ``scan.calibration``, then the packaged curve
        with a warning).
    progress : bool or None
        Progress bars on the long steps (None: on a terminal).

    Returns
    -------
    TransmitResult

    Raises
    ------
    InputError
        A scan that is not a HydrophoneScan, no frequency bin with signal, no aperture
        edge, no onset in the mean surface velocity, or what a step raises for bad data.

    Notes
    -----
    Steps (each a function of its own module):

    1. pressure (:func:`holoprobe.signal.pressure_from_voltage`), spectrum
       ``P = dt·conj(FFT p)`` (paper eq. complex-conjugate-fourier);
    2. signal band: the contiguous range of bins within ``band.threshold_db`` of the
       strongest bin (``select_signal_bins``);
    3. orientation (paper section II D, :func:`estimate_orientation`);
    4. starting z0 (``iterations.initial_z0``, see :class:`IterationConfig`);
    5. per iteration: back-projection (``ProjectionPlan.project(..., quantity="normal_velocity")``
       onto a grid on z = 0 with the scan's steps covering the scan footprint;
       :func:`fit_aperture`; :func:`fit_lens_focus`; :func:`reverse_lens_delays` (exact
       delays, paper eq. lens-delays); :func:`mean_surface_velocity`; onset
       t0 (:func:`holoprobe.signal.detect_onset`); ``x0 −= x_c, y0 −= y_c, z0 += c0 t0``;
       stop after ``iterations.count`` or when the update is below the tolerance;
    6. ū is advanced by t0 (onset at t = 0, consistent with the updated z0) and the
       transmit IR computed from ρ0c0·ū (:func:`transmit_impulse_response`, paper eqs.
       transmit-impulse-response, deconvolution-transmit), divided by the active
       fraction ``N w / W``, resampled to ``transmit.output_rate``;
    7. elements from W and the datasheet kerf; standard uncertainties; warnings.
    """
    from holoprobe.propagation import ProjectionPlan

    t_total = time.perf_counter()
    cfg = CharacterizationConfig() if config is None else config
    if not isinstance(scan, HydrophoneScan):
        raise InputError("expected a holoprobe.measurement.HydrophoneScan", field="scan")
    if not isinstance(cfg, CharacterizationConfig):
        raise InputError("expected a CharacterizationConfig", field="config")
    timer = _Timer()
    warnings: list[str] = []
    medium = scan.medium
    c0, z_ac = medium.sound_speed, medium.impedance
    fs = scan.sampling_rate
    dt = 1.0 / fs
    nt = scan.n_samples
    drive = drive if drive is not None else scan.drive

    # 1. pressure and spectrum ---------------------------------------------------------
    t = time.perf_counter()
    pressure = _pressure(scan, calibration, warnings, cfg)
    timer.add("pressure", t)
    t = time.perf_counter()
    freqs = frequency_axis(nt, fs)
    spectrum = to_frequency(pressure)  # (nx, ny, nf), complex64 for float32 data
    del pressure
    timer.add("spectrum", t)

    # 2. band ----------------------------------------------------------------------------
    t = time.perf_counter()
    bins = _signal_band(spectrum, freqs, cfg)
    fb = freqs[bins]
    spec_band = np.ascontiguousarray(spectrum[:, :, bins], dtype=np.complex128) * dt
    del spectrum
    step = max(scan.grid.dx, scan.grid.dy)
    if step > c0 / fb[-1] / 2 * (1 + 1e-9):
        warnings.append(f"scan step {step * 1e3:.3g} mm is coarser than λ/2 = "
                        f"{c0 / fb[-1] / 2 * 1e3:.3g} mm at the top of the signal band "
                        f"({fb[-1] / 1e6:.3g} MHz): the field is aliased")
    jitter = positioning_noise(spec_band, scan.grid, fb, c0)
    edge = _edge_fraction(spec_band, cfg.warnings.edge_width)
    if edge > cfg.warnings.edge_energy_fraction:
        warnings.append(f"field not captured at the scan edges: the outer "
                        f"{cfg.warnings.edge_width} points hold {edge:.1%} of the energy "
                        f"(threshold {cfg.warnings.edge_energy_fraction:.1%})")
    timer.add("band", t)

    # 3. orientation ---------------------------------------------------------------------
    t = time.perf_counter()
    oc = cfg.orientation
    orientation = estimate_orientation(
        spec_band, scan.grid, fb, medium,
        energy_threshold=10.0 ** (-oc.energy_threshold_db / 10.0),
        spectrum_weighting=oc.spectrum_weighting, theta_z_bounds_deg=oc.theta_z_bounds_deg,
        outlier_threshold=oc.outlier_threshold, max_tilt=np.deg2rad(oc.max_tilt_deg))
    timer.add("orientation", t)
    tilt = float(np.degrees(np.arccos(np.cos(orientation.theta_x)
                                      * np.cos(orientation.theta_y))))
    if tilt > cfg.warnings.max_tilt_deg:
        warnings.append(f"scan-plane tilt {tilt:.2f}° is larger than expected "
                        f"({cfg.warnings.max_tilt_deg:g}°)")
    at_bound = sum("search bound" in r for r in orientation.reasons)
    with_signal = sum("energy below threshold" not in r and "outside band" not in r
                      for r in orientation.reasons)
    if at_bound > cfg.warnings.theta_z_bound_fraction * max(with_signal, 1):
        warnings.append(f"theta_z of {at_bound} of {with_signal} frequency bins with signal "
                        f"lies at the search bound {oc.theta_z_bounds_deg} deg (widen "
                        "orientation.theta_z_bounds_deg)")

    # 4. starting distance -----------------------------------------------------------------
    t = time.perf_counter()
    z0, arrival = _initial_z0(spec_band, bins, nt, scan, cfg, warnings)
    if arrival is not None and arrival - scan.start_time < cfg.warnings.onset_margin:
        warnings.append(f"the wavefront arrives {(arrival - scan.start_time) * 1e6:.3g} µs "
                        "after the start of the record: the pulse may be cut")
    timer.add("initial_z0", t)
    x0 = y0 = 0.0

    # 5. iterations ----------------------------------------------------------------------
    bp = cfg.backprojection
    array_probe = (cfg.elements.enabled and scan.probe is not None
                   and scan.probe.element_count > 1)
    element_map = None
    map_warnings = []
    profile_width = float("nan")
    history: list[dict[str, Any]] = []
    aperture = lens = None
    onset = onset_rel = 0.0
    onset_threshold = 0.0
    noise_u = 0.0
    u_rec = np.zeros(nt)
    velocity = None
    src_grid = None
    # one plan: the scan's padded angular spectrum is computed in the first iteration and
    # reused by the later ones (the pose only changes phases)
    plan = ProjectionPlan(spec_band, scan.grid, fb, medium, eps=bp.eps,
                          guard_angle=np.deg2rad(bp.guard_angle_deg),
                          single_precision=bp.single_precision, allow_undersampled=True)
    for n in progress_iter(range(cfg.iterations.count), description="iterations",
                           enabled=progress):
        pose = orientation.pose(origin=(x0, y0, z0))
        src_grid = _source_grid(scan.grid, pose, bp.margin)
        t = time.perf_counter()
        velocity = plan.with_pose(pose).project(src_grid, quantity="normal_velocity",
                                                progress=progress)
        timer.add("backprojection", t)
        t = time.perf_counter()
        aperture = fit_aperture(velocity, src_grid, fb, medium,
                                threshold_db=cfg.aperture.threshold_db,
                                profile=cfg.aperture.profile,
                                fit_offset=cfg.aperture.fit_offset,
                                start_level=cfg.aperture.start_level)
        timer.add("aperture", t)
        if array_probe:
            t = time.perf_counter()
            map_warnings: list[str] = []
            aperture, element_map, profile_width = array_aperture(
                aperture, velocity, src_grid, fb, probe=scan.probe, scan_grid=scan.grid,
                pose=pose, sound_speed=c0, config=cfg.elements, warnings=map_warnings)
            timer.add("element_map", t)
        t = time.perf_counter()
        try:
            lens = fit_lens_focus(velocity, src_grid, fb, medium, aperture,
                                  threshold_db=cfg.lens.threshold_db,
                                  margin_wavelengths=cfg.lens.margin_wavelengths,
                                  significance=cfg.lens.significance,
                                  max_bins=cfg.lens.max_bins)
        except (InputError, FitError) as exc:
            lens = None
            lens_error = str(exc)
        else:
            lens_error = ""
        timer.add("lens", t)
        t = time.perf_counter()
        if lens is not None and lens.significant:
            # one lens centre everywhere: the aperture centre, as in the exported model
            # and the receive step (the fitted y_L is a nuisance parameter of the focus
            # fit: it also absorbs a residual θx, see LensFit)
            corrected = reverse_lens_delays(velocity, src_grid, fb, lens.focus,
                                            aperture.height, c0, center_y=aperture.center_y)
        else:
            corrected = velocity
        u_band = mean_surface_velocity(corrected, src_grid, aperture)
        full = np.zeros(nt // 2 + 1, complex)
        full[bins] = u_band
        u_rec = to_time(full, nt) * fs  # m/s, sample n at start_time + n/fs
        timer.add("mean_velocity", t)
        t = time.perf_counter()
        window = _noise_window(nt, fs, z0, c0, cfg)
        oc_ = cfg.onset
        noise_u = noise_sigma(u_rec, fs, noise_window=window,
                              min_noise_samples=oc_.min_noise_samples)
        try:
            onset_rel = detect_onset(u_rec, fs, threshold=oc_.threshold, noise=noise_u,
                                     polarity=oc_.polarity, upsample=oc_.upsample,
                                     allow_wrap=True)
        except FitError as exc:
            raise FitError(f"no onset in the lens-corrected mean surface velocity "
                             f"(iteration {n + 1}): {exc.detail}",
                             field="mean_surface_velocity") from None
        if onset_rel > 0.5 * nt / fs:  # a periodic record: the late half is "before 0"
            onset_rel -= nt / fs
        onset = scan.start_time + onset_rel
        onset_threshold = oc_.threshold * noise_u
        timer.add("onset", t)
        dx0, dy0, dz0 = -aperture.center_x, -aperture.center_y, c0 * onset
        history.append({
            "iteration": n + 1, "theta_deg": list(orientation.angles_deg),
            "origin": [x0, y0, z0], "width": aperture.width, "height": aperture.height,
            "center_x": aperture.center_x, "center_y": aperture.center_y,
            "lens_focus": None if lens is None else lens.focus, "onset": onset,
            "update": [dx0, dy0, dz0]})
        x0, y0, z0 = x0 + dx0, y0 + dy0, z0 + dz0
        if max(abs(dx0), abs(dy0), abs(dz0)) < cfg.iterations.tolerance:
            break

    assert aperture is not None and velocity is not None and src_grid is not None
    del plan  # its cached spectra are not needed any more
    pose = orientation.pose(origin=(x0, y0, z0))
    if lens is None:
        warnings.append(f"the lens fit failed ({lens_error}); no lens delays reversed")
        focus = float("inf")
    else:
        focus = float(lens.focus)
        if not lens.significant:
            warnings.append("the lens curvature is not significant: F reported as infinite")
        elif (abs(lens.center_y - aperture.center_y)
              > cfg.warnings.lens_center_bound_fraction * 0.5 * aperture.height):
            warnings.append("the lens centre y_L of the focus fit is at its bound (±H/2)")
        elif abs(lens.center_y - aperture.center_y) > 3 * lens.center_y_uncertainty:
            warnings.append(f"the focus fit puts the lens centre "
                            f"{(lens.center_y - aperture.center_y) * 1e6:.3g} ± "
                            f"{lens.center_y_uncertainty * 1e6:.2g} µm off the aperture "
                            f"centre (a θx error looks the same); the lens is centred on the "
                            f"aperture everywhere (transmit, receive, model)")

    warnings += map_warnings
    c_data = u_c_data = float("nan")
    if element_map is not None and cfg.elements.fit_sound_speed:
        t = time.perf_counter()
        c_data, u_c_data = sound_speed_from_data(
            velocity, src_grid, fb, probe=scan.probe, scan_grid=scan.grid,
            pose=orientation.pose(origin=tuple(history[-1]["origin"])), sound_speed=c0,
            config=cfg.elements)
        timer.add("sound_speed", t)
        if np.isfinite(c_data) and abs(c_data - c0) > u_c_data:
            warnings.append(f"the sound speed from the data, {c_data:.1f} ± {u_c_data:.1f} "
                            f"m/s, disagrees with the file's {c0:.1f} m/s (check the water "
                            "temperature; --water-temperature or --sound-speed)")
    live_scale = _live_scale(element_map, profile_width, warnings,
                             cfg.elements.width_warning_pitches)
    u_band = u_band * live_scale

    # 6. alignment, IR -------------------------------------------------------------------
    t = time.perf_counter()
    shift = onset - scan.start_time  # advance so that the onset is at t = 0
    phase = np.exp(-2j * np.pi * fb * shift)
    gain = np.ones(fb.size)
    if cfg.transmit.band_limit_correction:
        gain = band_limit_gain(
            src_grid, fb, medium, width=aperture.width, height=aperture.height,
            center_x=aperture.center_x, center_y=aperture.center_y,
            focus=focus if lens is not None and lens.significant else float("inf"),
            lens_center_y=None if lens is None else lens.center_y)
    full = np.zeros(nt // 2 + 1, complex)
    full[bins] = u_band / gain * phase
    mean_velocity = to_time(full, nt) * fs
    probe = scan.probe
    if probe is not None:
        count = probe.element_count
        kerf = probe.kerf
        if count > 1:
            # the band-limited source of N elements at pitch p is (w/p)·rect of width
            # N·p: the fit measures the envelope N·p, the outer-edge width is N·p − kerf.
            # reference_spec 2.7 step 10 applied to that edge width W_e = W − kerf:
            outer = aperture.width - kerf
            width = (outer - (count - 1) * kerf) / count
            pitch = (outer - width) / (count - 1)
        else:
            width = pitch = aperture.width
        if not 0 < width <= pitch:
            warnings.append(f"the fitted width W = {aperture.width * 1e3:.4g} mm leaves no "
                            f"room for {count} elements with kerf {kerf * 1e3:.3g} mm")
            width = pitch = aperture.width / count
    else:
        warnings.append("no probe description (element count, kerf): reported as one "
                        "element of width W")
        count, kerf, width, pitch = 1, 0.0, aperture.width, aperture.width
    fraction = count * width / aperture.width
    elements = ElementEstimate(count=int(count), pitch=float(pitch), width=float(width),
                               kerf=float(kerf),
                               pitch_uncertainty=aperture.width_uncertainty / count,
                               width_uncertainty=aperture.width_uncertainty / count,
                               active_fraction=float(fraction))
    edge_width = count * pitch - kerf if count > 1 else aperture.width
    tc = cfg.transmit
    duration = tc.duration if tc.duration is not None else nt / fs - z0 / c0
    n_keep = int(np.clip(round(duration * fs), 8, nt))
    response = z_ac * mean_velocity[:n_keep]
    ir = None
    if drive is None:
        warnings.append("no drive voltage (pass --drive): no transmit impulse response; "
                        "the spectrum summary describes ρ0c0·ū")
        summary = spectrum_summary(response, fs)
    else:
        ir = transmit_impulse_response(response, fs, drive, method=tc.method,
                                       output_rate=tc.output_rate,
                                       delta_tolerance=tc.delta_tolerance,
                                       active_fraction=fraction)
        summary = spectrum_summary(ir.ir, ir.sampling_rate)
    timer.add("transmit_ir", t)

    # source velocity in the time domain (advanced like ū), float32 ------------------------
    t = time.perf_counter()
    nxs, nys = src_grid.shape
    spec_src = np.zeros((nxs, nys, nt // 2 + 1), np.complex64)
    spec_src[:, :, bins] = (velocity * phase) * fs
    source_velocity = to_time(spec_src, nt).astype(np.float32)
    del spec_src
    timer.add("source_velocity", t)

    # 7. uncertainty of t0: noise bootstrap --------------------------------------------
    t = time.perf_counter()
    oc_ = cfg.onset
    u_onset = float("nan")
    if oc_.bootstrap > 0 and noise_u > 0:
        rng = np.random.default_rng(oc_.seed)
        draws = []
        for _ in range(oc_.bootstrap):
            try:
                noisy = u_rec + rng.normal(0.0, noise_u, nt)
                draws.append(detect_onset(noisy, fs, threshold=oc_.threshold, noise=noise_u,
                                          polarity=oc_.polarity, upsample=oc_.upsample,
                                          allow_wrap=True))
            except FitError:
                continue
        if len(draws) >= 2:
            d = np.asarray(draws)
            d = np.where(d > 0.5 * nt / fs, d - nt / fs, d)
            u_onset = float(np.std(d, ddof=1))
    timer.add("uncertainty", t)

    kb = int(np.argmax(np.sum(np.abs(spec_band) ** 2, axis=(0, 1))))
    source_field = z_ac * velocity[:, :, kb]
    source_corr = z_ac * (reverse_lens_delays(velocity[:, :, kb:kb + 1], src_grid, fb[kb:kb + 1],
                                              lens.focus, aperture.height, c0,
                                              center_y=aperture.center_y)[:, :, 0]
                          if lens is not None and lens.significant else velocity[:, :, kb])
    uncertainties = {
        "theta_x": orientation.u_theta_x, "theta_y": orientation.u_theta_y,
        "theta_z": orientation.u_theta_z,
        "x0": aperture.center_x_uncertainty, "y0": aperture.center_y_uncertainty,
        "z0": c0 * u_onset,
        "width": aperture.width_uncertainty, "edge_width": aperture.width_uncertainty,
        "height": aperture.height_uncertainty,
        "center_x": aperture.center_x_uncertainty, "center_y": aperture.center_y_uncertainty,
        "lens_focus": float("inf") if lens is None else lens.focus_uncertainty,
        "onset": u_onset,
        "pitch": elements.pitch_uncertainty, "element_width": elements.width_uncertainty,
    }
    timer.times["total"] = time.perf_counter() - t_total
    return TransmitResult(
        pose=pose, orientation=orientation, aperture=aperture, lens=lens, lens_focus=focus,
        onset=float(onset), onset_uncertainty=u_onset, elements=elements,
        impulse_response=ir, ir_spectrum=summary, mean_velocity=mean_velocity,
        mean_velocity_raw=u_rec, onset_threshold=float(onset_threshold), sampling_rate=fs,
        start_time=float(scan.start_time), source_grid=src_grid,
        source_velocity=source_velocity, frequencies=fb, center_frequency=float(fb[kb]),
        scan_field=spec_band[:, :, kb].copy(), source_field=source_field,
        source_field_corrected=source_corr, scan_grid=scan.grid.with_pose(pose),
        history=history, uncertainties=uncertainties, warnings=warnings,
        timings=dict(timer.times), config=cfg, medium=medium, source=scan.source,
        aperture_width=float(edge_width),
        extras={"edge_energy_fraction": edge, "tilt_deg": tilt, "arrival_time": arrival,
                "noise_sigma_velocity": noise_u, "band": (float(fb[0]), float(fb[-1])),
                "band_limit_gain": (float(gain.min()), float(gain.max())),
                "profile_width": profile_width, "live_scale": live_scale,
                "positioning_noise": jitter.rms,
                "positioning_noise_uncertainty": jitter.uncertainty,
                "sound_speed_from_data": c_data,
                "sound_speed_from_data_uncertainty": u_c_data,
                "lens_center_offset": (float(lens.center_y - aperture.center_y)
                                       if lens is not None and lens.significant else 0.0)},
        element_map=element_map,
    )


def _live_scale(element_map: ElementMap | None, profile_width: float,
                warnings: list[str], pitches: float) -> float:
    """Factor that turns the aperture mean of the velocity into the mean of the live
    elements (``N / Σ A_e``, live mean of A = 1), with the warnings of the map."""
    if element_map is None:
        return 1.0
    m = element_map
    nominal = m.count * m.pitch
    if np.isfinite(profile_width) and abs(profile_width - nominal) > pitches * m.pitch:
        warnings.append(f"the fitted aperture width {profile_width * 1e3:.4g} mm (profile "
                        f"fit) disagrees with the nominal array width {nominal * 1e3:.4g} mm "
                        f"({m.count} × {m.pitch * 1e3:.4g} mm): the element map explains "
                        "the difference; the nominal width is used")
    if m.dead:
        warnings.append(f"dead elements (0-based, RF column order): {list(m.dead)}; left "
                        "out of the mean surface velocity and the transmit IR")
    if m.weak:
        warnings.append(f"weak elements (0-based): {list(m.weak)} (relative amplitude "
                        f"{', '.join(f'{m.relative_amplitude[i]:.2f}' for i in m.weak)})")
    if m.ambiguous:
        warnings.append("an edge element is dead: the transmit scan alone cannot tell which "
                        "end of the array it is (the map could be shifted by one element); "
                        "the receive echo (dead RF channel) resolves it")
    if not (m.dead or m.weak):
        return 1.0
    total = float(np.sum(np.clip(m.relative_amplitude, 0.0, None)))
    return m.count / total if total > 0 else 1.0
