"""Benchmark: CPU time of the report's PNG figures, ``savefig`` vs one Agg draw (issue 14).

Characterizes the reduced P4-1 twin of the test suite (16 elements, 9.6 × 19.2 mm at
0.15 mm, 192 samples; cached in ``--cache``), then renders the figures of its
``report.html`` (:func:`holoprobe.workflow.report_figures`, fresh figures each round)
with ``Figure.savefig`` (which draws a constrained-layout figure twice: once with drawing
disabled, to lay it out, then again; the report's figures have fixed margins since
session 12, so both draw once) and with the report's own one-draw renderer, checks
that both give the same bytes (same zlib level) and prints the CPU seconds of each round.

    .venv/bin/python benchmarks/report_figures.py [--rounds 5] [--cache FILE]
"""

from __future__ import annotations

import argparse
import io
import os
import pickle
import time
from pathlib import Path


def _twin_result(cache: Path):
    if cache.exists():
        with cache.open("rb") as fh:
            return pickle.load(fh)
    from holoprobe.characterize import characterize_transmit
    from holoprobe.geometry import Pose
    from holoprobe.simulate import ArrayModel, simulate_scan

    model = ArrayModel.from_preset("p4-1", element_count=16)
    pose = Pose.from_degrees(0.5, -0.8, 0.6, (0.1e-3, -0.05e-3, 3.5e-3))
    scan, _ = simulate_scan(model, pose=pose, size=(9.6e-3, 19.2e-3), n_samples=192,
                            snr_db=40.0, seed=1)
    result = characterize_transmit(scan, progress=False)
    with cache.open("wb") as fh:
        pickle.dump(result, fh)
    return result


def _savefig_png(fig, dpi: float) -> bytes:
    from holoprobe._png import PNG_COMPRESS_LEVEL

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, metadata={"Software": None},
                facecolor="white", pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
    return buf.getvalue()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--cache", default="/tmp/holoprobe_report_twin.pkl")
    args = parser.parse_args()
    from holoprobe.report._html import _png_bytes
    from holoprobe.workflow import report_figures

    result = _twin_result(Path(args.cache))

    def figures():
        return [e[0] if isinstance(e, tuple) else e
                for _, entries in report_figures(result) for e in entries]

    for fig in figures():  # warm the font caches
        _png_bytes(fig, 110)
    print(f"load {os.getloadavg()[0]:.1f}")
    print("| round | figures | savefig (s CPU) | one draw (s CPU) | same bytes |")
    print("|---:|---:|---:|---:|---|")
    for k in range(args.rounds):
        old, new = figures(), figures()
        t0 = time.process_time()
        a = [_savefig_png(f, 110) for f in old]
        t1 = time.process_time()
        b = [_png_bytes(f, 110) for f in new]
        t2 = time.process_time()
        print(f"| {k} | {len(old)} | {t1 - t0:.2f} | {t2 - t1:.2f} | {a == b} |")
    print(f"load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
