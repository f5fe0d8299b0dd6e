"""Writing a simulated measurement and its truth to a directory."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

from holoprobe.errors import InputError
from holoprobe.io import write_echo, write_reference_echo, write_reference_scan, write_scan
from holoprobe.measurement import EchoRecording, HydrophoneScan
from holoprobe.simulate._truth import SimulationTruth

__all__ = ["NATIVE_ECHO_FILE", "NATIVE_SCAN_FILE", "write_simulation"]

NATIVE_SCAN_FILE = "scan.h5"
NATIVE_ECHO_FILE = "echo.h5"


def write_simulation(directory: str | os.PathLike,
                     measurement: HydrophoneScan | EchoRecording,
                     truth: SimulationTruth, *,
                     format: Literal["native", "reference-mat"] = "native",
                     mat_version: str = "5", overwrite: bool = False) -> list[Path]:
    """Write a simulated measurement (native HDF5 or the published .mat layout) + truth.

    Parameters
    ----------
    directory : str or PathLike
        Output directory (created if missing).
    measurement : HydrophoneScan or EchoRecording
        What :func:`simulate_scan` / :func:`simulate_echo` returned.
    truth : SimulationTruth
        Written as ``truth.json`` (parameters) and ``truth.h5`` (arrays).
    format : {"native", "reference-mat"}
        ``native``: ``scan.h5`` / ``echo.h5`` (schema in ``docs/formats.md``);
        ``reference-mat``: ScanData.mat, sensitivity.mat, TransmitData.mat /
        ReceiveData.mat (reference_spec section 4).
    mat_version : {"5", "7.3"}
        MAT-file version for ``reference-mat``.
    overwrite : bool
        Replace existing files.

    Returns
    -------
    list of pathlib.Path
        The files written.
    """
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    if format not in ("native", "reference-mat"):
        raise InputError(f"expected 'native' or 'reference-mat', got {format!r}",
                         field="format")
    written: list[Path] = []
    if isinstance(measurement, HydrophoneScan):
        if format == "native":
            written.append(write_scan(out / NATIVE_SCAN_FILE, measurement,
                                      overwrite=overwrite))
        else:
            written += write_reference_scan(out, measurement, version=mat_version,
                                            overwrite=overwrite)
    elif isinstance(measurement, EchoRecording):
        if format == "native":
            written.append(write_echo(out / NATIVE_ECHO_FILE, measurement,
                                      overwrite=overwrite))
        else:
            written.append(write_reference_echo(out, measurement, version=mat_version,
                                                overwrite=overwrite))
    else:
        raise InputError("expected a HydrophoneScan or an EchoRecording", field="measurement")
    written += list(truth.write(out, overwrite=overwrite))
    return written
