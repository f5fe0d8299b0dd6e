"""Benchmark: the hologram twin (simulate_hologram) for the sizes issue 13 works with.

Prints the wall time of each case (kernels compiled beforehand) and the number of source
points of the twin's quadrature. Cases: the test-size 40 mm bowl at 1 MHz (61 × 61, CW and
transient), and the acceptance-size 87 mm bowl (R = 87 mm) at 1.25 MHz, 171 × 171 CW.
Times, never asserted; the machine may be loaded by other jobs (say so in RESULTS.md).

Run:  .venv/bin/python benchmarks/hologram_twin.py [--skip-large]
"""

from __future__ import annotations

import argparse
import time

from holoprobe.geometry import SourceGeometry
from holoprobe.simulate import simulate_hologram

CASES = [
    ("40 mm bowl, 1 MHz, CW 61x61 (+power truth)", SourceGeometry(
        "spherical-cap", 40e-3, 40e-3, 40e-3), {"shape": (61, 61), "power": True}),
    ("40 mm bowl, 1 MHz, CW 61x61", SourceGeometry(
        "spherical-cap", 40e-3, 40e-3, 40e-3), {"shape": (61, 61), "power": False}),
    ("40 mm bowl, 1 MHz, transient 61x61, 5 cycles", SourceGeometry(
        "spherical-cap", 40e-3, 40e-3, 40e-3),
     {"shape": (61, 61), "signal": "transient", "power": False}),
    ("87 mm bowl, R 87 mm, 1.25 MHz, CW 171x171", SourceGeometry(
        "spherical-cap", 87e-3, 87e-3, 87e-3),
     {"shape": (171, 171), "frequency": 1.25e6, "step": (0.5e-3, 0.5e-3), "power": False,
      "z_position": 30e-3}),
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-large", action="store_true")
    args = parser.parse_args()
    small = SourceGeometry("flat-disc", 5e-3, 5e-3)
    simulate_hologram(small, shape=(3, 3))                       # compile
    simulate_hologram(small, shape=(3, 3), signal="transient", power=False)
    print(f"{'case':<50} {'source points':>13} {'time (s)':>9}")
    for name, geometry, kwargs in CASES:
        if args.skip_large and "171" in name:
            continue
        t0 = time.perf_counter()
        _, truth = simulate_hologram(geometry, **kwargs)
        dt = time.perf_counter() - t0
        print(f"{name:<50} {truth.parameters['synthesis']['points']:>13} {dt:>9.2f}")


if __name__ == "__main__":
    main()
