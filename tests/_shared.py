"""Helpers shared by the tests (fixtures are in ``conftest.py``).

* :data:`SHARED_DATA`: the published toolkit's data files (``shared/reference/data``
  beside the repository: the real hydrophone calibration, the PROTEUS settings with the
  measured P4-1 impulse responses, the BLP-15+ datasheet) let some tests check holoprobe
  against the original files. A user's clone has no ``shared/``: those tests skip
  cleanly (``skipif`` on :data:`SHARED_DATA` existing); the package itself only uses its
  own copies in ``src/holoprobe/data``.
* :func:`gaussian_ir`: the Gaussian-windowed tone burst the synthetic twins use as an
  impulse response (analytic, so tests can state its spectrum and delay exactly).
* :func:`delay_and_correlation`: the delay of a signal against a reference and their
  normalised correlation, independent of holoprobe's own onset detection.
* :func:`acoustic_axis_angles`: a matrix twin's true angles in the characterization's
  acoustic-axis convention (the live elements' delay trend removed).
* :func:`element_ir_errors`: a matrix virtual transducer's per-element transmit IRs
  against the twin's (correlation, timing, absolute in-band gain).
* :func:`run_cli`: run the ``holoprobe`` command in-process.
* :func:`tiny_transducer`: a small virtual transducer (8 elements, 2 MHz) for field tests.
* :func:`coverage_twin_scan`: the scan of one reduced twin of
  ``benchmarks/uncertainty_coverage.py`` from its drawn parameters.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "reference" / "data"


def gaussian_ir(fs: float, fc: float, sigma: float, tc: float) -> np.ndarray:
    """``exp(−(t − tc)²/(2σ²)) cos(2π fc (t − tc))`` sampled at ``fs`` on [0, 2 tc)."""
    t = np.arange(round(2 * tc * fs)) / fs
    return np.exp(-0.5 * ((t - tc) / sigma) ** 2) * np.cos(2 * np.pi * fc * (t - tc))


def delay_and_correlation(signal: np.ndarray, reference: np.ndarray, rate: float = 1.0, *,
                          upsample: int = 1) -> tuple[float, float]:
    """Delay of ``signal`` relative to ``reference`` (positive: later) and the peak of
    their normalised cross-correlation.

    Linear (zero-padded) cross-correlation by FFT, optionally Fourier-upsampled, with a
    parabolic refinement of its peak. The delay is in s (in samples for ``rate=1``).
    """
    a = np.asarray(signal, dtype=float)
    b = np.asarray(reference, dtype=float)
    n = 2 * max(a.size, b.size)
    m = n * int(upsample)
    xc = np.fft.irfft(np.fft.rfft(a, n) * np.conj(np.fft.rfft(b, n)), m) * upsample
    k = int(np.argmax(xc))
    y0, y1, y2 = xc[k - 1], xc[k], xc[(k + 1) % m]
    den = y0 - 2 * y1 + y2
    frac = 0.5 * (y0 - y2) / den if den < 0 else 0.0
    lag = ((k if k < m // 2 else k - m) + frac) / upsample
    return lag / rate, float(xc[k] / (np.linalg.norm(a) * np.linalg.norm(b)))


def run_cli(args: list[str], capsys) -> tuple[int, str, str]:
    """Run ``holoprobe ARGS`` in-process; return (exit code, stdout, stderr)."""
    from holoprobe.cli import main

    old = sys.argv
    sys.argv = ["holoprobe", *args]
    try:
        main()
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    finally:
        sys.argv = old
    captured = capsys.readouterr()
    return code, captured.out, captured.err


FS = 100e6


def tiny_transducer(n=8, pitch=0.3e-3, width=0.25e-3, height=3e-3, focus=0.02):
    """A small virtual transducer (n elements, 2 MHz Gaussian-burst IR sampled at FS)."""
    from holoprobe.geometry import Medium
    from holoprobe.transducer import VirtualTransducer

    t = np.arange(300) / FS
    h = 1e11 * np.exp(-(((t - 0.8e-6) / 0.3e-6) ** 2)) * np.sin(2 * np.pi * 2e6 * (t - 0.8e-6))
    return VirtualTransducer(element_count=n, pitch=pitch, element_width=width,
                             element_height=height, transmit_impulse_response=h,
                             transmit_sampling_rate=FS, lens_focus=focus, medium=Medium(),
                             aperture_center=(0.1e-3, 0.2e-3))


def coverage_twin_scan(elements, theta_deg, origin, snr_db, seed):
    """The P4-1 model of ``elements`` elements and the scan of a reduced twin of
    ``benchmarks/uncertainty_coverage.py`` (``run_one``: 0.15 mm step, (N·p + 5 mm) ×
    19.2 mm, 192 samples, λ/3 sources) with the ``params`` of its run: pose angles (°),
    origin (m), scan SNR (dB) and noise seed. Returns ``(model, scan)``."""
    from holoprobe.geometry import Pose
    from holoprobe.simulate import ArrayModel, simulate_scan

    model = ArrayModel.from_preset("p4-1", element_count=elements)
    scan, _ = simulate_scan(model, pose=Pose.from_degrees(*theta_deg, origin),
                            size=(elements * model.pitch + 5e-3, 19.2e-3),
                            step=(0.15e-3, 0.15e-3), n_samples=192, snr_db=snr_db, seed=seed,
                            points_per_wavelength=3.0)
    return model, scan


def acoustic_axis_angles(model, pose, sound_speed):
    """True (θx, θy, θz) in degrees turned by the linear trend of the live elements'
    delays (weighted by their amplitudes): τ = τ̄ + s_x x + s_y y steers like
    Δθy = −asin(c s_x), Δθx = +asin(c s_y)."""
    amp = np.asarray(model.apodization)
    live = amp > 0
    pos = model.array.positions[live]
    design = np.c_[np.ones(pos.shape[0]), pos[:, :2]] * amp[live, None]
    coef = np.linalg.lstsq(design, np.asarray(model.delays)[live] * amp[live], rcond=None)[0]
    tx, ty, tz = pose.angles_deg
    return (tx + np.degrees(np.arcsin(sound_speed * coef[2])),
            ty - np.degrees(np.arcsin(sound_speed * coef[1])), tz)


def element_ir_errors(model, truth, vt):
    """Per live element of a matrix twin: the correlation of the model's IR
    ``A_e h̄(t − τ_e)`` with the twin's, its lag against the true delay (trend and mean
    removed: the acoustic-axis convention), and the in-band gain
    ``|H_e(f)| / (A_e |H(f)|)`` at 2.4–3.6 MHz (the twin's elements share one IR).
    Also checks the dead elements' IRs are zero."""
    from holoprobe.signal import continuous_spectrum

    times, irs = vt.element_transmit_impulse_responses()
    fs = vt.transmit_sampling_rate
    assert irs.shape == (model.element_count, times.size) and times[0] < 0 < times[-1]
    assert model.ir_sampling_rate == fs
    ref = truth.arrays["transmit_ir"]
    amp = np.asarray(model.apodization)
    live = amp > 0
    assert np.all(irs[~live] == 0)
    x = np.c_[np.ones(live.sum()), model.array.positions[live, :2]]
    tau = np.asarray(model.delays)[live]
    tau = tau - x @ np.linalg.lstsq(x * amp[live, None], tau * amp[live], rcond=None)[0]
    a_true = amp[live] / amp[live].mean()
    f = np.linspace(2.4e6, 3.6e6, 7)
    h_ref = np.abs(continuous_spectrum(ref, fs, f))
    corrs, lags, gains = [], [], []
    for e, t_e, a_e in zip(np.flatnonzero(live), tau, a_true, strict=True):
        lag, corr = delay_and_correlation(irs[e], ref, fs, upsample=4)
        corrs.append(corr)
        lags.append(lag + times[0] - t_e)
        gains.append(np.abs(continuous_spectrum(irs[e], fs, f)) / (a_e * h_ref))
    print("per-element IR: correlation min", np.min(corrs), "lag spread (ns)",
          np.ptp(lags) * 1e9, "gain range", np.min(gains), np.max(gains))
    return np.array(corrs), np.array(lags), np.array(gains)
