"""Characterization: scan-plane orientation, aperture, lens, impulse responses.

Each algorithm lives in a private module and is re-exported here.
"""

from holoprobe.characterize._aperture import (
    ApertureFit,
    aperture_weights,
    band_limited_rectangle,
    fit_aperture,
    mean_surface_velocity,
    select_signal_bins,
)
from holoprobe.characterize._lens import (
    LensFit,
    fit_lens_focus,
    lens_delays,
    reverse_lens_delays,
)
from holoprobe.characterize._orientation import OrientationResult, estimate_orientation

__all__ = [
    "ApertureFit",
    "LensFit",
    "OrientationResult",
    "aperture_weights",
    "band_limited_rectangle",
    "estimate_orientation",
    "fit_aperture",
    "fit_lens_focus",
    "lens_delays",
    "mean_surface_velocity",
    "reverse_lens_delays",
    "select_signal_bins",
]
