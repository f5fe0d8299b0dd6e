"""Signal processing: Fourier convention, calibration, windows, onsets, deconvolution."""

from holoprobe.signal._fourier import (
    frequency_axis,
    next_fast_length,
    to_frequency,
    to_time,
    workers,
)

__all__ = ["frequency_axis", "next_fast_length", "to_frequency", "to_time", "workers"]
