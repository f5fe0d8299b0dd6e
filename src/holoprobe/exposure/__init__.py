"""Acoustic output quantities (IEC 62127-1 / IEC 62359 / FDA track 3) from p(t).

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

__all__ = [
    "DERATING_DB_PER_CM_MHZ",
    "UNITS",
    "ExposureMetrics",
    "acoustic_working_frequency",
    "beam_width",
    "derating_factor",
    "exposure_metrics",
    "mechanical_index",
    "peak_pressures",
    "pulse_duration",
    "pulse_intensity_integral",
]
