"""Run every benchmark of holoprobe in turn (``make bench``); each prints its own table.

Figures are recorded by hand in ``benchmarks/RESULTS.md`` with the machine and date.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
SCRIPTS = ["propagation.py", "simulate.py", "pipeline.py", "acceptance_field.py",
           "characterize_cli.py", "field_points.py", "table_fields.py", "sequence_fields.py",
           "dask_fields.py"]


def main() -> int:
    status = 0
    for name in SCRIPTS:
        script = HERE / name
        if not script.exists():
            print(f"(skipping {name}: not present)")
            continue
        print(f"\n=== {name} ===", flush=True)
        status |= subprocess.call([sys.executable, str(script), *sys.argv[1:]])
    return status


if __name__ == "__main__":
    raise SystemExit(main())
