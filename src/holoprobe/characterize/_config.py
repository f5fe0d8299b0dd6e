"""One typed configuration for the characterization pipeline (every tuning knob, with defaults).

The published MATLAB code hard-codes its tuning constants at the top of its files
(reference_spec section 3). Here they are fields of small frozen dataclasses, grouped in
sections, documented once, settable from a TOML file and from the command line, and
dumped into every output for provenance::

    [band]
    threshold_db = 40.0

    [iterations]
    count = 3

    cfg = CharacterizationConfig.from_toml("my.toml").with_overrides(["onset.threshold=6"])
    cfg.to_toml()  # the full configuration, defaults included

Units are SI (m, s, Hz); angles at this user boundary are in degrees with ``_deg``.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tomllib
import types
import typing
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from holoprobe.characterize._hologram_config import HologramConfig
from holoprobe.characterize._receive import ReceiveConfig
from holoprobe.errors import InputError
from holoprobe.plausibility import PlausibilityConfig
from holoprobe.signal import HydrophoneDeconvolutionConfig

__all__ = [
    "ApertureConfig",
    "BackProjectionConfig",
    "BandConfig",
    "CharacterizationConfig",
    "ElementsConfig",
    "IterationConfig",
    "LensConfig",
    "OnsetConfig",
    "OrientationConfig",
    "TransmitIRConfig",
    "WarningConfig",
]


@dataclass(frozen=True)
class BandConfig:
    """Which frequency bins carry signal (chosen from the data).

    Attributes
    ----------
    threshold_db : float
        Keep the bins whose scan-plane energy ``Σ|P|²`` is at most this many dB below
        the strongest bin (default 30 dB). Only these bins are back-projected; the rest
        are zero.
    band : (float, float) or None
        Explicit band (f_min, f_max) in Hz; the threshold still applies inside it.
    smooth_bins : int
        The energy is averaged over this many neighbouring bins before the band (the
        contiguous run around the strongest bin) is delimited (default 5).
    min_snr_db : float
        Bins must also exceed the noise floor by this many dB (default 3 dB).
    noise_percentile : float
        The noise floor is this percentile of the (smoothed) bin energies (default 10):
        white noise fills every bin, the signal only its band.
    """

    threshold_db: float = 30.0
    band: tuple[float, float] | None = None
    smooth_bins: int = 5
    min_snr_db: float = 3.0
    noise_percentile: float = 10.0


@dataclass(frozen=True)
class OrientationConfig:
    """Knobs of :func:`holoprobe.characterize.estimate_orientation` (paper section II D).

    Attributes
    ----------
    energy_threshold_db : float
        Bins within this many dB of the strongest bin's energy are analysed (20 dB).
    spectrum_weighting : {"velocity", "pressure"}
        Quantity whose angular spectrum is searched.
    theta_z_bounds_deg : (float, float)
        Search interval of θz in degrees.
    outlier_threshold : float
        Per-bin estimates farther than this many robust spreads from the median are
        rejected (spurious modes).
    max_tilt_deg : float
        Bins implying a larger tilt are rejected (degrees).
    """

    energy_threshold_db: float = 20.0
    spectrum_weighting: Literal["velocity", "pressure"] = "velocity"
    theta_z_bounds_deg: tuple[float, float] = (-5.0, 5.0)
    outlier_threshold: float = 5.0
    max_tilt_deg: float = 30.0


@dataclass(frozen=True)
class BackProjectionConfig:
    """Back-projection of the scan onto the source plane z = 0 (``holoprobe.propagation.project``).

    Attributes
    ----------
    eps : float
        Relative tolerance of the non-uniform FFTs (default 1e-4: the full-size P4-1
        scan's back-projected velocity within 1.5e-5 (L2) of 1e-6's, every summary value
        within 0.0012 σ of it, for ~0.2 s less CPU per pass).
    single_precision : bool
        complex64 NUFFTs (about twice as fast; ~1e-5 relative accuracy), and complex64
        FFTs in the window step's refocusing (``refocus``); false: complex128 for both.
    guard_angle_deg : float
        Padding rule of the projection (degrees, default 80 like ``project``).
    margin : float
        Extra margin in m added on every side of the scan footprint on z = 0.
    """

    eps: float = 1e-4
    single_precision: bool = True
    guard_angle_deg: float = 80.0
    margin: float = 0.0


@dataclass(frozen=True)
class ApertureConfig:
    """Knobs of :func:`holoprobe.characterize.fit_aperture` (paper section III A).

    Attributes
    ----------
    threshold_db : float
        Bins within this many dB of the strongest source bin are fitted.
    profile : {"magnitude", "coherent"}
        Profile definition (see ``fit_aperture``).
    fit_offset : bool
        Fit a noise floor per bin.
    start_level : float
        Fraction of the maximum whose crossings start the fit.
    window_correction : bool
        Remove the bias the finite scan window leaves in W, H and the lens focus
        (:func:`holoprobe.characterize.scan_window_bias`: the fitted model radiated
        onto the scan, cut to its window, back-projected and refitted); for a 2-D
        matrix array the same for the map's pitches and element sizes
        (:func:`holoprobe.characterize.matrix_window_bias`).
    window_bins : int
        Frequencies simulated for that correction (1-D; a matrix uses the bins its
        lattice was fitted on).
    window_iterations : int
        Passes of the search for the face plane (the plane where the back-projected
        source is in focus; W, H and F are fitted there).
    window_uncertainty : float
        Fraction of the correction counted as its own standard uncertainty (added in
        quadrature to the fit's): the model ignores the record's time window and the
        probe's finer structure.
    window_floor : float
        A model standard uncertainty (m) added in quadrature to W and H when the
        correction is on (0: none; on the coverage twins the corrected W and H need
        none, benchmarks/RESULTS.md, issue 10).
    """

    threshold_db: float = 20.0
    profile: Literal["magnitude", "coherent"] = "magnitude"
    fit_offset: bool = True
    start_level: float = 0.5
    window_correction: bool = True
    window_bins: int = 12
    window_iterations: int = 2
    window_uncertainty: float = 0.2
    window_floor: float = 0.0


@dataclass(frozen=True)
class LensConfig:
    """Knobs of :func:`holoprobe.characterize.fit_lens_focus` (paper eq. lens-delays).

    Attributes
    ----------
    threshold_db : float
        Bins within this many dB of the strongest source bin are fitted.
    margin_wavelengths : float
        The fit region is the aperture shrunk by this many wavelengths.
    significance : float
        F = ∞ unless the curvature exceeds this many standard uncertainties.
    max_bins : int or None
        Fit only this many bins, those with the most energy (None: all of them).
    """

    threshold_db: float = 20.0
    margin_wavelengths: float = 1.0
    significance: float = 3.0
    max_bins: int | None = 64


@dataclass(frozen=True)
class OnsetConfig:
    """Onset t0 of the lens-corrected mean surface velocity (``detect_onset``).

    Attributes
    ----------
    threshold : float
        Detection level in noise standard deviations σ (5, as the reference).
    upsample : int
        Band-limited upsampling factor before locating the zero crossing.
    polarity : {"either", "positive", "negative"}
        Which excursion counts as the pulse.
    noise_window : (float, float) or None
        Signal-free interval (start, stop) in s from the first sample for σ. Default:
        the last ``noise_window_fraction``·z0/c0 of the record (where the scan's samples
        before the wavefront arrived end up after back-projection) when that holds
        ``min_noise_samples``, else the robust estimate of ``detect_onset``.
    noise_window_fraction : float
        Length of the default noise window in units of z0/c0 (0.8: a margin before the
        wavefront's arrival time).
    min_noise_samples : int
        Fewest samples of a noise window.
    bootstrap : int
        Noise realisations for the standard uncertainty of t0 (0: none).
    seed : int
        Seed of the bootstrap's generator.
    """

    threshold: float = 5.0
    upsample: int = 10
    polarity: Literal["either", "positive", "negative"] = "either"
    noise_window: tuple[float, float] | None = None
    noise_window_fraction: float = 0.8
    min_noise_samples: int = 16
    bootstrap: int = 20
    seed: int = 0


@dataclass(frozen=True)
class IterationConfig:
    """The loop of paper Fig. 4 (pose → back-projection → fits → t0 → pose update).

    Attributes
    ----------
    count : int
        Maximum number of iterations (2, as the paper).
    tolerance : float
        Stop early when |Δx0|, |Δy0| and |Δz0| of an update are all below this (m).
    initial_z0 : float or None
        Starting distance z0 in m. ``None`` (default): estimated from the data as
        c0 × (arrival time of the wavefront at the strongest trace), assuming the scan's
        time origin is the emission; ``fallback_z0`` when that fails or falls outside
        ``z0_range``.
    fallback_z0 : float
        Starting z0 when the estimate fails (3 mm, the published code's guess).
    z0_range : (float, float)
        Plausible range of the estimated starting z0 in m.
    """

    count: int = 2
    tolerance: float = 1e-6
    initial_z0: float | None = None
    fallback_z0: float = 3e-3
    z0_range: tuple[float, float] = (0.2e-3, 50e-3)


@dataclass(frozen=True)
class TransmitIRConfig:
    """Transmit impulse response (paper eqs. transmit-impulse-response, deconvolution-transmit).

    Attributes
    ----------
    method : {"auto", "area", "wiener"}
        Division by the drive area for a delta-like drive, Wiener deconvolution otherwise.
    output_rate : float
        Sampling rate of the stored IR in Hz (250 MHz).
    duration : float or None
        IR length in s; ``None``: the record length minus the flight time z0/c0 (the
        tail of the back-projected record holds the scan's pre-arrival noise).
    delta_tolerance : float
        Delta-likeness tolerance of the "auto" choice.
    band_limit_correction : bool
        Divide the aperture mean by the box mean of the band-limited model source
        (:func:`holoprobe.characterize.band_limit_gain`): the back-projected field spills
        outside the W × H box, which made the IR a few per cent low, most at low
        frequency and for small apertures (default True).
    """

    method: Literal["auto", "area", "wiener"] = "auto"
    output_rate: float = 250e6
    duration: float | None = None
    delta_tolerance: float = 0.05
    band_limit_correction: bool = True


@dataclass(frozen=True)
class WarningConfig:
    """Thresholds of the warnings reported with the results.

    Attributes
    ----------
    edge_energy_fraction : float
        Warn when the scan's border (outer ``edge_width`` points) holds more than this
        fraction of the energy (field not captured).
    edge_width : int
        Width of the border in grid points.
    max_tilt_deg : float
        Warn when the scan-plane tilt exceeds this (degrees).
    max_sensor_tilt_deg : float
        Warn when the virtual-sensor tilt θy' (twice the reflector's tilt) exceeds this
        (degrees).
    onset_margin : float
        Warn when the onset lies within this time (s) of either end of the record.
    theta_z_bound_fraction : float
        Warn when θz of more than this fraction of the bins with signal lies at the
        search bound of the orientation.
    lens_center_bound_fraction : float
        Warn when the fitted lens centre y_L lies farther than this fraction of H/2 from
        the aperture centre (at the bound of the focus fit).
    """

    edge_energy_fraction: float = 0.01
    edge_width: int = 3
    max_tilt_deg: float = 3.0
    max_sensor_tilt_deg: float = 6.0
    onset_margin: float = 0.2e-6
    theta_z_bound_fraction: float = 0.25
    lens_center_bound_fraction: float = 0.99


@dataclass(frozen=True)
class ElementsConfig:
    """Per-element map, array-aware aperture and sound speed from the data.

    Attributes
    ----------
    enabled : bool
        Fit the element map when the scan describes an array (element count > 1).
    min_resolution : float
        Use only frequency bins whose wavenumber resolves neighbouring elements:
        ``k·p ≥ min_resolution·π`` (1: the band limit just reaches the element lattice).
    dead_threshold : float
        An element whose relative amplitude is below this is dead.
    weak_threshold : float
        An element whose relative amplitude is below this (and not dead) is weak; weak
        and dead elements take no part in the reference (live mean = 1).
    ridge : float
        Tikhonov weight of the per-bin element solve, relative to the mean diagonal.
    search_pitches : float
        Half-width, in pitches, of the coarse search of the array centre around the
        centroid of the field.
    offset_search : float
        Half-range, in wavelengths at the median frequency of the map's bins, of the
        search of the focus offset δ (the plane of sharpest focus relative to z = 0,
        either side: z = 0 is set by the onset of the mean velocity, not by the face).
    fit_pitch : bool
        Refine the pitch (the file's value is the start); by default the file's pitch
        is the prior and is kept.
    fit_sound_speed : bool
        Estimate the water's sound speed from the steep waves of the back-projection
        (reported as ``medium.sound_speed_from_data``, ``null`` when off; the
        characterization keeps the file's value unless ``--sound-speed from-data``).
        The reported element map is the one fitted at that c0 (a file's c0 6 m/s wrong
        left full-size amplitudes 3.1 % off instead of 1.7 %). Costs about
        9 × ``sound_speed_bins`` element solves and one map (a few s on a full-size
        96-element scan).
    sound_speed_bins : int
        Most frequency bins (alias-free ones, spread over the band) of that estimate.
        12: on the 30 reduced twins of ``benchmarks/uncertainty_coverage.py`` 6 bins
        left 87 % within 2σ (32-element twins +7 to +9 m/s at 2.3–2.5σ), 12 bins 100 %
        (mean error/σ +0.05); full-size scan 1479.8 ± 2.1 (6) / 1480.0 ± 2.0 (12) m/s
        for 1481.
    sound_speed_floor : float
        Model-error floor (m/s) added to the uncertainty of that estimate: noise-free
        line twins (exact 2-D Green's function, scan step 0.1–0.15 mm) left errors up to
        3.2 m/s with curvature uncertainties of 0.3–0.8 m/s; 96- and 24-element scan
        twins −1.0 and −1.7 m/s (``benchmarks/elements.py``, ``benchmarks/RESULTS.md``).
    width_warning_pitches : float
        Warn when the profile-fitted width and the nominal array width differ by more
        than this many pitches.
    edge_silent_threshold : float
        A dead edge element whose fitted relative amplitude is below this radiates
        nothing the map can tell from the fit's leakage (truly dead elements of the
        twins come out at 0.5–2.5 %): the array shifted by one pitch with the other edge
        element dead radiates the same field, so the map is ``ambiguous`` whatever the
        residuals of the two hypotheses say (they differed by up to 15 % on 24-element
        twins, the leakage's a²/N; a 5 % test alone missed it and one twin's map came
        out shifted: amplitudes 105 % off).
    map_optimizer : {"least-squares", "nelder-mead"}
        Flat 1-D arrays: the non-linear fit of the map's centre and focus offset (and
        pitch) from the grid searches' start (:func:`~holoprobe.characterize.fit_element_map`):
        Levenberg–Marquardt on the misfit vector (~15 evaluations on the full-size
        96-element twin) or Nelder–Mead on the residual (~110); the two land within
        0.05 µm of each other there (amplitudes 1e-4 apart). The second pose pass
        starts from the first pass's map moved by the pose update, without the grid
        searches. Convex arrays: ``convex.map_optimizer``.
    receive_dead_threshold : float
        A receive channel whose echo energy is below this fraction of the median
        channel's is dead (left out of the receive line fit, averages and noise).
    matrix_max_angle_deg : float
        2-D matrix arrays: largest propagation angle (deg) of the angular spectrum the
        element map uses; the scan's own capture angle (every aperture point's waves
        inside the footprint) lowers it.
    matrix_capture_inset : float
        2-D matrix arrays: the capture angle is the one at which the waves of every
        aperture point this fraction of the half-aperture in from its edges stay inside
        the scan footprint (0: every point, the rule before session 11). More of the
        propagating disc separates neighbouring elements better: on the 32 × 32 twin
        of seed 1 (40 dB, scan 18 mm at 2.5 mm) 0 gives 55.5° and amplitudes 0.91 % rms
        / 3.59 % worst, 0.3 gives 63.5° and 0.60 / 2.1 %; beyond ~65° the scan window's
        bias grows faster than the noise falls (noise-free worst element 0.26 % at
        55.5°, 0.46 % at 65°, 1.16 % at 72°; benchmarks/RESULTS.md).
    matrix_iterations : int
        2-D matrix arrays: alternating Gauss–Newton steps of the lattice centre,
        rotation and focus offset.
    matrix_bins : int
        2-D matrix arrays: most frequency bins (spread over those that resolve the
        elements) in the element map (each costs one N × N solve). 64 takes all of them
        on the 3 MHz twins (24 on a 512-sample record at 40 MHz): on the 32 × 32 twin
        of seed 1 (40 dB) the amplitudes are 0.91 % rms / 3.59 % worst against 1.16 % /
        4.81 % with 12, the delays 0.35 against 0.47 ns rms, for +1.2 s of CPU.
    matrix_fit_pitch : bool
        2-D matrix arrays: fit the x and y pitch from the data (the lattice phases across
        the array; the aperture ``(n − 1) p + w`` in x and y follows); else the file's.
    matrix_fit_element_size : bool
        2-D matrix arrays: fit the element width and height from the data too (the
        curvature of the element spectrum across the capture disc). Off by default: the
        scan's edge biases it by up to ±10 µm on the twins (the element map and the
        transmit IR's active fraction follow it; benchmarks/RESULTS.md).
    """

    enabled: bool = True
    min_resolution: float = 1.1
    dead_threshold: float = 0.3
    weak_threshold: float = 0.7
    ridge: float = 1e-4
    search_pitches: float = 4.0
    offset_search: float = 3.0
    fit_pitch: bool = False
    fit_sound_speed: bool = True
    sound_speed_bins: int = 12
    sound_speed_floor: float = 2.0
    width_warning_pitches: float = 3.0
    map_optimizer: str = "least-squares"
    receive_dead_threshold: float = 0.1
    edge_silent_threshold: float = 0.1
    matrix_max_angle_deg: float = 75.0
    matrix_capture_inset: float = 0.3
    matrix_iterations: int = 4
    matrix_bins: int = 64
    matrix_fit_pitch: bool = True
    matrix_fit_element_size: bool = False


@dataclass(frozen=True)
class ConvexConfig:
    """Convex (curvilinear) arrays: the geometry iterations of
    :func:`~holoprobe.characterize.characterize_convex_transmit` (docs/convex.md).

    Attributes
    ----------
    geometry_bins : int
        Frequency bins of the geometry iterations (the strongest, spread over those
        within ``geometry_threshold_db`` of the peak). 6 (was 12): the 32-element twin
        in 19.6 s CPU instead of 25.6 s, R −0.043 → −0.074 % (σ 0.66 %), H −0.3 →
        −1.6 µm (σ 2.4), F −0.04 → −0.06 %, θ within 0.0012°.
    geometry_threshold_db : float
        Level (dB below the strongest bin, negative) of the bins eligible for them.
    iterations : int
        Most geometry iterations (centre of curvature, radius, apex along the arc).
    tolerance : float
        Stop when every update (R, apex moves, R·angles, the tilts × H/2) is below this,
        in m. The updates shrink ≥ 4× per iteration (32-element twin: 2.2, 0.45,
        0.16 µm in iterations 4–6; 128-element C5-2 twin, R: −926, +14.5, +3.9,
        +0.04 µm), so 5 µm (3 µm before session 11: one more pass on the C5-2 twin for
        a 3.9 µm step of R) leaves ≲ 1.3 µm, well below the σ of W, H and R.
    projection : {"cylindrical", "type3"}
        How the scan is projected onto the cylinder: ``"cylindrical"`` (default) by the
        cylinder's symmetry (:func:`~holoprobe.propagation.project_cylinder`: a wave
        lattice along the axis, per column a circular convolution along the arc by 1-D
        NUFFTs; ~5× cheaper per bin on a C5-2 than the 3-D transform, the same numbers to
        ~1e-3 of the peak), ``"type3"``: the 3-D type-3 NUFFT of
        ``ProjectionPlan.project``, in patches of ``patch_angle_deg``.
    patch_angle_deg : float
        ``projection = "type3"`` only: the back-projection onto the cylinder runs patch
        by patch, each patch at most this wide (degrees of arc) and projected in its own
        frame (its normal along z):
        the type-3 NUFFT's fine grid spans the patch's bounding box, so thin patches
        cost far less than the whole arc's box (4× on a C5-2's ±37°), but each patch
        spreads all the scan's plane waves again. 0 (default): the count a cost model
        of the NUFFTs finds cheapest (one for a short arc).
    band_step : int
        The whole-band back-projection projects every D-th bin of the band and
        interpolates the others in frequency: the face signal of a transmit (every
        element fires at once) lasts a few µs, so the T/D-periodic time signal of the
        projected bins, cut to the T/D gate that holds it, has every bin's value (the
        noise outside the gate is dropped). 0 (default): the largest D ≤ 4 that leaves a
        gate of ≥ 4 µs and ≥ 8 projected bins; 1: every bin projected.
    gate_leakage : float
        When the face signal's power at the gate's edge, noise included, exceeds this
        fraction of its peak power (the signal would be cut), every bin is projected
        (with a warning). The 32-element twin at 40 dB: 5e-4 (noise).
    fit_tilts : bool
        Refine θz of the scan pose in the geometry iterations from the face itself:
        the tilt of the element lines on the unrolled face
        (:func:`~holoprobe.characterize.element_line_tilt`); False keeps the
        angular-spectrum estimate of the flat pipeline.
    lattice_start : bool
        Start each geometry pass's element-map pitch fit at the period of the element
        pattern on the face (:func:`~holoprobe.characterize.element_lattice`) instead of
        the nominal pitch: the fit's residual has local minima one end-element hop apart.
    map_optimizer : str
        The non-linear fit (centre, focus offset, pitch) of the element maps:
        ``"least-squares"`` (Levenberg–Marquardt on the misfit vector; each geometry
        pass starts from the last map) or ``"nelder-mead"`` (the flat pipeline's).
    element_views : bool
        The final element map models what each element of the arc sees of the scan
        (:func:`~holoprobe.characterize.arc_element_views`: its own angles to the
        scan's edges and its distance) instead of one flat footprint for all: the end
        elements of a C5-2 see the scan's outer edge 13° off their normal, not the flat
        model's 24°), cut where the record no longer holds the element's whole pulse
        (c0 × (record end − onset − pulse length) from it): 128-element twin
        amplitudes max 13.5 → 2.7 %, rms 2.0 → 0.7 %; +7 s CPU. The geometry passes
        keep the flat footprint.
    theta_x_from_lens : bool
        θx from the lens centre: a θx error ε leaves a delay slope ε cos φ/c0 along y
        on the face, which moves the fitted lens centre y_L by ε⟨cos φ⟩/κ; for a lens
        centred on the elevation aperture (centre y_a) ε = κ (y_L − y_a)/⟨cos φ⟩
        (docs/convex.md). The phase
        alone cannot tell a tilt from an offset of the lens axis: this assumes none,
        within ``lens_axis_tolerance``. False (or no significant lens): θx from the
        angular spectrum (σ ~0.015° on the 32-element twin).
    lens_axis_tolerance : float
        How far (m) the lens axis may sit off the elevation aperture's centre: κ × it
        joins the uncertainty of θx from the lens (5 µm: 0.0095° at F = 30 mm).
    eps, guard_angle_deg : float or None
        NUFFT tolerance and padding guard angle (degrees) of the projections onto the
        cylinder (None: those of ``[backprojection]``, 1e-4 and 80°); the tolerance
        also of the arc window model's NUFFTs (``window_model = "arc"``). The defaults
        (1e-4, 60°) change the projected face by ~1e-3 of its peak and make each
        frequency bin 6× cheaper on a C5-2 (benchmarks/RESULTS.md); on the small test
        twin every reported number agreed to its 3rd–4th digit.
    window_model : {"arc", "flat"}
        The model source of the scan-window correction (``aperture.window_correction``)
        of W, H and F. ``"arc"``: the fitted strips on the fitted cylinder, radiated
        as a curved face, back-projected by the pipeline's own projection
        (:func:`~holoprobe.characterize.arc_window_bias`); W, H and F are then the
        fits on the model's ``aperture.window_bins`` bins minus the model's bias on the
        same bins, W less one kerf (the model's W is N·pitch; the reported one the
        active aperture). 128-element C5-2 twin, 110 mm scan: W +111 → +15.5 µm, H +27.3
        → +14.4 µm, F +0.119 → +0.020 %; 32-element H 6 / F 30 twin: W +33 → +21 µm,
        H −12.7 → −1.9 µm, F −0.34 → +0.006 %. ``"flat"``: the old model laid flat on
        the apex's
        tangent plane (H and F corrected, W's bias added to its σ).
    window_bins : int or None
        Bins of the arc window model and of the W, H, F refit it corrects (None:
        ``aperture.window_bins``, 12). 10 (session 12): the step 5.3 → 3.9 s CPU on
        the 128-element C5-2 twin, W +14.3 → +18.8 µm (σ 12), H +13.1 → +11.3 µm,
        F +0.013 → +0.026 % (noise-free twin: W +6.8 → +17.3, H +20.0 → +16.4 µm).
        The refit's W hops by ~45 µm between bin sets (9 or 8 bins); the model hops
        with it, so the corrected W stays within ±20 µm.
    """

    geometry_bins: int = 6
    geometry_threshold_db: float = -10.0
    iterations: int = 6
    tolerance: float = 5e-6
    projection: Literal["cylindrical", "type3"] = "cylindrical"
    patch_angle_deg: float = 0.0
    band_step: int = 0
    gate_leakage: float = 3e-3
    fit_tilts: bool = True
    lattice_start: bool = True
    map_optimizer: str = "least-squares"
    element_views: bool = True
    theta_x_from_lens: bool = True
    lens_axis_tolerance: float = 5e-6
    eps: float | None = 1e-4
    guard_angle_deg: float | None = 60.0
    window_model: str = "arc"
    window_bins: int | None = 10


def _check_convex(cv: ConvexConfig) -> None:
    """The [convex] range checks (one line naming the field)."""
    if cv.geometry_bins < 1 or cv.iterations < 1:
        raise InputError("expected geometry_bins and iterations ≥ 1",
                         field="convex.iterations")
    if not cv.geometry_threshold_db < 0 or not cv.tolerance >= 0:
        raise InputError("expected a negative level in dB and a tolerance ≥ 0 m",
                         field="convex.geometry_threshold_db")
    if cv.eps is not None and not 1e-15 < cv.eps < 0.1:
        raise InputError(f"expected a tolerance in (1e-15, 0.1), got {cv.eps!r}",
                         field="convex.eps")
    if cv.guard_angle_deg is not None and not 0 <= cv.guard_angle_deg < 90:
        raise InputError(f"expected an angle in [0, 90) degrees, got "
                         f"{cv.guard_angle_deg!r}", field="convex.guard_angle_deg")
    wb = cv.window_bins
    if wb is not None and not (isinstance(wb, int) and not isinstance(wb, bool) and wb >= 1):
        raise InputError(f"expected a whole number of bins ≥ 1 or none, got {wb!r}",
                         field="convex.window_bins")
    if not cv.lens_axis_tolerance >= 0:
        raise InputError(f"expected a length ≥ 0 m, got {cv.lens_axis_tolerance!r}",
                         field="convex.lens_axis_tolerance")
    if cv.band_step < 0 or not 0 < cv.gate_leakage < 1:
        raise InputError(f"expected band_step ≥ 0 and gate_leakage in (0, 1), got "
                         f"{cv.band_step!r}, {cv.gate_leakage!r}",
                         field="convex.band_step")
    if not 0 <= cv.patch_angle_deg < 360:
        raise InputError(f"expected an angle in [0, 360) degrees, got "
                         f"{cv.patch_angle_deg!r}", field="convex.patch_angle_deg")
    for name, allowed in (("map_optimizer", ("least-squares", "nelder-mead")),
                          ("window_model", ("arc", "flat"))):
        if getattr(cv, name) not in allowed:
            raise InputError(f"expected one of {allowed}, got {getattr(cv, name)!r}",
                             field=f"convex.{name}")


_SECTIONS = {
    "hologram": HologramConfig,
    "convex": ConvexConfig,
    "band": BandConfig,
    "orientation": OrientationConfig,
    "backprojection": BackProjectionConfig,
    "aperture": ApertureConfig,
    "lens": LensConfig,
    "onset": OnsetConfig,
    "iterations": IterationConfig,
    "transmit": TransmitIRConfig,
    "warnings": WarningConfig,
    "hydrophone": HydrophoneDeconvolutionConfig,
    "elements": ElementsConfig,
    "plausibility": PlausibilityConfig,
    "receive": ReceiveConfig,
}


@dataclass(frozen=True)
class CharacterizationConfig:
    """The whole configuration of ``holoprobe characterize``, one section per step.

    Attributes
    ----------
    band, orientation, backprojection, aperture, lens, onset, iterations, transmit, warnings,
    elements
        See the section classes.
    hydrophone : HydrophoneDeconvolutionConfig
        How a voltage scan is deconvolved with a complex (phase-carrying) calibration
        (:func:`holoprobe.signal.deconvolve_records`).
    plausibility : PlausibilityConfig
        Plausible ranges of the physical inputs, checked where the CLI reads its files
        (:mod:`holoprobe.plausibility`); widen one deliberately with
        ``--set plausibility.sound_speed=[1000, 2000]``.
    convex : ConvexConfig
        Geometry iterations of convex arrays.
    receive : ReceiveConfig
        Settings of the receive side (:class:`holoprobe.characterize.ReceiveConfig`);
        a plain dict when that module is absent. The transmit pipeline does not read it.
    """

    band: BandConfig = field(default_factory=BandConfig)
    orientation: OrientationConfig = field(default_factory=OrientationConfig)
    backprojection: BackProjectionConfig = field(default_factory=BackProjectionConfig)
    aperture: ApertureConfig = field(default_factory=ApertureConfig)
    lens: LensConfig = field(default_factory=LensConfig)
    onset: OnsetConfig = field(default_factory=OnsetConfig)
    iterations: IterationConfig = field(default_factory=IterationConfig)
    transmit: TransmitIRConfig = field(default_factory=TransmitIRConfig)
    warnings: WarningConfig = field(default_factory=WarningConfig)
    hologram: HologramConfig = field(default_factory=HologramConfig)
    hydrophone: HydrophoneDeconvolutionConfig = field(
        default_factory=HydrophoneDeconvolutionConfig)
    elements: ElementsConfig = field(default_factory=ElementsConfig)
    plausibility: PlausibilityConfig = field(default_factory=PlausibilityConfig)
    receive: ReceiveConfig = field(default_factory=ReceiveConfig)
    convex: ConvexConfig = field(default_factory=ConvexConfig)

    def __post_init__(self) -> None:
        it = self.iterations
        if it.count < 1:
            raise InputError(f"expected at least 1 iteration, got {it.count}",
                             field="iterations.count")
        if not it.tolerance >= 0:
            raise InputError("expected a non-negative tolerance in m",
                             field="iterations.tolerance")
        if it.initial_z0 is not None and not it.initial_z0 > 0:
            raise InputError("expected a positive distance in m", field="iterations.initial_z0")
        if not self.transmit.output_rate > 0:
            raise InputError("expected a positive rate in Hz", field="transmit.output_rate")
        if self.onset.upsample < 1:
            raise InputError("expected an integer ≥ 1", field="onset.upsample")
        if self.onset.bootstrap < 0:
            raise InputError("expected an integer ≥ 0", field="onset.bootstrap")
        _check_convex(self.convex)
        wb = self.aperture.window_bins
        if not (isinstance(wb, int) and not isinstance(wb, bool) and wb >= 1):
            raise InputError(f"expected a whole number of bins ≥ 1, got {wb!r}",
                             field="aperture.window_bins")
        rc = self.receive
        if rc.eps is not None and not 1e-15 < rc.eps < 0.1:
            raise InputError(f"expected a tolerance in (1e-15, 0.1), got {rc.eps!r}",
                             field="receive.eps")
        if not rc.pose_tolerance >= 0:
            raise InputError(f"expected a number of standard uncertainties ≥ 0, got "
                             f"{rc.pose_tolerance!r}", field="receive.pose_tolerance")
        if not (math.isfinite(rc.transfer_function_floor) and rc.transfer_function_floor >= 0):
            raise InputError(f"expected a relative uncertainty ≥ 0, got "
                             f"{rc.transfer_function_floor!r}",
                             field="receive.transfer_function_floor")
        if not (math.isfinite(rc.ir_out_of_band_weight) and rc.ir_out_of_band_weight >= 0):
            raise InputError(f"expected a relative weight ≥ 0, got "
                             f"{rc.ir_out_of_band_weight!r}",
                             field="receive.ir_out_of_band_weight")
        if not (math.isfinite(rc.ir_noise_tail) and rc.ir_noise_tail >= 0):
            raise InputError(f"expected a noise level ≥ 0 (σ units), got "
                             f"{rc.ir_noise_tail!r}", field="receive.ir_noise_tail")
        if not (math.isfinite(rc.plan_cache_mb) and rc.plan_cache_mb >= 0):
            raise InputError(f"expected a memory budget ≥ 0 MiB, got {rc.plan_cache_mb!r}",
                             field="receive.plan_cache_mb")
        if not (isinstance(rc.pose_noise_draws, int) and rc.pose_noise_draws >= 0):
            raise InputError(f"expected a whole number of draws ≥ 0, got "
                             f"{rc.pose_noise_draws!r}", field="receive.pose_noise_draws")
        if not (isinstance(rc.band_decimation, int) and rc.band_decimation >= 0):
            raise InputError(f"expected 0 (from the data) or a decimation ≥ 1, got "
                             f"{rc.band_decimation!r}", field="receive.band_decimation")
        if not 0 <= rc.taper_band < 1:
            raise InputError(f"expected a band of sin θ in [0, 1), got {rc.taper_band!r}",
                             field="receive.taper_band")
        if not 0 < rc.band_alias_tolerance < 1:
            raise InputError(f"expected a fraction in (0, 1), got "
                             f"{rc.band_alias_tolerance!r}", field="receive.band_alias_tolerance")
        _check_hologram(self.hologram)
        if self.elements.map_optimizer not in ("least-squares", "nelder-mead"):
            raise InputError(f"expected 'least-squares' or 'nelder-mead', got "
                             f"{self.elements.map_optimizer!r}",
                             field="elements.map_optimizer")
        if not 0 <= self.elements.edge_silent_threshold < 1:
            raise InputError(f"expected a relative amplitude in [0, 1), got "
                             f"{self.elements.edge_silent_threshold!r}",
                             field="elements.edge_silent_threshold")
        if not 0 <= self.elements.matrix_capture_inset <= 1:
            raise InputError(f"expected a fraction of the half-aperture in [0, 1], got "
                             f"{self.elements.matrix_capture_inset!r}",
                             field="elements.matrix_capture_inset")

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_dict(cls, data: dict[str, Any], *, file: str | None = None
                  ) -> CharacterizationConfig:
        """Build from nested dicts ``{section: {key: value}}`` (unknown keys → InputError)."""
        if not isinstance(data, dict):
            raise InputError("expected a table of sections", file=file)
        kwargs: dict[str, Any] = {}
        for section, values in data.items():
            if section not in _SECTIONS:
                raise InputError(f"unknown section; expected one of "
                                 f"{sorted(_SECTIONS)}", file=file, field=section)
            if not isinstance(values, dict):
                raise InputError("expected a table of key = value", file=file, field=section)
            kwargs[section] = _build_section(_SECTIONS[section], section, values, file)
        return cls(**kwargs)

    @classmethod
    def from_toml(cls, path: str | os.PathLike) -> CharacterizationConfig:
        """Read a TOML file (sections as tables); unknown sections or keys → InputError."""
        p = Path(path)
        try:
            data = tomllib.loads(p.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise InputError("no such configuration file", file=str(p)) from None
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise InputError(f"not a valid TOML file: {exc}", file=str(p)) from None
        return cls.from_dict(data, file=str(p))

    @classmethod
    def resolve(cls, config: CharacterizationConfig | str | os.PathLike | None = None,
                overrides: Sequence[str] = ()) -> CharacterizationConfig:
        """The configuration a run uses: ``config`` (an object, a TOML path, or None for
        the defaults) with the ``section.key=value`` ``overrides`` applied."""
        if isinstance(config, str | os.PathLike):
            config = cls.from_toml(config)
        cfg = config if config is not None else cls()
        return cfg.with_overrides(list(overrides)) if overrides else cfg

    def with_overrides(self, assignments: list[str] | tuple[str, ...]
                       ) -> CharacterizationConfig:
        """A copy with ``section.key=value`` assignments applied (values in TOML syntax;
        a bare word is a string), e.g. ``["iterations.count=3", "band.band=[1e6, 4e6]"]``."""
        data = self.to_dict()
        for text in assignments:
            if "=" not in text:
                raise InputError(f"expected section.key=value, got {text!r}", field="--set")
            name, raw = (s.strip() for s in text.split("=", 1))
            if name.count(".") != 1:
                raise InputError(f"expected section.key, got {name!r}", field="--set")
            section, key = name.split(".")
            try:
                value = tomllib.loads(f"v = {raw}")["v"]
            except tomllib.TOMLDecodeError:
                value = raw
            if section not in data:
                raise InputError(f"unknown section; expected one of {sorted(data)}",
                                 field=section)
            if key not in data[section]:
                raise InputError(f"unknown key; expected one of {sorted(data[section])}",
                                 field=name)
            data[section][key] = value
        return CharacterizationConfig.from_dict(data)

    # ------------------------------------------------------------------ dumping
    def to_dict(self) -> dict[str, Any]:
        """Nested dict of every value (``None`` for unset optional values)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if dataclasses.is_dataclass(value) and not isinstance(value, type):
                out[f.name] = {k: (list(v) if isinstance(v, tuple) else v)
                               for k, v in dataclasses.asdict(value).items()}
            else:
                out[f.name] = dict(value) if isinstance(value, dict) else value
        return out

    def to_toml(self) -> str:
        """The configuration as TOML text (unset optional values are commented out)."""
        lines = ["# holoprobe characterization configuration", ""]
        for section, values in self.to_dict().items():
            lines.append(f"[{section}]")
            if isinstance(values, dict):
                for key, value in values.items():
                    if value is None:
                        lines.append(f"# {key} = (unset)")
                    else:
                        lines.append(f"{key} = {_toml_value(value)}")
            lines.append("")
        return "\n".join(lines)


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"cannot write {type(value).__name__} as TOML")


def _build_section(cls: type, section: str, values: dict[str, Any], file: str | None) -> Any:
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    kwargs = {}
    for key, value in values.items():
        if key not in names:
            raise InputError(f"unknown key; expected one of {sorted(names)}", file=file,
                             field=f"{section}.{key}")
        kwargs[key] = _coerce(value, hints[key], f"{section}.{key}", file)
    return cls(**kwargs)


def _coerce(value: Any, hint: Any, name: str, file: str | None) -> Any:
    """Check/convert a TOML value against a field's type hint."""
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        if value is None or (isinstance(value, str) and value.lower() in ("none", "null")):
            if type(None) in args:
                return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _coerce(value, arg, name, file)
            except InputError as exc:
                errors.append(exc.detail)
        raise InputError("; ".join(errors) or "unexpected value", file=file, field=name)
    if origin is Literal:
        if value not in args:
            raise InputError(f"expected one of {list(args)}, got {value!r}", file=file,
                             field=name)
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple) or len(value) != len(args):
            raise InputError(f"expected a list of {len(args)} values, got {value!r}",
                             file=file, field=name)
        return tuple(_coerce(v, a, name, file) for v, a in zip(value, args, strict=True))
    if hint is bool:
        if not isinstance(value, bool):
            raise InputError(f"expected true or false, got {value!r}", file=file, field=name)
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError(f"expected an integer, got {value!r}", file=file, field=name)
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise InputError(f"expected a number, got {value!r}", file=file, field=name)
        value = float(value)
        if math.isnan(value):
            raise InputError("expected a number, got NaN", file=file, field=name)
        return value
    if hint is str:
        if not isinstance(value, str):
            raise InputError(f"expected a string, got {value!r}", file=file, field=name)
        return value
    return value


def _check_hologram(hc: HologramConfig) -> None:
    """Ranges of the ``[hologram]`` knobs that the dataclass alone does not bound."""
    if not hc.window_model_source_points > 0:
        raise InputError(f"expected points per wavelength > 0, got "
                         f"{hc.window_model_source_points!r}",
                         field="hologram.window_model_source_points")
    if not hc.window_model_uncertainty >= 0:
        raise InputError(f"expected a fraction ≥ 0, got {hc.window_model_uncertainty!r}",
                         field="hologram.window_model_uncertainty")
    if not hc.velocity_gate_level > 1:
        raise InputError(f"expected a multiple of the noise floor > 1, got "
                         f"{hc.velocity_gate_level!r}", field="hologram.velocity_gate_level")
    if hc.focus_estimator not in ("auto", "lobe", "aperture"):
        raise InputError(f"expected 'auto', 'lobe' or 'aperture', got "
                         f"{hc.focus_estimator!r}", field="hologram.focus_estimator")
    if not hc.aperture_focus_above >= 0:
        raise InputError(f"expected a σ >= 0 m, got {hc.aperture_focus_above!r}",
                         field="hologram.aperture_focus_above")
    if not hc.aperture_margin_wavelengths >= 0:
        raise InputError(f"expected a margin >= 0 wavelengths, got "
                         f"{hc.aperture_margin_wavelengths!r}",
                         field="hologram.aperture_margin_wavelengths")
    if hc.transient_focus not in ("peak", "band"):
        raise InputError(f"expected 'peak' or 'band', got {hc.transient_focus!r}",
                         field="hologram.transient_focus")
    if hc.flattened_order not in ("auto", "x", "y"):
        raise InputError(f"expected 'auto', 'x' or 'y', got {hc.flattened_order!r}",
                         field="hologram.flattened_order")
