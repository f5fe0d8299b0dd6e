"""Benchmark: issue 11's acceptance run as a new user runs it, from the command line.

For every seed, two twins of a P4-1-like probe (96 elements at pitch 0.2945 mm, the
issue's held-out layout; a preset file written next to the data) in water at 1487 m/s
while the files say 1481 m/s, 40 dB scan SNR:

* ``worn``: ±5 % transmit amplitude and receive gain, 8 ns rms element delays, two dead
  elements (one inside, one at the edge), ±4 µm rms scan-position jitter;
* ``perfect``: the same probe, water and noise seeds without any of that (no element
  variation, no dead element, no jitter): the accuracy a perfect probe has.

Each twin is made with ``holoprobe simulate scan`` / ``holoprobe simulate receive`` and
characterized with ``holoprobe characterize SCAN --receive ECHO`` (the file's sound
speed, as a new user would first run it); ``--from-data`` and ``--temperature`` add
runs of the worn twin with ``--sound-speed from-data`` and ``--water-temperature``.
The script reads only ``summary.json``, ``virtual_transducer.h5`` and the simulator's
``truth.json`` / ``truth.h5`` and prints the acceptance table of issue 11::

    nice -n 10 .venv/bin/python benchmarks/elements_cli.py --work /tmp/el11 \\
        --seeds 1 2 --size-mm 36 19.2 --n-samples 768          # reduced scan
    nice -n 10 .venv/bin/python benchmarks/elements_cli.py --work /tmp/el11full \\
        --seeds 1 --from-data --temperature                    # the full default scan

Existing twin directories are reused (delete them to simulate again). Delays are
compared with their common delay removed (the issue's criterion); the linear trend is
printed too (a steering no field measurement tells from a tilt of the scan plane).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np

PITCH, KERF = 0.2945e-3, 0.05e-3
TRUE_C, FILE_C = 1487.0, 1481.0
WORN = ("--element-amplitude-rms", "0.05", "--element-delay-rms-ns", "8",
        "--receive-gain-rms", "0.05", "--jitter-um", "4")


def _preset(work: Path, elements: int) -> Path:
    """A P4-1-like preset with the issue's pitch (the packaged P4-1 has 0.2978 mm)."""
    from holoprobe.io import load_probe_preset

    src = Path(load_probe_preset("p4-1")["path"])
    text = src.read_text(encoding="utf-8")
    ir = (src.parent / "../p4-1_impulse_responses.h5").resolve()
    width = (elements - 1) * PITCH + PITCH - KERF
    out = []
    for line in text.splitlines():
        key = line.split("=")[0].strip()
        if line.startswith("pitch = 2.97"):
            line = f"pitch = {PITCH!r}"
        elif line.startswith("element_width = 2.47"):
            line = f"element_width = {PITCH - KERF!r}"
        elif line.startswith("aperture_width ="):
            line = f"aperture_width = {width!r}"
        elif key == "file":
            line = f'file = "{ir}"'
        out.append(line)
    path = work / "p4-1-like.toml"
    path.write_text("\n".join(out) + "\n", encoding="utf-8")
    return path


def _run(cmd: list[str], log: Path) -> float:
    t = time.perf_counter()
    with log.open("w") as fh:
        done = subprocess.run(cmd, stdout=fh, stderr=subprocess.STDOUT, check=False)
    if done.returncode:
        sys.exit(f"failed ({done.returncode}): {' '.join(cmd)}; see {log}")
    return time.perf_counter() - t


def simulate(d: Path, kind: str, seed: int, args, preset: Path) -> dict[str, float]:
    hp = [sys.executable, "-m", "holoprobe"]
    common = ["--preset", str(preset), "--elements", str(args.elements),
              "--sound-speed", str(TRUE_C), "--file-sound-speed", str(FILE_C), "--quiet"]
    if kind == "worn":
        dead = f"{args.elements // 2 - 8},{args.elements - 1}"  # inside, edge
        common += ["--dead", dead, "--element-seed", str(10 + seed)]
    times = {}
    d.mkdir(parents=True, exist_ok=True)
    if not (d / "scan" / "scan.h5").exists():
        extra = list(WORN) if kind == "worn" else []
        times["simulate scan"] = _run(
            [*hp, "simulate", "scan", "--out", str(d / "scan"), "--seed", str(seed),
             "--size-mm", *map(str, args.size_mm), "--n-samples", str(args.n_samples),
             "--overwrite", *common, *extra], d / "simulate_scan.log")
    if not (d / "echo" / "echo.h5").exists():
        extra = list(WORN[:-2]) if kind == "worn" else []
        times["simulate echo"] = _run(
            [*hp, "simulate", "receive", "--out", str(d / "echo"), "--seed", str(seed + 1),
             "--overwrite", *common, *extra], d / "simulate_echo.log")
    return times


def characterize(d: Path, name: str, options: list[str]) -> float | None:
    out = d / name
    if (out / "summary.json").exists():
        return None
    cmd = [sys.executable, "-m", "holoprobe", "characterize", str(d / "scan" / "scan.h5"),
           "--receive", str(d / "echo" / "echo.h5"), "--out", str(out), "--quiet",
           "--overwrite", *options]
    return _run(cmd, d / f"{name}.log")


