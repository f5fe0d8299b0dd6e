"""Transmit settings: per-element delays, apodization, drive voltage, PRF.

A :class:`TransmitSetting` does not depend on a particular probe: its delay law
(focus at a point, plane wave at an angle, diverging wave from a virtual source,
or explicit values) and its apodization (rectangular, Tukey, Hann, explicit) are
turned into per-element numbers for the elements of a
:class:`~holoprobe.transducer.VirtualTransducer` by
:meth:`TransmitSetting.element_delays` and :meth:`TransmitSetting.element_weights`.

Delay convention: element i is driven by ``E_T(t − τ_i)``; delays are shifted so
that the earliest element fires at t = 0 (all τ_i ≥ 0).
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.io import check_toml_format, read_transmit_sequence
from holoprobe.measurement import DriveSignal

__all__ = [
    "Apodization",
    "DelayLaw",
    "TransmitSequence",
    "TransmitSetting",
    "apodization_weights",
    "burst",
    "diverging_delays",
    "focused_delays",
    "plane_wave_delays",
    "rectangular_pulse",
]

_DELAY_KINDS = ("none", "focused", "plane_wave", "diverging", "explicit")
_APODIZATION_KINDS = ("rectangular", "tukey", "hann", "explicit")
_BURST_WINDOWS = ("rectangular", "hann", "tukey", "gaussian")
_TOML_FORMAT = "holoprobe-transmit"
_TOML_SCHEMA_VERSION = 1


# --------------------------------------------------------------------------- delay laws
def _points(positions: ArrayLike, name: str = "positions") -> NDArray[np.float64]:
    arr = np.asarray(positions, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] < 1:
        raise InputError(f"expected shape (n, 3) in m, got {arr.shape}", field=name)
    if not np.all(np.isfinite(arr)):
        raise InputError("contains NaN or inf", field=name)
    return arr


def _point(value: ArrayLike, name: str) -> NDArray[np.float64]:
    try:
        p = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError("expected a point (x, y, z) or (x, z) in m", field=name) from None
    if p.size == 2:
        p = np.array([p[0], 0.0, p[1]])
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise InputError(f"expected a finite point (x, y, z) or (x, z) in m, got {value!r}",
                         field=name)
    return p


def _speed(c0: float) -> float:
    c0 = float(c0)
    if not (math.isfinite(c0) and c0 > 0):
        raise InputError(f"expected a positive sound speed in m/s, got {c0!r}",
                         field="sound_speed")
    return c0


def focused_delays(positions: ArrayLike, focus: ArrayLike, sound_speed: float
                   ) -> NDArray[np.float64]:
    """Delays that focus on a point: ``τ_i = (max_j R_j − R_i) / c0``.

    Parameters
    ----------
    positions : array_like, shape (n, 3)
        Element centres in m.
    focus : array_like, shape (3,) or (2,)
        Focal point (x, y, z) or (x, z) in m (z > 0: in front of the probe).
    sound_speed : float
        c0 in m/s.

    Returns
    -------
    ndarray, shape (n,)
        Delays in s, ≥ 0; the farthest element fires first (τ = 0), so all
        wavefronts reach the focus at the same time.
    """
    pos = _points(positions)
    r = np.linalg.norm(pos - _point(focus, "focus"), axis=1)
    return (r.max() - r) / _speed(sound_speed)


def plane_wave_delays(positions: ArrayLike, angle: float, sound_speed: float
                      ) -> NDArray[np.float64]:
    """Delays that steer a plane wave by ``angle`` in the xz plane.

    ``τ_i = (x_i sin θ + z_i cos θ) / c0``, shifted to start at 0; the wave travels
    along ``(sin θ, 0, cos θ)`` (z_i = 0 on a flat face; a convex face's outer elements
    lie behind the apex and fire earlier).

    Parameters
    ----------
    positions : array_like, shape (n, 3)
        Element centres in m.
    angle : float
        Steering angle θ in rad (positive towards +x).
    sound_speed : float
        c0 in m/s.

    Returns
    -------
    ndarray, shape (n,)
        Delays in s, ≥ 0.
    """
    pos = _points(positions)
    angle = float(angle)
    if not (math.isfinite(angle) and abs(angle) < math.pi / 2):
        raise InputError(f"expected a steering angle in (−π/2, π/2) rad, got {angle!r}",
                         field="angle")
    tau = (pos[:, 0] * math.sin(angle) + pos[:, 2] * math.cos(angle)) / _speed(sound_speed)
    return tau - tau.min()


def diverging_delays(positions: ArrayLike, virtual_source: ArrayLike | float,
                     sound_speed: float) -> NDArray[np.float64]:
    """Delays of a diverging wave from a virtual source behind the probe.

    ``τ_i = (R_i − min_j R_j) / c0`` with R_i the distance from the virtual source
    to element i: the wavefront is a sphere centred on the virtual source.

    Parameters
    ----------
    positions : array_like, shape (n, 3)
        Element centres in m.
    virtual_source : float or array_like, shape (3,) or (2,)
        The virtual source (x, y, z) or (x, z) in m with z < 0, or a positive
        distance d meaning (0, 0, −d).
    sound_speed : float
        c0 in m/s.

    Returns
    -------
    ndarray, shape (n,)
        Delays in s, ≥ 0; the element nearest to the virtual source fires first.
    """
    pos = _points(positions)
    if np.ndim(virtual_source) == 0:
        # (type: ignore below) np.ndim(...) == 0 narrows to a scalar; mypy cannot see it
        d = float(virtual_source)  # type: ignore[arg-type]
        if not (math.isfinite(d) and d > 0):
            raise InputError(f"expected a positive distance behind the probe in m, got {d!r}",
                             field="virtual_source")
        src = np.array([0.0, 0.0, -d])
    else:
        src = _point(virtual_source, "virtual_source")
        if src[2] >= 0:
            raise InputError(f"a virtual source lies behind the probe (z < 0), got z = "
                             f"{src[2]:g} m", field="virtual_source")
    r = np.linalg.norm(pos - src, axis=1)
    return (r - r.min()) / _speed(sound_speed)


def apodization_weights(n: int, kind: str = "rectangular", *, alpha: float = 0.5,
                        values: ArrayLike | None = None) -> NDArray[np.float64]:
    """Per-element apodization weights.

    Parameters
    ----------
    n : int
        Number of elements.
    kind : {"rectangular", "tukey", "hann", "explicit"}
        Window: all ones; a Tukey (tapered cosine) window with taper fraction
        ``alpha``; a Hann window; or ``values``. The Tukey and Hann windows are
        sampled so that their end points fall half a pitch beyond the outer
        elements (every element radiates; ``scipy.signal.windows`` of length
        n + 2 without its two zero end points).
    alpha : float
        Tukey taper fraction in [0, 1] (0: rectangular, 1: Hann).
    values : array_like, shape (n,), optional
        Weights for ``kind="explicit"`` (finite, dimensionless).

    Returns
    -------
    ndarray, shape (n,)
        Weights, dimensionless.
    """
    n = int(n)
    if n < 1:
        raise InputError("expected at least one element", field="n")
    if kind not in _APODIZATION_KINDS:
        raise InputError(f"expected one of {_APODIZATION_KINDS}, got {kind!r}",
                         field="apodization.kind")
    if kind == "rectangular":
        return np.ones(n)
    if kind == "explicit":
        if values is None:
            raise InputError("expected values for an explicit apodization",
                             field="apodization.values")
        w = np.asarray(values, dtype=float).reshape(-1)
        if w.shape != (n,):
            raise InputError(f"expected {n} weights (one per element), got {w.size}",
                             field="apodization.values")
        if not np.all(np.isfinite(w)):
            raise InputError("contains NaN or inf", field="apodization.values")
        return w.copy()
    if kind == "tukey":
        alpha = float(alpha)
        if not (0.0 <= alpha <= 1.0):
            raise InputError(f"expected a taper fraction in [0, 1], got {alpha!r}",
                             field="apodization.alpha")
        return _tukey(n + 2, alpha)[1:-1]
    return _tukey(n + 2, 1.0)[1:-1]


def _tukey(m: int, alpha: float) -> NDArray[np.float64]:
    """Symmetric Tukey window of length m (``scipy.signal.windows.tukey(m, alpha)``; alpha
    1 is the Hann window), in NumPy: importing scipy.signal costs a cold process ≈ 1–2 s."""
    if alpha <= 0 or m < 3:
        return np.ones(m)
    k = np.arange(m)
    width = math.floor(alpha * (m - 1) / 2.0)
    w = np.ones(m)
    lo, hi = k[:width + 1], k[m - width - 1:]
    w[:width + 1] = 0.5 * (1 + np.cos(np.pi * (-1 + 2.0 * lo / alpha / (m - 1))))
    w[m - width - 1:] = 0.5 * (1 + np.cos(np.pi * (-2.0 / alpha + 1 + 2.0 * hi / alpha
                                                   / (m - 1))))
    return w


# --------------------------------------------------------------------------- drives
def burst(frequency: float, cycles: float, amplitude: float, *, sampling_rate: float = 250e6,
          window: str = "rectangular", alpha: float = 0.5) -> DriveSignal:
    """An N-cycle sine burst ``A w(t) sin(2π f0 t)``, 0 ≤ t ≤ N/f0.

    Parameters
    ----------
    frequency : float
        f0 in Hz.
    cycles : float
        Number of cycles N (> 0; fractional allowed).
    amplitude : float
        Peak voltage A in V.
    sampling_rate : float
        Sampling rate in Hz.
    window : {"rectangular", "hann", "tukey", "gaussian"}
        Envelope w(t) over the burst (gaussian: σ = duration/6).
    alpha : float
        Taper fraction of the Tukey envelope.

    Returns
    -------
    DriveSignal
        The voltage in V, one sample past the end of the burst (zero) included.
    """
    f0 = float(frequency)
    fs = float(sampling_rate)
    if not (math.isfinite(f0) and f0 > 0):
        raise InputError(f"expected a positive frequency in Hz, got {f0!r}",
                         field="drive.frequency")
    if not (math.isfinite(fs) and fs > 2 * f0):
        raise InputError(f"expected a sampling rate above 2 f0 = {2 * f0:g} Hz, got {fs!r}",
                         field="drive.sampling_rate")
    if not (math.isfinite(float(cycles)) and float(cycles) > 0):
        raise InputError(f"expected a positive number of cycles, got {cycles!r}",
                         field="drive.cycles")
    if not math.isfinite(float(amplitude)):
        raise InputError("expected a finite voltage in V", field="drive.amplitude")
    if window not in _BURST_WINDOWS:
        raise InputError(f"expected one of {_BURST_WINDOWS}, got {window!r}",
                         field="drive.window")
    duration = float(cycles) / f0
    n = math.floor(duration * fs) + 2
    t = np.arange(n) / fs
    inside = t <= duration
    x = np.clip(t / duration, 0.0, 1.0)
    if window == "rectangular":
        w = np.ones(n)
    elif window == "hann":
        w = np.sin(np.pi * x) ** 2
    elif window == "tukey":
        a = float(alpha)
        if not 0 <= a <= 1:
            raise InputError(f"expected a taper fraction in [0, 1], got {a!r}",
                             field="drive.alpha")
        w = np.ones(n)
        if a > 0:
            edge = np.minimum(x, 1 - x)
            taper = edge < a / 2
            w[taper] = 0.5 * (1 - np.cos(2 * np.pi * edge[taper] / a))
    else:
        w = np.exp(-0.5 * ((t - duration / 2) / (duration / 6)) ** 2)
    v = float(amplitude) * w * np.sin(2 * np.pi * f0 * t) * inside
    return DriveSignal(v, fs)


def rectangular_pulse(amplitude: float, duration: float, *, sampling_rate: float = 250e6
                      ) -> DriveSignal:
    """A rectangular voltage pulse of ``amplitude`` V lasting ``duration`` s.

    The pulse occupies ``round(duration · fs)`` samples (at least one) followed by
    one zero sample; its area is ``amplitude · round(duration · fs) / fs``.
    """
    fs = float(sampling_rate)
    if not (math.isfinite(fs) and fs > 0):
        raise InputError(f"expected a positive sampling rate in Hz, got {fs!r}",
                         field="drive.sampling_rate")
    d = float(duration)
    if not (math.isfinite(d) and d > 0):
        raise InputError(f"expected a positive duration in s, got {d!r}", field="drive.duration")
    if not math.isfinite(float(amplitude)):
        raise InputError("expected a finite voltage in V", field="drive.amplitude")
    n = max(1, round(d * fs))
    v = np.zeros(n + 1)
    v[:n] = float(amplitude)
    return DriveSignal(v, fs)


# --------------------------------------------------------------------------- the noun
@dataclass(frozen=True, eq=False)
class DelayLaw:
    """How the per-element transmit delays are made.

    Parameters
    ----------
    kind : {"none", "focused", "plane_wave", "diverging", "explicit"}
        No delays; :func:`focused_delays` on ``point``; :func:`plane_wave_delays`
        at ``angle``; :func:`diverging_delays` from ``point``; or ``values``.
    point : tuple of 3 floats, optional
        The focus or the virtual source (x, y, z) in m.
    angle : float
        Steering angle in rad (``plane_wave``).
    values : array_like, shape (n,), optional
        Delays in s (``explicit``).
    """

    kind: str = "none"
    point: tuple[float, float, float] | None = None
    angle: float = 0.0
    values: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        if self.kind not in _DELAY_KINDS:
            raise InputError(f"expected one of {_DELAY_KINDS}, got {self.kind!r}",
                             field="delays.kind")
        if self.kind in ("focused", "diverging"):
            if self.point is None:
                raise InputError(f"a {self.kind} delay law needs a point (x, y, z) in m",
                                 field="delays.point")
            p = _point(self.point, "delays.point")
            if self.kind == "focused" and p[2] <= 0:
                raise InputError(f"a focus lies in front of the probe (z > 0), got z = "
                                 f"{p[2]:g} m", field="delays.point")
            if self.kind == "diverging" and p[2] >= 0:
                raise InputError(f"a virtual source lies behind the probe (z < 0), got z = "
                                 f"{p[2]:g} m", field="delays.point")
            object.__setattr__(self, "point", tuple(float(v) for v in p))
        if self.kind == "plane_wave":
            a = float(self.angle)
            if not (math.isfinite(a) and abs(a) < math.pi / 2):
                raise InputError(f"expected a steering angle in (−π/2, π/2) rad, got {a!r}",
                                 field="delays.angle")
            object.__setattr__(self, "angle", a)
        if self.kind == "explicit":
            if self.values is None:
                raise InputError("an explicit delay law needs values (s)",
                                 field="delays.values")
            v = np.array(self.values, dtype=float).reshape(-1)
            if not np.all(np.isfinite(v)):
                raise InputError("contains NaN or inf", field="delays.values")
            v.setflags(write=False)
            object.__setattr__(self, "values", v)

    def delays(self, positions: ArrayLike, sound_speed: float) -> NDArray[np.float64]:
        """Per-element delays in s (≥ 0) for elements at ``positions`` (n, 3) in m."""
        pos = _points(positions)
        n = pos.shape[0]
        if self.kind == "none":
            return np.zeros(n)
        if self.kind == "focused":
            # (type: ignore below) point is set for a focused law (checked in __post_init__)
            return focused_delays(pos, self.point, sound_speed)  # type: ignore[arg-type]
        if self.kind == "plane_wave":
            return plane_wave_delays(pos, self.angle, sound_speed)
        if self.kind == "diverging":
            # (type: ignore below) point is set for a diverging law (checked in __post_init__)
            return diverging_delays(pos, self.point, sound_speed)  # type: ignore[arg-type]
        v = self.values
        assert v is not None
        if v.shape != (n,):
            raise InputError(f"expected {n} delays (one per element), got {v.size}",
                             field="delays.values")
        return v - v.min()


@dataclass(frozen=True, eq=False)
class Apodization:
    """Per-element transmit weights: see :func:`apodization_weights`."""

    kind: str = "rectangular"
    alpha: float = 0.5
    values: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        if self.kind not in _APODIZATION_KINDS:
            raise InputError(f"expected one of {_APODIZATION_KINDS}, got {self.kind!r}",
                             field="apodization.kind")
        if self.kind == "tukey" and not (0.0 <= float(self.alpha) <= 1.0):
            raise InputError(f"expected a taper fraction in [0, 1], got {self.alpha!r}",
                             field="apodization.alpha")
        if self.kind == "explicit":
            if self.values is None:
                raise InputError("an explicit apodization needs values",
                                 field="apodization.values")
            v = np.array(self.values, dtype=float).reshape(-1)
            if not np.all(np.isfinite(v)):
                raise InputError("contains NaN or inf", field="apodization.values")
            v.setflags(write=False)
            object.__setattr__(self, "values", v)

    def weights(self, n: int) -> NDArray[np.float64]:
        """Weights for ``n`` elements, shape (n,)."""
        return apodization_weights(n, self.kind, alpha=self.alpha, values=self.values)


def _as_apodization(value: Apodization | str | ArrayLike | None) -> Apodization:
    if value is None:
        return Apodization()
    if isinstance(value, Apodization):
        return value
    if isinstance(value, str):
        return Apodization(kind=value)
    return Apodization(kind="explicit", values=np.asarray(value, dtype=float))


@dataclass(frozen=True, eq=False)
class TransmitSetting:
    """One transmit event: delay law, apodization, drive voltage and PRF.

    Parameters
    ----------
    drive : DriveSignal
        Drive voltage E_T(t) of every element (V), sample 0 at t = 0.
    delays : DelayLaw
        Per-element delay law (default: none).
    apodization : Apodization
        Per-element weights (default: rectangular).
    prf : float, optional
        Pulse repetition frequency in Hz (for time-averaged output quantities).
    name : str
        A label.

    Examples
    --------
    >>> tx = TransmitSetting.focused((0.0, 0.0, 0.06), drive=burst(2.5e6, 2, 30.0),
    ...                              apodization=Apodization("tukey", alpha=0.5))
    >>> tx.delays.kind
    'focused'
    """

    drive: DriveSignal
    delays: DelayLaw = field(default_factory=DelayLaw)
    apodization: Apodization = field(default_factory=Apodization)
    prf: float | None = None
    name: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.drive, DriveSignal):
            raise InputError("expected a holoprobe.measurement.DriveSignal", field="drive")
        if not isinstance(self.delays, DelayLaw):
            raise InputError("expected a DelayLaw", field="delays")
        object.__setattr__(self, "apodization", _as_apodization(self.apodization))
        if self.prf is not None:
            prf = float(self.prf)
            if not (math.isfinite(prf) and prf > 0):
                raise InputError(f"expected a positive frequency in Hz, got {prf!r}",
                                 field="prf")
            object.__setattr__(self, "prf", prf)

    # ------------------------------------------------------------------ builders
    @classmethod
    def focused(cls, point: ArrayLike, *, drive: DriveSignal,
                apodization: Apodization | str | ArrayLike | None = None,
                prf: float | None = None, name: str = "") -> TransmitSetting:
        """Focus at ``point`` (x, y, z) or (x, z) in m; see :func:`focused_delays`."""
        return cls(drive, DelayLaw("focused", point=tuple(_point(point, "point"))),
                   _as_apodization(apodization), prf, name)

    @classmethod
    def plane_wave(cls, angle: float = 0.0, *, drive: DriveSignal,
                   apodization: Apodization | str | ArrayLike | None = None,
                   prf: float | None = None, name: str = "") -> TransmitSetting:
        """Plane wave steered by ``angle`` rad; see :func:`plane_wave_delays`."""
        return cls(drive, DelayLaw("plane_wave", angle=angle), _as_apodization(apodization),
                   prf, name)

    @classmethod
    def diverging(cls, virtual_source: ArrayLike | float, *, drive: DriveSignal,
                  apodization: Apodization | str | ArrayLike | None = None,
                  prf: float | None = None, name: str = "") -> TransmitSetting:
        """Diverging wave from a virtual source behind the probe (a point with z < 0,
        or a distance d meaning (0, 0, −d)); see :func:`diverging_delays`."""
        if np.ndim(virtual_source) == 0:
            # (type: ignore below) np.ndim(...) == 0 narrows to a scalar; mypy cannot see it
            d = float(virtual_source)  # type: ignore[arg-type]
            if not (math.isfinite(d) and d > 0):
                raise InputError(f"expected a positive distance in m, got {d!r}",
                                 field="virtual_source")
            point: tuple[float, ...] = (0.0, 0.0, -d)
        else:
            point = tuple(_point(virtual_source, "virtual_source"))
        # (type: ignore below) _point returns exactly 3 coordinates
        return cls(drive, DelayLaw("diverging", point=point),  # type: ignore[arg-type]
                   _as_apodization(apodization), prf, name)

    # ------------------------------------------------------------------ per element
    def element_delays(self, positions: ArrayLike, sound_speed: float) -> NDArray[np.float64]:
        """Delays τ_i in s (≥ 0) for elements at ``positions`` (n, 3) in m."""
        return self.delays.delays(positions, sound_speed)

    def element_weights(self, n: int) -> NDArray[np.float64]:
        """Apodization weights for ``n`` elements."""
        return self.apodization.weights(n)

    # ------------------------------------------------------------------ files
    @classmethod
    def from_toml(cls, path: str | os.PathLike) -> TransmitSetting:
        """Read a transmit setting from a TOML file.

        The file (all keys SI; angles in degrees with ``_deg``)::

            format = "holoprobe-transmit"      # optional
            schema_version = 1                 # optional
            name = "focus 60 mm"
            prf = 1000.0                       # Hz, optional

            [delays]
            kind = "focused"     # none | focused | plane_wave | diverging | explicit
            point = [0.0, 0.0, 0.06]           # m: focus, or virtual source (z < 0)
            # angle_deg = 10.0                 # plane_wave
            # distance = 0.035                 # diverging: virtual source at (0, 0, -d)
            # values = [...]                   # explicit, s

            [apodization]
            kind = "tukey"       # rectangular | tukey | hann | explicit
            alpha = 0.5
            # values = [...]

            [drive]
            kind = "burst"       # burst | pulse | samples | file
            frequency = 2.5e6    # Hz
            cycles = 2
            amplitude = 30.0     # V
            sampling_rate = 250e6
            window = "rectangular"  # rectangular | hann | tukey | gaussian
            # pulse: amplitude, duration (s), sampling_rate
            # samples: values = [...] (V), sampling_rate
            # file: file = "drive.csv" (one voltage per line, V; relative to this
            #       TOML), sampling_rate

        Raises
        ------
        InputError
            Unreadable TOML or a missing/invalid key (the message names the file
            and the key).
        """
        p = Path(path)
        file = str(p)
        if not p.is_file():
            raise InputError("no such transmit setting file", file=file)
        try:
            data = tomllib.loads(p.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise InputError(f"not valid TOML: {exc}", file=file) from None
        try:
            return _setting_from_dict(data, p.parent)
        except InputError as exc:
            raise InputError(exc.detail, file=file, field=exc.field) from None


def _number(table: dict, key: str, where: str, *, default: Any = None) -> float:
    if key not in table:
        if default is None:
            raise InputError("missing key", field=f"{where}.{key}")
        return default
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"expected a number, got {value!r}", field=f"{where}.{key}")
    return float(value)


def _table(data: dict, key: str, *, required: bool) -> dict:
    value = data.get(key)
    if value is None:
        if required:
            raise InputError("missing table", field=key)
        return {}
    if not isinstance(value, dict):
        raise InputError("expected a table", field=key)
    return value


def _number_list(table: dict, key: str, where: str) -> NDArray[np.float64]:
    value = table.get(key)
    if not isinstance(value, list) or not value or any(
            isinstance(v, bool) or not isinstance(v, int | float) for v in value):
        raise InputError("expected a non-empty list of numbers", field=f"{where}.{key}")
    return np.asarray(value, dtype=float)


def _setting_from_dict(data: dict, base: Path) -> TransmitSetting:
    check_toml_format(data, _TOML_FORMAT, _TOML_SCHEMA_VERSION, required=False)
    # delays
    dt = _table(data, "delays", required=False)
    kind = dt.get("kind", "none")
    if kind not in _DELAY_KINDS:
        raise InputError(f"expected one of {_DELAY_KINDS}, got {kind!r}", field="delays.kind")
    if kind in ("focused", "diverging"):
        if kind == "diverging" and "point" not in dt and "distance" in dt:
            d = _number(dt, "distance", "delays")
            if d <= 0:
                raise InputError("expected a positive distance in m", field="delays.distance")
            point = np.array([0.0, 0.0, -d])
        else:
            if "point" not in dt:
                raise InputError("missing key", field="delays.point")
            point = _number_list(dt, "point", "delays")
        x, y, z = (float(v) for v in _point(point, "delays.point"))
        law = DelayLaw(kind, point=(x, y, z))
    elif kind == "plane_wave":
        law = DelayLaw(kind, angle=math.radians(_number(dt, "angle_deg", "delays",
                                                        default=0.0)))
    elif kind == "explicit":
        law = DelayLaw(kind, values=_number_list(dt, "values", "delays"))
    else:
        law = DelayLaw()
    # apodization
    at = _table(data, "apodization", required=False)
    akind = at.get("kind", "rectangular")
    if akind not in _APODIZATION_KINDS:
        raise InputError(f"expected one of {_APODIZATION_KINDS}, got {akind!r}",
                         field="apodization.kind")
    apod = Apodization(
        akind, alpha=_number(at, "alpha", "apodization", default=0.5),
        values=_number_list(at, "values", "apodization") if akind == "explicit" else None)
    # drive
    dr = _table(data, "drive", required=True)
    dkind = dr.get("kind")
    fs = _number(dr, "sampling_rate", "drive", default=250e6)
    if dkind == "burst":
        window = dr.get("window", "rectangular")
        drive = burst(_number(dr, "frequency", "drive"), _number(dr, "cycles", "drive"),
                      _number(dr, "amplitude", "drive"), sampling_rate=fs,
                      window=window, alpha=_number(dr, "alpha", "drive", default=0.5))
    elif dkind == "pulse":
        drive = rectangular_pulse(_number(dr, "amplitude", "drive"),
                                  _number(dr, "duration", "drive"), sampling_rate=fs)
    elif dkind == "samples":
        drive = DriveSignal(_number_list(dr, "values", "drive"), fs)
    elif dkind == "file":
        name = dr.get("file")
        if not isinstance(name, str):
            raise InputError("expected a file name", field="drive.file")
        fp = (base / name) if not Path(name).is_absolute() else Path(name)
        if not fp.is_file():
            raise InputError(f"drive file {str(fp)!r} not found", field="drive.file")
        try:
            v = np.loadtxt(fp, dtype=float, delimiter=",", ndmin=1, comments="#")
        except ValueError as exc:
            raise InputError(f"drive file {str(fp)!r}: expected one voltage per line ({exc})",
                             field="drive.file") from None
        drive = DriveSignal(v.reshape(-1), fs)
    else:
        raise InputError(f"expected 'burst', 'pulse', 'samples' or 'file', got {dkind!r}",
                         field="drive.kind")
    prf = data.get("prf")
    if prf is not None and (isinstance(prf, bool) or not isinstance(prf, int | float)):
        raise InputError(f"expected a number in Hz, got {prf!r}", field="prf")
    name = data.get("name", "")
    return TransmitSetting(drive, law, apod, None if prf is None else float(prf), str(name))


@dataclass(frozen=True, eq=False)
class TransmitSequence:
    """An imaging mode: transmit settings fired in turn, with the sequence's timing.

    Parameters
    ----------
    settings : tuple of TransmitSetting
        The transmits of one frame, in firing order.
    prf : float
        Pulse repetition frequency in Hz: transmit events per second.
    frame_rate : float, optional
        Frames per second (each transmit fires once per frame); default
        ``prf / len(settings)``. Must satisfy ``frame_rate · n ≤ prf``.
    name : str
        A label.

    Notes
    -----
    A point's temporal-average intensity over the sequence is
    ``frame_rate · Σ_t PII_t`` (every transmit t contributes its pulse intensity
    integral once per frame); see :func:`holoprobe.exposure.sequence_exposure`.
    """

    settings: tuple[TransmitSetting, ...]
    prf: float
    frame_rate: float | None = None
    name: str = ""

    def __post_init__(self) -> None:
        settings = tuple(self.settings)
        if not settings or not all(isinstance(s, TransmitSetting) for s in settings):
            raise InputError("expected a non-empty sequence of TransmitSetting",
                             field="settings")
        object.__setattr__(self, "settings", settings)
        prf = float(self.prf)
        if not (math.isfinite(prf) and prf > 0):
            raise InputError(f"expected a positive PRF in Hz, got {self.prf!r}", field="prf")
        object.__setattr__(self, "prf", prf)
        rate = prf / len(settings) if self.frame_rate is None else float(self.frame_rate)
        if not (math.isfinite(rate) and rate > 0) or rate * len(settings) > prf * (1 + 1e-9):
            raise InputError(f"expected 0 < frame_rate ≤ prf / {len(settings)} = "
                             f"{prf / len(settings):g} Hz, got {self.frame_rate!r}",
                             field="frame_rate")
        object.__setattr__(self, "frame_rate", rate)

    def __len__(self) -> int:
        return len(self.settings)

    @classmethod
    def from_file(cls, path: str | os.PathLike) -> TransmitSequence:
        """Read a transmit-sequence TOML (:func:`holoprobe.io.read_transmit_sequence`)."""
        data = read_transmit_sequence(path)
        settings = []
        for i, table in enumerate(data["transmits"]):
            try:
                settings.append(_setting_from_dict(table, data["base"]))
            except InputError as exc:
                raise InputError(f"transmit {i + 1}: {exc.detail}", file=str(path),
                                 field=exc.field) from None
        return cls(tuple(settings), data["prf"], data["frame_rate"], data["name"])
