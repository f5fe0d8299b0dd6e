"""Plausible ranges of every physical input, in one typed place.

A value outside its range is almost surely a unit mistake (a sound speed in km/s, a
density in g/cm³, a step in mm, a voltage in mV given as V) that would otherwise give
garbage without a word. Readers check what they read
(:func:`holoprobe.io.check_measurement`) and
raise :class:`holoprobe.errors.InputError` with one line naming the file, the field,
the value and the expected range. A deliberate measurement outside a range (another
coupling medium, an unusual hydrophone) is accepted after widening that range: the
``[plausibility]`` section of the characterization configuration, e.g.
``--set plausibility.sound_speed=[1000, 2000]``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from holoprobe.errors import InputError

__all__ = ["DEFAULT_PLAUSIBILITY", "PlausibilityConfig"]

Range = tuple[float, float]


@dataclass(frozen=True)
class PlausibilityConfig:
    """Accepted ``(min, max)`` of each physical input (SI units).

    Attributes
    ----------
    sound_speed : (float, float)
        Medium sound speed in m/s (water-like coupling media).
    density : (float, float)
        Medium density in kg/m³.
    sampling_rate : (float, float)
        Sampling rate of any record (scan, echo, drive) in Hz.
    frequency : (float, float)
        Frequencies (calibration table, CW hologram, probe centre frequency) in Hz.
    scan_step : (float, float)
        Step of a scan or hologram grid in m.
    distance : (float, float)
        Extents and distances (scan size, lens focus) in m.
    element_size : (float, float)
        Probe pitch, element width and height in m.
    start_time : (float, float)
        Time of a record's first sample relative to the emission in s.
    sensitivity : (float, float)
        Hydrophone sensitivity magnitude in V/Pa.
    drive_voltage : (float, float)
        Peak |drive voltage| in V.
    scan_voltage : (float, float)
        Peak |hydrophone voltage| of a voltage scan in V.
    """

    sound_speed: Range = (1300.0, 1700.0)
    density: Range = (800.0, 1300.0)
    sampling_rate: Range = (1e5, 1e11)
    frequency: Range = (1e3, 1e9)
    scan_step: Range = (1e-6, 5e-3)
    distance: Range = (1e-5, 2.0)
    element_size: Range = (1e-6, 0.2)
    start_time: Range = (-1e-3, 1e-2)
    sensitivity: Range = (1e-11, 1e-2)
    drive_voltage: Range = (0.0, 1e4)
    scan_voltage: Range = (0.0, 1e2)

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            try:
                lo, hi = (float(v) for v in value)
            except (TypeError, ValueError):
                raise InputError(f"expected [min, max], got {value!r}",
                                 field=f"plausibility.{f.name}") from None
            if not lo < hi:
                raise InputError(f"expected min < max, got {value!r}",
                                 field=f"plausibility.{f.name}")
            object.__setattr__(self, f.name, (lo, hi))

    def check(self, name: str, value: float, *, file: str | None = None,
              field: str | None = None) -> float:
        """Return ``value`` if it lies in the range ``name``, else raise InputError.

        Parameters
        ----------
        name : str
            The range (a field of this class).
        value : float
            The value in SI units.
        file, field : str, optional
            Where the value came from, for the message.
        """
        lo, hi = getattr(self, name)
        unit = _UNITS[name]
        v = float(value)
        if not (math.isfinite(v) and lo <= v <= hi):
            raise InputError(
                f"{v:.6g} {unit} is implausible: expected a {name.replace('_', ' ')} in "
                f"[{lo:g}, {hi:g}] {unit} (a unit mistake? if deliberate, widen the range: "
                f"--set plausibility.{name}=[min, max])", file=file, field=field or name)
        return v


_UNITS = {"sound_speed": "m/s", "density": "kg/m^3", "sampling_rate": "Hz",
          "frequency": "Hz", "scan_step": "m", "distance": "m", "element_size": "m",
          "start_time": "s", "sensitivity": "V/Pa", "drive_voltage": "V",
          "scan_voltage": "V"}

DEFAULT_PLAUSIBILITY = PlausibilityConfig()
"""The default ranges."""
