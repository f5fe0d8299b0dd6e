"""The scan-window taper of the focus/axis search follows the field at the window's edge:
outgoing edge diffraction is tapered, field still converging onto the focus is kept."""

from __future__ import annotations

import numpy as np

from holoprobe.characterize import HologramConfig, characterize_hologram, edge_taper_fraction
from holoprobe.geometry import Medium, PlaneGrid, SourceGeometry
from holoprobe.simulate import simulate_hologram


def _spherical(sign: float) -> tuple[np.ndarray, PlaneGrid]:
    """A point source 20 mm behind the plane (sign +1, diverging, exp(−iωt)) or a wave
    converging onto a point 20 mm ahead (sign −1), uniform amplitude."""
    grid = PlaneGrid.centered(41, 41, 0.5e-3)
    x, y = np.meshgrid(grid.x, grid.y, indexing="ij")
    k = float(2 * np.pi / Medium().wavelength(1e6))
    return np.exp(sign * 1j * k * np.sqrt(x**2 + y**2 + 0.02**2)), grid


def test_the_taper_is_kept_for_outgoing_and_dropped_for_converging_edges():
    diverging, grid = _spherical(+1.0)
    converging, _ = _spherical(-1.0)
    assert edge_taper_fraction(diverging, grid, 0.3) == 0.3
    assert edge_taper_fraction(converging, grid, 0.3) == 0.0
    assert edge_taper_fraction(converging, grid, 0.0) == 0.0


def test_a_window_filled_by_the_converging_beam_is_not_tapered():
    """An F/1 bowl (R = a = 30 mm) scanned 10 mm in front, a 41 × 41 λ/2 window (29.6 mm)
    that the converging field still fills at its edge: the fixed 0.3 taper removed beam,
    not leakage — axis off by 0.067° (σ 0.045°), focal maximum by −119 µm in z (σ 105 µm);
    the edge-following taper (α 0.026): 0.020° (σ 0.050°), +1 µm."""
    bowl = SourceGeometry("spherical-cap", 0.03, 0.03, 0.03)
    cw, truth = simulate_hologram(bowl, frequency=1e6, power=False, z_position=0.010,
                                  tilt=(0.01, -0.02), offset=(0.5e-3, -0.3e-3), shape=(41, 41))
    alignment = characterize_hologram(cw, HologramConfig(monte_carlo=0)).alignment
    axis = np.array(truth.parameters["alignment"]["axis_direction"])
    focus = np.array(truth.parameters["alignment"]["focus_position"])
    angle = np.arccos(np.clip(alignment.axis @ axis, -1.0, 1.0))
    assert np.degrees(angle) < 0.04
    assert angle <= 2 * alignment.axis_uncertainty
    err = alignment.focus - focus
    assert np.all(np.abs(err) <= 2 * alignment.focus_uncertainty)
    assert abs(err[2]) < 20e-6