def _ir_check(vt_ir, vt_rate, true_ir, true_rate, scale):
    """(energy ratio est/(truth·scale), |H_est/(H_true·scale)| min, max over the truth's
    −6 dB band)."""
    n = 1 << 16
    f = np.fft.rfftfreq(n, 1 / true_rate)
    ht = np.abs(np.fft.rfft(true_ir, n)) / true_rate * scale
    he = np.interp(f, np.fft.rfftfreq(n, 1 / vt_rate),
                   np.abs(np.fft.rfft(vt_ir, n)) / vt_rate)
    band = ht >= ht.max() / 2
    energy = np.sqrt(np.sum(vt_ir**2) / vt_rate / (np.sum(true_ir**2) / true_rate)) / scale
    ratio = he[band] / ht[band]
    return float(energy), float(ratio.min()), float(ratio.max())


def evaluate(d: Path, name: str) -> dict:
    s = json.loads((d / name / "summary.json").read_text())
    t = json.loads((d / "scan" / "truth.json").read_text())
    te = json.loads((d / "echo" / "truth.json").read_text())
    u = s["uncertainty"]
    probe = t["probe"]
    apod = np.asarray(probe["apodization"], float)
    gains = np.asarray(probe["receive_gains"], float)
    live = apod > 0
    r: dict = {"warnings": s["warnings"], "dead_true": probe["dead_elements"]}
    r["W"] = (s["aperture"]["width"] - probe["aperture_width_m"], u["aperture"]["width"])
    r["H"] = (s["aperture"]["height"] - probe["aperture_height_m"], u["aperture"]["height"])
    r["F"] = (s["lens_focus"] / probe["lens_focus_m"] - 1, u["lens_focus"] / probe["lens_focus_m"])
    for a in ("theta_x_deg", "theta_y_deg", "theta_z_deg"):
        r[a] = (s["scan_plane"][a] - t["scan_pose"][a], u["scan_plane"][a])
    el, ue = s["elements"], u["elements"]
    r["dead"] = el["dead"]
    amp = np.asarray(el["relative_amplitude"], float)
    true_amp = apod / apod[live].mean()
    r["amp"] = np.abs(amp - true_amp)[live].max()
    r["amp_z"] = (np.abs(amp - true_amp) / np.asarray(ue["relative_amplitude"]))[live].max()
    delay = np.asarray(el["delay"], float) - np.asarray(probe["element_delays_s"], float)
    delay = delay[live] - delay[live].mean()
    x = np.arange(apod.size)[live] * probe["pitch_m"]
    r["delay"] = np.abs(delay).max()
    r["delay_trend"] = np.abs(delay - np.polyval(np.polyfit(x, delay, 1), x)).max()
    if el.get("receive_gain") is not None:
        g = np.asarray(el["receive_gain"], float)
        ug = np.asarray(ue["receive_gain"], float)
        err = g / g[live].mean() - gains / gains[live].mean()
        r["gain"] = np.abs(err)[live].max()
        r["gain_rms"] = float(np.sqrt(np.mean(err[live] ** 2)))
        r["gain_z"] = (np.abs(err) / (ug / g[live].mean()))[live].max()
    med = s["medium"]
    r["c_used"] = med["sound_speed"]
    r["c"] = (med["sound_speed_from_data"], med["sound_speed_from_data_uncertainty"])
    pos = s.get("scan_positioning") or {}
    r["jitter"] = (pos.get("noise_rms"), pos.get("noise_rms_uncertainty"),
                   (t["scan_grid"].get("position_jitter_rms_m") or [0, 0, 0])[2])
    with h5py.File(d / "scan" / "truth.h5") as ft, \
            h5py.File(d / name / "virtual_transducer.h5") as fv:
        rate = float(ft["ir_sampling_rate"][()])
        r["tx_ir"] = _ir_check(fv["transmit/impulse_response"][:],
                               float(fv["transmit/sampling_rate"][()]),
                               ft["transmit_ir"][:], rate, apod[live].mean())
        if "receive" in fv:
            r["rx_ir"] = _ir_check(fv["receive/impulse_response"][:],
                                   float(fv["receive/sampling_rate"][()]),
                                   ft["receive_ir"][:], rate, gains[live].mean())
        r["vt_sensitivity"] = (fv["elements/sensitivity"][:] if "elements/sensitivity" in fv
                               else None)
    r["theta_y_rx"] = (s["receive"]["theta_y_deg"] - te["virtual_sensor"]["theta_y_deg"],
                       u["receive"]["theta_y_deg"]) if s.get("receive") else None
    return r


def _fmt(v, unit, scale):
    return f"{v * scale:+.3g}{unit}"


