"""Benchmark: full transmit + receive characterization of the simulated P4-1.

Simulates the P4-1 preset scan (241 × 161 × 1024, pose (0.5°, −0.8°, 0.6°), SNR 40 dB;
cached in ``--cache``) and its reflector echo (plate at 45 mm, θy' = 3°, Rp = 0.78,
back wall, SNR 30 dB, 96 × 1400 samples from 50 µs; cached in ``--echo-cache``), runs
:func:`holoprobe.characterize.characterize_transmit` and then
:func:`holoprobe.characterize.characterize_receive` pinned to at most 2 cores, and
prints wall time and peak resident memory per step with the errors against the truth
(issues 4 and 5). Goals: transmit ≤ 30 s and ≤ 3 GB; transmit + receive ≤ 60 s and
≤ 4 GB on 2 cores. ``--no-receive`` skips the receive half.

    .venv/bin/python benchmarks/pipeline.py [--cache /tmp/holoprobe_p41_scan.pkl]
"""

from __future__ import annotations

import argparse
import os
import pickle
import threading
import time
from pathlib import Path

import numpy as np


class RssSampler:
    """Samples the resident set size (/proc/self/statm) every ``interval`` s."""

    def __init__(self, interval: float = 0.01):
        self.interval = interval
        self.page = os.sysconf("SC_PAGE_SIZE")
        self.peak = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def rss(self) -> int:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * self.page

    def _run(self) -> None:
        while not self._stop.is_set():
            self.peak = max(self.peak, self.rss())
            time.sleep(self.interval)

    def reset(self) -> None:
        self.peak = self.rss()

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cache", default="/tmp/holoprobe_p41_scan.pkl")
    parser.add_argument("--echo-cache", default="/tmp/holoprobe_p41_echo.pkl")
    parser.add_argument("--no-receive", action="store_true")
    parser.add_argument("--cores", type=int, default=2)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        cpus = sorted(os.sched_getaffinity(0))[: args.cores]
        os.sched_setaffinity(0, set(cpus))

    from holoprobe.characterize import _pipeline
    from holoprobe.geometry import Pose
    from holoprobe.simulate import ArrayModel, simulate_scan

    cache = Path(args.cache)
    if cache.exists():
        scan, truth = pickle.loads(cache.read_bytes())
    else:
        t = time.perf_counter()
        scan, truth = simulate_scan(ArrayModel.from_preset("p4-1"),
                                    pose=Pose.from_degrees(0.5, -0.8, 0.6,
                                                           (0.1e-3, -0.05e-3, 3.5e-3)),
                                    n_samples=1024, snr_db=40.0, seed=2)
        print(f"simulation: {time.perf_counter() - t:.1f} s, shape {scan.data.shape}")
        cache.write_bytes(pickle.dumps((scan, truth)))

    sampler = RssSampler()
    sampler.start()
    peaks: dict[str, int] = {}
    steps = {"pressure_from_voltage": "pressure", "to_frequency": "spectrum",
             "estimate_orientation": "orientation", "fit_aperture": "aperture",
             "fit_lens_focus": "lens", "transmit_impulse_response": "transmit_ir",
             "detect_onset": "onset"}

    def wrap(name, fn):
        def inner(*a, **k):
            before = sampler.peak
            sampler.reset()
            try:
                return fn(*a, **k)
            finally:
                peaks[steps[name]] = max(peaks.get(steps[name], 0), sampler.peak)
                sampler.peak = max(before, sampler.peak)
        return inner

    for name in steps:
        setattr(_pipeline, name, wrap(name, getattr(_pipeline, name)))
    import holoprobe.propagation as prop

    original_project = prop.project
    steps["project"] = "backprojection"
    prop.project = wrap("project", original_project)
    base = sampler.rss()
    t = time.perf_counter()
    try:
        result = _pipeline.characterize_transmit(scan, progress=False)
    finally:
        prop.project = original_project
    wall = time.perf_counter() - t
    sampler.stop()
    print(f"\ncharacterize_transmit on {scan.data.shape}, {len(cpus)} cores: {wall:.1f} s; "
          f"peak RSS {sampler.peak / 2**30:.2f} GiB (input scan alone "
          f"{scan.data.nbytes / 2**30:.2f} GiB, RSS before {base / 2**30:.2f} GiB)")
    print(f"{'step':<18}{'time (s)':>10}{'peak RSS (GiB)':>16}")
    for step, seconds in result.timings.items():
        peak = peaks.get(step)
        print(f"{step:<18}{seconds:>10.2f}{'' if peak is None else f'{peak / 2**30:>16.2f}'}")

    p = truth.parameters
    ir = result.impulse_response
    tr = truth.arrays["transmit_ir"]
    n = 2 * max(ir.ir.size, tr.size)
    a = np.zeros(n)
    a[:ir.ir.size] = ir.ir
    b = np.zeros(n)
    b[:tr.size] = tr
    xc = np.fft.irfft(np.fft.rfft(a) * np.conj(np.fft.rfft(b)), n)
    k = int(np.argmax(xc))
    lag = (k if k < n // 2 else k - n) / ir.sampling_rate
    corr = xc[k] / np.linalg.norm(a) / np.linalg.norm(b)
    sp = p["scan_pose"]
    print("\nerrors against the truth:")
    for name, est, true in zip(("theta_x", "theta_y", "theta_z"), result.pose.angles_deg,
                               (sp["theta_x_deg"], sp["theta_y_deg"], sp["theta_z_deg"]),
                               strict=True):
        print(f"  {name}: {est - true:+.4f} deg")
    print(f"  W: {(result.aperture_width - p['probe']['aperture_width_m']) * 1e6:+.1f} µm")
    print(f"  H: {(result.aperture.height - p['probe']['aperture_height_m']) * 1e6:+.1f} µm")
    print(f"  F: {(result.lens_focus / p['probe']['lens_focus_m'] - 1) * 100:+.2f} %")
    z0 = result.pose.origin[2] + result.medium.sound_speed * lag
    print(f"  z0 (IR delay {lag * 1e9:+.1f} ns moved into it): {(z0 - sp['z0_m']) * 1e6:+.1f} µm")
    print(f"  IR correlation: {corr:.4f}")
    print("warnings:", result.warnings)
    if not args.no_receive:
        receive_half(args, scan, truth, result, sampler, wall)


def receive_half(args, scan, scan_truth, transmit, sampler, transmit_wall) -> None:
    """Simulate (or load) the echo, run characterize_receive, print time, memory, errors."""
    import math

    import holoprobe.propagation as prop
    from holoprobe.characterize import characterize_receive
    from holoprobe.simulate import ArrayModel, simulate_echo

    model = ArrayModel.from_preset("p4-1")
    cache = Path(args.echo_cache)
    if cache.exists():
        echo, echo_truth = pickle.loads(cache.read_bytes())
    else:
        t = time.perf_counter()
        echo, echo_truth = simulate_echo(model, plate_distance=45e-3,
                                         virtual_tilt=math.radians(3.0),
                                         reflection_coefficient=0.78, snr_db=30.0, seed=3,
                                         start_time=50e-6, n_samples=1400)
        print(f"\necho simulation: {time.perf_counter() - t:.1f} s, shape {echo.rf.shape}")
        cache.write_bytes(pickle.dumps((echo, echo_truth)))
    peak_projection = 0
    original = prop.project

    def wrapped(*a, **k):
        nonlocal peak_projection
        before = sampler.peak
        sampler.reset()
        try:
            return original(*a, **k)
        finally:
            peak_projection = max(peak_projection, sampler.peak)
            sampler.peak = max(before, sampler.peak)

    sampler.reset()
    prop.project = wrapped
    t = time.perf_counter()
    try:
        rx = characterize_receive(echo, transmit, scan, progress=False)
    finally:
        prop.project = original
    wall = time.perf_counter() - t
    print(f"\ncharacterize_receive on echo {echo.rf.shape}: {wall:.1f} s; peak RSS "
          f"{sampler.peak / 2**30:.2f} GiB (projection {peak_projection / 2**30:.2f} GiB); "
          f"{rx.sensor_points} sensor points, {rx.extras['projection_bins']} bins")
    print(f"transmit + receive: {transmit_wall + wall:.1f} s")
    print(f"{'step':<22}{'time (s)':>10}")
    for step, seconds in rx.timings.items():
        print(f"{step:<22}{seconds:>10.2f}")
    vr = rx.receiver
    ir = rx.impulse_response

    def lag_corr(est, true, rate):
        n = 2 * max(est.size, true.size)
        a = np.zeros(n)
        a[:est.size] = est
        b = np.zeros(n)
        b[:true.size] = true
        xc = np.fft.irfft(np.fft.rfft(a) * np.conj(np.fft.rfft(b)), n)
        k = int(np.argmax(xc))
        return (k if k < n // 2 else k - n) / rate

    lag_r = lag_corr(ir.ir, model.receive_ir, ir.sampling_rate)
    tx = transmit.impulse_response
    lag_t = lag_corr(tx.ir, scan_truth.arrays["transmit_ir"], tx.sampling_rate)
    c0 = transmit.medium.sound_speed
    d_corr = vr.distance + c0 * (lag_r + lag_t) / (1 + math.cos(vr.theta_y))
    k = round(lag_r * ir.sampling_rate)
    m = round(2e-6 * ir.sampling_rate)
    a = ir.ir[max(k, 0):max(k, 0) + m]
    b = model.receive_ir[max(-k, 0):max(-k, 0) + m]
    n = min(a.size, b.size)
    corr = np.dot(a[:n], b[:n]) / np.linalg.norm(a[:n]) / np.linalg.norm(b[:n])
    print("\nreceive errors against the truth:")
    print(f"  theta_y': {math.degrees(vr.theta_y) - 3.0:+.4f} deg")
    print(f"  d (IR delays {lag_r * 1e9:+.1f} / {lag_t * 1e9:+.1f} ns moved into it): "
          f"{(d_corr - 45e-3) * 1e6:+.1f} µm (raw {(vr.distance - 45e-3) * 1e6:+.1f} µm)")
    print(f"  Rp: {rx.reflection_coefficient - 0.78:+.4f}")
    print(f"  receive IR correlation over its first 2 µs: {corr:.4f}")
    print("receive warnings:", rx.warnings)


if __name__ == "__main__":
    main()
