"""Small helpers shared by the analyses: envelopes, aperture handling, summary updates."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from holoprobe.errors import InputError

__all__ = ["Aperture", "as_aperture", "update_summary"]


@dataclass(frozen=True)
class Aperture:
    """A rectangular active aperture on the source plane (lengths in m).

    Attributes
    ----------
    center_x, center_y : float
        Centre (x_c, y_c).
    width, height : float
        Width W along x and height H along y.
    """

    center_x: float
    center_y: float
    width: float
    height: float

    def __post_init__(self) -> None:
        for name in ("center_x", "center_y", "width", "height"):
            value = float(getattr(self, name))
            if not math.isfinite(value):
                raise InputError(f"expected a finite number, got {value!r}",
                                 field=f"aperture.{name}")
            object.__setattr__(self, name, value)
        if not (self.width > 0 and self.height > 0):
            raise InputError(f"expected a positive width and height, got {self.width!r} × "
                             f"{self.height!r} m", field="aperture")


def as_aperture(value: object) -> Aperture:
    """An :class:`Aperture` from an Aperture, an object with ``center_x``, ``center_y``,
    ``width``, ``height`` attributes (e.g. :class:`holoprobe.characterize.ApertureFit`), a
    mapping with those keys, or a tuple ``(center_x, center_y, width, height)`` in m."""
    if isinstance(value, Aperture):
        return value
    names = ("center_x", "center_y", "width", "height")
    if all(hasattr(value, n) for n in names):
        return Aperture(*(getattr(value, n) for n in names))
    if isinstance(value, dict):
        try:
            return Aperture(*(value[n] for n in names))
        except KeyError as exc:
            raise InputError(f"missing key {exc}", field="aperture") from None
    try:
        items = [float(v) for v in value]  # type: ignore[attr-defined]  # any iterable; TypeError below
    except (TypeError, ValueError):
        raise InputError("expected an aperture (center_x, center_y, width, height) in m",
                         field="aperture") from None
    if len(items) != 4:
        raise InputError(f"expected 4 numbers (center_x, center_y, width, height), got "
                         f"{len(items)}", field="aperture")
    return Aperture(*items)


def update_summary(directory: str | os.PathLike, key: str, entry: dict[str, Any]) -> Path:
    """Set ``summary[key] = entry`` in ``DIR/summary.json`` atomically (create the file if
    absent); other keys are kept as they are.

    Raises
    ------
    InputError
        If the existing file is not a JSON object.
    """
    from holoprobe.io import read_json, write_json

    path = Path(directory) / "summary.json"
    data: dict[str, Any] = read_json(path) if path.exists() else {}
    if not isinstance(data, dict):
        raise InputError("expected a JSON object at the top level", file=str(path))
    data[key] = entry
    write_json(path, data, overwrite=True)
    return path
