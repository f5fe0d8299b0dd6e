"""Transmit sequences: a TOML file listing many transmit settings (an imaging mode).

The file (``docs/formats.md``, "Transmit sequences") holds the sequence's timing
(``prf``, optional ``frame_rate``), a ``[common]`` table of transmit-setting tables
shared by every transmit (drive, apodization, …), and either an explicit list of
``[[transmit]]`` tables or a ``[sweep]`` that generates them (focused lines, plane
waves at angles, diverging waves). This module reads and validates the file and
returns plain transmit-setting tables (the keys of the transmit TOML read by
:meth:`holoprobe.transducer.TransmitSetting.from_toml`);
:class:`holoprobe.transducer.TransmitSequence` turns them into settings.
"""

from __future__ import annotations

import copy
import math
import os
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from holoprobe.errors import InputError

__all__ = ["SEQUENCE_FORMAT", "check_toml_format", "read_transmit_sequence"]

SEQUENCE_FORMAT = "holoprobe-transmit-sequence"
_SCHEMA_VERSION = 1
_SWEEPS = ("focused", "plane_wave", "diverging")
_MAX_TRANSMITS = 100_000


def check_toml_format(data: dict, expected: str, max_version: int, *,
                      required: bool = True) -> None:
    """Check a TOML file's ``format`` tag and ``schema_version`` (1 … ``max_version``).

    Raises :class:`~holoprobe.errors.InputError` naming the key; ``required=False``
    accepts a file without a ``format`` key.
    """
    fmt = data.get("format", None if required else expected)
    if fmt != expected:
        raise InputError(f"expected {expected!r}, got {fmt!r}", field="format")
    version = data.get("schema_version", 1)
    if isinstance(version, bool) or not isinstance(version, int) or not (
            1 <= version <= max_version):
        raise InputError(f"expected 1..{max_version}, got {version!r}",
                         field="schema_version")


def _positive(table: dict, key: str, where: str, *, required: bool = True) -> float | None:
    value = table.get(key)
    if value is None:
        if required:
            raise InputError("missing key", field=f"{where}{key}")
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not (
            math.isfinite(value) and value > 0):
        raise InputError(f"expected a positive number, got {value!r}", field=f"{where}{key}")
    return float(value)


def _values(table: dict, key: str, where: str) -> np.ndarray:
    """A list of numbers, or ``{start, stop, count}`` (inclusive, evenly spaced)."""
    value = table.get(key)
    field = f"{where}{key}"
    if isinstance(value, dict):
        try:
            start, stop, count = float(value["start"]), float(value["stop"]), value["count"]
        except (KeyError, TypeError, ValueError):
            raise InputError("expected {start, stop, count}", field=field) from None
        if isinstance(count, bool) or not isinstance(count, int) or not (
                1 <= count <= _MAX_TRANSMITS):
            raise InputError(f"expected a count between 1 and {_MAX_TRANSMITS}, got {count!r}",
                             field=f"{field}.count")
        if not (math.isfinite(start) and math.isfinite(stop)):
            raise InputError("expected finite start and stop", field=field)
        return np.linspace(start, stop, count)
    if (not isinstance(value, list) or not value or len(value) > _MAX_TRANSMITS
            or any(isinstance(v, bool) or not isinstance(v, int | float) for v in value)):
        raise InputError("expected a non-empty list of numbers or {start, stop, count}",
                         field=field)
    out = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(out)):
        raise InputError("contains NaN or inf", field=field)
    return out


