"""Writing a simulated measurement and its truth to a directory."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal

from holoprobe.errors import InputError
from holoprobe.io import (
    NATIVE_FILES,
    write_echo,
    write_hologram,
    write_hologram_mat,
    write_reference_echo,
    write_reference_scan,
    write_scan,
)
from holoprobe.measurement import EchoRecording, Hologram, HydrophoneScan
from holoprobe.simulate._truth import SimulationTruth

__all__ = ["HOLOGRAM_MAT_FILE", "NATIVE_ECHO_FILE", "NATIVE_HOLOGRAM_FILE", "NATIVE_SCAN_FILE",
           "write_simulation"]

NATIVE_SCAN_FILE = NATIVE_FILES["scan"]
NATIVE_ECHO_FILE = NATIVE_FILES["receive"]
NATIVE_HOLOGRAM_FILE = NATIVE_FILES["hologram"]
HOLOGRAM_MAT_FILE = "hologram.mat"


def write_simulation(directory: str | os.PathLike,
                     measurement: HydrophoneScan | EchoRecording | Hologram,
                     truth: SimulationTruth, *,
                     format: Literal["native", "reference-mat"] = "native",
                     mat_version: str = "5", overwrite: bool = False,
                     mat_options: dict | None = None) -> list[Path]:
    """Write a simulated measurement (native HDF5 or the published .mat layout) + truth.

    Parameters
    ----------
    directory : str or PathLike
        Output directory (created if missing).
    measurement : HydrophoneScan, EchoRecording or Hologram
        What :func:`simulate_scan` / :func:`simulate_echo` / :func:`simulate_hologram`
        returned.
    truth : SimulationTruth
        Written as ``truth.json`` (parameters) and ``truth.h5`` (arrays).
    format : {"native", "reference-mat"}
        ``native``: ``scan.h5`` / ``echo.h5`` (schema in ``docs/formats.md``);
        ``reference-mat``: ScanData.mat, sensitivity.mat, TransmitData.mat /
        ReceiveData.mat (reference_spec section 4). A hologram: ``hologram.h5`` or
        ``hologram.mat`` (the holography community's layout).
    mat_version : {"5", "7.3"}
        MAT-file version for ``reference-mat``.
    overwrite : bool
        Replace existing files.
    mat_options : dict, optional
        Holograms: keywords of :func:`holoprobe.io.write_hologram_mat` (``exp_sign``,
        ``grid_layout``, ``descending``).

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
    elif isinstance(measurement, Hologram):
        if format == "native":
            written.append(write_hologram(out / NATIVE_HOLOGRAM_FILE, measurement,
                                          overwrite=overwrite))
        else:
            written.append(write_hologram_mat(out / HOLOGRAM_MAT_FILE, measurement,
                                              version=mat_version, overwrite=overwrite,
                                              **(mat_options or {})))
    else:
        raise InputError("expected a HydrophoneScan, an EchoRecording or a Hologram",
                         field="measurement")
    written += list(truth.write(out, overwrite=overwrite))
    return written
