"""Benchmark: 2-D matrix arrays (issue 16 acceptance), held-out twins.

Twins: ``ArrayModel.matrix(32)`` (32 × 32 elements, pitch 0.3 mm, kerf 0.03 mm, 3 MHz,
Gaussian impulse responses, no lens) with ±5 % element amplitudes, 3 ns rms element
delays, dead elements, a tilted scan plane 2.5 mm from the face, an 18 × 18 mm scan at
0.15 mm (121 × 121 points, 512 samples at 40 MHz) and 40 dB peak SNR; each seed draws
other element variations, dead elements and noise. Runs
``holoprobe.workflow.characterize`` and prints the errors against the truth.

    .venv/bin/python benchmarks/matrix.py [--seeds 1 2] [--n 32] [--cache DIR] [--noise-free]
    .venv/bin/python benchmarks/matrix.py --seeds 1 --receive   # + plate echo, receive
    .venv/bin/python benchmarks/matrix.py --seeds 1 --monte-carlo 40 46 49 52 --draws 5

Angles are compared with the true pose turned by the linear trend of the true element
delays (the characterization's acoustic-axis convention: a delay trend steers the beam
exactly like a tilt of the scan plane); delays with that trend removed.
"""

from __future__ import annotations

import argparse
import pickle
import time
from pathlib import Path

import numpy as np


def simulate(n: int, seed: int, cache: Path, snr_db: float | None = 40.0, *,
             sparse: tuple[int, str] | None = None):
    """The n × n twin of the module doc (cached); ``sparse=(count, layout)`` thins the
    lattice to ``count`` elements (:func:`holoprobe.geometry.sparse_layout`)."""
    from holoprobe.geometry import Pose, sparse_layout
    from holoprobe.simulate import ArrayModel, simulate_scan

    if sparse is not None:
        count, layout = sparse
        path = cache / f"sparse{count}of{n}_{layout}_seed{seed}_snr{snr_db}.pkl"
    else:
        count = n * n
        path = cache / (f"matrix{n}_seed{seed}.pkl" if snr_db == 40.0
                        else f"matrix{n}_seed{seed}_snr{snr_db}.pkl")
    if path.exists():
        return pickle.loads(path.read_bytes())
    rng = np.random.default_rng(100 + seed)
    dead = tuple(sorted(rng.choice(count, size=3, replace=False).tolist()))
    active = (None if sparse is None
              else sparse_layout(n, n, count, layout=sparse[1], taper=0.5, seed=seed))
    model = ArrayModel.matrix(n, active=active).with_element_variation(
        amplitude_rms=0.05, delay_rms=3e-9, dead=dead, seed=seed)
    angles = rng.uniform(-1.0, 1.0, 3)
    pose = Pose.from_degrees(*angles, (rng.uniform(-0.2e-3, 0.2e-3),
                                       rng.uniform(-0.2e-3, 0.2e-3), 2.5e-3))
    size = 0.3e-3 * n + 8.4e-3
    t0 = time.perf_counter()
    scan, truth = simulate_scan(model, pose=pose, size=(size, size), step=(0.15e-3, 0.15e-3),
                                sampling_rate=40e6, n_samples=512, snr_db=snr_db, seed=seed,
                                calibration=None, points_per_wavelength=2)
    out = (model, pose, scan, truth, time.perf_counter() - t0)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(pickle.dumps(out))
    return out


def print_table(rows: list[dict]) -> None:
    """The rows as a Markdown table (floats to 4 significant digits)."""
    if not rows:
        return
    keys = list(rows[0])
    print("| " + " | ".join(keys) + " |")
    print("|" + "---|" * len(keys))
    for r in rows:
        print("| " + " | ".join(f"{r[k]:.4g}" if isinstance(r[k], float) else str(r[k])
                                 for k in keys) + " |")


ECHO = {"plate_distance": 15e-3, "virtual_tilt": np.radians(-2.0),
        "virtual_tilt_x": np.radians(1.5), "reflection_coefficient": 0.78}


def simulate_echo_twin(n: int, seed: int, cache: Path, model):
    """The plate echo of the seed's twin (cached): 15 mm, θx' 1.5°, θy' −2°, Rp 0.78,
    6 mm steel back wall, 40 dB, dense Rayleigh sums onto the mirrored cells."""
    from holoprobe.simulate import simulate_echo

    path = cache / f"matrix{n}_seed{seed}_echo.pkl"
    if path.exists():
        return pickle.loads(path.read_bytes())
    t0 = time.perf_counter()
    echo, truth = simulate_echo(model, back_wall=True, plate_thickness=6e-3, snr_db=40,
                                seed=seed + 50, band=(1.5e6, 4.5e6), points_per_wavelength=2,
                                start_time=16e-6, n_samples=768, sampling_rate=40e6, **ECHO)
    out = (echo, truth, time.perf_counter() - t0)
    path.write_bytes(pickle.dumps(out))
    return out


