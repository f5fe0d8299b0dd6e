"""holoprobe: from a hydrophone scan and a reflector echo to a virtual transducer.

The public nouns live here; the verbs live in the sub-packages
(:mod:`holoprobe.propagation`, :mod:`holoprobe.signal`, ...).
"""

from holoprobe.errors import FitError, InputError
from holoprobe.geometry import Medium, PlaneGrid, Pose, Surface, rotation_matrix

__version__ = "0.1.0"

__all__ = ["FitError", "InputError", "Medium", "PlaneGrid", "Pose", "Surface", "__version__",
           "rotation_matrix"]
