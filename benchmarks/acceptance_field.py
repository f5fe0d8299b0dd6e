"""Benchmark: issue 6 twin acceptance on the full 96-element P4-1 (241 × 161 × 1024 scan).

Simulates (or reads from ``--cache``, the same recipe as ``benchmarks/pipeline.py``) the
noisy P4-1 twin scan (pose (0.5°, −0.8°, 0.6°), SNR 40 dB, seed 2), characterizes it,
writes and reloads ``virtual_transducer.h5``, then predicts the on-axis field of a
transmit the characterization never saw: 2-cycle 2.5 MHz burst (30 V), Tukey
apodization (α = 0.5), diverging wave from a virtual source 35 mm behind the probe.
The truth is the twin's own dense Rayleigh synthesis
(:func:`holoprobe.simulate.simulate_field`). Prints the relative L2 error of the on-axis
peak-pressure profile (acceptance: ≤ 5 %) and the timings.

    .venv/bin/python benchmarks/acceptance_field.py [--cache /tmp/holoprobe_p41_scan.pkl]
"""

from __future__ import annotations

import argparse
import os
import pickle
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.signal


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cache", default="/tmp/holoprobe_p41_scan.pkl")
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--z-max-mm", type=float, default=120.0)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        cpus = sorted(os.sched_getaffinity(0))[: args.cores]
        os.sched_setaffinity(0, set(cpus))

    from holoprobe.characterize import characterize_transmit
    from holoprobe.geometry import Medium, Pose
    from holoprobe.simulate import ArrayModel, simulate_field, simulate_scan
    from holoprobe.transducer import (
        Apodization,
        TransmitSetting,
        VirtualTransducer,
        burst,
        predict_field,
    )
    from holoprobe.workflow import write_outputs

    model = ArrayModel.from_preset("p4-1")
    cache = Path(args.cache)
    if cache.exists():
        scan, _ = pickle.loads(cache.read_bytes())
        print(f"scan from {cache}: {scan.data.shape}")
    else:
        t = time.perf_counter()
        scan, truth = simulate_scan(model, pose=Pose.from_degrees(0.5, -0.8, 0.6,
                                                                  (0.1e-3, -0.05e-3, 3.5e-3)),
                                    n_samples=1024, snr_db=40.0, seed=2)
        print(f"simulation: {time.perf_counter() - t:.1f} s, shape {scan.data.shape}")
        cache.write_bytes(pickle.dumps((scan, truth)))

    t = time.perf_counter()
    result = characterize_transmit(scan, progress=False)
    print(f"characterization: {time.perf_counter() - t:.1f} s")
    with tempfile.TemporaryDirectory() as tmp:
        vt = VirtualTransducer.load(write_outputs(result, tmp, report=False)
                                    ["virtual_transducer"])
    print(f"virtual transducer: N = {vt.element_count}, pitch {vt.pitch * 1e3:.4f} mm "
          f"(true {model.pitch * 1e3:.4f}), H {vt.element_height * 1e3:.3f} mm "
          f"(true {model.element_height * 1e3:.3f}), F {vt.lens_focus * 1e3:.1f} mm "
          f"(true {model.lens_focus * 1e3:.1f})")

    medium = Medium()
    c0 = medium.sound_speed
    fs = 250e6
    drive = burst(2.5e6, 2, 30.0, sampling_rate=model.ir_sampling_rate)
    z = np.arange(5e-3, args.z_max_mm * 1e-3 + 1e-9, 0.5e-3)
    pts = np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=-1)

    # the twin's truth, transmit written from its definitions
    x = model.element_centers()
    r = np.hypot(x, 35e-3)
    weights = scipy.signal.windows.tukey(model.element_count + 2, 0.5)[1:-1]
    twin = model.replace(drive=drive, apodization=weights, delays=(r - r.min()) / c0)
    t = time.perf_counter()
    _, p_true = simulate_field(twin, pts, medium=medium, sampling_rate=fs)
    print(f"truth (dense Rayleigh, {z.size} points): {time.perf_counter() - t:.1f} s")
    peak_true = np.abs(p_true).max(axis=1)

    setting = TransmitSetting.diverging(35e-3, drive=drive,
                                        apodization=Apodization("tukey", alpha=0.5))
    for method in ("auto", "rayleigh"):
        t = time.perf_counter()
        pred = predict_field(vt, setting, pts, sampling_rate=fs, time_window="local",
                             method=method)
        elapsed = time.perf_counter() - t
        peak = np.abs(pred.pressure).max(axis=1)
        l2 = np.linalg.norm(peak - peak_true) / np.linalg.norm(peak_true)
        worst = np.abs(peak - peak_true).max() / peak_true.max()
        print(f"prediction ({method}): {elapsed:.1f} s; on-axis peak pressure L2 relative "
              f"error {100 * l2:.2f} % (acceptance ≤ 5 %), max |Δ| {100 * worst:.2f} % of "
              f"the peak; peak {peak.max() / 1e3:.1f} kPa vs true {peak_true.max() / 1e3:.1f}"
              f" kPa at z = {z[np.argmax(peak_true)] * 1e3:.1f} mm")


if __name__ == "__main__":
    main()
