"""Benchmark: ``holoprobe characterize`` as a new user runs it (cold process, files in, files out).

The full-size job of issue 14: a simulated P4-1 scan of 241 × 161 points × 850 samples
(``holoprobe simulate scan --n-samples 850``) and its reflector echo (96 × ~4800
samples, ``holoprobe simulate receive``), both cached in ``--data`` (first run: a few
minutes of simulation). Runs ``holoprobe characterize`` transmit-only and with
``--receive`` in fresh processes, ``--repeat`` times each, and prints wall time, CPU
time (user + system: what the job costs regardless of other load) and peak RSS, with
the step timings the run records in summary.json. The load average is printed with
each run: on a shared machine compare runs taken under the same load only.

    .venv/bin/python benchmarks/characterize_cli.py [--data /tmp/holoprobe_bench_cli]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path


def _run(args: list[str]) -> tuple[float, float, float]:
    """Wall s, CPU s (children user + system) and peak RSS GiB of one command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, after.ru_maxrss / 2**20


def _data(folder: Path) -> tuple[Path, Path]:
    scan, echo = folder / "scan" / "scan.h5", folder / "echo" / "echo.h5"
    cli = [sys.executable, "-m", "holoprobe", "simulate"]
    if not scan.exists():
        subprocess.run([*cli, "scan", "--out", str(scan.parent), "--n-samples", "850",
                        "--quiet"], check=True)
    if not echo.exists():
        subprocess.run([*cli, "receive", "--out", str(echo.parent), "--quiet"], check=True)
    return scan, echo


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--data", default="/tmp/holoprobe_bench_cli")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--no-receive", action="store_true")
    parser.add_argument("--no-report", action="store_true",
                        help="also time each job with --no-report (no report.html)")
    args = parser.parse_args()
    data = Path(args.data)
    scan, echo = _data(data)
    out = data / "out"
    jobs = [("transmit", [])] + ([] if args.no_receive else
                                 [("transmit + receive", ["--receive", str(echo)])])
    if args.no_report:
        jobs += [(f"{name} --no-report", [*extra, "--no-report"]) for name, extra in jobs]
    print(f"{'job':<32}{'load':>7}{'wall (s)':>10}{'CPU (s)':>9}{'peak RSS (GiB)':>16}")
    for _ in range(args.repeat):
        for name, extra in jobs:
            load = os.getloadavg()[0]
            wall, cpu, rss = _run([sys.executable, "-m", "holoprobe", "characterize",
                                   str(scan), "--out", str(out), "--overwrite", "--quiet",
                                   *extra])
            print(f"{name:<32}{load:>7.1f}{wall:>10.1f}{cpu:>9.1f}{rss:>16.2f}")
            summary = json.loads((out / "summary.json").read_text())
            steps = {}
            for section in ("timings", "receive"):
                part = summary.get(section, {})
                steps.update(part.get("timings", {}) if section == "receive" else part)
            print("   steps (s): " + ", ".join(f"{k} {v:.2f}" for k, v in steps.items()
                                             if isinstance(v, int | float)))


if __name__ == "__main__":
    main()
