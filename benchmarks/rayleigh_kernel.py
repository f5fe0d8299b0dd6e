"""Micro-benchmark of the dense Rayleigh sum: kernel evaluations per second.

Usage::

    .venv/bin/python benchmarks/rayleigh_kernel.py [--points 20000] [--nf 8]

One evaluation = one (source point, target point, frequency) term. Wall time and
process CPU time are both reported (CPU time is the robust number on a shared
machine). NumPy runs on a smaller problem (it is ~10× slower) and is reported per
evaluation.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from holoprobe.geometry import Medium, PlaneGrid, Pose
from holoprobe.propagation import rayleigh_integral


def _planes(n_points: int):
    side = math.isqrt(n_points)
    src = PlaneGrid.centered(side, side, 0.15e-3).to_surface()
    dst = PlaneGrid.centered(side, side, 0.15e-3,
                             pose=Pose.from_degrees(1.0, 2.0, 0.0, (0.0, 0.0, 5e-3)))
    return src, dst.to_surface(flip_normal=True)


def _run(n_points: int, nf: int, backend: str, dtype, kernel: str) -> tuple[float, float, int]:
    src, dst = _planes(n_points)
    f = 2.0e6 + 50e3 * np.arange(nf)  # uniform grid: phasor recurrence
    values = np.ones((src.size, nf), dtype=complex)
    # warm up (compilation)
    rayleigh_integral(values[:4], _planes(4)[0], dst.__class__(dst.points[:4], dst.normals[:4],
                      dst.weights[:4]), f, Medium(), kernel=kernel, dtype=dtype, backend=backend)
    wall, cpu = time.perf_counter(), time.process_time()
    rayleigh_integral(values, src, dst, f, Medium(), kernel=kernel, dtype=dtype, backend=backend)
    return time.perf_counter() - wall, time.process_time() - cpu, src.size * dst.size * nf


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=20000)
    parser.add_argument("--numpy-points", type=int, default=2500)
    parser.add_argument("--nf", type=int, default=8)
    parser.add_argument("--kernel", default="fwd_vp")
    args = parser.parse_args()
    for backend, n in (("numba", args.points), ("numpy", args.numpy_points)):
        for dtype in (np.float32, np.float64):
            wall, cpu, evals = _run(n, args.nf, backend, dtype, args.kernel)
            print(f"{backend:5s} {np.dtype(dtype).name:7s} {args.kernel} {n}×{n}×{args.nf}: "
                  f"{wall:6.2f} s wall, {evals / wall:.3g} eval/s wall, "
                  f"{evals / cpu:.3g} eval/s per CPU-second")


if __name__ == "__main__":
    main()
