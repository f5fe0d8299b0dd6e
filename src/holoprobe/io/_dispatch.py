"""Read a measurement from any supported format, chosen by extension and contents."""

from __future__ import annotations

import os
from pathlib import Path

from holoprobe.errors import InputError
from holoprobe.io._hologram_mat import HOLOGRAM_STRUCTS, read_hologram_mat
from holoprobe.io._hologram_native import HOLOGRAM_KINDS, read_hologram
from holoprobe.io._matfile import mat_variable_names
from holoprobe.io._native import KIND_ECHO, KIND_SCAN, read_echo, read_file_kind, read_scan
from holoprobe.io._reference_mat import REFERENCE_FILES, read_reference_echo, read_reference_scan
from holoprobe.measurement import EchoRecording, Hologram, HydrophoneScan
from holoprobe.plausibility import PlausibilityConfig

__all__ = ["NATIVE_FILES", "NATIVE_SUFFIXES", "measurement_kind", "read_echo_any",
           "read_hologram_any", "read_scan_any"]

NATIVE_SUFFIXES = (".h5", ".hdf5", ".hdf")
"""File extensions of holoprobe's native HDF5 files."""


NATIVE_FILES = {"scan": "scan.h5", "receive": "echo.h5", "hologram": "hologram.h5"}
"""The native file ``holoprobe simulate`` writes into its output directory, per
measurement kind; the readers look for the same names in such a directory."""


def _in_directory(path: str | os.PathLike, *kinds: str) -> Path:
    """``path``, or for a directory that holds no reference file of ``kinds`` but a
    native file of one of them (the output directory of ``holoprobe simulate``), that
    file."""
    p = Path(path)
    if not p.is_dir() or any((p / REFERENCE_FILES[k]).is_file()
                             for k in kinds if k in REFERENCE_FILES):
        return p
    for kind in kinds:
        if (p / NATIVE_FILES[kind]).is_file():
            return p / NATIVE_FILES[kind]
    return p


def _format_of(path: str | os.PathLike) -> str:
    p = Path(path)
    if p.is_dir():
        return "reference"
    if not p.exists():
        raise InputError("no such file or directory", file=str(p))
    suffix = p.suffix.lower()
    if suffix in NATIVE_SUFFIXES:
        return "native"
    if suffix == ".mat":
        return "reference"
    raise InputError(
        f"unknown file type {suffix or '(no extension)'!r}: expected a holoprobe HDF5 file "
        f"({', '.join(NATIVE_SUFFIXES)}), a MATLAB .mat file of the reference layout, or a "
        "directory holding one", file=str(p))


def measurement_kind(path: str | os.PathLike) -> str:
    """What a measurement file holds: ``"hologram"``, ``"hydrophone_scan"`` or ``"echo_recording"``.

    Native files are told by their root attribute ``kind``; MATLAB files by their
    variables (``HologramSf``/``HologramTr`` → hologram; ``ReceiveData.mat``'s
    ``Receive`` → echo; the toolkit's ``Grid`` + ``voltage_mV`` → scan); a directory
    is the toolkit's layout (a scan), or, without ``ScanData.mat``, the native file
    ``holoprobe simulate`` wrote there (``scan.h5``, ``echo.h5`` or ``hologram.h5``).
    Nothing large is read.

    Raises
    ------
    InputError
        For a missing path, an unknown extension or a file none of the readers knows.
    """
    p = _in_directory(path, "scan", "receive", "hologram")
    fmt = _format_of(p)
    if fmt == "native":
        kind = read_file_kind(p)
        if kind in HOLOGRAM_KINDS:
            return "hologram"
        if kind in (KIND_SCAN, KIND_ECHO):
            return kind
        raise InputError(f"file kind {kind!r} is not a measurement", file=str(p), field="/")
    if p.is_dir():
        return "hydrophone_scan"
    names = set(mat_variable_names(p))
    if names & set(HOLOGRAM_STRUCTS):
        return "hologram"
    if "Receive" in names:
        return "echo_recording"
    if {"Grid", "voltage_mV"} & names or p.name == REFERENCE_FILES["scan"]:
        return "hydrophone_scan"
    raise InputError(
        f"holds neither a hologram (HologramSf/HologramTr), a scan (Grid, voltage_mV) nor an "
        f"echo (Receive); variables: {', '.join(sorted(names)) or 'none'}", file=str(p))


def read_hologram_any(path: str | os.PathLike, *, flattened_order: str = "auto"
                      ) -> Hologram:
    """Read a hologram from a native .h5 file or a MATLAB file of the community layout.

    ``*.h5`` → :func:`read_hologram`; ``*.mat`` → :func:`read_hologram_mat` (its
    defaults, and ``flattened_order``: which index runs fastest in [n, nt] data on axis
    vectors, "auto" | "x" | "y").
    """
    path = _in_directory(path, "hologram")
    if _format_of(path) == "native":
        return read_hologram(path)
    return read_hologram_mat(path, flattened_order=flattened_order)


def read_scan_any(path: str | os.PathLike, *, plausibility: PlausibilityConfig | None = None
                  ) -> HydrophoneScan:
    """Read a hydrophone scan from a native .h5 file, a reference .mat file or a directory.

    Parameters
    ----------
    path : str or PathLike
        ``*.h5``/``*.hdf5`` → :func:`read_scan`; ``*.mat`` or a directory →
        :func:`read_reference_scan` (with its default options); a directory without
        ``ScanData.mat`` but with ``scan.h5`` (``holoprobe simulate scan --out DIR``)
        → that file (``echo.h5`` and ``hologram.h5`` likewise for the other readers).
    plausibility : PlausibilityConfig, optional
        Ranges of the physical values (:mod:`holoprobe.plausibility`).

    Returns
    -------
    HydrophoneScan

    Raises
    ------
    InputError
        For a missing path or an unknown extension, or whatever the chosen reader raises.
    """
    path = _in_directory(path, "scan")
    fmt = _format_of(path)
    if fmt == "reference" and Path(path).is_file() and \
            set(mat_variable_names(path)) & set(HOLOGRAM_STRUCTS):
        raise InputError("is a hologram (HologramSf/HologramTr), not an array scan: read it "
                         "with holoprobe.io.read_hologram_any", file=str(path))
    if fmt == "native":
        return read_scan(path, plausibility=plausibility)
    return read_reference_scan(path, plausibility=plausibility)


def read_echo_any(path: str | os.PathLike, *, plausibility: PlausibilityConfig | None = None
                  ) -> EchoRecording:
    """Read an echo recording from a native .h5 file, ``ReceiveData.mat`` or a directory.

    See :func:`read_scan_any` for the dispatch rule (readers :func:`read_echo` and
    :func:`read_reference_echo`).
    """
    path = _in_directory(path, "receive")
    if _format_of(path) == "native":
        return read_echo(path, plausibility=plausibility)
    return read_reference_echo(path, plausibility=plausibility)
