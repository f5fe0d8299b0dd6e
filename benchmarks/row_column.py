"""Benchmark: row-column arrays (issue 16 stretch), held-out twins.

Twin: ``ArrayModel.row_column(n)`` (n columns + n rows, pitch 0.3 mm, kerf 0.03 mm,
3 MHz, no lens) transmitting with one set, ±5 % strip amplitudes, 2 ns rms delays, one
dead strip, a tilted scan plane 2.5 mm from the face, a scan 6 mm wider than the
aperture at 0.15 mm (512 samples at 40 MHz), 40 dB peak SNR. Runs
``holoprobe.workflow.characterize_row_column`` and prints the errors against the truth:
the probe-frame angles in the acoustic-axis convention, the strips' amplitudes, the IR
correlation and in-band gain, the time.

    .venv/bin/python benchmarks/row_column.py [--n 32] [--sets columns rows] [--seed 1]
    .venv/bin/python benchmarks/row_column.py --receive   # + plate echo, every strip receives

``--receive``: the strips also get ±5 % receive gains and the twin the plate echo of
``benchmarks/matrix.py --receive`` (15 mm, θx' 1.5°, θy' −2°, Rp 0.78, 6 mm steel back
wall, 40 dB; dense Rayleigh sums onto the mirrored strips' cells, one channel per strip
of the whole array); the receive (``characterize_row_column(..., echo=)``) is scored
like the matrix's, plus the receive IR's correlation and in-band gain against the
twin's and the largest gain error in units of its σ.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from matrix import ECHO, correlation, print_table, receive_errors


def echo_twin(model, seed: int):
    """The plate echo of ``benchmarks/matrix.py --receive`` for a row-column twin."""
    from holoprobe.simulate import simulate_echo

    t0 = time.perf_counter()
    echo, _ = simulate_echo(model, back_wall=True, plate_thickness=6e-3, snr_db=40,
                            seed=seed + 50, band=(1.5e6, 4.5e6), points_per_wavelength=2,
                            start_time=16e-6, n_samples=768, sampling_rate=40e6, **ECHO)
    return echo, time.perf_counter() - t0


def receive_scores(model, run) -> dict[str, float]:
    """:func:`matrix.receive_errors` plus the receive IR against the twin's (correlation,
    in-band gain 2.2–3.8 MHz) and the largest relative-gain error over its σ."""
    from holoprobe.signal import continuous_spectrum

    rx = run.receive
    ir = rx.impulse_response
    f = np.linspace(2.2e6, 3.8e6, 9)
    gain = np.abs(continuous_spectrum(ir.ir, ir.sampling_rate, f)) / np.abs(
        continuous_spectrum(model.receive_ir, model.ir_sampling_rate, f))
    g = np.asarray(model.receive_gains)
    live = g > 0
    sens = rx.sensitivity
    err = (sens.amplitude / sens.amplitude[live].mean() - g / g[live].mean())[live]
    return {**receive_errors(model, run),
            "gain_max_over_sigma": float(np.max(np.abs(err) / sens.amplitude_uncertainty[live])),
            "rx_ir_correlation": correlation(ir.ir, ir.sampling_rate, model.receive_ir,
                                             model.ir_sampling_rate),
            "rx_ir_gain_min": float(gain.min()), "rx_ir_gain_max": float(gain.max())}


def run_set(n: int, transmit: str, seed: int, receive: bool = False
            ) -> dict[str, float | str]:
    from holoprobe.geometry import Pose
    from holoprobe.signal import continuous_spectrum
    from holoprobe.simulate import ArrayModel, simulate_scan
    from holoprobe.workflow import characterize_row_column

    rng = np.random.default_rng(200 + seed)
    offset = 0 if transmit == "columns" else n
    dead = (offset + int(rng.integers(1, n - 1)),)
    model = ArrayModel.row_column(n, transmit=transmit).with_element_variation(
        amplitude_rms=0.05, delay_rms=2e-9, dead=dead, seed=seed,
        receive_gain_rms=0.05 if receive else 0.0)
    pose = Pose.from_degrees(*rng.uniform(-1.0, 1.0, 3), (rng.uniform(-0.2e-3, 0.2e-3),
                                                          rng.uniform(-0.2e-3, 0.2e-3), 2.5e-3))
    side = 0.3e-3 * n + 6e-3
    t0 = time.perf_counter()
    scan, truth = simulate_scan(model, pose=pose, size=(side, side), step=(0.15e-3, 0.15e-3),
                                sampling_rate=40e6, n_samples=512, snr_db=40.0, seed=seed,
                                calibration=None, points_per_wavelength=2)
    t_sim = time.perf_counter() - t0
    echo = None
    if receive:
        echo, t_echo = echo_twin(model, seed)
        t_sim += t_echo
    t0, c0 = time.perf_counter(), time.process_time()
    run = characterize_row_column(scan, transmit, echo=echo)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    s = run.summary
    rc = s["row_column"]
    # acoustic axis: the live strips' delay trend steers like a tilt
    amp, tau = np.asarray(model.apodization), np.asarray(model.delays)
    live = amp > 0
    pos = model.array.positions[live, :2]
    design = np.c_[np.ones(live.sum()), pos]
    coef = np.linalg.lstsq(design * amp[live, None], tau[live] * amp[live], rcond=None)[0]
    c = scan.medium.sound_speed
    tx, ty, tz = pose.angles_deg
    want = (tx + np.degrees(np.arcsin(c * coef[2])), ty - np.degrees(np.arcsin(c * coef[1])),
            tz)
    got = [rc["scan_plane"][f"theta_{k}_deg"] for k in "xyz"]
    idx = np.asarray(rc["elements"])
    a = amp[idx]
    ok = a > 0
    err = np.asarray(s["elements"]["relative_amplitude"])[ok] - a[ok] / a[ok].mean()
    ir = run.transmit.impulse_response
    ref = truth.arrays["transmit_ir"]
    f = np.linspace(2.2e6, 3.8e6, 9)
    gain = np.abs(continuous_spectrum(ir.ir, ir.sampling_rate, f)) / np.abs(
        continuous_spectrum(ref, model.ir_sampling_rate, f))
    scores = {} if echo is None else receive_scores(model, run)
    return {"set": transmit, "sim_s": t_sim, "wall_s": wall, "cpu_s": cpu, **scores,
            **{f"theta_{k}_err_deg": g - w for k, g, w in zip("xyz", got, want, strict=True)},
            "x0_err_um": (rc["scan_plane"]["x0"] - pose.origin[0]) * 1e6,
            "y0_err_um": (rc["scan_plane"]["y0"] - pose.origin[1]) * 1e6,
            "pitch_err_um": (s["elements"]["pitch"] - 0.3e-3) * 1e6,
            "amp_err_rms_%": 100 * float(np.sqrt(np.mean(err**2))),
            "amp_err_max_%": 100 * float(np.abs(err).max()),
            "dead_found": float([int(idx[i]) for i in s["elements"]["dead"]] == list(dead)),
            "ir_correlation": correlation(ir.ir, ir.sampling_rate, ref, model.ir_sampling_rate),
            "ir_gain_min": float(gain.min()), "ir_gain_max": float(gain.max())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=32)
    parser.add_argument("--sets", nargs="+", default=["columns", "rows"])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--receive", action="store_true",
                        help="also simulate the plate echo and characterize the receive")
    args = parser.parse_args()
    rows = []
    for transmit in args.sets:
        row = run_set(args.n, transmit, args.seed, args.receive)
        print({k: (round(v, 5) if isinstance(v, float) else v) for k, v in row.items()},
              flush=True)
        rows.append(row)
    print_table(rows)


if __name__ == "__main__":
    main()
