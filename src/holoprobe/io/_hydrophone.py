"""Hydrophone files: complex calibrations (CSV, HDF5), single waveforms and their results.

Layouts (``docs/formats.md``, section "Hydrophone calibration and waveforms"):

* **Complex calibration CSV**: ``#`` comment lines (``# polarity: -1`` optional), then
  the header ``frequency_Hz,magnitude_V_per_Pa,phase_rad[,u_magnitude_V_per_Pa,
  u_phase_rad]``. The phase is that of ``M(f) = U(f)/P(f)`` with numpy's forward FFT
  (``exp(−i2πft)``), as calibration certificates give it; uncertainties are standard
  (k = 1).
* **Calibration HDF5**: the same columns as 1-D datasets at the root, attributes
  ``format = "holoprobe-hydrophone-calibration"``, ``phase_convention = "fft"``,
  ``polarity``, ``name``.
* **Waveform CSV**: header ``time_s,voltage_V``, uniformly sampled.
* **Pressure CSV** (output): ``time_s,pressure_Pa,u_pressure_Pa``.
"""

from __future__ import annotations

import csv
import io as _io
import os
import re
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.io._atomic import atomic_write
from holoprobe.measurement import HydrophoneCalibration

__all__ = [
    "CALIBRATION_FORMAT",
    "COMPLEX_CALIBRATION_COLUMNS",
    "is_complex_calibration",
    "read_complex_calibration",
    "read_csv_columns",
    "read_waveform_csv",
    "write_calibration_h5",
    "write_pressure_csv",
]

CALIBRATION_FORMAT = "holoprobe-hydrophone-calibration"
COMPLEX_CALIBRATION_COLUMNS = ("frequency_Hz", "magnitude_V_per_Pa", "phase_rad",
                               "u_magnitude_V_per_Pa", "u_phase_rad")
_H5_SUFFIXES = (".h5", ".hdf5", ".he5")
_POLARITY_RE = re.compile(r"polarity\s*[:=]\s*([+-]?1)\b", re.IGNORECASE)


