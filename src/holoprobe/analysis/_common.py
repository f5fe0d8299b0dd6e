"""Small helpers shared by the analyses: envelopes, aperture handling, summary updates."""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.signal import to_frequency

__all__ = ["Aperture", "as_aperture", "envelope", "update_summary"]


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
        items = [float(v) for v in value]  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise InputError("expected an aperture (center_x, center_y, width, height) in m",
                         field="aperture") from None
    if len(items) != 4:
        raise InputError(f"expected 4 numbers (center_x, center_y, width, height), got "
                         f"{len(items)}", field="aperture")
    return Aperture(*items)


def envelope(signal: ArrayLike, *, axis: int = -1) -> NDArray[np.float64]:
    """Magnitude of the analytic signal along ``axis`` (the Hilbert envelope).

    The analytic signal keeps the positive frequencies doubled (DC and Nyquist once) of
    the record zero-padded to twice its length (so that the envelope does not wrap); its
    magnitude does not depend on the sign convention of the transform.
    """
    x = np.moveaxis(np.asarray(signal, dtype=float), axis, -1)
    n = x.shape[-1]
    m = 2 * n  # zero padding: the end of the record does not wrap onto its start
    spec = np.conj(to_frequency(x, n=m))  # plain rfft (FFT convention)
    weights = np.full(spec.shape[-1], 2.0)
    weights[0] = 1.0
    weights[-1] = 1.0
    full = np.zeros((*x.shape[:-1], m), dtype=complex)
    full[..., :spec.shape[-1]] = spec * weights
    analytic = np.fft.ifft(full, axis=-1)[..., :n]  # spectrum → time, FFT convention
    return np.moveaxis(np.abs(analytic), -1, axis)


def update_summary(directory: str | os.PathLike, key: str, entry: dict[str, Any]) -> Path:
    """Set ``summary[key] = entry`` in ``DIR/summary.json`` atomically (create the file if
    absent); other keys are kept as they are.

    Raises
    ------
    InputError
        If the existing file is not a JSON object.
    """
    from holoprobe.io import atomic_write

    path = Path(directory) / "summary.json"
    data: dict[str, Any] = {}
    if path.exists():
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            raise InputError(f"cannot read it as JSON ({exc})", file=str(path)) from None
        if not isinstance(data, dict):
            raise InputError("expected a JSON object at the top level", file=str(path))
    data[key] = entry
    text = json.dumps(data, indent=2, allow_nan=True, default=_json_default)
    with atomic_write(path, overwrite=True) as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")
    return path


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
