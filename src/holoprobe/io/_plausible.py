"""Plausibility of the physical values of measurement nouns (:mod:`holoprobe.plausibility`)."""

from __future__ import annotations

import math
from typing import Any, TypeVar

import numpy as np

from holoprobe.errors import InputError
from holoprobe.geometry import Medium
from holoprobe.measurement import (
    DriveSignal,
    EchoRecording,
    Hologram,
    HydrophoneCalibration,
    HydrophoneScan,
    ProbeInfo,
)
from holoprobe.plausibility import DEFAULT_PLAUSIBILITY, PlausibilityConfig

__all__ = ["check_measurement"]

T = TypeVar("T")


def _peak(values: Any) -> float:
    """max |values| (0 for none); of real values as max(max, −min), without the
    temporary |values| (a full-size scan: 130 MB, two passes fewer)."""
    a = np.asarray(values)
    if not a.size:
        return 0.0
    if np.iscomplexobj(a):
        return float(np.max(np.abs(a)))
    return float(np.maximum(float(a.max()), -float(a.min())))


def _checks(obj: Any, prefix: str) -> list[tuple[str, float, str]]:
    """(range name, value, field) of every physical input of a noun."""
    out: list[tuple[str, float, str]] = []
    if obj is None:
        return out
    if isinstance(obj, Medium):
        return [("sound_speed", obj.sound_speed, f"{prefix}sound_speed"),
                ("density", obj.density, f"{prefix}density")]
    if isinstance(obj, DriveSignal):
        return [("sampling_rate", obj.sampling_rate, f"{prefix}sampling_rate"),
                ("drive_voltage", _peak(obj.voltage), f"{prefix}voltage")]
    if isinstance(obj, HydrophoneCalibration):
        s = np.abs(np.asarray(obj.sensitivity, float))
        f = np.asarray(obj.frequency, float)
        return [("sensitivity", float(s.min()), f"{prefix}sensitivity"),
                ("sensitivity", float(s.max()), f"{prefix}sensitivity"),
                ("frequency", float(f[f > 0].min()) if np.any(f > 0) else 0.0,
                 f"{prefix}frequency"),
                ("frequency", float(f.max()), f"{prefix}frequency")]
    if isinstance(obj, ProbeInfo):
        out = [("element_size", obj.pitch, f"{prefix}pitch"),
               ("element_size", obj.element_width, f"{prefix}element_width"),
               ("element_size", obj.element_height, f"{prefix}element_height"),
               ("frequency", obj.center_frequency, f"{prefix}center_frequency")]
        if math.isfinite(obj.lens_focus):
            out.append(("distance", abs(obj.lens_focus), f"{prefix}lens_focus"))
        return out
    if isinstance(obj, HydrophoneScan | Hologram):
        for axis in ("x", "y"):
            coord = np.asarray(getattr(obj.grid, axis), float)
            if coord.size > 1:  # a line scan has one point along the other axis
                out += [("scan_step", abs(float(coord[1] - coord[0])),
                         f"{prefix}grid.d{axis}"),
                        ("distance", float(np.ptp(coord)), f"{prefix}grid.{axis}")]
    if isinstance(obj, HydrophoneScan):
        out += [("sampling_rate", obj.sampling_rate, f"{prefix}sampling_rate"),
                ("start_time", obj.start_time, f"{prefix}start_time")]
        if obj.quantity == "voltage":
            out.append(("scan_voltage", _peak(obj.data), f"{prefix}data"))
        for name in ("medium", "calibration", "probe", "drive"):
            out += _checks(getattr(obj, name), f"{prefix}{name}.")
    elif isinstance(obj, EchoRecording):
        out += [("sampling_rate", obj.sampling_rate, f"{prefix}sampling_rate"),
                ("start_time", obj.start_time, f"{prefix}start_time")]
        for name in ("medium", "probe", "drive"):
            out += _checks(getattr(obj, name), f"{prefix}{name}.")
    elif isinstance(obj, Hologram):
        out += _checks(obj.medium, f"{prefix}medium.")
        if obj.frequency is not None:
            out.append(("frequency", float(obj.frequency), f"{prefix}frequency"))
        elif obj.sampling_rate is not None:
            out.append(("sampling_rate", float(obj.sampling_rate), f"{prefix}sampling_rate"))
    return out


def check_measurement(obj: T, config: PlausibilityConfig | None = None, *,
                      file: str | None = None) -> T:
    """Check every physical input of a measurement noun against its plausible range.

    Parameters
    ----------
    obj : measurement noun
        A HydrophoneScan, EchoRecording, Hologram, DriveSignal, HydrophoneCalibration,
        ProbeInfo or Medium: what a reader built (nested nouns are checked too: a scan's medium,
        calibration, probe and drive).
    config : PlausibilityConfig, optional
        The ranges (default :data:`DEFAULT_PLAUSIBILITY`).
    file : str, optional
        The file it was read from (named in the message).

    Returns
    -------
    The same object.

    Raises
    ------
    InputError
        One line: file, field (e.g. ``medium.sound_speed``), value and expected range.
    """
    cfg = DEFAULT_PLAUSIBILITY if config is None else config
    if not isinstance(cfg, PlausibilityConfig):
        raise InputError("expected a holoprobe.plausibility.PlausibilityConfig",
                         field="plausibility")
    for name, value, field in _checks(obj, ""):
        cfg.check(name, value, file=file, field=field)
    return obj
