"""``virtual_transducer.h5``: the versioned HDF5 file of a :class:`VirtualTransducer`.

Root attributes ``format="holoprobe"``, ``kind="virtual_transducer"``,
``schema_version=1``; groups ``/elements``, ``/lens``, ``/aperture``,
``/transmit``, ``/receive`` (optional), ``/medium``, ``/parameters``,
``/provenance``. Every numeric dataset carries a ``units`` attribute. The layout
is documented in ``docs/formats.md`` ("virtual_transducer.h5"). The reader
validates every dataset and raises :class:`~holoprobe.errors.InputError` naming
the file and the dataset.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from holoprobe.errors import InputError, require_instance
from holoprobe.geometry import Medium
from holoprobe.io import HDF5Reader, write_array_geometry
from holoprobe.transducer._model import (
    RECEIVE_UNITS,
    TRANSMIT_UNITS,
    Provenance,
    VirtualTransducer,
)

__all__ = [
    "FORMAT_NAME",
    "KIND_VIRTUAL_TRANSDUCER",
    "SCHEMA_VERSION",
    "read_virtual_transducer",
    "write_virtual_transducer",
]

FORMAT_NAME = "holoprobe"
KIND_VIRTUAL_TRANSDUCER = "virtual_transducer"
SCHEMA_VERSION = 1
"""Schema written by this holoprobe; the reader accepts versions 1 … SCHEMA_VERSION."""

_STR = h5py.string_dtype(encoding="utf-8")


def _num(group: h5py.Group, name: str, value: Any, units: str) -> None:
    ds = group.create_dataset(name, data=value)
    ds.attrs["units"] = units


def _text(group: h5py.Group, name: str, value: str) -> None:
    group.create_dataset(name, data=value, dtype=_STR)


def write_virtual_transducer(path: str | os.PathLike, vt: VirtualTransducer, *,
                             overwrite: bool = False) -> Path:
    """Write a :class:`VirtualTransducer` to HDF5 atomically (schema version 1).

    Parameters
    ----------
    path : str or PathLike
        Output file, e.g. ``DIR/virtual_transducer.h5``.
    vt : VirtualTransducer
        The model.
    overwrite : bool
        Replace an existing file.

    Returns
    -------
    pathlib.Path
        The written file.
    """
    from holoprobe.io import atomic_write

    require_instance(vt, VirtualTransducer, "vt")
    target = Path(path)
    with atomic_write(target, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as f:
        f.attrs["format"] = FORMAT_NAME
        f.attrs["kind"] = KIND_VIRTUAL_TRANSDUCER
        f.attrs["schema_version"] = np.int64(SCHEMA_VERSION)
        f.attrs["name"] = vt.name
        f.attrs["created_by"] = "holoprobe.transducer.VirtualTransducer.save"

        g = f.create_group("elements")
        _num(g, "count", np.int64(vt.element_count), "1")
        _num(g, "pitch", vt.pitch, "m")
        _num(g, "width", vt.element_width, "m")
        _num(g, "height", vt.element_height, "m")
        _num(g, "centers", vt.element_centers(), "m")
        if vt.element_sensitivity is not None:
            _num(g, "sensitivity", np.asarray(vt.element_sensitivity), "1")
        if vt.element_delay is not None:
            _num(g, "delay", np.asarray(vt.element_delay), "s")
        if vt.element_transmit_amplitude is not None:
            _num(g, "transmit_amplitude", np.asarray(vt.element_transmit_amplitude), "1")
        if vt.element_transmit_delay is not None:
            _num(g, "transmit_delay", np.asarray(vt.element_transmit_delay), "s")
        if vt.array is not None:
            write_array_geometry(g.create_group("array"), vt.array)

        g = f.create_group("lens")
        _num(g, "focus", vt.lens_focus, "m")

        g = f.create_group("aperture")
        _num(g, "center", np.asarray(vt.aperture_center, dtype=float), "m")
        # (type: ignore below) set by VirtualTransducer.__post_init__
        _num(g, "width", float(vt.aperture_width), "m")  # type: ignore[arg-type]
        # (type: ignore below) set by VirtualTransducer.__post_init__
        _num(g, "height", float(vt.aperture_height), "m")  # type: ignore[arg-type]

        for side, ir, fs, units in (
            ("transmit", vt.transmit_impulse_response, vt.transmit_sampling_rate,
             vt.transmit_units),
            ("receive", vt.receive_impulse_response, vt.receive_sampling_rate,
             vt.receive_units),
        ):
            if ir is None:
                continue
            g = f.create_group(side)
            _num(g, "impulse_response", np.asarray(ir), units)
            # (type: ignore below) not None where its impulse response is not None
            _num(g, "sampling_rate", float(fs), "Hz")  # type: ignore[arg-type]
            _num(g, "start_time", 0.0, "s")
            _text(g, "unit", units)

        g = f.create_group("medium")
        _num(g, "density", vt.medium.density, "kg/m^3")
        _num(g, "sound_speed", vt.medium.sound_speed, "m/s")

        g = f.create_group("parameters")
        values = g.create_group("values")
        for key, value in vt.parameters.items():
            values.create_dataset(key, data=float(value))
        unc = g.create_group("uncertainties")
        for key, value in vt.uncertainties.items():
            unc.create_dataset(key, data=float(value))

        p = vt.provenance
        g = f.create_group("provenance")
        _text(g, "holoprobe_version", p.holoprobe_version)
        _text(g, "created_utc", p.created_utc)
        _text(g, "config", p.config)
        _text(g, "config_format", p.config_format)
        _text(g, "notes", p.notes)
        names = list(p.input_files)
        g.create_dataset("input_files", data=np.array(names, dtype=object), dtype=_STR,
                         shape=(len(names),))
        g.create_dataset("input_sha256", data=np.array([p.input_files[n] for n in names],
                                                       dtype=object),
                         dtype=_STR, shape=(len(names),))
    return target


def _root_check(f: h5py.File, file: str) -> None:
    def attr(key: str) -> Any:
        value = f.attrs.get(key)
        return value.decode() if isinstance(value, bytes) else value

    if attr("format") != FORMAT_NAME or attr("kind") != KIND_VIRTUAL_TRANSDUCER:
        raise InputError(f"not a holoprobe virtual transducer file (format={attr('format')!r}, "
                         f"kind={attr('kind')!r}; expected {FORMAT_NAME!r}, "
                         f"{KIND_VIRTUAL_TRANSDUCER!r})", file=file, field="/")
    version = attr("schema_version")
    if isinstance(version, bool) or not isinstance(version, int | np.integer):
        raise InputError(f"expected an integer schema_version attribute, got {version!r}",
                         file=file, field="/schema_version")
    if not 1 <= int(version) <= SCHEMA_VERSION:
        raise InputError(f"schema_version {int(version)} is not supported by this holoprobe "
                         f"(reads 1..{SCHEMA_VERSION}); upgrade holoprobe", file=file,
                         field="/schema_version")


def read_virtual_transducer(path: str | os.PathLike) -> VirtualTransducer:
    """Read ``virtual_transducer.h5`` (see :func:`write_virtual_transducer`).

    Raises
    ------
    InputError
        Missing file, not HDF5, wrong ``format``/``kind``, unsupported
        ``schema_version``, or a missing/malformed dataset (named in the message).
    """
    file = str(path)
    if not Path(file).is_file():
        raise InputError("no such file", file=file)
    try:
        f = h5py.File(file, "r")
    except OSError as exc:
        raise InputError(f"not a readable HDF5 file ({exc})", file=file) from None
    with f:
        _root_check(f, file)
        r = HDF5Reader(f, file)
        count = r.integer("/elements/count")
        if count < 1:
            raise r.error(f"expected at least one element, got {count}", "/elements/count")
        tx, tx_fs, tx_units = _read_response(r, "transmit", TRANSMIT_UNITS)
        if "receive" in f:
            rx, rx_fs, rx_units = _read_response(r, "receive", RECEIVE_UNITS)
        else:
            rx, rx_fs, rx_units = None, None, RECEIVE_UNITS[0]
        focus = r.scalar("/lens/focus", units="m", allow_inf=True)
        center = r.array("/aperture/center", units="m", ndim=1, shape=(2,), dtype=float)
        names, hashes = _read_input_files(r)
        try:
            return VirtualTransducer(
                provenance=_provenance(r, names, hashes),
                element_count=count,
                pitch=r.scalar("/elements/pitch", units="m"),
                element_width=r.scalar("/elements/width", units="m"),
                element_height=r.scalar("/elements/height", units="m"),
                transmit_impulse_response=tx,
                transmit_sampling_rate=tx_fs,
                transmit_units=tx_units,
                lens_focus=focus,
                aperture_center=(float(center[0]), float(center[1])),
                aperture_width=r.scalar("/aperture/width", units="m"),
                aperture_height=r.scalar("/aperture/height", units="m"),
                receive_impulse_response=rx,
                receive_sampling_rate=rx_fs,
                receive_units=rx_units,
                medium=Medium(density=r.scalar("/medium/density", units="kg/m^3"),
                              sound_speed=r.scalar("/medium/sound_speed", units="m/s")),
                **_element_arrays(r, count),
                array=(r.array_geometry("/elements/array") if "/elements/array" in f
                       else None),
                parameters=r.floats("/parameters/values"),
                uncertainties=r.floats("/parameters/uncertainties"),
                name=str(f.attrs.get("name", "")),
            )
        except InputError as exc:
            if exc.file:
                raise
            raise InputError(exc.detail, file=file, field=_dataset_of(exc.field)) from None


def _read_response(r: HDF5Reader, side: str, units: tuple[str, ...]
                   ) -> tuple[np.ndarray, float, str]:
    """The impulse response of ``/transmit`` or ``/receive``: (samples, sampling rate in
    Hz, unit), checked (≥ 2 samples, a unit among ``units``, start time 0 if given)."""
    r.node(f"/{side}", group=True)
    arr = r.array(f"/{side}/impulse_response", units=units, ndim=1, dtype=float)
    if arr.size < 2:
        raise r.error("expected at least 2 samples", f"/{side}/impulse_response")
    unit = r.units(r.f[f"/{side}/impulse_response"], f"/{side}/impulse_response", units)
    fs = r.scalar(f"/{side}/sampling_rate", units="Hz", positive=True)
    if f"/{side}/start_time" in r.f:
        start = r.scalar(f"/{side}/start_time", units="s")
        if start != 0.0:
            raise r.error(f"expected 0 (responses start at t = 0), got {start!r}",
                          f"/{side}/start_time")
    return arr, fs, unit


def _read_input_files(r: HDF5Reader) -> tuple[list[str], list[str]]:
    """Names and SHA-256 hashes of ``/provenance``'s input files (one hash per name)."""
    r.node("/provenance", group=True)
    names = r.texts("/provenance/input_files")
    hashes = r.texts("/provenance/input_sha256")
    if len(names) != len(hashes):
        raise r.error(f"expected one hash per input file ({len(names)}), got {len(hashes)}",
                      "/provenance/input_sha256")
    return names, hashes


