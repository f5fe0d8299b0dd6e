"""Benchmark: CPU of every forward projection the receive characterization makes (issue 14).

Runs ``holoprobe characterize SCAN --receive ECHO …`` in this process (as
``characterize_steps.py record`` does: the steps' CPU is printed too) with
``SensorPredictor.band_pressure`` wrapped, and prints one row per projection onto the
virtual sensor: the step that asked for it (the first caller outside the predictor), its
band decimation D and bins, the CPU its plan spent transforming the scan
(``ProjectionPlan._transform``: 0 when the spectra were reused) and its whole CPU (all
threads, ``time.process_time``). The load of a shared machine inflates every figure;
compare runs made one after another.

    PYTHONPATH=src python benchmarks/receive_projections.py SCAN --receive ECHO [options]

For the issue-14 full-size job SCAN and ECHO are ``scan/scan.h5`` and ``echo/echo.h5``
of ``characterize_cli.py``'s data (RESULTS: "Issue 14 receive and report").
"""

from __future__ import annotations

import inspect
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

_INSIDE = {"band_pressure", "__call__", "timed", "wrapper", "counted"}


def _caller() -> str:
    """The first function on the stack outside the predictor and these wrappers."""
    for frame in inspect.stack()[2:8]:
        if frame.function not in _INSIDE:
            return frame.function
    return "?"


def main(args: list[str]) -> None:
    """Run the CLI on ``args`` and print the projections' table and the steps' CPU."""
    import characterize_steps
    import holoprobe.characterize._receive_pipeline as rp
    from holoprobe.propagation import ProjectionPlan

    rows: list[tuple[str, int, int, float, float]] = []
    spent = {"transform": 0.0}
    transform, band_pressure = ProjectionPlan._transform, rp.SensorPredictor.band_pressure

    def timed(self, *a, **k):  # a generator: time each step of it
        gen = transform(self, *a, **k)
        while True:
            c = time.process_time()
            try:
                item = next(gen)
            except StopIteration:
                spent["transform"] += time.process_time() - c
                return
            spent["transform"] += time.process_time() - c
            yield item

    def counted(self, receiver):
        c, t = time.process_time(), spent["transform"]
        try:
            return band_pressure(self, receiver)
        finally:
            rows.append((_caller(), int(self.decimation), int(self.selected.sum()),
                         spent["transform"] - t, time.process_time() - c))

    ProjectionPlan._transform = timed  # type: ignore[method-assign]
    rp.SensorPredictor.band_pressure = counted  # type: ignore[method-assign]
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "steps.json"
        characterize_steps.record(out, args)
        steps = json.loads(out.read_text())["steps"]
    print(f"{'projection asked by':<26}{'D':>3}{'bins':>6}{'transform (s)':>15}{'CPU (s)':>10}")
    for name, d, nb, tr, cpu in rows:
        print(f"{name:<26}{d:>3}{nb:>6}{tr:>15.3f}{cpu:>10.3f}")
    print(f"{'all projections':<26}{'':>9}{sum(r[3] for r in rows):>15.3f}"
          f"{sum(r[4] for r in rows):>10.3f}")
    receive = ("virtual_receiver", "reflection", "scan_spectrum", "forward_projection",
               "element_pressure", "receive_ir", "element_sensitivity")
    total = sum(c for n, c in steps if n in receive)
    print(f"receive steps: {total:.2f} s CPU (" + ", ".join(
        f"{n} {sum(c for m, c in steps if m == n):.2f}" for n in receive) + ")")


if __name__ == "__main__":
    if len(sys.argv) < 2 or "--receive" not in sys.argv:
        print(__doc__)
        sys.exit(2)
    main(sys.argv[1:])
