"""Benchmark: do the reported uncertainties cover the actual errors? (issue 10 item 11)

Runs ``--runs`` reduced digital twins (``holoprobe.simulate``) with random scan poses,
plate distances and tilts, reflection coefficients, noise seeds and SNRs, characterizes
each one (transmit, and receive unless ``--no-receive``), and compares every value of
``summary.json`` that carries an uncertainty with the twin's truth. Printed per
parameter, and written to ``OUT/summary.json``: the fraction of runs with
``|error| ≤ 2σ`` (goal ≥ 90 %), the mean of error/σ (a bias shows here) and the
median |error|/σ. Each run is cached as ``OUT/runs/NNN.json`` (``--fresh`` redoes
them), so the benchmark can be interrupted, extended (``--runs``) or parallelised
(``--jobs``; each job runs one twin on one core).

What is compared (truth from the twin's ``truth.parameters``):

- scan pose, aperture W and H, element pitch and width, lens focus: directly;
- ``aperture.center_x/center_y``: the aperture centre of the last fit equals the
  origin before the last update minus the true origin; its error is therefore minus
  the error of x0/y0 (the pipeline moves the origin by −centre);
- ``scan_plane.z0`` and ``transmit.onset``: a pure delay moves between the transmit
  IR and the distance (DESIGN.md "Testing"): z0 is compared after moving the IR's
  measured delay (cross-correlation with the true IR) into it, and the onset error is
  that z0 error over c0;
- receive: θy′ and the reflection coefficient directly; the reflector distance d, z0′
  and x0′ = d sin θy′ after moving the delays of both IRs into them (as
  ``tests/test_pipeline_receive.py``; the pipeline moves the sensor along the ray from
  the source, ``_shift_receiver``); the receive onset is ``z0′`` error / c0;
- ``medium.sound_speed_from_data``: against the twin's water, C0 = 1481 m/s;
- ``receive.transfer_function``: |H_R(f)| at every reported frequency against the twin's
  (pooled over frequencies and twins; also over the truth's −6 dB band only). The
  receive IR of each run is pickled beside its JSON (``NNN.ir.pkl``).

Twins are kept small (16–32 elements, 0.15 mm scan step, 192 samples, λ/3 sources)
so that one run takes about 10–30 s on one core of the shared machine.

    .venv/bin/python benchmarks/uncertainty_coverage.py --runs 30 --jobs 2 \
        --out /tmp/coverage
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pickle
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

C0 = 1481.0


def draw(index: int, seed: int, elements: tuple[int, ...] = (16, 24, 32)) -> dict:
    """The random twin of run ``index``: pose, SNRs, plate, noise seeds."""
    rng = np.random.default_rng([seed, index])
    return {
        "index": index,
        "elements": int(rng.choice(list(elements))),
        "theta_deg": [float(v) for v in rng.uniform(-1.5, 1.5, 3)],
        "origin": [float(rng.uniform(-0.3e-3, 0.3e-3)), float(rng.uniform(-0.3e-3, 0.3e-3)),
                   float(rng.uniform(3e-3, 5e-3))],
        "scan_snr_db": float(rng.uniform(30.0, 45.0)),
        "scan_seed": int(rng.integers(1 << 30)),
        "plate_distance": float(rng.uniform(25e-3, 45e-3)),
        "virtual_tilt_deg": float(rng.choice([-1, 1]) * rng.uniform(1.0, 5.0)),
        "reflection_coefficient": float(rng.uniform(0.6, 0.9)),
        "echo_snr_db": float(rng.uniform(25.0, 40.0)),
        "echo_seed": int(rng.integers(1 << 30)),
    }


def lag(ir: np.ndarray, truth: np.ndarray, rate: float) -> float:
    """Delay (s) of ``ir`` against ``truth`` by cross-correlation (parabolic peak)."""
    n = 2 * max(ir.size, truth.size)
    xc = np.fft.irfft(np.fft.rfft(ir, n) * np.conj(np.fft.rfft(truth, n)), n)
    k = int(np.argmax(xc))
    y0, y1, y2 = xc[k - 1], xc[k], xc[(k + 1) % n]
    return ((k if k < n // 2 else k - n) + 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2)) / rate


def _transmit_rows(result, summary: dict, truth) -> dict:
    p, pose = truth.parameters["probe"], truth.parameters["scan_pose"]
    s, u = summary, summary["uncertainty"]
    ir = result.impulse_response
    lag_t = lag(ir.ir, truth.arrays["transmit_ir"], ir.sampling_rate)
    c0 = result.medium.sound_speed
    err = {
        "scan_plane.theta_x_deg": s["scan_plane"]["theta_x_deg"] - pose["theta_x_deg"],
        "scan_plane.theta_y_deg": s["scan_plane"]["theta_y_deg"] - pose["theta_y_deg"],
        "scan_plane.theta_z_deg": s["scan_plane"]["theta_z_deg"] - pose["theta_z_deg"],
        "scan_plane.x0": s["scan_plane"]["x0"] - pose["x0_m"],
        "scan_plane.y0": s["scan_plane"]["y0"] - pose["y0_m"],
        "scan_plane.z0": s["scan_plane"]["z0"] + c0 * lag_t - pose["z0_m"],
        "aperture.width": s["aperture"]["width"] - p["aperture_width_m"],
        "aperture.height": s["aperture"]["height"] - p["aperture_height_m"],
        "elements.pitch": s["elements"]["pitch"] - p["pitch_m"],
        "elements.width": s["elements"]["width"] - p["element_width_m"],
        "lens_focus": s["lens_focus"] - p["lens_focus_m"],
    }
    err["aperture.center_x"] = -err["scan_plane.x0"]
    err["aperture.center_y"] = -err["scan_plane.y0"]
    err["transmit.onset"] = err["scan_plane.z0"] / c0
    rows = {}
    for key, e in err.items():
        sec, _, name = key.rpartition(".")
        sigma = u[sec][name] if sec else u[name]
        rows[key] = {"error": float(e), "sigma": None if sigma is None else float(sigma)}
    c_data = s["medium"].get("sound_speed_from_data")
    if c_data is not None:  # the twin's water is C0; null when the estimate is off
        u_c = s["medium"].get("sound_speed_from_data_uncertainty")
        rows["medium.sound_speed_from_data"] = {
            "error": float(c_data) - C0, "sigma": None if u_c is None else float(u_c)}
    rows["_lag_transmit"] = float(lag_t)
    rows["_ir_peak_ratio"] = float(np.max(np.abs(ir.ir))
                                   / np.max(np.abs(truth.arrays["transmit_ir"])))
    return rows


def _receive_rows(receive, summary: dict, echo_truth, lag_t: float, model) -> dict:
    vs = echo_truth.parameters["virtual_sensor"]
    refl = echo_truth.parameters["reflector"]
    r, u = summary["receive"], summary["uncertainty"]["receive"]
    ir = receive.impulse_response
    lag_r = lag(ir.ir, echo_truth.arrays["receive_ir"], ir.sampling_rate)
    theta = math.radians(r["theta_y_deg"])
    moved = C0 * (lag_r + lag_t) / (1 + math.cos(theta))  # d of the IRs' delays
    d_err = r["reflector_distance"] + moved - refl["plate_distance_m"]
    z_err = r["sensor_z0"] + C0 * (lag_r + lag_t) - vs["z0_m"]
    err = {
        "receive.theta_y_deg": r["theta_y_deg"] - vs["theta_y_deg"],
        # x0' = d sin θy' moves with d along the ray from the source (_shift_receiver)
        "receive.sensor_x0": r["sensor_x0"] + moved * math.sin(theta) - vs["x0_m"],
        "receive.sensor_z0": z_err,
        "receive.reflector_distance": d_err,
        "receive.reflection_coefficient": (r["reflection_coefficient"]
                                           - refl["reflection_coefficient"]),
        "receive.onset": z_err / C0,
    }
    rows = {k: {"error": float(e), "sigma": None if u[k.split(".")[1]] is None
                else float(u[k.split(".")[1]])} for k, e in err.items()}
    rows["_lag_receive"] = float(lag_r)
    rows.update(_transfer_function_rows(r["transfer_function"], u["transfer_function"],
                                        model))
    return rows


def _transfer_function_rows(tf: dict, u_tf: dict, model) -> dict:
    """|H_R(f)| of summary.json against the twin's |H_R(f)| at every reported frequency
    (lists, pooled by :func:`coverage`), also restricted to the truth's −6 dB band."""
    from holoprobe.signal import continuous_spectrum

    f = np.asarray(tf["frequency"], dtype=float)
    h = model.receive_ir
    truth = np.abs(continuous_spectrum(h, model.ir_sampling_rate, f))
    peak = np.abs(np.fft.rfft(h, 16 * h.size)).max() / model.ir_sampling_rate
    err = np.asarray(tf["magnitude"], dtype=float) - truth
    sig = np.asarray(u_tf["magnitude"], dtype=float)
    band = truth >= 0.5 * peak
    return {"receive.transfer_function": {"error": err.tolist(), "sigma": sig.tolist(),
                                          "frequency": f.tolist(),
                                          "relative_error": (err / truth).tolist()},
            "receive.transfer_function (−6 dB band)": {"error": err[band].tolist(),
                                                      "sigma": sig[band].tolist()}}


