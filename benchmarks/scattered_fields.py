"""Benchmark: fields at scattered 3-D points by plane waves (issue 14 item 2, 10⁶ points).

P4-1 preset, diverging 2-cycle 2.5 MHz transmit (virtual source 35 mm behind the probe,
Tukey 0.5), random points x ∈ ±25, y ∈ ±3, z ∈ 5–100 mm, local time windows at 20 MHz
(≈ 500 samples, ≈ 100 bins of the −40 dB band), float32 records.

For each size: ``predict_field`` with ``method="plane_waves"`` (and ``"auto"`` when asked),
wall and CPU time (user + system of this process) with the load average. Accuracy on
``--check`` random points of the set: the plane-wave records against the exact element
superposition (``method="element"``, float64) on the same record grid, relative to the
largest pressure; ``--near`` of them lie at z 0.5–5 mm (near the face).

    .venv/bin/python benchmarks/scattered_fields.py [--sizes 10000 100000 1000000]
                                                   [--check 60] [--near 15] [--auto]
"""

from __future__ import annotations

import argparse
import os
import resource
import time

import numpy as np

from field_points import TX  # the transmit (benchmarks/field_points.py)

FS = 20e6


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _points(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(-25e-3, 25e-3, n), rng.uniform(-3e-3, 3e-3, n),
                     rng.uniform(5e-3, 100e-3, n)], axis=-1)


def _timed(fn):
    load = os.getloadavg()[0]
    t, c = time.perf_counter(), _cpu()
    out = fn()
    return out, time.perf_counter() - t, _cpu() - c, load


def main() -> None:
    import tempfile
    from pathlib import Path

    from holoprobe.transducer import TransmitSetting, VirtualTransducer, predict_field

    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000])
    ap.add_argument("--check", type=int, default=60)
    ap.add_argument("--near", type=int, default=15)
    ap.add_argument("--auto", action="store_true")
    args = ap.parse_args()
    vt = VirtualTransducer.from_preset("p4-1")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tx.toml"
        path.write_text(TX)
        setting = TransmitSetting.from_toml(path)
    kw = dict(sampling_rate=FS, time_window="local")
    print(f"{'points':>9}{'method':>14}{'samples':>8}{'load':>6}{'wall (s)':>10}"
          f"{'CPU (s)':>9}{'err/peak':>10}")
    for n in args.sizes:
        pts = _points(n)
        methods = ["plane_waves"] + (["auto"] if args.auto else [])
        for method in methods:
            pred, wall, cpu, load = _timed(lambda m=method, p=pts: predict_field(
                vt, setting, p, method=m, dtype=np.float32, **kw))
            print(f"{n:>9}{pred.method:>14}{pred.pressure.shape[1]:>8}{load:>6.1f}"
                  f"{wall:>10.1f}{cpu:>9.1f}{'':>10}", flush=True)
            del pred
    if args.check:
        pts = _points(args.check, seed=1)
        rng = np.random.default_rng(2)
        pts[:args.near, 2] = rng.uniform(0.5e-3, 5e-3, args.near)
        waves, wall, cpu, load = _timed(lambda: predict_field(
            vt, setting, pts, method="plane_waves", dtype=np.float64, **kw))
        exact, wall_e, cpu_e, load_e = _timed(lambda: predict_field(
            vt, setting, pts, method="element", dtype=np.float64,
            n_samples=waves.pressure.shape[1], **kw))
        peak = np.abs(exact.pressure).max()
        err = np.abs(waves.pressure - exact.pressure).max(axis=1) / peak
        print(f"{args.check:>9}{'plane_waves':>14}{waves.pressure.shape[1]:>8}{load:>6.1f}"
              f"{wall:>10.1f}{cpu:>9.1f}{err.max():>10.1e}")
        print(f"{args.check:>9}{'element':>14}{exact.pressure.shape[1]:>8}{load_e:>6.1f}"
              f"{wall_e:>10.1f}{cpu_e:>9.1f}{'(exact)':>10}")
        print(f"error/peak: all {err.max():.1e}, the {args.near} points at z 0.5–5 mm "
              f"{err[:args.near].max():.1e}, median {np.median(err):.1e}")


if __name__ == "__main__":
    main()
