"""JSON files (summary.json, truth.json, ...): one encoder for NumPy values, atomic writes."""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from holoprobe.errors import InputError
from holoprobe.io._atomic import atomic_write

__all__ = ["json_default", "read_json", "write_json"]


def json_default(value: Any) -> Any:
    """The ``default`` hook of :func:`json.dumps` for holoprobe's values.

    NumPy scalars become Python numbers, arrays nested lists, paths strings; anything
    else raises :class:`TypeError` (a silent ``str()`` would hide a bug).

    Examples
    --------
    >>> json.dumps({"f": np.float64(1.5), "a": np.arange(2)}, default=json_default)
    '{"f": 1.5, "a": [0, 1]}'
    """
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def _finite(value: Any) -> Any:
    """``value`` with every non-finite float replaced by None (JSON has no NaN)."""
    if isinstance(value, float | np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.ndarray) and value.dtype.kind == "f":
        return _finite(value.tolist())
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def write_json(path: str | os.PathLike, data: Any, *, overwrite: bool = False,
               protect: Iterable[str | os.PathLike] = ()) -> Path:
    """Write ``data`` as indented, strict JSON atomically (NaN and ±inf become ``null``).

    Parameters
    ----------
    path : str or PathLike
        Output file.
    data : object
        JSON-serialisable with :func:`json_default` (dicts, lists, numbers, strings,
        NumPy values, paths).
    overwrite, protect
        As for :func:`holoprobe.io.atomic_write`.
    """
    text = json.dumps(_finite(data), indent=2, default=json_default)
    path = Path(path)
    with atomic_write(path, overwrite=overwrite, protect=protect) as tmp:
        Path(tmp).write_text(text + "\n", encoding="utf-8")
    return path


def read_json(path: str | os.PathLike) -> Any:
    """Read a JSON file; :class:`InputError` naming the file when it is not valid JSON."""
    path = Path(path)
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot read it as JSON ({exc})", file=str(path)) from None