def _scan_and_transmit(params: dict, model, ppw: float, cache: Path | None):
    """The twin's scan and truth, and its transmit result: from ``cache`` (a pickle
    written by an earlier run of any code version) when there is one."""
    from holoprobe.geometry import Pose
    from holoprobe.simulate import simulate_scan
    from holoprobe.workflow import characterize

    if cache is not None and cache.exists():
        return pickle.loads(cache.read_bytes())
    width = params["elements"] * model.pitch
    scan, truth = simulate_scan(
        model, pose=Pose.from_degrees(*params["theta_deg"], tuple(params["origin"])),
        size=(width + 5e-3, 19.2e-3), step=(0.15e-3, 0.15e-3), n_samples=192,
        snr_db=params["scan_snr_db"], seed=params["scan_seed"], points_per_wavelength=ppw)
    transmit = characterize(scan).transmit if cache is not None else None
    if cache is not None:
        tmp = cache.with_suffix(".tmp")
        tmp.write_bytes(pickle.dumps((scan, truth, transmit)))
        os.replace(tmp, cache)
    return scan, truth, transmit


def _characterize(scan, echo, transmit, overrides: tuple[str, ...] = ()):
    """``holoprobe.workflow.characterize(scan, echo=echo)``; with a cached transmit
    result, only its receive half (the same calls); ``overrides``: ``--set`` items."""
    from holoprobe.characterize import (
        CharacterizationConfig,
        channel_levels,
        characterize_receive,
        resolve_edge_ambiguity,
    )
    from holoprobe.workflow import CharacterizationRun, characterize

    if transmit is None:
        return characterize(scan, echo=echo, overrides=overrides)
    if echo is None:
        return CharacterizationRun(transmit)
    cfg = CharacterizationConfig().with_overrides(list(overrides))
    transmit = resolve_edge_ambiguity(transmit, channel_levels(echo.rf),
                                      cfg.elements.receive_dead_threshold)
    receive = characterize_receive(echo, transmit, scan, cfg)
    return CharacterizationRun(transmit, receive)


