"""The paper's analyses of a characterized probe: spurious modes (section III D), phase
compensation and reciprocity (section IV B), source representation (sections II C, IV C).

Each analysis lives in a private module and is re-exported here.
"""

from holoprobe.analysis._baffle import BaffleResult, analyse_baffle, baffle_figure, kwave_available
from holoprobe.analysis._common import Aperture, update_summary
from holoprobe.analysis._modes import ModesResult, analyse_modes, modes_figures
from holoprobe.analysis._phase import (
    PhaseResult,
    analyse_phase,
    default_filter_phase,
    hydrophone_phase,
    normalised_similarity,
    phase_figures,
)
from holoprobe.signal import envelope  # re-export (it moved to signal)

__all__ = [
    "Aperture",
    "BaffleResult",
    "ModesResult",
    "PhaseResult",
    "analyse_baffle",
    "analyse_modes",
    "analyse_phase",
    "baffle_figure",
    "default_filter_phase",
    "envelope",
    "hydrophone_phase",
    "kwave_available",
    "modes_figures",
    "normalised_similarity",
    "phase_figures",
    "update_summary",
]