def _provenance(r: HDF5Reader, names: list[str], hashes: list[str]) -> Provenance:
    """The :class:`Provenance` of ``/provenance`` (its own checks name ``provenance.*``)."""
    return Provenance(
        holoprobe_version=r.text("/provenance/holoprobe_version"),
        created_utc=r.text("/provenance/created_utc"),
        input_files=dict(zip(names, hashes, strict=True)),
        config=r.text("/provenance/config", default=""),
        config_format=r.text("/provenance/config_format", default=""),
        notes=r.text("/provenance/notes", default=""),
    )


def _element_arrays(r: HDF5Reader, count: int) -> dict[str, np.ndarray | None]:
    """The optional per-element datasets of ``/elements`` (shape (count,); None if absent),
    by their :class:`VirtualTransducer` field names."""
    datasets = {"element_sensitivity": ("/elements/sensitivity", "1"),
                "element_delay": ("/elements/delay", "s"),
                "element_transmit_amplitude": ("/elements/transmit_amplitude", "1"),
                "element_transmit_delay": ("/elements/transmit_delay", "s")}
    return {key: (r.array(name, units=units, ndim=1, shape=(count,), dtype=float)
                  if name in r.f else None)
            for key, (name, units) in datasets.items()}


_FIELD_TO_DATASET = {
    "element_count": "/elements/count",
    "pitch": "/elements/pitch",
    "element_width": "/elements/width",
    "element_height": "/elements/height",
    "transmit_impulse_response": "/transmit/impulse_response",
    "transmit_sampling_rate": "/transmit/sampling_rate",
    "lens_focus": "/lens/focus",
    "aperture_center": "/aperture/center",
    "aperture_width": "/aperture/width",
    "aperture_height": "/aperture/height",
    "receive_impulse_response": "/receive/impulse_response",
    "receive_sampling_rate": "/receive/sampling_rate",
    "density": "/medium/density",
    "sound_speed": "/medium/sound_speed",
    "element_sensitivity": "/elements/sensitivity",
    "element_delay": "/elements/delay",
    "element_transmit_amplitude": "/elements/transmit_amplitude",
    "element_transmit_delay": "/elements/transmit_delay",
}


def _dataset_of(field: str | None) -> str | None:
    if field is None:
        return None
    if field.startswith("provenance."):
        return "/provenance/" + field.split(".", 1)[1].split("[", 1)[0]
    return _FIELD_TO_DATASET.get(field, field)