def receive_errors(model, run) -> dict[str, float]:
    """Plate pose errors (and their σ) and the relative receive-gain errors."""
    rx = run.receive
    vr, u = rx.receiver, rx.uncertainties
    g = np.asarray(model.receive_gains)
    live = g > 0
    got = rx.sensitivity.amplitude / rx.sensitivity.amplitude[live].mean()
    err = (got - g / g[live].mean())[live]
    return {"d_err_um": (vr.distance - ECHO["plate_distance"]) * 1e6,
            "u_d_um": vr.distance_uncertainty * 1e6,
            "tx_err_deg": float(np.degrees(vr.theta_x - ECHO["virtual_tilt_x"])),
            "u_tx_deg": float(np.degrees(u["theta_x"])),
            "ty_err_deg": float(np.degrees(vr.theta_y - ECHO["virtual_tilt"])),
            "u_ty_deg": float(np.degrees(u["theta_y"])),
            "gain_rms_pct": float(np.sqrt(np.mean(err**2)) * 100),
            "gain_max_pct": float(np.max(np.abs(err)) * 100),
            "rx_cpu_s": float(rx.timings.get("total", float("nan")))}


def errors(model, pose, scan, truth, run) -> dict[str, float]:
    from holoprobe.signal import continuous_spectrum

    tx = run.transmit
    c0 = scan.medium.sound_speed
    amp = np.asarray(model.apodization)
    live = amp > 0
    pos = model.array.positions[live, :2]
    design = np.c_[np.ones(pos.shape[0]), pos]
    coef = np.linalg.lstsq(design * amp[live, None], np.asarray(model.delays)[live] * amp[live],
                           rcond=None)[0]
    tx_, ty_, tz_ = pose.angles_deg
    expected = (tx_ + np.degrees(np.arcsin(c0 * coef[2])),
                ty_ - np.degrees(np.arcsin(c0 * coef[1])), tz_)
    got = tx.pose.angles_deg
    u = {k: np.degrees(tx.uncertainties[k]) for k in ("theta_x", "theta_y", "theta_z")}
    out = {}
    for i, k in enumerate(("theta_x", "theta_y", "theta_z")):
        out[f"{k}_deg"] = got[i] - expected[i]
        out[f"u_{k}_deg"] = u[k]
    probe = truth.parameters["probe"]
    out["aperture_x_mm"] = (tx.aperture_width - probe["aperture_width_m"]) * 1e3
    out["aperture_y_mm"] = (run.summary["aperture"]["height"] - probe["aperture_height_m"]) * 1e3
    out["u_aperture_x_mm"] = run.summary["uncertainty"]["aperture"]["width"] * 1e3
    out["u_aperture_y_mm"] = run.summary["uncertainty"]["aperture"]["height"] * 1e3
    out["x0_um"] = (tx.pose.origin[0] - pose.origin[0]) * 1e6
    out["y0_um"] = (tx.pose.origin[1] - pose.origin[1]) * 1e6
    m = tx.element_map
    geo = model.array
    for key, got_, true, u_ in (
            ("pitch_x", m.pitch, geo.pitch[0], m.pitch_uncertainty),
            ("pitch_y", m.pitch_y, geo.pitch[1], m.pitch_y_uncertainty),
            ("width", m.element_width, float(np.median(geo.widths)), m.width_uncertainty),
            ("height", m.element_height, float(np.median(geo.heights)),
             m.height_uncertainty)):
        out[f"{key}_err_um"] = (got_ - true) * 1e6
        out[f"u_{key}_um"] = u_ * 1e6
    nx, ny = m.grid_shape
    # the scan-window correction of the pitches (removed; NaN when off)
    out["window_bias_pitch_x_um"] = tx.extras.get("window_bias_width", np.nan) / nx * 1e6
    out["window_bias_pitch_y_um"] = tx.extras.get("window_bias_height", np.nan) / ny * 1e6
    t_amp = amp / amp[live].mean()
    err = m.relative_amplitude - t_amp
    out["amp_err_rms_%"] = 100 * float(np.sqrt(np.mean(err[live] ** 2)))
    out["amp_err_max_%"] = 100 * float(np.abs(err[live]).max())
    out["amp_err_over_u_max"] = float(np.max(np.abs(err[live]) / m.amplitude_uncertainty[live]))
    out["dead_found"] = float(tuple(m.dead) == tuple(model.dead_elements))
    tau = np.asarray(model.delays)[live]
    tau = tau - design @ np.linalg.lstsq(design, tau, rcond=None)[0]
    d = m.delay[live] - design @ np.linalg.lstsq(design, m.delay[live], rcond=None)[0]
    out["delay_err_rms_ns"] = float(np.sqrt(np.mean((d - tau) ** 2)) * 1e9)
    ir = tx.impulse_response
    ref = truth.arrays["transmit_ir"]
    out["ir_correlation"] = correlation(ir.ir, ir.sampling_rate, ref, model.ir_sampling_rate)
    f = np.linspace(2.2e6, 3.8e6, 9)
    ratio = np.abs(continuous_spectrum(ir.ir, ir.sampling_rate, f)) / np.abs(
        continuous_spectrum(ref, model.ir_sampling_rate, f))
    out["ir_gain_min"], out["ir_gain_max"] = float(ratio.min()), float(ratio.max())
    return out


