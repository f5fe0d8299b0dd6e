"""
Deconvolve a hydrophone record
==============================

A hydrophone's voltage is its pressure filtered by a frequency-dependent complex
sensitivity M(f). :func:`holoprobe.exposure.hydrophone_pulse` divides it out with a
regularised inverse filter (PyDynamic's GUM propagation of the noise and of the
calibration's uncertainty) and computes the IEC 62127-1 pulse parameters with their
standard uncertainties.

The record is made here, independently of the deconvolver: a known 5 MHz pulse with
a second harmonic passes through a resonant hydrophone (40 MHz, damping 0.3) and a
60 ns cable delay, then gets white noise and a DC offset.
"""

# %%
import numpy as np
from scipy.signal import fftconvolve

from holoprobe.exposure import PULSE_KEYS, hydrophone_pulse
from holoprobe.measurement import HydrophoneCalibration
from holoprobe.report import plot_hydrophone_pulse

fs, m0, fn, zeta, delay = 250e6, 5e-8, 40e6, 0.3, 60e-9   # Hz, V/Pa, Hz, -, s
t = np.arange(2048) / fs


def true_pressure(t):
    x = (t - 2e-6) / 0.25e-6
    env = np.exp(-x**2)
    return 1e6 * env * (np.sin(2 * np.pi * 5e6 * (t - 2e-6))
                        + 0.35 * env * np.cos(4 * np.pi * 5e6 * (t - 2e-6)))


# the hydrophone's impulse response (2nd-order resonator behind a delay), 8x oversampled
fine = 8 * fs
tf = np.arange(8 * t.size) / fine
wn, wd = 2 * np.pi * fn, 2 * np.pi * fn * np.sqrt(1 - zeta**2)
th = np.arange(int(1.5e-6 * fine)) / fine - delay
h = np.where(th >= 0, wn**2 / wd * np.exp(-zeta * wn * th) * np.sin(wd * th), 0.0)
rng = np.random.default_rng(1)
voltage = (m0 * fftconvolve(true_pressure(tf), h)[:tf.size] / fine)[::8]
voltage += 0.02 + 0.4e-3 * rng.standard_normal(t.size)

# %%
# The calibration certificate
# ---------------------------
# Magnitude and phase (numpy's FFT convention, as certificates give it) at 1–60 MHz,
# with 3 % and 0.03 rad standard uncertainties.
f = np.arange(1e6, 60.01e6, 0.5e6)
w = 2 * np.pi * f
m = m0 * wn**2 / (wn**2 - w**2 + 2j * zeta * wn * w) * np.exp(-1j * w * delay)
calibration = HydrophoneCalibration.from_fft_phase(
    f, np.abs(m), np.unwrap(np.angle(m)), u_sensitivity=0.03 * np.abs(m),
    u_phase=np.full(f.size, 0.03), name="resonant needle")

# %%
# Deconvolve and compare with the truth
# -------------------------------------
result = hydrophone_pulse(voltage, fs, calibration, n_draws=60)
p_true = true_pressure(t)
values, unc = result.parameters.values, result.parameters.uncertainties
print(f"p_c = {values['p_c_Pa'] / 1e6:.3f} ± {unc['p_c_Pa'] / 1e6:.3f} MPa "
      f"(truth {p_true.max() / 1e6:.3f} MPa)")
print(f"p_r = {values['p_r_Pa'] / 1e6:.3f} ± {unc['p_r_Pa'] / 1e6:.3f} MPa "
      f"(truth {-p_true.min() / 1e6:.3f} MPa)")
print("keys:", ", ".join(PULSE_KEYS))
pulse_figure = plot_hydrophone_pulse(result)
