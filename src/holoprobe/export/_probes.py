"""Exports of a virtual transducer to the probe descriptions imaging people load.

* **UFF v0.3 probe** (:func:`uff_probe_dict`, :func:`export_uff`): the ``probe`` object of
  the Ultrasound File Format v0.3 as the ``uff-reader`` package (de)serialises it — element
  list (transform + rectangular perimeter + impulse response), ``element_impulse_response``
  (``initial_time``, ``sampling_frequency``, ``data``, ``units``), ``focal_length``
  (elevation lens), plus the linear-array fields ``number_elements``, ``pitch``,
  ``element_width``, ``element_height``. HDF5 layout: lists are groups ``00000001`` … with
  the attribute ``array_size``; strings are ``|S1`` character arrays; the probe is the group
  ``/uff.probe`` and ``/version`` holds ``major, minor, patch = 0, 3, 0``.
* **Verasonics** ``Trans`` (:func:`verasonics_trans`, :func:`export_verasonics`): a MATLAB
  v5 file with the struct ``Trans`` in Verasonics' units (``units = 'wavelengths'``:
  ``ElementPos`` (N × 5: x, y, z in wavelengths, azimuth and elevation angles in rad),
  ``elementWidth`` and ``spacing`` in wavelengths of ``frequency`` at the Verasonics sound
  speed 1540 m/s; ``spacingMm``, ``elevationApertureMm``, ``elevationFocusMm`` in mm;
  ``frequency`` and ``Bandwidth`` in MHz; ``IR1wy`` / ``IR2wy`` the one-way (transmit) and
  two-way (transmit ⊛ receive, or ``IR1wy ⊛ IR1wy`` without a receive IR) impulse
  responses as 250 MHz discrete filters, column vectors, normalised to a passband peak gain
  of 1 (Verasonics uses them as shapes). A second variable ``holoprobe`` keeps the absolute
  scales and units.
* **PyMUST** ``param`` (:func:`pymust_param`, :func:`to_pymust`): ``Nelements, fc, pitch,
  width, kerf, height, focus, bandwidth, baffle, c, attenuation, radius``. MUST does not
  take an impulse response: it synthesises its pulse-echo spectrum from ``fc`` and
  ``bandwidth`` (a generalised normal window whose −6 dB fractional width is
  ``bandwidth``), so the measured IRs enter only through those two numbers, computed here
  from the measured pulse-echo response (−6 dB band of ``|H_T · H_R|``, or ``|H_T|²``).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import scipy.io
from numpy.typing import NDArray

from holoprobe.errors import InputError
from holoprobe.export._proteus import PROTEUS_IR_SAMPLING_RATE, _to_250

__all__ = [
    "UFF_VERSION",
    "VERASONICS_IR_SAMPLING_RATE",
    "export_uff",
    "export_verasonics",
    "pulse_echo_response",
    "pymust_param",
    "to_pymust",
    "uff_probe_dict",
    "verasonics_trans",
]

UFF_VERSION = (0, 3, 0)
"""Version of the Ultrasound File Format written by :func:`export_uff`."""
VERASONICS_IR_SAMPLING_RATE = PROTEUS_IR_SAMPLING_RATE
"""Verasonics' ``IR1wy``/``IR2wy`` sampling rate (its 250 MHz system clock), Hz."""
_MM = 1e3
_MHZ = 1e-6


def _check_vt(vt: Any) -> Any:
    from holoprobe.transducer import VirtualTransducer

    if not isinstance(vt, VirtualTransducer):
        raise InputError("expected a holoprobe.transducer.VirtualTransducer", field="vt")
    return vt


