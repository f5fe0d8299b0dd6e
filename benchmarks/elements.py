"""Benchmark: a worn 96-element P4-1-like probe in warm water (issue 11 acceptance).

Twin: 96 elements at pitch 0.2945 mm, elements 40 (inside) and 95 (edge) dead, ±5 %
transmit amplitude and receive gain, 8 ns rms element delays, 4 µm rms scan-position
jitter, scan SNR 40 dB, water at 1487 m/s while the files say 1481 m/s; the default
scan (36 × 24 mm at 0.15 mm, 1024 samples) and reflector echo (plate at 44.9 mm,
θy' = 3.17°, Rp = 0.78, back wall, 40 dB). Runs ``holoprobe.workflow.characterize``
(transmit + receive) and prints the errors against the truth as a table.

    .venv/bin/python benchmarks/elements.py [--cache /tmp/holoprobe_worn96.pkl]

Delays are compared with the common delay and the linear trend across the array
removed: a linear delay trend steers the beam exactly like a tilt of the scan plane,
and the orientation step puts it into the angles.
"""

from __future__ import annotations

import argparse
import pickle
import time
from pathlib import Path

import numpy as np

DEAD = (40, 95)
PITCH = 0.2945e-3


def simulate(cache: Path):
    from holoprobe.geometry import Medium
    from holoprobe.simulate import ArrayModel, simulate_echo, simulate_scan

    if cache.exists():
        return pickle.loads(cache.read_bytes())
    base = ArrayModel.from_preset("p4-1")
    kerf = base.pitch - base.element_width
    model = base.replace(pitch=PITCH, element_width=PITCH - kerf).with_element_variation(
        amplitude_rms=0.05, delay_rms=8e-9, receive_gain_rms=0.05, dead=DEAD, seed=11)
    true, file = Medium(sound_speed=1487.0), Medium(sound_speed=1481.0)
    t = time.perf_counter()
    scan, scan_truth = simulate_scan(model, snr_db=40.0, seed=1, position_jitter=4e-6,
                                     medium=true, recorded_medium=file, progress=True)
    t_scan = time.perf_counter() - t
    t = time.perf_counter()
    echo, echo_truth = simulate_echo(model, snr_db=40.0, seed=2, medium=true,
                                     recorded_medium=file, progress=True)
    t_echo = time.perf_counter() - t
    data = (model, scan, scan_truth, echo, echo_truth, t_scan, t_echo)
    cache.write_bytes(pickle.dumps(data))
    return data


