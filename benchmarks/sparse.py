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
import time
from pathlib import Path

from matrix import errors, print_table
from matrix import simulate as matrix_twin


def simulate(n: int, count: int, layout: str, seed: int, cache: Path,
             snr_db: float | None = 40.0):
    """The thinned twin of :func:`matrix.simulate` (the same draws, cached)."""
    return matrix_twin(n, seed, cache, snr_db, sparse=(count, layout))


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
    print_table(rows)


if __name__ == "__main__":
    main()