def pulse_echo_response(vt: Any, sampling_rate: float = VERASONICS_IR_SAMPLING_RATE
                        ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """One-way and two-way impulse responses at ``sampling_rate`` as discrete filters.

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    sampling_rate : float
        Hz.

    Returns
    -------
    one_way : ndarray, shape (n,)
        ``h_T / fs`` (Pa/V per sample): the transmit IR as a discrete filter.
    two_way : ndarray, shape (n + m − 1,)
        ``(h_T ⊛ h_R) / fs²`` with the receive IR, else ``one_way ⊛ one_way``.
    """
    _check_vt(vt)
    rate = float(sampling_rate)
    one = _to_250(vt.transmit_impulse_response, vt.transmit_sampling_rate, rate) / rate
    if vt.receive_impulse_response is None:
        return one, np.convolve(one, one)
    rx = _to_250(vt.receive_impulse_response, float(vt.receive_sampling_rate), rate) / rate
    return one, np.convolve(one, rx)


def _band(ir: NDArray, rate: float):
    from holoprobe.signal import spectrum_summary

    return spectrum_summary(ir, rate, level_db=-6.0)


def _unit_gain(ir: NDArray) -> tuple[NDArray[np.float64], float]:
    from holoprobe.signal import next_fast_length, to_frequency

    gain = float(np.abs(to_frequency(ir, n=next_fast_length(8 * ir.size))).max())
    return ir / gain, gain


# --------------------------------------------------------------------------- PyMUST
def pymust_param(vt: Any, *, baffle: str | float = "rigid",
                 attenuation_db_cm_mhz: float = 0.0) -> dict[str, Any]:
    """The PyMUST / MUST ``param`` of a virtual transducer, as a dict.

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    baffle : {"rigid", "soft"} or float
        MUST's baffle (obliquity factor). holoprobe's fields are Rayleigh integrals of a
        normal velocity in a rigid baffle, hence ``"rigid"``.
    attenuation_db_cm_mhz : float
        MUST's ``attenuation`` (dB/cm/MHz).

    Returns
    -------
    dict
        ``Nelements`` (int), ``fc`` (Hz: centre of the −6 dB band of the pulse-echo
        spectrum), ``pitch``, ``width``, ``kerf``, ``height`` (m), ``focus`` (elevation
        focus, m, inf without a lens), ``bandwidth`` (pulse-echo −6 dB fractional
        bandwidth in %), ``baffle``, ``c`` (m/s), ``attenuation``, ``radius`` (inf:
        linear array). MUST synthesises its pulse from ``fc`` and ``bandwidth`` only.
    """
    _check_vt(vt)
    rate = VERASONICS_IR_SAMPLING_RATE
    _, two_way = pulse_echo_response(vt, rate)
    band = _band(two_way, rate)
    ok = baffle in ("rigid", "soft") if isinstance(baffle, str) else float(baffle) > 0
    if not ok:
        raise InputError(f"expected 'rigid', 'soft' or a positive number, got {baffle!r}",
                         field="baffle")
    return {
        "Nelements": int(vt.element_count),
        "fc": float(band.center_frequency),
        "pitch": float(vt.pitch),
        "width": float(vt.element_width),
        "kerf": float(vt.kerf),
        "height": float(vt.element_height),
        "focus": float(vt.lens_focus),
        "bandwidth": float(100.0 * band.fractional_bandwidth),
        "baffle": baffle,
        "c": float(vt.medium.sound_speed),
        "attenuation": float(attenuation_db_cm_mhz),
        "radius": math.inf,
    }


def to_pymust(vt: Any, **kwargs: Any) -> Any:
    """:func:`pymust_param` as a ``pymust.utils.Param`` (needs the optional ``pymust``).

    Raises
    ------
    InputError
        When pymust is not installed.
    """
    try:
        from pymust.utils import Param
    except ImportError:
        raise InputError("pymust is not installed (pip install pymust)",
                         field="pymust") from None
    param = Param()
    for key, value in pymust_param(vt, **kwargs).items():
        param[key] = value
    return param


# --------------------------------------------------------------------------- Verasonics
def verasonics_trans(vt: Any, *, sound_speed: float = 1540.0) -> dict[str, Any]:
    """The Verasonics ``Trans`` struct of a virtual transducer (units in the module notes).

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    sound_speed : float
        Verasonics' ``Resource.Parameters.speedOfSound`` (m/s) that defines the
        wavelength.

    Returns
    -------
    dict
        Field name → value (``ElementPos`` (N, 5), ``IR1wy``/``IR2wy`` (n, 1)).
    """
    _check_vt(vt)
    if not (math.isfinite(sound_speed) and sound_speed > 0):
        raise InputError(f"expected a positive speed in m/s, got {sound_speed!r}",
                         field="sound_speed")
    rate = VERASONICS_IR_SAMPLING_RATE
    one, two = pulse_echo_response(vt, rate)
    band = _band(two, rate)
    fc = band.center_frequency
    wavelength = sound_speed / fc
    pos = np.zeros((vt.element_count, 5))
    pos[:, :3] = vt.element_centers() / wavelength
    if vt.array is not None:  # azimuth angle of each element's normal (rad)
        pos[:, 3] = vt.array.element_angles
    return {
        "name": vt.name or "holoprobe virtual transducer",
        "units": "wavelengths",
        **_curvature(vt, wavelength),
        "frequency": fc * _MHZ,
        "Bandwidth": np.array([[band.f_low * _MHZ, band.f_high * _MHZ]]),
        "numelements": float(vt.element_count),
        "elementWidth": vt.element_width / wavelength,
        "spacing": vt.pitch / wavelength,
        "spacingMm": vt.pitch * _MM,
        "ElementPos": pos,
        "elevationApertureMm": vt.element_height * _MM,
        "elevationFocusMm": vt.lens_focus * _MM,
        "lensCorrection": 0.0,
        "ConnectorES": np.arange(1, vt.element_count + 1, dtype=float).reshape(-1, 1),
        "IR1wy": _unit_gain(one)[0].reshape(-1, 1),
        "IR2wy": _unit_gain(two)[0].reshape(-1, 1),
    }


def _curvature(vt: Any, wavelength: float) -> dict[str, Any]:
    """Verasonics' convex fields of a model: ``type`` 1 (curved linear), ``radius``
    (in ``wavelength`` units) and ``radiusMm``; ``type`` 0 for a flat one."""
    arr = vt.array
    if arr is None or arr.kind != "convex" or arr.radius_of_curvature is None:
        return {"type": 0.0}
    r = float(arr.radius_of_curvature)
    return {"type": 1.0, "radius": r / wavelength, "radiusMm": r * _MM}


def export_verasonics(vt: Any, path: str | os.PathLike, *, sound_speed: float = 1540.0,
                      overwrite: bool = False) -> Path:
    """Write ``Trans`` (and the scales in ``holoprobe``) to a MATLAB v5 file.

    ``holoprobe`` holds ``IR1wy_gain`` (Pa/V: ``IR1wy · gain · fs`` is the transmit IR in
    Pa/(V·s)), ``IR2wy_gain`` and the units of both, ``sound_speed`` (m/s).
    """
    from holoprobe.io import atomic_write

    trans = verasonics_trans(vt, sound_speed=sound_speed)
    one, two = pulse_echo_response(vt)
    extras = {"IR1wy_gain": _unit_gain(one)[1], "IR2wy_gain": _unit_gain(two)[1],
              "IR1wy_units": "Pa/V per sample (transmit IR / 250 MHz)",
              "IR2wy_units": ("(Pa/V)·(rx units·s) per sample" if vt.has_receive
                              else "(Pa/V)^2 per sample"),
              "sound_speed": float(sound_speed)}
    with atomic_write(path, overwrite=overwrite) as tmp:
        scipy.io.savemat(tmp, {"Trans": trans, "holoprobe": extras}, format="5",
                         oned_as="column", do_compression=False)
    return Path(path)


# --------------------------------------------------------------------------- UFF
def _xyz(x: float, y: float, z: float) -> dict[str, float]:
    return {"x": float(x), "y": float(y), "z": float(z)}


def _listing(items: list[Any]) -> dict[str, Any]:
    return {f"{i:08d}": item for i, item in enumerate(items, start=1)}


def uff_probe_dict(vt: Any) -> dict[str, Any]:
    """The UFF v0.3 ``probe`` of a virtual transducer as nested dicts (uff-reader's
    ``Probe.serialize`` layout; lists as ``{"00000001": …}``).

    The element impulse response is the transmit IR (``units`` = its units, e.g.
    ``"Pa/(V*s)"``; ``initial_time`` 0, the onset convention of the model); a receive IR,
    when present, is the second entry of ``element_impulse_response``. Elements are
    rectangles ``element_width × element_height`` centred on :meth:`element_centers`,
    turned about y by the azimuth angle of their normal (``rotation.y``, rad: the
    right-handed turn that takes +z to the normal; USTB's θ) — a convex array's
    elements face along the arc; the flat rectangle is the tangent plane of a curved
    element (sagitta w²/(8R), 0.5 µm for a C5-2).
    """
    _check_vt(vt)
    hw, hh = 0.5 * vt.element_width, 0.5 * vt.element_height
    corners = [(-hw, -hh), (hw, -hh), (hw, hh), (-hw, hh)]
    geometry = {"perimeter": {"position": _listing([_xyz(x, y, 0.0) for x, y in corners])}}
    tx = {"initial_time": 0.0, "sampling_frequency": float(vt.transmit_sampling_rate),
          "data": np.asarray(vt.transmit_impulse_response, float),
          "units": vt.transmit_units}
    responses = [tx]
    if vt.has_receive:
        responses.append({"initial_time": 0.0,
                          "sampling_frequency": float(vt.receive_sampling_rate),
                          "data": np.asarray(vt.receive_impulse_response, float),
                          "units": vt.receive_units})
    angles = (np.zeros(vt.element_count) if vt.array is None
              else np.asarray(vt.array.element_angles))
    elements = [{"transform": {"translation": _xyz(*c), "rotation": _xyz(0, a, 0)},
                 "element_geometry": geometry, "impulse_response": tx}
                for c, a in zip(vt.element_centers(), angles, strict=True)]
    return {
        "number_elements": int(vt.element_count),
        "pitch": float(vt.pitch),
        "element_height": float(vt.element_height),
        "element_width": float(vt.element_width),
        "transform": {"translation": _xyz(0, 0, 0), "rotation": _xyz(0, 0, 0)},
        "element": _listing(elements),
        "element_impulse_response": _listing(responses),
        "focal_length": float(vt.lens_focus),
        "element_geometry": _listing([geometry]),
    }


def _write_group(group: Any, data: dict[str, Any]) -> None:
    for key, value in data.items():
        if isinstance(value, dict):
            sub = group.create_group(key)
            _write_group(sub, value)
            if value and all(k.isdecimal() for k in value):
                sub.attrs["array_size"] = len(value)
        elif isinstance(value, str):
            group.create_dataset(key, data=[list(c) for c in value] or [[""]], dtype="|S1")
        else:
            group.create_dataset(key, data=value)


def export_uff(vt: Any, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write the UFF v0.3 probe (:func:`uff_probe_dict`) to an HDF5 file (``.uff``)."""
    import h5py

    from holoprobe.io import atomic_write

    probe = uff_probe_dict(vt)
    with atomic_write(path, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as f:
        version = f.create_group("version")
        for key, value in zip(("major", "minor", "patch"), UFF_VERSION, strict=True):
            version.create_dataset(key, data=value)
        _write_group(f.create_group("uff.probe"), probe)
    return Path(path)
