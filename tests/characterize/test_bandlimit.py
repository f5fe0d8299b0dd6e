"""Box mean of a band-limited source (holoprobe.characterize.band_limit_gain, issue 10 item 7).

Checked against an analytic 1-D result and against a brute-force 2-D computation (FFT of
the lensed rectangle, propagating disc kept, lens reversed, box mean); the end-to-end
absolute transmit IR is checked in tests/test_pipeline_transmit.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import sici

from holoprobe.characterize import aperture_weights, band_limit_gain, lens_delays
from holoprobe.geometry import Medium, PlaneGrid

C0 = 1481.0


def test_long_strip_matches_the_analytic_box_mean_of_a_band_limited_rectangle():
    # H → ∞: g = (1/W)∫_box [Si(k(x+W/2)) − Si(k(x−W/2))]/π dx
    #          = 2 (kW Si(kW) + cos kW − 1) / (π kW)
    w, h = 4.7e-3, 6.0
    grid = PlaneGrid(np.arange(-200, 201) * 0.02e-3, np.arange(-20, 21) * 0.5e-3)
    f = np.array([0.5e6, 1e6, 2.5e6, 4e6])
    g = band_limit_gain(grid, f, Medium(998.0, C0), width=w, height=h)
    u = 2 * np.pi * f / C0 * w
    expected = 2 * (u * sici(u)[0] + np.cos(u) - 1) / (np.pi * u)
    np.testing.assert_allclose(g, expected, rtol=2e-4)
    assert np.all(np.diff(g) > 0) and g[0] < 0.95  # the spill grows towards low f


def test_lensed_aperture_matches_a_brute_force_two_dimensional_band_limit():
    med = Medium(998.0, C0)
    dx = dy = 0.15e-3
    grid = PlaneGrid(np.arange(-40, 41) * dx, np.arange(-70, 71) * dy)
    w, h, xc, yc, focus, yl = 4.8e-3, 14.2e-3, 0.07e-3, -0.1e-3, 0.03, 0.2e-3
    f = np.array([0.8e6, 2.5e6])
    g = band_limit_gain(grid, f, med, width=w, height=h, center_x=xc, center_y=yc,
                        focus=focus, lens_center_y=yl)
    big = PlaneGrid(np.arange(-512, 512) * dx, np.arange(-512, 512) * dy)
    box = aperture_weights(big, width=w, height=h, center_x=xc, center_y=yc)
    tau = lens_delays(big.y - yl, focus, h, C0)
    kx = 2 * np.pi * np.fft.fftfreq(big.x.size, dx)
    ky = 2 * np.pi * np.fft.fftfreq(big.y.size, dy)
    for gi, fi in zip(g, f, strict=True):
        lens = np.exp(2j * np.pi * fi * tau)[None, :]
        spec = np.fft.fft2(box * lens)
        spec[kx[:, None] ** 2 + ky[None, :] ** 2 >= (2 * np.pi * fi / C0) ** 2] = 0
        mean = np.sum(box * np.fft.ifft2(spec) * np.conj(lens)) / box.sum()
        assert abs(mean.imag) < 1e-3
        assert gi == pytest.approx(mean.real, abs=2e-3)
    assert g[0] < g[1] < 1
