"""Benchmark: fields at scattered 3-D points from the column table (issue 14 item 2).

P4-1 preset, the issue's diverging 2-cycle 2.5 MHz transmit (``field_points.TX``), random
points x ∈ ±25, y ∈ ±3, z ∈ 5–100 mm, local time windows at 20 MHz (≈ 500 samples,
≈ 100 bins of the −40 dB band), float32 records.

1. ``--cli N``: ``holoprobe field --points`` on a CSV of N such points in a cold process
   (the records streamed into field.h5 chunk by chunk): wall, CPU (user + system) and
   peak RSS of the child, the size of field.h5 and the method it records.
2. ``--sizes``: :func:`holoprobe.transducer.predict_field` in-process (``method="auto"``,
   which sends scattered points to the table): wall and CPU time, µs CPU per point and
   frequency bin.
3. ``--check M``: accuracy of the table on M points (a quarter of them at z 1.5–5 mm,
   near the face) against the dense Rayleigh sum over every sub-element of the array
   (``method="rayleigh"``, float64, the same record), relative to the largest pressure,
   for float64 and float32 tables.

Prints wall and CPU time with the load average: on a shared machine compare CPU times.

    .venv/bin/python benchmarks/table_fields.py [--cli 1000000] [--sizes 10000 100000]
                                                [--check 200] [--work DIR]
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

from field_points import TX  # the transmit (benchmarks/field_points.py)

FS = 20e6


def _setup(folder: Path):
    from holoprobe.transducer import TransmitSetting, VirtualTransducer

    vt = VirtualTransducer.from_preset("p4-1")
    tx = folder / "tx.toml"
    tx.write_text(TX)
    return vt, TransmitSetting.from_toml(tx), tx


def _points(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform([-25e-3, -3e-3, 5e-3], [25e-3, 3e-3, 100e-3], size=(n, 3))


def cli(n: int, folder: Path) -> None:
    import h5py

    vt, _, tx = _setup(folder)
    vt_path = vt.save(folder / "vt.h5", overwrite=True)
    csv = folder / "points.csv"
    np.savetxt(csv, _points(n) * 1e3, delimiter=",", fmt="%.5f")
    args = [sys.executable, "-m", "holoprobe", "field", str(vt_path), "--transmit", str(tx),
            "--points", str(csv), "--sampling-rate", str(FS / 1e6), "--out",
            str(folder / "out"), "--overwrite", "--quiet"]
    load = os.getloadavg()[0]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(args, check=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    out = folder / "out" / "field.h5"
    with h5py.File(out) as f:
        shape, method = f["pressure"].shape, f.attrs["method"]
    print(f"holoprobe field --points, {n} points -> {shape} float32 ({method}): load "
          f"{load:.1f}, wall {wall:.1f} s, CPU {cpu:.1f} s, peak RSS "
          f"{after.ru_maxrss / 2**20:.2f} GiB, field.h5 {out.stat().st_size / 1e9:.2f} GB",
          flush=True)


def sizes(ns: list[int], folder: Path) -> None:
    from holoprobe.transducer import FieldStream, predict_field

    vt, setting, _ = _setup(folder)
    predict_field(vt, setting, _points(200, 1), sampling_rate=FS, time_window="local",
                  dtype=np.float32)  # compile
    print(f"{'points':>10}{'load':>6}{'wall (s)':>10}{'CPU (s)':>9}{'bins':>6}"
          f"{'µs CPU / point / bin':>22}  method")
    for n in ns:
        pts = _points(n, 2)
        load = os.getloadavg()[0]
        t, c = time.perf_counter(), time.process_time()
        pred = predict_field(vt, setting, pts, sampling_rate=FS, time_window="local",
                             dtype=np.float32)
        wall, cpu = time.perf_counter() - t, time.process_time() - c
        nf = FieldStream(vt, setting, pts, sampling_rate=FS).bins().size
        print(f"{n:>10}{load:>6.1f}{wall:>10.1f}{cpu:>9.1f}{nf:>6}"
              f"{cpu / n / nf * 1e6:>22.2f}  {pred.method}", flush=True)


def check(m: int, folder: Path) -> None:
    from holoprobe.transducer import predict_field

    vt, setting, _ = _setup(folder)
    rng = np.random.default_rng(3)
    pts = _points(m, 4)
    near = m // 4
    pts[:near, 2] = rng.uniform(1.5e-3, 5e-3, near)
    kw = {"sampling_rate": FS, "time_window": "local"}
    dense = predict_field(vt, setting, pts, method="rayleigh", dtype=np.float64, **kw)
    scale = np.abs(dense.pressure).max()
    print(f"\n{m} points ({near} at z 1.5–5 mm), {dense.pressure.shape[1]} samples; "
          f"max |Δp| / max |p| against the dense Rayleigh sum ({scale / 1e6:.3f} MPa)")
    for dtype in (np.float64, np.float32):
        t = predict_field(vt, setting, pts, method="table", dtype=dtype,
                          n_samples=dense.pressure.shape[1], **kw)
        err = np.abs(t.pressure - dense.pressure)
        print(f"  table {np.dtype(dtype).name}: all {err.max() / scale:.2e}, near "
              f"{err[:near].max() / scale:.2e}, far {err[near:].max() / scale:.2e} "
              f"({t.method})", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cli", type=int, default=0, help="points for the CLI run")
    parser.add_argument("--sizes", type=int, nargs="*", default=[10000, 100000])
    parser.add_argument("--check", type=int, default=200)
    parser.add_argument("--work", default=None, help="folder for the files (default tmp)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(args.work or tmp)
        folder.mkdir(parents=True, exist_ok=True)
        if args.cli:
            cli(args.cli, folder)
        if args.sizes:
            sizes(args.sizes, folder)
        if args.check:
            check(args.check, folder)


if __name__ == "__main__":
    main()
