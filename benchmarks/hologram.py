"""Benchmark: characterization of single-element sources from holograms (issue 13).

Cases (twins from :func:`holoprobe.simulate.simulate_hologram`, dense Rayleigh from a
Gauss-Legendre ring quadrature, cached under ``--cache`` so that only the characterization
is timed):

* ``cw171``: an 87 mm bowl (R = 87 mm) at 1.25 MHz, 171 × 171 CW hologram at 0.5 mm,
  30 mm from the apex, tilted (0.5°, −0.3°) and offset (1.2, −0.8) mm, 40 dB SNR;
* ``tr200``: the same bowl, 200 × 200 × 1000 transient hologram (5-cycle burst,
  10 MHz sampling).

Prints wall and CPU seconds of :func:`holoprobe.characterize.characterize_hologram`
(alignment, back-projection, power, focal field; uncertainties included) per step, and the
errors against the twin's truth. Times are printed, never asserted; say in RESULTS.md how
loaded the machine was.

Transient cases also print which bins were back-projected onto the surface (``band``:
``hologram.band_decimation``, 0 = from the data; ``--band-decimation 1`` = every bin of
the record, the path before the shortened record).

Run:  .venv/bin/python benchmarks/hologram.py [--case cw171|tr200|all] [--cache DIR]
      [--band-decimation D]
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from holoprobe.characterize import HologramConfig, characterize_hologram, hologram_summary
from holoprobe.geometry import SourceGeometry
from holoprobe.io import read_hologram, write_hologram
from holoprobe.simulate import simulate_hologram

BOWL = SourceGeometry("spherical-cap", 87e-3, 87e-3, 87e-3)
POSE = {"z_position": 30e-3, "tilt": (np.deg2rad(0.5), np.deg2rad(-0.3)),
        "offset": (1.2e-3, -0.8e-3), "snr_db": 40.0}
CASES = {
    "cw171": {"frequency": 1.25e6, "shape": (171, 171), "step": (0.5e-3, 0.5e-3)},
    # the transient twin is synthesised on a coarser quadrature than the default λ/4 at
    # the band top (0.22 mm) to keep its dense sum affordable: 0.3 mm puts the field
    # within 1.5e-4 (rms, relative) of a 0.15 mm quadrature's at 1.25 MHz and 1.6e-2 at
    # the −30 dB band top (1.71 MHz). The 0.6 mm used before session 9 was off by 4.8 % and
    # 21 %: its own error gave a 3.3 % surface-velocity error on a noise-free CW twin
    "tr200": {"frequency": 1.25e6, "shape": (200, 200), "step": (0.5e-3, 0.5e-3),
              "signal": "transient", "cycles": 5, "sampling_rate": 10e6, "band_db": -30.0,
              "spacing": 0.3e-3},
}


def _twin(name: str, cache: Path):
    path, truth_path = cache / f"{name}.h5", cache / f"{name}_truth.json"
    if path.exists() and truth_path.exists():
        return read_hologram(path), json.loads(truth_path.read_text())
    t0 = time.perf_counter()
    holo, truth = simulate_hologram(BOWL, power=name == "cw171", **POSE, **CASES[name])
    print(f"  (twin {name} synthesised in {time.perf_counter() - t0:.1f} s)")
    cache.mkdir(parents=True, exist_ok=True)
    write_hologram(path, holo, overwrite=True)
    truth_path.write_text(json.dumps(truth.parameters, default=float))
    return holo, truth.parameters


def _errors(summary: dict, truth: dict) -> dict[str, float]:
    axis = np.array(summary["alignment"]["axis_direction"])
    t_axis = np.array(truth["alignment"]["axis_direction"])
    out = {
        "axis error (deg)": float(np.degrees(np.arccos(np.clip(axis @ t_axis, -1, 1)))),
        "axis u (deg)": summary["uncertainty"]["axis_direction_deg"],
        "apex error (um)": float(np.linalg.norm(np.array(summary["alignment"]["source_apex"])
                                                - truth["alignment"]["apex_position"]) * 1e6),
        "R error (%)": 100 * (summary["source"]["radius_of_curvature"]
                              / truth["source"]["radius_of_curvature"] - 1),
        "aperture error (mm)": 1e3 * (summary["source"]["aperture_diameter"]
                                      - truth["source"]["aperture_diameter"]),
        "surface vs hologram power (%)": 100 * summary["acoustic_power"]["relative_difference"],
    }
    power = (truth.get("acoustic_power") or {}).get("scan_window")
    if power and summary["frequency"] == truth["frequency_hz"]:
        measured = summary["acoustic_power"]["hologram"]
        out["hologram power vs truth in the scan window (%)"] = 100 * (measured / power - 1)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="cw171", choices=[*CASES, "all"])
    parser.add_argument("--cache", type=Path, default=Path(os.environ.get(
        "HOLOPROBE_BENCH_CACHE", "/tmp/holoprobe-bench")))
    parser.add_argument("--band-decimation", type=int, default=0,
                        help="hologram.band_decimation (0: from the data; 1: every bin)")
    args = parser.parse_args()
    cfg = HologramConfig(band_decimation=args.band_decimation)
    warm, _ = simulate_hologram(SourceGeometry("spherical-cap", 10e-3, 10e-3, 12e-3),
                                shape=(31, 31), power=False)
    characterize_hologram(warm)  # compile and import everything once
    for name in (CASES if args.case == "all" else [args.case]):
        holo, truth = _twin(name, args.cache)
        t0, c0 = time.perf_counter(), time.process_time()
        result = characterize_hologram(holo, cfg)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        print(f"{name}: {holo.pressure.shape}, wall {wall:.2f} s, CPU {cpu:.2f} s, "
              f"load average {os.getloadavg()[0]:.1f}")
        for step, seconds in result.timings.items():
            print(f"  {step:<22} {seconds:8.2f} s")
        summary = hologram_summary(result)
        for key, value in _errors(summary, truth).items():
            print(f"  {key:<32} {value: .4g}")
        if "band" in summary:
            print(f"  band (surface)                   {summary['band']}")
            print(f"  surface power (W)                {summary['acoustic_power']['surface']:.6g}")


if __name__ == "__main__":
    main()
