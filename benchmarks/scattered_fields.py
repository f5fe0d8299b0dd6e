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

``--per-bin N`` instead times :func:`holoprobe.propagation.rayleigh_plane_waves` one
frequency at a time at N random points (plus 200 check points, 50 of them at z 0.5–5 mm,
whose error against the dense Rayleigh sum over every sub-element is printed), for
``--frequencies`` across the band, and sums the CPU time over the ≈ 100 bins of the
20 MHz local record by interpolating the measured CPU per bin linearly in f: the
full-band figure for 10⁶ points when the machine is too loaded to run it whole.
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
    ap.add_argument("--per-bin", type=int, default=0)
    ap.add_argument("--frequencies", type=float, nargs="+",
                    default=[0.5e6, 1.5e6, 2.5e6, 3.5e6, 4.5e6])
    args = ap.parse_args()
    vt = VirtualTransducer.from_preset("p4-1")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tx.toml"
        path.write_text(TX)
        setting = TransmitSetting.from_toml(path)
    kw = dict(sampling_rate=FS, time_window="local")
    if args.per_bin:
        per_bin(vt, setting, args.per_bin, args.frequencies)
        return
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


def per_bin(vt, setting, n: int, frequencies: list[float]) -> None:
    """CPU per frequency bin at n points, error vs the dense sum, and the full-band total."""
    from holoprobe.geometry import Surface
    from holoprobe.propagation import plane_wave_cost, rayleigh_integral, rayleigh_plane_waves
    from holoprobe.transducer import record_length, signal_band, surface_velocity

    check = _points(200, seed=1)
    check[:50, 2] = np.random.default_rng(2).uniform(0.5e-3, 5e-3, 50)
    pts = np.concatenate([check, _points(n)])
    f_lo, f_hi = signal_band(vt, setting)
    n_rec = record_length(vt, [setting], pts, FS)
    bins = np.fft.rfftfreq(n_rec, 1 / FS)
    bins = bins[(bins >= f_lo) & (bins <= f_hi)]
    print(f"{n} points + 200 check points; record {n_rec} samples at {FS / 1e6:g} MHz, "
          f"{bins.size} bins in {f_lo / 1e6:.3f}–{f_hi / 1e6:.2f} MHz")
    print(f"{'f (MHz)':>8}{'nodes':>10}{'load':>6}{'wall (s)':>10}{'CPU (s)':>9}"
          f"{'err/peak':>10}{'near face':>10}")
    target = Surface(check, np.tile([0.0, 0.0, 1.0], (200, 1)), np.ones(200))
    cpus = []
    for f in frequencies:
        surface, velocity = surface_velocity(vt, setting, [f])
        nodes, _ = plane_wave_cost(surface.points, pts, [f], vt.medium)
        p, wall, cpu, load = _timed(lambda s=surface, v=velocity, f=f: rayleigh_plane_waves(
            v, s.points, s.weights, pts, [f], vt.medium, dtype=np.complex64))
        dense = rayleigh_integral(velocity, surface, target, [f], vt.medium, kernel="fwd_vp",
                                  baffle="rigid")[:, 0]
        err = np.abs(p[:200, 0] - dense) / np.abs(dense).max()
        cpus.append(cpu)
        print(f"{f / 1e6:>8.2f}{nodes:>10.0f}{load:>6.1f}{wall:>10.1f}{cpu:>9.1f}"
              f"{err.max():>10.1e}{err[:50].max():>10.1e}", flush=True)
    total = float(np.sum(np.interp(bins, frequencies, cpus)))
    print(f"full band ({bins.size} bins), CPU interpolated from the bins above: {total:.0f} s")


if __name__ == "__main__":
    main()
