"""Benchmark: fields of a transmit sequence on dask, time vs points and vs workers.

P4-1 preset, 4 focused lines (focus 30 mm, x from −5 to 5 mm, 2-cycle 2.5 MHz burst),
float32 at 36 MHz, on 3-D volumes x ±10 mm, y ±2 mm, z 10–40 mm at steps giving a
growing number of points. For each size: the in-process
:func:`holoprobe.transducer.predict_fields` (numpy result, no output) and
:func:`holoprobe.transducer.field_dataset` streamed to ``field.zarr`` by
:func:`holoprobe.io.write_field_zarr` on dask's local threaded scheduler; for the
largest size also a ``distributed.LocalCluster`` with 1 and 2 single-threaded worker
processes. Prints wall time, points per second and the load average, and the largest
difference of the Zarr store from the in-process result (relative to the peak).

    .venv/bin/python benchmarks/dask_fields.py [--sizes 2000 8000] [--no-distributed]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np


def _axes(n_target: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Axes of the volume with about ``n_target`` points (same extent, finer step)."""
    extent = np.array([20e-3, 4e-3, 30e-3])
    h = float((np.prod(extent) / n_target) ** (1 / 3))
    return (np.arange(-10e-3, 10e-3 + 1e-9, h), np.arange(-2e-3, 2e-3 + 1e-9, h),
            np.arange(10e-3, 40e-3 + 1e-9, h))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--sizes", type=int, nargs="+", default=[2000, 8000])
    parser.add_argument("--lines", type=int, default=4)
    parser.add_argument("--chunk-mb", type=float, default=16.0)
    parser.add_argument("--no-distributed", action="store_true")
    args = parser.parse_args()
    from holoprobe.io import write_field_zarr
    from holoprobe.transducer import (
        TransmitSetting,
        VirtualTransducer,
        burst,
        field_dataset,
        predict_fields,
    )

    vt = VirtualTransducer.from_preset("p4-1")
    drive = burst(2.5e6, 2, 30.0)
    settings = [TransmitSetting.focused((x, 0.0, 0.03), drive=drive)
                for x in np.linspace(-5e-3, 5e-3, args.lines)]
    fs = 36e6
    tmp = Path(tempfile.mkdtemp(prefix="holoprobe-dask-bench-"))
    print(f"{len(settings)} transmits, chunks ≤ {args.chunk_mb:g} MB, {os.cpu_count()} cores")
    print(f"{'points':>8} {'path':<24} {'wall s':>8} {'points/s':>9} {'load':>5} {'max diff':>9}")
    for size in args.sizes:
        axes = _axes(size)
        g = np.meshgrid(*axes, indexing="ij")
        pts = np.stack([a.ravel() for a in g], axis=-1)
        n = pts.shape[0]
        t = time.perf_counter()
        ref = np.stack([f.pressure for f in predict_fields(vt, settings, pts,
                                                            sampling_rate=fs)])
        wall = time.perf_counter() - t
        print(f"{n:>8} {'in-process':<24} {wall:>8.1f} {n / wall:>9.0f} "
              f"{os.getloadavg()[0]:>5.1f} {'':>9}", flush=True)
        runs: list[tuple[str, dict]] = [("dask threads (2)", {"num_workers": 2})]
        if size == args.sizes[-1] and not args.no_distributed:
            runs += [("distributed 1 worker", {"workers": 1}),
                     ("distributed 2 workers", {"workers": 2})]
        for label, opts in runs:
            ds = field_dataset(vt, settings, volume=axes, sampling_rate=fs,
                               chunk_bytes=args.chunk_mb * 1e6)
            out = tmp / f"{label.replace(' ', '_')}_{n}.zarr"
            t = time.perf_counter()
            if "workers" in opts:
                from distributed import LocalCluster

                with LocalCluster(n_workers=opts["workers"], threads_per_worker=1,
                                  processes=True, dashboard_address=None) as cluster:
                    t = time.perf_counter()  # cluster start-up not counted
                    write_field_zarr(out, ds, scheduler=cluster.scheduler_address)
                    wall = time.perf_counter() - t
            else:
                write_field_zarr(out, ds, num_workers=opts["num_workers"])
                wall = time.perf_counter() - t
            import xarray as xr

            got = xr.open_zarr(out).pressure.values.reshape(ref.shape)
            diff = float(np.max(np.abs(got - ref)) / np.max(np.abs(ref)))
            print(f"{n:>8} {label:<24} {wall:>8.1f} {n / wall:>9.0f} "
                  f"{os.getloadavg()[0]:>5.1f} {diff:>9.1e}", flush=True)


if __name__ == "__main__":
    main()
