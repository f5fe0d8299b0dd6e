"""Benchmark: do the hologram uncertainties cover the errors? (issue 13, held-out twins)

Bowls of three sizes, poses, frequencies and noise levels (none of them the tests'),
synthesised by :func:`holoprobe.simulate.simulate_hologram` (dense Rayleigh, rings
quadrature) and characterized with the default settings (plus ``--apex`` for the data
apex). Prints, per twin, the error against the truth and the reported standard
uncertainty of the focal maximum (each coordinate), the aperture and, with ``--apex``, the
apex along the axis from the data. Twins are cached under ``--cache``.

``--spread N`` measures the noise floor instead: each noisy twin's noise-free twin gets N
fresh noise realisations (the simulator's definition: complex white noise, σ from the
peak SNR) and only the alignment is run; it prints the mean error (the bias), the spread
of the errors over the draws (what noise alone does to one measurement), the mean
reported σ, and the axis error's RMS against the mean reported axis uncertainty.

``--full`` runs each draw through ``characterize_hologram`` (the window's bias modelled on
the placed source and removed, :func:`holoprobe.characterize.correct_window_bias`).

Run:  .venv/bin/python benchmarks/hologram_coverage.py [--apex] [--spread N [--full]]
          [--cache DIR] [--monte-carlo N] [--only NAME-PART]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import pickle
from pathlib import Path

import numpy as np

from holoprobe.characterize import (
    HologramConfig,
    align_focused,
    characterize_hologram,
    hologram_grid,
    hologram_noise_level,
    hologram_summary,
    rim_capture_angle,
)
from holoprobe.geometry import SourceGeometry
from holoprobe.simulate import noise_std_for_snr, simulate_hologram

# name: aperture, R (m), frequency (Hz), z (m), tilt (deg), offset (m), shape, SNR (dB), seed
TWINS = {
    "40/R40 61² 40 dB s0": (0.04, 0.04, 1e6, 0.02, (0.8, -0.5), (1e-3, -0.5e-3), 61, 40, 0),
    "40/R40 61² 40 dB s1": (0.04, 0.04, 1e6, 0.02, (0.8, -0.5), (1e-3, -0.5e-3), 61, 40, 1),
    "40/R40 61² 40 dB s2": (0.04, 0.04, 1e6, 0.02, (0.8, -0.5), (1e-3, -0.5e-3), 61, 40, 2),
    "40/R40 61² no noise": (0.04, 0.04, 1e6, 0.02, (0.8, -0.5), (1e-3, -0.5e-3), 61, None, 0),
    "40/R40 101² no noise": (0.04, 0.04, 1e6, 0.02, (0.8, -0.5), (1e-3, -0.5e-3), 101, None, 0),
    "30/R45 1.5 MHz 71² 30 dB": (0.03, 0.045, 1.5e6, 0.025, (-1.2, 0.6), (-0.7e-3, 0.4e-3),
                                 71, 30, 3),
    "30/R45 1.5 MHz 71² no noise": (0.03, 0.045, 1.5e6, 0.025, (-1.2, 0.6),
                                    (-0.7e-3, 0.4e-3), 71, None, 3),
    "50/R60 0.8 MHz 61² 35 dB": (0.05, 0.06, 0.8e6, 0.03, (0.3, 1.5), (0.3e-3, 1.2e-3), 61,
                                 35, 5),
}


def _twin(name: str, cache: Path, *, clean: bool = False):
    stem = name.replace(" ", "_").replace("/", "-").replace("²", "")
    path = cache / (stem + ("_clean" if clean else "") + ".pkl")
    if path.exists():
        return pickle.loads(path.read_bytes())
    ap, r, f, z, tilt, offset, n, snr, seed = TWINS[name]
    snr = None if clean else snr
    holo, truth = simulate_hologram(SourceGeometry("spherical-cap", ap, ap, r), frequency=f,
                                    z_position=z, tilt=tuple(np.deg2rad(tilt)), offset=offset,
                                    shape=(n, n), snr_db=snr, seed=seed, power=False)
    cache.mkdir(parents=True, exist_ok=True)
    path.write_bytes(pickle.dumps((holo, truth.parameters)))
    return holo, truth.parameters


def _spread(name: str, cache: Path, draws: int, cfg: HologramConfig, full: bool = False
            ) -> None:
    """Alignment errors over ``draws`` noise realisations added to the noise-free twin
    (``full``: each draw through ``characterize_hologram``, else ``align_focused`` alone,
    whose window term is then |untapered − tapered|)."""
    holo, truth = _twin(name, cache, clean=True)
    snr, radius = TWINS[name][7], TWINS[name][1]
    grid, p3 = hologram_grid(holo.grid.x, holo.grid.y, holo.pressure)
    clean = p3[:, :, 0]
    sigma = noise_std_for_snr(clean, snr)
    k = float(holo.medium.wavenumber(holo.frequency))
    focus, axis = (np.array(truth["alignment"][key]) for key in ("focus_position",
                                                                 "axis_direction"))
    errors, sigmas, axis_err, axis_u = [], [], [], []
    for seed in range(draws):
        rng = np.random.default_rng(1000 + seed)
        noise = rng.standard_normal(clean.shape) + 1j * rng.standard_normal(clean.shape)
        p = clean + sigma / np.sqrt(2) * noise
        if full:   # the whole pipeline: the window's bias is modelled on the placed source
            noisy = dataclasses.replace(holo, pressure=p)   # same grid order (increasing)
            al = characterize_hologram(noisy, cfg).alignment
        else:
            al = align_focused(p, grid, holo.frequency, holo.medium,
                               search_span=(-0.9 * holo.z_position, 2 * radius), cfg=cfg,
                               noise_level=hologram_noise_level(p, grid.dx, grid.dy, k))
        errors.append(1e6 * (al.focus - focus))
        sigmas.append(1e6 * al.focus_uncertainty)
        axis_err.append(np.degrees(np.arccos(np.clip(al.axis @ axis, -1.0, 1.0))))
        axis_u.append(np.degrees(al.axis_uncertainty))
    e = np.array(errors)
    print(f"{name} | {draws} | {np.round(e.mean(axis=0), 1)} | "
          f"{np.round(e.std(axis=0, ddof=1), 1)} | {np.round(np.mean(sigmas, axis=0), 1)} | "
          f"{np.sqrt(np.mean(np.square(axis_err))):.4f} | {np.mean(axis_u):.4f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--apex", action="store_true", help="also the data apex")
    parser.add_argument("--spread", type=int, default=0, metavar="N",
                        help="noise floor: N noise draws on each noisy twin's clean twin")
    parser.add_argument("--full", action="store_true",
                        help="--spread through the whole characterization (the window model)")
    parser.add_argument("--cache", type=Path, default=Path(os.environ.get(
        "HOLOPROBE_BENCH_CACHE", "/tmp/holoprobe-bench")) / "coverage")
    parser.add_argument("--monte-carlo", type=int, default=0, metavar="N",
                        help="hologram.monte_carlo (0, the default: linear noise propagation)")
    parser.add_argument("--only", default="", help="only the twins whose name holds this")
    args = parser.parse_args()
    cfg = HologramConfig(fit_apex=args.apex, monte_carlo=args.monte_carlo)
    if args.spread:
        print("twin | draws | mean focus error (µm, x y z) | spread of the error | mean σ | "
              "axis error RMS (°) | mean axis u (°)")
        done = set()
        for name, params in TWINS.items():  # one per noise level
            if params[7] is not None and params[:8] not in done and args.only in name:
                done.add(params[:8])
                _spread(name, args.cache, args.spread, cfg, args.full)
        return
    print("twin | focus error (µm, x y z) | focus σ | aperture error (µm) | σ"
          + (" | rim capture angle | data apex error along the axis (µm) | σ" if args.apex
             else ""))
    for name in (n for n in TWINS if args.only in n):
        holo, truth = _twin(name, args.cache)
        result = characterize_hologram(holo, cfg)
        s = hologram_summary(result)
        al = result.alignment
        err = 1e6 * (al.focus - np.array(truth["alignment"]["focus_position"]))
        rec = result.reconstruction
        ap = 1e6 * (rec.geometry.aperture[0] - truth["source"]["aperture_diameter"])
        row = [name, np.round(err, 1), np.round(1e6 * al.focus_uncertainty, 1),
               f"{ap:.1f}", f"{1e6 * rec.aperture_uncertainty:.1f}"]
        if args.apex:
            row.append(f"rim seen {np.degrees(rim_capture_angle(rec.geometry, result.grid)):.1f}°")
        if args.apex and s["alignment"]["source_apex_from_data"] is not None:
            apex = (np.array(s["alignment"]["source_apex_from_data"])
                    - truth["alignment"]["apex_position"]) @ rec.geometry.axis
            row += [f"{1e6 * apex:.1f}",
                    f"{1e6 * s['uncertainty']['source_apex_from_data_along_axis']:.1f}"]
        print(" | ".join(str(v) for v in row), flush=True)


if __name__ == "__main__":
    main()
