"""Benchmark: holoprobe's predicted field of a P4-1 virtual transducer vs k-wave-python.

Issue 6 acceptance: "the field of a P4-1 virtual transducer predicted by holoprobe agrees
with k-wave-python (Python backend, small 3-D grid, monopole source) on axis at 5 mm and
in a focal plane: max difference ≤ 3 % of the peak" (the paper reports 2.1 % for
monopoles, section II C).

The virtual transducer is the packaged P4-1 (measured transmit IR, pitch, kerf, lens
F = 180.7 mm), cut to ``--elements`` elements and ``--height-mm`` elevation so that the
grid stays small. The transmit is a 2-cycle 2.5 MHz burst focused on the axis at
``--depth-mm`` (5 mm). k-wave-python's pure-Python backend propagates the monopole
source of :func:`holoprobe.export.kwave_source` (``source.p = ρ0 c0 u``, off-grid
``kWaveArray`` strips) and records the pressure on the focal plane (parallel to the
array face, through the focus). holoprobe predicts the same points with
:func:`holoprobe.transducer.predict_field` (dense Rayleigh integral, paper eq.
rayleigh-fwd-vp). Printed: the on-axis waveform difference at the focus and the
largest waveform and peak-pressure differences over the focal plane, each in % of the
peak. k-Wave's additive pressure source acts half a time step before the sample time of
its signal (see the comment in :func:`compare_with_kwave`); holoprobe is evaluated at
(n + ½)·dt, and the residual delay is printed.

Measured (2 shared cores, k-wave-python 0.6.2, float32): 8 elements, H = 3 mm,
dx = 0.125 mm, grid 47 × 37 × 41 + PML, 336 steps: k-Wave 100 s; on axis at 5 mm
0.59 %, focal plane 0.76 % (waveforms), 0.16 % (peak pressure), residual delay 0.
16 elements, full height H = 14.28 mm: grid 47 × 55 × 133 + PML, 613 steps, k-Wave
322 s (source 52 s): on axis 1.02 %, focal plane 1.02 % (waveforms), 0.64 % (peak).

Needs k-wave-python (``pip install holoprobe[kwave]``; offline see ``docs/kwave.md``),
run from the repository root, e.g.::

    PYTHONPATH=src /tmp/kwenv/bin/python benchmarks/kwave_comparison.py
    PYTHONPATH=src /tmp/kwenv/bin/python benchmarks/kwave_comparison.py --elements 16 \
        --height-mm 6 --dx-mm 0.1
"""

from __future__ import annotations

import argparse
import math
import os
import time
from dataclasses import dataclass

import numpy as np


@dataclass
class Comparison:
    """Differences between k-Wave and holoprobe (fractions of holoprobe's peak)."""

    axis_waveform: float
    plane_waveform: float
    plane_peak: float
    residual_lag: float
    peak_pressure: float
    peak_pressure_kwave: float
    grid: tuple[int, int, int]
    steps: int
    seconds_kwave: float
    seconds_holoprobe: float
    seconds_source: float
    time: np.ndarray | None = None
    axis_kwave: np.ndarray | None = None
    axis_holoprobe: np.ndarray | None = None


