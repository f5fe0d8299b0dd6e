"""Benchmark: fields at planes and at arbitrary points (issue 14 item 2), and their accuracy.

1. ``holoprobe field`` in a cold process for the P4-1 preset's virtual transducer and a
   diverging 2-cycle 2.5 MHz transmit (virtual source 35 mm behind the probe, Tukey
   0.5): the xz plane x ∈ ±25 mm, z 5–100 mm at 0.3 mm (``--plane``), and the same
   points as a ``--points`` CSV (x on a 0.3 mm lattice that does not divide the pitch),
   and 10 points (the start-up: imports, numba, figures); each with and without
   ``--no-figures``.
2. Time vs number of points of :func:`holoprobe.transducer.predict_field` at random
   points in that region (the scaling curve; element superposition, float32).
3. Accuracy on a small case: the element superposition against the dense Rayleigh
   sum over every sub-element of the array (``method="rayleigh"``, float64), relative
   to the largest pressure.
4. The issue's 52 939 points in-process (``predict_field``, float32, what ``auto``
   picks: lines along x interpolated from the element lattice) against the exact
   element superposition (``method="element"``) on a subset of lines and the dense
   Rayleigh oracle at random points of the set, same record; and time vs number of
   such lines.

Prints wall and CPU time (user + system) with the load average: on a shared machine
compare runs taken under the same load.

    .venv/bin/python benchmarks/field_points.py [--skip-cli] [--sizes 1000 3000 10000]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TX = """name = "diverging 2-cycle"
