"""Configuration of the receive half of the pipeline (paper section III B).

Every knob of :func:`~holoprobe.characterize.estimate_virtual_receiver`,
:func:`~holoprobe.characterize.estimate_reflection_coefficient`,
:func:`~holoprobe.characterize.virtual_sensor_surface` and
:func:`~holoprobe.characterize.receive_impulse_response` in one frozen dataclass, with
the same defaults; the pipeline's configuration embeds it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

__all__ = ["ReceiveConfig"]


@dataclass(frozen=True)
class ReceiveConfig:
    """Settings of the receive characterization (SI units).

    Attributes
    ----------
    window : (float, float) or None
        Interval (s, transmit clock) holding the main echo and a pre-echo noise segment
        (None: the record after the transmit feed-through, see
        :func:`~holoprobe.characterize.echo_search_window`).
    arrival_method : {"envelope", "xcorr"}
        Per-element echo arrival estimator.
    noise_guard : float
        Gap (s) between the pre-echo noise segment and the echo.
    min_quality, min_relative_quality : float
        Peak-SNR floors (absolute, relative to the best element) of a usable element.
    outlier_threshold : float
        Arrival-line outlier rejection in robust σ.
    loss : str
        Robust loss of the line fit (``scipy.optimize.least_squares``).
    highpass_cutoff : float
        Zero-phase high-pass cut-off (Hz) before the onset detection (0: none).
    highpass_order : int
        Butterworth order of that high-pass.
    onset_threshold : float
        Onset detection level in noise σ.
    onset_upsample : int
        Upsampling factor of the onset detection.
    reflection_coefficient : float or None
        Rp given by the user (None: from the echo train).
    reflection_fallback : float or None
        Rp used, with a warning, when the echo train does not support an estimate
        (None: raise).
    peak_fraction : float
        Envelope fall-off that separates echoes of the train.
    peak_count : int
        Echoes of the train to find.
    attenuating : bool
        Rp from the attenuation-cancelling ratio of ratios (needs 3 echoes).
    points_per_wavelength : float
        Virtual-sensor sampling: spacing λ_min / this.
    output_rate : float
        Sampling rate of the receive IR (Hz).
    truncate_before : float or None
        Longest receive IR (s; ``ir_noise_tail`` may end it earlier); None: the
        echo-train period.
    ir_onset_margin : float
        Time (s) kept before the receive IR's onset (the rise of its first lobe, which
        sits at this time in the IR; the geometry absorbs the rest of the delay).
    ir_time_limited : bool
        The receive IR is the time-limited response (its pre-onset margin to the
        truncation) whose spectrum fits the deconvolution's in-band bins by weighted
        least squares (:func:`receive_impulse_response`), not the band-limited response
        cut to that length, whose ringing before the onset, cut away, put a same-sign
        ripple of ±1–3 % into |H_R| at 25 dB (benchmarks/RESULTS.md "Session 9").
    ir_out_of_band_weight : float
        Weight (relative to the best in-band bin, target zero) of the bins outside the
        band in that fit: keeps the response's out-of-band content small.
    ir_noise_tail : float
        The time-limited receive IR ends where it has fallen into its noise (the first
        0.25 µs after its peak whose rms is below this × its noise σ) instead of at the
        truncation (:func:`receive_impulse_response` ``noise_tail``); 0: at the
        truncation.
    pressure_floor_db : float
        Fallback pressure noise floor (dB below peak) without a pre-arrival segment.
    segment_length : int
        Welch segment length for the noise spectra.
    refine_pose : bool
        Refine θy' (x0', d) by comparing every element's RF with its predicted pressure
        (:func:`~holoprobe.characterize.refine_receiver_tilt`): no diffraction bias.
    pose_iterations : int
        Most predictions (forward projections) of the refinement, each at the last pose.
    pose_tolerance : float
        The refinement stops before ``pose_iterations`` predictions once a step of θy'
        is at most this many of its standard uncertainties (the fit's): a prediction
        at the new pose would move θy' by a fraction of that step only (the step's gain
        error). 0: always ``pose_iterations`` predictions. Flat linear arrays only.
    eps : float or None
        Relative tolerance of the non-uniform FFTs of the forward projections onto the
        virtual sensor (None: ``backprojection.eps``; for a 2-D matrix's mirrored
        faces, type-3 transforms, 1e-4: ``_matrix_receive.PREDICTION_EPS``). Since the
        element averages are taken wave by wave (1-D transforms), 1e-4 saves no CPU on a
        full-size P4-1
        scan and changes the predicted pressure by up to 8.5e-5 of its peak
        (benchmarks/RESULTS.md, issue 14); it still shortens the 3-D transforms of a
        curved array's mirrored faces.
    element_sensitivity : bool
        Also estimate per-element receive amplitude and delay.
    steering_uncertainty : bool
        Add to each element's receive-gain uncertainty the change one standard
        uncertainty of the steering hidden in the transmit map's delays gives
        (:func:`~holoprobe.characterize.steering_prediction`; only with a 1-D element
        map).
    distance_uncertainty : bool
        Add to each element's receive-gain uncertainty its change when the sensor is
        moved back by the receive IR's onset (the sensor sits where the IR starts at
        t = 0; the echo hardly tells the IR's delay from distance): one more forward
        projection (:func:`~holoprobe.characterize.sensitivity_step`). Flat linear
        arrays only (convex and matrix receive: not applied).
    sensitivity_band_db : float
        Band level for the per-element sensitivity fit.
    peak_min_snr : float
        An echo-train peak counts only above this many times the median envelope before
        it (:func:`echo_train_peaks`).
    smooth_bins : int
        Least width (bins) of the moving average of the spectral powers in the per-bin
        SNR that sets the receive IR's band (:func:`receive_impulse_response`).
    transfer_function_floor : float
        Relative standard uncertainty added in quadrature to every frequency of the
        receive transfer function |H_R(f)| in summary.json
        (:func:`~holoprobe.characterize.transfer_function_estimate`): the errors the
        deconvolution's noise does not hold (the projected pressure's, the truncation's
        leakage). On 30 reduced P4-1 twins with the time-limited IR the mean error per
        0.22 MHz band is within ±0.6 % except +1.0 % at 3.1–3.5 MHz; noise alone covers
        93 % within 2σ, with 0.005 95 % (benchmarks/RESULTS.md "Session 9"). 0 leaves the
        noise alone.
    record_guard : float
        Extra zero padding (s) of the scan record before the forward projection, on top
        of the geometric spread and the largest lens delay.
    guard_angle_deg : float
        Guard angle of the forward projection's padding rule (degrees; the transmit's
        back-projection uses ``backprojection.guard_angle_deg``, 80°: the sensor is ~20
        scan widths away, where 80° would pad the scan to ~1 m for components that carry
        nothing at the sensor).
    image_taper : bool
        Fade out the scan's plane waves steeper than any line from the scan to the
        sensor, down to zero where the padded scan's periodic images could reach it
        (:func:`~holoprobe.propagation.image_taper_range`): without it, the edge waves
        of a wide array close to the scan reach a sensor ~90 mm away from the images
        through the 30° guard (a pattern of 2–3 elements' period in the predicted
        element pressure, 0.7 % rms at full size; a 60° guard removed it at 4× the CPU).
        Used by the flat linear-array and the matrix receive (on the 32 × 32 matrix at
        15 mm: gains 1.36 → 0.85 % rms, predictions at about half the CPU); the
        convex faces' predictions run without it.
    plan_cache_mb : float
        Most MiB of the scan's padded spectra kept between the predictions of the pose
        refinement (the lowest frequencies first; the others are transformed again at
        each prediction). The full set is ≈ 0.6 GB for a full-size P4-1 scan; 256 MiB
        keeps 175 of its 232 bins and saves ≈ 0.9 s CPU per prediction, in the memory
        the sensor grid's field took before the element averages were taken wave by
        wave (benchmarks/RESULTS.md, issue 14). 0 keeps nothing.
    pose_noise_draws : int
        2-D matrix arrays: Monte-Carlo draws of the scan's noise (its level from the
        evanescent part of each bin's spectrum) forward-projected onto the mirrored
        grid, whose change of the fitted plate pose joins σ(d), σ(θx'), σ(θy')
        (:func:`~holoprobe.characterize.prediction_noise_pose`: the projected noise is
        correlated over neighbouring elements, which the arrivals' residual scatter
        misses); one projection each; 0: off.
    band_decimation : int
        Flat linear and convex arrays: predict the element pressures on every D-th
        frequency bin of the padded scan record only, i.e. on the bins of a record D
        times shorter: the prediction folded with that period, unfolded about its pulse
        (the element pressures last a few µs of the record, which must hold the scan's
        spread of arrivals). Exact when the predicted pulse fits the shorter record; 1/D of the
        plane waves per prediction. 0 (default): the largest D of 8, 4, 2, 1 whose first
        prediction passes the compactness check (``band_alias_tolerance``, as the
        hologram's ``band_decimation``); D ≥ 1: that D, unchecked (1: every bin).
    taper_band : float
        Flat linear arrays with ``image_taper``: the scan is padded only as far as leaves
        the image taper this band in sin θ beyond the steepest scan-to-sensor direction
        (``taper_guard`` of the receive pipeline, for each predicted pose: a sensor
        moved closer needs more padding), never beyond
        ``guard_angle_deg``'s padding: 0.18 (default) pads the full-size P4-1 for 20.4°
        instead of 30° (2.3× fewer plane waves; the predicted pressure moves by 1.8e-4 of
        its peak). 0: the ``guard_angle_deg`` padding. No effect on convex and matrix
        arrays: their predictions onto the mirrored faces
        (:func:`~holoprobe.characterize.faces_sensor_predictor`) pad with
        ``guard_angle_deg`` (convex: without the image taper; with it, the 12-element
        convex receive twin's predicted element pressure moved by 1.1 % of its peak;
        not measured on the benchmarks).
    band_alias_tolerance : float
        Compactness check of ``band_decimation`` = 0: the predicted pressure's energy
        (all elements, noise floor removed) outside the best half of the shorter record
        must stay below this fraction (default 1e-5). The energy beyond the shorter
        record folds onto the pulse: its share ε changes the pressure by ~√ε of its peak
        (a 16-element twin's long edge waves, ε = 2.6e-4 at D = 4: 2.6 %; the full-size
        P4-1, ε = 4.6e-6: 0.23 %, gains ≤ 0.22 σ, θy' 0.15 σ).
    """

    window: tuple[float, float] | None = None
    arrival_method: str = "xcorr"
    noise_guard: float = 2e-6
    min_quality: float = 10.0
    min_relative_quality: float = 0.25
    outlier_threshold: float = 4.0
    loss: str = "soft_l1"
    highpass_cutoff: float = 0.1e6
    highpass_order: int = 3
    onset_threshold: float = 5.0
    onset_upsample: int = 10
    reflection_coefficient: float | None = None
    reflection_fallback: float | None = None
    peak_fraction: float = 0.2
    peak_count: int = 5
    attenuating: bool = False
    points_per_wavelength: float = 4.0
    output_rate: float = 250e6
    truncate_before: float | None = None
    ir_onset_margin: float = 0.25e-6
    ir_time_limited: bool = True
    ir_out_of_band_weight: float = 1e-3
    ir_noise_tail: float = 1.5
    pressure_floor_db: float = 60.0
    segment_length: int = 256
    refine_pose: bool = True
    pose_iterations: int = 3
    pose_tolerance: float = 0.1
    eps: float | None = None
    element_sensitivity: bool = False
    steering_uncertainty: bool = True
    distance_uncertainty: bool = True
    sensitivity_band_db: float = -12.0
    peak_min_snr: float = 4.0
    smooth_bins: int = 9
    transfer_function_floor: float = 0.005
    record_guard: float = 2e-6
    guard_angle_deg: float = 30.0
    image_taper: bool = True
    plan_cache_mb: float = 256.0
    pose_noise_draws: int = 8
    band_decimation: int = 0
    taper_band: float = 0.18
    band_alias_tolerance: float = 1e-5

    def virtual_receiver_options(self) -> dict[str, Any]:
        """Keyword arguments for :func:`estimate_virtual_receiver`."""
        return {"window": self.window, "arrival_method": self.arrival_method,
                "noise_guard": self.noise_guard, "min_quality": self.min_quality,
                "min_relative_quality": self.min_relative_quality,
                "outlier_threshold": self.outlier_threshold, "loss": self.loss,
                "highpass_cutoff": self.highpass_cutoff,
                "highpass_order": self.highpass_order,
                "onset_threshold": self.onset_threshold,
                "onset_upsample": self.onset_upsample}
