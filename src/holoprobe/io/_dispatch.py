"""Read a measurement from any supported format, chosen by extension and contents."""

from __future__ import annotations

import os
from pathlib import Path

from holoprobe.errors import InputError
from holoprobe.io._native import read_echo, read_scan
from holoprobe.io._reference_mat import read_reference_echo, read_reference_scan
from holoprobe.measurement import EchoRecording, HydrophoneScan

__all__ = ["NATIVE_SUFFIXES", "read_echo_any", "read_scan_any"]

NATIVE_SUFFIXES = (".h5", ".hdf5", ".hdf")
"""File extensions of holoprobe's native HDF5 files."""


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


def read_scan_any(path: str | os.PathLike) -> HydrophoneScan:
    """Read a hydrophone scan from a native .h5 file, a reference .mat file or a directory.

    Parameters
    ----------
    path : str or PathLike
        ``*.h5``/``*.hdf5`` → :func:`read_scan`; ``*.mat`` or a directory →
        :func:`read_reference_scan` (with its default options).

    Returns
    -------
    HydrophoneScan

    Raises
    ------
    InputError
        For a missing path or an unknown extension, or whatever the chosen reader raises.
    """
    if _format_of(path) == "native":
        return read_scan(path)
    return read_reference_scan(path)


def read_echo_any(path: str | os.PathLike) -> EchoRecording:
    """Read an echo recording from a native .h5 file, ``ReceiveData.mat`` or a directory.

    See :func:`read_scan_any` for the dispatch rule (readers :func:`read_echo` and
    :func:`read_reference_echo`).
    """
    if _format_of(path) == "native":
        return read_echo(path)
    return read_reference_echo(path)