def ir_energy(ir: np.ndarray, rate: float) -> float:
    return float(np.sqrt(np.sum(np.asarray(ir, float) ** 2) / rate))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cache", type=Path, default=Path("/tmp/holoprobe_worn96.pkl"))
    parser.add_argument("--sound-speed", default=None,
                        help="m/s or 'from-data' (default: the file's, 1481 m/s)")
    parser.add_argument("--save", type=Path, default=None,
                        help="pickle the transmit and receive results here")
    args = parser.parse_args()
    speed = (None if args.sound_speed is None
             else args.sound_speed if args.sound_speed == "from-data"
             else float(args.sound_speed))
    from holoprobe.workflow import characterize

    model, scan, st, echo, _, t_scan, t_echo = simulate(args.cache)
    t = time.perf_counter()
    run = characterize(scan, echo=echo, overrides=["onset.bootstrap=0"], sound_speed=speed)
    t_char = time.perf_counter() - t
    if args.save is not None:
        args.save.write_bytes(pickle.dumps((run.transmit, run.receive)))
    tx, rx = run.transmit, run.receive
    m = tx.element_map
    p = st.parameters
    apod = np.asarray(model.apodization)
    live = apod > 0
    rows = []

    def row(name, value, truth, unit, scale=1.0, tol=None):
        err = value - truth
        ok = "" if tol is None else ("yes" if abs(err) <= tol else "NO")
        rows.append(f"| {name} | {value * scale:.5g} | {truth * scale:.5g} | "
                    f"{err * scale:+.3g} {unit} | {ok} |")

    row("W (mm)", tx.aperture_width, p["probe"]["aperture_width_m"], "mm", 1e3, 0.05e-3)
    row("H (mm)", tx.aperture.height, p["probe"]["aperture_height_m"], "mm", 1e3, 0.05e-3)
    row("F (mm)", tx.lens_focus, p["probe"]["lens_focus_m"], "mm", 1e3,
        0.03 * p["probe"]["lens_focus_m"])
    for i, name in enumerate(("theta_x", "theta_y", "theta_z")):
        row(f"{name} (deg)", tx.pose.angles_deg[i], p["scan_pose"][f"{name}_deg"], "deg",
            1.0, 0.02)
    e_tx = ir_energy(tx.impulse_response.ir, tx.impulse_response.sampling_rate)
    e_true = ir_energy(st.arrays["transmit_ir"], model.ir_sampling_rate)
    row("transmit IR energy / truth·mean live apod.", e_tx / e_true, apod[live].mean(), "",
        1.0, 0.03)
    if rx is not None:
        gains = np.asarray(model.receive_gains)
        e_rx = ir_energy(rx.impulse_response.ir, rx.impulse_response.sampling_rate)
        e_rtrue = ir_energy(model.receive_ir, model.ir_sampling_rate)
        row("receive IR energy / truth·mean live gain", e_rx / e_rtrue,
            gains[live].mean(), "", 1.0, 0.05)
    c, u = tx.extras["sound_speed_from_data"], tx.extras["sound_speed_from_data_uncertainty"]
    row(f"c0 from data (± {u:.2g} m/s)", c, 1487.0, "m/s", 1.0, max(3.0, 2 * u))
    print(f"simulation: scan {t_scan:.0f} s, echo {t_echo:.0f} s; characterize "
          f"(transmit + receive) {t_char:.0f} s wall; transmit steps (wall): "
          + ", ".join(f"{k} {v:.1f} s" for k, v in tx.timings.items()))
    print(f"dead found {list(m.dead)} (truth {list(DEAD)}), weak {list(m.weak)}, "
          f"ambiguous {m.ambiguous}")
    a = apod / apod[live].mean()
    amp_err = (m.relative_amplitude - a)[live]
    x = model.element_centers()[live]
    d = m.delay[live] - model.delays[live]
    d_trend = d - np.polyval(np.polyfit(x, d, 1), x)
    d_common = d - d.mean()
    print("| quantity | estimate | truth | error | within acceptance |")
    print("|---|---:|---:|---:|:---:|")
    for r in rows:
        print(r)
    print(f"| element amplitude, max abs error | {np.abs(amp_err).max():.3%} | | "
          f"rms {np.sqrt(np.mean(amp_err**2)):.3%} | "
          f"{'yes' if np.abs(amp_err).max() < 0.02 else 'NO'} |")
    print(f"| element delay, max abs error (common removed) | "
          f"{np.abs(d_common).max() * 1e9:.2f} ns | | rms "
          f"{np.sqrt(np.mean(d_common**2)) * 1e9:.2f} ns | "
          f"{'yes' if np.abs(d_common).max() < 3e-9 else 'NO'} |")
    print(f"| element delay, max abs error (linear trend removed) | "
          f"{np.abs(d_trend).max() * 1e9:.2f} ns | | rms "
          f"{np.sqrt(np.mean(d_trend**2)) * 1e9:.2f} ns | "
          f"{'yes' if np.abs(d_trend).max() < 3e-9 else 'NO'} |")
    if rx is not None and rx.sensitivity is not None:
        g = rx.sensitivity.amplitude
        gt = np.asarray(model.receive_gains)
        g_err = (g / g[live].mean() - gt / gt[live].mean())[live]
        print(f"| receive gain, max abs error | {np.abs(g_err).max():.3%} | | rms "
              f"{np.sqrt(np.mean(g_err**2)):.3%} | "
              f"{'yes' if np.abs(g_err).max() < 0.03 else 'NO'} |")
        u_g = rx.sensitivity.amplitude_uncertainty
        if u_g is not None:
            z = g_err / (u_g[live] / g[live].mean())
            print(f"| receive gain error / its uncertainty | max {np.abs(z).max():.2f} | | "
                  f"rms {np.sqrt(np.mean(z**2)):.2f} | "
                  f"{'yes' if np.abs(z).max() <= 3 else 'NO'} |")
    z_a = amp_err / m.amplitude_uncertainty[live]
    print(f"| element amplitude error / its uncertainty | max {np.abs(z_a).max():.2f} | | "
          f"rms {np.sqrt(np.mean(z_a**2)):.2f} | {'yes' if np.abs(z_a).max() <= 3 else 'NO'} |")
    print("warnings:", *tx.warnings, *(rx.warnings if rx else []), sep="\n  ")


if __name__ == "__main__":
    main()