def _sweep(sweep: dict) -> list[dict[str, Any]]:
    """Delay tables (and names) of the transmits a ``[sweep]`` generates."""
    kind = sweep.get("kind")
    if kind not in _SWEEPS:
        raise InputError(f"expected one of {_SWEEPS}, got {kind!r}", field="sweep.kind")
    out = []
    if kind == "plane_wave":
        for a in _values(sweep, "angles_deg", "sweep."):
            out.append({"name": f"plane wave {a:+.4g} deg",
                        "delays": {"kind": "plane_wave", "angle_deg": float(a)}})
    elif kind == "diverging":
        distance = _positive(sweep, "distance", "sweep.")
        assert distance is not None
        angles = _values(sweep, "angles_deg", "sweep.") if "angles_deg" in sweep \
            else np.zeros(1)
        for a in angles:  # virtual source behind the probe, tilted by the angle
            t = math.radians(a)
            point = [-distance * math.sin(t), 0.0, -distance * math.cos(t)]
            out.append({"name": f"diverging {a:+.4g} deg",
                        "delays": {"kind": "diverging", "point": point}})
    else:
        depth = _positive(sweep, "depth", "sweep.")
        assert depth is not None
        if ("x" in sweep) == ("angles_deg" in sweep):
            raise InputError("give either x (linear scan) or angles_deg (sector scan)",
                             field="sweep.x")
        if "x" in sweep:
            points = [[float(x), 0.0, depth] for x in _values(sweep, "x", "sweep.")]
        else:
            points = [[depth * math.sin(math.radians(a)), 0.0,
                       depth * math.cos(math.radians(a))]
                      for a in _values(sweep, "angles_deg", "sweep.")]
        for p in points:
            out.append({"name": f"focus ({p[0] * 1e3:.4g}, {p[2] * 1e3:.4g}) mm",
                        "delays": {"kind": "focused", "point": p}})
    return out


def _merge(common: dict, own: dict) -> dict:
    """``own`` over ``common``, table by table (a transmit's table replaces the common one)."""
    merged = copy.deepcopy(common)
    for key, value in own.items():
        merged[key] = copy.deepcopy(value)
    return merged


def read_transmit_sequence(path: str | os.PathLike) -> dict[str, Any]:
    """Read a transmit-sequence TOML file (format in ``docs/formats.md``).

    Parameters
    ----------
    path : str or path-like
        The ``.toml`` file.

    Returns
    -------
    dict
        ``name`` (str), ``prf`` (Hz), ``frame_rate`` (Hz; default ``prf / n``),
        ``base`` (the file's folder, for drive files named in it) and ``transmits``: a
        list of transmit-setting tables (the keys of a transmit TOML), in firing order.

    Raises
    ------
    InputError
        Unreadable TOML, a missing or invalid key, or a frame rate the PRF cannot
        sustain (``frame_rate × n > prf``); the message names the file and the key.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError("no such transmit sequence file", file=str(p))
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid TOML: {exc}", file=str(p)) from None
    try:
        return _parse(data, p.parent)
    except InputError as exc:
        raise InputError(exc.detail, file=str(p), field=exc.field) from None


def _parse(data: dict, base: Path) -> dict[str, Any]:
    check_toml_format(data, SEQUENCE_FORMAT, _SCHEMA_VERSION)
    prf = _positive(data, "prf", "")
    common = data.get("common", {})
    if not isinstance(common, dict):
        raise InputError("expected a table", field="common")
    listed, sweep = data.get("transmit"), data.get("sweep")
    if (listed is None) == (sweep is None):
        raise InputError("give either [[transmit]] tables or one [sweep] table",
                         field="transmit")
    if listed is not None:
        if not isinstance(listed, list) or not listed or not all(
                isinstance(t, dict) for t in listed):
            raise InputError("expected a non-empty array of tables [[transmit]]",
                             field="transmit")
        own = listed
    else:
        if not isinstance(sweep, dict):
            raise InputError("expected a table", field="sweep")
        own = _sweep(sweep)
    transmits = []
    for i, t in enumerate(own):
        merged = _merge(common, t)
        merged.setdefault("name", f"transmit {i + 1}")
        merged["prf"] = prf
        transmits.append(merged)
    n = len(transmits)
    assert prf is not None
    frame_rate = _positive(data, "frame_rate", "", required=False)
    if frame_rate is None:
        frame_rate = prf / n
    elif frame_rate * n > prf * (1 + 1e-9):
        raise InputError(f"{n} transmits per frame at {frame_rate:g} frames/s need a PRF of "
                         f"{frame_rate * n:g} Hz, more than prf = {prf:g} Hz",
                         field="frame_rate")
    return {"name": str(data.get("name", "")), "prf": prf, "frame_rate": frame_rate,
            "base": base, "transmits": transmits}
