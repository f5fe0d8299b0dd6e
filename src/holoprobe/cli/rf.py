"""``holoprobe rf``: per-element RF of the virtual transducer for point scatterers.

A thin shell over :func:`holoprobe.transducer.simulate_rf`. The scatterers CSV has
one scatterer per line: ``x, y, z`` in mm and an optional scattering amplitude in
mm (default 0.1 mm; the echo is ``a p_inc e^{ikR}/R``). ``rf.h5`` (written
atomically) holds ``rf`` (n_elements, n_samples) in the unit of the receive IR
times Pa·s, ``time`` (s), ``scatterers`` (m), ``amplitudes`` (m), the transmit
setting's TOML text and the inputs; ``rf.png`` shows the element RF as an
envelope image in dB (depth axis c0 t / 2).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from holoprobe.cli._app import OutputDirectory, TransmitSetting, VirtualTransducerPath

__all__ = ["rf"]


def rf(
    virtual_transducer: VirtualTransducerPath,
    transmit: TransmitSetting,
    scatterers: Annotated[Path, typer.Option(
        "--scatterers", help="CSV: x, y, z in mm [, amplitude in mm].")],
    out: OutputDirectory,
    sampling_rate: Annotated[float | None, typer.Option(
        "--sampling-rate", help="RF sampling rate in MHz (default 8 × band top).")] = None,
    n_samples: Annotated[int | None, typer.Option(
        "--n-samples", help="Record length (default: the latest echo fits).")] = None,
    default_amplitude: Annotated[float, typer.Option(
        "--amplitude", help="Scattering amplitude in mm where the CSV has none.")] = 0.1,
    dynamic_range: Annotated[float, typer.Option(
        "--dynamic-range", help="Dynamic range of the image in dB.")] = 50.0,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
    overwrite: Annotated[bool, typer.Option(help="Replace existing outputs.")] = False,
) -> None:
    """Per-element received RF of point scatterers (rf.h5) and an envelope image (rf.png)."""
    from holoprobe._progress import progress_task
    from holoprobe.cli.field import read_points_csv
    from holoprobe.errors import InputError
    from holoprobe.io import write_rf
    from holoprobe.transducer import TransmitSetting, VirtualTransducer, rf_units, simulate_rf

    vt = VirtualTransducer.load(virtual_transducer)
    if not vt.has_receive:
        raise InputError("the virtual transducer has no receive impulse response; rf needs "
                         "one", file=str(virtual_transducer), field="receive_impulse_response")
    setting = TransmitSetting.from_toml(transmit)
    table = read_points_csv(scatterers, columns=4, name="--scatterers")
    pos = table[:, :3] * 1e-3
    amp = np.where(np.isnan(table[:, 3]), default_amplitude, table[:, 3]) * 1e-3
    if np.any(pos[:, 2] <= 0):
        raise InputError("scatterers must lie in front of the probe (z > 0 mm)",
                         file=str(scatterers), field="--scatterers")
    fs = None if sampling_rate is None else sampling_rate * 1e6
    with progress_task(1.0, description="rf", enabled=False if quiet else None) as advance:
        state = {"done": 0.0}

        def report(done: int, total: int) -> None:
            frac = done / max(total, 1)
            advance(max(0.0, frac - state["done"]))
            state["done"] = frac

        from holoprobe.transducer import signal_band

        fs = 8.0 * signal_band(vt, setting)[1] if fs is None else fs
        data = simulate_rf(vt, setting, pos, amp, sampling_rate=fs, n_samples=n_samples,
                           progress=report)
    time = np.arange(data.shape[1]) / fs
    unit = rf_units(vt)
    protect = [virtual_transducer, transmit, scatterers]
    write_rf(out / "rf.h5", data, time, pos, amp, unit=unit, sampling_rate=fs,
             provenance={"virtual_transducer": str(virtual_transducer),
                         "transmit_file": str(transmit),
                         "transmit_setting_toml": Path(transmit).read_text(encoding="utf-8")},
             overwrite=overwrite, protect=protect)
    _image(out / "rf.png", data, time, vt.medium.sound_speed, unit, dynamic_range, overwrite,
           protect)
    if not quiet:
        typer.echo(f"rf: {data.shape[0]} elements × {data.shape[1]} samples at "
                   f"{fs / 1e6:.3g} MHz, {pos.shape[0]} scatterers -> {out}")


def _image(path, data, time, c0, unit, dynamic_range, overwrite, protect) -> None:
    from matplotlib.figure import Figure

    from holoprobe.io import atomic_write
    from holoprobe.signal import envelope

    env = envelope(data, axis=1, pad=False)
    top = float(env.max())
    db = 20 * np.log10(np.maximum(env, top * 10 ** (-dynamic_range / 20) if top > 0 else 1.0)
                       / (top if top > 0 else 1.0))
    fig = Figure(figsize=(5.6, 6.4), layout="constrained")
    ax = fig.add_subplot()
    n = data.shape[0]
    depth = c0 * time / 2 * 1e3
    im = ax.imshow(db.T, aspect="auto", cmap="gray", vmin=-dynamic_range, vmax=0,
                   extent=(0.5, n + 0.5, float(depth[-1]), float(depth[0])),
                   interpolation="nearest")
    ax.set_xlabel("element")
    ax.set_ylabel("depth c0·t/2 (mm)")
    ax.set_title(f"element RF envelope (peak {top:.3g} {unit})")
    fig.colorbar(im, ax=ax, label="envelope (dB re max)")
    with atomic_write(path, overwrite=overwrite, protect=protect) as tmp:
        fig.savefig(tmp, dpi=120)
