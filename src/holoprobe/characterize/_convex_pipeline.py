"""Transmit characterization of a convex (curvilinear) array from a hydrophone scan.

The flat-array driver (:func:`characterize_transmit`) with the plane z = 0 replaced by
the cylindrical face (:mod:`holoprobe.characterize._convex`): orientation from the
scan's angular spectrum (θx, θz and a first θy), then iterations on a few strong bins
that move the trial cylinder — centre of curvature from the phase along the arc
(:func:`fit_arc_center`), apex along the arc from the centre of the aperture,
elevation centre from the aperture — and one pass on the whole band for the element map,
the lens focus, the lens-corrected mean surface velocity, its onset (which moves the
apex along the radius: R −= c0·t0) and the transmit impulse response.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Any

import numpy as np
from numpy.typing import NDArray

from holoprobe.characterize._aperture import fit_aperture
from holoprobe.characterize._aperture_bias import _pick, scan_window_bias
from holoprobe.characterize._arc_window import arc_window_bias
from holoprobe.characterize._bandlimit import band_limit_gain
from holoprobe.characterize._config import CharacterizationConfig
from holoprobe.characterize._convex import (
    ConvexTransmitResult,
    arc_element_views,
    arc_footprint,
    element_lattice,
    element_line_tilt,
    fit_arc_center,
    move_source_frame,
    project_on_cylinder,
    unrolled_grid,
)
from holoprobe.characterize._elements import fit_element_map
from holoprobe.characterize._lens import fit_lens_focus
from holoprobe.characterize._pipeline import (
    BandSpectrum,
    _aperture_options,
    _geometry_model,
    initial_distance,
    lens_corrected_mean_velocity,
    lens_focus_step,
    onset_uncertainty,
    scan_orientation,
    scan_pressure,
    signal_band,
    transmit_response,
    velocity_onset,
)
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import ArrayGeometry, PlaneGrid, Pose, rotation_matrix
from holoprobe.measurement import DriveSignal, HydrophoneCalibration, HydrophoneScan
from holoprobe.signal import blas_threads, frequency_axis, to_frequency, to_time

__all__ = ["characterize_convex_transmit", "convex_start_pose"]

_NODE_PAD = 3  # nodes of the whole-band back-projection beyond each end of the band


def _geometry_bins(spec_band: NDArray, count: int, threshold_db: float = -10.0
                   ) -> NDArray[np.intp]:
    """At most ``count`` bins spread over those within ``threshold_db`` of the peak."""
    energy = np.sum(np.abs(spec_band) ** 2, axis=(0, 1))
    strong = np.flatnonzero(energy >= energy.max() * 10 ** (threshold_db / 10))
    if strong.size <= count:
        return strong
    pick = np.unique(np.round(np.linspace(0, strong.size - 1, count)).astype(int))
    return strong[pick]


def _project(plan, pose: Pose, grid: PlaneGrid, radius: float, progress,
             cfg: CharacterizationConfig) -> NDArray:
    return project_on_cylinder(plan, pose, grid, radius, progress=progress,
                               method=cfg.convex.projection,
                               patch_angle=np.radians(cfg.convex.patch_angle_deg))


def _plan(spectrum: NDArray, scan: HydrophoneScan, freqs: NDArray,
          cfg: CharacterizationConfig):
    """The scan's projection plan with the convex section's NUFFT tolerance and guard
    angle (``convex.eps``, ``convex.guard_angle_deg``; ``None``: the back-projection
    section's)."""
    from holoprobe.propagation import ProjectionPlan

    bp, cv = cfg.backprojection, cfg.convex
    guard = bp.guard_angle_deg if cv.guard_angle_deg is None else cv.guard_angle_deg
    return ProjectionPlan(spectrum, scan.grid, freqs, scan.medium, eps=_eps(cfg),
                          guard_angle=np.deg2rad(guard),
                          single_precision=bp.single_precision, allow_undersampled=True)


def _eps(cfg: CharacterizationConfig) -> float:
    """The NUFFT tolerance of the convex projections (``convex.eps``; ``None``: the
    back-projection section's)."""
    return float(cfg.backprojection.eps if cfg.convex.eps is None else cfg.convex.eps)


def _aperture(v: NDArray, grid: PlaneGrid, freqs: NDArray, scan: HydrophoneScan,
              cfg: CharacterizationConfig):
    return fit_aperture(v, grid, freqs, scan.medium, threshold_db=cfg.aperture.threshold_db,
                        profile=cfg.aperture.profile, fit_offset=cfg.aperture.fit_offset,
                        start_level=cfg.aperture.start_level)


def _update(pose: Pose, radius: float, arc, center: float, center_y: float,
            pitch_scale: float) -> tuple[Pose, float, list[float]]:
    """Move the trial cylinder: the centre of curvature by the arc fit (apex kept), the
    apex along the radius so that the elements have their nominal arc pitch
    (``pitch_scale`` = nominal / apparent pitch on the trial cylinder), then the apex
    along the arc to the array centre ``center`` (about the centre of curvature) and
    along y to ``center_y``."""
    r_arc = float(np.hypot(arc.dx, radius - arc.dz))
    tilt = float(np.arctan2(-arc.dx, radius - arc.dz))
    pose = move_source_frame(pose, angle=tilt)
    r_new = r_arc * pitch_scale
    pose = move_source_frame(pose, apex=np.array([0.0, 0.0, r_new - r_arc]))
    turn = center / radius
    pose = move_source_frame(pose, angle=turn, pivot=np.array([0.0, 0.0, -r_new]))
    pose = move_source_frame(pose, apex=np.array([0.0, center_y, 0.0]))
    return pose, r_new, [tilt, turn, center_y, r_new - radius]


def _geometry_iterations(scan, spec_band, fb, pose, radius, cfg, iterations, progress,
                         history, warnings):

    bp = cfg.backprojection
    c0 = scan.medium.sound_speed
    probe = scan.probe
    plan = _plan(spec_band, scan, fb, cfg)
    arc = emap = None
    tilt_u, offset = float("nan"), 0.0
    for n in range(iterations):
        grid = unrolled_grid(scan.grid, pose, radius, bp.margin)
        v = _project(plan, pose, grid, radius, progress, cfg)
        ap = _aperture(v, grid, fb, scan, cfg)
        # after the first pass the last map's array centre sits at the new apex (s = 0)
        # and the face lies ``offset`` in front of it: start there, not from the coarse
        # search, which can hop by whole pitches between passes (the ends of a long arc
        # barely tell them apart); from a stale offset (the last pass's, ~1 mm before
        # the radial move) the fit fell half a pitch off on the 128-element twin
        start = None if emap is None else (0.0, offset)
        lattice = _lattice(v, grid, fb, scan, pose, radius, ap, cfg)
        emap = _element_map(v, grid, fb, scan, pose, radius, cfg, warnings,
                            fit_pitch=True, start=start,
                            pitch=None if lattice is None else lattice.pitch)
        pitch, center = ((emap.pitch, emap.center_x) if emap is not None
                         else (None, ap.center_x))
        width = probe.element_count * pitch if pitch is not None else ap.width
        support = np.abs(grid.x - center) < 0.5 * width
        arc = fit_arc_center(v, grid, fb, radius, c0, support=support,
                             correlation_length=None if probe is None else probe.pitch)
        scale = probe.pitch / pitch if pitch is not None else 1.0
        r_arc = float(np.hypot(arc.dx, radius - arc.dz))
        pose, radius, step = _update(pose, radius, arc, center, ap.center_y, scale)
        # the apex moved (radius − r_arc) towards the scan along the radius
        offset = 0.0 if emap is None else float(emap.focus_offset) - (radius - r_arc)
        pose, eps = _pass_theta_x(v, grid, fb, scan, ap, pose, radius, cfg)
        step.append(eps * 0.5 * ap.height)
        if cfg.convex.fit_tilts and pitch is not None:
            pose, turn, tilt_u = _tilt_step(v, grid, pitch, ap, support, pose, warnings)
            step.append(turn * 0.5 * ap.height)
        history.append({"iteration": n + 1, "radius_of_curvature": radius,
                        "theta_deg": list(pose.angles_deg), "origin": list(pose.origin),
                        "arc_width": ap.width, "height": ap.height,
                        "apparent_pitch": pitch,
                        "update": step})
        if max(abs(step[0]) * radius, abs(step[1]) * radius, *(abs(x) for x in step[2:])
               ) < cfg.convex.tolerance:
            break
    # the final map starts at the last centre (now the apex)
    start = None if emap is None else (0.0, offset)
    return pose, radius, arc, tilt_u, start


def _pass_theta_x(v, grid, fb, scan, ap, pose, radius, cfg) -> tuple[Pose, float]:
    """θx from the lens centre in a geometry pass (:func:`_lens_tilt`; 0 when there is
    no significant lens or no finite centre): the source frame turned about the apex
    tangent by −ε. Left to the whole-band pass (session 10), the passes ran with the
    angular spectrum's θx error ε (0.5° on the 128-element C5-2 twin): the trial face
    then lies ε y cos φ off the true one along its normal, and the waves the scan
    window keeps (leaning towards the scan's normal, θy off the apex's) carry each
    element's pattern sideways by that distance times their slope, so the element
    lines tilted by ~ε sin θy (θz off by 0.0065° / −0.0095° on the noisy /
    noise-free twin, σ 0.0008°) and twisted between the arc's halves."""
    lens, _ = lens_focus_step(v, grid, fb, scan.medium, ap, cfg.lens)
    eps, _ = _lens_tilt(lens, ap, v, grid, fb, radius, cfg)
    if not np.isfinite(eps) or eps == 0.0:
        return pose, 0.0
    return _turn_about_x(pose, eps, v, grid, fb, ap, radius), eps


def _turn_about_x(pose: Pose, eps: float, v: NDArray, grid: PlaneGrid, fb: NDArray, ap,
                  radius: float) -> Pose:
    """The source frame turned by −ε about the axis along x through (0, 0, ⟨Z⟩), ⟨Z⟩
    the face's power-weighted depth below the apex (:func:`_aperture_mean` of
    R (cos φ − 1)): about the apex itself the face points move by −ε Z along y, and
    the next pass read that mean as a move of the elevation centre (−73, +25, +2 µm
    on the C5-2 twin: one more pass)."""
    depth = _aperture_mean(radius * (np.cos(grid.x / radius) - 1.0), v, grid, fb, ap)
    return move_source_frame(pose, rotation=rotation_matrix(-eps, 0.0, 0.0),
                             pivot=np.array([0.0, 0.0, depth]))


def _lattice(v, grid, fb, scan, pose, radius, ap, cfg):
    """The period of the element pattern (:func:`element_lattice`): the start of the
    element map's pitch fit, whose residual has local minima an end-element hop apart
    (~1.6 % of the pitch at 128 elements: from the nominal pitch the map stayed 1.5 %
    off on the C5-2 twin). None (the nominal pitch then) without ``convex.lattice_start``,
    an array description, or a fit. Support: the array's nominal extent about the
    aperture centre and the scan's footprint, each less two pitches."""
    probe = scan.probe
    if not cfg.convex.lattice_start or probe is None or probe.element_count < 8:
        return None
    p0, count = probe.pitch, probe.element_count
    lo, hi = arc_footprint(scan.grid, pose, radius)
    s = grid.x
    support = ((np.abs(s - ap.center_x) < 0.5 * count * p0 - 2 * p0)
               & (s > lo + 2 * p0) & (s < hi - 2 * p0))
    rows = np.abs(grid.y - ap.center_y) < 0.5 * ap.height
    try:
        lattice = element_lattice(v, grid, fb, pitch=p0, count=count,
                                  sound_speed=scan.medium.sound_speed, support=support,
                                  rows=rows, reference=ap.center_x)
    except FitError:
        return None
    # a start within the map's basin or none: far off, the nominal pitch is the better bet
    return lattice if abs(lattice.pitch / p0 - 1) < 0.05 else None


def _tilt_step(v, grid, pitch, ap, support, pose, warnings):
    """Turn the source frame about the apex normal by the element-line tilt on the
    unrolled face (θz); returns the pose, the tilt α (rad) and its standard uncertainty
    (nan when the fit fails)."""
    rows = np.abs(grid.y - ap.center_y) < 0.5 * ap.height
    try:
        alpha, u_a = element_line_tilt(v, grid, pitch, support=support, rows=rows)
    except FitError as exc:
        warnings.append(f"no element-line tilt (θz kept): {exc.detail}")
        return pose, 0.0, float("nan")
    return move_source_frame(pose, rotation=rotation_matrix(0.0, 0.0, -alpha)), alpha, u_a


def characterize_convex_transmit(
    scan: HydrophoneScan,
    config: CharacterizationConfig | None = None,
    *,
    radius_of_curvature: float | None = None,
    drive: DriveSignal | None = None,
    calibration: HydrophoneCalibration | None = None,
    geometry_bins: int | None = None,
    iterations: int | None = None,
    progress: bool | None = None,
) -> ConvexTransmitResult:
    """Characterize the transmit side of a convex array from a hydrophone scan.

    Parameters
    ----------
    scan : HydrophoneScan
        Raster scan, shape (nx, ny, nt); its probe description gives the element count,
        pitch and width (arc lengths) of the element map.
    config : CharacterizationConfig, optional
        The knobs of the flat pipeline (band, orientation, back-projection, aperture,
        lens, onset, transmit, elements) apply unchanged.
    radius_of_curvature : float, optional
        Nominal R in m (the start of the fit); default: the scan's probe description
        (``scan.probe.array``, a convex :class:`~holoprobe.geometry.ArrayGeometry`).
    drive : DriveSignal, optional
        Drive voltage (default ``scan.drive``); without one no impulse response.
    calibration : HydrophoneCalibration, optional
        Hydrophone sensitivity (default ``scan.calibration``).
    geometry_bins, iterations : int, optional
        Override ``config.convex.geometry_bins`` / ``.iterations``.
    progress : bool or None
        Progress bars.

    Returns
    -------
    ConvexTransmitResult
    """

    t_total = time.perf_counter()
    cfg = CharacterizationConfig() if config is None else config
    if not isinstance(scan, HydrophoneScan):
        raise InputError("expected a holoprobe.measurement.HydrophoneScan", field="scan")
    if radius_of_curvature is None:
        array = scan.probe.array if scan.probe is not None else None
        if array is None or array.radius_of_curvature is None:
            raise InputError("the scan's probe description has no radius of curvature: "
                             "give radius_of_curvature (m)", field="radius_of_curvature")
        radius_of_curvature = array.radius_of_curvature
    if not (np.isfinite(radius_of_curvature) and radius_of_curvature > 0):
        raise InputError(f"expected a positive radius of curvature in m, got "
                         f"{radius_of_curvature!r}", field="radius_of_curvature")
    # the steps share their bins over threads of their own: BLAS threads within them
    # only oversubscribe the cores (their spinning cost ~5 s of 34 s CPU on the
    # 128-element C5-2 twin at load 12)
    with blas_threads(1):
        return _transmit(scan, cfg, float(radius_of_curvature), drive, calibration,
                         geometry_bins, iterations, progress, t_total)


def _transmit(scan: HydrophoneScan, cfg: CharacterizationConfig, radius_of_curvature: float,
              drive: DriveSignal | None, calibration: HydrophoneCalibration | None,
              geometry_bins: int | None, iterations: int | None, progress: bool | None,
              t_total: float) -> ConvexTransmitResult:
    """:func:`characterize_convex_transmit` after its checks."""
    timings: dict[str, float] = {}
    warnings: list[str] = []
    medium = scan.medium
    t = time.perf_counter()
    band, nodes = _band_and_nodes(scan, calibration, cfg, warnings)
    orientation, _ = scan_orientation(band, scan.grid, medium, cfg, warnings)
    start = convex_start_pose(scan, band, orientation, cfg, warnings)
    timings["orientation"] = time.perf_counter() - t
    history: list[dict[str, Any]] = []
    t = time.perf_counter()
    cv = cfg.convex
    gb = _geometry_bins(band.spectrum, geometry_bins or cv.geometry_bins,
                        cv.geometry_threshold_db)
    pose, radius, arc, tilt_u, map_start = _geometry_iterations(
        scan, np.ascontiguousarray(band.spectrum[:, :, gb]), band.frequencies[gb],
        start, float(radius_of_curvature), cfg,
        iterations or cv.iterations, progress, history, warnings)
    timings["geometry"] = time.perf_counter() - t
    t = time.perf_counter()
    bp = cfg.backprojection
    grid = unrolled_grid(scan.grid, pose, radius, bp.margin)
    velocity = _band_velocity(scan, band, nodes, pose, radius, grid, cfg, progress,
                              warnings)
    timings["backprojection"] = time.perf_counter() - t
    if np.isfinite(tilt_u):  # θz from the element lines (the last geometry pass)
        orientation = dataclasses.replace(orientation, u_theta_z=tilt_u)
    return _finish(scan, cfg, velocity, grid, band, pose, radius, arc, orientation,
                   drive if drive is not None else scan.drive, history, warnings, timings,
                   t_total, map_start)


def _envelopes(spectra: NDArray, bins: NDArray, n_samples: int) -> NDArray[np.float64]:
    """Envelopes (..., nt) of traces given by their band bins (..., nb): the analytic
    signal of the band alone (the conjugate convention: e^{−iωt} back to time)."""
    full = np.zeros((*spectra.shape[:-1], n_samples), complex)
    full[..., bins] = spectra
    return np.abs(np.fft.fft(full, axis=-1))


def _earliest_column(scan: HydrophoneScan, band: BandSpectrum) -> tuple[int, int, float]:
    """The trace above the face point nearest to the scan plane: (ix, iy) and the scan
    x (m) of the vertex of the earliest envelope peak along x.

    A convex face's strongest trace need not be its nearest: the elevation lens gathers
    the field as it travels, so the traces far out along the arc (~23 mm from the face
    for a C5-2 10 mm above its apex) are the strongest while the nearest lie above the
    apex. In each column along x the strongest row is taken (the elevation centre);
    of the columns within 10 dB of the strongest, the earliest envelope peak (a
    parabola through the peak times within 0.5 µs of it gives its x) marks the face
    point whose normal is the scan's.
    """
    energy = np.sum(np.abs(band.spectrum) ** 2, axis=2)  # (nx, ny)
    rows = np.argmax(energy, axis=1)
    cols = np.arange(energy.shape[0])
    level = energy[cols, rows]
    strong = np.flatnonzero(level >= 0.1 * level.max())
    env = _envelopes(band.spectrum[strong, rows[strong]], band.bins, scan.n_samples)
    k = np.argmax(env, axis=1)
    m = env.shape[1]
    lo, mid, hi = (env[np.arange(k.size), (k + d) % m] for d in (-1, 0, 1))
    curv = lo - 2.0 * mid + hi
    frac = np.where(curv < 0, 0.5 * (lo - hi) / np.where(curv < 0, curv, -1.0), 0.0)
    t_peak = (k + frac) / scan.sampling_rate
    best = int(np.argmin(t_peak))
    x = scan.grid.x[strong]
    near = t_peak <= t_peak[best] + 0.5e-6
    x_min = float(x[best])
    if near.sum() >= 3:
        a, b, _ = np.polyfit(x[near], t_peak[near], 2)
        if a > 0 and x[near].min() <= -b / (2 * a) <= x[near].max():
            x_min = float(-b / (2 * a))
    return int(strong[best]), int(rows[strong[best]]), x_min


def convex_start_pose(scan: HydrophoneScan, band: BandSpectrum, orientation,
                cfg: CharacterizationConfig, warnings: list[str]) -> Pose:
    """The trial source frame of the first geometry iteration: its apex on the face
    point nearest to the scan plane (:func:`_earliest_column`), with the apex plane
    parallel to the scan plane about y (θy = 0: the nearest point's normal is the
    scan's), θx and θz from the angular spectrum, z0 = c0 × the onset of the earliest
    trace (:func:`initial_distance`).

    Neither the strongest trace (far out along the arc, where the lens has gathered
    the field: z0 14 mm too long on a C5-2's 96 mm scan) nor the angular spectrum's θy
    (the centroid of a ±37° fan the scan window cuts unevenly: 4.5° off there) is a
    start the geometry iterations recover from. The iterations then turn the apex about
    the centre of curvature to the array's centre. With ``iterations.initial_z0`` the
    old start: that z0 above the scan origin, θy from the angular spectrum.
    """
    c0 = scan.medium.sound_speed
    if cfg.iterations.initial_z0 is not None:
        return orientation.pose(origin=(0.0, 0.0, float(cfg.iterations.initial_z0)))
    i, j, x_min = _earliest_column(scan, band)
    z0, _ = initial_distance(band, scan.n_samples, scan.sampling_rate, scan.start_time, c0,
                             cfg, warnings, trace_index=(i, j))
    if x_min in (float(scan.grid.x[0]), float(scan.grid.x[-1])):
        warnings.append(f"the earliest arrival lies at the scan's edge (x = "
                        f"{x_min * 1e3:.3g} mm): the scan may not cover the face's "
                        "nearest point")
    rot = rotation_matrix(orientation.theta_x, 0.0, orientation.theta_z)
    origin = np.array([0.0, 0.0, z0]) - rot @ np.array([x_min, 0.0, 0.0])
    return Pose(orientation.theta_x, 0.0, orientation.theta_z, tuple(origin))


def _band_and_nodes(scan: HydrophoneScan, calibration, cfg: CharacterizationConfig,
                    warnings: list[str]) -> tuple[BandSpectrum, tuple[NDArray, NDArray] | None]:
    """The signal band and the spectrum at the nodes of the whole-band back-projection:
    every D-th bin (``convex.band_step``) from ``_NODE_PAD`` nodes below the band to as
    many above it (None when D = 1). Nodes outside the band carry the data there, so
    that the band's edge bins are interpolated, not extrapolated."""
    fs, nt = scan.sampling_rate, scan.n_samples
    spectrum = to_frequency(scan_pressure(scan, calibration, warnings, cfg))
    band = signal_band(spectrum, frequency_axis(nt, fs), scan.grid, fs,
                       scan.medium.sound_speed, cfg, warnings)
    step = _band_step(band, scan, cfg.convex.band_step)
    if step == 1:
        return band, None
    lo, hi = int(band.bins[0]), int(band.bins[-1])
    first = lo - step * min(_NODE_PAD, (lo - 1) // step)
    count = int(np.ceil((hi - first) / step)) + 1 + _NODE_PAD
    nodes = first + step * np.arange(count)
    nodes = nodes[nodes <= nt // 2]
    node_spec = np.ascontiguousarray(spectrum[:, :, nodes], dtype=np.complex128) / fs
    return band, (nodes, node_spec)


def _band_velocity(scan: HydrophoneScan, band: BandSpectrum, nodes, pose: Pose,
                   radius: float, grid: PlaneGrid, cfg: CharacterizationConfig, progress,
                   warnings: list[str]) -> NDArray[np.complex128]:
    """The face velocity on every band bin: projected at the nodes (every D-th bin,
    :func:`_band_and_nodes`), the band's bins interpolated in frequency with the face
    signal gated in time (:func:`_gate`); every band bin projected when there are no
    nodes or when the gate would cut the signal (power at its edge, noise included,
    above ``convex.gate_leakage`` of the peak power)."""
    if nodes is None:
        return _project(_plan(band.spectrum, scan, band.frequencies, cfg), pose, grid,
                        radius, progress, cfg)
    bins, node_spec = nodes
    df = 1.0 / (scan.n_samples / scan.sampling_rate)
    f_nodes = bins * df
    v = _project(_plan(node_spec, scan, f_nodes, cfg), pose, grid, radius, progress, cfg)
    period = 1.0 / (f_nodes[1] - f_nodes[0])
    start, leak = _gate(v, f_nodes, period, _face_peak_time(scan, band, pose, radius))
    if leak > cfg.convex.gate_leakage:
        warnings.append(f"the face signal does not fit a {period * 1e6:.3g} µs gate "
                        f"(edge power {leak:.1e}): every band bin projected")
        return _project(_plan(band.spectrum, scan, band.frequencies, cfg), pose, grid,
                        radius, progress, cfg)
    return _gated_interpolation(v, f_nodes, band.frequencies, start, period)


def _gated_interpolation(values: NDArray, f_nodes: NDArray, f_out: NDArray, start: float,
                         period: float) -> NDArray[np.complex128]:
    """Spectra (..., nn) at nodes spaced 1/period → (..., nout) at ``f_out``: the
    period-periodic time signal of the nodes cut to the gate [start, start + period)
    (delays are positive phases): V(f_i) = Σ_j V(f_j) e^{iω_ij t_c} sinc(Δf_ij T_D),
    t_c the gate's middle."""
    diff = f_out[:, None] - f_nodes[None, :]
    weights = np.exp(2j * np.pi * diff * (start + 0.5 * period)) * np.sinc(diff * period)
    flat = np.ascontiguousarray(values).reshape(-1, f_nodes.size)
    with blas_threads(1):  # one thin product: threads only cost under load
        out = flat @ weights.T
    return out.reshape(*values.shape[:-1], f_out.size)


def _band_step(band: BandSpectrum, scan: HydrophoneScan, step: int) -> int:
    """D of ``convex.band_step`` (0: auto, the largest ≤ 4 that leaves a gate of ≥ 4 µs
    and ≥ 8 nodes in the band)."""
    if step > 0:
        return int(step)
    record = scan.n_samples / scan.sampling_rate
    nb = band.frequencies.size
    return int(max(1, min(4, record // 4e-6, nb // 8)))


def _face_peak_time(scan: HydrophoneScan, band: BandSpectrum, pose: Pose,
                    radius: float) -> float:
    """Expected time (s after the record's start) of the face signal's peak: the peak of
    the strongest trace's envelope less the travel time from the cylinder to it."""
    energy = np.sum(np.abs(band.spectrum) ** 2, axis=2)
    i, j = np.unravel_index(int(np.argmax(energy)), energy.shape)
    envelope = _envelopes(band.spectrum[i, j], band.bins, scan.n_samples)
    t_peak = float(np.argmax(envelope)) / scan.sampling_rate
    point = pose.to_global(np.array([scan.grid.x[i], scan.grid.y[j], 0.0]))
    distance = float(np.hypot(point[0], point[2] + radius) - radius)
    return t_peak - distance / scan.medium.sound_speed


def _gate(velocity: NDArray, freqs: NDArray, period: float, expected: float
          ) -> tuple[float, float]:
    """Start (s after the record's start) of the gate of length ``period`` that holds
    the face signal, and the power at its edge, noise included (fraction of the peak
    power).

    The projected bins are spaced 1/period: their time signal repeats every period. Its
    power summed over the face, on 64 samples of a period, is quietest where the gate
    should begin; of the repetitions, the gate is the one that holds ``expected``.
    """
    t = np.arange(64) * (period / 64)
    phases = np.exp(-2j * np.pi * np.outer(freqs, t))  # (nf, 64)
    flat = np.ascontiguousarray(velocity).reshape(-1, freqs.size)
    with blas_threads(1):
        power = np.sum(np.abs(flat @ phases) ** 2, axis=0)
    smooth = np.convolve(np.concatenate([power[-2:], power, power[:2]]), np.ones(5) / 5,
                         mode="valid")
    k = int(np.argmin(smooth))
    start = float(t[k])
    start += np.floor((expected - start) / period) * period
    return start, float(smooth[k] / power.max())


def _theta_x_step(pose: Pose, orientation, lens, ap, velocity: NDArray, grid: PlaneGrid,
                  fb: NDArray, radius: float, sound_speed: float,
                  cfg: CharacterizationConfig, warnings: list[str]):
    """θx of the scan from the lens centre (``convex.theta_x_from_lens``; docs/convex.md),
    and the face velocity re-referenced to the turned frame.

    A θx error ε of the scan pose turns the trial cylinder about the apex tangent (x):
    a face point at arc angle φ = s/R moves along its normal by ε y cos φ, which leaves
    the delay slope ε cos φ / c0 along y on the face. The lens fit takes it up by moving
    its centre: y_L = y_a + ε ⟨cos φ⟩ / κ for a lens centred on the elevation aperture
    (centre y_a), ⟨cos φ⟩ the power-weighted mean over the aperture's columns (the lens
    fit weights each column by its power; 0.94 on a C5-2's ±37.6° arc, where κ (y_L −
    y_a) alone left 6 % of ε). So ε = κ (y_L − y_a) / ⟨cos φ⟩, and the source frame is
    turned about the apex by it; its uncertainty joins κ σ(y_L), κ σ(y_a), (y_L − y_a)
    σ(κ) and κ × ``convex.lens_axis_tolerance`` (how far the lens axis may sit off the
    aperture centre), over ⟨cos φ⟩. The velocity projected on the untilted cylinder is
    then moved onto the turned one (to first order in ε: the phase
    e^{−iω ε cos φ (y − y_a)/c0}); left as projected, its aperture mean lost
    sinc(f H ε / c0) (16 % of the transmit IR's peak on the 128-element C5-2 twin, its
    θx 0.5° off before this step) and the element map's middle elements more than its
    ends. The lens centre is moved with it (to y_a). Without a significant lens θx stays
    the angular spectrum's and the velocity as projected.

    Returns
    -------
    pose, orientation, velocity, lens
    """
    eps, u = _lens_tilt(lens, ap, velocity, grid, fb, radius, cfg)
    if lens is None or eps == 0.0:
        return pose, orientation, velocity, lens
    if not (np.isfinite(eps) and np.isfinite(u)):
        warnings.append("θx kept from the angular spectrum: no finite lens centre")
        return pose, orientation, velocity, lens
    pose = _turn_about_x(pose, eps, velocity, grid, fb, ap, radius)
    cos_phi = np.cos(grid.x / radius)
    slope = (eps / sound_speed) * np.multiply.outer(cos_phi, grid.y - ap.center_y)
    velocity = velocity * np.exp(-2j * np.pi * np.multiply.outer(slope, fb))
    lens = dataclasses.replace(lens, center_y=float(ap.center_y))
    return pose, dataclasses.replace(orientation, u_theta_x=u), velocity, lens


def _lens_tilt(lens, ap, velocity: NDArray, grid: PlaneGrid, fb: NDArray, radius: float,
               cfg: CharacterizationConfig) -> tuple[float, float]:
    """The θx error ε = κ (y_L − y_a)/⟨cos φ⟩ of :func:`_theta_x_step` (rad) and its
    standard uncertainty; (0, 0) without ``convex.theta_x_from_lens`` or a significant
    lens, NaN where the lens centre is not finite."""
    cv = cfg.convex
    if not cv.theta_x_from_lens or lens is None or not lens.significant:
        return 0.0, 0.0
    kappa, offset = float(lens.curvature), float(lens.center_y - ap.center_y)
    mean_cos = _aperture_mean(np.cos(grid.x / radius), velocity, grid, fb, ap)
    u = float(np.sqrt((kappa * lens.center_y_uncertainty) ** 2
                      + (kappa * ap.center_y_uncertainty) ** 2
                      + (offset * lens.curvature_uncertainty) ** 2
                      + (kappa * cv.lens_axis_tolerance) ** 2)) / mean_cos
    return kappa * offset / mean_cos, u


def _aperture_mean(values: NDArray, velocity: NDArray, grid: PlaneGrid, fb: NDArray,
                   ap) -> float:
    """Mean of per-column ``values`` (ns,) over the aperture's columns, each weighted by
    its power Σ_y,f ω²|v|² inside the aperture (the lens fit's weighting)."""
    cols = np.abs(grid.x - ap.center_x) < 0.5 * ap.width
    rows = np.abs(grid.y - ap.center_y) < 0.5 * ap.height
    power = np.einsum("syf,f->s", np.abs(velocity[cols][:, rows]) ** 2, fb**2)
    return float(np.sum(power * values[cols]) / np.sum(power))


def _record_range(u_rec: NDArray, scan: HydrophoneScan, onset: float, c0: float,
                  noise: float = 0.0) -> float:
    """How far (m) from the face the record holds the whole pulse: c0 × (record end −
    onset − the time the mean surface velocity takes, from its onset, to 99.9 % of its
    energy, or to its last sample above 5 × the noise σ ``noise`` (m/s) if that is
    sooner: the noise's own energy, spread over the record, pushes the 99.9 % point
    towards the record's end (1 % of noise energy: a 27.5 mm reach read as 2 mm); inf
    when that is not positive (no cut then)."""
    fs, nt = scan.sampling_rate, u_rec.size
    i0 = int(np.round((onset - scan.start_time) * fs)) % nt
    power = np.roll(np.abs(u_rec) ** 2, -i0)
    energy = np.cumsum(power)
    length = float(np.searchsorted(energy, 0.999 * energy[-1])) / fs
    above = np.flatnonzero(power > 25.0 * noise**2) if noise > 0 else np.array([], int)
    if above.size:
        length = min(length, (above[-1] + 1) / fs)
    reach = c0 * (scan.start_time + nt / fs - onset - length)
    return reach if reach > 0 else float("inf")


def _element_map(velocity, grid, fb, scan, pose, radius, cfg, warnings, *,
                 fit_pitch: bool = False, start: tuple[float, float] | None = None,
                 pitch: float | None = None, views: float | None = None):
    """The element map on the unrolled face; ``pitch``: the model's pitch (the start of
    the pitch fit; default the probe's); ``views``: with ``convex.element_views`` each
    element's own view of the scan (:func:`arc_element_views`), cut at this range (m,
    :func:`_record_range`; inf: no cut); None: the flat footprint."""
    probe = scan.probe
    if probe is None or probe.element_count < 2 or not cfg.elements.enabled:
        return None
    ec = cfg.elements
    try:
        return fit_element_map(
            velocity, grid, fb, count=probe.element_count,
            pitch=probe.pitch if pitch is None else pitch,
            element_width=min(probe.element_width, probe.pitch),
            footprint=arc_footprint(scan.grid, pose, radius), distance=float(pose.origin[2]),
            sound_speed=scan.medium.sound_speed, min_resolution=ec.min_resolution,
            dead_threshold=ec.dead_threshold, weak_threshold=ec.weak_threshold,
            ridge=ec.ridge, search_pitches=ec.search_pitches, fit_pitch=fit_pitch,
            fit_sound_speed=False, start=start, optimizer=cfg.convex.map_optimizer,
            edge_silent_threshold=ec.edge_silent_threshold,
            local_views=(arc_element_views(scan.grid, pose, radius,
                                           None if np.isinf(views) else views)
                         if views is not None and cfg.convex.element_views else None))
    except (InputError, FitError) as exc:
        warnings.append(f"no element map: {exc.detail}")
        return None


def _band_limit_gain(grid: PlaneGrid, fb: NDArray, medium, ap, lens,
                     cfg: CharacterizationConfig) -> NDArray[np.float64]:
    """The aperture mean's band-limit gain g(ω) (``transmit.band_limit_correction``;
    :func:`band_limit_gain`) of the unrolled face: along y the face is straight, and
    along the arc the box mean is taken over a W wide strip whose wavenumbers the
    projection keeps up to ω/c0 locally (kR ≈ 760 on a C5-2: curvature is a
    1/(kR) correction). Ones when the correction is off."""
    if not cfg.transmit.band_limit_correction:
        return np.ones(fb.size)
    focus = lens.focus if lens is not None and lens.significant else float("inf")
    return band_limit_gain(grid, fb, medium, width=ap.width, height=ap.height,
                           center_x=ap.center_x, center_y=ap.center_y, focus=focus,
                           lens_center_y=None if lens is None else lens.center_y)


def _window_step(scan: HydrophoneScan, cfg: CharacterizationConfig, velocity: NDArray,
                 grid: PlaneGrid, fb: NDArray, pose: Pose, radius: float, ap, emap, lens,
                 focus: float, warnings: list[str]):
    """W, H and F without the bias of the scan window (``aperture.window_correction``,
    ``convex.window_model``; docs/convex.md).

    ``"arc"``: :func:`arc_window_bias` of the model on the fitted cylinder, on
    ``convex.window_bins`` of the aperture fit's bins; W, H and F are refitted on
    the same bins of the data and the model's bias subtracted (the biases depend on the
    bins: on the 128-element twin the all-bin W is 42 µm wider than the 12-bin one,
    so a bias measured on 12 bins does not correct the all-bin fit);
    ``window_uncertainty`` × each correction joins its uncertainty. The model's W is
    N·pitch (N strips of W/N − kerf): the corrected fit estimates that, and the
    reported W is the active aperture (N − 1)·pitch + width, one kerf less (compared
    with the active aperture without it, the 12-bin corrected W read +73 / +89 µm on
    the 110 / 160 mm scans of the 128-element twin, +15 / +31 µm with it). ``"flat"``:
    the old model laid flat on the
    apex's tangent plane (:func:`_flat_window_step`).

    Returns
    -------
    ap, lens, focus, record
        Corrected aperture and lens (and reported F); ``record``: ``window_bias_width``,
        ``window_bias_height``, ``window_bias_focus`` (m; NaN when off or failed).
    """
    nan = float("nan")
    record = dict(window_bias_width=nan, window_bias_height=nan, window_bias_focus=nan)
    ac = cfg.aperture
    if not ac.window_correction:
        return ap, lens, focus, record
    if cfg.convex.window_model == "flat":
        return _flat_window_step(scan, cfg, grid, pose, ap, emap, lens, focus, record,
                                 warnings)
    a_opt, l_opt = _aperture_options(cfg)
    bins = ac.window_bins if cfg.convex.window_bins is None else cfg.convex.window_bins
    try:
        sel = np.searchsorted(fb, np.asarray(ap.frequencies, float)[_pick(ap, bins)])
        sub = fit_aperture(velocity[:, :, sel], grid, fb[sel], scan.medium, **a_opt)
        sub_lens = lens  # the 12-bin refit is used only if the whole step succeeds
        if lens is not None and lens.significant:
            sub_lens = fit_lens_focus(velocity[:, :, sel], grid, fb[sel], scan.medium, sub,
                                      **l_opt)

        def project(pressure: NDArray, f: NDArray) -> NDArray:
            return _project(_plan(pressure, scan, f, cfg), pose, grid, radius, False, cfg)

        strips = _geometry_model(emap, scan.probe, delays=False)
        bias = arc_window_bias(scan.grid.with_pose(pose), grid, scan.medium, radius, sub,
                               sub_lens, project, aperture_options=a_opt, lens_options=l_opt,
                               strips=strips, max_bins=bins,
                               guard_angle=np.deg2rad(cfg.backprojection.guard_angle_deg),
                               eps=_eps(cfg))
    except (InputError, FitError) as exc:
        warnings.append(f"no scan-window correction of W, H and F: {exc.detail}")
        return ap, lens, focus, record
    # the model's W is N strips of W/N − kerf: its refit minus W is the bias of the
    # model's N·pitch; the active aperture is that less one kerf, (N − 1)·pitch + width
    kerf = float(strips[1]) if strips is not None else 0.0
    ap = _corrected_aperture(sub, bias, ac.window_uncertainty, record, kerf=kerf)
    return (ap, *_corrected_lens(sub_lens, bias.focus, ac.window_uncertainty, focus), record)


def _corrected_aperture(ap, bias, frac: float, record: dict, *, kerf: float | None):
    """The aperture fit less the window ``bias`` (recorded in ``record``): H − bias,
    ``frac`` × the bias joining σ(H); W − bias − ``kerf`` likewise, or with ``kerf``
    None W as fitted and the whole W bias joining σ(W) (the flat model's W bias is not
    the arc's)."""
    record.update(window_bias_width=bias.width, window_bias_height=bias.height,
                  window_bias_focus=bias.focus)
    if kerf is None:
        width, u_width = ap.width, float(np.hypot(ap.width_uncertainty, bias.width))
    else:
        width = ap.width - bias.width - kerf
        u_width = float(np.hypot(ap.width_uncertainty, frac * bias.width))
    return dataclasses.replace(
        ap, width=width, width_uncertainty=u_width, height=ap.height - bias.height,
        height_uncertainty=float(np.hypot(ap.height_uncertainty, frac * bias.height)))


def _corrected_lens(lens, bias: float, frac: float, focus: float):
    """The lens with F − ``bias`` (``frac`` × bias joins σ(F)) and the reported F."""
    if lens is None or not lens.significant or not np.isfinite(bias):
        return lens, focus
    f_new = lens.focus - bias
    u_f = float(np.hypot(lens.focus_uncertainty, frac * bias))
    lens = dataclasses.replace(lens, focus=f_new, focus_uncertainty=u_f,
                               curvature=1.0 / f_new, curvature_uncertainty=u_f / f_new**2)
    return lens, f_new if np.isfinite(focus) else focus


def _flat_window_step(scan: HydrophoneScan, cfg: CharacterizationConfig, grid: PlaneGrid,
                      pose: Pose, ap, emap, lens, focus: float, record: dict,
                      warnings: list[str]):
    """``convex.window_model = "flat"``: :func:`scan_window_bias` of the fitted model
    laid flat (the strips at their arc pitch on the apex's tangent plane, the fitted H
    and lens) and posed as the scan is relative to the apex plane. Along y the face is
    straight, so the model's H and F biases are taken as those of the arc and
    subtracted; along the arc the flat model radiates differently (the measured W bias
    has the other sign on the 32-element twin), so W is left as fitted and the flat
    model's W bias is added to its uncertainty in quadrature."""
    ac, bp = cfg.aperture, cfg.backprojection
    a_opt, l_opt = _aperture_options(cfg)
    try:
        bias = scan_window_bias(scan.grid.with_pose(pose), grid, scan.medium, ap, lens,
                                aperture_options=a_opt, lens_options=l_opt,
                                strips=_geometry_model(emap, scan.probe, delays=False),
                                max_bins=ac.window_bins,
                                guard_angle=np.deg2rad(bp.guard_angle_deg), eps=bp.eps)
    except (InputError, FitError) as exc:
        warnings.append(f"no scan-window correction of H and F: {exc.detail}")
        return ap, lens, focus, record
    ap = _corrected_aperture(ap, bias, ac.window_uncertainty, record, kerf=None)
    return (ap, *_corrected_lens(lens, bias.focus, ac.window_uncertainty, focus), record)


def _finish(scan, cfg, velocity, grid, band: BandSpectrum, pose, radius, arc, orientation,
            drive, history, warnings, timings, t_total, map_start=None
            ) -> ConvexTransmitResult:
    t = time.perf_counter()
    medium = scan.medium
    c0, fs, nt = medium.sound_speed, scan.sampling_rate, scan.n_samples
    fb = band.frequencies
    ap = _aperture(velocity, grid, fb, scan, cfg)
    lens, why = lens_focus_step(velocity, grid, fb, medium, ap, cfg.lens)
    if lens is None:
        warnings.append(f"the lens fit failed ({why}); no lens delays reversed")
    focus = float(lens.focus) if lens is not None and lens.significant else float("inf")
    pose, orientation, velocity, lens = _theta_x_step(pose, orientation, lens, ap, velocity,
                                                      grid, fb, radius, c0, cfg, warnings)
    u_band, u_rec = lens_corrected_mean_velocity(velocity, grid, band, ap, lens, c0, nt, fs)
    z0 = float(pose.origin[2])
    # the onset is the time origin of the IR; the face is placed by the geometry
    onset, noise_u, _ = velocity_onset(u_rec, fs, scan.start_time, z0, c0, cfg.onset)
    u_onset = onset_uncertainty(u_rec, noise_u, fs, cfg.onset)
    emap = _element_map(velocity, grid, fb, scan, pose, radius, cfg, warnings,
                        start=map_start,
                        views=_record_range(u_rec, scan, onset, c0, noise_u))
    phase = np.exp(-2j * np.pi * fb * (onset - scan.start_time))
    velocity = velocity * phase
    full = np.zeros(nt // 2 + 1, complex)
    full[band.bins] = u_band * phase / _band_limit_gain(grid, fb, medium, ap, lens, cfg)
    mean_velocity = to_time(full, nt) * fs
    probe = scan.probe
    count = probe.element_count if probe is not None else 1
    pitch = emap.pitch if emap is not None else (probe.pitch if probe else ap.width)
    width = min(probe.element_width, pitch) if probe is not None else ap.width
    fraction = min(count * width / ap.width, 1.0) if count > 1 else 1.0
    ir, spec = transmit_response(mean_velocity, fs, medium, z0, drive, fraction, cfg.transmit,
                              warnings)
    n_fit = round((ap.width - width) / pitch) + 1 if count > 1 else 1
    if count > 1 and n_fit != count:
        warnings.append(f"the arc of {ap.width * 1e3:.4g} mm holds {n_fit} elements at the "
                        f"pitch {pitch * 1e3:.4g} mm; the file says {count}")
    u_r = float(arc.dz_uncertainty) if arc is not None else float("nan")
    # θy of the apex plane comes from the arc fit (tilt about the apex) and the element
    # centring (turn about C), not from the angular spectrum
    u_ty = float(np.hypot(arc.dx_uncertainty, ap.center_x_uncertainty) / radius
                 if arc is not None else orientation.u_theta_y)
    ap, lens, focus, window = _window_step(scan, cfg, velocity, grid, fb, pose, radius, ap,
                                           emap, lens, focus, warnings)
    timings["finish"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t_total
    return ConvexTransmitResult(
        pose=pose, radius_of_curvature=float(radius), radius_uncertainty=u_r,
        angle_uncertainties=(orientation.u_theta_x, u_ty, orientation.u_theta_z),
        aperture=ap, arc_angle=float(ap.width / radius), element_count=n_fit,
        element_map=emap, lens=lens, lens_focus=focus,
        geometry=ArrayGeometry.convex(count, pitch, radius, width, ap.height), grid=grid,
        velocity=velocity, frequencies=fb, mean_velocity=mean_velocity, sampling_rate=fs,
        onset=float(onset), onset_uncertainty=u_onset, impulse_response=ir, ir_spectrum=spec,
        history=history, warnings=warnings, timings=timings, window_bias=window)
