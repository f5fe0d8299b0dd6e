"""One characterization run of a single-element source from its hologram (CW or transient).

``characterize_hologram(hologram)`` chains the steps of issue 13: alignment (focused:
focal maximum and lobe axis; flat: tilt and offset) → the source surface placed on the
aligned axis → back-projection with the phase-flattest radius of curvature and the measured
aperture → power through the hologram and leaving the surface → uniformity → the focal
field. Every position is in **scan coordinates** (origin at the scan grid's x = 0, y = 0 on
the scan plane, x and y along the grid's axes, z along the plane's normal away from the
source). ``summary`` gives the documented ``summary.json`` tree.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from holoprobe.characterize._alignment import (
    FocusAlignment,
    align_band,
    align_focused,
    band_noise_levels,
    correct_window_bias,
    hologram_noise_level,
    window_model,
)
from holoprobe.characterize._aperture_focus import aperture_axis, aperture_focus
from holoprobe.characterize._hologram_config import HologramConfig, check_band_monte_carlo
from holoprobe.characterize._hologram_field import (
    hologram_grid,
    hologram_power,
    plane_wave_field,
    propagation_guard_angle,
)
from holoprobe.characterize._source_band import (
    BandProjection,
    VelocityGate,
    gated_velocity,
    project_band,
)
from holoprobe.characterize._source_field import FocalField, focal_field, focal_waveform
from holoprobe.characterize._source_surface import (
    SourcePlacement,
    SourceReconstruction,
    Uniformity,
    fit_source_surface,
    hologram_plan,
    rim_capture_angle,
    rim_offset,
    surface_flux,
    uniformity,
)
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import Medium, PlaneGrid, SourceGeometry
from holoprobe.measurement import Hologram
from holoprobe.propagation import ProjectionPlan
from holoprobe.signal import to_frequency

__all__ = ["HologramResult", "characterize_hologram", "hologram_summary"]

_FLAT = ("flat-disc", "flat-rectangle")


@dataclass(frozen=True)
class HologramResult:
    """Everything one hologram characterization produced (scan coordinates, SI).

    Attributes
    ----------
    hologram : Hologram
        The input.
    grid : PlaneGrid
        The scan grid (identity pose).
    frequency : float
        Frequency (Hz) of the CW analysis (the hologram's, or a transient one's peak bin).
    pressure : ndarray, complex, shape (nx, ny)
        The CW hologram analysed, Pa (a transient one: the spectrum at ``frequency``, Pa·s).
    alignment : FocusAlignment or None
        Focused sources.
    reconstruction : SourceReconstruction
        Aligned surface, its velocity (and pressure) at ``frequency``.
    power_hologram, power_surface : float
        W (transient: mean power over the record).
    inside_aperture_fraction : float
        Share of the surface power leaving through the aperture.
    uniformity : Uniformity
    focal : FocalField or None
    band : ndarray
        Frequencies (Hz) of the record's bins kept (transient: hologram power, focal
        waveform).
    band_velocity : ndarray, complex, shape (n_surface, nv) or None
        Surface velocity (m/s·s) per bin of ``velocity_band`` (transient only), for exports.
    focal_waveform : ndarray, shape (nt,) or None
        Transient focused sources: the pressure waveform (Pa) at the focal maximum, on the
        hologram's time axis from t = 0.
    noise_level : float
        Noise per hologram sample (Pa) used for uncertainties.
    timings : dict
        Seconds per step.
    warnings : list of str
    velocity_band : ndarray, shape (nv,) or None
        Transient: frequencies (Hz) of ``band_velocity``, the bins of a record of
        ``velocity_record`` samples at the hologram's sampling rate (:func:`project_band`:
        the hologram's record shortened ``band_decimation`` times).
    velocity_record : int or None
        Samples of that record (transient only).
    band_decimation : int
        D of that record (1: the hologram's own bins).
    velocity_gate : VelocityGate or None
        Transient: the gate whose surface waveforms gave ``reconstruction.velocity``
        (``hologram.velocity_gate``; None: ungated, the record's bin at ``frequency``).
    """

    hologram: Hologram
    grid: PlaneGrid
    frequency: float
    pressure: NDArray[np.complex128]
    alignment: FocusAlignment | None
    reconstruction: SourceReconstruction
    power_hologram: float
    power_surface: float
    inside_aperture_fraction: float
    uniformity: Uniformity
    focal: FocalField | None
    band: NDArray[np.float64]
    band_velocity: NDArray[np.complex128] | None
    noise_level: float
    focal_waveform: NDArray[np.float64] | None = None
    timings: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    velocity_band: NDArray[np.float64] | None = None
    velocity_record: int | None = None
    band_decimation: int = 1
    velocity_gate: VelocityGate | None = None


def _cw_view(hologram: Hologram, cfg: HologramConfig
             ) -> tuple[NDArray, float, NDArray, NDArray, float]:
    """(CW pressure, its frequency, band spectra (nx, ny, nb), band freqs, energy factor)."""
    f0, rate = hologram.frequency, hologram.sampling_rate
    if f0 is not None:  # CW (Hologram: exactly one of frequency and sampling_rate is set)
        p = np.asarray(hologram.pressure, np.complex128)
        return p, float(f0), p[:, :, None], np.array([f0]), 0.0
    assert rate is not None
    fs = float(rate)
    n = hologram.n_samples
    spec = to_frequency(np.asarray(hologram.pressure, float), axis=-1) / fs
    # the record starts at start_time: restore the phase of t = 0
    freqs = np.arange(spec.shape[-1]) * fs / n
    spec = spec * np.exp(1j * 2 * np.pi * freqs * hologram.start_time)
    energy = np.sum(np.abs(spec) ** 2, axis=(0, 1))
    energy[0] = 0.0
    peak = int(np.argmax(energy))
    band = _band_bins(energy, cfg.band_fraction, spec.shape[0] * spec.shape[1])
    return spec[:, :, peak], float(freqs[peak]), spec[:, :, band], freqs[band], fs / n


def _band_bins(energy: NDArray, fraction: float, n_points: int) -> NDArray[np.intp]:
    """Bins whose energy above the noise floor is at least ``fraction`` of the strongest's.

    White noise gives every bin the same energy (within 1/√n_points over the scan's
    n_points samples); the median bin's is taken as that floor (a pulse fills less than
    half of an oversampled record's band). Noise-only bins would add the noise's power to
    both powers and cost a back-projection each.
    """
    floor = float(np.median(energy[1:]))
    excess = energy - floor
    peak = float(excess.max())
    keep = (excess >= fraction * peak) & (energy > floor * (1 + 6 / np.sqrt(n_points)))
    keep[0] = False
    return np.nonzero(keep)[0]


def _geometry(hologram: Hologram, kind: str | None, radius: float | None,
              aperture: float | tuple[float, float] | None) -> tuple[str, float | None,
                                                                     tuple[float, float],
                                                                     float]:
    """Nominal kind, R, aperture (along e1, e2) and opening from the file and overrides."""
    g = hologram.geometry
    if kind is None:
        kind = g.kind if g is not None else None
    if kind is None:
        kind = "spherical-cap" if radius is not None else None
    if kind is None:
        raise InputError("the hologram carries no Geometry; give the source kind and size "
                         "(--source, --aperture, --radius-of-curvature)", field="Geometry")
    if kind not in ("spherical-cap", *_FLAT):
        raise InputError(f"expected spherical-cap, flat-disc or flat-rectangle for a hologram, "
                         f"got {kind!r} (arrays: characterize a transient array scan)",
                         field="--source")
    if aperture is None and g is not None:
        aperture = (g.aperture_max, g.aperture_min)
    if aperture is None:
        raise InputError("unknown aperture: give --aperture", field="Geometry.apertureMax")
    pair = np.asarray(aperture, float)
    ap = (float(pair), float(pair)) if pair.ndim == 0 else (float(pair[0]), float(pair[1]))
    if kind == "flat-disc":
        ap = (max(ap), max(ap))
    if kind == "spherical-cap":
        if radius is None and g is not None:
            radius = g.radius_of_curvature
        if radius is None:
            raise InputError("a spherical cap needs a radius of curvature: give "
                             "--radius-of-curvature", field="Geometry.radiusOfCurvature")
        ap = (max(ap), max(ap))
    else:
        radius = None
    opening = g.opening_diameter if g is not None else 0.0
    return kind, radius, ap, opening


def characterize_hologram(hologram: Hologram, cfg: HologramConfig | None = None, *,
                          source: str | None = None, radius_of_curvature: float | None = None,
                          aperture: float | tuple[float, float] | None = None,
                          progress: bool | None = False) -> HologramResult:
    """Characterize a single-element source from its hologram.

    Parameters
    ----------
    hologram : Hologram
        CW or transient hologram (:func:`holoprobe.io.read_hologram_any`).
    cfg : HologramConfig, optional
        The ``[hologram]`` settings.
    source : {"spherical-cap", "flat-disc", "flat-rectangle"}, optional
        Overrides the file's ``Geometry`` kind.
    radius_of_curvature : float, optional
        Nominal R in m (overrides the file; the effective R is then measured).
    aperture : float or (float, float), optional
        Nominal aperture in m (diameter, or width along x and height along y).
    progress : bool or None
        Progress bars.

    Returns
    -------
    HologramResult
    """
    cfg = cfg or HologramConfig()
    timings: dict[str, float] = {}
    warnings: list[str] = list(hologram.notes)  # what the reader assumed
    t0 = time.perf_counter()
    kind, radius, ap, opening = _geometry(hologram, source, radius_of_curvature, aperture)
    if hologram.is_transient and kind == "spherical-cap":  # before any work: where the
        check_band_monte_carlo(cfg)  # band focus applies (a CW hologram honours the draws)
    z_pos = float(hologram.z_position)
    medium = hologram.medium
    p_cw, f0, band_spec, band, df = _cw_view(hologram, cfg)
    grid, p3 = hologram_grid(hologram.grid.x, hologram.grid.y, p_cw)
    p = p3[:, :, 0]
    k = float(medium.wavenumber(f0))
    noise = cfg.noise_level if cfg.noise_level is not None else \
        hologram_noise_level(p, grid.dx, grid.dy, k)
    guard = propagation_guard_angle(p, grid, f0, medium, energy=cfg.guard_energy,
                                    margin_deg=cfg.guard_margin_deg)
    timings["prepare"] = time.perf_counter() - t0
    t = time.perf_counter()
    alignment, placement = _place_source(p, grid, f0, medium, kind, radius, ap, opening,
                                         z_pos, cfg, noise,
                                         (band_spec, band) if hologram.is_transient else None)
    timings["alignment"] = time.perf_counter() - t
    t = time.perf_counter()
    plan = hologram_plan(p3, grid, np.array([f0]), medium, guard_angle=guard)
    rec = fit_source_surface(p, grid, f0, medium, placement, guard_angle=guard, cfg=cfg,
                             progress=progress, plan=plan)
    rec = _recentre(p, grid, f0, medium, rec, guard, cfg, progress, plan)
    del plan
    alignment = _window_step(alignment, rec, p, grid, f0, medium, cfg, warnings, noise)
    _check_apex(rec, grid, z_pos, 0.25 * float(medium.wavelength(f0)), cfg, warnings)
    timings["backprojection"] = time.perf_counter() - t
    t = time.perf_counter()
    w_s, w_h, inside_fraction, projected = _source_power(
        hologram, rec, p, f0, band_spec, band, df, grid, guard, progress, cfg)
    rec, gate = _gate_step(hologram, rec, projected, f0, cfg)
    unif = uniformity(rec, cfg)
    timings["power"] = time.perf_counter() - t
    t = time.perf_counter()
    focal, waveform = None, None
    if alignment is not None:
        focal, waveform = _focal_step(hologram, rec, alignment, p, f0, band_spec, band,
                                      grid, cfg)
    timings["field"] = time.perf_counter() - t
    if not abs(w_s - w_h) <= 0.01 * abs(w_h):
        warnings.append(f"power leaving the surface ({w_s:.4g} W) and through the hologram "
                        f"({w_h:.4g} W) differ by more than 1 %: the reconstruction surface "
                        "misses part of the beam or the scan truncates it")
    timings["total"] = time.perf_counter() - t0
    return HologramResult(hologram, grid, f0, p, alignment, rec, float(w_h), float(w_s),
                          float(inside_fraction), unif, focal, band,
                          None if projected is None else projected.velocity,
                          float(noise), waveform, timings, warnings,
                          None if projected is None else projected.frequencies,
                          None if projected is None else projected.record,
                          1 if projected is None else projected.decimation, gate)


def _place_source(p: NDArray[np.complex128], grid: PlaneGrid, f0: float, medium: Medium,
                  kind: str, radius: float | None, ap: tuple[float, float],
                  opening: float, z_pos: float, cfg: HologramConfig, noise: float,
                  band: tuple[NDArray[np.complex128], NDArray[np.float64]] | None = None
                  ) -> tuple[FocusAlignment | None, SourcePlacement]:
    """Alignment and the starting placement of the source surface.

    A spherical cap: :func:`align_focused` (focal maximum and lobe axis, searched from
    −0.9 z to 2 R along the axis), then for a transient hologram with
    ``hologram.transient_focus = "band"`` :func:`align_band` on its ``band`` (spectra,
    frequencies); the cap placed ``z_pos`` behind the axis' crossing of the scan plane.
    A flat source: :func:`_flat_start` (no alignment returned).
    """
    if kind != "spherical-cap":
        return None, _flat_start(p, grid, f0, medium, kind, ap, z_pos, cfg)
    assert radius is not None  # _geometry: a spherical cap has its radius of curvature
    span = (-0.9 * z_pos, 2.0 * float(radius))
    alignment = align_focused(p, grid, f0, medium, search_span=span, cfg=cfg,
                              noise_level=noise, window_term=not cfg.window_model)
    if band is not None and cfg.transient_focus == "band" and band[1].size > 1:
        levels = (np.full(band[1].size, noise) if cfg.noise_level is not None  # given:
                  else band_noise_levels(band[0], grid, band[1], medium, noise))  # white
        alignment = align_band(band[0], grid, band[1], medium, alignment, pressure=p,
                               frequency=f0, cfg=cfg, noise_levels=levels)
    d = alignment.axis
    crossing = alignment.focus - alignment.focus[2] / d[2] * d
    return alignment, SourcePlacement(kind, crossing - z_pos * d, d, radius, ap, opening)


def _source_power(hologram: Hologram, rec: SourceReconstruction, p: NDArray[np.complex128],
                  f0: float, band_spec: NDArray[np.complex128], band: NDArray[np.float64],
                  df: float, grid: PlaneGrid, guard: float, progress: bool | None,
                  cfg: HologramConfig) -> tuple[float, float, float, BandProjection | None]:
    """Power leaving the source surface and through the hologram (W).

    A transient hologram: the mean power over the record, through the hologram from every
    band bin (``4 df²`` Σ), leaving the surface from the band back-projected on the bins
    of a shortened record (:func:`project_band`: ``4 (fs / record)(fs / n)`` Σ); a CW
    one: the reconstruction's own bin.

    Returns
    -------
    w_s, w_h : float
        Power leaving the surface and through the hologram plane (W).
    inside_fraction : float
        Share of ``w_s`` leaving inside the aperture.
    band : BandProjection or None
        The surface velocity and pressure per bin (transient only).
    """
    medium, weights = hologram.medium, rec.unrolled.surface.weights
    if not hologram.is_transient:
        flux = surface_flux(rec.pressure, rec.velocity, weights)
        w_s = float(flux.sum())
        return w_s, hologram_power(p, grid, f0, medium), float(flux[rec.inside].sum() / w_s), \
            None
    projected = project_band(hologram, rec.unrolled, grid, band, band_spec, rec.inside,
                             guard_angle=guard, cfg=cfg, progress=progress)
    flux = surface_flux(projected.pressure, projected.velocity, weights)
    fs = float(hologram.sampling_rate or 0.0)
    w_s = 4 * (fs / projected.record) * (fs / hologram.n_samples) * float(flux.sum())
    inside_fraction = float(flux[rec.inside].sum() / flux.sum())
    w_h = 4 * df * df * sum(hologram_power(band_spec[:, :, j], grid, f, medium)
                            for j, f in enumerate(band))
    return w_s, w_h, inside_fraction, projected


def _window_step(alignment: FocusAlignment | None, rec: SourceReconstruction,
                 p: NDArray[np.complex128], grid: PlaneGrid, f0: float, medium: Medium,
                 cfg: HologramConfig, warnings: list[str], noise: float = 0.0
                 ) -> FocusAlignment | None:
    """The scan window's bias of the focus and axis, modelled on a uniform cap placed
    where the source was (:func:`correct_window_bias`; ``hologram.window_model``)."""
    forced = alignment is not None and cfg.focus_estimator == "aperture"
    if alignment is None or not cfg.window_model:
        if forced:
            warnings.append('hologram.focus_estimator = "aperture" needs '
                            "hologram.window_model (its bias model): the lobe estimate "
                            "is kept")
        return alignment
    g = rec.geometry
    cap = SourceGeometry("spherical-cap", min(g.aperture), max(g.aperture),
                         g.radius_of_curvature, g.hole_diameter)
    try:
        model = window_model(grid, f0, medium, cap, g.apex, g.axis, cfg)
        corrected = correct_window_bias(alignment, p, grid, f0, medium, cap, g.apex, g.axis,
                                        cfg, model=model)
    except FitError as exc:  # a cap too weakly focused for an axial maximum
        warnings.append(f"focus and axis not corrected for the scan window: {exc}")
        return alignment
    wanted = cfg.focus_estimator == "aperture" or (
        cfg.focus_estimator == "auto"
        and float(np.max(corrected.focus_uncertainty)) > cfg.aperture_focus_above)
    if not wanted or alignment.definition == "band":
        if forced and alignment.definition == "band":
            warnings.append('hologram.focus_estimator = "aperture" is not made for the '
                            'band focus (hologram.transient_focus = "band"): the band '
                            "lobe estimate is kept")
        return corrected
    radiated = _aperture_step(corrected, rec, p, grid, f0, medium, cfg, noise, model)
    if cfg.focus_estimator == "auto" and (float(np.max(radiated.focus_uncertainty))
                                          >= float(np.max(corrected.focus_uncertainty))):
        return corrected  # auto: the aperture's estimate only where it is the surer one
    return radiated


def _aperture_step(alignment: FocusAlignment, rec: SourceReconstruction,
                   p: NDArray[np.complex128], grid: PlaneGrid, f0: float, medium: Medium,
                   cfg: HologramConfig, noise: float,
                   model: tuple[NDArray[np.complex128], NDArray[np.float64]]
                   ) -> FocusAlignment:
    """The focal maximum radiated by the reconstructed aperture (:func:`aperture_focus`,
    ``hologram.focus_estimator = "aperture"``): the nodes within
    ``aperture_margin_wavelengths`` of the fitted rim; the same estimate on the uniform
    cap's hologram ``model``, minus its exact maximum, is the bias removed (and
    ``window_model_uncertainty`` × it is added to σ). The axis: the lobe axis of
    the same radiated field (:func:`aperture_axis`); its error on the cap's hologram
    (noise-free, ≤ 0.002° on the acceptance twins) is not removed but added to σ."""
    g, surf = rec.geometry, rec.unrolled.surface
    rel = surf.points - g.apex
    rho = np.linalg.norm(rel - (rel @ g.axis)[:, None] * g.axis, axis=1)
    keep = rho <= 0.5 * max(g.aperture) + cfg.aperture_margin_wavelengths * float(
        medium.wavelength(f0))
    args = (grid, f0, medium, surf.points, surf.normals, surf.weights, keep)
    focus, sigma = aperture_focus(p, *args, alignment.focus, noise_level=noise,
                                  velocity=rec.velocity[:, 0], cfg=cfg)
    biased, _ = aperture_focus(model[0], *args, model[1], cfg=cfg)
    bias = biased - model[1]
    axis, axis_sigma = aperture_axis(p, *args, focus, alignment.axis,
                                     noise_level=noise, velocity=rec.velocity[:, 0], cfg=cfg)
    cap_axis, _ = aperture_axis(model[0], *args, model[1], g.axis, cfg=cfg)
    tilt = float(np.arccos(min(1.0, abs(float(cap_axis @ g.axis)))))
    return replace(alignment, focus=focus - bias, focus_uncertainty=np.hypot(
        sigma, cfg.window_model_uncertainty * np.abs(bias)), estimator="aperture",
        axis=axis * np.sign(axis @ alignment.axis), axis_estimator="aperture",
        axis_uncertainty=float(np.hypot(axis_sigma, cfg.window_model_uncertainty * tilt)))


def _gate_step(hologram: Hologram, rec: SourceReconstruction,
               projected: BandProjection | None, f0: float, cfg: HologramConfig
               ) -> tuple[SourceReconstruction, VelocityGate | None]:
    """A transient hologram's surface velocity at ``f0`` from its gated surface waveforms
    (:func:`gated_velocity`; ``hologram.velocity_gate``); unchanged otherwise."""
    if projected is None or not cfg.velocity_gate or hologram.sampling_rate is None:
        return rec, None
    gate = gated_velocity(projected, f0, float(hologram.sampling_rate), rec.inside,
                          rec.unrolled.surface.weights, rec.velocity[:, 0],
                          cfg.velocity_gate_level)
    if gate is None:
        return rec, None
    return replace(rec, velocity=gate.velocity[:, None].astype(rec.velocity.dtype)), gate


def _focal_step(hologram: Hologram, rec: SourceReconstruction, alignment: FocusAlignment,
                p: NDArray[np.complex128], f0: float, band_spec: NDArray[np.complex128],
                band: NDArray[np.float64], grid: PlaneGrid, cfg: HologramConfig
                ) -> tuple[FocalField, NDArray[np.float64] | None]:
    """The focal field of a focused source (plane-wave field from the hologram over
    ±``z_pos`` around the focus, :func:`focal_field`) and, for a transient hologram,
    the focal waveform (:func:`focal_waveform`)."""
    medium, z_pos = hologram.medium, float(hologram.z_position)
    reach = np.array([alignment.focus - z_pos * alignment.axis,
                      alignment.focus + z_pos * alignment.axis])
    fld = plane_wave_field(p, grid, f0, medium, reach=reach,
                           prune_tolerance=cfg.prune_tolerance,
                           guard_energy=cfg.focal_guard_energy,
                           guard_margin_deg=cfg.guard_margin_deg)
    apex_distance = float(np.linalg.norm(alignment.focus - rec.geometry.apex))
    mean_v = float(np.average(np.abs(rec.velocity[rec.inside, 0]),
                              weights=rec.unrolled.surface.weights[rec.inside]))
    focal = focal_field(fld, alignment.focus, alignment.axis, apex_distance=apex_distance,
                        mean_velocity=mean_v, cfg=cfg)
    waveform = None
    if hologram.sampling_rate is not None:  # transient
        waveform = focal_waveform(band_spec, grid, band, medium, alignment.focus,
                                  hologram.n_samples, float(hologram.sampling_rate), cfg=cfg)
    return focal, waveform


def _check_apex(rec: SourceReconstruction, grid: PlaneGrid, z_pos: float, least: float,
                cfg: HologramConfig, warnings: list[str]) -> None:
    """Warn when the file's zPosition and the apex found from the data disagree, or when
    the apex was asked for and the scan is too narrow to find it."""
    u = rec.apex_uncertainty
    kind = rec.geometry.kind
    if cfg.fit_apex and u is None and kind in ("spherical-cap", "flat-disc"):
        seen = np.degrees(rim_capture_angle(rec.geometry, grid))
        if seen < cfg.apex_min_capture_deg:
            warnings.append(f"the source's apex is not sought from the data: the scan sees "
                            f"its rim only {seen:.1f}° outwards of the rim's normal "
                            f"(hologram.apex_min_capture_deg = {cfg.apex_min_capture_deg:g}; "
                            "a wider scan is needed); the file's zPosition is used")
    if u is None or not abs(rec.apex_shift) > max(cfg.apex_warning_sigma * u, least):
        return
    used = "the data's" if cfg.apex_from_data else "the file's"
    warnings.append(f"the source lies {(z_pos - rec.apex_shift) * 1e3:.4g} mm behind the scan "
                    f"plane along its axis by the data (± {u * 1e3:.2g} mm), not "
                    f"{z_pos * 1e3:.4g} mm as the file's zPosition says: {used} position "
                    "is used (hologram.apex_from_data)")


def _flat_start(p: NDArray, grid: PlaneGrid, f0: float, medium: Any, kind: str,
                ap: tuple[float, float], z_pos: float, cfg: HologramConfig
                ) -> SourcePlacement:
    """Flat source: axis along the power-weighted direction through the intensity centroid."""
    fld = plane_wave_field(p, grid, f0, medium, prune_tolerance=cfg.prune_tolerance,
                           guard_energy=cfg.coarse_guard_energy,
                           guard_margin_deg=cfg.guard_margin_deg)
    d = fld.power_direction()
    intensity = np.abs(p.ravel()) ** 2
    centroid = intensity @ grid.points() / intensity.sum()
    return SourcePlacement(kind, centroid - z_pos * d, d, None, ap)


def _rim_shift(rec: SourceReconstruction, cfg: HologramConfig, step: float
               ) -> NDArray[np.float64]:
    """How far the source's centre lies from ``rec``'s apex along the surface (m).

    Circular sources: the centre of the reconstructed rim (:func:`rim_offset`, which a
    dead sector does not move); a rectangle: the amplitude-weighted centre of the nodes
    above ``edge_level`` of the median, across the normal."""
    g = rec.geometry
    if g.kind != "flat-rectangle":
        offset, _ = rim_offset(rec.unrolled, rec.velocity[:, 0], cfg, step)
        return offset if np.all(np.isfinite(offset)) else np.zeros(3)
    amp = np.abs(rec.velocity[:, 0])
    sel = amp >= cfg.edge_level * np.median(amp[rec.inside])
    centre = np.average(rec.unrolled.surface.points[sel], axis=0, weights=amp[sel])
    shift = centre - g.apex
    return shift - (shift @ g.axis) * g.axis


def _recentre(p: NDArray, grid: PlaneGrid, f0: float, medium: Any,
              rec: SourceReconstruction, guard: float, cfg: HologramConfig,
              progress: bool | None, plan: ProjectionPlan) -> SourceReconstruction:
    """Move the source so that its reconstructed aperture is centred on it, refit.

    The alignment places a cap on the focal lobe's axis and a flat source on the power
    direction through the intensity centroid; a source whose velocity is not uniform (a
    dead sector, a weak segment) tilts both away from its geometric axis. A flat source is
    moved across its normal, a cap turned about its centre of curvature (which the phase
    fit holds and a turn does not change) so that its apex moves along the sphere; moves
    below 1 % of a wavelength are not made.
    """
    wavelength = float(medium.wavelength(f0))
    step = cfg.surface_step_wavelengths * wavelength
    first = rec
    for _ in range(2):
        g = rec.geometry
        shift = _rim_shift(rec, cfg, step)
        if not np.linalg.norm(shift) > 0.01 * wavelength:
            break
        if g.radius_of_curvature is not None and g.centre is not None:
            axis = g.axis - shift / g.radius_of_curvature
            axis /= np.linalg.norm(axis)
            g = replace(g, apex=g.centre - g.radius_of_curvature * axis, axis=axis)
        else:
            g = replace(g, apex=g.apex + shift)
        rec = fit_source_surface(p, grid, f0, medium, g, guard_angle=guard, cfg=cfg,
                                 fit_apex=False, progress=progress, plan=plan)
    if rec is first:
        return rec
    return replace(rec, apex_shift=first.apex_shift, apex_uncertainty=first.apex_uncertainty,
                   data_apex=first.data_apex)


def _vec(v: NDArray | None) -> list[float] | None:
    return None if v is None else [float(x) for x in v]


def hologram_summary(result: HologramResult) -> dict[str, Any]:
    """The ``summary.json`` tree of a hologram characterization (keys documented in
    docs/formats.md; positions and directions in scan coordinates, SI units)."""
    rec, al, geo = result.reconstruction, result.alignment, result.reconstruction.geometry
    axis = al.axis if al is not None else geo.axis
    summary: dict[str, Any] = {
        "kind": "hologram_characterization",
        "coordinates": "scan: origin at the scan grid's x = 0, y = 0 on the scan plane, "
                       "z along its normal away from the source",
        "frequency": result.frequency,
        "alignment": {
            "axis_direction": _vec(axis),
            "focus_position": _vec(al.focus) if al is not None else None,
            "focus_estimator": al.estimator if al is not None else None,
            "axis_estimator": al.axis_estimator if al is not None else None,
            "power_direction": _vec(al.power_direction) if al is not None else None,
            "geometric_focus": _vec(geo.centre),
            "source_apex": _vec(geo.apex),
            "source_apex_from_data": _vec(rec.data_apex),
            "source_normal": _vec(geo.axis),
            "tilt_deg": float(np.degrees(np.arccos(min(abs(axis[2]), 1.0)))),
        },
        "source": {
            "kind": geo.kind,
            "radius_of_curvature": geo.radius_of_curvature,
            "aperture_diameter": float(max(geo.aperture)),
            "aperture_size": [float(geo.aperture[0]), float(geo.aperture[1])],
            "centre_of_curvature": _vec(geo.centre),
        },
        "acoustic_power": {
            "hologram": result.power_hologram,
            "surface": result.power_surface,
            "inside_aperture_fraction": result.inside_aperture_fraction,
            "relative_difference": (result.power_surface - result.power_hologram)
            / result.power_hologram if result.power_hologram else None,
        },
        "uniformity": {
            "fraction_above_db": result.uniformity.fraction_above,
            "median_velocity": result.uniformity.median_velocity,
            "hot_spots": result.uniformity.hot_spots,
            "dead_regions": result.uniformity.dead_regions,
            "phase_defects": result.uniformity.phase_defects,
        },
        "uncertainty": {
            "axis_direction_deg": float(np.degrees(al.axis_uncertainty)) if al else (
                None if rec.tilt_uncertainty is None
                else float(np.degrees(rec.tilt_uncertainty))),
            "focus_position": _vec(al.focus_uncertainty) if al else None,
            "radius_of_curvature": rec.radius_uncertainty,
            "source_apex_from_data_along_axis": rec.apex_uncertainty,
            "aperture_diameter": rec.aperture_uncertainty,
        },
        "noise_level": result.noise_level,
        "timings": result.timings,
        "warnings": list(result.warnings),
    }
    f = result.focal
    if f is not None:
        summary["focal_field"] = {
            "focal_pressure": f.focal_pressure,
            "gain": f.gain,
            "axial_length_6db": f.axial_length,
            "width_6db": [f.width_e1, f.width_e2],
        }
    if result.velocity_band is not None:  # transient: the bins back-projected
        summary["band"] = {"hologram_bins": int(result.band.size),
                           "surface_bins": int(result.velocity_band.size),
                           "decimation": int(result.band_decimation),
                           "focus_definition": None if al is None else al.definition,
                           "surface_record_samples": result.velocity_record,
                           "velocity_gate": None if result.velocity_gate is None else [
                               result.velocity_gate.start - result.velocity_gate.taper,
                               result.velocity_gate.stop + result.velocity_gate.taper]}
    if result.focal_waveform is not None:  # transient: the waveform's peaks, in Pa
        summary["focal_field"]["focal_pressure"] = float(np.abs(result.focal_waveform).max())
        summary["focal_field"]["peak_positive_pressure"] = float(result.focal_waveform.max())
        summary["focal_field"]["peak_negative_pressure"] = float(-result.focal_waveform.min())
    return summary
