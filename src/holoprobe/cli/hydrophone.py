"""``holoprobe hydrophone``: one hydrophone record → pressure with its uncertainty.

* ``holoprobe hydrophone deconvolve WAVEFORM.csv --calibration CAL.csv --out DIR``:
  ``DIR/pressure.csv`` (time_s, pressure_Pa, u_pressure_Pa), ``DIR/pulse.json`` (p_c,
  p_r, PII, pulse duration, f_awf and their standard uncertainties ``u_*``) and
  ``DIR/deconvolution.png``; see :func:`holoprobe.exposure.hydrophone_pulse` and
  :func:`holoprobe.report.write_hydrophone_outputs`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from holoprobe.cli._app import OutputDirectory, new_app

__all__ = ["app"]

app = new_app("Hydrophone records: deconvolution with a (complex) calibration.")


@app.command()
def deconvolve(
    waveform: Annotated[Path, typer.Argument(help="CSV with header time_s,voltage_V.")],
    calibration: Annotated[Path, typer.Option(
        "--calibration", help="Calibration: complex CSV (frequency_Hz,magnitude_V_per_Pa,"
                              "phase_rad[,u_…]), HDF5, amplitude-only CSV or .mat.")],
    out: OutputDirectory,
    cutoff_hz: Annotated[float | None, typer.Option(
        "--cutoff-hz", help="−3 dB frequency of the regularising low-pass (Hz); default: "
                            "from the noise and the calibration's range.")] = None,
    filter_order: Annotated[int, typer.Option(help="Order of the low-pass.")] = 8,
    outside: Annotated[str, typer.Option(
        help="Calibration outside its range: hold or extrapolate.")] = "hold",
    amplitude_only_phase: Annotated[str, typer.Option(
        help="Phase for an amplitude-only calibration: minimum or zero.")] = "minimum",
    keep_offset: Annotated[bool, typer.Option(
        "--keep-offset", help="Do not remove the DC offset.")] = False,
    draws: Annotated[int, typer.Option(help="Monte Carlo draws for the pulse "
                                            "parameters' uncertainties.")] = 200,
    overwrite: Annotated[bool, typer.Option(help="Replace existing output files.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", help="Print nothing.")] = False,
) -> None:
    """Deconvolve a hydrophone record: pressure.csv, pulse.json, deconvolution.png."""
    from holoprobe.exposure import PULSE_KEYS, hydrophone_pulse
    from holoprobe.io import read_waveform_csv
    from holoprobe.report import write_hydrophone_outputs
    from holoprobe.signal import HydrophoneDeconvolutionConfig, load_calibration

    t, v, fs = read_waveform_csv(waveform)
    cal = load_calibration(calibration)
    cfg = HydrophoneDeconvolutionConfig(
        # (type: ignore below) typer gives a str; the config checks the literal
        cutoff_hz=cutoff_hz, filter_order=filter_order, outside=outside,  # type: ignore[arg-type]
        # (type: ignore below) typer gives a str; the config checks the literal
        amplitude_only_phase=amplitude_only_phase,  # type: ignore[arg-type]
        remove_offset=not keep_offset)
    result = hydrophone_pulse(v, fs, cal, config=cfg, start_time=float(t[0]), n_draws=draws)
    files = write_hydrophone_outputs(result, out, overwrite=overwrite,
                                     protect=(waveform, calibration))
    if quiet:
        return
    par = result.parameters
    typer.echo(f"cut-off {result.pressure.cutoff_hz / 1e6:.3g} MHz, offset "
               f"{result.pressure.offset * 1e3:.4g} mV, noise "
               f"{result.pressure.noise_sigma * 1e3:.3g} mV")
    for key in PULSE_KEYS:
        typer.echo(f"{key:18s} {par.values[key]:.5g} ± {par.uncertainties[key]:.2g} (k=1)")
    for path in files.values():
        typer.echo(str(path))
