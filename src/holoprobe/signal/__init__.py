"""Signal processing: Fourier convention, calibration, windows, onsets, deconvolution."""

from holoprobe.signal._calibration import (
    default_calibration,
    load_calibration,
    pressure_from_voltage,
    pressure_spectrum_from_voltage,
    sensitivity_response,
    voltage_from_pressure,
)
from holoprobe.signal._cw import cw_amplitude, extract_cw
from holoprobe.signal._deconvolution import (
    TransmitImpulseResponse,
    drive_is_delta_like,
    noise_floor,
    transmit_impulse_response,
    wiener_deconvolve,
)
from holoprobe.signal._fourier import (
    analytic_signal,
    bin_energy,
    blas_threads,
    continuous_spectrum,
    envelope,
    frequency_axis,
    next_fast_length,
    to_frequency,
    to_time,
    workers,
)
from holoprobe.signal._hydrophone import (
    DeconvolvedPressure,
    HydrophoneDeconvolutionConfig,
    auto_cutoff,
    deconvolve_hydrophone,
    deconvolve_records,
    estimate_offset_and_noise,
    lowpass_response,
    regularised_inverse,
    voltage_dft,
    with_phase,
)
from holoprobe.signal._iir import butter_highpass_sos, sosfiltfilt
from holoprobe.signal._onset import detect_onset, noise_sigma
from holoprobe.signal._peaks import PEAK_MAX_BAND, band_limited_peaks, interpolation_weights
from holoprobe.signal._phase import (
    PhaseResponse,
    compensate_phase,
    filter_phase_from_group_delay,
    minimum_phase,
)
from holoprobe.signal._resample import fractional_delay, resample
from holoprobe.signal._robust import MAD_TO_SIGMA, mad_sigma, theil_sen
from holoprobe.signal._spectrum import SpectrumSummary, spectrum_summary
from holoprobe.signal._threads import Threads

__all__ = ["Threads", "bin_energy", "blas_threads", "frequency_axis", "next_fast_length",
           "to_frequency", "to_time", "workers"]
__all__ += ["PEAK_MAX_BAND", "band_limited_peaks", "interpolation_weights"]
__all__ += ["butter_highpass_sos", "sosfiltfilt"]
__all__ += ["MAD_TO_SIGMA", "analytic_signal", "continuous_spectrum", "envelope", "mad_sigma",
            "theil_sen"]
__all__ += [
    "DeconvolvedPressure",
    "HydrophoneDeconvolutionConfig",
    "auto_cutoff",
    "deconvolve_hydrophone",
    "deconvolve_records",
    "estimate_offset_and_noise",
    "lowpass_response",
    "regularised_inverse",
    "voltage_dft",
    "with_phase",
]
__all__ += [
    "PhaseResponse",
    "SpectrumSummary",
    "TransmitImpulseResponse",
    "compensate_phase",
    "cw_amplitude",
    "default_calibration",
    "detect_onset",
    "drive_is_delta_like",
    "extract_cw",
    "filter_phase_from_group_delay",
    "fractional_delay",
    "load_calibration",
    "minimum_phase",
    "noise_floor",
    "noise_sigma",
    "pressure_from_voltage",
    "pressure_spectrum_from_voltage",
    "resample",
    "sensitivity_response",
    "spectrum_summary",
    "transmit_impulse_response",
    "voltage_from_pressure",
    "wiener_deconvolve",
]
