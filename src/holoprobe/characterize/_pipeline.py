"""The transmit characterization pipeline (paper Fig. 4, sections II D, II F, III A).

scan (voltage) → pressure (hydrophone sensitivity) → conj-FFT → signal band from the
data → scan-plane orientation → iterate { pose (θ, x0, y0, z0) → back-projection onto
the source plane z = 0 (normal velocity, NUFFT fast path) → aperture fit (W, H, x_c,
y_c) → lens focus F → reversal of the exact lens delays → mean surface velocity → onset
t0 → x0 −= x_c, y0 −= y_c, z0 += c0 t0 } → transmit impulse response (ρ0c0·ū
deconvolved by the drive) → elements, uncertainties, warnings.

The module reads in the order of the scan: the result nouns, then one function per step
(:func:`scan_pressure`, :func:`signal_band`, :func:`scan_orientation`,
:func:`initial_distance`, :func:`iterate_pose` = :func:`estimate_source` per pass,
:func:`lens_focus_warnings`, :func:`data_sound_speed`, :func:`align_to_onset`,
:func:`element_estimate`, :func:`transmit_response`, :func:`source_velocity_in_time`,
:func:`onset_uncertainty`), then the driver :func:`characterize_transmit` that calls them
in that order. Every step takes its section of
:class:`~holoprobe.characterize.CharacterizationConfig`; the estimators themselves
(orientation, aperture, lens, element map, onset, IR) live in their own modules.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.fft
from numpy.typing import NDArray

from holoprobe._progress import progress_iter
from holoprobe.characterize._aperture import (
    ApertureFit,
    bins_view,
    fit_aperture,
    mean_surface_velocity,
    select_signal_bins,
)
from holoprobe.characterize._aperture_bias import Strips, face_plane
from holoprobe.characterize._bandlimit import band_limit_gain
from holoprobe.characterize._config import (
    BandConfig,
    CharacterizationConfig,
    ElementsConfig,
    LensConfig,
    OnsetConfig,
    TransmitIRConfig,
    WarningConfig,
)
from holoprobe.characterize._elements import (
    ElementMap,
    array_aperture,
    element_map_with_sound_speed,
    with_steering,
)
from holoprobe.characterize._jitter import PositioningNoise, positioning_noise
from holoprobe.characterize._lens import (
    LensFit,
    fit_lens_focus,
    lens_reversal,
    reverse_lens_delays,
)
from holoprobe.characterize._matrix import (
    MatrixElementMap,
    lattice_aperture,
    lattice_pose_correction,
    lattice_pose_uncertainty,
    matrix_aperture,
    matrix_map_options,
    matrix_window_bias,
    remove_lattice_bias,
)
from holoprobe.characterize._orientation import OrientationResult, estimate_orientation
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose
from holoprobe.measurement import (
    DriveSignal,
    HydrophoneCalibration,
    HydrophoneScan,
    ProbeInfo,
)
from holoprobe.signal import (
    SpectrumSummary,
    Threads,
    TransmitImpulseResponse,
    bin_energy,
    blas_threads,
    deconvolve_records,
    default_calibration,
    detect_onset,
    frequency_axis,
    noise_sigma,
    pressure_from_voltage,
    pressure_spectrum_from_voltage,
    spectrum_summary,
    to_frequency,
    to_time,
    transmit_impulse_response,
    workers,
)

if TYPE_CHECKING:
    from holoprobe.propagation import ProjectionPlan

# the step functions are exported by holoprobe.characterize
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
        Lens-corrected mean normal surface velocity ū (m/s), sample n at n/fs; of an
        array with an element map, the live elements' common velocity (their delays'
        spread and the dead ones undone: :func:`align_to_onset`).
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
        or when ``elements.enabled`` is off); a :class:`MatrixElementMap` for a 2-D
        matrix array.
    aperture_height : float
        2-D matrix arrays: outer-edge height ``(n_y − 1)·p_y + h`` in m (NaN otherwise:
        the aperture height is ``aperture.height``).
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
    aperture_height: float = float("nan")


class _Timer:
    """Seconds per named step (summed over the iterations)."""

    def __init__(self) -> None:
        self.times: dict[str, float] = {}

    @contextmanager
    def __call__(self, name: str) -> Iterator[None]:
        start = time.perf_counter()
        try:
            yield
        finally:
            self.times[name] = self.times.get(name, 0.0) + time.perf_counter() - start


# --------------------------------------------------------------------------------------
# The steps, in the order the scan goes through them (paper Fig. 4)
# --------------------------------------------------------------------------------------
def scan_pressure(scan: HydrophoneScan, calibration: HydrophoneCalibration | None,
                  warnings: list[str], config: CharacterizationConfig) -> NDArray:
    """Step 1: the scan in Pa, shape (nx, ny, nt), float32.

    A pressure scan is returned as is; a voltage scan is divided by the hydrophone
    sensitivity (``calibration``, else the scan's, else the packaged curve with a
    warning), or deconvolved with the ``hydrophone`` section when the calibration has a
    phase (as ``holoprobe hydrophone deconvolve``).
    """
    if scan.quantity == "pressure":
        return np.asarray(scan.data, dtype=np.float32)
    cal = _scan_calibration(scan, calibration, warnings)
    if cal.phase is not None:  # complex calibration: as `holoprobe hydrophone deconvolve`
        pressure, _ = deconvolve_records(np.asarray(scan.data, dtype=np.float32),
                                         scan.sampling_rate, cal, config=config.hydrophone)
        return pressure
    return pressure_from_voltage(np.asarray(scan.data, dtype=np.float32), scan.sampling_rate,
                                 cal)


def _scan_calibration(scan: HydrophoneScan, calibration: HydrophoneCalibration | None,
                      warnings: list[str]) -> HydrophoneCalibration:
    """The hydrophone calibration of a voltage scan: ``calibration``, else the scan's,
    else the packaged curve (with a warning)."""
    cal = calibration if calibration is not None else scan.calibration
    if cal is None:
        cal = default_calibration()
        warnings.append("no hydrophone calibration given or stored with the scan: used the "
                        "packaged fibre-optic hydrophone curve (pass --sensitivity)")
    return cal


def scan_spectrum(scan: HydrophoneScan, calibration: HydrophoneCalibration | None,
                  warnings: list[str], config: CharacterizationConfig) -> NDArray:
    """Steps 1 and 2's spectrum: ``conj(FFT p)`` of :func:`scan_pressure`'s pressure,
    shape (nx, ny, nt // 2 + 1), complex64. A voltage scan with an amplitude-only
    calibration goes straight from the voltage's spectrum
    (:func:`~holoprobe.signal.pressure_spectrum_from_voltage`: no inverse FFT to the
    pressure and FFT back)."""
    cal = calibration
    if scan.quantity != "pressure":
        cal = _scan_calibration(scan, calibration, warnings)
        if cal.phase is None:
            return pressure_spectrum_from_voltage(np.asarray(scan.data, dtype=np.float32),
                                                  scan.sampling_rate, cal)
    return to_frequency(scan_pressure(scan, cal, warnings, config))


_pressure = scan_pressure  # the receive pipeline's name for it


@dataclass(frozen=True)
class BandSpectrum:
    """The scan spectrum in the signal band (step 2, :func:`signal_band`).

    Attributes
    ----------
    bins : ndarray of int, shape (nb,)
        Indices of the band in the record's one-sided frequency axis.
    frequencies : ndarray, shape (nb,)
        Their frequencies (Hz).
    spectrum : ndarray, complex128, shape (nx, ny, nb)
        Scan pressure spectrum ``dt·conj(FFT p)`` (Pa·s) in the band.
    edge_energy_fraction : float
        Fraction of the energy in the scan's border (``warnings.edge_width`` points).
    positioning : PositioningNoise
        Scan positioning noise from the phase residuals.
    """

    bins: NDArray[np.intp]
    frequencies: NDArray[np.float64]
    spectrum: NDArray[np.complex128]
    edge_energy_fraction: float
    positioning: PositioningNoise


def _band_bins(spectrum: NDArray, freqs: NDArray[np.float64], band: BandConfig
               ) -> NDArray[np.intp]:
    """The contiguous run of bins around the strongest one whose energy ``Σ|P|²``
    (moving average over ``band.smooth_bins``) is within ``band.threshold_db`` of the
    peak and ``band.min_snr_db`` above the noise floor (the ``band.noise_percentile``
    percentile of the bin energies): isolated noise bins do not stretch the band."""
    candidates = select_signal_bins(spectrum, freqs, band=band.band,
                                    threshold_db=band.threshold_db)
    energy = bin_energy(spectrum)
    allowed = np.zeros(freqs.size, bool)
    allowed[candidates.min():candidates.max() + 1] = True
    allowed &= freqs > 0
    n_smooth = max(1, int(band.smooth_bins))
    smooth = np.convolve(energy, np.ones(n_smooth) / n_smooth, mode="same")
    smooth = np.where(allowed, smooth, 0.0)
    peak = int(np.argmax(smooth))
    # noise floor: a low percentile of the smoothed bin energies (white noise spreads
    # evenly over all bins, the signal does not); long records put the noise of every
    # bin close to the relative threshold, so both criteria apply
    floor = float(np.percentile(smooth[allowed], band.noise_percentile))
    level = max(smooth[peak] * 10.0 ** (-band.threshold_db / 10.0),
                floor * 10.0 ** (band.min_snr_db / 10.0))
    above = smooth >= level
    lo = hi = peak
    while lo > 0 and above[lo - 1]:
        lo -= 1
    while hi < freqs.size - 1 and above[hi + 1]:
        hi += 1
    return np.arange(lo, hi + 1)


def _edge_fraction(spec_band: NDArray, width: int) -> float:
    energy = np.sum(np.abs(spec_band) ** 2, axis=2)
    total = float(energy.sum())
    w = int(max(1, min(width, min(energy.shape) // 4)))
    inner = float(energy[w:-w, w:-w].sum())
    return (total - inner) / total if total > 0 else 0.0


def signal_band(spectrum: NDArray, frequencies: NDArray[np.float64], grid: PlaneGrid,
                sampling_rate: float, sound_speed: float, config: CharacterizationConfig,
                warnings: list[str]) -> BandSpectrum:
    """Step 2: the signal band of the scan spectrum (``band`` section), with the
    aliasing, edge-energy (``warnings`` section) and positioning-noise checks.

    Parameters
    ----------
    spectrum : ndarray, complex, shape (nx, ny, nt // 2 + 1)
        ``conj(FFT p)`` of the scan pressure (:func:`holoprobe.signal.to_frequency`).
    frequencies : ndarray, shape (nt // 2 + 1,)
        Its frequency axis (Hz, :func:`holoprobe.signal.frequency_axis`).
    grid : PlaneGrid
        The scan grid.
    sampling_rate, sound_speed : float
        Hz, m/s.
    config : CharacterizationConfig
        Its ``band`` and ``warnings`` sections.
    warnings : list of str
        Appended to.
    """
    bins = _band_bins(spectrum, frequencies, config.band)
    fb = frequencies[bins]
    dt = 1.0 / sampling_rate
    # the band's bins (a contiguous run: a view, no copy) in float64, scaled in place
    spec_band = bins_view(spectrum, bins).astype(np.complex128)
    spec_band *= dt
    step = max(grid.dx, grid.dy)
    if step > sound_speed / fb[-1] / 2 * (1 + 1e-9):
        warnings.append(f"scan step {step * 1e3:.3g} mm is coarser than λ/2 = "
                        f"{sound_speed / fb[-1] / 2 * 1e3:.3g} mm at the top of the signal "
                        f"band ({fb[-1] / 1e6:.3g} MHz): the field is aliased")
    jitter = positioning_noise(spec_band, grid, fb, sound_speed)
    wc = config.warnings
    edge = _edge_fraction(spec_band, wc.edge_width)
    if edge > wc.edge_energy_fraction:
        warnings.append(f"field not captured at the scan edges: the outer "
                        f"{wc.edge_width} points hold {edge:.1%} of the energy "
                        f"(threshold {wc.edge_energy_fraction:.1%})")
    return BandSpectrum(bins, fb, spec_band, edge, jitter)


def scan_orientation(band: BandSpectrum, grid: PlaneGrid, medium: Medium,
                     config: CharacterizationConfig, warnings: list[str]
                     ) -> tuple[OrientationResult, float]:
    """Step 3: the scan-plane angles (paper section II D, ``orientation`` section) and
    the tilt ``arccos(cos θx cos θy)`` in degrees, with the tilt and θz-bound warnings."""
    oc = config.orientation
    orientation = estimate_orientation(
        band.spectrum, grid, band.frequencies, medium,
        energy_threshold=10.0 ** (-oc.energy_threshold_db / 10.0),
        spectrum_weighting=oc.spectrum_weighting, theta_z_bounds_deg=oc.theta_z_bounds_deg,
        outlier_threshold=oc.outlier_threshold, max_tilt=np.deg2rad(oc.max_tilt_deg))
    wc = config.warnings
    tilt = float(np.degrees(np.arccos(np.cos(orientation.theta_x)
                                      * np.cos(orientation.theta_y))))
    if tilt > wc.max_tilt_deg:
        warnings.append(f"scan-plane tilt {tilt:.2f}° is larger than expected "
                        f"({wc.max_tilt_deg:g}°)")
    at_bound = sum("search bound" in r for r in orientation.reasons)
    with_signal = sum("energy below threshold" not in r and "outside band" not in r
                      for r in orientation.reasons)
    if at_bound > wc.theta_z_bound_fraction * max(with_signal, 1):
        warnings.append(f"theta_z of {at_bound} of {with_signal} frequency bins with signal "
                        f"lies at the search bound {oc.theta_z_bounds_deg} deg (widen "
                        "orientation.theta_z_bounds_deg)")
    return orientation, tilt


def initial_distance(band: BandSpectrum, n_samples: int, sampling_rate: float,
                     start_time: float, sound_speed: float, config: CharacterizationConfig,
                     warnings: list[str], trace_index: tuple[int, int] | None = None
                     ) -> tuple[float, float | None]:
    """Step 4: the starting z0 = c0 × arrival time at the strongest trace (see
    :class:`IterationConfig`) and that arrival time (s from the emission; None when
    ``iterations.initial_z0`` is given or no onset was found). ``trace_index``: the (ix, iy)
    of another trace to time (a convex array's earliest, not its strongest)."""
    it = config.iterations
    if it.initial_z0 is not None:
        return float(it.initial_z0), None
    if trace_index is None:
        energy = np.sum(np.abs(band.spectrum) ** 2, axis=2)
        ii, jj = np.unravel_index(int(np.argmax(energy)), energy.shape)
        trace_index = (int(ii), int(jj))
    i, j = trace_index
    full = np.zeros(n_samples // 2 + 1, complex)
    full[band.bins] = band.spectrum[i, j]
    trace = to_time(full, n_samples)
    oc = config.onset
    try:
        t_rel = detect_onset(trace, sampling_rate, threshold=oc.threshold,
                             upsample=oc.upsample, polarity=oc.polarity,
                             allow_wrap=False, min_noise_samples=oc.min_noise_samples)
    except FitError:
        t_rel = np.nan
    t_arrival = start_time + t_rel
    z0 = sound_speed * t_arrival
    lo, hi = it.z0_range
    arrival: float | None = float(t_arrival)
    if not (np.isfinite(z0) and lo <= z0 <= hi):
        warnings.append(f"could not estimate the scan distance from the arrival time "
                        f"(got {z0 * 1e3:.3g} mm); started from z0 = "
                        f"{it.fallback_z0 * 1e3:.3g} mm")
        z0 = float(it.fallback_z0)
        arrival = arrival if np.isfinite(t_arrival) else None
    if arrival is not None and arrival - start_time < config.warnings.onset_margin:
        warnings.append(f"the wavefront arrives {(arrival - start_time) * 1e6:.3g} µs "
                        "after the start of the record: the pulse may be cut")
    return float(z0), arrival


def source_grid(scan_grid: PlaneGrid, pose: Pose, margin: float) -> PlaneGrid:
    """The back-projection grid on z = 0: the scan's steps, aligned on multiples of the
    step, covering the footprint of the (posed) scan plane plus ``margin`` (m)."""
    corners = np.array([[u, v, 0.0] for u in (scan_grid.x[0], scan_grid.x[-1])
                        for v in (scan_grid.y[0], scan_grid.y[-1])])
    pts = pose.to_global(corners)
    dx, dy = scan_grid.dx, scan_grid.dy
    ix0 = int(np.floor((pts[:, 0].min() - margin) / dx + 1e-9))
    ix1 = int(np.ceil((pts[:, 0].max() + margin) / dx - 1e-9))
    iy0 = int(np.floor((pts[:, 1].min() - margin) / dy + 1e-9))
    iy1 = int(np.ceil((pts[:, 1].max() + margin) / dy - 1e-9))
    x = np.arange(ix0, ix1 + 1, dtype=np.float64) * dx
    y = np.arange(iy0, iy1 + 1, dtype=np.float64) * dy
    return PlaneGrid(x, y, Pose())


def lens_focus_step(velocity: NDArray, grid: PlaneGrid, frequencies: NDArray,
                    medium: Medium, aperture: ApertureFit, lens: LensConfig
                    ) -> tuple[LensFit | None, str]:
    """Step 5c: :func:`fit_lens_focus` with the ``lens`` section; a fit the data do not
    support gives ``(None, why)`` instead of an exception (the run goes on without lens
    reversal and says so)."""
    try:
        fit = fit_lens_focus(velocity, grid, frequencies, medium, aperture,
                             threshold_db=lens.threshold_db,
                             margin_wavelengths=lens.margin_wavelengths,
                             significance=lens.significance, max_bins=lens.max_bins)
    except (InputError, FitError) as exc:
        return None, str(exc)
    return fit, ""


def lens_corrected_mean_velocity(velocity: NDArray, grid: PlaneGrid, band: BandSpectrum,
                                 aperture: ApertureFit, lens: LensFit | None,
                                 sound_speed: float, n_samples: int, sampling_rate: float,
                                 *, plane_integral: bool = False
                                 ) -> tuple[NDArray[np.complex128], NDArray[np.float64]]:
    """Step 5d: reverse the lens delays (centred on the aperture, as the exported model
    and the receive step: the fitted y_L is a nuisance parameter of the focus fit, it
    also absorbs a residual θx) and average over the aperture. ``plane_integral`` (2-D
    matrix arrays): the integral over the whole source plane divided by the aperture's
    area instead (the k = 0 component, which no band limit touches).

    Returns
    -------
    u_band : ndarray, complex, shape (nb,)
        Mean normal velocity spectrum (m/s·s) in the band.
    u_rec : ndarray, shape (n_samples,)
        The same in time (m/s), sample n at ``start_time + n / sampling_rate``.
    """
    if plane_integral:
        corrected = velocity if lens is None or not lens.significant else \
            reverse_lens_delays(velocity, grid, band.frequencies, lens.focus,
                                aperture.height, sound_speed, center_y=aperture.center_y)
        u_band = corrected.sum(axis=(0, 1)) * (grid.dx * grid.dy
                                               / (aperture.width * aperture.height))
    else:  # reverse_lens_delays' factor e^{−iωτ(y)} per row, not over the whole grid
        u_band = mean_surface_velocity(velocity, grid, aperture, row_factor=None if (
            lens is None or not lens.significant) else lens_reversal(
                grid, band.frequencies, lens.focus, aperture.height, sound_speed,
                center_y=aperture.center_y))
    full = np.zeros(n_samples // 2 + 1, complex)
    full[band.bins] = u_band
    return u_band, to_time(full, n_samples) * sampling_rate


def _noise_window(nt: int, fs: float, z0: float, c0: float, onset: OnsetConfig
                  ) -> tuple[float, float] | None:
    if onset.noise_window is not None:
        return onset.noise_window
    duration = nt / fs
    length = onset.noise_window_fraction * z0 / c0
    if length * fs < onset.min_noise_samples or length >= 0.5 * duration:
        return None
    return (duration - length, duration)


def velocity_onset(u_rec: NDArray, sampling_rate: float, start_time: float, z0: float,
                   sound_speed: float, onset: OnsetConfig, *, iteration: int = 0
                   ) -> tuple[float, float, float]:
    """Step 5e: the onset t0 of the mean surface velocity (``onset`` section).

    Returns ``(t0, σ, threshold)``: t0 in s from the emission (a periodic record's late
    half counts as before 0), the noise σ of ``u_rec`` (m/s, from the record's end where
    the wavefront's earlier samples land, see :class:`OnsetConfig`) and the detection
    level (m/s). Raises :class:`FitError` when nothing crosses the level.
    """
    nt, fs = u_rec.size, sampling_rate
    window = _noise_window(nt, fs, z0, sound_speed, onset)
    noise_u = noise_sigma(u_rec, fs, noise_window=window,
                          min_noise_samples=onset.min_noise_samples)
    try:
        onset_rel = detect_onset(u_rec, fs, threshold=onset.threshold, noise=noise_u,
                                 polarity=onset.polarity, upsample=onset.upsample,
                                 allow_wrap=True)
    except FitError as exc:
        raise FitError(f"no onset in the lens-corrected mean surface velocity "
                       f"(iteration {iteration + 1}): {exc.detail}",
                       field="mean_surface_velocity") from None
    if onset_rel > 0.5 * nt / fs:  # a periodic record: the late half is "before 0"
        onset_rel -= nt / fs
    return start_time + onset_rel, noise_u, onset.threshold * noise_u


@dataclass(frozen=True)
class SourceEstimate:
    """One pass of the loop of paper Fig. 4 at one pose (step 5, :func:`estimate_source`).

    Attributes
    ----------
    pose : Pose
        The scan-plane pose of the back-projection.
    grid : PlaneGrid
        The source-plane grid (z = 0).
    velocity : ndarray, complex, shape (nx_s, ny_s, nb)
        Back-projected normal surface velocity (m/s·s) in the band.
    aperture : ApertureFit
        W, H and the centre (for an array: explained by the element map).
    lens : LensFit or None
        The focus fit (None when it failed: ``lens_error`` says why).
    lens_error : str
    mean_velocity_band : ndarray, complex, shape (nb,)
        Lens-corrected aperture mean of the velocity.
    mean_velocity : ndarray, shape (nt,)
        The same in time (m/s), sample n at ``start_time + n/fs``.
    noise : float
        Noise σ of ``mean_velocity`` (m/s).
    onset, onset_threshold : float
        t0 (s from the emission) and its detection level (m/s).
    element_map : ElementMap or None
        Per-element amplitudes and delays of an array.
    profile_width : float
        The profile-fitted aperture width of an array (m; NaN otherwise).
    map_warnings : tuple of str
        Warnings of the element map.
    """

    pose: Pose
    grid: PlaneGrid
    velocity: NDArray[np.complex128]
    aperture: ApertureFit
    lens: LensFit | None
    lens_error: str
    mean_velocity_band: NDArray[np.complex128]
    mean_velocity: NDArray[np.float64]
    noise: float
    onset: float
    onset_threshold: float
    element_map: ElementMap | None = None
    profile_width: float = float("nan")
    map_warnings: tuple[str, ...] = ()


def estimate_source(plan: ProjectionPlan, scan: HydrophoneScan, pose: Pose, band: BandSpectrum,
                    z0: float, config: CharacterizationConfig, *, iteration: int = 0,
                    timer: _Timer | None = None, progress: bool | None = None,
                    previous: ElementMap | None = None) -> SourceEstimate:
    """Step 5, one pass at ``pose``: back-projection onto z = 0
    (``plan.with_pose(pose)``), :func:`fit_aperture` (for an array
    :func:`array_aperture` with the element map), :func:`fit_lens_focus`, lens reversal
    and aperture mean, onset t0 — each with its config section. ``previous``: the map
    of the last pass, which starts this pass's map (a 1-D array's moved into this
    pass's frame by :func:`iterate_pose`). A 2-D matrix array (``scan.probe.is_matrix``):
    :func:`matrix_aperture`, no lens, the plane integral as the mean velocity."""
    timer = _Timer() if timer is None else timer
    medium, fb, fs = scan.medium, band.frequencies, scan.sampling_rate
    c0 = medium.sound_speed
    grid = source_grid(scan.grid, pose, config.backprojection.margin)
    with timer("backprojection"):
        velocity = plan.with_pose(pose).project(grid, quantity="normal_velocity",
                                                progress=progress)
    with timer("aperture"):
        aperture = fit_aperture(velocity, grid, fb, medium, **_aperture_options(config)[0])
    element_map, profile_width = None, float("nan")
    map_warnings: list[str] = []
    matrix = scan.probe is not None and scan.probe.is_matrix
    if config.elements.enabled and scan.probe is not None and scan.probe.element_count > 1:
        with timer("element_map"):
            extra: dict[str, Any] = ({} if matrix and not isinstance(previous, MatrixElementMap)
                                     else {"previous": previous})
            fit_map = matrix_aperture if matrix else array_aperture
            aperture, element_map, profile_width = fit_map(
                aperture, velocity, grid, fb, probe=scan.probe, scan_grid=scan.grid,
                pose=pose, sound_speed=c0, config=config.elements, warnings=map_warnings,
                **extra)
    with timer("lens"):
        lens, lens_error = (None, "a matrix array has no lens") if matrix else \
            lens_focus_step(velocity, grid, fb, medium, aperture, config.lens)
    with timer("mean_velocity"):
        u_band, u_rec = lens_corrected_mean_velocity(velocity, grid, band, aperture, lens, c0,
                                                     scan.n_samples, fs,
                                                     plane_integral=matrix)
    with timer("onset"):
        onset, noise_u, threshold = velocity_onset(u_rec, fs, scan.start_time, z0, c0,
                                                   config.onset, iteration=iteration)
    return SourceEstimate(pose, grid, velocity, aperture, lens, lens_error, u_band, u_rec,
                          noise_u, onset, threshold, element_map, profile_width,
                          tuple(map_warnings))


def _moved_map(element_map: ElementMap | None, dx0: float, dz0: float
               ) -> ElementMap | None:
    """A 1-D array's map in the frame of the next pose pass (x0 moved by ``dx0`` along
    the array, z = 0 by ``dz0`` away from the scan: the face δ in front of z = 0 is then
    δ + dz0 in front), the start of that pass's map; a matrix map as it is."""
    if element_map is None or isinstance(element_map, MatrixElementMap):
        return element_map
    return dataclasses.replace(element_map, center_x=element_map.center_x + dx0,
                               focus_offset=element_map.focus_offset + dz0)


def iterate_pose(scan: HydrophoneScan, band: BandSpectrum, orientation: OrientationResult,
                 z0: float, config: CharacterizationConfig, *, timer: _Timer | None = None,
                 progress: bool | None = None
                 ) -> tuple[SourceEstimate, list[dict[str, Any]], Pose]:
    """Step 5: :func:`estimate_source` at the current pose, then ``x0 −= x_c,
    y0 −= y_c, z0 += c0 t0`` (the source centre and the onset define the origin);
    ``iterations.count`` passes at most, fewer when an update is below
    ``iterations.tolerance``. The element map of a 2-D matrix array also turns the
    orientation (:func:`lattice_pose_correction`: θz by the lattice rotation, θx/θy
    so that the live elements' delays have no linear trend).

    One :class:`~holoprobe.propagation.ProjectionPlan` serves every pass: the scan's
    padded angular spectrum is computed once, the pose only changes phases.

    Returns
    -------
    last : SourceEstimate
        The last pass.
    history : list of dict
        Per pass: pose, W, H, x_c, y_c, F, t0 and the update.
    pose : Pose
        The final pose (the last update applied).
    """
    from holoprobe.propagation import ProjectionPlan

    bp, it = config.backprojection, config.iterations
    plan = ProjectionPlan(band.spectrum, scan.grid, band.frequencies, scan.medium, eps=bp.eps,
                          guard_angle=np.deg2rad(bp.guard_angle_deg),
                          single_precision=bp.single_precision, allow_undersampled=True)
    x0 = y0 = 0.0
    history: list[dict[str, Any]] = []
    last, previous = None, None
    for n in progress_iter(range(it.count), description="iterations", enabled=progress):
        pose = orientation.pose(origin=(x0, y0, z0))
        last = estimate_source(plan, scan, pose, band, z0, config, iteration=n, timer=timer,
                               progress=progress, previous=previous)
        if isinstance(last.element_map, MatrixElementMap):  # the lattice's tilt and θz
            d_ang = lattice_pose_correction(last.element_map, scan.medium.sound_speed)
            orientation = dataclasses.replace(
                orientation, theta_x=orientation.theta_x + d_ang[0],
                theta_y=orientation.theta_y + d_ang[1], theta_z=orientation.theta_z + d_ang[2])
        ap = last.aperture
        dx0, dy0, dz0 = -ap.center_x, -ap.center_y, scan.medium.sound_speed * last.onset
        history.append({
            "iteration": n + 1, "theta_deg": list(orientation.angles_deg),
            "origin": [x0, y0, z0], "width": ap.width, "height": ap.height,
            "center_x": ap.center_x, "center_y": ap.center_y,
            "lens_focus": None if last.lens is None else last.lens.focus,
            "onset": last.onset, "update": [dx0, dy0, dz0]})
        x0, y0, z0 = x0 + dx0, y0 + dy0, z0 + dz0
        if max(abs(dx0), abs(dy0), abs(dz0)) < it.tolerance:
            break
        previous = _moved_map(last.element_map, dx0, dz0)
    if last is None:
        raise InputError(f"expected at least one iteration, got {it.count}",
                         field="iterations.count")
    return last, history, orientation.pose(origin=(x0, y0, z0))


def final_pose(est: SourceEstimate, pose: Pose) -> Pose:
    """The pose of :func:`iterate_pose` with x0, y0 moved by the centre of the final
    aperture instead of the last pass's: ``x0 = x0_last − x_c``, ``y0 = y0_last − y_c``
    with ``est.pose`` the last pass's pose and ``est.aperture`` the fit of step 6c
    (:func:`window_bias_step`: at the face plane, where the back-projection is in
    focus). z0 and the angles are ``pose``'s. Unchanged when the aperture is the last
    pass's."""
    x_last, y_last, _ = est.pose.origin
    return dataclasses.replace(pose, origin=(x_last - est.aperture.center_x,
                                             y_last - est.aperture.center_y, pose.origin[2]))


def lens_focus_warnings(lens: LensFit | None, lens_error: str, aperture: ApertureFit,
                        config: WarningConfig, warnings: list[str]) -> float:
    """The reported F (m; ``inf`` when the fit failed or the curvature is not
    significant) with the warnings of the focus fit."""
    if lens is None:
        warnings.append(f"the lens fit failed ({lens_error}); no lens delays reversed")
        return float("inf")
    offset = lens.center_y - aperture.center_y
    if not lens.significant:
        warnings.append("the lens curvature is not significant: F reported as infinite")
    elif abs(offset) > config.lens_center_bound_fraction * 0.5 * aperture.height:
        warnings.append("the lens centre y_L of the focus fit is at its bound (±H/2)")
    elif abs(offset) > 3 * lens.center_y_uncertainty:
        warnings.append(f"the focus fit puts the lens centre "
                        f"{offset * 1e6:.3g} ± "
                        f"{lens.center_y_uncertainty * 1e6:.2g} µm off the aperture "
                        f"centre (a θx error looks the same); the lens is centred on the "
                        f"aperture everywhere (transmit, receive, model)")
    return float(lens.focus)


def _aperture_options(config: CharacterizationConfig) -> tuple[dict, dict]:
    """Keyword arguments of :func:`fit_aperture` and :func:`fit_lens_focus` from the
    ``aperture`` and ``lens`` sections."""
    ac, lc = config.aperture, config.lens
    return (dict(threshold_db=ac.threshold_db, profile=ac.profile, fit_offset=ac.fit_offset,
                 start_level=ac.start_level),
            dict(threshold_db=lc.threshold_db, margin_wavelengths=lc.margin_wavelengths,
                 significance=lc.significance, max_bins=lc.max_bins))


def _geometry_model(element_map: ElementMap | None, probe: ProbeInfo | None,
                    delays: bool = True) -> Strips | None:
    """The lateral model of :func:`model_velocity`: an array's strips (element-map
    amplitudes and delays, the file's kerf), None (one rectangle) otherwise. The delays
    matter: :func:`defocus` assumes a source real up to one phase per bin, and 8 ns rms
    element delays moved the face plane enough to bias H by −56 µm on a 24-element
    twin unless the model carries them too (``delays=False``: amplitudes only)."""
    if probe is None or probe.element_count <= 1:
        return None
    if element_map is None or element_map.count != probe.element_count:
        return np.ones(probe.element_count), float(probe.kerf)
    amp = np.clip(element_map.relative_amplitude, 0.0, None)
    if not delays:
        return np.asarray(amp, float), float(probe.kerf)
    delay = np.where(np.isfinite(element_map.delay), element_map.delay, 0.0)
    return np.asarray(amp, float), float(probe.kerf), np.asarray(delay, float)


def window_bias_step(est: SourceEstimate, band: BandSpectrum, scan: HydrophoneScan,
                     config: CharacterizationConfig, focus: float,
                     warnings: list[str] | None = None
                     ) -> tuple[SourceEstimate, float, dict[str, float]]:
    """Step 6c: W, H and F at the face and without the bias of the scan window
    (``aperture.window_*``; not for a 2-D matrix).

    :func:`face_plane` finds where the back-projection is in focus (the onset
    convention's plane is not the face), the aperture and the lens are refitted on the
    velocity refocused there, and :func:`scan_window_bias` of that fit is subtracted.
    The centre is the face fit's (:func:`final_pose` moves x0, y0 by it): the onset's
    plane sits in discrete threshold-crossing states up to ~1 mm off the face, and at a
    defocused plane the fitted centre of a tilted scan moves by ~5–15 µm per mm (seed
    2027 coverage twins). The mean surface velocity keeps the box and plane it was
    averaged on; a width that is not the profile fit's (an array with dead elements:
    N·p) and its centre x_c are held fixed in the face-plane refits (``keep_lateral``
    of :func:`face_plane`). When the face plane cannot be found, a line in ``warnings``
    says that H and F are uncorrected (the centre stays the onset plane's).

    Returns
    -------
    est : SourceEstimate
        With the corrected aperture and lens. Their uncertainties gain, in quadrature,
        ``window_uncertainty`` × the window correction (W, H, F), the change of the fit
        over one standard uncertainty of the face distance and (W, H)
        ``window_floor``.
    focus : float
        The corrected reported focus (unchanged when it is ``inf``).
    record : dict
        ``face_offset`` (m, along +z from the back-projection plane) and its
        uncertainty, and the window corrections ``window_bias_*`` (NaN when off).
    """
    nan = float("nan")
    record = dict(face_offset=nan, face_offset_uncertainty=nan, window_bias_width=nan,
                  window_bias_height=nan, window_bias_focus=nan)
    probe, ac, bp = scan.probe, config.aperture, config.backprojection
    if not ac.window_correction:
        return est, focus, record
    if probe is not None and probe.is_matrix:
        return matrix_window_step(est, scan, config, record, warnings), focus, record
    a_opt, l_opt = _aperture_options(config)
    common = dict(strips=_geometry_model(est.element_map, probe), max_bins=ac.window_bins,
                  guard_angle=np.deg2rad(bp.guard_angle_deg), eps=bp.eps,
                  single_precision=bp.single_precision)
    fb, medium = band.frequencies, scan.medium
    frac, old = ac.window_uncertainty, est.aperture
    profile = not np.isfinite(est.profile_width) or est.profile_width == old.width
    try:
        face = face_plane(est.velocity, est.grid, fb, medium, est.aperture, est.lens,
                          scan.grid.with_pose(est.pose), aperture_options=a_opt,
                          lens_options=l_opt, iterations=ac.window_iterations,
                          keep_lateral=not profile, **common)
    except (InputError, FitError) as exc:
        if warnings is not None:
            warnings.append(f"H and F are not corrected for the scan window (face "
                            f"plane: {exc})")
        return est, focus, record
    bias, fit, near = face.bias, face.aperture, face.nearby
    record.update(face_offset=face.distance, face_offset_uncertainty=face.uncertainty,
                  window_bias_width=bias.width, window_bias_height=bias.height,
                  window_bias_focus=bias.focus)
    floor2 = ac.window_floor**2
    u_w = float(np.sqrt(fit.width_uncertainty**2 + (frac * bias.width)**2
                        + (near.width - fit.width)**2 + floor2))
    ap = dataclasses.replace(
        old, width=fit.width - bias.width if profile else old.width,
        width_uncertainty=u_w if profile else old.width_uncertainty,
        height=fit.height - bias.height,
        height_uncertainty=float(np.sqrt(fit.height_uncertainty**2 + (frac * bias.height)**2
                                         + (near.height - fit.height)**2 + floor2)),
        center_x=fit.center_x, center_y=fit.center_y,
        center_x_uncertainty=float(np.hypot(fit.center_x_uncertainty,
                                            near.center_x - fit.center_x)),
        center_y_uncertainty=float(np.hypot(fit.center_y_uncertainty,
                                            near.center_y - fit.center_y)))
    lens = est.lens
    if lens is not None and lens.significant and np.isfinite(bias.focus):
        at_face, _ = lens_focus_step(face.velocity, est.grid, fb, medium, fit, config.lens)
        if at_face is not None and at_face.significant:
            f_new = at_face.focus - bias.focus
            u_f = float(np.hypot(at_face.focus_uncertainty, frac * bias.focus))
            lens = dataclasses.replace(at_face, focus=f_new, focus_uncertainty=u_f,
                                       curvature=1.0 / f_new,
                                       curvature_uncertainty=u_f / f_new**2)
            focus = f_new if np.isfinite(focus) else focus
    return dataclasses.replace(est, aperture=ap, lens=lens), focus, record


def matrix_window_step(est: SourceEstimate, scan: HydrophoneScan,
                       config: CharacterizationConfig, record: dict[str, float],
                       warnings: list[str] | None = None) -> SourceEstimate:
    """Step 6c of a 2-D matrix array: the pitches, element sizes and per-element
    amplitudes and delays of the map without the scan window's bias
    (:func:`matrix_window_bias`: the map's own model radiated onto the scan, cut to its
    window, back-projected and refitted; refit − map is subtracted, per element too,
    :func:`remove_lattice_bias`, and ``aperture.window_uncertainty`` × the
    correction joins each uncertainty). The aperture ``n_x p_x × n_y p_y`` follows;
    ``record`` gains ``window_bias_width``/``_height`` (the aperture's corrections, m)
    and ``face_offset`` (± ``face_offset_uncertainty``): the corrected focus offset δ,
    where the array face lies in front of the back-projection plane (m, along +z).
    Unchanged when the map is missing or the model cannot be refitted (then a line in
    ``warnings`` says so: the pitches and the face offset keep the window's bias)."""
    emap, probe = est.element_map, scan.probe
    if not isinstance(emap, MatrixElementMap) or probe is None or probe.array is None:
        return est
    bp = config.backprojection
    try:
        refit = matrix_window_bias(emap, probe.array, est.grid, scan.grid.with_pose(est.pose),
                                   scan.medium, options=matrix_map_options(config.elements),
                                   guard_angle=np.deg2rad(bp.guard_angle_deg), eps=bp.eps)
    except (InputError, FitError) as exc:
        if warnings is not None:
            warnings.append(f"the matrix element map is not corrected for the scan window "
                            f"(refit: {exc}): its pitches, amplitudes, delays and the face "
                            "offset keep the window's bias")
        return est
    fixed = remove_lattice_bias(emap, refit, config.aperture.window_uncertainty)
    nx, ny = emap.grid_shape
    record.update(window_bias_width=nx * (emap.pitch - fixed.pitch),
                  window_bias_height=ny * (emap.pitch_y - fixed.pitch_y),
                  face_offset=fixed.focus_offset,
                  face_offset_uncertainty=fixed.focus_offset_uncertainty)
    return dataclasses.replace(est, aperture=lattice_aperture(est.aperture, fixed),
                               element_map=fixed)


def data_sound_speed(est: SourceEstimate, band: BandSpectrum, scan: HydrophoneScan,
                     config: ElementsConfig, warnings: list[str]
                     ) -> tuple[float, float, ElementMap | None]:
    """Water sound speed (m/s) and its uncertainty from the back-projection of an array
    (:func:`element_map_with_sound_speed`, started from ``est.element_map``; ``elements``
    section), with a warning when it disagrees with the file's; NaN when not fitted
    (and for a matrix map: the 1-D model only).

    The third value is the element map fitted with that sound speed (None when not
    fitted): its amplitudes and delays are free of the defocus a wrong c0 leaves in the
    steep waves, so it replaces the map of the pose iterations.
    """
    if est.element_map is None or not config.fit_sound_speed \
            or isinstance(est.element_map, MatrixElementMap):
        return float("nan"), float("nan"), None
    c0 = scan.medium.sound_speed
    emap = element_map_with_sound_speed(
        est.velocity, est.grid, band.frequencies, probe=scan.probe, scan_grid=scan.grid,
        pose=est.pose, sound_speed=c0, config=config, start=est.element_map)
    if emap is None:
        return float("nan"), float("nan"), None
    c_data, u_c_data = emap.sound_speed, emap.sound_speed_uncertainty
    if np.isfinite(c_data) and abs(c_data - c0) > u_c_data:
        warnings.append(f"the sound speed from the data, {c_data:.1f} ± {u_c_data:.1f} "
                        f"m/s, disagrees with the file's {c0:.1f} m/s (check the water "
                        "temperature; --water-temperature or --sound-speed)")
    return c_data, u_c_data, emap


def sound_speed_step(est: SourceEstimate, band: BandSpectrum, scan: HydrophoneScan,
                     config: ElementsConfig, warnings: list[str]
                     ) -> tuple[SourceEstimate, float, float]:
    """:func:`data_sound_speed`, with the element map it refits put into the estimate.

    Returns
    -------
    est : SourceEstimate
        ``est`` with ``element_map`` replaced by the map at the fitted sound speed (when
        one was fitted).
    sound_speed, uncertainty : float
        Water sound speed from the data and its standard uncertainty (m/s).
    """
    c_speed, u_speed, speed_map = data_sound_speed(est, band, scan, config, warnings)
    if speed_map is not None:
        est = dataclasses.replace(est, element_map=speed_map)
    return est, c_speed, u_speed


def element_step(est: SourceEstimate, probe: ProbeInfo | None, warnings: list[str]
                 ) -> tuple[ElementEstimate, float, float]:
    """The element estimate from the fitted aperture (paper section II E).

    A matrix array (``probe.is_matrix``) uses :func:`matrix_element_estimate` on the
    element map; any other probe :func:`element_estimate` from W and the kerf.

    Returns
    -------
    elements : ElementEstimate
    edge_width : float
        Aperture width from the edges (m).
    edge_height : float
        Aperture height from the edges of a matrix (m); NaN for a 1-D array.
    """
    if probe is not None and probe.is_matrix:
        return matrix_element_estimate(est.aperture, probe, est.element_map)
    elements, edge_width = element_estimate(est.aperture, probe, warnings)
    return elements, edge_width, float("nan")


def _checked_inputs(scan: object, config: object) -> CharacterizationConfig:
    """The configuration (default ``CharacterizationConfig()``) after checking the types
    of the scan and of the configuration."""
    cfg = CharacterizationConfig() if config is None else config
    if not isinstance(scan, HydrophoneScan):
        raise InputError("expected a holoprobe.measurement.HydrophoneScan", field="scan")
    if not isinstance(cfg, CharacterizationConfig):
        raise InputError("expected a CharacterizationConfig", field="config")
    array = None if scan.probe is None else scan.probe.array
    if array is not None and array.kind == "row-column":
        raise InputError("a row-column array transmits with one set of strips: "
                         "characterize that set (holoprobe.workflow.characterize_row_column, "
                         "CLI --transmit-set)", file=scan.source or None, field="probe.array")
    return cfg


def _live_scale(element_map: ElementMap | None, profile_width: float,
                warnings: list[str], pitches: float) -> float:
    """Factor that turns the aperture mean of the velocity into the mean of the live
    elements (``N / Σ A_e``, live mean of A = 1), with the warnings of the map."""
    if element_map is None:
        return 1.0
    m = element_map
    nominal = getattr(m, "grid_shape", (m.count,))[0] * m.pitch  # n_x of a matrix
    sparse = getattr(m, "layout", "full") == "sparse"  # its profile is no box: no check
    if np.isfinite(profile_width) and abs(profile_width - nominal) > pitches * m.pitch \
            and not sparse:
        warnings.append(f"the fitted aperture width {profile_width * 1e3:.4g} mm (profile "
                        f"fit) disagrees with the nominal array width {nominal * 1e3:.4g} mm "
                        f"({round(nominal / m.pitch)} × {m.pitch * 1e3:.4g} mm): the element "
                        "map explains "
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


SPREAD_FLOOR = 0.5
"""Least |D(f)| (:meth:`ElementMap.delay_response`) that :func:`align_to_onset` divides
by: delays spread over a large part of a period (a steering or focusing the map holds)
null D inside the band, where the division would only amplify noise."""


def align_to_onset(est: SourceEstimate, band: BandSpectrum, medium: Medium, focus: float,
                   start_time: float, sampling_rate: float, live_scale: float,
                   transmit: TransmitIRConfig, warnings: list[str] | None = None
                   ) -> tuple[NDArray[np.float64], NDArray[np.complex128], NDArray[np.float64]]:
    """Step 6a: ū advanced so that the onset is at t = 0, scaled to the live elements
    and divided by the band-limit gain (``transmit.band_limit_correction``, see
    :func:`band_limit_gain`; not for a matrix array, whose ū is the plane integral).

    With an element map, ū is also divided by the spread of the element delays
    (:meth:`ElementMap.delay_response`): ū is then the elements' common velocity, the
    one the model (and the transmit IR) gives every element before its own delay and
    amplitude (8 ns rms delays had left the full-size worn twin's IR 0.8 % low in
    energy, 1.5 % at the top of the band). Where |D| < ``SPREAD_FLOOR`` it is divided by
    that floor instead (its phase kept), with a line in ``warnings``.

    Returns
    -------
    mean_velocity : ndarray, shape (nt,)
        ū (m/s), sample n at n/fs.
    phase : ndarray, complex, shape (nb,)
        The advance ``e^{−iωΔ}`` (Δ = t0 − start_time), applied to the source too.
    gain : ndarray, shape (nb,)
        The band-limit gain ū was divided by (ones when the correction is off).
    """
    fb, lens, ap = band.frequencies, est.lens, est.aperture
    nt = est.mean_velocity.size
    phase = onset_phase(fb, est.onset, start_time)
    gain = np.ones(fb.size)
    if transmit.band_limit_correction and not isinstance(est.element_map, MatrixElementMap):
        gain = band_limit_gain(
            est.grid, fb, medium, width=ap.width, height=ap.height,
            center_x=ap.center_x, center_y=ap.center_y,
            focus=focus if lens is not None and lens.significant else float("inf"),
            lens_center_y=None if lens is None else lens.center_y)
    full = np.zeros(nt // 2 + 1, complex)
    spread = (np.ones(fb.size, complex) if est.element_map is None
              else est.element_map.delay_response(fb))  # the elements' delays undone
    low = np.abs(spread) < SPREAD_FLOOR
    if low.any():
        k = int(np.argmin(np.abs(spread)))
        if warnings is not None:
            warnings.append(
                f"the element delays' spread |D(f)| falls to {abs(spread[k]):.2f} at "
                f"{fb[k] / 1e6:.3g} MHz (the map's delays hold a steering or focusing?): "
                f"the transmit IR is divided by {SPREAD_FLOOR} there instead")
        spread = np.where(low, SPREAD_FLOOR * np.exp(1j * np.angle(spread)), spread)
    full[band.bins] = est.mean_velocity_band * live_scale / gain * phase / spread
    return to_time(full, nt) * sampling_rate, phase, gain


def window_then_align(est: SourceEstimate, band: BandSpectrum, scan: HydrophoneScan,
                      config: CharacterizationConfig, focus: float, live_scale: float,
                      warnings: list[str]) -> tuple[SourceEstimate, float, dict[str, float],
                                                    tuple[NDArray, NDArray, NDArray]]:
    """Step 6c (:func:`window_bias_step`), then 6a (:func:`align_to_onset`) on the box,
    plane, lens and focus ū was averaged on (the band-limit gain's) but with the FINAL
    element map's delay spread D(f): a matrix's window step replaces the map.

    Returns the corrected estimate, the corrected focus, the window record and
    :func:`align_to_onset`'s (ū, phase, gain)."""
    final, corrected, window = window_bias_step(est, band, scan, config, focus, warnings)
    aligned = align_to_onset(dataclasses.replace(est, element_map=final.element_map), band,
                             scan.medium, focus, scan.start_time, scan.sampling_rate,
                             live_scale, config.transmit, warnings)
    return final, corrected, window, aligned


def element_estimate(aperture: ApertureFit, probe: ProbeInfo | None, warnings: list[str]
                     ) -> tuple[ElementEstimate, float]:
    """Step 6b: element pitch and width from the fitted W and the datasheet kerf
    (reference_spec 2.7 step 10), and the active outer-edge width (m).

    The band-limited source of N elements at pitch p is (w/p)·rect of width N·p: the
    fit measures the envelope N·p, the outer-edge width is N·p − kerf.
    """
    if probe is not None:
        count = probe.element_count
        kerf = probe.kerf
        if count > 1:
            # reference_spec 2.7 step 10 applied to the edge width W_e = W − kerf:
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
    return elements, float(edge_width)


def matrix_element_estimate(aperture: ApertureFit, probe: ProbeInfo,
                            element_map: ElementMap | None
                            ) -> tuple[ElementEstimate, float, float]:
    """Step 6b of a 2-D matrix array: the element estimate (count N, the x pitch and
    element width — fitted from the data with ``elements.matrix_fit_pitch`` and
    ``matrix_fit_element_size``, else the file's — and the kerf p − w), the active
    fraction ``(N / (n_x n_y)) w h / (p_x p_y)`` of the envelope (``N / (n_x n_y)``:
    the populated share of a sparse grid) and the outer-edge width and height
    ``(n − 1) p + w`` in x and y (m)."""
    array = probe.array
    assert array is not None and array.grid_shape is not None and array.pitch is not None
    nx, ny = array.grid_shape
    px, py = array.pitch
    w, h = float(np.median(array.widths)), float(np.median(array.heights))
    u_px = u_w = aperture.width_uncertainty / nx
    if isinstance(element_map, MatrixElementMap):
        px, py = element_map.pitch, element_map.pitch_y
        w, h = element_map.element_width, element_map.element_height
        u_px, u_w = element_map.pitch_uncertainty, element_map.width_uncertainty
    elements = ElementEstimate(count=int(probe.element_count), pitch=float(px), width=w,
                               kerf=float(px - w), pitch_uncertainty=float(u_px),
                               width_uncertainty=float(u_w),
                               active_fraction=array.count / (nx * ny) * w * h / (px * py))
    return elements, float((nx - 1) * px + w), float((ny - 1) * py + h)


def transmit_response(mean_velocity: NDArray, sampling_rate: float, medium: Medium, z0: float,
                      drive: DriveSignal | None, active_fraction: float,
                      transmit: TransmitIRConfig, warnings: list[str]
                      ) -> tuple[TransmitImpulseResponse | None, SpectrumSummary]:
    """Step 6c: the transmit IR from ρ0c0·ū (``transmit`` section,
    :func:`transmit_impulse_response`, paper eqs. transmit-impulse-response,
    deconvolution-transmit) and its spectrum summary (of ρ0c0·ū without a drive).

    ū is kept for ``transmit.duration`` (default: the record minus the travel time
    z0/c0, where the scan's pre-arrival samples land)."""
    nt, fs, c0 = mean_velocity.size, sampling_rate, medium.sound_speed
    duration = transmit.duration if transmit.duration is not None else nt / fs - z0 / c0
    n_keep = int(np.clip(round(duration * fs), 8, nt))
    response = medium.impedance * mean_velocity[:n_keep]
    if drive is None:
        warnings.append("no drive voltage (pass --drive): no transmit impulse response; "
                        "the spectrum summary describes ρ0c0·ū")
        return None, spectrum_summary(response, fs)
    ir = transmit_impulse_response(response, fs, drive, method=transmit.method,
                                   output_rate=transmit.output_rate,
                                   delta_tolerance=transmit.delta_tolerance,
                                   active_fraction=active_fraction)
    return ir, spectrum_summary(ir.ir, ir.sampling_rate)


def onset_phase(frequencies: NDArray, onset: float, start_time: float
                ) -> NDArray[np.complex128]:
    """``e^{−iωΔ}``, ``Δ = onset − start_time`` (s): the advance that puts the onset at
    t = 0 (:func:`align_to_onset`), per frequency (Hz)."""
    return np.exp(-2j * np.pi * np.asarray(frequencies, float) * (onset - start_time))


def source_velocity_in_time(velocity: NDArray, phase: NDArray, bins: NDArray[np.intp],
                            n_samples: int, sampling_rate: float) -> NDArray[np.float32]:
    """The back-projected source velocity (m/s) in time, advanced like ū (``phase``),
    float32, shape (nx_s, ny_s, n_samples)."""
    nxs, nys = velocity.shape[:2]
    # the conjugate spectrum to_time would transform (conj commutes with the float32
    # cast), filled a few rows at a time: no full-size temporaries besides the result
    conj_src = np.zeros((nxs, nys, n_samples // 2 + 1), np.complex64)
    for i in range(0, nxs, 16):
        scaled = velocity[i:i + 16] * phase
        scaled *= sampling_rate
        conj_src[i:i + 16, :, bins] = np.conj(scaled, out=scaled)
    return scipy.fft.irfft(conj_src, n=n_samples, axis=-1, workers=workers(),
                           overwrite_x=True).astype(np.float32, copy=False)


def onset_uncertainty(mean_velocity: NDArray, noise: float, sampling_rate: float,
                      onset: OnsetConfig) -> float:
    """Step 7: standard uncertainty of t0 (s) by a noise bootstrap (``onset.bootstrap``
    realisations of σ = ``noise`` added to ū; NaN when off or fewer than 2 onsets)."""
    nt, fs = mean_velocity.size, sampling_rate
    if not (onset.bootstrap > 0 and noise > 0):
        return float("nan")
    rng = np.random.default_rng(onset.seed)
    draws = []
    for _ in range(onset.bootstrap):
        try:
            noisy = mean_velocity + rng.normal(0.0, noise, nt)
            draws.append(detect_onset(noisy, fs, threshold=onset.threshold, noise=noise,
                                      polarity=onset.polarity, upsample=onset.upsample,
                                      allow_wrap=True))
        except FitError:
            continue
    if len(draws) < 2:
        return float("nan")
    d = np.asarray(draws)
    d = np.where(d > 0.5 * nt / fs, d - nt / fs, d)
    return float(np.std(d, ddof=1))


def _center_fields(band: BandSpectrum, est: SourceEstimate, medium: Medium
                   ) -> tuple[int, NDArray[np.complex128], NDArray[np.complex128]]:
    """The band bin with the most energy, and ρ0c0 × the source velocity there before
    and after lens reversal (Pa·s, for the figures)."""
    kb = int(np.argmax(bin_energy(band.spectrum)))
    velocity, lens, ap = est.velocity, est.lens, est.aperture
    source_field = medium.impedance * velocity[:, :, kb]
    if lens is not None and lens.significant:
        corrected = reverse_lens_delays(velocity[:, :, kb:kb + 1], est.grid,
                                        band.frequencies[kb:kb + 1], lens.focus, ap.height,
                                        medium.sound_speed, center_y=ap.center_y)[:, :, 0]
    else:
        corrected = velocity[:, :, kb]
    return kb, source_field, medium.impedance * corrected


def _uncertainties(orientation: OrientationResult, est: SourceEstimate,
                   elements: ElementEstimate, u_onset: float, sound_speed: float,
                   ) -> tuple[ElementMap | None, float, dict[str, float]]:
    """Standard uncertainties of the transmit parameters, with the element map and the
    steering σ_ε (rad) of :func:`with_steering` (0 without a map), which joins θy: the
    fit puts a steering of the element delays into the scan plane's tilt (24-element
    twins: θy 0.16° off at σ 0.008° without it)."""
    element_map, steering = (est.element_map, 0.0) if est.element_map is None else \
        with_steering(est.element_map, sound_speed)
    ap, lens = est.aperture, est.lens
    out = {
        "theta_x": orientation.u_theta_x,
        "theta_y": float(np.hypot(orientation.u_theta_y, steering)),
        "theta_z": orientation.u_theta_z,
        "x0": ap.center_x_uncertainty, "y0": ap.center_y_uncertainty,
        "z0": sound_speed * u_onset,
        "width": ap.width_uncertainty, "edge_width": ap.width_uncertainty,
        "height": ap.height_uncertainty,
        "center_x": ap.center_x_uncertainty, "center_y": ap.center_y_uncertainty,
        "lens_focus": float("inf") if lens is None else lens.focus_uncertainty,
        "onset": u_onset,
        "pitch": elements.pitch_uncertainty, "element_width": elements.width_uncertainty,
    }
    if isinstance(est.element_map, MatrixElementMap):  # the angles the map refined
        out.update(zip(("theta_x", "theta_y", "theta_z"),
                       lattice_pose_uncertainty(est.element_map, sound_speed), strict=True))
    return element_map, steering, out


def sound_speed_uncertainty(used: float, from_data: float, data_uncertainty: float
                            ) -> float:
    """Standard uncertainty (m/s) of the sound speed ``used``, as the scan sees it:
    ``hypot(used − from_data, data_uncertainty)`` (0 when the data gave no estimate).

    The water's c0 scales what the pipeline reads from phases: the direction of a wave
    (sin θ = k_x c0/ω), a lens focus (F ∝ ω/c0 over the phase curvature) and a distance
    from an arrival time (c0·t). The file's c0 is as good as the thermometer someone
    read; where the data's estimate disagrees, the disagreement is the best measure of
    its error there is (the data's own σ kept on top, so that a c0 that agrees is not
    taken as exact).
    """
    if not (math.isfinite(from_data) and math.isfinite(data_uncertainty)):
        return 0.0
    return float(math.hypot(used - from_data, data_uncertainty))


def with_sound_speed_uncertainty(result: TransmitResult, uncertainty: float
                                 ) -> TransmitResult:
    """``result`` with the sound speed's standard uncertainty (m/s) in the σ of every
    parameter c0 scales (:func:`sound_speed_uncertainty`): the scan plane's tilts θx, θy
    (``|tan θ|·u_c/c0``: sin θ = k_x c0/ω), z0 and the lens focus F (``·u_c/c0``); a
    full-size P4-1 twin in water 6 m/s faster than its file had θy 16σ and F 14σ off
    without it. ``extras['sound_speed_uncertainty']`` keeps u_c (the receive side adds
    it to θy', x0', z0' and d). The angles' new σ reach x0, y0 and the aperture centre
    through :func:`with_angle_lever`, applied again at the end (it starts from the centre
    fit's σ, so the lever is counted once however often it is applied). A 0 (or
    non-finite) uncertainty leaves ``result`` unchanged."""
    if not (math.isfinite(uncertainty) and uncertainty > 0):
        return result
    rel = uncertainty / result.medium.sound_speed
    u = dict(result.uncertainties)
    pose = result.pose
    tilt_x, tilt_y, _ = np.radians(pose.angles_deg)
    terms = {"theta_x": abs(math.tan(tilt_x)) * rel, "theta_y": abs(math.tan(tilt_y)) * rel,
             "z0": abs(float(pose.origin[2])) * rel}
    if math.isfinite(result.lens_focus):
        terms["lens_focus"] = abs(result.lens_focus) * rel
    for key, term in terms.items():
        u[key] = float(math.hypot(u[key], term))
    return with_angle_lever(dataclasses.replace(result, uncertainties=u, extras={
        **result.extras, "sound_speed_uncertainty": float(uncertainty)}))


def with_angle_lever(result: TransmitResult) -> TransmitResult:
    """``result`` with the angles' uncertainty over the lever to the scan origin in the
    σ of x0, y0 (and of the aperture centre, whose error is theirs): r0 is the scan
    origin in the probe frame, and a frame turned by small angles δ about the source
    centre sees it moved by −δ × r0, so ``u(x0)² = u(x_c)² + (z0 u(θy))² + (y0 u(θz))²``
    and ``u(y0)² = u(y_c)² + (z0 u(θx))² + (x0 u(θz))²``, with the final angle σ (the
    element delays' steering and the sound speed's terms included). On the seed 2027
    coverage twins x0's error was z0 times θy's (16 elements: σ(θy) ≈ 0.02°, z0·σ ≈ 1.5
    µm against the centre fit's 0.8 µm). Idempotent: it starts from the aperture's
    centre-fit σ (``center_x_uncertainty``), so apply it again after any change of the
    angles' σ."""
    u = dict(result.uncertainties)
    x0, y0, z0 = (abs(float(v)) for v in result.pose.origin)
    ap = result.aperture
    u_x = float(np.sqrt(ap.center_x_uncertainty**2 + (z0 * u["theta_y"])**2
                        + (y0 * u["theta_z"])**2))
    u_y = float(np.sqrt(ap.center_y_uncertainty**2 + (z0 * u["theta_x"])**2
                        + (x0 * u["theta_z"])**2))
    u.update(x0=u_x, center_x=u_x, y0=u_y, center_y=u_y)
    return dataclasses.replace(result, uncertainties=u)


def _extras(band: BandSpectrum, est: SourceEstimate, *, tilt: float, arrival: float | None,
            gain: NDArray, live_scale: float, sound_speed: tuple[float, float],
            window: dict[str, float] | None = None) -> dict[str, Any]:
    lens, fb = est.lens, band.frequencies
    return {**(window or {}),
            "edge_energy_fraction": band.edge_energy_fraction, "tilt_deg": tilt,
            "arrival_time": arrival, "noise_sigma_velocity": est.noise,
            "band": (float(fb[0]), float(fb[-1])),
            "band_limit_gain": (float(gain.min()), float(gain.max())),
            "profile_width": est.profile_width, "live_scale": live_scale,
            "positioning_noise": band.positioning.rms,
            "positioning_noise_uncertainty": band.positioning.uncertainty,
            "sound_speed_from_data": sound_speed[0],
            "sound_speed_from_data_uncertainty": sound_speed[1],
            "lens_center_offset": (float(lens.center_y - est.aperture.center_y)
                                   if lens is not None and lens.significant else 0.0)}


# --------------------------------------------------------------------------------------
# The driver
# --------------------------------------------------------------------------------------
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
        A scan that is not a HydrophoneScan, or what a step raises for bad input.
    FitError
        Data that do not support an estimate: no frequency bin with signal, no
        aperture edge, no onset in the mean surface velocity.

    Notes
    -----
    The steps, in the order the scan goes through them (each a function of this module
    or of another; every knob from its config section):

    1. :func:`scan_spectrum`: the pressure (:func:`scan_pressure`,
       :func:`holoprobe.signal.pressure_from_voltage`) spectrum ``P = dt·conj(FFT p)``
       (paper eq. complex-conjugate-fourier);
    2. :func:`signal_band`: the contiguous range of bins within ``band.threshold_db`` of
       the strongest bin and ``band.min_snr_db`` above the noise floor;
    3. :func:`scan_orientation` (paper section II D, :func:`estimate_orientation`);
    4. :func:`initial_distance`: starting z0 (``iterations.initial_z0``, see
       :class:`IterationConfig`);
    5. :func:`iterate_pose`: per pass :func:`estimate_source` = back-projection
       (``ProjectionPlan.project(..., quantity="normal_velocity")`` onto
       :func:`source_grid`), :func:`fit_aperture` (:func:`array_aperture` for an
       array), :func:`fit_lens_focus`, :func:`reverse_lens_delays` (exact delays, paper
       eq. lens-delays) and :func:`mean_surface_velocity`, onset t0
       (:func:`velocity_onset`); ``x0 −= x_c, y0 −= y_c, z0 += c0 t0``; stop after
       ``iterations.count`` or when the update is below the tolerance;
    6. :func:`window_bias_step`: W, H, F and the centre refitted at the face plane
       (where the back-projection is in focus), x0, y0 moved by that centre
       (:func:`final_pose`; not for a 2-D matrix array);
       :func:`align_to_onset`: ū advanced by t0 (onset at t = 0, consistent with the
       updated z0); :func:`element_estimate` from W and the datasheet kerf;
       :func:`transmit_response`: the transmit IR from ρ0c0·ū (paper eqs.
       transmit-impulse-response, deconvolution-transmit), divided by the active
       fraction ``N w / W``, resampled to ``transmit.output_rate``;
    7. :func:`onset_uncertainty` (noise bootstrap); uncertainties
       (:func:`with_sound_speed_uncertainty`, :func:`with_angle_lever`); warnings.

    BLAS runs single-threaded throughout (:func:`~holoprobe.signal.blas_threads`): the
    steps' products are small, the steps thread over frequency bins themselves, and
    OpenBLAS's idle threads only spin (0.3 s CPU of a full-size run).
    """
    with blas_threads(1):
        return _characterize_transmit(scan, config, drive=drive, calibration=calibration,
                                      progress=progress)


def _characterize_transmit(scan: HydrophoneScan, config: CharacterizationConfig | None, *,
                           drive: DriveSignal | None,
                           calibration: HydrophoneCalibration | None,
                           progress: bool | None) -> TransmitResult:
    """:func:`characterize_transmit` (its steps, without the BLAS limit)."""
    t_total, timer, warnings = time.perf_counter(), _Timer(), list[str]()
    cfg = _checked_inputs(scan, config)
    medium, fs, nt, t_start = scan.medium, scan.sampling_rate, scan.n_samples, scan.start_time
    drive = drive if drive is not None else scan.drive
    with timer("spectrum"):  # 1. pressure spectrum (nx, ny, nf), complex64
        spectrum = scan_spectrum(scan, calibration, warnings, cfg)
    with timer("band"):  # 2. signal band
        band = signal_band(spectrum, frequency_axis(nt, fs), scan.grid, fs,
                           medium.sound_speed, cfg, warnings)
        del spectrum
    with timer("orientation"):  # 3. orientation
        orientation, tilt = scan_orientation(band, scan.grid, medium, cfg, warnings)
    with timer("initial_z0"):  # 4. starting distance
        z0, arrival = initial_distance(band, nt, fs, t_start, medium.sound_speed, cfg,
                                       warnings)
    est, history, pose = iterate_pose(scan, band, orientation, z0, cfg,  # 5. iterations
                                      timer=timer, progress=progress)
    with Threads(name="holoprobe-background") as background:  # joined if a step raises
        velocity_job = background.submit(  # beside 5b–6
            source_velocity_in_time, est.velocity,
            onset_phase(band.frequencies, est.onset, t_start), band.bins, nt, fs)
        matrix = scan.probe is not None and scan.probe.is_matrix
        focus = float("inf") if matrix else lens_focus_warnings(
            est.lens, est.lens_error, est.aperture, cfg.warnings, warnings)
        warnings += est.map_warnings
        with timer("sound_speed"):
            est, c_speed, u_speed = sound_speed_step(est, band, scan, cfg.elements, warnings)
        live_scale = _live_scale(est.element_map, est.profile_width, warnings,
                                 cfg.elements.width_warning_pitches)
        with timer("transmit_ir"):  # 6. alignment, elements, transmit IR
            est, focus, window, (mean_velocity, _, gain) = window_then_align(
                est, band, scan, cfg, focus, live_scale, warnings)
            if not matrix:  # x0, y0 from the centre at the face plane (step 6c)
                pose = final_pose(est, pose)
            elements, edge_width, edge_height = element_step(est, scan.probe, warnings)
            ir, summary = transmit_response(mean_velocity, fs, medium, pose.origin[2], drive,
                                            elements.active_fraction, cfg.transmit, warnings)
        with timer("source_velocity"):  # est.velocity and the onset's phase are unchanged
            source_velocity = velocity_job.result()
    with timer("uncertainty"):  # 7. uncertainty of t0, then of every parameter
        u_onset = onset_uncertainty(est.mean_velocity, est.noise, fs, cfg.onset)
        element_map, steering, uncertainties = _uncertainties(orientation, est, elements,
                                                              u_onset, medium.sound_speed)
    kb, source_field, source_corr = _center_fields(band, est, medium)
    timer.times["total"] = time.perf_counter() - t_total
    return with_sound_speed_uncertainty(with_angle_lever(TransmitResult(
        pose=pose, orientation=orientation, aperture=est.aperture, lens=est.lens,
        lens_focus=focus, onset=float(est.onset), onset_uncertainty=u_onset,
        elements=elements, impulse_response=ir, ir_spectrum=summary,
        mean_velocity=mean_velocity, mean_velocity_raw=est.mean_velocity,
        onset_threshold=float(est.onset_threshold), sampling_rate=fs,
        start_time=float(t_start), source_grid=est.grid, source_velocity=source_velocity,
        frequencies=band.frequencies, center_frequency=float(band.frequencies[kb]),
        scan_field=band.spectrum[:, :, kb].copy(), source_field=source_field,
        source_field_corrected=source_corr, scan_grid=scan.grid.with_pose(pose),
        history=history, warnings=warnings, uncertainties=uncertainties,
        timings=dict(timer.times), config=cfg, medium=medium, source=scan.source,
        aperture_width=edge_width, element_map=element_map, aperture_height=edge_height,
        extras={**_extras(band, est, tilt=tilt, arrival=arrival, gain=gain,
                          live_scale=live_scale, sound_speed=(c_speed, u_speed),
                          window=window), "steering_uncertainty": steering})),
        sound_speed_uncertainty(medium.sound_speed, c_speed, u_speed))
