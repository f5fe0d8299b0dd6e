"""The paper's analyses of a characterized probe: spurious modes (section III D), phase
compensation and reciprocity (section IV B), source representation (sections II C, IV C).

Each analysis lives in a private module and is re-exported here.
"""

from holoprobe.analysis._common import Aperture, envelope, update_summary
from holoprobe.analysis._modes import ModesResult, analyse_modes, modes_figures

__all__ = [
    "Aperture",
    "ModesResult",
    "analyse_modes",
    "envelope",
    "modes_figures",
    "update_summary",
]
