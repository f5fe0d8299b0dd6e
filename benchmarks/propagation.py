"""Benchmark: P4-1-size back-projection, NUFFT fast path versus the dense Rayleigh oracle.

A 241 × 161 scan (0.15 mm step) on a tilted plane near z = 3.6 mm is projected back
onto a 241 × 161 grid on the source plane z = 0 (normal velocity, paper eq.
rayleigh-bwd-pv), for 200 and 500 frequency bins in 0.3–4.9 MHz. The dense
Rayleigh sum over all 241 × 161 targets would take minutes, so it is timed on an
evenly spread subset of the targets and extrapolated (the cost is exactly linear
in the number of targets); the relative difference is measured on that subset.

Run: ``python benchmarks/propagation.py [--quick]``. Prints one table.
"""

from __future__ import annotations

import argparse
import platform
import time
import tracemalloc
from functools import partial

import numpy as np

import holoprobe as hp
from holoprobe.propagation import project, rayleigh_integral

MEDIUM = hp.Medium()


def p41_like_scan_field(scan: hp.PlaneGrid, freqs: np.ndarray) -> np.ndarray:
    """Pressure of a lensed 28.5 × 14.3 mm aperture on the scan plane (via the fast path)."""
    source = hp.PlaneGrid.centered(241, 161, 0.15e-3)
    x, y = np.meshgrid(source.x, source.y, indexing="ij")
    inside = (np.abs(x) <= 14.27e-3) & (np.abs(y) <= 7.14e-3)
    focus, half = 0.18, 7.14e-3
    delay = (np.sqrt(half**2 + focus**2) - np.sqrt(y**2 + focus**2)) / MEDIUM.sound_speed
    spectrum = np.exp(-(((freqs - 2.5e6) / 1.2e6) ** 2))
    field = (inside * MEDIUM.impedance)[:, :, None] * np.exp(
        1j * 2 * np.pi * freqs[None, None, :] * delay[:, :, None]) * spectrum
    return project(field, source, scan, freqs, MEDIUM, eps=1e-8)


def timed(fn):
    tracemalloc.start()
    start = time.perf_counter()
    result = fn()
    elapsed = time.perf_counter() - start
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return result, elapsed, peak


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="200 bins only, fewer targets")
    args = parser.parse_args()
    scan = hp.PlaneGrid.centered(
        241, 161, 0.15e-3,
        pose=hp.Pose.from_degrees(-0.08, 0.65, -0.77, (-0.31e-3, -0.06e-3, 3.57e-3)))
    target = hp.PlaneGrid.centered(241, 161, 0.15e-3)
    subset_step = 97 if not args.quick else 389
    subset_idx = np.arange(0, target.size, subset_step)
    full_surface = target.to_surface()
    subset = hp.Surface(full_surface.points[subset_idx], full_surface.normals[subset_idx],
                        full_surface.weights[subset_idx])
    data_surface = scan.to_surface(flip_normal=True)
    rows = []
    for nf in ((200,) if args.quick else (200, 500)):
        freqs = np.linspace(0.3e6, 4.9e6, nf)
        field = p41_like_scan_field(scan, freqs)
        values = field.reshape(scan.size, nf)
        for label, options in (("nufft", {}),
                               ("nufft (complex64)", {"single_precision": True})):
            fast, t_fast, mem_fast = timed(partial(
                project, field, scan, target, freqs, MEDIUM, quantity="normal_velocity",
                **options))
            fast_subset = fast.reshape(target.size, nf)[subset_idx]
            rows.append((nf, label, t_fast, mem_fast, fast_subset))
        for dtype in (np.float32, np.float64):
            exact, t_sub, mem = timed(partial(
                rayleigh_integral, values, data_surface, subset, freqs, MEDIUM,
                kernel="bwd_pv", dtype=dtype))
            t_full = t_sub * target.size / subset.size
            rows.append((nf, f"rayleigh {np.dtype(dtype).name} (extrapolated)", t_full, mem,
                         exact))
    print(f"# P4-1-size back-projection, 241x161 -> 241x161, tilted plane; "
          f"{platform.processor() or platform.machine()}, {time.strftime('%Y-%m-%d')}")
    print(f"{'bins':>5} | {'method':<34} | {'time (s)':>9} | {'peak MB':>8} | "
          f"{'vs rayleigh f64':>15} | {'speed-up':>8}")
    print("-" * 95)
    for nf in sorted({r[0] for r in rows}):
        group = [r for r in rows if r[0] == nf]
        ref = next(r for r in group if "float64" in r[1])
        for _, label, t, mem, res in group:
            diff = np.linalg.norm(res - ref[4]) / np.linalg.norm(ref[4])
            print(f"{nf:>5} | {label:<34} | {t:>9.2f} | {mem / 2**20:>8.0f} | "
                  f"{diff:>15.2e} | {ref[2] / t:>8.0f}")


if __name__ == "__main__":
    main()
