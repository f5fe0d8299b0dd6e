"""Timings of the hydrophone deconvolution (issue 15.1) and the output power (15.2).

Prints a table; asserts nothing. Run: ``PYTHONPATH=src python benchmarks/hydrophone_output.py``.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from holoprobe.exposure import acoustic_output_power, hydrophone_pulse
from holoprobe.measurement import DriveSignal, HydrophoneCalibration
from holoprobe.transducer import DelayLaw, TransmitSetting, VirtualTransducer


def _record(n: int, fs: float = 250e6) -> np.ndarray:
    t = np.arange(n) / fs
    t0 = 0.4 * n / fs
    x = (t - t0) / 0.25e-6
    rng = np.random.default_rng(0)
    return 5e-2 * np.exp(-x**2) * np.sin(2 * np.pi * 5e6 * (t - t0)) + 4e-4 * rng.standard_normal(n)


def main() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import PyDynamic  # noqa: F401  (import once, outside the timings)
    f = np.arange(1e6, 60.01e6, 0.5e6)
    cal = HydrophoneCalibration.from_fft_phase(f, np.full(f.size, 5e-8), -2 * np.pi * f * 50e-9,
                                               u_sensitivity=np.full(f.size, 1.5e-9),
                                               u_phase=np.full(f.size, 0.03))
    print("| record (samples) | deconvolution + GUM (s) | + 200 Monte Carlo draws (s) |")
    print("|---:|---:|---:|")
    for n in (2048, 8192, 32768):
        v = _record(n)
        t0 = time.perf_counter()
        res = hydrophone_pulse(v, 250e6, cal, n_draws=1)
        t1 = time.perf_counter()
        hydrophone_pulse(v, 250e6, cal, n_draws=200)
        t2 = time.perf_counter()
        assert res.pressure.pressure.size == n
        print(f"| {n} | {t1 - t0:.2f} | {t2 - t1:.2f} |")
    print()
    print("| probe | output power, plane + source (s) | plane/source − 1 |")
    print("|---|---:|---:|")
    for n_el in (16, 96):
        vt = VirtualTransducer.from_preset("p4-1").replace(element_count=n_el)
        drive = DriveSignal(np.r_[np.zeros(3), np.full(25, 10.0), np.zeros(12)], 250e6)
        tx = TransmitSetting(drive, delays=DelayLaw("focused", point=(0.0, 0.0, 0.03)),
                             prf=1000.0)
        t0 = time.perf_counter()
        out = acoustic_output_power(vt, tx)
        print(f"| P4-1, {n_el} elements | {time.perf_counter() - t0:.1f} | "
              f"{out.relative_difference:+.4f} |")


if __name__ == "__main__":
    main()
