"""Drive voltage files: native HDF5 (/drive), the toolkit's TransmitData.mat, CSV."""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

from holoprobe.errors import InputError
from holoprobe.io._matfile import load_mat
from holoprobe.measurement import DriveSignal

__all__ = ["read_drive"]


def read_drive(path: str | os.PathLike, *, field: str = "--drive") -> DriveSignal:
    """A drive voltage from a native HDF5 file, TransmitData.mat or a CSV of (time, volt).

    Parameters
    ----------
    path : str or PathLike
        ``.mat`` (struct ``Transmit`` with ``VoltageSignal`` and ``SamplingRate``),
        ``.h5``/``.hdf5``/``.hdf`` (``/drive/voltage``, ``/drive/sampling_rate``) or a
        CSV with the columns ``time_s, voltage_V`` (uniform, increasing times).
    field : str
        What a missing file is reported as (the CLI's option name).

    Returns
    -------
    DriveSignal
        The voltage in V and its sampling rate in Hz.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if not path.is_file():
        raise InputError("no such file", file=str(path), field=field)
    if suffix == ".mat":
        data = load_mat(path)
        t = data.get("Transmit")
        if not isinstance(t, dict) or "VoltageSignal" not in t or "SamplingRate" not in t:
            raise InputError("expected a struct Transmit with VoltageSignal and SamplingRate",
                             file=str(path), field="Transmit")
        try:
            return DriveSignal(voltage=t["VoltageSignal"], sampling_rate=t["SamplingRate"])
        except InputError as exc:
            raise InputError(exc.detail, file=str(path),
                             field=f"Transmit.{exc.field}") from None
    if suffix in (".h5", ".hdf5", ".hdf"):
        with h5py.File(path, "r") as f:
            if "drive/voltage" not in f or "drive/sampling_rate" not in f:
                raise InputError("expected /drive/voltage and /drive/sampling_rate",
                                 file=str(path), field="drive")
            return DriveSignal(f["drive/voltage"][()], float(f["drive/sampling_rate"][()]))
    try:
        table = np.loadtxt(path, delimiter=",", comments="#", ndmin=2)
    except ValueError as exc:
        raise InputError(f"expected two CSV columns time_s, voltage_V ({exc})",
                         file=str(path)) from None
    if table.shape[1] != 2 or table.shape[0] < 2:
        raise InputError(f"expected two columns time_s, voltage_V, got shape {table.shape}",
                         file=str(path))
    step = np.diff(table[:, 0])
    if np.any(step <= 0) or np.ptp(step) > 1e-6 * step.mean():
        raise InputError("times must be uniform and increasing", file=str(path),
                         field="time_s")
    return DriveSignal(table[:, 1], 1.0 / step.mean())
