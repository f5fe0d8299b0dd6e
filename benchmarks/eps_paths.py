"""backprojection.eps 1e-4 vs 1e-6 on the paths besides the full-size flat transmit.

Usage: PYTHONPATH=src python benchmarks/eps_paths.py {convex,convex-flat,flat,matrix}

Each twin is characterized twice in one process (``backprojection.eps`` = 1e-4 and 1e-6)
and every reported value that has an uncertainty is compared: the table lists, per
quantity, the largest |value(1e-4) − value(1e-6)| / σ(1e-4). Twins: ``convex`` the 32-element
C5-2-like twin of convex_receive.py (transmit + receive, H 6 mm, F 30 mm, plate 20 mm at
2°), ``convex-flat`` the same with ``convex.window_model = "flat"``, ``flat`` the reduced
16-element and the worn 24-element P4-1 twins of no_change.py (the latter with its
receive), ``matrix`` the 8 × 8 twin of matrix.py (transmit). 2–5 min CPU each. Asserts
nothing; RESULTS.md "backprojection.eps 1e-4 vs 1e-6 off the full-size flat case".
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from no_change import flat_twins, flatten

EPS = ("1e-4", "1e-6")


def convex(extra: list[str]) -> dict[str, dict]:
    from convex import convex_model
    from convex_receive import receive_ir
    from holoprobe.characterize import (
        CharacterizationConfig,
        ConvexFace,
        characterize_convex_receive,
        characterize_convex_transmit,
    )
    from holoprobe.geometry import Pose
    from holoprobe.simulate import simulate_echo, simulate_scan

    model = convex_model(32, 1, 6e-3, 30e-3)
    model = model.replace(receive_ir=receive_ir(model.ir_sampling_rate))
    model = model.with_element_variation(receive_gain_rms=0.05, seed=8)
    pose = Pose.from_degrees(0.35, -0.6, 0.8, (0.2e-3, -0.15e-3, 6e-3))
    d, band = 20e-3, (1.5e6, 5.5e6)
    scan, _ = simulate_scan(model, pose=pose, size=(26e-3, 12e-3), step=(0.2e-3,) * 2,
                            sampling_rate=25e6, n_samples=512, snr_db=40, seed=1, band=band)
    echo, _ = simulate_echo(model, plate_distance=d, virtual_tilt=math.radians(2.0),
                            back_wall=True, plate_thickness=6e-3, snr_db=40, seed=2, band=band,
                            start_time=2 * d / 1481.0 - 6e-6, n_samples=1000)
    recs = {}
    for eps in EPS:
        cfg = CharacterizationConfig().with_overrides([f"backprojection.eps={eps}", *extra])
        c = time.process_time()
        tx = characterize_convex_transmit(scan, cfg, radius_of_curvature=50.5e-3,
                                          progress=False)
        rx = characterize_convex_receive(echo, ConvexFace.from_transmit(tx), scan, cfg,
                                         progress=False)
        out: dict = {}
        flatten(tx, "tx", out)
        flatten(rx, "rx", out)
        recs[eps] = out
        print(f"eps {eps}: {time.process_time() - c:.1f} s CPU", flush=True)
    return recs


def flat() -> dict[str, dict]:
    from holoprobe.characterize import (
        CharacterizationConfig,
        characterize_receive,
        characterize_transmit,
    )
    from holoprobe.workflow import summary_dict

    scan, wscan, echo = flat_twins()
    recs = {}
    for eps in EPS:
        cfg = CharacterizationConfig().with_overrides([f"backprojection.eps={eps}"])
        out: dict = {}
        flatten(summary_dict(characterize_transmit(scan, cfg, progress=False)), "reduced",
                out)
        wcfg = cfg.with_overrides(["onset.bootstrap=0"])
        wtx = characterize_transmit(wscan, wcfg, progress=False)
        wrx = characterize_receive(echo, wtx, wscan, wcfg, progress=False)
        flatten(summary_dict(wtx, wrx), "worn", out)
        flatten(wrx, "worn_receive", out)
        recs[eps] = out
    return recs


def matrix() -> dict[str, dict]:
    from holoprobe.characterize import CharacterizationConfig, characterize_transmit
    from holoprobe.workflow import summary_dict
    from matrix import simulate

    _, _, scan, _, _ = simulate(8, 1, Path("/tmp/holoprobe_matrix"))
    recs = {}
    for eps in EPS:
        cfg = CharacterizationConfig().with_overrides([f"backprojection.eps={eps}"])
        tx = characterize_transmit(scan, cfg, progress=False)
        out: dict = {}
        flatten(summary_dict(tx), "summary", out)
        flatten(tx, "tx", out)
        recs[eps] = out
    return recs


def shifts(recs: dict[str, dict]) -> dict[str, float]:
    """Per quantity: max |Δvalue| / σ, pairing ``X.uncertainty.Y`` with ``X.Y`` and
    ``Z_uncertainty`` with ``Z``."""
    a, b = recs[EPS[0]], recs[EPS[1]]
    rows: dict[str, float] = {}
    for key, sigma in a.items():
        if ".uncertainty." in key:
            base = key.replace(".uncertainty.", ".", 1)
        elif key.endswith("_uncertainty"):
            base = key[: -len("_uncertainty")]
        else:
            continue
        try:
            va, vb, sg = (np.asarray(x, float) for x in (a[base], b[base], sigma))
        except (KeyError, TypeError, ValueError):
            continue
        if va.shape != vb.shape or sg.shape not in ((), va.shape):
            continue
        with np.errstate(all="ignore"):
            q = np.abs(va - vb) / sg
        q = q[np.isfinite(q)]
        if q.size:
            group = base.split("[")[0]
            rows[group] = max(rows.get(group, 0.0), float(q.max()))
    return rows


def main() -> None:
    which = sys.argv[1] if len(sys.argv) > 1 else "convex"
    recs = {"convex": lambda: convex([]),
            "convex-flat": lambda: convex(["convex.window_model=flat"]),
            "flat": flat, "matrix": matrix}[which]()
    print(f"| {which}: quantity | max shift / σ |\n|---|---|")
    for name, q in sorted(shifts(recs).items(), key=lambda x: -x[1])[:20]:
        print(f"| {name} | {q:.4f} |")


if __name__ == "__main__":
    main()
