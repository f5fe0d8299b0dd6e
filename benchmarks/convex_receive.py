"""Convex-array twin → receive from a flat reflector: errors against the truth.

Usage: python benchmarks/convex_receive.py [--elements 32] [--distance-mm 20]
       [--tilt-deg 2] [--truth-face] [--seed 1]

The C5-2-like geometry of benchmarks/convex.py (pitch 0.508 mm, R = 49.6 mm, width
0.45 mm, 3.6 MHz Gaussian transmit IR), H and F as given, element variation 5 % / 5 ns
and 5 % receive gains, a receive IR unlike the transmit IR (3.3 MHz with a ringing copy
0.16 µs later), a 6 mm steel plate with its back wall, Rp = 0.78, 40 dB. The receive step
runs on the fitted face of the transmit characterization (default) or on the true one
(``--truth-face``: the receive step alone). Prints every error with the reported
uncertainty and the run times; asserts nothing.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from convex import convex_model
from holoprobe.characterize import (
    CharacterizationConfig,
    ConvexFace,
    characterize_convex_receive,
    characterize_convex_transmit,
)
from holoprobe.geometry import Pose
from holoprobe.simulate import simulate_echo, simulate_scan


def receive_ir(fs: float) -> np.ndarray:
    t = np.arange(int(1.4e-6 * fs)) / fs
    h = np.exp(-0.5 * ((t - 0.7e-6) / 0.18e-6) ** 2) * np.cos(2 * np.pi * 3.3e6
                                                               * (t - 0.7e-6)) * 3e-3
    return h + 0.25 * np.roll(h, round(0.16e-6 * fs))


def ir_errors(got: np.ndarray, truth: np.ndarray, fs: float) -> tuple[float, float, float]:
    """Delay (s) of ``got`` against ``truth``, their correlation after it, and the
    least-squares amplitude ratio (same rate, full length)."""
    n = 2 * max(got.size, truth.size)
    xc = np.fft.irfft(np.fft.rfft(got, n) * np.conj(np.fft.rfft(truth, n)), n)
    k = int(np.argmax(xc))
    lag = k if k < n // 2 else k - n
    a, b = got[max(lag, 0):], truth[max(-lag, 0):]
    m = min(a.size, b.size)
    corr = float(xc[k] / np.linalg.norm(got) / np.linalg.norm(truth))
    return lag / fs, corr, float(np.dot(a[:m], b[:m]) / np.dot(b[:m], b[:m]))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--elements", type=int, default=32)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--height-mm", type=float, default=6.0)
    ap.add_argument("--focus-mm", type=float, default=30.0)
    ap.add_argument("--size-mm", type=float, nargs=2, default=(26.0, 12.0))
    ap.add_argument("--scan-distance-mm", type=float, default=6.0)
    ap.add_argument("--distance-mm", type=float, default=20.0)
    ap.add_argument("--tilt-deg", type=float, default=2.0)
    ap.add_argument("--truth-face", action="store_true")
    ap.add_argument("--set", action="append", default=[])
    args = ap.parse_args()
    model = convex_model(args.elements, args.seed, args.height_mm * 1e-3,
                         args.focus_mm * 1e-3)
    model = model.replace(receive_ir=receive_ir(model.ir_sampling_rate))
    model = model.with_element_variation(receive_gain_rms=0.05, seed=args.seed + 7)
    pose = Pose.from_degrees(0.35, -0.6, 0.8, (0.2e-3, -0.15e-3, args.scan_distance_mm * 1e-3))
    d, tilt = args.distance_mm * 1e-3, math.radians(args.tilt_deg)
    band = (1.5e6, 5.5e6)
    t = time.perf_counter()
    scan, _ = simulate_scan(model, pose=pose, size=tuple(s * 1e-3 for s in args.size_mm),
                            step=(0.2e-3,) * 2, sampling_rate=25e6, n_samples=512, snr_db=40,
                            seed=args.seed, band=band)
    start = 2 * d / 1481.0 - 6e-6
    echo, _ = simulate_echo(model, plate_distance=d, virtual_tilt=tilt, back_wall=True,
                            plate_thickness=6e-3, snr_db=40, seed=args.seed + 1, band=band,
                            start_time=start, n_samples=1000)
    t_sim = time.perf_counter() - t
    cfg = CharacterizationConfig().with_overrides(args.set)
    t, c = time.perf_counter(), time.process_time()
    if args.truth_face:
        face = ConvexFace(model.array_geometry(), pose, model.lens_focus, band)
    else:
        res = characterize_convex_transmit(scan, cfg, radius_of_curvature=50.5e-3,
                                           progress=False)
        face = ConvexFace.from_transmit(res)
    t_tx, c_tx = time.perf_counter() - t, time.process_time() - c
    t, c = time.perf_counter(), time.process_time()
    rx = characterize_convex_receive(echo, face, scan, cfg, progress=False)
    t_rx, c_rx = time.perf_counter() - t, time.process_time() - c
    print(f"elements {args.elements}, plate {args.distance_mm} mm at θy' {args.tilt_deg}°, "
          f"face {'truth' if args.truth_face else 'fitted'}; twin {t_sim:.0f} s, transmit "
          f"{t_tx:.1f} s wall / {c_tx:.1f} s CPU, receive {t_rx:.1f} s wall / {c_rx:.1f} s "
          f"CPU, load {os.getloadavg()[0]:.1f}; {rx.timings}")
    vr = rx.receiver
    print(f"d        error {(vr.distance - d) * 1e6:+.1f} µm ± {vr.distance_uncertainty * 1e6:.1f}")
    print(f"θy'      error {math.degrees(vr.theta_y - tilt):+.4f}° ± "
          f"{math.degrees(vr.theta_y_uncertainty):.4f}°")
    print(f"Rp       error {rx.reflection_coefficient - 0.78:+.4f} ± "
          f"{rx.reflection_uncertainty:.4f}")
    ir = rx.impulse_response
    lag, corr, amp = ir_errors(ir.ir, model.receive_ir, ir.sampling_rate)
    print(f"IR       correlation {corr:.4f}, amplitude {amp:.4f}, time "
          f"{(lag - rx.extras['ir_shift']) * 1e9:+.1f} ns (2δd/c0 "
          f"{-2 * (vr.distance - d) / 1481.0 * 1e9:+.1f} ns)")
    g = np.asarray(model.receive_gains) / np.mean(model.receive_gains)
    s = rx.sensitivity
    err = s.amplitude / np.mean(s.amplitude) - g
    print(f"gains    max |error| {np.abs(err).max() * 100:.2f} %, rms "
          f"{np.sqrt(np.mean(err**2)) * 100:.2f} %, mean σ "
          f"{np.mean(s.amplitude_uncertainty) * 100:.2f} %, max |error|/σ "
          f"{np.max(np.abs(err) / s.amplitude_uncertainty):.2f}")
    print(f"refinement {rx.extras['pose_refinement']}")
    print("warnings:", rx.warnings)


if __name__ == "__main__":
    main()
