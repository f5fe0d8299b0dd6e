"""Benchmark: the bias of the receive IR step alone, over noise draws (issue 10).

The same-sign ripple of |H_est/H_true| seen on every coverage twin is isolated here
from everything before the IR step: each reduced twin of ``uncertainty_coverage.py``
(same draws) is simulated once without noise; the virtual receiver (tilt delays, used
elements) is located once on one noisy draw and then held fixed; the twin's TRUE
element pressure (no projection) is tilt-aligned and averaged with it; and
:func:`holoprobe.characterize.receive_impulse_response` deconvolves ``--draws`` noisy
echoes (fresh Gaussian noise at ``--snr`` dB on the clean RF, SNR as ``simulate``)
for each variant of its keyword arguments. Printed per variant: the mean of
``|H_est/H_true| − 1`` over the draws at a few frequencies, its rms and largest value
in 1.6–3.6 MHz, and the mean per-draw scatter there (the standard error of the mean
is that over √draws). A bias of the estimator shows as a mean that stays when the
draws grow; noise averages out.

    .venv/bin/python benchmarks/receive_ir_bias.py --twins 0 1 --draws 16 --snr 25 \
        --variant onset_margin=0.25e-6 --variant onset_margin=0.75e-6

Clean echoes are cached in ``--cache`` (default /tmp/receive_ir_bias).
"""

from __future__ import annotations

import argparse
import math
import pickle
import warnings
from pathlib import Path

import numpy as np

from holoprobe.characterize import (
    ReceiveConfig,
    aligned_average,
    locate_receiver,
    receive_impulse_response,
    tilt_aligned_average,
)
from holoprobe.signal import continuous_spectrum
from holoprobe.simulate import ArrayModel, simulate_echo
from uncertainty_coverage import C0, draw


def clean_echo(index: int, seed: int, back_wall: bool, cache: Path):
    """The noise-free echo of coverage twin ``index`` (cached)."""
    params = draw(index, seed)
    path = cache / f"{seed}_{index:03d}_{'bw' if back_wall else 'nobw'}.pkl"
    if path.exists():
        return params, *pickle.loads(path.read_bytes())
    model = ArrayModel.from_preset("p4-1", element_count=params["elements"])
    echo, truth = simulate_echo(
        model, plate_distance=params["plate_distance"],
        virtual_tilt=math.radians(params["virtual_tilt_deg"]),
        reflection_coefficient=params["reflection_coefficient"], back_wall=back_wall,
        snr_db=None, points_per_wavelength=3.0,
        start_time=2 * params["plate_distance"] / C0 - 8e-6, n_samples=1000)
    cache.mkdir(parents=True, exist_ok=True)
    path.write_bytes(pickle.dumps((model, echo, truth)))
    return params, model, echo, truth


def _value(text: str) -> float | int | bool | None:
    if text in ("None", "none"):
        return None
    if text in ("true", "false"):
        return text == "true"
    return int(text) if text.lstrip("-").isdigit() else float(text)


def bias_table(index: int, args: argparse.Namespace) -> None:
    params, model, echo, truth = clean_echo(index, args.seed, args.back_wall, args.cache)
    fs, ex = echo.sampling_rate, echo.probe.element_centers()
    rc = ReceiveConfig()
    rng = np.random.default_rng(args.noise_seed)
    rf0 = truth.arrays["rf_clean"].astype(float)
    sigma = np.abs(rf0).max() / 10 ** (args.snr / 20)
    receiver, _ = locate_receiver(rf0 + rng.normal(0, sigma, rf0.shape), fs, echo.start_time,
                                  ex, focus=model.lens_focus, height=model.element_height,
                                  sound_speed=C0, config=rc, notes=[])
    slope, used = receiver.slope, receiver.used
    pressure = tilt_aligned_average(truth.arrays["element_pressure"].astype(float), fs, ex,
                                    slope, used=used)
    f = np.arange(1.2e6, 4.0e6, 0.05e6)
    h_true = np.abs(continuous_spectrum(model.receive_ir, model.ir_sampling_rate, f))
    period = 2 * 12.7e-3 / 5900.0  # the twin's plate: 12.7 mm at 5900 m/s
    variants = [dict(v.split("=", 1) for v in spec.split(",")) if spec else {}
                for spec in (args.variant or [""])]
    ratios: list[list[np.ndarray]] = [[] for _ in variants]
    for _ in range(args.draws):
        y = aligned_average(rf0 + rng.normal(0, sigma, rf0.shape), fs, slope * ex, used=used)
        for k, var in enumerate(variants):
            kw = {key: _value(val) for key, val in var.items()}
            ir = receive_impulse_response(
                y, pressure, fs, voltage_start_time=echo.start_time,
                pressure_start_time=echo.start_time, truncate_before=period,
                noise_window=(echo.start_time, receiver.onset - rc.noise_guard), **kw)
            ratios[k].append(np.abs(continuous_spectrum(ir.ir, ir.sampling_rate, f)) / h_true)
    print(f"twin {index}: {params['elements']} elements, echo {args.snr:g} dB, "
          f"back wall {args.back_wall}, {args.draws} draws")
    mid = (f >= 1.6e6) & (f <= 3.6e6)
    for var, r in zip(variants, ratios, strict=True):
        e = np.asarray(r) - 1.0
        mean, sd = e.mean(axis=0), e.std(axis=0)
        cells = " ".join(f"{a / 1e6:.2f}:{b * 100:+.1f}"
                         for a, b in list(zip(f, mean, strict=True))[::4])
        name = ",".join(f"{a}={b}" for a, b in var.items()) or "defaults"
        print(f"  {name:28s} mid rms {np.sqrt(np.mean(mean[mid] ** 2)) * 100:.2f} % max "
              f"{np.abs(mean[mid]).max() * 100:.2f} % (scatter {sd[mid].mean() * 100:.2f} %)"
              f" | {cells}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--twins", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--seed", type=int, default=2026, help="coverage draw seed")
    ap.add_argument("--draws", type=int, default=16)
    ap.add_argument("--snr", type=float, default=25.0)
    ap.add_argument("--noise-seed", type=int, default=1)
    ap.add_argument("--back-wall", action="store_true")
    ap.add_argument("--variant", action="append",
                    help="comma-separated receive_impulse_response keywords, e.g. "
                         "onset_margin=0.75e-6 (repeatable; none: the defaults)")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/receive_ir_bias"))
    args = ap.parse_args()
    warnings.simplefilter("ignore", UserWarning)
    for index in args.twins:
        bias_table(index, args)


if __name__ == "__main__":
    main()
