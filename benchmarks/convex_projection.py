"""Cost of the back-projection onto a convex array's cylinder, per frequency bin.

Usage: python benchmarks/convex_projection.py [--elements 128] [--bins 2]

The type-3 NUFFT of ``ProjectionPlan.project`` onto the cylinder dominates a convex
characterization (each geometry iteration projects ~12 bins, the final pass the whole
band, ~90 bins). This script builds the scan of a C5-2-like probe (pitch 0.508 mm,
R = 49.6 mm, 13.5 mm high) without the twin — the field of a few point sources on the
arc, so that the projected values mean something — and times one projection per bin for
settings of the plan (eps, guard angle of the padding), of the patches of the 3-D
type-3 transform and for the cylindrical projection by the cylinder's symmetry
(:func:`holoprobe.characterize.project_on_cylinder`, ``method``), with the error of
each against the most accurate type-3 setting. Prints a table; asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from holoprobe.characterize import project_on_cylinder, unrolled_grid
from holoprobe.geometry import Medium, PlaneGrid, Pose
from holoprobe.propagation import ProjectionPlan


def scan_field(n_el: int, step: float, distance: float, freqs: np.ndarray,
               radius: float, medium: Medium) -> tuple[PlaneGrid, np.ndarray, Pose]:
    """A scan plane covering the arc's field and the pressure of point sources on the arc."""
    arc = n_el * 0.508e-3
    half = radius * np.sin(0.5 * arc / radius) + distance * np.tan(0.5 * arc / radius) + 4e-3
    nx, ny = int(2 * half / step) + 1, int(20e-3 / step) + 1
    grid = PlaneGrid.centered(nx, ny, step, step)
    pose = Pose.from_degrees(0.3, -0.5, 0.7, (0.1e-3, -0.1e-3, distance))
    pts = grid.points() @ pose.rotation.T + pose.origin_array  # source frame
    ang = np.linspace(-0.45, 0.45, 7) * arc / radius
    src = np.stack([radius * np.sin(ang), np.zeros(7), radius * (np.cos(ang) - 1)], -1)
    k = 2 * np.pi * freqs / medium.sound_speed
    d = np.linalg.norm(pts[:, None, :] - src[None, :, :], axis=-1)  # (n, 7)
    p = np.einsum("ns,nsf->nf", np.ones((pts.shape[0], 7)),
                  np.exp(1j * d[..., None] * k) / d[..., None])
    return grid, p.reshape(nx, ny, -1), pose


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--elements", type=int, default=128)
    ap.add_argument("--bins", type=int, default=2)
    ap.add_argument("--step-mm", type=float, default=0.2)
    ap.add_argument("--distance-mm", type=float, default=10.0)
    args = ap.parse_args()
    medium, radius = Medium(), 49.6e-3
    freqs = np.linspace(3e6, 5e6, args.bins)
    t = time.perf_counter()
    scan, field, pose = scan_field(args.elements, args.step_mm * 1e-3,
                                   args.distance_mm * 1e-3, freqs, radius, medium)
    print(f"{args.elements} elements, scan {field.shape} (built in "
          f"{time.perf_counter() - t:.1f} s), OMP/threads {os.cpu_count()}, "
          f"load {os.getloadavg()[0]:.1f}")
    grid = unrolled_grid(scan, pose, radius, 0.0)
    ref = None
    print("method       eps     guard  patches  padded        s/bin (wall)  cpu s/bin  "
          "max err")
    for method, eps, guard, patch in [
            ("type3", 1e-9, 80, 0.0), ("type3", 1e-6, 80, 0.0), ("type3", 1e-6, 80, 10.0),
            ("type3", 1e-4, 80, 0.0), ("type3", 1e-4, 60, 0.0), ("type3", 1e-4, 60, 10.0),
            ("type3", 1e-4, 45, 10.0), ("cylindrical", 1e-9, 80, 0.0),
            ("cylindrical", 1e-6, 80, 0.0), ("cylindrical", 1e-4, 80, 0.0),
            ("cylindrical", 1e-4, 60, 0.0)]:
        plan = ProjectionPlan(field, scan, freqs, medium, eps=eps,
                              guard_angle=np.radians(guard), single_precision=eps > 1e-8,
                              allow_undersampled=True)
        t, c = time.perf_counter(), time.process_time()
        v = project_on_cylinder(plan, pose, grid, radius, method=method,
                                patch_angle=np.radians(patch))
        wall, cpu = time.perf_counter() - t, time.process_time() - c
        if ref is None:
            ref = v
        err = np.abs(v - ref).max() / np.abs(ref).max()
        print(f"{method:11s}  {eps:6.0e}  {guard:4.0f}°  {patch:5.0f}°   {plan.shape!s:12s}  "
              f"{wall / args.bins:10.2f}  {cpu / args.bins:9.2f}  {err:.1e}")


if __name__ == "__main__":
    main()
