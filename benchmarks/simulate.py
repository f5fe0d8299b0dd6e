"""Benchmark: the full P4-1 hydrophone scan of the digital twin (wall time, peak memory).

A 241 × 161-point scan (36 × 24 mm, step 0.15 mm) of the ``p4-1`` preset, 1024 samples at
25 MHz, at the default pose (~3.6 mm in front of the probe), float32, default band and λ/4
source quadrature. Prints the wall time, the peak traced allocation (tracemalloc) and the
peak resident set size of the process.

Run:  .venv/bin/python benchmarks/simulate.py [--elements N] [--size-mm U V]
(reduced sizes are for a quick look; the figures in RESULTS.md are for the defaults).
"""

from __future__ import annotations

import argparse
import resource
import time
import tracemalloc

import numpy as np

from holoprobe.simulate import ArrayModel, simulate_scan


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--elements", type=int, default=None)
    parser.add_argument("--size-mm", type=float, nargs=2, default=(36.0, 24.0))
    parser.add_argument("--points-per-wavelength", type=float, default=4.0)
    parser.add_argument("--progress", action="store_true")
    args = parser.parse_args()
    overrides = {} if args.elements is None else {"element_count": args.elements}
    model = ArrayModel.from_preset("p4-1", **overrides)
    # compile the kernels outside the timing
    simulate_scan(model.replace(element_count=1), size=(0.3e-3, 0.3e-3), n_samples=64)
    tracemalloc.start()
    t0 = time.perf_counter()
    scan, truth = simulate_scan(model, size=[v * 1e-3 for v in args.size_mm],
                                step=(0.15e-3, 0.15e-3), sampling_rate=25e6,
                                n_samples=1024, points_per_wavelength=args.points_per_wavelength,
                                dtype=np.float32, progress=args.progress)
    wall = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    syn = truth.parameters["synthesis"]
    nx, ny, nt = scan.data.shape
    print(f"scan {nx}x{ny}x{nt} ({scan.data.dtype}), {syn['n_source_points']} source points "
          f"at {syn['source_spacing_m'] * 1e6:.1f} um, band {syn['band_hz'][0] / 1e6:.2f}-"
          f"{syn['band_hz'][1] / 1e6:.2f} MHz")
    print(f"wall time {wall:.1f} s; peak traced memory {peak / 2**20:.0f} MiB; "
          f"peak RSS {rss / 2**20:.0f} MiB")


if __name__ == "__main__":
    main()