def table(results: dict) -> None:
    """Print the acceptance table: one column per (seed, twin, run)."""
    keys = list(results)
    print("| quantity | " + " | ".join(f"{s}/{k}/{n}" for s, k, n in keys) + " |")
    print("|---|" + "---:|" * len(keys))

    def line(label, fn):
        cells = []
        for key in keys:
            try:
                cells.append(fn(results[key]))
            except (KeyError, TypeError):
                cells.append("—")
        print(f"| {label} | " + " | ".join(cells) + " |")

    for q, unit, scale in (("W", " µm", 1e6), ("H", " µm", 1e6), ("F", " %", 100),
                           ("theta_x_deg", "°", 1), ("theta_y_deg", "°", 1),
                           ("theta_z_deg", "°", 1)):
        line(f"{q} error (σ)", lambda r, q=q, unit=unit, scale=scale:
             f"{_fmt(r[q][0], unit, scale)} ({r[q][1] * scale:.2g})")
    line("transmit IR energy / truth", lambda r: f"{r['tx_ir'][0]:.4f}")
    line("transmit \\|H\\| ratio in −6 dB band",
         lambda r: f"{r['tx_ir'][1]:.3f}…{r['tx_ir'][2]:.3f}")
    line("receive IR energy / truth", lambda r: f"{r['rx_ir'][0]:.4f}")
    line("receive \\|H\\| ratio in −6 dB band",
         lambda r: f"{r['rx_ir'][1]:.3f}…{r['rx_ir'][2]:.3f}")
    line("dead found (truth)", lambda r: f"{r['dead']} ({r['dead_true']})")
    line("amplitude max \\|err\\| (max err/σ)",
         lambda r: f"{r['amp']:.2%} ({r['amp_z']:.2f})")
    line("delay max \\|err\\|, common removed", lambda r: f"{r['delay'] * 1e9:.2f} ns")
    line("delay max \\|err\\|, linear trend removed",
         lambda r: f"{r['delay_trend'] * 1e9:.2f} ns")
    line("receive gain max \\|err\\| (rms; max err/σ)",
         lambda r: f"{r['gain']:.2%} ({r['gain_rms']:.2%}; {r['gain_z']:.2f})")
    line("c0 used", lambda r: f"{r['c_used']:.1f}")
    line("c0 from data − truth (σ)",
         lambda r: f"{r['c'][0] - TRUE_C:+.2f} ({r['c'][1]:.2f})")
    line("positioning noise (truth z)", lambda r: (
        f"{r['jitter'][0] * 1e6:.2f} ± {r['jitter'][1] * 1e6:.2f} µm "
        f"({r['jitter'][2] * 1e6:.2f})"))
    line("θy' error (σ)", lambda r: f"{r['theta_y_rx'][0]:+.4f}° ({r['theta_y_rx'][1]:.2g})")
    for key in keys:
        print(f"warnings {'/'.join(map(str, key))}:", *results[key]["warnings"], sep="\n  ")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--work", type=Path, required=True)
    p.add_argument("--elements", type=int, default=96)
    p.add_argument("--seeds", type=int, nargs="+", default=[1])
    p.add_argument("--size-mm", type=float, nargs=2, default=(36.0, 24.0))
    p.add_argument("--n-samples", type=int, default=1024)
    p.add_argument("--twins", nargs="+", default=["worn", "perfect"])
    p.add_argument("--from-data", action="store_true",
                   help="also run the worn twin with --sound-speed from-data")
    p.add_argument("--temperature", action="store_true",
                   help="also run the worn twin with --water-temperature (true water)")
    p.add_argument("--evaluate-only", action="store_true")
    p.add_argument("--simulate-only", action="store_true")
    args = p.parse_args()
    from holoprobe.geometry import water_sound_speed

    args.work.mkdir(parents=True, exist_ok=True)
    preset = _preset(args.work, args.elements)
    temps = np.linspace(20, 24, 4001)
    temp = float(temps[np.argmin(np.abs(water_sound_speed(temps) - TRUE_C))])
    runs = {"file_c": []}
    if args.from_data:
        runs["from_data"] = ["--sound-speed", "from-data"]
    if args.temperature:
        runs["temperature"] = ["--water-temperature", f"{temp:.3f}"]
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    results = {}
    for seed in args.seeds:
        for kind in args.twins:
            d = args.work / f"s{seed}" / kind
            if not args.evaluate_only:
                for what, sec in simulate(d, kind, seed, args, preset).items():
                    print(f"seed {seed} {kind}: {what} {sec:.0f} s wall", flush=True)
            for name, opts in runs.items():
                if args.simulate_only or (kind != "worn" and name != "file_c"):
                    continue
                if not args.evaluate_only:
                    sec = characterize(d, name, opts)
                    if sec is not None:
                        print(f"seed {seed} {kind}: characterize {name} {sec:.0f} s wall",
                              flush=True)
                if (d / name / "summary.json").exists():
                    results[(seed, kind, name)] = evaluate(d, name)
    print(f"\nwater {TRUE_C} m/s (file {FILE_C}); --water-temperature {temp:.3f} °C; "
          f"{args.elements} elements, pitch {PITCH * 1e3} mm; scan {args.size_mm} mm, "
          f"{args.n_samples} samples")
    table(results)


if __name__ == "__main__":
    main()