def run_one(params: dict, receive: bool, transmit_cache: Path | None = None,
            ir_dump: Path | None = None, overrides: tuple[str, ...] = ()) -> dict:
    """Simulate and characterize one twin; the errors and σ of every parameter."""
    from holoprobe.simulate import ArrayModel, simulate_echo

    t0 = time.perf_counter()
    model = ArrayModel.from_preset("p4-1", element_count=params["elements"])
    ppw = 3.0  # the twin's full band (a band-limited twin biases W, H and F)
    scan, truth, transmit = _scan_and_transmit(params, model, ppw, transmit_cache)
    t_sim = time.perf_counter() - t0
    out = {"params": params, "timings": {"scan": t_sim}}
    echo = echo_truth = None
    if receive:
        t1 = time.perf_counter()
        echo, echo_truth = simulate_echo(
            model, plate_distance=params["plate_distance"],
            virtual_tilt=math.radians(params["virtual_tilt_deg"]),
            reflection_coefficient=params["reflection_coefficient"], back_wall=True,
            snr_db=params["echo_snr_db"], seed=params["echo_seed"],
            points_per_wavelength=ppw, start_time=2 * params["plate_distance"] / C0 - 8e-6,
            n_samples=params.get("echo_samples", 1000))
        out["timings"]["echo"] = time.perf_counter() - t1
    try:  # as a user would: holoprobe.workflow.characterize, summary.json's tree
        run = _characterize(scan, echo, transmit, overrides)
    except Exception as exc:  # a receive failure is a result of the benchmark
        out["receive_error"] = f"{type(exc).__name__}: {exc}"
        run = _characterize(scan, None, transmit, overrides)
    summary = run.summary
    rows = _transmit_rows(run.transmit, summary, truth)
    if run.receive is not None:
        rows.update(_receive_rows(run.receive, summary, echo_truth, rows["_lag_transmit"],
                                  model))
        if ir_dump is not None:  # to study the receive IR's σ offline
            ir_dump.write_bytes(pickle.dumps(run.receive.impulse_response))
    out["rows"] = rows
    out["warnings"] = summary["warnings"]
    out["timings"]["total"] = time.perf_counter() - t0
    return out


