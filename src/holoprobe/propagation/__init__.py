"""Field propagation: angular spectrum, Rayleigh integrals and fast projection.

Each algorithm lives in a private module and is re-exported here.
"""

from holoprobe.propagation._angular_spectrum import (
    angular_spectrum,
    evanescent_filter,
    inverse_angular_spectrum,
    propagate_parallel,
    spectral_propagator,
    wavenumber_axes,
)
from holoprobe.propagation._cylinder import project_cylinder
from holoprobe.propagation._plan import ProjectionPlan, image_taper_range, padded_shape
from holoprobe.propagation._plane_waves import plane_wave_cost, rayleigh_plane_waves
from holoprobe.propagation._power import plane_power, source_power
from holoprobe.propagation._project import project
from holoprobe.propagation._rayleigh import (
    RAYLEIGH_KERNELS,
    rayleigh_integral,
    rayleigh_time_domain,
)

__all__: list[str] = ["ProjectionPlan", "image_taper_range", "padded_shape", "project",
                      "project_cylinder"]
__all__ += [
    "angular_spectrum",
    "evanescent_filter",
    "inverse_angular_spectrum",
    "propagate_parallel",
    "spectral_propagator",
    "wavenumber_axes",
]
__all__ += ["RAYLEIGH_KERNELS", "rayleigh_integral", "rayleigh_time_domain"]
__all__ += ["plane_power", "source_power"]
__all__ += ["plane_wave_cost", "rayleigh_plane_waves"]
