"""Holograms with known truth for the hologram-characterization tests.

The field is a dense Rayleigh sum (``fwd_vp``, rigid baffle) from a bowl or disc sampled
on Gauss-Legendre rings (:meth:`holoprobe.geometry.Surface.spherical_cap`, ``layout="rings"``,
``order=3``) — a different discretisation from the estimator's unrolled Cartesian grid and
plane-wave sums (no inverse crime). The source is tilted and offset; positions are in scan
coordinates (z = 0 on the scan plane, z < 0 behind it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from holoprobe.geometry import Medium, PlaneGrid, Pose, SourceGeometry, Surface, rotation_matrix
from holoprobe.measurement import Hologram
from holoprobe.propagation import rayleigh_integral


@dataclass(frozen=True)
class Twin:
    hologram: Hologram
    apex: np.ndarray
    axis: np.ndarray
    surface: Surface
    velocity: np.ndarray
    radius: float | None
    aperture: float


def make_twin(*, radius: float | None = 40e-3, aperture: float = 30e-3, frequency: float = 1e6,
              z_position: float = 25e-3, tilt=(0.02, -0.015), offset=(1.3e-3, -0.7e-3),
              n: int = 81, step: float = 0.5e-3, u0: float = 0.1, velocity=None,
              descending: bool = False, noise: float = 0.0, seed: int = 0,
              medium: Medium | None = None) -> Twin:
    """A CW hologram of a tilted, offset bowl (or disc for ``radius=None``)."""
    medium = medium or Medium()
    wavelength = medium.sound_speed / frequency
    local = Surface.spherical_cap(aperture, radius, spacing=wavelength / 4, layout="rings",
                                  order=3)
    rot = rotation_matrix(tilt[0], tilt[1], 0.0)
    axis = rot[:, 2]
    apex = np.array([offset[0], offset[1], 0.0]) - z_position * axis
    src = Surface(local.points @ rot.T + apex, local.normals @ rot.T, local.weights)
    vel = np.full(src.size, u0, complex) if velocity is None else velocity(local.points)
    x = (np.arange(n) - (n - 1) / 2) * step + 0.3e-3
    y = (np.arange(n) - (n - 1) / 2) * step - 0.2e-3
    plane = PlaneGrid(x, y).to_surface()
    p = rayleigh_integral(vel[:, None], src, plane, [frequency], medium,
                          kernel="fwd_vp")[:, 0].reshape(n, n)
    if noise:
        rng = np.random.default_rng(seed)
        p = p + noise / np.sqrt(2) * (rng.standard_normal(p.shape)
                                      + 1j * rng.standard_normal(p.shape))
    kind = "spherical-cap" if radius is not None else "flat-disc"
    geometry = SourceGeometry(kind, aperture, aperture, radius)
    if descending:
        x, p = x[::-1], p[::-1]
    grid = PlaneGrid(np.sort(x), y, Pose(origin=(0.0, 0.0, z_position)))
    data = p[::-1] if descending else p
    holo = Hologram(data, grid, medium, frequency=frequency, geometry=geometry,
                    source="twin")
    return Twin(holo, apex, axis, src, vel, radius, aperture)