def read_csv_columns(path: str | os.PathLike) -> tuple[dict[str, NDArray], dict[str, str]]:
    """Numeric columns of a CSV file with ``#`` comment lines and one header line.

    Parameters
    ----------
    path : str or PathLike
        The file.

    Returns
    -------
    columns : dict of str to ndarray, shape (rows,)
        One float array per header name.
    comments : dict of str to str
        ``key: value`` pairs found in the comment lines (keys lower case).

    Raises
    ------
    InputError
        Unreadable file, no header, ragged rows or a cell that is not a number (the
        message names the file, the column and the row).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the file ({exc})", file=str(path)) from None
    comments: dict[str, str] = {}
    body = []
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("#"):
            key, sep, value = stripped.lstrip("#").partition(":")
            if sep:
                comments[key.strip().lower()] = value.strip()
            continue
        if stripped:
            body.append(stripped)
    if not body:
        raise InputError("no header line with column names", file=str(path))
    rows = list(csv.reader(_io.StringIO("\n".join(body))))
    header = [h.strip() for h in rows[0]]
    data = rows[1:]
    columns: dict[str, list[float]] = {h: [] for h in header}
    for i, row in enumerate(data, start=1):
        if len(row) != len(header):
            raise InputError(f"data row {i} has {len(row)} values, expected {len(header)} "
                             f"(one per column of the header)", file=str(path))
        for name, cell in zip(header, row, strict=True):
            try:
                columns[name].append(float(cell))
            except ValueError:
                raise InputError(f"data row {i}: expected a number, got {cell.strip()!r}",
                                 file=str(path), field=name) from None
    return {k: np.asarray(v, float) for k, v in columns.items()}, comments


def _polarity(value: Any, path: Path) -> int:
    try:
        pol = int(float(value))
    except (TypeError, ValueError):
        pol = 0
    if pol not in (1, -1):
        raise InputError(f"expected 1 or -1, got {value!r}", file=str(path), field="polarity")
    return pol


def is_complex_calibration(path: str | os.PathLike) -> bool:
    """True for an HDF5 calibration or a CSV whose header names ``magnitude_V_per_Pa``."""
    path = Path(path)
    if path.suffix.lower() in _H5_SUFFIXES:
        return True
    try:
        with path.open(encoding="utf-8-sig") as fh:
            for line in fh:
                if line.strip() and not line.lstrip().startswith("#"):
                    return "magnitude_V_per_Pa" in line
    except (OSError, UnicodeDecodeError):
        return False
    return False


def _read_h5(path: Path) -> tuple[dict[str, NDArray], dict[str, str]]:
    import h5py

    try:
        with h5py.File(path, "r") as f:
            fmt = f.attrs.get("format", "")
            if isinstance(fmt, bytes):
                fmt = fmt.decode()
            if fmt != CALIBRATION_FORMAT:
                raise InputError(f"expected the attribute format = {CALIBRATION_FORMAT!r}, "
                                 f"got {fmt!r}", file=str(path), field="format")
            conv = f.attrs.get("phase_convention", "fft")
            conv = conv.decode() if isinstance(conv, bytes) else str(conv)
            if conv != "fft":
                raise InputError(f"expected 'fft', got {conv!r}", file=str(path),
                                 field="phase_convention")
            cols = {k: np.asarray(f[k][()], float).reshape(-1)
                    for k in COMPLEX_CALIBRATION_COLUMNS if k in f}
            meta = {k: (v.decode() if isinstance(v, bytes) else str(v))
                    for k, v in f.attrs.items() if k in ("polarity", "name")}
    except OSError as exc:
        raise InputError(f"cannot read the HDF5 file ({exc})", file=str(path)) from None
    return cols, meta


def read_complex_calibration(path: str | os.PathLike, *, polarity: int | None = None,
                             name: str | None = None) -> HydrophoneCalibration:
    """Read a complex hydrophone calibration (CSV or HDF5, layouts in the module notes).

    Parameters
    ----------
    path : str or PathLike
        The file (``.h5``/``.hdf5``: HDF5; anything else: CSV).
    polarity : {1, -1}, optional
        Overrides the file's polarity (default: the file's, else 1).
    name : str, optional
        A label (default: the file's ``name`` attribute, else the file name).

    Returns
    -------
    HydrophoneCalibration
        Phase converted to holoprobe's convention (``−phase_rad``) by
        :meth:`HydrophoneCalibration.from_fft_phase`; uncertainties when given.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", file=str(path))
    if path.suffix.lower() in _H5_SUFFIXES:
        cols, meta = _read_h5(path)
    else:
        cols, meta = read_csv_columns(path)
    missing = [c for c in COMPLEX_CALIBRATION_COLUMNS[:3] if c not in cols]
    if missing:
        raise InputError(f"missing column(s) {', '.join(missing)}; expected "
                         f"{','.join(COMPLEX_CALIBRATION_COLUMNS)} (last two optional)",
                         file=str(path), field=missing[0])
    f = cols["frequency_Hz"]
    if f.size < 2:
        raise InputError(f"expected at least 2 frequencies, got {f.size}", file=str(path),
                         field="frequency_Hz")
    for key, arr in cols.items():
        if not np.all(np.isfinite(arr)):
            raise InputError("contains NaN or inf", file=str(path), field=key)
    if np.any(f < 0) or np.any(np.diff(f) <= 0):
        raise InputError("frequencies must be non-negative and strictly increasing",
                         file=str(path), field="frequency_Hz")
    mag = cols["magnitude_V_per_Pa"]
    if np.any(mag <= 0) or np.any(mag > 1.0):
        bad = mag[(mag <= 0) | (mag > 1.0)][0]
        raise InputError(f"expected magnitudes in (0, 1] V/Pa (hydrophones give µV–mV per "
                         f"kPa), got {bad:g}", file=str(path), field="magnitude_V_per_Pa")
    for key in COMPLEX_CALIBRATION_COLUMNS[3:]:
        if key in cols and np.any(cols[key] < 0):
            raise InputError("uncertainties must be non-negative", file=str(path), field=key)
    pol = _polarity(meta.get("polarity", 1), path) if polarity is None else polarity
    try:
        return HydrophoneCalibration.from_fft_phase(
            f, mag, cols["phase_rad"], polarity=pol,
            name=name or meta.get("name") or path.name,
            u_sensitivity=cols.get("u_magnitude_V_per_Pa"), u_phase=cols.get("u_phase_rad"))
    except InputError as exc:
        raise InputError(exc.detail, file=str(path), field=exc.field) from None


def write_calibration_h5(path: str | os.PathLike, calibration: HydrophoneCalibration, *,
                         overwrite: bool = False) -> Path:
    """Write a calibration in the HDF5 layout of :func:`read_complex_calibration`.

    A magnitude-only calibration is written with zero phase.
    """
    import h5py

    cal = calibration
    phase = cal.phase_fft if cal.phase is not None else np.zeros_like(cal.frequency)
    columns = {"frequency_Hz": cal.frequency, "magnitude_V_per_Pa": cal.sensitivity,
               "phase_rad": phase, "u_magnitude_V_per_Pa": cal.u_sensitivity,
               "u_phase_rad": cal.u_phase}
    with atomic_write(path, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as f:
        f.attrs["format"] = CALIBRATION_FORMAT
        f.attrs["phase_convention"] = "fft"
        f.attrs["polarity"] = int(cal.polarity)
        f.attrs["name"] = cal.name
        for key, value in columns.items():
            if value is not None:
                f.create_dataset(key, data=np.asarray(value, float))
    return Path(path)


def read_waveform_csv(path: str | os.PathLike, *, quantity: str = "voltage_V"
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Read a uniformly sampled waveform ``time_s,<quantity>``.

    Parameters
    ----------
    path : str or PathLike
        The CSV file.
    quantity : str
        Name of the value column (``voltage_V`` for hydrophone records).

    Returns
    -------
    time : ndarray, shape (n,)
        Sample times in s.
    values : ndarray, shape (n,)
        The samples.
    sampling_rate : float
        In Hz, from the median time step.

    Raises
    ------
    InputError
        Missing column, fewer than 16 samples, NaN, or a non-uniform time axis
        (relative step deviation above 1e-3).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", file=str(path))
    cols, _ = read_csv_columns(path)
    for key in ("time_s", quantity):
        if key not in cols:
            raise InputError(f"missing column; expected the header time_s,{quantity} "
                             f"(found: {', '.join(cols) or 'nothing'})", file=str(path),
                             field=key)
    t, v = cols["time_s"], cols[quantity]
    if t.size < 16:
        raise InputError(f"expected at least 16 samples, got {t.size}", file=str(path),
                         field="time_s")
    for key, arr in (("time_s", t), (quantity, v)):
        if not np.all(np.isfinite(arr)):
            raise InputError("contains NaN or inf", file=str(path), field=key)
    dt = np.diff(t)
    step = float(np.median(dt))
    if not step > 0 or np.max(np.abs(dt - step)) > 1e-3 * step:
        k = int(np.argmax(np.abs(dt - step)))
        raise InputError(f"expected uniformly increasing times; step {k + 1} is {dt[k]:.6g} s, "
                         f"the median step {step:.6g} s", file=str(path), field="time_s")
    fs = 1.0 / step
    if not 1e3 <= fs <= 1e12:
        raise InputError(f"implausible sampling rate {fs:.4g} Hz (expected 1 kHz–1 THz; are "
                         f"the times in s?)", file=str(path), field="time_s")
    return t, v, fs


def write_pressure_csv(path: str | os.PathLike, time: ArrayLike, pressure: ArrayLike,
                       u_pressure: ArrayLike, *, overwrite: bool = False,
                       protect: tuple[str | os.PathLike, ...] = ()) -> Path:
    """Write ``time_s,pressure_Pa,u_pressure_Pa`` (atomically; ``u`` standard, k = 1)."""
    table = np.column_stack([np.asarray(time, float), np.asarray(pressure, float),
                             np.asarray(u_pressure, float)])
    with atomic_write(path, overwrite=overwrite, protect=protect) as tmp:
        np.savetxt(tmp, table, delimiter=",", header="time_s,pressure_Pa,u_pressure_Pa",
                   comments="", fmt="%.10g")
    return Path(path)


