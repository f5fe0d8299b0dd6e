"""The alignment's noise uncertainties against drawn noise (issue 13).

By default the σ of the focal maximum and of the acoustic axis comes from linear
propagation of the hologram's white noise (no draws). Here it is checked against what it
did not compute: the spread of many drawn noise realisations pushed through the
estimator's perturbed solve. The hologram is an apodised converging spherical wave
(analytic, cheap); the spread of the full estimate over fresh noisy holograms of the
Rayleigh twins is measured in benchmarks/hologram_coverage.py --spread.
"""

from __future__ import annotations

import numpy as np
import pytest

from holoprobe.characterize import HologramConfig, align_focused
from holoprobe.geometry import Medium, PlaneGrid


@pytest.fixture(scope="module")
def converging():
    medium, frequency = Medium(), 1e6
    k = float(medium.wavenumber(frequency))
    x = (np.arange(41) - 20) * 0.5e-3
    y = x + 0.1e-3  # a grid not centred on the beam
    xx, yy = np.meshgrid(x, y, indexing="ij")
    rr = np.sqrt((xx - 0.3e-3) ** 2 + (yy + 0.2e-3) ** 2 + 0.02**2)  # focus 20 mm ahead
    p = 1e5 * np.exp(-((xx - 0.3e-3) ** 2 + yy**2) / 5e-3**2) * np.exp(-1j * k * rr)
    return PlaneGrid(x, y), p, frequency, medium


def _align(data, sigma_fraction, **cfg):
    grid, p, frequency, medium = data
    return align_focused(p, grid, frequency, medium, search_span=(-0.005, 0.04),
                         cfg=HologramConfig(window_taper=0.0, **cfg),
                         noise_level=sigma_fraction * np.abs(p).max())


def test_linear_noise_propagation_matches_many_monte_carlo_draws(converging):
    linear = _align(converging, 0.01)
    drawn = _align(converging, 0.01, monte_carlo=300)
    # 300 draws: the drawn σ is itself uncertain by ~4 %; the axis σ holds the line fit's
    # standard error (common to both) and the noise term (~80 % of its square here)
    np.testing.assert_allclose(linear.focus_uncertainty, drawn.focus_uncertainty, rtol=0.12)
    assert linear.axis_uncertainty == pytest.approx(drawn.axis_uncertainty, rel=0.12)
    np.testing.assert_array_equal(linear.focus, drawn.focus)


def test_no_noise_no_noise_term(converging):
    none, low = _align(converging, 0.0), _align(converging, 0.002)
    assert np.all(none.focus_uncertainty == 0)
    assert np.all(low.focus_uncertainty > 0)
    assert none.axis_uncertainty < low.axis_uncertainty
