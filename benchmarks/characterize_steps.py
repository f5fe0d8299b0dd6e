"""Benchmark: CPU time per step of ``holoprobe characterize`` in a cold process.

Wall time on a shared machine says little; the CPU time of each step (all threads of the
process, ``time.process_time``) is the comparable figure. This runs the CLI in this
process with the pipelines' step timer patched to record CPU time as well, and writes a
JSON record: ``import`` (the package, CLI and workflow modules), every step of the
transmit and receive pipelines as it ran (a step that runs once per pose iteration
appears once per pass), ``characterize`` (everything from reading the files to the
results), ``write`` (the output files and the report), ``total`` (user + system CPU of
the process) and ``maxrss_gib`` (peak resident memory).

    PYTHONPATH=src python benchmarks/characterize_steps.py record OUT.json SCAN [--receive ECHO] ...
    python benchmarks/characterize_steps.py table A.json [B.json ...]

Everything after ``record OUT.json`` is passed to ``holoprobe characterize`` (``--out``
defaults to a temporary folder, ``--overwrite --quiet`` are added). ``table`` prints
the steps summed over passes, one column per record. For the issue-14 full-size job see
``benchmarks/characterize_cli.py`` (it simulates the data).
"""

from __future__ import annotations

import json
import resource
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def record(out: Path, args: list[str]) -> None:
    """Run the CLI on ``args`` in this process and write the CPU record to ``out``."""
    t0 = time.process_time()
    import holoprobe.characterize._pipeline as pipeline
    import holoprobe.workflow as workflow
    import holoprobe.workflow._run as run
    from holoprobe.cli import main

    cpu: dict = {"import": time.process_time() - t0, "steps": []}

    @contextmanager
    def timed(self, name: str) -> Iterator[None]:  # the pipelines' _Timer, plus CPU
        start, c = time.perf_counter(), time.process_time()
        try:
            yield
        finally:
            self.times[name] = self.times.get(name, 0.0) + time.perf_counter() - start
            cpu["steps"].append((name, time.process_time() - c))

    def measured(key: str, func):
        def wrapper(*a, **k):
            c = time.process_time()
            try:
                return func(*a, **k)
            finally:
                cpu[key] = time.process_time() - c
        return wrapper

    pipeline._Timer.__call__ = timed  # type: ignore[method-assign]
    run.CharacterizationRun.save = measured("write", run.CharacterizationRun.save)
    workflow.characterize = measured("characterize", workflow.characterize)
    if "--out" not in args:
        args = [*args, "--out", tempfile.mkdtemp(prefix="holoprobe_steps_")]
    sys.argv = ["holoprobe", "characterize", *args, "--overwrite", "--quiet"]
    try:
        main()
    except SystemExit as exc:
        if exc.code:
            raise
    usage = resource.getrusage(resource.RUSAGE_SELF)
    cpu["total"] = usage.ru_utime + usage.ru_stime
    cpu["maxrss_gib"] = usage.ru_maxrss / 2**20
    out.write_text(json.dumps(cpu, indent=1))
    print(f"CPU {cpu['total']:.1f} s, peak RSS {cpu['maxrss_gib']:.2f} GiB -> {out}")


def _summed(path: Path) -> dict[str, float]:
    d = json.loads(path.read_text())
    rows: dict[str, float] = {"import": d["import"]}
    for name, c in d["steps"]:
        rows[name] = rows.get(name, 0.0) + c
    rows["read + rest"] = d["characterize"] - sum(c for _, c in d["steps"])
    rows["write"] = d.get("write", float("nan"))
    rows["total CPU"] = d["total"]
    rows["peak RSS (GiB)"] = d["maxrss_gib"]
    return rows


def table(paths: list[Path]) -> None:
    """Print the records side by side (CPU s per step)."""
    cols = [_summed(p) for p in paths]
    keys = list(dict.fromkeys(k for c in cols for k in c))
    print(f"{'step':<22}" + "".join(f"{p.stem[:12]:>13}" for p in paths))
    for k in keys:
        print(f"{k:<22}" + "".join(f"{c.get(k, float('nan')):>13.2f}" for c in cols))


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "record":
        record(Path(sys.argv[2]), sys.argv[3:])
    elif len(sys.argv) >= 3 and sys.argv[1] == "table":
        table([Path(p) for p in sys.argv[2:]])
    else:
        print(__doc__)
        sys.exit(2)
