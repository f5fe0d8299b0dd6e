"""Record every number a characterization produces, and compare two records bit for bit.

For a change that must not change results (a refactoring, a move, a split): record with
the code before, record with the code after, compare.

    PYTHONPATH=src python benchmarks/no_change.py record before.pkl   # old code
    PYTHONPATH=src python benchmarks/no_change.py record after.pkl    # new code
    python benchmarks/no_change.py compare before.pkl after.pkl

The runs: the reduced 16-element P4-1 twin of ``tests/conftest.py`` (default
configuration, with its ``summary.json`` tree), and the 24-element worn twin of
``tests/characterize/test_elements.py`` (dead elements, jitter, a warmer tank) with its
receive characterization from a simulated echo, and three hologram twins (CW bowl,
transient bowl, noisy flat disc; :func:`record_holograms`). Every array and scalar of the
``TransmitResult``/``ReceiveResult`` (timings and the config excepted) is kept; the
comparison reports each value that differs (``np.array_equal``, NaN equal to NaN) with
its largest relative difference. About 3 min of CPU. The records are pickles: compare
only files you wrote.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import pickle
from pathlib import Path

import numpy as np


def flatten(obj, prefix: str, out: dict, depth: int = 0) -> None:
    """Every number, string and array below ``obj`` under a dotted name."""
    if depth > 6:
        return
    if isinstance(obj, bool | int | float | complex | str | type(None) | np.generic):
        out[prefix] = obj
    elif isinstance(obj, np.ndarray):
        out[prefix] = obj.copy()
    elif isinstance(obj, dict):
        for k, v in obj.items():
            if "timing" not in str(k):
                flatten(v, f"{prefix}.{k}", out, depth + 1)
    elif isinstance(obj, list | tuple):
        for i, v in enumerate(obj):
            flatten(v, f"{prefix}[{i}]", out, depth + 1)
    elif dataclasses.is_dataclass(obj):
        for f in dataclasses.fields(obj):
            if f.name not in ("timings", "config"):
                flatten(getattr(obj, f.name), f"{prefix}.{f.name}", out, depth + 1)
    else:
        for name in ("x", "y", "rotation", "origin"):
            if hasattr(obj, name):
                flatten(np.asarray(getattr(obj, name)), f"{prefix}.{name}", out, depth + 1)
        out[prefix + ".type"] = type(obj).__name__


def flat_twins():
    """The reduced 16-element P4-1 scan, the worn 24-element scan and its echo (module
    doc)."""
    from holoprobe.geometry import Medium, Pose
    from holoprobe.simulate import ArrayModel, simulate_echo, simulate_scan

    pose = Pose.from_degrees(0.5, -0.8, 0.6, (0.1e-3, -0.05e-3, 3.5e-3))
    model = ArrayModel.from_preset("p4-1", element_count=16)
    scan, _ = simulate_scan(model, pose=pose, size=(9.6e-3, 19.2e-3), n_samples=192,
                            snr_db=40.0, seed=1)
    worn = ArrayModel.from_preset("p4-1", element_count=24).with_element_variation(
        amplitude_rms=0.05, delay_rms=8e-9, receive_gain_rms=0.05, dead=[0, 9], seed=2)
    wscan, _ = simulate_scan(worn, pose=pose, size=(12e-3, 19.2e-3), n_samples=192,
                             snr_db=40.0, seed=1, position_jitter=4e-6,
                             medium=Medium(sound_speed=1487.0),
                             recorded_medium=Medium(sound_speed=1481.0))
    echo, _ = simulate_echo(worn, plate_distance=20e-3, virtual_tilt=math.radians(2.0),
                            snr_db=40.0, seed=3, band=(1e6, 4e6), points_per_wavelength=3.0,
                            start_time=20e-6, n_samples=1200)
    return scan, wscan, echo


def record(path: Path) -> None:
    from holoprobe.characterize import (
        CharacterizationConfig,
        characterize_receive,
        characterize_transmit,
    )
    from holoprobe.workflow import summary_dict

    out: dict = {}
    scan, wscan, echo = flat_twins()
    tx = characterize_transmit(scan, progress=False)
    flatten(tx, "reduced", out)
    flatten(summary_dict(tx), "reduced_summary", out)
    wtx = characterize_transmit(wscan, CharacterizationConfig().with_overrides(
        ["onset.bootstrap=0"]), progress=False)
    flatten(wtx, "worn", out)
    wrx = characterize_receive(echo, wtx, wscan, progress=False)
    flatten(wrx, "worn_receive", out)
    flatten(summary_dict(wtx, wrx), "worn_summary", out)
    record_holograms(out)
    path.write_bytes(pickle.dumps(out))
    print(f"{len(out)} values -> {path}")


def record_holograms(out: dict) -> None:
    """Three hologram twins through ``characterize_hologram``: a tilted, offset CW bowl
    (49 × 49, the pair of tests/characterize/test_characterize_hologram_simulate.py), the
    same bowl as a 20-cycle transient, and a noisy flat disc (the flat path with its
    recentring fits)."""
    from holoprobe.characterize import HologramConfig, characterize_hologram, hologram_summary
    from holoprobe.geometry import SourceGeometry
    from holoprobe.simulate import simulate_hologram

    cfg = HologramConfig(monte_carlo=0)
    bowl = SourceGeometry("spherical-cap", 0.02, 0.02, 0.03)
    pose = dict(z_position=0.018, tilt=(0.01, -0.02), offset=(0.5e-3, -0.3e-3), shape=(49, 49))
    twins = {
        "hologram_cw": simulate_hologram(bowl, frequency=1e6, power=False, **pose)[0],
        "hologram_transient": simulate_hologram(bowl, frequency=1e6, signal="transient",
                                                cycles=20, power=False, band_db=-30,
                                                **pose)[0],
        "hologram_disc": simulate_hologram(SourceGeometry("flat-disc", 20e-3, 20e-3),
                                           shape=(21, 21), snr_db=30.0, seed=3)[0],
    }
    for name, hologram in twins.items():
        result = characterize_hologram(hologram, cfg)
        flatten(dataclasses.replace(result, hologram=None), name, out)
        flatten(hologram_summary(result), name + "_summary", out)


def compare(a_path: Path, b_path: Path) -> int:
    a, b = pickle.loads(a_path.read_bytes()), pickle.loads(b_path.read_bytes())
    differ = 0
    for key in sorted(set(a) | set(b)):
        if key not in a or key not in b:
            print(f"only in {'the first' if key in a else 'the second'}: {key}")
            differ += 1
            continue
        x, y = a[key], b[key]
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            x, y = np.asarray(x), np.asarray(y)
            if x.shape != y.shape or x.dtype != y.dtype:
                print(f"{key}: shape/dtype {x.shape} {x.dtype} vs {y.shape} {y.dtype}")
                differ += 1
            elif not np.array_equal(x, y, equal_nan=x.dtype.kind in "fc"):
                scale = max(float(np.nanmax(np.abs(x))), 1e-300) if x.dtype.kind in "fc" else 1
                rel = (float(np.nanmax(np.abs(x - y))) / scale if x.dtype.kind in "fc"
                       else float("nan"))
                print(f"{key}: differs (max relative {rel:.3g})")
                differ += 1
        elif not (x == y or (isinstance(x, float) and isinstance(y, float)
                             and math.isnan(x) and math.isnan(y))):
            print(f"{key}: {x!r} vs {y!r}")
            differ += 1
    print(f"{len(a)} values compared, {differ} differ")
    return differ


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("record").add_argument("out", type=Path)
    cmp_ = sub.add_parser("compare")
    cmp_.add_argument("a", type=Path)
    cmp_.add_argument("b", type=Path)
    args = parser.parse_args()
    if args.command == "record":
        record(args.out)
    else:
        raise SystemExit(1 if compare(args.a, args.b) else 0)


if __name__ == "__main__":
    main()
