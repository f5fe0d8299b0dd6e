"""Benchmark: receive-side acceptance of issue 10 on twins made by holoprobe.simulate.

``ir`` — the full-size P4-1 twin (scan 241 × 161 × 1024 at 40 dB, pose (0.5°, −0.8°,
0.6°); echo from a plate at 45 mm, θy' = 3°, Rp = 0.78, back wall, **25 dB** echo SNR,
96 × 1400 samples from 50 µs), characterized end to end; prints the receive IR's
correlation with the truth over its first 2 µs (aligned by cross-correlation) and
|H_est/H_true| over the truth's −6 dB band (absolute gain, not only shape).

``tilt`` — θy' of the arrival line and of the model-based refinement on P4-1-like
arrays of 64, 96 and 128 elements (same pitch) at plate tilts ±1…5° (θy' = 2 × the
plate tilt), plate at 45 mm, 30 dB, band 1.5–3.5 MHz (see :func:`run_tilt`).

Both twins come from dense Rayleigh sums on a λ/3 source quadrature and the image
method for the plate (no inverse crime: the pipeline forward-projects the noisy scan
with the NUFFT onto its own sensor sampling).

    .venv/bin/python benchmarks/receive_acceptance.py ir [--cache DIR]
    .venv/bin/python benchmarks/receive_acceptance.py tilt [--elements 64 96] [--tilts -1 3]
    .venv/bin/python benchmarks/receive_acceptance.py pipeline --snr 30 [--jobs 2] \
        --cache DIR

``pipeline`` — θy' end to end on the same arrays and tilts: reduced scans (as in
``uncertainty_coverage.py``) characterized by the pipeline, whose receive step predicts
the element pressure by projecting the scan (see :func:`run_pipeline`).
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import pickle
import time
from pathlib import Path

import numpy as np


def _cached(path: Path, make):
    if path.exists():
        return pickle.loads(path.read_bytes())
    t = time.perf_counter()
    value = make()
    print(f"  simulated {path.name} in {time.perf_counter() - t:.0f} s")
    path.write_bytes(pickle.dumps(value))
    return value


def lag_and_gain(est: np.ndarray, true: np.ndarray, rate: float) -> tuple[float, float,
                                                                           float, float]:
    """Lag (s, est later), correlation over the truth's first 2 µs after alignment, and the
    range of |H_est/H_true| over the truth's −6 dB band."""
    n = 4 * max(est.size, true.size)
    a = np.fft.rfft(est, n)
    b = np.fft.rfft(true, n)
    xc = np.fft.irfft(a * np.conj(b), n)
    k = int(np.argmax(xc))
    lag = (k if k < n // 2 else k - n) / rate
    m = round(2e-6 * rate)
    i = k if k < n // 2 else k - n
    x = est[max(i, 0):max(i, 0) + m]
    y = true[max(-i, 0):max(-i, 0) + m]
    q = min(x.size, y.size)
    corr = float(x[:q] @ y[:q] / np.linalg.norm(x[:q]) / np.linalg.norm(y[:q]))
    f = np.fft.rfftfreq(n, 1 / rate)
    ratio = np.abs(a * np.exp(2j * np.pi * f * lag) / b)
    band = np.abs(b) >= 0.5 * np.abs(b).max()
    return lag, corr, float(ratio[band].min()), float(ratio[band].max())


def run_ir(args: argparse.Namespace) -> None:
    from holoprobe.characterize import characterize_receive, characterize_transmit
    from holoprobe.geometry import Pose
    from holoprobe.simulate import ArrayModel, simulate_echo, simulate_scan

    model = ArrayModel.from_preset("p4-1")
    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    scan, scan_truth = _cached(cache / "p41_scan.pkl", lambda: simulate_scan(
        model, pose=Pose.from_degrees(0.5, -0.8, 0.6, (0.1e-3, -0.05e-3, 3.5e-3)),
        n_samples=1024, snr_db=40.0, seed=2))
    echo, _ = _cached(cache / f"p41_echo_{args.snr:g}dB.pkl", lambda: simulate_echo(
        model, plate_distance=45e-3, virtual_tilt=math.radians(3.0),
        reflection_coefficient=0.78, snr_db=args.snr, seed=3, start_time=50e-6,
        n_samples=1400))
    t = time.perf_counter()
    transmit = characterize_transmit(scan, progress=False)
    rx = characterize_receive(echo, transmit, scan, progress=False)
    wall = time.perf_counter() - t
    if args.save:
        Path(args.save).write_bytes(pickle.dumps((transmit, rx)))
    ir = rx.impulse_response
    lag, corr, lo, hi = lag_and_gain(ir.ir, model.receive_ir, ir.sampling_rate)
    tx = transmit.impulse_response
    lag_t, corr_t, lo_t, hi_t = lag_and_gain(tx.ir, scan_truth.arrays["transmit_ir"],
                                             tx.sampling_rate)
    c0 = transmit.medium.sound_speed
    d_corr = rx.receiver.distance + c0 * (lag + lag_t) / (1 + math.cos(rx.receiver.theta_y))
    print(f"full-size P4-1 twin, echo SNR {args.snr:g} dB: transmit + receive {wall:.1f} s")
    print(f"  receive IR: correlation over the first 2 µs {corr:.4f}; |H_est/H_true| in "
          f"the −6 dB band {lo:.3f} … {hi:.3f}; IR lag {lag * 1e9:+.1f} ns")
    peak_t = np.max(np.abs(tx.ir)) / np.max(np.abs(scan_truth.arrays["transmit_ir"]))
    print(f"  transmit IR: correlation {corr_t:.4f}; |H_est/H_true| in the −6 dB band "
          f"{lo_t:.3f} … {hi_t:.3f}; peak ratio {peak_t:.4f}")
    print(f"  θy' error {math.degrees(rx.receiver.theta_y) - 3.0:+.4f}° "
          f"(σ {math.degrees(rx.receiver.theta_y_uncertainty):.4f}°); d error "
          f"{(d_corr - 45e-3) * 1e6:+.1f} µm after moving the IR delays; Rp "
          f"{rx.reflection_coefficient - 0.78:+.4f}")


def run_tilt(args: argparse.Namespace) -> None:
    """θy' of the arrival line and of the model-based refinement
    (:func:`~holoprobe.characterize.refine_receiver_tilt`, 3 predictions with secant
    steps as in characterize_receive) against the truth. The predictions here are the
    simulator's noise-free element pressure at the candidate pose (dense Rayleigh), not
    the pipeline's projection of a scan (a full-size scan per probe costs ~15 min)."""
    from holoprobe.characterize import estimate_virtual_receiver
    from holoprobe.characterize._receive_pipeline import _refine_pose
    from holoprobe.simulate import ArrayModel, simulate_echo

    print(f"{'elements':>8} {'plate tilt':>10} {'line err (°)':>13} {'refined err (°)':>16} "
          f"{'σ (°)':>8} {'|err|/σ':>8} {'time (s)':>9}")
    d = 45e-3
    kw = dict(plate_distance=d, band=(1.5e6, 3.5e6), points_per_wavelength=2.5,
              back_wall=False, start_time=2 * d / 1481.0 - 3e-6, n_samples=600)
    for n_el in args.elements:
        model = ArrayModel.from_preset("p4-1", element_count=n_el)
        ex = model.probe_info().element_centers()
        for plate in args.tilts:
            t = time.perf_counter()
            theta = math.radians(2 * plate)
            echo, _ = simulate_echo(model, virtual_tilt=theta, snr_db=30.0, seed=7, **kw)
            line = estimate_virtual_receiver(echo.rf, echo.sampling_rate, ex,
                                             focus=model.lens_focus,
                                             height=model.element_height,
                                             start_time=echo.start_time, noise_guard=1e-6)

            def predict(rx, model=model, echo=echo):
                _, pred = simulate_echo(model, virtual_tilt=rx.theta_y, snr_db=None, **kw)
                return pred.arrays["element_pressure"].astype(float), echo.start_time

            p0, t0 = predict(line)
            opts = dict(pressure_rate=echo.sampling_rate, rf_start_time=echo.start_time,
                        focus=model.lens_focus, height=model.element_height,
                        sound_speed=1481.0)
            rx, _, _, _ = _refine_pose(line, echo.rf - echo.rf.mean(axis=1, keepdims=True),
                                       p0, t0, echo.sampling_rate, ex, predict, 3, opts)
            e_line = math.degrees(line.theta_y - theta)
            err = math.degrees(rx.theta_y - theta)
            sig = math.degrees(rx.theta_y_uncertainty)
            print(f"{n_el:>8} {plate:>+9g}° {e_line:>+13.4f} {err:>+16.4f} {sig:>8.4f} "
                  f"{abs(err) / sig:>8.1f} {time.perf_counter() - t:>9.0f}", flush=True)


def _pipeline_case(task: tuple) -> dict:
    params, cache = task
    from uncertainty_coverage import run_one  # benchmarks/ is the script's folder

    return run_one(params, True, Path(cache))


def run_pipeline(args: argparse.Namespace) -> None:
    """θy' end to end (``characterize_receive`` after ``characterize_transmit``, the
    predictions projected from the twin's noisy scan) on P4-1-like arrays of
    ``--elements`` at plate tilts ``--tilts`` (θy' = 2 × the plate tilt), plate at
    45 mm, Rp 0.78, back wall, ``--snr`` echo SNR. Scans reduced as in
    benchmarks/uncertainty_coverage.py (width + 5 mm × 19.2 mm at 0.15 mm, 192 samples,
    40 dB, pose (0.5°, −0.8°, 0.6°)); one transmit characterization per array, pickled
    in ``--cache``."""
    from concurrent.futures import ProcessPoolExecutor

    cache = Path(args.cache)
    cache.mkdir(parents=True, exist_ok=True)
    tasks = []
    for plate in args.tilts:
        for n_el in args.elements:
            params = {"index": -1, "elements": n_el, "theta_deg": [0.5, -0.8, 0.6],
                      "origin": [0.1e-3, -0.05e-3, 4e-3], "scan_snr_db": 40.0,
                      "scan_seed": 11 + n_el, "plate_distance": 45e-3,
                      "virtual_tilt_deg": 2 * plate, "reflection_coefficient": 0.78,
                      "echo_snr_db": args.snr, "echo_seed": 7 + n_el, "echo_samples": 1400}
            tasks.append((params, str(cache / f"scan_{n_el}.pkl")))
    print(f"{'elements':>8} {'plate tilt':>10} {'θy′ error (°)':>14} {'σ (°)':>8} "
          f"{'|err|/σ':>8} {'time (s)':>9}", flush=True)
    # one per array first (they write the transmit), the largest array first
    first = sorted(tasks[:len(args.elements)], key=lambda t: -t[0]["elements"])
    with ProcessPoolExecutor(args.jobs) as pool:  # printed as they come, in order
        for out in itertools.chain(pool.map(_pipeline_case, first),
                                   pool.map(_pipeline_case, tasks[len(first):])):
            p, row = out["params"], out["rows"].get("receive.theta_y_deg")
            name = f"case_{p['elements']}_{p['virtual_tilt_deg'] / 2:+g}.json"
            (cache / name).write_text(json.dumps(out, indent=1))
            if row is None:
                print(f"{p['elements']:>8} {p['virtual_tilt_deg'] / 2:>+9g}° failed: "
                      f"{out.get('receive_error')}", flush=True)
                continue
            print(f"{p['elements']:>8} {p['virtual_tilt_deg'] / 2:>+9g}° "
                  f"{row['error']:>+14.4f} {row['sigma']:>8.4f} "
                  f"{abs(row['error']) / row['sigma']:>8.1f} {out['timings']['total']:>9.0f}",
                  flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("part", choices=("ir", "tilt", "pipeline"))
    parser.add_argument("--cache", default="/tmp/holoprobe_receive_acceptance")
    parser.add_argument("--snr", type=float, default=25.0)
    parser.add_argument("--save", default=None,
                        help="ir: pickle (transmit result, receive result) to this file")
    parser.add_argument("--elements", type=int, nargs="+", default=[64, 96, 128])
    parser.add_argument("--tilts", type=float, nargs="+",
                        default=[-5.0, -3.0, -1.0, 1.0, 3.0, 5.0])
    parser.add_argument("--jobs", type=int, default=2, help="pipeline: processes")
    args = parser.parse_args()
    {"ir": run_ir, "tilt": run_tilt, "pipeline": run_pipeline}[args.part](args)


if __name__ == "__main__":
    main()
