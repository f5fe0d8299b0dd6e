"""Files of ``holoprobe hydrophone deconvolve``: pressure.csv, pulse.json, a figure."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from holoprobe.exposure import HydrophonePulse
from holoprobe.io import atomic_write, write_json, write_pressure_csv
from holoprobe.report._figures import plot_hydrophone_deconvolution
from holoprobe.signal import frequency_axis, next_fast_length, to_frequency

__all__ = ["HYDROPHONE_FILES", "plot_hydrophone_pulse", "write_hydrophone_outputs"]

HYDROPHONE_FILES = {"pressure": "pressure.csv", "pulse": "pulse.json",
                    "figure": "deconvolution.png"}
"""Names of the files written into the output directory, by role."""


def _db(values: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return 20 * np.log10(values / values.max())


def plot_hydrophone_pulse(result: HydrophonePulse) -> Figure:
    """The figure of :func:`holoprobe.report.plot_hydrophone_deconvolution` for a
    :class:`holoprobe.exposure.HydrophonePulse` (spectra zero-padded 4×)."""
    d = result.pressure
    n = next_fast_length(4 * d.voltage.size)
    f = frequency_axis(n, d.sampling_rate)
    cal = d.calibration
    return plot_hydrophone_deconvolution(
        d.time, d.voltage, d.pressure, d.u_pressure, f,
        _db(np.abs(to_frequency(d.voltage, n=n))), _db(np.abs(to_frequency(d.pressure, n=n))),
        cal.frequency, 20 * np.log10(cal.sensitivity), cutoff_hz=d.cutoff_hz)


def write_hydrophone_outputs(result: HydrophonePulse, out_dir: str | os.PathLike, *,
                             overwrite: bool = False,
                             protect: tuple[str | os.PathLike, ...] = (),
                             figure: bool = True) -> dict[str, Path]:
    """Write ``pressure.csv`` (time_s, pressure_Pa, u_pressure_Pa), ``pulse.json`` and
    ``deconvolution.png`` into ``out_dir`` (atomically; inputs in ``protect`` are never
    overwritten).

    Returns
    -------
    dict of str to Path
        The files, keyed like :data:`HYDROPHONE_FILES`.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    d = result.pressure
    paths = {k: out / v for k, v in HYDROPHONE_FILES.items()}
    write_pressure_csv(paths["pressure"], d.time, d.pressure, d.u_pressure,
                       overwrite=overwrite, protect=protect)
    write_json(paths["pulse"], result.to_dict(), overwrite=overwrite, protect=protect)
    if figure:
        fig = plot_hydrophone_pulse(result)
        with atomic_write(paths["figure"], overwrite=overwrite, protect=protect) as tmp:
            fig.savefig(tmp, format="png", dpi=110)
    else:
        del paths["figure"]
    return paths