def _cached(path: Path, params: dict, receive: bool, fresh: bool,
            transmit_cache: Path | None = None, overrides: tuple[str, ...] = ()) -> dict:
    if path.exists() and not fresh:
        data = json.loads(path.read_text())
        if data["params"] == params and (not receive or "receive.theta_y_deg" in data["rows"]
                                         or "receive_error" in data):
            return data
    data = run_one(params, receive, transmit_cache, path.with_suffix(".ir.pkl"), overrides)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=1))
    os.replace(tmp, path)
    return data


def _worker(args: tuple) -> dict:
    path, params, receive, fresh, transmit_cache, overrides = args
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    return _cached(Path(path), params, receive, fresh,
                   None if transmit_cache is None else Path(transmit_cache), overrides)


def _pairs(row: dict) -> list[tuple[float, float | None]]:
    """(error, σ) of a row: one, or one per frequency of a list-valued row."""
    if isinstance(row["error"], list):
        return list(zip(row["error"], row["sigma"], strict=True))
    return [(row["error"], row["sigma"])]


def coverage(runs: list[dict]) -> dict:
    """Per parameter: n, fraction with |error| ≤ 2σ, mean error/σ, median |error|/σ
    (list-valued rows, e.g. |H_R(f)| per frequency, pooled over their values)."""
    keys = sorted({k for r in runs for k in r["rows"] if not k.startswith("_")})
    table = {}
    for key in keys:
        pairs = [pair for r in runs if key in r["rows"] for pair in _pairs(r["rows"][key])]
        ok = [(e, s) for e, s in pairs if s is not None and math.isfinite(s) and s > 0]
        if not ok:
            table[key] = {"n": len(pairs), "coverage_2sigma": None, "note": "no σ reported"}
            continue
        z = np.array([e / s for e, s in ok])
        err = np.array([e for e, _ in ok])
        table[key] = {"n": len(ok), "coverage_2sigma": float(np.mean(np.abs(z) <= 2)),
                      "mean_z": float(np.mean(z)), "median_abs_z": float(np.median(np.abs(z))),
                      "rms_error": float(np.sqrt(np.mean(err ** 2))),
                      "median_sigma": float(np.median([s for _, s in ok]))}
    return table


