"""Settings of the hologram characterization of single-element sources (bowls, discs).

One frozen dataclass, the ``[hologram]`` section of
:class:`holoprobe.characterize.CharacterizationConfig` (TOML and ``--set hologram.key=value``).
Units are SI (m, Hz); angles at this user boundary in degrees (``_deg``).
"""

from __future__ import annotations

from dataclasses import dataclass

from holoprobe.errors import InputError

__all__ = ["HologramConfig"]


@dataclass(frozen=True)
class HologramConfig:
    """Knobs of alignment, back-projection onto the source surface, power and field.

    Attributes
    ----------
    prune_tolerance : float
        The hologram is expanded in propagating plane waves; the weakest components whose
        summed magnitude is at most this fraction of the total are dropped (bounds the
        relative error of the field at the focus; default 1e-5).
    guard_energy : float
        Padding rule: the propagation angle containing this fraction of the plane's
        propagating power sets the guard angle of :func:`holoprobe.propagation.padded_shape`
        (default 0.999).
    focal_guard_energy : float
        The same for the plane waves evaluated around the focus (alignment, focal field;
        default 0.99: the focal lobe is made of the beam's main waves, the weak wide-angle
        edge waves need no guard there).
    coarse_guard_energy : float
        The same for the coarse search of the focus along the beam (default 0.99).
    lobe_reach_wavelengths : float
        The focal lobe is searched for within this many wavelengths of the coarse maximum
        along the beam (default 12).
    guard_margin_deg : float
        Added to that angle, in degrees (default 10).
    focus_search_points : int
        Samples of the coarse search for the focal maximum along the beam (default 400).
    window_taper : float
        Focused sources: the hologram is brought to zero over this fraction of each axis
        of the scan window (Tukey α; half at each edge) before the focal maximum and the
        axis are found; the change against the untapered window is the window term of
        their uncertainties (default 0.3; 0: no taper and no window term).
    window_taper_follows_edge : bool
        Scale ``window_taper`` by the share of the power in the band it covers that goes
        outward (away from the hologram's intensity centroid, by its phase gradient):
        outgoing edge diffraction is tapered, field still converging onto the focus is
        kept (default True; False: the fixed ``window_taper``).
    window_model : bool
        For a spherical cap of known geometry, the window term is the bias of the
        (tapered) estimate on a model: the hologram a uniform cap of the file's geometry,
        placed at the estimated focus and axis, radiates onto the same window
        (:func:`holoprobe.characterize.cap_hologram`); that bias is removed from the focus
        and axis and ``window_model_uncertainty`` of it kept as the window term (default
        True). False (or no geometry): the window term is |untapered − tapered estimate|,
        which measured the untapered window's bias and overstated the tapered one's 3–30×
        on twins.
    window_model_uncertainty : float
        Fraction of the modelled window bias counted as its standard uncertainty
        (default 1: the model's velocity is uniform, and on a twin with a dead 40°
        sector the uniform model's −1.9 µm correction was wrong by all of it).
    window_model_source_points : float
        Source points per wavelength of the model cap's rings quadrature (default 3).
    focus_smoothing : float
        The focal maximum is that of the axial |p|² profile smoothed by a sixth-order
        Gaussian kernel of width this fraction of the lobe's shorter −6 dB half-length
        (default 0.15): ripples of 1e-4 of the peak with 1–2 λ periods (window edges,
        λ/2 sampling) moved the local maximum of long lobes by 20–60 µm; the kernel moves
        O'Neil's exact bowl lobes (F/0.5–F/3) by < 1 µm. 0: the local maximum of |p|².
    axis_planes : int
        Planes across the focal lobe whose lobe centres define the acoustic axis
        (default 9).
    axis_span : float
        The planes span this fraction of the lobe's −6 dB axial extent on each side of the
        focal maximum (default 0.8).
    axis_iterations : int
        Re-orientations of the planes to the fitted axis (default 2).
    monte_carlo : int
        How the hologram's noise reaches the alignment's uncertainties. 0 (default): linear
        propagation, exact to first order in the noise and the limit of infinitely many
        Monte-Carlo draws, at the cost of about one draw; n > 0: Monte Carlo with n noise
        realisations (a check of the linearisation; a few draws give a σ that is itself
        uncertain by ~1/√(2n)); refused for a transient spherical cap's hologram with
        ``transient_focus = "band"`` (the band focus is propagated linearly; checked by
        ``characterize_hologram``, where the hologram's kind is known: a CW hologram
        has no band focus and honours the draws). ``noise_level = 0`` turns the noise
        term off.
    noise_level : float or None
        Noise standard deviation of the hologram in Pa per sample; ``None``: estimated
        from its evanescent spectrum when the scan samples beyond k (else 0).
    surface_step_wavelengths : float
        Sampling step of the source surface in wavelengths (default 0.25).
    fit_step_wavelengths : float
        Coarser step (wavelengths) of the surface while the radius or tilt is updated
        (default 0.5); the final reconstruction uses ``surface_step_wavelengths``.
    fit_apex : bool
        Circular sources: find the source's position along its axis from the data (the
        back-projected edge is sharpest on the true surface) and cross-check the file's
        ``zPosition`` with it (default False: ten more back-projections onto an annulus
        around the edge, about as long as the rest of the back-projection).
    apex_from_data : bool
        Use that position instead of the file's (default False: on twins it is within
        −4…+14 µm (σ 6–19 µm) where the scan sees the rim widely enough, see
        ``apex_min_capture_deg``; it needs the extra back-projections and a scan wider
        than the file's zPosition needs).
    apex_min_capture_deg : float
        The data's apex is only sought when the scan window sees the rim at least this
        many degrees outwards of the rim's normal
        (:func:`holoprobe.characterize.rim_capture_angle`; default 34): narrower scans
        lose the edge's outward diffraction, which moved the sharpest edge towards the
        medium on twins (noise-free as at 30 dB) by +116 µm at 22.9°, +80 µm at 28.4°,
        +34 µm (σ 12) at 29.0°, against −4…+14 µm (σ 6–19) at 35.5° and −3 µm at 40.4°.
    apex_span_wavelengths : float
        Half-span (wavelengths) of the first pass of that search (default 1.5).
    apex_warning_sigma : float
        Warn when the file's ``zPosition`` and the data's differ by more than this many
        standard uncertainties and by more than a quarter wavelength (default 3).
    surface_margin : float
        The reconstruction surface extends this fraction of the aperture beyond it on each
        side (default 0.15): the aperture edge is found, not assumed.
    curvature_iterations : int
        Updates of the effective radius of curvature (phase flattening; default 4).
    curvature_tolerance : float
        Stop when the relative update of the radius is below this (default 2e-5).
    edge_level : float
        The aperture edge is where the azimuthally averaged velocity amplitude falls to this
        fraction of the plateau (default 0.5, the band-limited step's midpoint).
    uniformity_db : float
        Fraction of the aperture above this level (dB) relative to the median velocity
        amplitude inside it (default −6).
    hot_spot_ratio : float
        Regions whose amplitude exceeds this multiple of the median are hot spots
        (default 1.5).
    dead_ratio : float
        Regions whose amplitude is below this fraction of the median are dead (default 0.3).
    phase_defect_rad : float
        Regions whose phase departs from the median by more than this (rad) are phase
        defects (default 0.6).
    min_region_area_wavelengths : float
        Regions smaller than this many square wavelengths are ignored (default 1).
    band_fraction : float
        Transient holograms: the frequency bins whose scan-plane energy above the noise
        floor (the median bin's) is at least this fraction of the strongest's are
        back-projected for power and exports (default 1e-3).
    band_eps : float
        Relative tolerance of the type-3 NUFFTs of those band back-projections (default
        1e-4: on the 200 × 200 × 778 twin of an 87 mm bowl the surface velocity moves by
        4e-5 and the surface power by 1e-6 relative to 1e-6, at ~60 % of the time).
    band_decimation : int
        Transient holograms: back-project every D-th frequency bin of the record
        (zero-padded to a multiple of D), i.e. the bins of a record D times shorter. Exact
        when the source's velocity waveform lasts less than that shorter record (a pulsed
        source does; the scan's long edge-wave tails do not matter). 0 (default): the
        largest D of 8, 4, 2, 1 whose surface velocity passes the compactness check
        (``band_alias_tolerance``); D ≥ 1: that D, unchecked (1: every bin, as before).
    band_alias_tolerance : float
        Compactness check of ``band_decimation`` = 0: the surface velocity's signal energy
        (inside the aperture, noise floor removed) outside the best half of the shorter
        record must stay below this fraction (default 1e-3).
    velocity_gate : bool
        Transient holograms: the surface velocity at the analysis frequency (the maps,
        uniformity, defects) comes from the back-projected surface waveforms kept where
        the pulse stands above the noise (:func:`holoprobe.characterize.gated_velocity`):
        the back-projected noise lasts the whole record, a source's motion far less
        (default True; the power and the exported band velocity are not gated).
    velocity_gate_level : float
        The gate keeps the span where the aperture's summed envelope energy exceeds this
        multiple of its noise floor (default 2: signal at least as strong as the noise).
    transient_focus : {"peak", "band"}
        Transient focused holograms: where the focal maximum and the lobe axis come from.
        "peak" (default): the CW estimate on the record's peak bin (the focus of that one
        frequency; its noise is the whole record's against that bin's share of the pulse).
        "band": the maximum of the pulse-pressure-squared integral ∫ p² dt, i.e. of
        Σ_j |p_j|² over every bin of the band, and the line through its in-plane maxima
        (:func:`holoprobe.characterize.align_band`): the focus of the pulse, with the
        pulse's noise (on a 5-cycle 61² twin at 40 dB its z scatter is 2.5× smaller,
        but its σ z fell 1.36× short of the errors over 10 draws: not yet shown honest);
        it costs one expansion and alignment pass per bin (27 bins: ~50 s CPU).
    focus_estimator : {"auto", "lobe", "aperture"}
        Focused sources: where the focal maximum comes from. "lobe": the plane-wave
        field of the hologram (:func:`holoprobe.characterize.align_focused`, the window's
        bias removed). "aperture": the field the reconstructed source radiates from the
        nodes within ``aperture_margin_wavelengths`` of its fitted rim
        (:func:`holoprobe.characterize.aperture_focus`), the same estimate on a uniform
        cap's hologram giving its bias (removed, and kept in σ): on 81² 40 dB twins its
        scatter is 2–3 µm against the lobe estimate's 13–18 µm (the waves that cross the
        focus at angles the aperture cannot radiate carry most of the noise), at the
        cost of a few type-3 NUFFTs over the surface (171²: ~2.5 s CPU). "auto"
        (default): "aperture" where the lobe estimate's σ exceeds
        ``aperture_focus_above`` and the aperture estimate's σ is the smaller (on clean
        data the lobe σ is mostly its window-model term, and the aperture's own model
        term can be larger). Wherever the aperture focus is taken, the axis is
        that radiated field's lobe axis too
        (:func:`holoprobe.characterize.aperture_axis`; on 81² 40 dB twins ~1.6× less
        scatter than the plane-wave axis; the uniform cap's axis error is not removed
        but added to σ; summary key ``alignment.axis_estimator``).
    aperture_margin_wavelengths : float
        Rim margin (wavelengths) of the radiating nodes for the aperture focus (default
        1: the reconstruction blurs the rim over about λ).
    aperture_focus_above : float
        "auto": the lobe estimate's largest coordinate σ (m) above which the aperture
        focus is taken (default 10 µm).
    flattened_order : {"auto", "x", "y"}
        MATLAB data of shape [n, nt] (or [n]) on ``xGrid``/``yGrid`` axis vectors, n =
        nx·ny: which index runs fastest in the flattened points. "x" (MATLAB's
        ``reshape(p, [], nt)`` of an [nx, ny, nt] array), "y" (of a meshgrid-shaped
        [ny, nx, nt] one); "auto" (default): on a non-square grid the reading whose
        image is smoother (the other is a sheared scramble), on a square grid "x" with a
        warning (the two readings are each other's transpose: the file cannot tell).
    profile_points : int
        Samples of each axial and transverse profile (default 401).
    field_grid_points : int
        Samples per axis of the 3-D field grid around the focus (default 31).
    """

    prune_tolerance: float = 1e-5
    guard_energy: float = 0.99
    focal_guard_energy: float = 0.99
    coarse_guard_energy: float = 0.99
    lobe_reach_wavelengths: float = 12.0
    guard_margin_deg: float = 10.0
    focus_search_points: int = 400
    window_taper: float = 0.3
    window_taper_follows_edge: bool = True
    window_model: bool = True
    window_model_uncertainty: float = 1.0
    window_model_source_points: float = 3.0
    focus_smoothing: float = 0.15
    axis_planes: int = 9
    axis_span: float = 0.8
    axis_iterations: int = 2
    monte_carlo: int = 0
    noise_level: float | None = None
    surface_step_wavelengths: float = 0.25
    fit_step_wavelengths: float = 0.5
    fit_apex: bool = False
    apex_from_data: bool = False
    apex_span_wavelengths: float = 1.5
    apex_min_capture_deg: float = 34.0
    apex_warning_sigma: float = 3.0
    surface_margin: float = 0.15
    curvature_iterations: int = 4
    curvature_tolerance: float = 2e-5
    edge_level: float = 0.5
    uniformity_db: float = -6.0
    hot_spot_ratio: float = 1.5
    dead_ratio: float = 0.3
    phase_defect_rad: float = 0.6
    min_region_area_wavelengths: float = 1.0
    band_fraction: float = 1e-3
    band_eps: float = 1e-4
    band_decimation: int = 0
    band_alias_tolerance: float = 1e-3
    velocity_gate: bool = True
    velocity_gate_level: float = 2.0
    transient_focus: str = "peak"
    focus_estimator: str = "auto"
    aperture_margin_wavelengths: float = 1.0
    aperture_focus_above: float = 10e-6
    flattened_order: str = "auto"
    profile_points: int = 401
    field_grid_points: int = 31


def check_band_monte_carlo(cfg: HologramConfig) -> None:
    """Refuse ``monte_carlo`` > 0 with the band focus (``transient_focus = "band"``): the
    band focus propagates its noise linearly (:func:`holoprobe.characterize.align_band`);
    the draws are for the peak bin's CW focus only. For a transient spherical cap's
    hologram only (the config alone cannot tell: a CW hologram has no band focus)."""
    if cfg.transient_focus == "band" and cfg.monte_carlo > 0:
        raise InputError(f"expected 0 with hologram.transient_focus = 'band' (the band "
                         f"focus propagates its noise linearly; Monte-Carlo draws are for "
                         f"the peak bin's focus), got {cfg.monte_carlo!r}",
                         field="hologram.monte_carlo")
