"""Benchmark: sparse 2-D matrix arrays (issue 16 stretch), held-out twins.

Twins: ``ArrayModel.matrix(32, active=sparse_layout(32, 32, 256, ...))``: 256 elements
on a 32 × 32 lattice (pitch 0.3 mm, kerf 0.03 mm, 3 MHz, no lens) in a density-tapered
spiral or random layout, ±5 % element amplitudes, 3 ns rms delays, 3 dead elements, a
tilted scan plane 2.5 mm from the face, an 18 × 18 mm scan at 0.15 mm (121 × 121
points, 512 samples at 40 MHz), 40 dB peak SNR — the twin of ``benchmarks/matrix.py``
with the lattice thinned. Runs ``holoprobe.workflow.characterize`` and prints the errors
against the truth (:func:`matrix.errors`: angles in the acoustic-axis convention,
amplitudes of the present elements, IR correlation and in-band gain) and the time.

    .venv/bin/python benchmarks/sparse.py [--seeds 1] [--count 256] [--layout spiral]
"""

from __future__ import annotations

import argparse
import pickle
import time
from pathlib import Path

import numpy as np

from matrix import errors


def simulate(n: int, count: int, layout: str, seed: int, cache: Path,
             snr_db: float | None = 40.0):
    from holoprobe.geometry import Pose, sparse_layout
    from holoprobe.simulate import ArrayModel, simulate_scan

    path = cache / f"sparse{count}of{n}_{layout}_seed{seed}_snr{snr_db}.pkl"
    if path.exists():
        return pickle.loads(path.read_bytes())
    rng = np.random.default_rng(100 + seed)
    dead = tuple(sorted(rng.choice(count, size=3, replace=False).tolist()))
    active = sparse_layout(n, n, count, layout=layout, taper=0.5, seed=seed)
    model = ArrayModel.matrix(n, active=active).with_element_variation(
        amplitude_rms=0.05, delay_rms=3e-9, dead=dead, seed=seed)
    angles = rng.uniform(-1.0, 1.0, 3)
    pose = Pose.from_degrees(*angles, (rng.uniform(-0.2e-3, 0.2e-3),
                                       rng.uniform(-0.2e-3, 0.2e-3), 2.5e-3))
    size = 0.3e-3 * n + 8.4e-3
    t0 = time.perf_counter()
    scan, truth = simulate_scan(model, pose=pose, size=(size, size), step=(0.15e-3, 0.15e-3),
                                sampling_rate=40e6, n_samples=512, snr_db=snr_db, seed=seed,
                                calibration=None, points_per_wavelength=2)
    out = (model, pose, scan, truth, time.perf_counter() - t0)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(pickle.dumps(out))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--n", type=int, default=32)
    parser.add_argument("--count", type=int, default=256)
    parser.add_argument("--layout", default="spiral", choices=("spiral", "random"))
    parser.add_argument("--cache", type=Path, default=Path("/tmp/holoprobe_sparse"))
    parser.add_argument("--noise-free", action="store_true")
    args = parser.parse_args()
    from holoprobe.workflow import characterize

    rows = []
    for seed in args.seeds:
        model, pose, scan, truth, t_sim = simulate(args.n, args.count, args.layout, seed,
                                                   args.cache,
                                                   None if args.noise_free else 40.0)
        print(f"seed {seed}: {model.name}, twin {scan.data.shape} ({t_sim:.0f} s to "
              "simulate)", flush=True)
        t0, c0 = time.perf_counter(), time.process_time()
        run = characterize(scan, progress=False)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        row = {"seed": seed, "wall_s": wall, "cpu_s": cpu,
               **errors(model, pose, scan, truth, run)}
        rows.append(row)
        print({k: (round(v, 5) if isinstance(v, float) else v) for k, v in row.items()},
              flush=True)
        print("timings", {k: round(v, 2) for k, v in run.transmit.timings.items()})
        print("warnings", run.transmit.warnings)
    if rows:
        keys = list(rows[0])
        print("| " + " | ".join(keys) + " |")
        print("|" + "---|" * len(keys))
        for r in rows:
            print("| " + " | ".join(f"{r[k]:.4g}" if isinstance(r[k], float) else str(r[k])
                                     for k in keys) + " |")


if __name__ == "__main__":
    main()