def _print_markdown(table: dict) -> None:
    print("| parameter | n | \\|e\\| ≤ 2σ | mean e/σ | median \\|e\\|/σ | rms error | median σ |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for key, row in table.items():
        if row["coverage_2sigma"] is None:
            print(f"| {key} | {row['n']} | no σ | | | | |")
            continue
        print(f"| {key} | {row['n']} | {row['coverage_2sigma']:.0%} | {row['mean_z']:.2f} | "
              f"{row['median_abs_z']:.2f} | {row['rms_error']:.3g} | {row['median_sigma']:.3g} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=30)
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--out", default="/tmp/holoprobe_coverage")
    parser.add_argument("--no-receive", action="store_true")
    parser.add_argument("--fresh", action="store_true", help="ignore cached runs")
    parser.add_argument("--markdown", action="store_true", help="print the table as markdown")
    parser.add_argument("--elements", default="16,24,32",
                        help="element counts to draw from (reduced run: 16,24)")
    parser.add_argument("--echo-samples", type=int, default=1000,
                        help="RF record length of the echo (reduced run: 600)")
    parser.add_argument("--transmit-cache", default=None,
                        help="folder of pickled (scan, truth, transmit result) per twin: "
                             "written on the first run, then only the receive half runs "
                             "(to compare receive code on the same transmit results)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="configuration override, as the CLI's --set (repeatable)")
    args = parser.parse_args()
    elements = tuple(int(v) for v in args.elements.split(","))
    out = Path(args.out)
    (out / "runs").mkdir(parents=True, exist_ok=True)
    receive = not args.no_receive
    tag = "-".join(map(str, elements))

    def tx_cache(i: int) -> str | None:
        if not args.transmit_cache:
            return None
        Path(args.transmit_cache).mkdir(parents=True, exist_ok=True)
        return str(Path(args.transmit_cache) / f"{args.seed}_{i:03d}_{tag}.pkl")

    tasks = [(str(out / "runs" / f"{i:03d}.json"),
              {**draw(i, args.seed, elements), "echo_samples": args.echo_samples}, receive,
              args.fresh, tx_cache(i), tuple(args.set)) for i in range(args.runs)]
    t0 = time.perf_counter()
    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as pool:
            runs = list(pool.map(_worker, tasks))
    else:
        runs = [_worker(t) for t in tasks]
    table = coverage(runs)
    failed = [r["params"]["index"] for r in runs if "receive_error" in r]
    summary = {"runs": len(runs), "receive": receive, "seed": args.seed,
               "receive_failures": failed, "coverage": table,
               "mean_run_s": float(np.mean([r["timings"]["total"] for r in runs])),
               "wall_s": time.perf_counter() - t0}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(f"{len(runs)} twins, mean {summary['mean_run_s']:.1f} s per twin, "
          f"wall {summary['wall_s']:.0f} s; receive failures: {failed}")
    if args.markdown:
        _print_markdown(table)
        return
    print(f"{'parameter':34s} {'n':>3s} {'|e|≤2σ':>7s} {'mean e/σ':>9s} {'med |e|/σ':>9s} "
          f"{'rms error':>10s} {'median σ':>10s}")
    for key, row in table.items():
        if row["coverage_2sigma"] is None:
            print(f"{key:34s} {row['n']:3d}   (no σ)")
            continue
        print(f"{key:34s} {row['n']:3d} {row['coverage_2sigma']:7.0%} {row['mean_z']:9.2f} "
              f"{row['median_abs_z']:9.2f} {row['rms_error']:10.3g} {row['median_sigma']:10.3g}")


if __name__ == "__main__":
    main()
