"""Acoustic output quantities (IEC 62127-1 / IEC 62359 / FDA track 3) from p(t), and
validation of a predicted field against a measured one (paper section III C).

Each part lives in a private module and is re-exported here.
"""

from holoprobe.exposure._metrics import (
    DERATING_DB_PER_CM_MHZ,
    UNITS,
    ExposureMetrics,
    acoustic_working_frequency,
    beam_width,
    derating_factor,
    exposure_metrics,
    mechanical_index,
    peak_pressures,
    pulse_duration,
    pulse_intensity_integral,
)
from holoprobe.exposure._power import OutputPower, acoustic_output_power, velocity_grid
from holoprobe.exposure._pulse import (
    PULSE_KEYS,
    HydrophonePulse,
    PulseParameters,
    hydrophone_pulse,
    pulse_parameters,
)
from holoprobe.exposure._sequence import SequenceExposure, sequence_exposure
from holoprobe.exposure._thermal import (
    C_TIB1_MW_PER_CM,
    C_TIB2_MW,
    C_TIC_MW_PER_CM,
    C_TIS1_MW_MHZ,
    ThermalIndices,
    beam_area,
    plane_pulse_energy,
    source_pulse_energy,
    thermal_indices,
)
from holoprobe.exposure._validation import (
    MEASURED_FIELD_FORMAT,
    MeasuredField,
    ValidationResult,
    least_squares_scale,
    plot_validation,
    read_measured_field,
    validate_field,
    write_measured_field,
)

__all__ = [
    "C_TIB1_MW_PER_CM",
    "C_TIB2_MW",
    "C_TIC_MW_PER_CM",
    "C_TIS1_MW_MHZ",
    "DERATING_DB_PER_CM_MHZ",
    "MEASURED_FIELD_FORMAT",
    "PULSE_KEYS",
    "UNITS",
    "ExposureMetrics",
    "HydrophonePulse",
    "MeasuredField",
    "OutputPower",
    "PulseParameters",
    "SequenceExposure",
    "ThermalIndices",
    "ValidationResult",
    "acoustic_output_power",
    "acoustic_working_frequency",
    "beam_area",
    "beam_width",
    "derating_factor",
    "exposure_metrics",
    "hydrophone_pulse",
    "least_squares_scale",
    "mechanical_index",
    "peak_pressures",
    "plane_pulse_energy",
    "plot_validation",
    "pulse_duration",
    "pulse_intensity_integral",
    "pulse_parameters",
    "read_measured_field",
    "sequence_exposure",
    "source_pulse_energy",
    "thermal_indices",
    "validate_field",
    "velocity_grid",
    "write_measured_field",
]
