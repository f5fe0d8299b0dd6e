"""signal: continuous-time spectrum, Hilbert envelope and the MAD noise level, against
analytic truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holoprobe.signal import MAD_TO_SIGMA, bin_energy, continuous_spectrum, envelope, mad_sigma


def test_continuous_spectrum_of_a_sampled_gaussian_is_its_analytic_transform():
    fs, sigma, t0 = 50e6, 0.2e-6, 2.1e-6  # the record holds ±10 σ
    t = 0.1e-6 + np.arange(200) / fs
    x = np.exp(-0.5 * ((t - t0) / sigma) ** 2)
    f = np.linspace(0.0, 3e6, 7)
    got = continuous_spectrum(x, fs, f, start_time=0.1e-6)
    # ∫ exp(−(t−t0)²/2σ²) e^{+2πift} dt (holoprobe's conjugate convention)
    truth = sigma * math.sqrt(2 * math.pi) * np.exp(-2 * (np.pi * sigma * f) ** 2) \
        * np.exp(2j * np.pi * f * t0)
    np.testing.assert_allclose(got, truth, rtol=0, atol=1e-9 * np.abs(truth).max())


def test_continuous_spectrum_on_a_dft_grid_is_the_direct_sum_and_the_analytic_one():
    """A uniform grid commensurate with fs (what signal_band searches, step fs/(4n), from
    negative frequencies up past fs/2) goes through one FFT: same values as the direct
    sum and as the Gaussian's analytic transform; an irregular grid is summed directly."""
    fs, sigma, t0, start = 50e6, 0.2e-6, 2.1e-6, 0.1e-6
    t = start + np.arange(200) / fs
    x = np.exp(-0.5 * ((t - t0) / sigma) ** 2)
    df = fs / 800
    for f in (np.arange(-40, 500) * df, np.arange(1, 430) * df * 0.999):
        got = continuous_spectrum(x, fs, f, start_time=start)
        direct = np.exp(2j * np.pi * np.outer(f, t)) @ x / fs
        truth = sigma * math.sqrt(2 * math.pi) * np.exp(-2 * (np.pi * sigma * f) ** 2) \
            * np.exp(2j * np.pi * f * t0)
        np.testing.assert_allclose(got, direct, rtol=0, atol=1e-12 * np.abs(direct).max())
        low = np.abs(f) < fs / 2
        np.testing.assert_allclose(got[low], truth[low], rtol=0,
                                   atol=1e-9 * np.abs(truth).max())


def test_envelope_of_an_amplitude_modulated_tone_is_the_modulation():
    fs = 100e6
    t = np.arange(2000) / fs
    a = np.exp(-0.5 * ((t - 10e-6) / 2e-6) ** 2)
    x = np.stack([a * np.cos(2 * np.pi * 5e6 * t), 2 * a * np.sin(2 * np.pi * 5e6 * t)])
    for pad in (True, False):
        env = envelope(x, axis=1, pad=pad)
        np.testing.assert_allclose(env[0], a, atol=1e-3)
        np.testing.assert_allclose(env[1], 2 * a, atol=2e-3)
    np.testing.assert_allclose(envelope(x.T, axis=0), envelope(x, axis=1).T)


def test_mad_sigma_estimates_the_standard_deviation_and_ignores_outliers():
    assert MAD_TO_SIGMA == pytest.approx(1 / 0.6744897501960817, rel=1e-15)
    rng = np.random.default_rng(3)
    x = rng.normal(0.0, 2.5, size=(4, 40000))
    x[:, :400] = 1e3  # 1 % gross outliers
    np.testing.assert_allclose(mad_sigma(x, axis=1), 2.5, rtol=0.03)
    assert mad_sigma(x[0]) == pytest.approx(2.5, rel=0.03)


def test_analytic_signal_and_theil_sen_equal_scipy():
    import scipy.signal
    import scipy.stats

    from holoprobe.signal import analytic_signal, theil_sen

    rng = np.random.default_rng(5)
    x = rng.normal(size=(3, 101))
    for n in (None, 101, 202, 64):
        np.testing.assert_allclose(analytic_signal(x, n=n, axis=1),
                                   scipy.signal.hilbert(x, N=n, axis=1), atol=1e-12)
    np.testing.assert_allclose(analytic_signal(x.T, axis=0), scipy.signal.hilbert(x.T, axis=0),
                               atol=1e-12)
    xs = np.repeat(np.arange(12.0), 2)  # ties in x
    ys = 0.3 * xs + rng.standard_cauchy(xs.size)
    ref = scipy.stats.theilslopes(ys, xs)
    assert theil_sen(xs, ys) == pytest.approx((ref.slope, ref.intercept), rel=1e-12)


def test_the_characterize_command_imports_neither_scipy_signal_nor_scipy_stats():
    """≈ 2 s of start-up (scipy.signal imports scipy.stats) that a transmit run never used."""
    import subprocess
    import sys

    code = ("import sys, holoprobe.workflow, holoprobe.cli.characterize, holoprobe.transducer;"
            "print(sorted(m for m in ('scipy.signal', 'scipy.stats') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_blas_threads_limits_blas_inside_the_block_only():
    import threadpoolctl

    from holoprobe.signal import blas_threads

    def blas_threads_now():
        return [i["num_threads"] for i in threadpoolctl.threadpool_info()
                if i["user_api"] == "blas"]

    before = blas_threads_now()
    assert before  # numpy's BLAS is loaded
    with blas_threads(1):
        assert blas_threads_now() == [1] * len(before)
    assert blas_threads_now() == before


@pytest.mark.parametrize("dtype", [np.complex128, np.complex64, np.float32])
def test_bin_energy_is_the_sum_of_squared_moduli_over_the_plane(dtype):
    """Per bin Σ|v|² over the leading axes, against an explicit loop in float64 (a
    non-contiguous view too)."""
    rng = np.random.default_rng(3)
    v = rng.normal(size=(7, 5, 6)) + (1j * rng.normal(size=(7, 5, 6))
                                      if np.dtype(dtype).kind == "c" else 0.0)
    v = v.astype(dtype)
    for field in (v, v[:, ::2, 1::2]):
        truth = [sum(abs(complex(z)) ** 2 for z in field[:, :, k].ravel())
                 for k in range(field.shape[2])]
        got = bin_energy(field)
        assert got.dtype == np.float64 and got.shape == (field.shape[2],)
        np.testing.assert_allclose(got, truth, rtol=1e-12)