def relative_delay(a: np.ndarray, b: np.ndarray, *, upsample: int = 16) -> float:
    """Delay of ``a`` relative to ``b`` in samples (peak of the Fourier-upsampled
    cross-correlation; negative: ``a`` is earlier)."""
    n = 2 * a.size
    xc = np.fft.irfft(np.fft.rfft(a, n) * np.conj(np.fft.rfft(b, n)), n * upsample)
    k = int(np.argmax(xc))
    return (k if k < xc.size // 2 else k - xc.size) / upsample


def compare_with_kwave(*, elements: int = 8, height: float = 3e-3, dx: float = 0.125e-3,
                       depth: float = 5e-3, lateral_margin: float = 1.0e-3,
                       elevation_margin: float = 1.0e-3, beyond: int = 6,
                       cfl: float = 0.3, pml: int = 10, frequency: float = 2.5e6,
                       cycles: float = 2.0, voltage: float = 30.0,
                       dtype: type = np.float32, quiet: bool = True) -> Comparison:
    """Run one comparison (see the module docstring); lengths in m.

    The grid has ``dx`` in every direction: x (propagation) from one step behind the
    array face to ``beyond`` steps past the focal plane, y (lateral) and z (elevation)
    the aperture plus the margins on each side; a PML of ``pml`` points lies outside.
    The time step is ``cfl·dx/c0``; the record ends when the last possible arrival at
    the focal plane plus the signal duration has passed.
    """
    from holoprobe.export import kwave_source, prepare_kwave_offline
    from holoprobe.transducer import TransmitSetting, VirtualTransducer, burst, predict_field

    prepare_kwave_offline()
    from kwave.data import Vector
    from kwave.kgrid import kWaveGrid
    from kwave.kmedium import kWaveMedium
    from kwave.ksensor import kSensor
    from kwave.kspaceFirstOrder import kspaceFirstOrder

    vt = VirtualTransducer.from_preset("p4-1").replace(
        element_count=elements, element_height=height, aperture_width=None,
        aperture_height=None)
    c0, rho0 = vt.medium.sound_speed, vt.medium.density
    setting = TransmitSetting.focused((0.0, 0.0, depth), drive=burst(frequency, cycles,
                                                                      voltage))
    steps = round(depth / dx)
    if not math.isclose(steps * dx, depth, rel_tol=1e-9):
        raise ValueError(f"the depth {depth} m is not a whole number of steps {dx} m")
    half_w = 0.5 * (vt.aperture_width or 0.0) + lateral_margin
    half_h = 0.5 * height + elevation_margin
    nx = steps + 1 + beyond
    ny = 2 * math.ceil(half_w / dx) + 1
    nz = 2 * math.ceil(half_h / dx) + 1
    kgrid = kWaveGrid(Vector([nx, ny, nz]), Vector([dx, dx, dx]))
    dt = cfl * dx / c0
    far = math.sqrt(depth**2 + (2 * half_w) ** 2 + (2 * half_h) ** 2)
    duration = (vt.transmit_impulse_response.size / vt.transmit_sampling_rate
                + setting.drive.duration)
    delays = setting.element_delays(vt.element_centers(), c0)
    nt = math.ceil((far / c0 + duration + float(delays.max())) / dt) + 1
    kgrid.setTime(nt, dt)
    x_vec = np.asarray(kgrid.x_vec).reshape(-1)
    ix_face = 1
    ix_plane = ix_face + steps

    t = time.perf_counter()
    source = kwave_source(vt, setting, kgrid, representation="monopole")
    seconds_source = time.perf_counter() - t
    mask = np.zeros((nx, ny, nz), dtype=bool)
    mask[ix_plane] = True
    sensor = kSensor(mask)
    sensor.record = ["p"]
    medium = kWaveMedium(sound_speed=c0, density=rho0)
    t = time.perf_counter()
    result = kspaceFirstOrder(kgrid, medium, source, sensor, backend="python", device="cpu",
                              pml_size=pml, pml_inside=False, dtype=dtype, quiet=quiet)
    seconds_kwave = time.perf_counter() - t
    p_kw = np.asarray(result["p"], dtype=float).reshape(ny, nz, nt)

    # the same points in holoprobe coordinates: x lateral (k-Wave y), y elevation
    # (k-Wave z), z the distance from the array face
    y_vec = np.asarray(kgrid.y_vec).reshape(-1)
    z_vec = np.asarray(kgrid.z_vec).reshape(-1)
    lat, elev = np.meshgrid(y_vec, z_vec, indexing="ij")
    points = np.stack([lat.ravel(), elev.ravel(),
                       np.full(lat.size, x_vec[ix_plane] - x_vec[ix_face])], axis=-1)
    # k-Wave's time axis: its additive pressure (mass) source adds sample n of
    # source.p to the density in the update that ends at t_n = n·dt, i.e. it acts over
    # ((n − 1)·dt, n·dt], centred on (n − ½)·dt, while the recorded p[n] is at t_n. The
    # signals of kwave_source are the source at t = n·dt, so k-Wave's field is the true
    # one advanced by dt/2: p_kw[n] = p((n + ½)·dt). holoprobe is evaluated there.
    t = time.perf_counter()
    pred = predict_field(vt, setting, points, sampling_rate=1.0 / dt, start_time=0.5 * dt,
                         n_samples=2 * nt, method="rayleigh")
    seconds_holoprobe = time.perf_counter() - t
    p_hp = pred.pressure[:, :nt].reshape(ny, nz, nt)

    peak = float(np.abs(p_hp).max())
    iy, iz = ny // 2, nz // 2  # the axis: y = z = 0 on k-Wave's grid
    axis = float(np.abs(p_kw[iy, iz] - p_hp[iy, iz]).max()) / peak
    plane = float(np.abs(p_kw - p_hp).max()) / peak
    peak_map = float(np.abs(np.abs(p_kw).max(axis=-1) - np.abs(p_hp).max(axis=-1)).max()) / peak
    lag = relative_delay(p_kw[iy, iz], p_hp[iy, iz])
    return Comparison(axis, plane, peak_map, lag, peak, float(np.abs(p_kw).max()), (nx, ny, nz), nt,
                      seconds_kwave, seconds_holoprobe, seconds_source, np.arange(nt) * dt,
                      p_kw[iy, iz], p_hp[iy, iz])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--elements", type=int, default=8)
    parser.add_argument("--height-mm", type=float, default=3.0)
    parser.add_argument("--dx-mm", type=float, default=0.125)
    parser.add_argument("--depth-mm", type=float, default=5.0)
    parser.add_argument("--float64", action="store_true", help="k-Wave in float64")
    parser.add_argument("--cores", type=int, default=2)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        cpus = sorted(os.sched_getaffinity(0))[: args.cores]
        os.sched_setaffinity(0, set(cpus))
    r = compare_with_kwave(elements=args.elements, height=args.height_mm * 1e-3,
                           dx=args.dx_mm * 1e-3, depth=args.depth_mm * 1e-3,
                           dtype=np.float64 if args.float64 else np.float32)
    print(f"P4-1 virtual transducer, {args.elements} elements, H = {args.height_mm} mm, "
          f"focus on axis at {args.depth_mm} mm; grid {r.grid} (+PML), dx = {args.dx_mm} mm,"
          f" {r.steps} steps")
    print(f"k-wave-python (python backend): {r.seconds_kwave:.1f} s (source "
          f"{r.seconds_source:.1f} s); holoprobe predict_field: {r.seconds_holoprobe:.1f} s")
    print(f"peak pressure: holoprobe {r.peak_pressure / 1e3:.1f} kPa, k-Wave "
          f"{r.peak_pressure_kwave / 1e3:.1f} kPa")
    print(f"residual delay of k-Wave's on-axis waveform: {r.residual_lag:+.3f} dt (after the "
          "half-step source convention)")
    print(f"on axis at {args.depth_mm} mm, max |Δp(t)|: {100 * r.axis_waveform:.2f} % of the "
          f"peak (acceptance ≤ 3 %)")
    print(f"focal plane, max |Δp(t)| over all points: {100 * r.plane_waveform:.2f} %; "
          f"max |Δ peak pressure|: {100 * r.plane_peak:.2f} % of the peak (acceptance ≤ 3 %)")


if __name__ == "__main__":
    main()
