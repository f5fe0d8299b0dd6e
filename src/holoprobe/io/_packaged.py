"""Data shipped with holoprobe: measured impulse responses and probe presets.

* ``holoprobe/data/<name>_impulse_responses.h5`` — transmit and receive impulse
  responses of a characterized probe (native HDF5, ``kind="impulse_responses"``);
* ``holoprobe/data/probes/<name>.toml`` — a probe preset: datasheet values and
  published characterization results (format in ``docs/formats.md``).
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import Medium
from holoprobe.io._atomic import atomic_write
from holoprobe.io._matfile import MatStruct, load_mat
from holoprobe.io._native import _open_checked, _Reader, _write_medium, _write_root
from holoprobe.measurement import ProbeInfo

__all__ = [
    "KIND_IMPULSE_RESPONSES",
    "ImpulseResponses",
    "impulse_responses_from_proteus",
    "load_packaged_impulse_responses",
    "load_probe_preset",
    "packaged_data_path",
    "probe_info_from_preset",
    "read_impulse_responses",
    "write_impulse_responses",
]

KIND_IMPULSE_RESPONSES = "impulse_responses"
_TRANSMIT_UNITS = "Pa/(V*s)"
_RECEIVE_UNITS = "ADCL/(Pa*s)"
_PRESET_FORMAT = "holoprobe-probe-preset"
_PRESET_SCHEMA_VERSION = 1
_PROBE_KEYS = ("element_count", "pitch", "element_width", "element_height",
               "center_frequency", "lens_focus")


@dataclass(frozen=True)
class ImpulseResponses:
    """Transmit and receive impulse responses of one probe (one IR for all elements).

    Parameters
    ----------
    transmit : ndarray, shape (n_t,)
        Transmit impulse response: surface pressure ρ0·c0·u per volt-second of
        drive, in Pa/(V·s); the pressure is ``conv(V, h_t) / fs``.
    receive : ndarray, shape (n_r,)
        Receive impulse response in ADCL/(Pa·s) (ADC levels per pascal-second of
        element-averaged pressure); the RF is ``conv(p, h_r) / fs``.
    sampling_rate : float
        Sampling rate in Hz; sample 0 is at t = 0.
    transmit_units, receive_units : str
        Units of the two responses.
    medium : Medium
        Medium with which the responses were derived.
    source, license : str
        Provenance of the data.
    """

    transmit: NDArray[np.float64]
    receive: NDArray[np.float64]
    sampling_rate: float
    transmit_units: str = _TRANSMIT_UNITS
    receive_units: str = _RECEIVE_UNITS
    medium: Medium = field(default_factory=Medium)
    source: str = ""
    license: str = ""

    def __post_init__(self) -> None:
        for name in ("transmit", "receive"):
            arr = np.array(getattr(self, name), dtype=float)
            if arr.ndim != 1 or arr.size < 2:
                raise InputError(f"expected a 1-D array of at least 2 samples, got shape "
                                 f"{arr.shape}", field=name)
            if not np.all(np.isfinite(arr)):
                raise InputError("contains NaN or inf", field=name)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        fs = float(self.sampling_rate)
        if not (np.isfinite(fs) and fs > 0):
            raise InputError(f"expected a positive rate in Hz, got {fs!r}", field="sampling_rate")
        object.__setattr__(self, "sampling_rate", fs)

    @property
    def transmit_time(self) -> NDArray[np.float64]:
        """Sample times of ``transmit`` in s, shape (n_t,)."""
        return np.arange(self.transmit.size) / self.sampling_rate

    @property
    def receive_time(self) -> NDArray[np.float64]:
        """Sample times of ``receive`` in s, shape (n_r,)."""
        return np.arange(self.receive.size) / self.sampling_rate


def packaged_data_path(*parts: str) -> Path:
    """Path of a file shipped in ``holoprobe/data`` (e.g. ``"probes", "p4-1.toml"``)."""
    return Path(str(resources.files("holoprobe").joinpath("data", *parts)))


def impulse_responses_from_proteus(
    path: str | os.PathLike,
    *,
    duration: float | None = None,
    medium: Medium | None = None,
    source: str | None = None,
    license: str = "",
) -> ImpulseResponses:
    """Take the impulse responses out of a PROTEUS settings .mat file.

    Parameters
    ----------
    path : str or PathLike
        PROTEUS settings (struct ``Transducer`` with ``TransmitImpulseResponse``,
        ``ReceiveImpulseResponse`` and ``SamplingRate`` in Hz).
    duration : float, optional
        Keep only the first ``duration`` seconds (default: all samples).
    medium : Medium, optional
        Medium with which the responses were derived (default: the file's
        ``Medium`` {Density, SpeedOfSound}).
    source : str, optional
        Provenance text (default: the file path).
    license : str
        License of the data.

    Returns
    -------
    ImpulseResponses
    """
    file = str(path)
    top = MatStruct(load_mat(path), file)
    trans = top.struct("Transducer")
    fs = trans.scalar("SamplingRate", positive=True)
    tx = trans.vector("TransmitImpulseResponse").astype(float)
    rx = trans.vector("ReceiveImpulseResponse").astype(float)
    if duration is not None:
        n = round(duration * fs)
        if n < 2:
            raise InputError(f"keeps {n} samples at {fs:g} Hz; expected at least 2",
                             field="duration")
        tx, rx = tx[:n], rx[:n]
    if medium is None:
        med = top.struct("Medium")
        medium = Medium(density=med.scalar("Density", positive=True),
                        sound_speed=med.scalar("SpeedOfSound", positive=True))
    return ImpulseResponses(transmit=tx, receive=rx, sampling_rate=fs, medium=medium,
                            source=file if source is None else source, license=license)


def write_impulse_responses(path: str | os.PathLike, irs: ImpulseResponses, *,
                            overwrite: bool = False, description: str = "") -> Path:
    """Write impulse responses to a native holoprobe HDF5 file (``kind="impulse_responses"``).

    Parameters
    ----------
    path : str or PathLike
        Output file (``.h5``), written atomically.
    irs : ImpulseResponses
        The responses.
    overwrite : bool
        Replace an existing file.
    description : str
        Free text stored as the root attribute ``description``.

    Returns
    -------
    pathlib.Path
    """
    target = Path(path)
    with atomic_write(target, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as f:
        _write_root(f, KIND_IMPULSE_RESPONSES, irs.source,
                    "holoprobe.io.write_impulse_responses")
        f.attrs["license"] = irs.license
        f.attrs["description"] = description
        for name, units in (("transmit", irs.transmit_units), ("receive", irs.receive_units)):
            ds = f.create_dataset(name, data=getattr(irs, name))
            ds.attrs["units"] = units
            ds.dims[0].label = "t"
        ds = f.create_dataset("sampling_rate", data=irs.sampling_rate)
        ds.attrs["units"] = "Hz"
        ds = f.create_dataset("start_time", data=0.0)
        ds.attrs["units"] = "s"
        _write_medium(f, irs.medium)
    return target


def read_impulse_responses(path: str | os.PathLike) -> ImpulseResponses:
    """Read impulse responses written by :func:`write_impulse_responses`, validating them."""
    f, file = _open_checked(path, KIND_IMPULSE_RESPONSES)
    with f:
        r = _Reader(f, file)
        tx = r.array("/transmit", units=None, ndim=1)
        rx = r.array("/receive", units=None, ndim=1)
        start = r.scalar("/start_time", units="s")
        if start != 0.0:
            raise r.error(f"expected 0 (responses start at t = 0), got {start!r}", "/start_time")
        return r.build(
            ImpulseResponses, "/",
            transmit=tx, receive=rx,
            sampling_rate=r.scalar("/sampling_rate", units="Hz", positive=True),
            transmit_units=r.units(f["transmit"], "/transmit", None),
            receive_units=r.units(f["receive"], "/receive", None),
            medium=r.medium(),
            source=r.attr_str(f, "source", "/", default=""),
            license=r.attr_str(f, "license", "/", default=""),
        )


def load_packaged_impulse_responses(name: str = "p4-1") -> ImpulseResponses:
    """The measured impulse responses shipped with holoprobe.

    Parameters
    ----------
    name : str
        Probe name; ``"p4-1"``: the first 2 µs (500 samples at 250 MHz) of the
        transmit (Pa/(V·s)) and receive (ADCL/(Pa·s)) impulse responses of the
        P4-1 characterized with the published toolkit (transducer-characterization
        / PROTEUS by N. Blanken, LGPL-3.0).

    Returns
    -------
    ImpulseResponses
    """
    path = packaged_data_path(f"{name.lower()}_impulse_responses.h5")
    if not path.is_file():
        known = sorted(p.name.removesuffix("_impulse_responses.h5")
                       for p in packaged_data_path().glob("*_impulse_responses.h5"))
        raise InputError(f"no packaged impulse responses {name!r}; available: {known}",
                         field="name")
    return read_impulse_responses(path)


def _preset_path(name_or_path: str | os.PathLike) -> Path:
    text = str(name_or_path)
    p = Path(text)
    if p.suffix.lower() == ".toml" or os.sep in text or "/" in text:
        if not p.is_file():
            raise InputError("no such probe preset file", file=text)
        return p
    candidate = packaged_data_path("probes", f"{text.lower()}.toml")
    if not candidate.is_file():
        known = sorted(q.stem for q in packaged_data_path("probes").glob("*.toml"))
        raise InputError(f"no packaged probe preset {text!r}; available: {known}",
                         field="probe")
    return candidate


def _check_probe_table(table: Any, where: str, file: str) -> None:
    if not isinstance(table, dict):
        raise InputError("expected a table", file=file, field=where)
    for key in _PROBE_KEYS:
        if key not in table:
            raise InputError("missing key", file=file, field=f"{where}.{key}")
        value = table[key]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise InputError(f"expected a number, got {value!r}", file=file,
                             field=f"{where}.{key}")


def load_probe_preset(name_or_path: str | os.PathLike) -> dict[str, Any]:
    """Read a probe preset (TOML) by packaged name (``"p4-1"``) or path.

    Parameters
    ----------
    name_or_path : str or PathLike
        A packaged preset name (``holoprobe/data/probes/<name>.toml``,
        case-insensitive) or the path of a ``.toml`` file.

    Returns
    -------
    dict
        The parsed TOML. Added keys: ``"path"`` (the preset file) and, when the
        preset has an ``[impulse_responses]`` table, ``impulse_responses["path"]``
        (its ``file`` resolved relative to the preset).

    Raises
    ------
    InputError
        Unknown name, unreadable TOML, wrong ``format``/``schema_version``, or a
        ``[datasheet]`` / ``[published]`` table missing a ProbeInfo key.
    """
    path = _preset_path(name_or_path)
    file = str(path)
    try:
        preset = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid TOML: {exc}", file=file) from None
    if preset.get("format") != _PRESET_FORMAT:
        raise InputError(f"expected format = {_PRESET_FORMAT!r}, got "
                         f"{preset.get('format')!r}", file=file, field="format")
    version = preset.get("schema_version")
    if not isinstance(version, int) or not 1 <= version <= _PRESET_SCHEMA_VERSION:
        raise InputError(f"expected schema_version 1..{_PRESET_SCHEMA_VERSION}, got "
                         f"{version!r}", file=file, field="schema_version")
    _check_probe_table(preset.get("datasheet"), "datasheet", file)
    if "published" in preset:
        _check_probe_table(preset["published"], "published", file)
    preset["path"] = file
    irs = preset.get("impulse_responses")
    if isinstance(irs, dict) and "file" in irs:
        irs["path"] = str((path.parent / irs["file"]).resolve())
    return preset


def probe_info_from_preset(preset: dict[str, Any] | str | os.PathLike, *,
                           values: str = "datasheet") -> ProbeInfo:
    """Build a :class:`ProbeInfo` from a probe preset.

    Parameters
    ----------
    preset : dict or str or PathLike
        A preset from :func:`load_probe_preset`, or a name/path to load.
    values : {"datasheet", "published"}
        Which description: the manufacturer's nominal values, or the published
        characterization results.

    Returns
    -------
    ProbeInfo
    """
    if not isinstance(preset, dict):
        preset = load_probe_preset(preset)
    if values not in ("datasheet", "published"):
        raise InputError(f"expected 'datasheet' or 'published', got {values!r}", field="values")
    file = preset.get("path")
    if values not in preset:
        raise InputError("the preset has no such table", file=file, field=values)
    table = preset[values]
    _check_probe_table(table, values, str(file))
    try:
        return ProbeInfo(**{k: table[k] for k in _PROBE_KEYS}, name=str(preset.get("name", "")))
    except InputError as exc:
        raise InputError(exc.detail, file=file, field=f"{values}.{exc.field}") from None