def correlation(a, rate_a, b, rate_b) -> float:
    """Peak of the normalised cross-correlation of two signals (``a`` interpolated onto
    the sample times of ``b``; both sampled far above their band)."""
    t = np.arange(max(a.size / rate_a, b.size / rate_b) * rate_b) / rate_b
    a = np.interp(t, np.arange(a.size) / rate_a, a, right=0.0)
    b = np.pad(b, (0, t.size - b.size))
    n = 2 * t.size
    xc = np.fft.irfft(np.fft.rfft(a, n) * np.conj(np.fft.rfft(b, n)), n)
    return float(xc.max() / (np.linalg.norm(a) * np.linalg.norm(b)))


def monte_carlo(n: int, seed: int, cache: Path, snrs: list[float], reps: int) -> None:
    """Element amplitudes over fresh noise draws on the noise-free twin of ``seed``: per
    SNR the rms and worst-element errors of each draw, the Monte-Carlo σ of each element
    against its stated uncertainty u, and the share of errors within u and 2u."""
    import dataclasses

    from holoprobe.simulate import noise_std_for_snr
    from holoprobe.workflow import characterize

    model, _, scan, _, _ = simulate(n, seed, cache, snr_db=None)
    amp = np.asarray(model.apodization)
    live = amp > 0
    truth = amp / amp[live].mean()
    clean = np.asarray(scan.data)
    for snr in snrs:
        sigma = noise_std_for_snr(clean, snr)
        errs, us = [], []
        for r in range(reps):
            noise = np.random.default_rng(1000 + r).standard_normal(clean.shape)
            m = characterize(dataclasses.replace(scan, data=clean + sigma * noise)
                             ).transmit.element_map
            errs.append((m.relative_amplitude - truth)[live])
            us.append(m.amplitude_uncertainty[live])
        e, u = np.array(errs), np.array(us)
        sd = e.std(axis=0, ddof=1)
        print(f"SNR {snr:g} dB, {reps} draws: rms {100 * np.sqrt(np.mean(e**2)):.2f} %, "
              f"worst element per draw {np.round(100 * np.abs(e).max(axis=1), 2)} %, "
              f"MC σ median {100 * np.median(sd):.2f} % (max {100 * sd.max():.2f} %), "
              f"u/σ median {np.median(u.mean(axis=0) / sd):.2f}, |e| ≤ u "
              f"{np.mean(np.abs(e) <= u):.3f}, ≤ 2u {np.mean(np.abs(e) <= 2 * u):.3f}",
              flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--n", type=int, default=32)
    parser.add_argument("--cache", type=Path, default=Path("/tmp/holoprobe_matrix"))
    parser.add_argument("--simulate-only", action="store_true")
    parser.add_argument("--monte-carlo", type=float, nargs="+", metavar="SNR_DB",
                        help="Monte-Carlo of the element amplitudes at these peak SNRs "
                             "(fresh noise on the noise-free twin of the first seed)")
    parser.add_argument("--draws", type=int, default=5)
    parser.add_argument("--noise-free", action="store_true",
                        help="characterize the noise-free copies of the twins")
    parser.add_argument("--receive", action="store_true",
                        help="also simulate the plate echo and characterize the receive")
    args = parser.parse_args()
    if args.monte_carlo:
        monte_carlo(args.n, args.seeds[0], args.cache, args.monte_carlo, args.draws)
        return
    from holoprobe.workflow import characterize

    rows = []
    for seed in args.seeds:
        model, pose, scan, truth, t_sim = simulate(args.n, seed, args.cache,
                                                   None if args.noise_free else 40.0)
        print(f"seed {seed}: twin {scan.data.shape} ({t_sim:.0f} s to simulate)", flush=True)
        echo = None
        if args.receive:
            echo, _, t_echo = simulate_echo_twin(args.n, seed, args.cache, model)
            print(f"echo {echo.rf.shape} ({t_echo:.0f} s to simulate)", flush=True)
        if args.simulate_only:
            continue
        t0, c0 = time.perf_counter(), time.process_time()
        run = characterize(scan, echo=echo, progress=False)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        row = {"seed": seed, "wall_s": wall, "cpu_s": cpu,
               **errors(model, pose, scan, truth, run)}
        if echo is not None:
            row.update(receive_errors(model, run))
            print("receive timings", {k: round(v, 2) for k, v in run.receive.timings.items()})
        rows.append(row)
        print({k: (round(v, 5) if isinstance(v, float) else v) for k, v in row.items()},
              flush=True)
        print("timings", {k: round(v, 2) for k, v in run.transmit.timings.items()})
    print_table(rows)


if __name__ == "__main__":
    main()
