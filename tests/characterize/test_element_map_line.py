"""Element map of a 2-D (x, z) strip-array twin whose face lies off z = 0 (issue 11).

The pipeline's z = 0 is set by the onset of the mean surface velocity, not by the face:
on the full-size 96-element twin the face lay 0.4 mm *behind* it, outside the start grid
of the old fit (offsets ≥ 0 only), and the map came out half a pitch off with no dead
element found (benchmarks/RESULTS.md). The twin here is independent of the estimator's
model: every strip a Gauss–Legendre line of point sources radiating by the exact 2-D
Green's function (H0 of kr) onto a finely sampled scan line, cut to the scan's
footprint, carried back by a padded angular spectrum and decimated onto the source grid
(the estimator: sinc strips carried forward and back by FFT on its own grid).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.special

from holoprobe.characterize import fit_element_map
from holoprobe.geometry import PlaneGrid

C, PITCH, WIDTH = 1500.0, 0.3e-3, 0.25e-3


def _line_twin(count, dead, delta, center):
    """Back-projected velocity (nx, 2, nf), grid, bins, amplitudes, delays, distance and
    footprint of an array whose face lies ``delta`` farther from the scan than z = 0."""
    rng = np.random.default_rng(5)
    amp = 1.0 + 0.05 * rng.standard_normal(count)
    amp[list(dead)] = 0.0
    tau = 8e-9 * rng.standard_normal(count)
    d, dx = 3.0e-3, 0.05e-3
    half = 0.5 * count * PITCH + 3.1e-3
    xs = np.arange(-2048, 2048) * dx
    freqs = np.linspace(3.0e6, 4.8e6, 4)
    t, wq = np.polynomial.legendre.leggauss(12)
    src = (center + (np.arange(count) - 0.5 * (count - 1)) * PITCH)[:, None] + 0.5 * WIDTH * t
    kx = 2 * np.pi * np.fft.fftfreq(xs.size, dx)
    scan = np.abs(xs) <= half
    v = np.zeros((xs.size, freqs.size), complex)
    for j, f in enumerate(freqs):
        k = 2 * np.pi * f / C
        weights = (amp * np.exp(2j * np.pi * f * tau))[:, None] * wq * 0.5 * WIDTH
        r = np.hypot(xs[scan, None] - src.ravel()[None, :], d + delta)
        p = np.zeros(xs.size, complex)
        p[scan] = scipy.special.hankel1(0, k * r) @ weights.ravel()
        kz = np.sqrt(np.maximum(k**2 - kx**2, 0.0))
        back = np.where(np.abs(kx) < k, kz * np.exp(-1j * kz * d), 0.0)
        v[:, j] = np.fft.ifft(np.fft.fft(p) * back)
    n_keep = round((half + 2.5e-3) / dx)
    keep = slice(2048 - n_keep, 2048 + n_keep, 2)
    grid = PlaneGrid(xs[keep], np.array([-0.5e-3, 0.5e-3]))
    return (np.repeat(v[keep, None, :], 2, axis=1), grid, freqs, amp, tau, d,
            (-half, half))


@pytest.mark.parametrize(("count", "dead", "delta"), [
    (64, (25, 63), 0.4e-3),  # the old fit: half a pitch off, no dead element found
    (16, (4, 9), -0.25e-3),  # the face in front of z = 0
])
def test_map_finds_centre_offset_and_dead_elements_either_side_of_z0(count, dead, delta):
    center = 0.37 * PITCH
    v, grid, freqs, amp, tau, d, footprint = _line_twin(count, dead, delta, center)
    m = fit_element_map(v, grid, freqs, count=count, pitch=PITCH, element_width=WIDTH,
                        footprint=footprint, distance=d, sound_speed=C, fit_pitch=False,
                        fit_sound_speed=False)
    assert abs(m.center_x - center) < PITCH / 20
    assert m.focus_offset == pytest.approx(-delta, abs=0.05e-3)
    assert tuple(m.dead) == dead and m.weak == ()
    live = amp > 0
    err = m.relative_amplitude[live] - amp[live] / amp[live].mean()
    assert np.max(np.abs(err)) < 0.02
    assert np.all(np.abs(err) <= 3 * m.amplitude_uncertainty[live])
    dt = m.delay[live] - tau[live]
    assert np.max(np.abs(dt - dt.mean())) < 3e-9
