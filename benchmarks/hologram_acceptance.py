"""Benchmark: issue 13's acceptance lines, measured on hologram twins (one table).

Twins from :func:`holoprobe.simulate.simulate_hologram` (dense Rayleigh from a
Gauss-Legendre ring / cell quadrature; the estimator back-projects onto a Cartesian grid
with plane-wave sums: no inverse crime), with tilt and offset, cached noise-free under
``--cache``: bowls (uniform, with a central opening, segmented with a weak segment, with a
dead sector and a phase defect), a transient bowl, a flat disc and a flat rectangle; each
gets its own noise draw (40 dB peak SNR, seed = its index) and is characterized with the
default settings (``characterize_hologram``), and so is its noise-free twin (the method's
own error, below the noise floor); with ``--large`` also the cached 171² CW and 200²
transient twins of ``benchmarks/hologram.py``. Compared with the truth:

* axis: the focal-lobe axis against the truth's (focused), the source normal against the
  geometric axis (flat); ° (target 0.02°), with its reported σ;
* focus: |focal maximum − truth| (µm, target 20 µm), its z component and reported σ z;
* R (%, target 0.2 %) and its σ; aperture (mm, target 0.2 mm; a rectangle's worse side);
* power: surface vs hologram (%, target 1 %), hologram vs the twin's true power through
  the scan window (%);
* velocity: ‖v − v_true‖ / ‖v_true‖ on the reconstructed surface inside the aperture,
  leaving out nodes within one wavelength of an edge of the true velocity map (the rim,
  the opening, a sector or patch edge: a band-limited reconstruction cannot follow a step)
  (target 3 %), after one phase common to the whole surface (the piston k·δ of a
  placement δ along the normal: 7 µm at 1 MHz is 0.03 rad, i.e. 3 %) with the amplitude
  absolute (CW; transient: after one complex scale, the spectrum's); "with piston phase"
  is the CW figure without that phase removed;
* defects: the dead region's azimuth error (°), the phase defect's centre error (mm); a
  weak (−6 dB) segment is no dead region (``hologram.dead_ratio`` 0.3): its power
  direction off the lobe axis and that direction's error are shown instead.

Prints one block per twin with ``PASS``/``FAIL`` per target, then one markdown table.
Timings are printed, never asserted (issue targets cw171 ≤ 5 s, tr200 ≤ 30 s on 2 idle
cores: measure those with ``benchmarks/hologram.py`` on an idle machine).

``--draws N`` instead characterizes each focused twin with N noise draws (seeds 100…)
and prints the focal maximum's error statistics: mean and spread of the z error, the mean
reported σ z, the share of draws within 20 µm, RMS error/σ per coordinate (1: σ honest)
and the share of draws whose z error lies within 2 σ.

``--transient-focus band`` characterizes transient holograms with
``hologram.transient_focus = "band"`` and compares their focus and axis with the truth of
that definition (the pulse-pressure-squared integral's maximum,
``simulate_hologram(band_focus=True)``, cached as ``*_band_truth.json``; tr200's is read
from ``tr200_band_truth.json`` in the cache when present).

Run:  .venv/bin/python benchmarks/hologram_acceptance.py [--only NAME-PART] [--large]
          [--no-clean] [--cache DIR] [--draws N] [--transient-focus peak|band]
          [--focus-estimator lobe|aperture]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import pickle
import time
from pathlib import Path
from typing import Any

import numpy as np

from holoprobe.characterize import HologramConfig, characterize_hologram, hologram_summary
from holoprobe.geometry import SourceGeometry
from holoprobe.io import read_hologram
from holoprobe.simulate import VelocityMap, noise_std_for_snr, simulate_hologram, source_pose

_DEG = math.radians
_POSE = {"tilt": (_DEG(1.0), _DEG(-0.6)), "offset": (1.2e-3, -0.8e-3)}
_BOWL = SourceGeometry("spherical-cap", 0.04, 0.04, 0.04)
# name: (geometry, velocity map, simulate_hologram keywords)
TWINS: dict[str, tuple[SourceGeometry, VelocityMap, dict[str, Any]]] = {
    "bowl 40/R40 1 MHz 81² 40 dB": (_BOWL, VelocityMap(), {
        "frequency": 1e6, "z_position": 0.02, "shape": (81, 81), "snr_db": 40.0, **_POSE}),
    "bowl 40/R40 opening 12 mm": (
        SourceGeometry("spherical-cap", 0.04, 0.04, 0.04, 0.012), VelocityMap(), {
            "frequency": 1e6, "z_position": 0.02, "shape": (81, 81), "snr_db": 40.0,
            **_POSE}),
    "bowl 6 segments, one at 0.5": (_BOWL, VelocityMap(sector_gains=(1, 1, 0.5, 1, 1, 1)), {
        "frequency": 1e6, "z_position": 0.02, "shape": (81, 81), "snr_db": 40.0, **_POSE}),
    "bowl dead sector + phase patch": (_BOWL, VelocityMap(
        dead_sectors=((_DEG(30), _DEG(70)),), phase_patches=((5e-3, -4e-3, 2e-3, _DEG(90)),)),
        {"frequency": 1e6, "z_position": 0.02, "shape": (81, 81), "snr_db": 40.0, **_POSE}),
    "bowl 30/R40 transient 61² 40 dB": (
        SourceGeometry("spherical-cap", 0.03, 0.03, 0.04), VelocityMap(), {
            "frequency": 1e6, "signal": "transient", "cycles": 5, "band_db": -30.0,
            "z_position": 0.02, "shape": (61, 61), "snr_db": 40.0, **_POSE}),
    "disc 12 mm 1.5 MHz 101² 40 dB": (SourceGeometry("flat-disc", 0.012, 0.012), VelocityMap(), {
        "frequency": 1.5e6, "z_position": 0.008, "shape": (101, 101), "step": (4e-4, 4e-4),
        "snr_db": 40.0, "tilt": (_DEG(1.1), _DEG(-0.6)), "offset": (0.7e-3, -0.4e-3)}),
    "rectangle 12×8 mm 1.5 MHz 101² 40 dB": (
        SourceGeometry("flat-rectangle", 0.008, 0.012), VelocityMap(), {
            "frequency": 1.5e6, "z_position": 0.008, "shape": (101, 101),
            "step": (4e-4, 4e-4), "snr_db": 40.0, "tilt": (_DEG(1.1), _DEG(-0.6)),
            "offset": (0.7e-3, -0.4e-3)}),
}
LARGE = ("cw171", "tr200")  # benchmarks/hologram.py's cached twins (87 mm bowl)
TARGETS = {"axis (°)": 0.02, "focus (µm)": 20.0, "R (%)": 0.2, "aperture (mm)": 0.2,
           "surface vs hologram power (%)": 1.0, "velocity (%)": 3.0}


def _twin(name: str, cache: Path, seed: int | None = None
          ) -> tuple[Any, Any, dict[str, Any]]:
    """The noise-free twin (cached) and the same twin with its noise (the simulator's
    definition: complex white noise for CW, real for transient, σ from the peak SNR;
    seed = the twin's index unless given, so that the twins do not share one draw)."""
    stem = "".join(c if c.isalnum() else "_" for c in name)
    path = cache / f"{stem}_clean.pkl"
    geometry, vmap, kw = TWINS[name]
    if path.exists():
        clean, truth = pickle.loads(path.read_bytes())
    else:
        clean, sim = simulate_hologram(geometry, velocity=vmap,
                                       power=kw.get("signal", "cw") == "cw",
                                       **{**kw, "snr_db": None})
        truth = sim.parameters
        cache.mkdir(parents=True, exist_ok=True)
        path.write_bytes(pickle.dumps((clean, truth)))
    data = np.asarray(clean.pressure)
    sigma = noise_std_for_snr(data, kw["snr_db"])
    rng = np.random.default_rng(list(TWINS).index(name) if seed is None else seed)
    if clean.is_transient:
        noise = sigma * rng.standard_normal(data.shape)
    else:
        noise = sigma / np.sqrt(2) * (rng.standard_normal(data.shape)
                                      + 1j * rng.standard_normal(data.shape))
    return clean, dataclasses.replace(clean, pressure=data + noise), truth


def _band_truth(name: str, cache: Path, truth: dict[str, Any]) -> dict[str, Any]:
    """``truth`` with the alignment of the pulse (``band_focus``) for a transient twin."""
    geometry, vmap, kw = TWINS.get(name, (None, None, {}))
    path = cache / ("".join(c if c.isalnum() else "_" for c in name) + "_band_truth.json")
    if not path.exists() and geometry is not None:
        # the truth depends on the source, pose and pulse only: a 3 x 3 grid suffices
        _, sim = simulate_hologram(geometry, velocity=vmap, power=False, band_focus=True,
                                   **{**kw, "snr_db": None, "shape": (3, 3)})
        path.write_text(json.dumps(sim.parameters["alignment"], default=float))
    if not path.exists():
        raise SystemExit(f"no band truth for {name}: {path}")
    return {**truth, "alignment": {**truth["alignment"], **json.loads(path.read_text())}}


def _large(name: str, cache: Path) -> tuple[Any, dict[str, Any]] | None:
    path, truth = cache / f"{name}.h5", cache / f"{name}_truth.json"
    if not (path.exists() and truth.exists()):
        print(f"  ({name}: no cached twin in {cache}; run benchmarks/hologram.py first)")
        return None
    return read_hologram(path), json.loads(truth.read_text())


def _angle(a: Any, b: Any) -> float:
    return math.degrees(math.acos(min(1.0, abs(float(np.dot(a, b))))))


def _velocity_error(result: Any, truth: dict[str, Any], vmap: VelocityMap | None
                    ) -> tuple[float, float | None, float | None] | None:
    """Relative error of the surface velocity inside the aperture, away from the map's
    edges (one wavelength): (after one global phase, as is, |scale|).

    The first figure removes one phase common to the whole surface (for CW: the piston
    k·δ that a placement δ along the normal puts on every node, e.g. 0.03 rad for 7 µm
    at 1 MHz; for transient records also the pulse's arbitrary time origin) and keeps the
    amplitude absolute; ``scale`` = |Σ v v̄_true| / Σ |v_true|² is that amplitude.
    """
    if vmap is None:
        return None
    rec = result.reconstruction
    pose = truth["pose"]
    true_pose = source_pose(-pose["z0_m"], tilt=(_DEG(pose["theta_x_deg"]),
                                                 _DEG(pose["theta_y_deg"])),
                            offset=(pose["x0_m"], pose["y0_m"]))
    local = true_pose.to_local(rec.unrolled.surface.points)
    src = truth["source"]
    wavelength = result.hologram.medium.sound_speed / result.frequency
    rho = np.hypot(local[:, 0], local[:, 1])
    if src["kind"] == "flat-rectangle":
        inside = ((np.abs(local[:, 0]) < 0.5 * src["aperture_diameter"] - wavelength)
                  & (np.abs(local[:, 1]) < 0.5 * truth["aperture_min"] - wavelength))
    else:
        inside = (rho < 0.5 * src["aperture_diameter"] - wavelength) & (
            rho > 0.5 * src["opening_diameter"] + wavelength)
    v_true = vmap(local)
    for a in np.linspace(0, 2 * np.pi, 8, endpoint=False):   # away from the map's edges
        shifted = local + wavelength * np.array([math.cos(a), math.sin(a), 0.0])
        inside &= np.isclose(vmap(shifted), v_true)
    inside &= v_true != 0
    v = rec.velocity[inside, 0]
    ref = v_true[inside]
    scale = np.vdot(ref, v) / np.vdot(ref, ref)
    norm = np.linalg.norm(ref)
    if result.hologram.is_transient:        # the spectrum's amplitude and phase are not u0's
        return float(np.linalg.norm(v - ref * scale) / (norm * abs(scale))), None, None
    return (float(np.linalg.norm(v - ref * scale / abs(scale)) / norm),
            float(np.linalg.norm(v - ref) / norm), float(abs(scale)))


def _errors(holo: Any, truth: dict[str, Any], vmap: VelocityMap | None,
            cfg: HologramConfig) -> dict[str, Any]:
    """Characterize one hologram and compare with the truth (one row's numbers)."""
    t0, c0 = time.perf_counter(), time.process_time()
    result = characterize_hologram(holo, cfg)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    s = hologram_summary(result)
    al, src, tsrc, u = s["alignment"], s["source"], truth["source"], s["uncertainty"]
    row: dict[str, Any] = {"wall (s)": wall, "CPU (s)": cpu,
                           "axis σ (°)": u["axis_direction_deg"]}
    if al["focus_position"] is not None:
        row["axis (°)"] = _angle(al["axis_direction"], truth["alignment"]["axis_direction"])
        err = 1e6 * (np.array(al["focus_position"]) - truth["alignment"]["focus_position"])
        row["focus (µm)"] = float(np.linalg.norm(err))
        row["focus err z (µm)"] = float(err[2])
        row["focus σ z (µm)"] = 1e6 * u["focus_position"][2]
        row["R (%)"] = 100 * (src["radius_of_curvature"] / tsrc["radius_of_curvature"] - 1)
        row["R σ (%)"] = 100 * u["radius_of_curvature"] / tsrc["radius_of_curvature"]
    else:
        row["axis (°)"] = _angle(al["source_normal"], truth["alignment"]["geometric_axis"])
    row["source normal vs geometric axis (°)"] = _angle(al["source_normal"],
                                                        truth["alignment"]["geometric_axis"])
    row["apex (µm)"] = 1e6 * float(np.linalg.norm(np.array(al["source_apex"])
                                                  - truth["alignment"]["apex_position"]))
    if tsrc["kind"] == "flat-rectangle":
        true_sides = np.array([tsrc["aperture_diameter"], truth["aperture_min"]])
        row["aperture (mm)"] = 1e3 * float(np.max(np.abs(np.array(src["aperture_size"])
                                                         - true_sides)))
    else:
        row["aperture (mm)"] = 1e3 * (src["aperture_diameter"] - tsrc["aperture_diameter"])
    pw = s["acoustic_power"]
    row["surface vs hologram power (%)"] = 100 * pw["relative_difference"]
    window = (truth.get("acoustic_power") or {}).get("scan_window")
    if window and not holo.is_transient:
        row["hologram power vs truth (%)"] = 100 * (pw["hologram"] / window - 1)
    v_err = _velocity_error(result, truth, vmap)
    if v_err is not None:
        row["velocity (%)"] = 100 * v_err[0]
        if v_err[1] is not None:
            row["velocity with piston phase (%)"] = 100 * v_err[1]
            row["velocity amplitude scale"] = v_err[2]
    row.update(_defects(s, truth))
    return row


def _row(name: str, holo: Any, truth: dict[str, Any], vmap: VelocityMap | None,
         cfg: HologramConfig, clean: Any = None) -> dict[str, Any]:
    row = {"twin": name, **_errors(holo, truth, vmap, cfg)}
    if clean is not None:              # the same twin without noise: the method's own error
        free = _errors(clean, truth, vmap, cfg)
        for key in ("axis (°)", "focus err z (µm)", "focus σ z (µm)", "R (%)", "velocity (%)"):
            if key in free:
                row[f"{key}, noise-free"] = free[key]
    return row


def _defects(s: dict[str, Any], truth: dict[str, Any]) -> dict[str, Any]:
    """Dead region azimuth error (°) and phase defect centre error (mm), when the twin has
    them (untilted-frame comparison: the source's own x, y ≈ the unrolled map's)."""
    out: dict[str, Any] = {}
    v = truth["velocity"]
    if v["dead_sectors_deg"]:
        a, b = v["dead_sectors_deg"][0]
        dead = s["uniformity"]["dead_regions"]
        out["dead regions found"] = len(dead)
        if dead:
            out["dead azimuth error (°)"] = (dead[0]["azimuth_deg"] - 0.5 * (a + b) + 180) % 360 \
                - 180
    gains = [abs(complex(*g)) for g in v.get("sector_gains", [])]
    if gains and min(gains) < 1:      # a weak segment tilts the power direction, not the axis
        out["power direction error (°)"] = _angle(s["alignment"]["power_direction"],
                                                  truth["alignment"]["power_direction"])
        out["power direction vs lobe axis (°)"] = _angle(s["alignment"]["power_direction"],
                                                         s["alignment"]["axis_direction"])
    if v["phase_patches"]:
        c = np.array(v["phase_patches"][0]["center_m"])
        found = s["uniformity"]["phase_defects"]
        out["phase defects found"] = len(found)
        if found:
            out["phase defect centre error (mm)"] = 1e3 * float(
                np.linalg.norm(np.array(found[0]["unrolled"]) - c))
    return out


def _print(rows: list[dict[str, Any]]) -> None:
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    for r in rows:
        print(f"\n{r['twin']}")
        for k in keys[1:]:
            if k not in r:
                continue
            value = r[k]
            text = f"{value:.4g}" if isinstance(value, float) else str(value)
            verdict = ""
            if k in TARGETS and isinstance(value, float):
                verdict = "  PASS" if abs(value) <= TARGETS[k] else f"  FAIL (> {TARGETS[k]:g})"
            print(f"  {k:<38} {text}{verdict}")


def _cell(row: dict[str, Any], key: str, sigma: str | None = None, fmt: str = ".3g",
          clean: bool = False) -> str:
    if key not in row:
        return "—"
    text = format(row[key], fmt)
    if sigma and sigma in row:
        text += f" ({format(row[sigma], fmt)})"
    if clean and f"{key}, noise-free" in row:
        text += f"; {format(row[f'{key}, noise-free'], fmt)}"
    return text


def _markdown(rows: list[dict[str, Any]]) -> None:
    """One table: every acceptance item per twin (issue target in the header)."""
    head = ["twin", "axis ° (σ); noise-free (0.02)", "focus error µm",
            "focus z µm (σ z); noise-free z (σ z)", "R % (σ) (0.2)", "aperture mm (0.2)",
            "surface − hologram power % (1)", "velocity % (3); with piston phase",
            "defects: dead az. °, phase patch mm; weak segment", "wall / CPU s"]
    print("\n| " + " | ".join(head) + " |\n|" + "---|" * len(head))
    for r in rows:
        focus_z = "—"
        if "focus err z (µm)" in r:
            focus_z = f"{r['focus err z (µm)']:+.1f} ({r['focus σ z (µm)']:.1f})"
            if "focus err z (µm), noise-free" in r:
                focus_z += (f"; {r['focus err z (µm), noise-free']:+.1f} "
                            f"({r['focus σ z (µm), noise-free']:.1f})")
        defects = []
        if "dead regions found" in r:
            defects.append(f"{r['dead regions found']} found, "
                           f"{_cell(r, 'dead azimuth error (°)', fmt='+.2f')}")
        if "power direction error (°)" in r:
            defects.append(f"power direction {r['power direction vs lobe axis (°)']:.3f}° "
                           f"off the axis, error {r['power direction error (°)']:.4f}°")
        if "phase defects found" in r:
            defects.append(f"{r['phase defects found']} found, "
                           f"{_cell(r, 'phase defect centre error (mm)', fmt='.2f')}")
        cells = [r["twin"], _cell(r, "axis (°)", "axis σ (°)", ".4f", clean=True),
                 _cell(r, "focus (µm)", fmt=".1f"), focus_z,
                 _cell(r, "R (%)", fmt="+.3f") + f" ({r['R σ (%)']:.3f})" if "R (%)" in r else "—",
                 _cell(r, "aperture (mm)", fmt="+.4f"),
                 _cell(r, "surface vs hologram power (%)", fmt="+.3f"),
                 (_cell(r, "velocity (%)", fmt=".2f") + "; "
                  + _cell(r, "velocity with piston phase (%)", fmt=".2f")),
                 "; ".join(defects) or "—", f"{r['wall (s)']:.1f} / {r['CPU (s)']:.1f}"]
        print("| " + " | ".join(cells) + " |")


def _draws(name: str, n: int, cache: Path, cfg: HologramConfig) -> None:
    """The focus of one focused twin over ``n`` noise draws (seeds 100…): is a single
    draw's error within 20 µm, and does its reported σ cover it?"""
    errs, sigmas, axes = [], [], []
    for seed in range(100, 100 + n):
        _, holo, truth = _twin(name, cache, seed)
        if holo.is_transient and cfg.transient_focus == "band":
            truth = _band_truth(name, cache, truth)
        s = hologram_summary(characterize_hologram(holo, cfg))
        axes.append((_angle(s["alignment"]["axis_direction"],
                            truth["alignment"]["axis_direction"]),
                     s["uncertainty"]["axis_direction_deg"]))
        errs.append(np.array(s["alignment"]["focus_position"])
                    - truth["alignment"]["focus_position"])
        sigmas.append(np.array(s["uncertainty"]["focus_position"]))
    e, u = 1e6 * np.array(errs), 1e6 * np.array(sigmas)
    z = e / u
    print(f"{name}: {n} draws; focus error z mean {e[:, 2].mean():+.1f} µm, sd "
          f"{e[:, 2].std(ddof=1):.1f}, mean σ z {u[:, 2].mean():.1f}; |error| ≤ 20 µm in "
          f"{np.mean(np.linalg.norm(e, axis=1) <= 20):.2f} of the draws; RMS error/σ (x y z) "
          f"{np.sqrt(np.mean(z ** 2, axis=0)).round(2).tolist()}; |error z| ≤ 2σ in "
          f"{np.mean(np.abs(z[:, 2]) <= 2):.2f}; axis error RMS "
          f"{np.sqrt(np.mean(np.array(axes)[:, 0] ** 2)):.4f}°, mean σ "
          f"{np.mean(np.array(axes)[:, 1]):.4f}°, max {np.max(np.array(axes)[:, 0]):.4f}°, "
          f"≤ 2σ in {np.mean(np.array(axes)[:, 0] <= 2 * np.array(axes)[:, 1]):.2f}",
          flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default="", help="only the twins whose name holds this")
    parser.add_argument("--large", action="store_true",
                        help="also benchmarks/hologram.py's cached cw171 and tr200 twins")
    parser.add_argument("--no-clean", action="store_true",
                        help="skip the noise-free twins (the method's own error)")
    parser.add_argument("--cache", type=Path, default=Path(os.environ.get(
        "HOLOPROBE_BENCH_CACHE", "/tmp/holoprobe-bench")))
    parser.add_argument("--draws", type=int, default=0, metavar="N",
                        help="instead: the focus of each focused twin over N noise draws")
    parser.add_argument("--transient-focus", choices=("peak", "band"), default="peak",
                        help="hologram.transient_focus for the transient twins")
    parser.add_argument("--focus-estimator", choices=("lobe", "aperture"), default=None,
                        help="hologram.focus_estimator (default: the configuration's)")
    args = parser.parse_args()
    cfg = HologramConfig(transient_focus=args.transient_focus)
    if args.focus_estimator is not None:
        cfg = dataclasses.replace(cfg, focus_estimator=args.focus_estimator)
    if args.draws:
        for name, (geometry, _, _) in TWINS.items():
            if args.only in name and geometry.radius_of_curvature is not None:
                _draws(name, args.draws, args.cache / "acceptance", cfg)
        return
    rows = []
    print(f"load average {os.getloadavg()[0]:.1f}")
    for name, (geometry, vmap, _) in TWINS.items():
        if args.only not in name:
            continue
        clean, holo, truth = _twin(name, args.cache / "acceptance")
        if holo.is_transient and cfg.transient_focus == "band":
            truth = _band_truth(name, args.cache / "acceptance", truth)
        if geometry.kind == "flat-rectangle":
            truth = {**truth, "aperture_min": geometry.aperture_min}
        rows.append(_row(name, holo, truth, vmap, cfg, None if args.no_clean else clean))
        _print(rows[-1:])
    for name in LARGE if args.large else ():
        if args.only not in name:
            continue
        loaded = _large(name, args.cache)
        if loaded is not None and loaded[0].is_transient and cfg.transient_focus == "band":
            loaded = (loaded[0], _band_truth(name, args.cache, loaded[1]))
        if loaded is not None:
            rows.append(_row(name, *loaded, VelocityMap(), cfg))
            _print(rows[-1:])
    print(f"load average {os.getloadavg()[0]:.1f}")
    _markdown(rows)


if __name__ == "__main__":
    main()
