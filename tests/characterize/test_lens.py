"""Tests of holoprobe.characterize._lens: lens delays, focus fit and delay reversal.

Synthetic sources carry the exact lens delays written out here (not taken from
the code under test), are band-limited with the 2-D circular limit on a grid 3×
finer than the scan and decimated, and get 1 % complex noise.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from holoprobe.characterize._aperture import fit_aperture
from holoprobe.characterize._lens import fit_lens_focus, reverse_lens_delays
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import Medium, PlaneGrid
from holoprobe.lens import lens_delays
from holoprobe.signal import frequency_axis, to_frequency

C0 = 1481.0
H = 14.28e-3


def lensed_source(grid, freqs, *, focus, width, height, center_x, center_y, up=3,
                  noise=0.01, seed=0):
    """Rectangular source with exact lens delays, band-limited, shape (nx, ny, nf)."""
    nx, ny = grid.shape
    hx, hy = grid.dx / up, grid.dy / up
    off = (up - 1) // 2
    xf = grid.x[0] + (np.arange(nx * up) - off) * hx
    yf = grid.y[0] + (np.arange(ny * up) - off) * hy

    def cover(c, lo, hi, h):
        return np.clip((np.minimum(c + h / 2, hi) - np.maximum(c - h / 2, lo)) / h, 0, 1)

    rect = (cover(xf, center_x - width / 2, center_x + width / 2, hx)[:, None]
            * cover(yf, center_y - height / 2, center_y + height / 2, hy)[None, :])
    a = height / 2
    tau = 0.0 if np.isinf(focus) else (np.sqrt(a**2 + focus**2)
                                        - np.sqrt((yf - center_y) ** 2 + focus**2)) / C0
    kr2 = ((2 * np.pi * np.fft.fftfreq(xf.size, hx))[:, None] ** 2
           + (2 * np.pi * np.fft.fftfreq(yf.size, hy))[None, :] ** 2)
    rng = np.random.default_rng(seed)
    out = np.empty((nx, ny, len(freqs)), complex)
    for j, f in enumerate(freqs):
        omega = 2 * np.pi * f
        spectrum = np.fft.fft2(rect * np.exp(1j * omega * tau))
        spectrum[kr2 >= (omega / C0) ** 2] = 0
        out[:, :, j] = np.fft.ifft2(spectrum)[off::up, off::up][:nx, :ny]
    scale = noise * np.abs(out).max() / np.sqrt(2)
    return out + scale * (rng.standard_normal(out.shape) + 1j * rng.standard_normal(out.shape))


GRID = PlaneGrid.centered(41, 91, 0.18e-3)
FREQS = np.arange(1.0e6, 4.01e6, 0.25e6)
APERTURE = dict(width=5.5e-3, height=H, center_x=0.2e-3, center_y=0.25e-3)


def test_lens_delays_match_the_references_lens_and_the_paraxial_limit():
    # reference_spec 2.9: stored F = 0.1806689295 m, H = 14.2790297 mm -> max delay 95.2 ns
    tau = lens_delays(np.array([0.0, 7.13951485e-3, -7.13951485e-3]), 0.1806689295,
                      14.2790297e-3, 1481.0)
    assert tau[0] == pytest.approx(95.2e-9, abs=0.05e-9)
    np.testing.assert_allclose(tau[1:], 0.0, atol=1e-18)
    # weak lens: τ(0) → (H/2)²/(2 F c0) with relative error ≈ (H/2)²/(4F²)
    focus = 50.0
    paraxial = (H / 2) ** 2 / (2 * focus * C0)
    assert lens_delays(0.0, focus, H, C0) == pytest.approx(paraxial, rel=1e-8)
    assert lens_delays(0.0, focus, H, C0) < paraxial
    np.testing.assert_array_equal(lens_delays(np.linspace(-1e-2, 1e-2, 5), np.inf, H, C0), 0)
    assert lens_delays(0.0, -0.2, H, C0) == pytest.approx(-lens_delays(0.0, 0.2, H, C0))
    with pytest.raises(InputError, match="focus"):
        lens_delays(0.0, 0.0, H, C0)
    with pytest.raises(InputError, match="height"):
        lens_delays(0.0, 0.2, -H, C0)


@pytest.mark.parametrize(("focus", "tolerance"), [(0.1807, 0.005), (0.11, 0.03), (0.5, 0.03)])
def test_focus_fit_recovers_the_focal_distance_of_a_noisy_lensed_source(focus, tolerance):
    v = lensed_source(GRID, FREQS, focus=focus, **APERTURE)
    aperture = fit_aperture(v, GRID, FREQS)
    lens = fit_lens_focus(v, GRID, FREQS, Medium(), aperture)
    assert lens.significant
    assert abs(lens.focus / focus - 1) < tolerance
    assert abs(lens.center_y - APERTURE["center_y"]) < 50e-6
    # the standard uncertainty is honest: the error is within 4 u, and u is small
    assert abs(lens.focus - focus) < 4 * lens.focus_uncertainty + 1e-4 * focus
    assert lens.focus_uncertainty < 0.01 * focus
    assert lens.per_bin_focus.shape == lens.frequencies.shape == (FREQS.size,)
    assert np.all(np.abs(lens.per_bin_focus / focus - 1) < 0.05)
    assert lens.explained > 0.99


def test_focus_fit_reports_infinity_for_a_source_without_lens():
    v = lensed_source(GRID, FREQS, focus=np.inf, seed=4, **APERTURE)
    aperture = fit_aperture(v, GRID, FREQS)
    lens = fit_lens_focus(v, GRID, FREQS, None, aperture)
    assert not lens.significant
    assert np.isinf(lens.focus) and np.isinf(lens.focus_uncertainty)
    assert abs(lens.curvature) < 4 * lens.curvature_uncertainty
    assert lens.center_y == aperture.center_y


def test_focus_fit_is_immune_to_column_phase_offsets_that_break_unwrapping():
    # arbitrary phase per column x and per bin (a lateral phase pattern, 2π jumps)
    rng = np.random.default_rng(7)
    v = lensed_source(GRID, FREQS, focus=0.1807, **APERTURE)
    v = v * np.exp(1j * rng.uniform(-np.pi, np.pi, (GRID.shape[0], 1, FREQS.size)))
    aperture = fit_aperture(v, GRID, FREQS)
    lens = fit_lens_focus(v, GRID, FREQS, None, aperture)
    assert abs(lens.focus / 0.1807 - 1) < 0.005


def test_lens_reversal_aligns_time_domain_pulses_delayed_by_the_lens():
    # each elevation y emits the same Gaussian pulse delayed by the lens; synthesised
    # in the time domain, transformed with holoprobe's convention, then reversed
    fs, n = 100e6, 2048
    t = np.arange(n) / fs
    focus, yc = 0.1807, 0.3e-3
    grid = PlaneGrid.centered(3, 41, 0.35e-3)
    a = H / 2
    tau = (np.sqrt(a**2 + focus**2) - np.sqrt((grid.y - yc) ** 2 + focus**2)) / C0

    def pulse(time):
        return np.exp(-(((time - 4e-6) / 0.35e-6) ** 2)) * np.cos(2 * np.pi * 2.5e6 * (time - 4e-6))

    p = pulse(t[None, None, :] - tau[None, :, None]) * np.ones((3, 1, 1))
    spectrum = to_frequency(p)
    freqs = frequency_axis(n, fs)
    band = (freqs > 1e6) & (freqs < 4e6)
    reversed_ = reverse_lens_delays(spectrum[:, :, band], grid, freqs[band], focus, H, C0,
                                    center_y=yc)
    edge_pulse = to_frequency(pulse(t))[band]  # what the aperture edge emits (τ = 0)
    phase = np.angle(reversed_ / edge_pulse[None, None, :])
    assert np.max(np.abs(phase)) < 1e-3
    before = np.angle(spectrum[:, :, band] / edge_pulse[None, None, :])
    assert np.max(np.abs(before)) > 1.0  # the lens phase was there to remove


def test_lens_fit_rejects_an_aperture_too_small_for_the_margin():
    v = lensed_source(GRID, FREQS, focus=0.1807, **APERTURE)
    small = fit_aperture(v, GRID, FREQS)
    tiny = type(small)(**{**small.__dict__, "width": 1.0e-3})
    with pytest.raises(FitError, match="margin"):
        fit_lens_focus(v, GRID, FREQS, None, tiny)


def test_focus_fit_does_not_depend_on_the_units_of_the_field():
    # a field in m/s·s (~1e-10) and one in arbitrary large units: the same F, and the
    # per-bin curvatures are fitted (not left at the start value) at either scale
    v = lensed_source(GRID, FREQS, focus=0.1807, seed=11, **APERTURE)
    aperture = fit_aperture(v, GRID, FREQS)
    small = fit_lens_focus(1e-10 * v, GRID, FREQS, None, aperture)
    large = fit_lens_focus(1e6 * v, GRID, FREQS, None, aperture)
    assert small.focus == pytest.approx(large.focus, rel=1e-6)
    assert small.center_y == pytest.approx(large.center_y, rel=1e-6, abs=1e-9)
    assert abs(small.focus / 0.1807 - 1) < 0.005
    for fit in (small, large):
        assert np.ptp(fit.per_bin_focus) > 1e-6 * fit.focus  # not all identical
        assert np.all(np.abs(fit.per_bin_focus / 0.1807 - 1) < 0.05)
    np.testing.assert_allclose(small.per_bin_focus, large.per_bin_focus, rtol=1e-6)


def test_focus_fit_keeps_the_strongest_bins_when_limited():
    # a Gaussian source spectrum around 2.5 MHz: the 5 strongest bins are the 5
    # frequencies nearest to it, and F from them alone is as accurate
    spectrum = np.exp(-(((FREQS - 2.5e6) / 0.8e6) ** 2))
    v = lensed_source(GRID, FREQS, focus=0.1807, seed=12, **APERTURE) * spectrum
    aperture = fit_aperture(v, GRID, FREQS)
    lens = fit_lens_focus(v, GRID, FREQS, None, aperture, max_bins=5)
    nearest = np.sort(FREQS[np.argsort(np.abs(FREQS - 2.5e6))[:5]])
    np.testing.assert_allclose(lens.frequencies, nearest)
    assert abs(lens.focus / 0.1807 - 1) < 0.005
    with pytest.raises(InputError, match="max_bins"):
        fit_lens_focus(v, GRID, FREQS, None, aperture, max_bins=0)


def test_analytic_delay_derivatives_match_finite_differences():
    from holoprobe.characterize._lens import _delay_derivatives

    s = np.linspace(-9e-3, 9e-3, 37)
    for kappa in (0.0, 1 / 0.1807, -1 / 0.05):
        tau, d_k, d_yl = _delay_derivatives(s, np.asarray(kappa), H / 2, C0)
        if kappa != 0:
            np.testing.assert_allclose(tau, lens_delays(s, 1 / kappa, H, C0), rtol=1e-12,
                                       atol=1e-22)
        hk, hy = 1e-3, 1e-7
        num_k = (_delay_derivatives(s, np.asarray(kappa + hk), H / 2, C0)[0]
                 - _delay_derivatives(s, np.asarray(kappa - hk), H / 2, C0)[0]) / (2 * hk)
        # y_L enters as s = y − y_L
        num_y = (_delay_derivatives(s - hy, np.asarray(kappa), H / 2, C0)[0]
                 - _delay_derivatives(s + hy, np.asarray(kappa), H / 2, C0)[0]) / (2 * hy)
        np.testing.assert_allclose(d_k, num_k, rtol=1e-6, atol=1e-9 * np.max(np.abs(num_k)))
        np.testing.assert_allclose(d_yl, num_y, rtol=1e-6, atol=1e-9 * np.max(np.abs(num_y)))


def test_closed_form_normal_equations_match_the_direct_residual_and_its_differences():
    # the per-column least-squares residual r of V − α e^{iωτ}, computed directly on a
    # random block (rows 0-1 outside the fit region), its cost, and Jᵀr and JᵀJ from
    # central differences of r, against the closed form from Bᴴ B
    from holoprobe.characterize._lens import _normal_equations

    rng = np.random.default_rng(3)
    nx, ny = 23, 17
    y = np.linspace(-6e-3, 6e-3, ny)
    omega = 2 * np.pi * 2.2e6
    mask = np.ones(ny)
    mask[:2] = 0
    block = (rng.standard_normal((nx, ny)) + 1j * rng.standard_normal((nx, ny))) * mask

    def residual(p):
        tau = lens_delays(y - p[1], 1 / p[0], H, C0)
        e = np.exp(1j * omega * tau) * mask
        alpha = block @ np.conj(e) / mask.sum()
        r = block - alpha[:, None] * e[None, :]
        return np.concatenate([r.real.ravel(), r.imag.ravel()])

    p0 = np.array([1 / 0.1807, 0.4e-3])
    steps = np.array([1e-3, 1e-8])
    jac = np.stack([(residual(p0 + h) - residual(p0 - h)) / (2 * h[k])
                    for k, h in enumerate(np.diag(steps))], axis=1)
    r0 = residual(p0)
    cost, jtr, jtj = _normal_equations((block.conj().T @ block)[None], mask[None],
                                       np.array([omega]), y, p0[:1], p0[1], H / 2, C0)
    assert cost[0] == pytest.approx(r0 @ r0, rel=1e-10)
    np.testing.assert_allclose(jtr[0], jac.T @ r0, rtol=1e-5)
    np.testing.assert_allclose(jtj[0], jac.T @ jac, rtol=1e-5)


def test_lens_delays_equalise_the_path_to_the_focus():
    h, F, c = 14e-3, 0.18, 1481.0
    y = np.linspace(-h / 2, h / 2, 11)
    tau = lens_delays(y, F, h, c)
    assert tau[0] == pytest.approx(0, abs=1e-18) and tau[-1] == pytest.approx(0, abs=1e-18)
    # paper eq. lens-delays: delay + travel time to (0, 0, F) is the same for every y
    total = tau + np.hypot(y, F) / c
    np.testing.assert_allclose(total, math.hypot(h / 2, F) / c, rtol=0, atol=1e-15)
    assert np.all(lens_delays(y, math.inf, h, c) == 0)
