"""Convex-array twin → transmit characterization: errors against the truth.

Usage: python benchmarks/convex.py [--elements 48] [--seed 1] [--size-mm 40 20]
       [--cache scan.pkl]  (the twin's scan: read when the file exists, else written)

The C5-2-like geometry (pitch 0.508 mm, R = 49.6 mm, width 0.45 mm, H = 13.5 mm,
F = 60 mm, 3.6 MHz Gaussian IR), element variation 5 % / 5 ns, a tilted scan plane
10 mm above the apex, 40 dB SNR. Prints every error with the reported uncertainty and
the run times; asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import pickle
import time

import numpy as np

from holoprobe.characterize import CharacterizationConfig, characterize_convex_transmit
from holoprobe.geometry import Pose
from holoprobe.simulate import ArrayModel, rectangular_pulse, simulate_scan


def convex_model(n: int, seed: int, height: float = 13.5e-3, focus: float = 60e-3
                 ) -> ArrayModel:
    fs = 250e6
    t = np.arange(int(1.5e-6 * fs)) / fs
    ir = np.exp(-0.5 * ((t - 0.6e-6) / 0.15e-6) ** 2) * np.cos(2 * np.pi * 3.6e6
                                                                 * (t - 0.6e-6)) * 1e11
    model = ArrayModel(element_count=n, pitch=0.508e-3, element_width=0.45e-3,
                       element_height=height, lens_focus=focus, transmit_ir=ir,
                       receive_ir=ir, ir_sampling_rate=fs,
                       drive=rectangular_pulse(sampling_rate=fs), center_frequency=3.6e6,
                       radius_of_curvature=49.6e-3, name=f"C5-2-like-{n}")
    return model.with_element_variation(amplitude_rms=0.05, delay_rms=5e-9, seed=seed)


def _print_ir(ir, model: ArrayModel) -> None:
    """Transmit IR against the model's h_T and against the mean of the elements'
    (h̄: apodization a_e and delay τ_e each, H̄ = H mean_e a_e e^{−iωτ_e}), the mean
    surface velocity's IR that the aperture mean measures: correlation, peak ratio,
    least-squares scale at the best lag, |H_est/H̄| at a few frequencies."""
    fs = ir.sampling_rate
    ref = np.interp(np.arange(ir.ir.size) / fs,
                    np.arange(model.transmit_ir.size) / model.ir_sampling_rate,
                    model.transmit_ir, right=0.0)
    f = np.fft.rfftfreq(ref.size, 1 / fs)
    coherence = (np.asarray(model.apodization)[:, None]
                 * np.exp(-2j * np.pi * np.outer(model.delays, f))).mean(axis=0)
    mean_ref = np.fft.irfft(np.fft.rfft(ref) * coherence, ref.size)
    h_est = np.fft.rfft(ir.ir)
    for name, r in (("h_T", ref), ("element mean", mean_ref)):
        xc = np.correlate(ir.ir, r, "full")
        corr = xc.max() / np.linalg.norm(ir.ir) / np.linalg.norm(r)
        print(f"IR vs {name:12s} correlation {corr:.4f}, peak ratio "
              f"{np.abs(ir.ir).max() / np.abs(r).max():.4f}, least-squares scale "
              f"{xc.max() / np.dot(r, r):.4f}")
    h_mean = np.fft.rfft(mean_ref)
    picks = [int(np.argmin(np.abs(f - fm * 1e6))) for fm in (2.0, 3.0, 3.6, 4.2, 5.0)]
    print("|H_est/H̄| at 2, 3, 3.6, 4.2, 5 MHz:",
          " ".join(f"{abs(h_est[i]) / abs(h_mean[i]):.4f}" for i in picks))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--elements", type=int, default=48)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--size-mm", type=float, nargs=2, default=(40.0, 20.0))
    ap.add_argument("--step-mm", type=float, default=0.2)
    ap.add_argument("--height-mm", type=float, default=13.5)
    ap.add_argument("--focus-mm", type=float, default=60.0)
    ap.add_argument("--distance-mm", type=float, default=10.0)
    ap.add_argument("--points-per-wavelength", type=float, default=4.0,
                    help="twin quadrature (2 makes a 128-element twin affordable)")
    ap.add_argument("--twin-band-mhz", type=float, nargs=2, default=None,
                    help="band the twin simulates (default: its -30 dB band)")
    ap.add_argument("--cache", default=None,
                    help="pickle of the twin's scan: read if it exists, else written")
    ap.add_argument("--set", action="append", default=[],
                    help="configuration override, e.g. convex.iterations=4")
    args = ap.parse_args()
    model = convex_model(args.elements, args.seed, args.height_mm * 1e-3,
                         args.focus_mm * 1e-3)
    pose = Pose.from_degrees(0.35, -0.6, 0.8, (0.2e-3, -0.15e-3, args.distance_mm * 1e-3))
    t = time.perf_counter()
    if args.cache is not None and os.path.exists(args.cache):
        with open(args.cache, "rb") as fh:
            scan = pickle.load(fh)
    else:
        scan, _ = simulate_scan(model, pose=pose, size=tuple(s * 1e-3 for s in args.size_mm),
                                step=(args.step_mm * 1e-3,) * 2, sampling_rate=25e6,
                                n_samples=512, snr_db=40, seed=args.seed,
                                points_per_wavelength=args.points_per_wavelength,
                                band=None if args.twin_band_mhz is None
                                else tuple(f * 1e6 for f in args.twin_band_mhz))
        if args.cache is not None:
            with open(args.cache, "wb") as fh:
                pickle.dump(scan, fh)
    t_sim = time.perf_counter() - t
    t, c = time.perf_counter(), time.process_time()
    cfg = CharacterizationConfig().with_overrides(args.set)
    res = characterize_convex_transmit(scan, cfg, radius_of_curvature=50.5e-3, progress=False)
    t_char, c_char = time.perf_counter() - t, time.process_time() - c
    print(f"elements {args.elements}, scan {scan.data.shape}, twin {t_sim:.0f} s, "
          f"characterization {t_char:.1f} s wall, {c_char:.1f} s CPU, load "
          f"{os.getloadavg()[0]:.1f}; {res.timings}")
    u = np.degrees(res.angle_uncertainties)
    for name, got, want, unc in zip(("theta_x", "theta_y", "theta_z"), res.pose.angles_deg,
                                    pose.angles_deg, u, strict=True):
        print(f"{name:8s} error {got - want:+.4f} deg  ± {unc:.4f}")
    r = model.radius_of_curvature
    print(f"R        error {(res.radius_of_curvature - r) * 1e6:+.1f} µm "
          f"({(res.radius_of_curvature / r - 1) * 100:+.3f} %) ± "
          f"{res.radius_uncertainty * 1e6:.1f} µm")
    print(f"arc W    error {(res.aperture.width - model.aperture_width) * 1e6:+.1f} µm "
          f"± {res.aperture.width_uncertainty * 1e6:.1f}")
    print(f"H        error {(res.aperture.height - model.element_height) * 1e6:+.1f} µm "
          f"± {res.aperture.height_uncertainty * 1e6:.1f}")
    lens_u = res.lens.focus_uncertainty if res.lens is not None else float("nan")
    print(f"F        error {(res.lens_focus / model.lens_focus - 1) * 100:+.2f} % "
          f"± {lens_u / model.lens_focus * 100:.2f} %")
    print(f"elements {res.element_count} (true {model.element_count})")
    pitches = [h["apparent_pitch"] for h in res.history if h["apparent_pitch"]]
    if pitches:  # the element pattern's period on each pass's trial cylinder
        print(f"pitch    first pass {(pitches[0] / model.pitch - 1) * 100:+.3f} %, last "
              f"{(pitches[-1] / model.pitch - 1) * 100:+.3f} % (on the fitted cylinder)")
    if res.element_map is not None:
        amp = np.asarray(model.apodization) / np.mean(model.apodization)
        err = res.element_map.relative_amplitude - amp
        print(f"amplitudes max |error| {np.abs(err).max() * 100:.2f} %, rms "
              f"{np.sqrt(np.mean(err**2)) * 100:.2f} %, mean σ "
              f"{res.element_map.amplitude_uncertainty.mean() * 100:.2f} %")
    if res.impulse_response is not None:
        _print_ir(res.impulse_response, model)
    for h in res.history:
        print(f"iteration {h['iteration']}: R {h['radius_of_curvature'] * 1e3:.4f} mm, "
              f"updates {np.round(np.asarray(h['update']) * 1e6, 2)} (µm / µrad)")
    print("warnings:", res.warnings)


if __name__ == "__main__":
    main()