prf = 2000.0
[delays]
kind = "diverging"
distance = 0.035
[apodization]
kind = "tukey"
alpha = 0.5
[drive]
kind = "burst"
frequency = 2.5e6
cycles = 2
amplitude = 30.0
"""


def _child(args: list[str]) -> tuple[float, float]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def cli_runs(folder: Path) -> None:
    from holoprobe.transducer import VirtualTransducer

    vt_path = VirtualTransducer.from_preset("p4-1").save(folder / "vt.h5", overwrite=True)
    tx = folder / "tx.toml"
    tx.write_text(TX)
    x = np.arange(-25.0, 25.0 + 1e-9, 0.3)
    z = np.arange(5.0, 100.0 + 1e-9, 0.3)
    gx, gz = np.meshgrid(x, z, indexing="ij")
    csv = folder / "points.csv"
    np.savetxt(csv, np.stack([gx.ravel(), np.zeros(gx.size), gz.ravel()], axis=-1),
               delimiter=",", fmt="%.4f")
    base = [sys.executable, "-m", "holoprobe", "field", str(vt_path), "--transmit", str(tx),
            "--overwrite", "--quiet"]
    few = folder / "points10.csv"
    np.savetxt(few, np.stack([np.linspace(-4, 4, 10), np.zeros(10), np.linspace(10, 70, 10)],
                             axis=-1), delimiter=",", fmt="%.4f")
    runs = {"xz plane (--plane)": ["--plane", "xz", "--extent", "-25", "25", "5", "100",
                                   "--step", "0.3", "--out", str(folder / "plane")],
            f"{gx.size} points (--points)": ["--points", str(csv), "--out",
                                             str(folder / "points")],
            "10 points (start-up)": ["--points", str(few), "--out", str(folder / "few")]}
    print(f"{'holoprobe field':<40}{'load':>6}{'wall (s)':>10}{'CPU (s)':>9}")
    for name, extra in runs.items():
        for flag in ("", "--no-figures"):
            load = os.getloadavg()[0]
            wall, cpu = _child([*base, *extra, *([flag] if flag else [])])
            print(f"{name + ' ' + flag:<40}{load:>6.1f}{wall:>10.1f}{cpu:>9.1f}")


def scaling(sizes: list[int]) -> None:
    from holoprobe.transducer import TransmitSetting, VirtualTransducer, predict_field

    vt = VirtualTransducer.from_preset("p4-1")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tx.toml"
        path.write_text(TX)
        setting = TransmitSetting.from_toml(path)
    rng = np.random.default_rng(0)
    print(f"\n{'random points':>14}{'load':>6}{'wall (s)':>10}{'CPU (s)':>9}{'µs CPU/point':>14}")
    for n in sizes:
        pts = rng.uniform([-25e-3, -3e-3, 5e-3], [25e-3, 3e-3, 100e-3], size=(n, 3))
        load = os.getloadavg()[0]
        t, c = time.perf_counter(), time.process_time()
        predict_field(vt, setting, pts, time_window="local", dtype=np.float32)
        wall, cpu = time.perf_counter() - t, time.process_time() - c
        print(f"{n:>14}{load:>6.1f}{wall:>10.1f}{cpu:>9.1f}{cpu / n * 1e6:>14.0f}")


def accuracy() -> None:
    from holoprobe.transducer import TransmitSetting, VirtualTransducer, predict_field

    vt = VirtualTransducer.from_preset("p4-1").replace(element_count=16)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tx.toml"
        path.write_text(TX)
        setting = TransmitSetting.from_toml(path)
    rng = np.random.default_rng(1)
    pts = rng.uniform([-5e-3, -2e-3, 5e-3], [5e-3, 2e-3, 40e-3], size=(150, 3))
    kw = {"sampling_rate": 20e6, "n_samples": 1024}
    dense = predict_field(vt, setting, pts, method="rayleigh", **kw)
    print(f"\n{'method vs dense Rayleigh (16 elements, 150 random points)':<58}"
          f"{'max |Δp| / max |p|':>20}")
    for name, dtype in (("element superposition float64", np.float64),
                        ("element superposition float32", np.float32)):
        fast = predict_field(vt, setting, pts, method="element", dtype=dtype, **kw)
        err = np.abs(fast.pressure - dense.pressure).max() / np.abs(dense.pressure).max()
        print(f"{name:<58}{err:>20.2e}")


def issue_plane(lines: list[int], oracle_points: int) -> None:
    from holoprobe.transducer import TransmitSetting, VirtualTransducer, predict_field

    vt = VirtualTransducer.from_preset("p4-1")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tx.toml"
        path.write_text(TX)
        setting = TransmitSetting.from_toml(path)
    x = np.arange(-25.0, 25.0 + 1e-9, 0.3) * 1e-3
    z = np.arange(5.0, 100.0 + 1e-9, 0.3) * 1e-3
    gx, gz = np.meshgrid(x, z, indexing="ij")
    pts = np.stack([gx.ravel(), np.zeros(gx.size), gz.ravel()], axis=-1)
    predict_field(vt, setting, pts[:50], time_window="local", dtype=np.float32)  # compile
    print(f"\n{'xz plane x ±25, z 5–100 mm at 0.3 mm':<40}{'load':>6}{'wall (s)':>10}"
          f"{'CPU (s)':>9}{'µs CPU/point':>14}")
    rng = np.random.default_rng(2)
    for n_lines in lines:
        keep = np.isin(np.rint(pts[:, 2] * 1e7), np.rint(rng.choice(z, min(n_lines, z.size),
                                                                 replace=False) * 1e7))
        sub = pts[keep] if n_lines < z.size else pts
        load = os.getloadavg()[0]
        t, c = time.perf_counter(), time.process_time()
        fast = predict_field(vt, setting, sub, time_window="local", dtype=np.float32)
        wall, cpu = time.perf_counter() - t, time.process_time() - c
        name = f"{sub.shape[0]} points ({fast.method})"
        print(f"{name:<40}{load:>6.1f}{wall:>10.1f}{cpu:>9.1f}{cpu / sub.shape[0] * 1e6:>14.0f}")
    pick = rng.choice(sub.shape[0], oracle_points, replace=False)  # of the last set timed
    n = fast.time.size
    dense = predict_field(vt, setting, sub[pick], method="rayleigh", time_window="local",
                          dtype=np.float64, n_samples=n)
    exact = predict_field(vt, setting, sub[pick], method="element", time_window="local",
                          dtype=np.float64, n_samples=n)
    scale = np.abs(dense.pressure).max()
    print(f"{'at ' + str(oracle_points) + ' random points of the set':<40}"
          f"{'max |Δp| / max |p|':>20}")
    print(f"{'lattice (float32) vs dense Rayleigh':<40}"
          f"{np.abs(fast.pressure[pick] - dense.pressure).max() / scale:>20.2e}")
    print(f"{'element (float64) vs dense Rayleigh':<40}"
          f"{np.abs(exact.pressure - dense.pressure).max() / scale:>20.2e}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--skip-cli", action="store_true")
    parser.add_argument("--sizes", type=int, nargs="+", default=[1000, 3000, 10000])
    parser.add_argument("--work", default=None, help="folder for the CLI runs (default tmp)")
    parser.add_argument("--lines", type=int, nargs="+", default=[32, 100, 317],
                        help="numbers of depth lines of the issue's plane to time")
    parser.add_argument("--oracle-points", type=int, default=60)
    args = parser.parse_args()
    if not args.skip_cli:
        if args.work:
            Path(args.work).mkdir(parents=True, exist_ok=True)
            cli_runs(Path(args.work))
        else:
            with tempfile.TemporaryDirectory() as tmp:
                cli_runs(Path(tmp))
    issue_plane(args.lines, args.oracle_points)
    scaling(args.sizes)
    accuracy()


if __name__ == "__main__":
    main()
