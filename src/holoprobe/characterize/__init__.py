"""Characterization: scan-plane orientation, aperture, lens, impulse responses.

Each algorithm lives in a private module and is re-exported here.
"""

from holoprobe.characterize._alignment import (
    FocusAlignment,
    align_focused,
    hologram_noise_level,
    orthonormal_frame,
)
from holoprobe.characterize._aperture import (
    ApertureFit,
    aperture_weights,
    band_limited_rectangle,
    fit_aperture,
    mean_surface_velocity,
    select_signal_bins,
)
from holoprobe.characterize._bandlimit import band_limit_gain
from holoprobe.characterize._config import (
    ApertureConfig,
    BackProjectionConfig,
    BandConfig,
    CharacterizationConfig,
    ElementsConfig,
    IterationConfig,
    LensConfig,
    OnsetConfig,
    OrientationConfig,
    TransmitIRConfig,
    WarningConfig,
)
from holoprobe.characterize._elements import (
    ElementMap,
    fit_element_map,
    resolve_edge_ambiguity,
)
from holoprobe.characterize._hologram_config import HologramConfig
from holoprobe.characterize._hologram_field import (
    PlaneWaveField,
    hologram_grid,
    hologram_power,
    plane_wave_field,
    propagation_guard_angle,
)
from holoprobe.characterize._hologram_pipeline import (
    HologramResult,
    characterize_hologram,
    hologram_summary,
)
from holoprobe.characterize._lens import (
    LensFit,
    fit_lens_focus,
    lens_delays,
    reverse_lens_delays,
)
from holoprobe.characterize._orientation import OrientationResult, estimate_orientation
from holoprobe.characterize._pipeline import (
    ElementEstimate,
    TransmitResult,
    characterize_transmit,
)
from holoprobe.characterize._receive import ReceiveConfig
from holoprobe.characterize._receive_ir import (
    DriveRatio,
    ElementSensitivity,
    ReceiveImpulseResponse,
    drive_amplitude_ratio,
    element_receive_pressure,
    element_sensitivity,
    receive_impulse_response,
    spectral_window,
)
from holoprobe.characterize._receive_pipeline import (
    ReceiveResult,
    characterize_receive,
    refine_receiver_tilt,
    sensor_grid,
)
from holoprobe.characterize._reflection import (
    ReflectionEstimate,
    echo_train_peaks,
    estimate_reflection_coefficient,
    reflection_coefficient_from_peaks,
)
from holoprobe.characterize._source_field import (
    FocalField,
    focal_field,
    focal_waveform,
    half_level_width,
)
from holoprobe.characterize._source_surface import (
    SourcePlacement,
    SourceReconstruction,
    Uniformity,
    UnrolledSurface,
    backproject_source,
    fit_source_surface,
    surface_flux,
    uniformity,
    unrolled_surface,
)
from holoprobe.characterize._virtual_receiver import (
    ArrivalLine,
    SensorLayout,
    VirtualReceiver,
    echo_arrivals,
    echo_search_window,
    estimate_virtual_receiver,
    fit_arrival_line,
    lens_path_offset,
    sensor_distance_from_onset,
    tilt_aligned_average,
    tilt_from_slope,
    virtual_sensor_surface,
)

__all__ = [
    "ApertureFit",
    "ElementMap",
    "ElementsConfig",
    "LensFit",
    "OrientationResult",
    "aperture_weights",
    "band_limit_gain",
    "band_limited_rectangle",
    "estimate_orientation",
    "fit_aperture",
    "fit_element_map",
    "fit_lens_focus",
    "lens_delays",
    "mean_surface_velocity",
    "resolve_edge_ambiguity",
    "reverse_lens_delays",
    "select_signal_bins",
]
__all__ += [  # receive half (paper section III B)
    "ArrivalLine",
    "DriveRatio",
    "ElementSensitivity",
    "ReceiveConfig",
    "ReceiveImpulseResponse",
    "ReflectionEstimate",
    "SensorLayout",
    "VirtualReceiver",
    "drive_amplitude_ratio",
    "echo_arrivals",
    "echo_search_window",
    "echo_train_peaks",
    "element_receive_pressure",
    "element_sensitivity",
    "estimate_reflection_coefficient",
    "estimate_virtual_receiver",
    "fit_arrival_line",
    "lens_path_offset",
    "receive_impulse_response",
    "reflection_coefficient_from_peaks",
    "sensor_distance_from_onset",
    "spectral_window",
    "tilt_aligned_average",
    "tilt_from_slope",
    "virtual_sensor_surface",
]
__all__ += [  # transmit pipeline (paper Fig. 4)
    "ApertureConfig",
    "BackProjectionConfig",
    "BandConfig",
    "CharacterizationConfig",
    "ElementEstimate",
    "IterationConfig",
    "LensConfig",
    "OnsetConfig",
    "OrientationConfig",
    "TransmitIRConfig",
    "TransmitResult",
    "WarningConfig",
    "characterize_transmit",
]
__all__ += [  # receive pipeline (paper section III B)
    "ReceiveResult",
    "characterize_receive",
    "refine_receiver_tilt",
    "sensor_grid",
]
__all__ += [  # single-element sources from holograms (issue 13)
    "FocalField",
    "FocusAlignment",
    "HologramConfig",
    "HologramResult",
    "PlaneWaveField",
    "SourcePlacement",
    "SourceReconstruction",
    "Uniformity",
    "UnrolledSurface",
    "align_focused",
    "backproject_source",
    "characterize_hologram",
    "fit_source_surface",
    "focal_field",
    "focal_waveform",
    "half_level_width",
    "hologram_grid",
    "hologram_noise_level",
    "hologram_power",
    "hologram_summary",
    "orthonormal_frame",
    "plane_wave_field",
    "propagation_guard_angle",
    "surface_flux",
    "uniformity",
    "unrolled_surface",
]
