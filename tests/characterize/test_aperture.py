"""Tests of holoprobe.characterize._aperture: band-limited rectangle, aperture fit, mean velocity.

Synthetic apertures are produced independently of the fit's model: a rectangle
sampled with exact cell-coverage fractions on a grid 5× finer than the scan,
low-pass filtered with the 2-D circular band limit kx² + ky² < (ω/c0)² by an FFT
on that fine grid, decimated, with complex noise added.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad

from holoprobe.characterize._aperture import (
    aperture_weights,
    band_limited_rectangle,
    bins_view,
    fit_aperture,
    mean_surface_velocity,
)
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import PlaneGrid

C0 = 1481.0


def _coverage(centres, lo, hi, step):
    return np.clip((np.minimum(centres + step / 2, hi) - np.maximum(centres - step / 2, lo))
                   / step, 0.0, 1.0)


def synthetic_source(grid, freqs, *, width, height, center_x, center_y, focus=None,
                     up=5, noise=0.01, seed=0):
    """Band-limited rectangular source (optionally with a lens phase), shape (nx, ny, nf)."""
    nx, ny = grid.shape
    hx, hy = grid.dx / up, grid.dy / up
    off = (up - 1) // 2
    xf = grid.x[0] + (np.arange(nx * up) - off) * hx
    yf = grid.y[0] + (np.arange(ny * up) - off) * hy
    rect = (_coverage(xf, center_x - width / 2, center_x + width / 2, hx)[:, None]
            * _coverage(yf, center_y - height / 2, center_y + height / 2, hy)[None, :])
    kx = 2 * np.pi * np.fft.fftfreq(xf.size, hx)
    ky = 2 * np.pi * np.fft.fftfreq(yf.size, hy)
    kr2 = kx[:, None] ** 2 + ky[None, :] ** 2
    out = np.empty((nx, ny, len(freqs)), complex)
    for j, f in enumerate(freqs):
        omega = 2 * np.pi * f
        s = rect.astype(complex)
        if focus is not None:
            a = height / 2
            tau = (np.hypot(a, focus) - np.hypot(yf - center_y, focus)) / C0
            s = s * np.exp(1j * omega * tau)[None, :]
        spec = np.fft.fft2(s)
        spec[kr2 >= (omega / C0) ** 2] = 0
        out[:, :, j] = np.fft.ifft2(spec)[off::up, off::up][:nx, :ny]
    rng = np.random.default_rng(seed)
    scale = noise * np.abs(out).max() / np.sqrt(2)
    return out + scale * (rng.standard_normal(out.shape) + 1j * rng.standard_normal(out.shape))


def test_band_limited_rectangle_matches_quadrature_of_the_papers_k_space_integral():
    width, center = 14.28e-3, 0.4e-3
    k = 2 * np.pi * 2.5e6 / C0

    def paper(x):  # (W/2π) ∫_{-k}^{k} sinc(kx W / 2π) e^{i kx (x − xc)} dkx, real part
        integrand = lambda kx: np.sinc(kx * width / (2 * np.pi)) * np.cos(kx * (x - center))  # noqa: E731
        return width / (2 * np.pi) * quad(integrand, -k, k, limit=400, epsabs=1e-13)[0]

    xs = np.array([-12e-3, -7.14e-3, -3e-3, 0.0, 0.4e-3, 6.9e-3, 7.54e-3, 11e-3])
    expected = np.array([paper(x) for x in xs])
    np.testing.assert_allclose(band_limited_rectangle(xs, center, width, k), expected,
                               atol=1e-10)


def test_band_limited_rectangle_in_the_references_periodic_form_gives_its_values():
    # reference_spec 2.7.3: N = 241, dx = 0.15 mm, W = 14.28 mm, xc = 0, 2.5 MHz, c0 1481
    # B(0) = 0.994549, B(±7.05 mm) = 0.789165. Its FFT version is the Dirichlet kernel:
    # the continuous profile with cut-off (n_max + ½)·dk, summed over periodic images.
    n, dx, width = 241, 0.15e-3, 14.28e-3
    period = n * dx
    dk = 2 * np.pi / period
    k = 2 * np.pi * 2.5e6 / C0
    k_eff = (np.floor(k / dk) + 0.5) * dk
    xs = np.array([0.0, 7.05e-3, -7.05e-3])
    periodic = sum(band_limited_rectangle(xs + m * period, 0.0, width, k_eff)
                   for m in range(-300, 301))
    np.testing.assert_allclose(periodic, [0.994549, 0.789165, 0.789165], atol=2e-6)
    # the continuous profile itself differs from the grid's version by ~2.5e-3 at x = 0
    continuous = band_limited_rectangle(0.0, 0.0, width, k)
    assert abs(continuous - 0.994549) > 2e-3
    assert continuous == pytest.approx(0.992016, abs=1e-6)


def test_band_limited_rectangle_has_area_w_and_tends_to_the_rectangle():
    width, center = 10e-3, -1e-3
    x = np.linspace(-0.6, 0.6, 1_200_001)
    area = np.sum(band_limited_rectangle(x, center, width, 2e4)) * (x[1] - x[0])
    assert area == pytest.approx(width, rel=2e-4)
    inside = band_limited_rectangle([center - 3e-3, center + 4e-3], center, width, 1e7)
    outside = band_limited_rectangle([center - 6e-3, center + 5.5e-3], center, width, 1e7)
    np.testing.assert_allclose(inside, 1.0, atol=1e-3)
    np.testing.assert_allclose(outside, 0.0, atol=1e-3)


@pytest.mark.parametrize("profile", ["magnitude", "coherent"])
def test_aperture_fit_recovers_width_and_centre_of_noisy_band_limited_source(profile):
    # reference_spec section 8 check 9: W 28.54 mm, xc −0.31 mm, 1 % noise -> within 20 µm
    grid = PlaneGrid.centered(241, 121, 0.15e-3)
    freqs = np.array([1.5e6, 2.0e6, 2.5e6, 3.0e6, 3.5e6])
    truth = dict(width=28.54e-3, height=14.28e-3, center_x=-0.31e-3, center_y=0.12e-3)
    v = synthetic_source(grid, freqs, focus=0.1807, **truth)
    fit = fit_aperture(v, grid, freqs, profile=profile)
    assert abs(fit.width - truth["width"]) < 20e-6
    assert abs(fit.center_x - truth["center_x"]) < 20e-6
    assert abs(fit.height - truth["height"]) < 20e-6
    assert abs(fit.center_y - truth["center_y"]) < 20e-6
    for u in (fit.width_uncertainty, fit.height_uncertainty,
              fit.center_x_uncertainty, fit.center_y_uncertainty):
        assert 0 < u < 10e-6
    assert fit.profile_x.shape == (5, 241) and fit.model_y().shape == (5, 121)
    assert fit.residual_x < 0.05


def test_aperture_fit_uses_only_bins_with_signal():
    grid = PlaneGrid.centered(101, 81, 0.2e-3)
    freqs = np.array([0.0, 1.0e6, 2.0e6, 3.0e6, 9.0e6])
    v = synthetic_source(grid, freqs, width=12e-3, height=8e-3, center_x=0.5e-3,
                         center_y=-0.4e-3, noise=0.0)
    v[:, :, 4] *= 1e-3  # a bin 60 dB down: not signal
    v[:, :, 0] = 1.0  # DC is never used
    fit = fit_aperture(v, grid, freqs)
    np.testing.assert_array_equal(fit.frequencies, [1.0e6, 2.0e6, 3.0e6])
    assert abs(fit.width - 12e-3) < 5e-6 and abs(fit.center_y + 0.4e-3) < 5e-6


def test_aperture_fit_reports_a_flat_or_uncovered_aperture_clearly():
    grid = PlaneGrid.centered(40, 30, 0.2e-3)
    freqs = np.array([2e6])
    with pytest.raises(FitError, match="no aperture edge found along x"):
        fit_aperture(np.ones((40, 30, 1), complex), grid, freqs)
    v = synthetic_source(grid, freqs, width=20e-3, height=3e-3, center_x=0.0, center_y=0.0)
    with pytest.raises(FitError, match="grid edge"):
        fit_aperture(v, grid, freqs)
    with pytest.raises(InputError, match="velocity"):
        fit_aperture(np.ones((40, 31, 1)), grid, freqs)
    with pytest.raises(FitError, match="zero"):  # the data, not the input's form
        fit_aperture(np.zeros((40, 30, 1)), grid, freqs)


def test_aperture_weights_cover_exactly_the_rectangle_area():
    grid = PlaneGrid.centered(50, 40, 0.3e-3)
    w = aperture_weights(grid, width=7.37e-3, height=4.123e-3, center_x=0.071e-3,
                         center_y=-1.013e-3)
    assert np.sum(w) * grid.cell_area == pytest.approx(7.37e-3 * 4.123e-3, rel=1e-12)
    assert w.min() >= 0 and w.max() <= 1
    assert np.count_nonzero((w > 0) & (w < 1)) > 0  # partial cells at the edges


def test_mean_surface_velocity_equals_the_uniform_velocity_of_the_aperture():
    grid = PlaneGrid.centered(60, 50, 0.2e-3)
    rng = np.random.default_rng(3)
    u0 = rng.standard_normal(32)  # a time signal, m/s
    ap = type("Ap", (), dict(width=6.33e-3, height=4.71e-3, center_x=0.37e-3,
                             center_y=-0.52e-3))()
    covered = aperture_weights(grid, width=ap.width, height=ap.height,
                               center_x=ap.center_x, center_y=ap.center_y) > 0
    v = np.where(covered[:, :, None], u0[None, None, :], 5.0)  # 5 m/s outside: must not leak
    np.testing.assert_allclose(mean_surface_velocity(v, grid, ap), u0, rtol=1e-12)


def test_mean_surface_velocity_with_a_row_factor_undoes_a_lens_exactly():
    """A uniform source behind a cylindrical lens (V = u0(f)·e^{+iωτ(y − y_L)} on the
    aperture, the delays from the lens formula, not from the code under test): the mean
    with the lens reversal as ``row_factor`` is u0(f) whatever the delays; without it
    the lens phase averages the mean down."""
    from holoprobe.characterize._lens import lens_reversal

    grid = PlaneGrid.centered(60, 50, 0.2e-3)
    f = np.array([2.5e6, 3.5e6, 4.5e6])
    u0 = np.array([1.0 + 0.5j, -0.3j, 0.7])
    focus, height, y_l = 20e-3, 4.71e-3, -0.4e-3
    ap = type("Ap", (), dict(width=6.33e-3, height=height, center_x=0.37e-3,
                             center_y=-0.52e-3))()
    dy = grid.y - y_l
    tau = (np.sqrt(focus**2 + (height / 2) ** 2) - np.sqrt(focus**2 + dy**2)) / C0
    covered = aperture_weights(grid, width=ap.width, height=ap.height,
                               center_x=ap.center_x, center_y=ap.center_y) > 0
    lensed = u0[None, :] * np.exp(2j * np.pi * f[None, :] * tau[:, None])  # (ny, nf)
    v = np.where(covered[:, :, None], lensed[None], 5.0)
    factor = lens_reversal(grid, f, focus, height, C0, center_y=y_l)
    np.testing.assert_allclose(mean_surface_velocity(v, grid, ap, row_factor=factor), u0,
                               rtol=1e-12)
    assert np.all(np.abs(mean_surface_velocity(v, grid, ap)) < 0.95 * np.abs(u0))


def test_mean_surface_velocity_changes_continuously_with_the_aperture_width():
    # field x²: its mean over [-W/2, W/2] is W²/12. Overlap weights follow it within
    # dx²/8 (3e-8 m² here) for any W; a nearest-index box jumps by ~W·dx/6 (2.5e-7 m²).
    grid = PlaneGrid.centered(81, 21, 0.25e-3)
    v = np.broadcast_to((grid.x**2)[:, None, None], (81, 21, 1))
    for width in np.linspace(6.0e-3, 6.25e-3, 6):
        ap = type("Ap", (), dict(width=width, height=3e-3, center_x=0.0, center_y=0.0))()
        assert mean_surface_velocity(v, grid, ap)[0] == pytest.approx(width**2 / 12, abs=3e-8)


def test_bins_view_is_a_view_for_a_contiguous_run_and_a_copy_otherwise():
    spectrum = np.arange(2 * 3 * 8, dtype=float).reshape(2, 3, 8)
    for bins in (np.arange(2, 6), np.array([1, 3, 4]), np.array([5]), np.zeros(0, np.intp)):
        got = bins_view(spectrum, bins)
        assert np.array_equal(got, spectrum[:, :, bins])
        assert np.shares_memory(got, spectrum) == (bins.size > 0 and bool(
            np.all(np.diff(bins) == 1)))
