"""holoprobe's native HDF5 files for measurements (schema version 1).

One file holds one measurement: a hydrophone scan (``kind="hydrophone_scan"``)
or an echo recording (``kind="echo_recording"``). Every dataset carries a
``units`` attribute; the schema is documented in ``docs/formats.md``. Readers
validate everything and raise :class:`~holoprobe.errors.InputError` naming the
file and the dataset.
"""

from __future__ import annotations

import datetime as _dt
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError, require_instance
from holoprobe.geometry import ArrayGeometry, Medium, PlaneGrid, Pose, uniform_axis_step
from holoprobe.io._atomic import atomic_write
from holoprobe.io._hdf5 import HDF5Reader
from holoprobe.io._plausible import check_measurement
from holoprobe.measurement import (
    DriveSignal,
    EchoRecording,
    HydrophoneCalibration,
    HydrophoneScan,
    ProbeInfo,
    adopt_read_only,
)
from holoprobe.plausibility import PlausibilityConfig

__all__ = [
    "FORMAT_NAME",
    "KIND_ECHO",
    "KIND_SCAN",
    "SCHEMA_VERSION",
    "probe_array_kind",
    "read_echo",
    "read_file_kind",
    "read_scan",
    "write_echo",
    "write_scan",
]

FORMAT_NAME = "holoprobe"
"""Value of the root attribute ``format`` of every native file."""
SCHEMA_VERSION = 1
"""Schema version written by this holoprobe; readers accept versions up to it."""
KIND_SCAN = "hydrophone_scan"
KIND_ECHO = "echo_recording"

_QUANTITY_UNITS = {"voltage": "V", "pressure": "Pa"}
_PROBE_FIELDS = {  # field -> units
    "element_count": "1",
    "pitch": "m",
    "element_width": "m",
    "element_height": "m",
    "center_frequency": "Hz",
    "lens_focus": "m",
}


def _holoprobe_version() -> str:
    try:
        from holoprobe import __version__
    except ImportError:  # pragma: no cover - partial installs
        return "unknown"
    return str(__version__)


# --------------------------------------------------------------------------- writing


def _dataset(group: h5py.Group, name: str, value: Any, units: str, **kwargs: Any) -> h5py.Dataset:
    ds = group.create_dataset(name, data=value, **kwargs)
    ds.attrs["units"] = units
    return ds


def _chunk_shape(shape: tuple[int, ...], itemsize: int, chunk_bytes: int) -> tuple[int, ...]:
    """Chunks that keep the last (time) axis whole and hold about ``chunk_bytes``."""
    *lead, last = shape
    per_row = max(1, last * itemsize)
    rows = max(1, chunk_bytes // per_row)
    chunk = [last]
    for n in reversed(lead):
        take = int(min(n, rows))
        chunk.insert(0, max(1, take))
        rows = max(1, rows // max(1, n))
    return tuple(chunk)


def _big_dataset_options(arr: NDArray, compression: str | None, compression_level: int,
                         chunk_bytes: int) -> dict[str, Any]:
    options: dict[str, Any] = {"chunks": _chunk_shape(arr.shape, arr.dtype.itemsize, chunk_bytes)}
    if compression is not None:
        if compression not in ("gzip", "lzf"):
            raise InputError("expected None, 'gzip' or 'lzf'", field="compression")
        options["compression"] = compression
        if compression == "gzip":
            options["compression_opts"] = int(compression_level)
        options["shuffle"] = True
    return options


def _write_root(f: h5py.File, kind: str, source: str, created_by: str) -> None:
    f.attrs["format"] = FORMAT_NAME
    f.attrs["kind"] = kind
    f.attrs["schema_version"] = np.int64(SCHEMA_VERSION)
    f.attrs["created_by"] = created_by
    f.attrs["holoprobe_version"] = _holoprobe_version()
    f.attrs["created_utc"] = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    f.attrs["source"] = source


def _write_medium(f: h5py.File, medium: Medium) -> None:
    g = f.create_group("medium")
    _dataset(g, "density", float(medium.density), "kg/m^3")
    _dataset(g, "sound_speed", float(medium.sound_speed), "m/s")


def _write_probe(f: h5py.File, probe: ProbeInfo | None) -> None:
    if probe is None:
        return
    g = f.create_group("probe")
    g.attrs["name"] = probe.name
    g.attrs["nominal"] = True
    for name, units in _PROBE_FIELDS.items():
        value = getattr(probe, name)
        _dataset(g, name, np.int64(value) if name == "element_count" else float(value), units)
    if probe.array is not None:
        write_array_geometry(g.create_group("array"), probe.array)


def write_array_geometry(g: h5py.Group, array: ArrayGeometry) -> None:
    """Write an :class:`~holoprobe.geometry.ArrayGeometry` into the HDF5 group ``g``:
    datasets ``positions``, ``normals``, ``width_directions``, ``widths``, ``heights``
    and, when present, ``radius_of_curvature``, ``pitch``, ``grid_shape``,
    ``grid_position``; attribute ``kind`` (``/probe/array`` of a measurement,
    ``/elements/array`` of a virtual transducer; read back by
    :meth:`HDF5Reader.array_geometry`)."""
    g.attrs["kind"] = array.kind
    for name in ("positions", "widths", "heights"):
        _dataset(g, name, np.asarray(getattr(array, name)), "m")
    for name in ("normals", "width_directions"):
        _dataset(g, name, np.asarray(getattr(array, name)), "1")
    if array.radius_of_curvature is not None:
        _dataset(g, "radius_of_curvature", float(array.radius_of_curvature), "m")
    if array.pitch is not None:
        _dataset(g, "pitch", np.asarray(array.pitch, dtype=float), "m")
    if array.grid_shape is not None:
        _dataset(g, "grid_shape", np.asarray(array.grid_shape, dtype=np.int64), "1")
    if array.grid_position is not None:
        _dataset(g, "grid_position", np.asarray(array.grid_position, dtype=np.int64), "1")


def _write_drive(f: h5py.File, drive: DriveSignal | None) -> None:
    if drive is None:
        return
    g = f.create_group("drive")
    _dataset(g, "voltage", np.asarray(drive.voltage), "V")
    _dataset(g, "sampling_rate", float(drive.sampling_rate), "Hz")


def _write_calibration(f: h5py.File, cal: HydrophoneCalibration | None) -> None:
    if cal is None:
        return
    g = f.create_group("calibration")
    g.attrs["name"] = cal.name
    _dataset(g, "frequency", np.asarray(cal.frequency), "Hz")
    _dataset(g, "sensitivity", np.asarray(cal.sensitivity), "V/Pa")
    if cal.phase is not None:
        ph = _dataset(g, "phase", np.asarray(cal.phase), "rad")
        ph.attrs["convention"] = "P(omega) = conj(FFT{p}) (holoprobe)"
    _dataset(g, "polarity", np.int64(cal.polarity), "1")


def _protect(source: str) -> tuple[str, ...]:
    return (source,) if source and os.path.exists(source) else ()


@contextmanager
def _create(target: Path, kind: str, source: str, created_by: str, overwrite: bool
            ) -> Iterator[h5py.File]:
    """A new native file of ``kind`` at ``target``, written atomically, its root
    attributes set; the input file named by ``source`` is never overwritten."""
    with atomic_write(target, overwrite=overwrite, protect=_protect(source)) as tmp, \
            h5py.File(tmp, "w") as f:
        _write_root(f, kind, source, created_by)
        yield f


def _write_on_grid(f: h5py.File, grid: PlaneGrid, name: str, data: np.ndarray, units: str,
                   **options: Any) -> h5py.Dataset:
    """Write the scan-plane axes ``x``, ``y`` (m) and ``data`` (x, y, ...) with the
    axes attached as its dimension scales."""
    x = _dataset(f, "x", np.asarray(grid.x), "m")
    y = _dataset(f, "y", np.asarray(grid.y), "m")
    ds = _dataset(f, name, data, units, **options)
    x.make_scale("x")
    y.make_scale("y")
    ds.dims[0].attach_scale(x)
    ds.dims[1].attach_scale(y)
    ds.dims[0].label, ds.dims[1].label = "x", "y"
    return ds


def _write_timing(f: h5py.File, sampling_rate: float, start_time: float) -> None:
    """The sampling rate (Hz) and the time of sample 0 (s) of a recording."""
    _dataset(f, "sampling_rate", float(sampling_rate), "Hz")
    _dataset(f, "start_time", float(start_time), "s")


def write_scan(
    path: str | os.PathLike,
    scan: HydrophoneScan,
    *,
    overwrite: bool = False,
    compression: str | None = None,
    compression_level: int = 4,
    chunk_bytes: int = 1 << 20,
) -> Path:
    """Write a hydrophone scan to a native holoprobe HDF5 file (atomically).

    Parameters
    ----------
    path : str or PathLike
        Output file (``.h5``). Written through a temporary file and renamed.
    scan : HydrophoneScan
        The scan; ``data`` of shape (nx, ny, nt) is stored with its dtype.
    overwrite : bool
        Replace an existing file. The file named by ``scan.source`` (the input)
        is never overwritten.
    compression : {None, "gzip", "lzf"}
        HDF5 filter for the scan data (default none: fastest to read and write).
    compression_level : int
        gzip level 0–9 (only with ``compression="gzip"``).
    chunk_bytes : int
        Target size of one HDF5 chunk of the scan data in bytes; a chunk keeps
        the time axis whole.

    Returns
    -------
    pathlib.Path
        The written file.

    Notes
    -----
    The layout (datasets, shapes, units) is documented in ``docs/formats.md``.
    ``scan.source`` is kept as the root attribute ``source``.
    """
    require_instance(scan, HydrophoneScan, "scan")
    target = Path(path)
    data = np.asarray(scan.data)
    with _create(target, KIND_SCAN, scan.source, "holoprobe.io.write_scan", overwrite) as f:
        ds = _write_on_grid(f, scan.grid, "data", data, _QUANTITY_UNITS[scan.quantity],
                            **_big_dataset_options(data, compression, compression_level,
                                                   chunk_bytes))
        ds.attrs["quantity"] = scan.quantity
        ds.dims[2].label = "t"
        _write_timing(f, scan.sampling_rate, scan.start_time)
        pose = f.create_group("pose")
        pose.attrs["nominal"] = True
        pose.attrs["convention"] = ("R = Rz(theta[2]) @ Ry(theta[1]) @ Rx(theta[0]); "
                                    "in-plane (u, v, 0) lies at R @ (u, v, 0) + origin")
        p = scan.grid.pose
        _dataset(pose, "theta", np.array([p.theta_x, p.theta_y, p.theta_z]), "rad")
        _dataset(pose, "origin", np.asarray(p.origin, dtype=float), "m")
        _write_medium(f, scan.medium)
        _write_calibration(f, scan.calibration)
        _write_probe(f, scan.probe)
        _write_drive(f, scan.drive)
    return target


def write_echo(
    path: str | os.PathLike,
    rec: EchoRecording,
    *,
    overwrite: bool = False,
    compression: str | None = None,
    compression_level: int = 4,
    chunk_bytes: int = 1 << 20,
) -> Path:
    """Write an echo recording to a native holoprobe HDF5 file (atomically).

    Parameters
    ----------
    path : str or PathLike
        Output file (``.h5``).
    rec : EchoRecording
        The recording; ``rf`` of shape (n_elements, n_samples) is stored with its dtype.
    overwrite, compression, compression_level, chunk_bytes
        As for :func:`write_scan`.

    Returns
    -------
    pathlib.Path
        The written file.
    """
    require_instance(rec, EchoRecording, "rec")
    target = Path(path)
    rf = np.asarray(rec.rf)
    with _create(target, KIND_ECHO, rec.source, "holoprobe.io.write_echo", overwrite) as f:
        ds = _dataset(f, "rf", rf, rec.unit,
                      **_big_dataset_options(rf, compression, compression_level, chunk_bytes))
        ds.dims[0].label = "element"
        ds.dims[1].label = "t"
        _write_timing(f, rec.sampling_rate, rec.start_time)
        _write_medium(f, rec.medium)
        _write_probe(f, rec.probe)
        _write_drive(f, rec.drive)
    return target


# --------------------------------------------------------------------------- reading


class _Reader(HDF5Reader):
    """:class:`HDF5Reader` plus the measurement nouns of the native schema."""

    def build(self, cls: type, prefix: str, **kwargs: Any) -> Any:
        """Construct a measurement noun, re-raising its InputError with file and dataset."""
        try:
            return cls(**kwargs)
        except InputError as exc:
            name = f"{prefix}/{exc.field}" if exc.field else prefix
            raise self.error(exc.detail, name) from None

    def grid_axes(self) -> tuple[NDArray, NDArray]:
        """``/x`` and ``/y`` (m), checked to be uniform and increasing."""
        axes = []
        for name in ("/x", "/y"):
            axis = self.array(name, units="m", ndim=1)
            try:
                uniform_axis_step(axis, name)
            except InputError as exc:
                raise self.error(exc.detail, name) from None
            axes.append(axis)
        return axes[0], axes[1]

    # nouns ---------------------------------------------------------------------------

    def medium(self) -> Medium:
        self.node("/medium", group=True)
        return self.build(
            Medium, "/medium",
            density=self.scalar("/medium/density", units="kg/m^3", positive=True),
            sound_speed=self.scalar("/medium/sound_speed", units="m/s", positive=True),
        )

    def probe(self) -> ProbeInfo | None:
        if "probe" not in self.f:
            return None
        g = self.node("/probe", group=True)
        values: dict[str, Any] = {}
        for name, units in _PROBE_FIELDS.items():
            values[name] = self.scalar(f"/probe/{name}", units=units,
                                       integer=name == "element_count",
                                       allow_inf=name == "lens_focus")
        values["name"] = self.attr_str(g, "name", "/probe", default="")
        if "array" in g:
            values["array"] = self.array_geometry("/probe/array")
        return self.build(ProbeInfo, "/probe", **values)

    def drive(self) -> DriveSignal | None:
        if "drive" not in self.f:
            return None
        self.node("/drive", group=True)
        return self.build(
            DriveSignal, "/drive",
            voltage=self.array("/drive/voltage", units="V", ndim=1),
            sampling_rate=self.scalar("/drive/sampling_rate", units="Hz", positive=True),
        )

    def calibration(self) -> HydrophoneCalibration | None:
        if "calibration" not in self.f:
            return None
        g = self.node("/calibration", group=True)
        freq = self.array("/calibration/frequency", units="Hz", ndim=1)
        n = freq.shape[0]
        sens = self.array("/calibration/sensitivity", units="V/Pa", ndim=1, shape=(n,))
        phase = None
        if "phase" in g:
            phase = self.array("/calibration/phase", units="rad", ndim=1, shape=(n,))
        return self.build(
            HydrophoneCalibration, "/calibration",
            frequency=freq, sensitivity=sens, phase=phase,
            polarity=self.scalar("/calibration/polarity", units="1", integer=True),
            name=self.attr_str(g, "name", "/calibration", default=""),
        )


def _open_checked(path: str | os.PathLike, kind: str) -> tuple[h5py.File, str]:
    p = Path(path)
    file = str(p)
    if not p.is_file():
        raise InputError("no such file", file=file)
    if not h5py.is_hdf5(p):
        raise InputError("not an HDF5 file (expected a holoprobe .h5 file)", file=file)
    try:
        f = h5py.File(p, "r")
    except OSError as exc:
        raise InputError(f"cannot open as HDF5: {exc}", file=file) from None
    try:
        fmt = f.attrs.get("format")
        if isinstance(fmt, bytes):
            fmt = fmt.decode()
        if fmt != FORMAT_NAME:
            raise InputError(f"root attribute 'format' is {fmt!r}, expected {FORMAT_NAME!r} "
                             "(not a holoprobe file)", file=file, field="/")
        version = f.attrs.get("schema_version")
        if version is None or not np.issubdtype(np.asarray(version).dtype, np.integer):
            raise InputError(f"root attribute 'schema_version' is {version!r}, expected an "
                             "integer", file=file, field="/")
        if int(version) > SCHEMA_VERSION:
            raise InputError(
                f"schema version {int(version)} was written by a newer holoprobe; this one "
                f"reads versions up to {SCHEMA_VERSION}: upgrade holoprobe",
                file=file, field="/")
        if int(version) < 1:
            raise InputError(f"invalid schema version {int(version)}", file=file, field="/")
        found = f.attrs.get("kind")
        if isinstance(found, bytes):
            found = found.decode()
        if found != kind:
            hint = {KIND_SCAN: "read_scan", KIND_ECHO: "read_echo",
                    "cw_hologram": "read_hologram",
                    "transient_hologram": "read_hologram"}.get(str(found), "")
            raise InputError(
                f"file kind is {found!r}, expected {kind!r}"
                + (f" (read it with holoprobe.io.{hint})" if hint else ""),
                file=file, field="/")
    except BaseException:
        f.close()
        raise
    return f, file


def read_file_kind(path: str | os.PathLike) -> str:
    """The ``kind`` root attribute of a native holoprobe file (e.g. ``"hydrophone_scan"``).

    Raises
    ------
    InputError
        If the file is not a holoprobe HDF5 file.
    """
    p = Path(path)
    if not p.is_file() or not h5py.is_hdf5(p):
        raise InputError("not a holoprobe HDF5 file", file=str(p))
    with h5py.File(p, "r") as f:
        fmt = f.attrs.get("format")
        kind = f.attrs.get("kind")
    fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
    kind = kind.decode() if isinstance(kind, bytes) else kind
    if fmt != FORMAT_NAME or not isinstance(kind, str):
        raise InputError("not a holoprobe file (root attributes 'format'/'kind')",
                         file=str(p), field="/")
    return kind


def probe_array_kind(path: str | os.PathLike) -> str | None:
    """The element layout kind (``/probe/array`` attribute ``kind``, e.g. ``"convex"``)
    of a native measurement file, None when it has no layout or is not a native file.
    Nothing large is read."""
    p = Path(path)
    if not p.is_file() or not h5py.is_hdf5(p):
        return None
    with h5py.File(p, "r") as f:
        g = f.get("/probe/array")
        kind = None if g is None else g.attrs.get("kind")
    return kind.decode() if isinstance(kind, bytes) else kind


def read_scan(path: str | os.PathLike, *, plausibility: PlausibilityConfig | None = None
              ) -> HydrophoneScan:
    """Read a hydrophone scan from a native holoprobe HDF5 file, validating it.

    Parameters
    ----------
    path : str or PathLike
        A file written by :func:`write_scan` (schema version ≤ :data:`SCHEMA_VERSION`).
    plausibility : PlausibilityConfig, optional
        Ranges of the physical values (:mod:`holoprobe.plausibility`; default ranges
        when omitted): a value outside gives one InputError line naming the file, the
        field, the value and the range.

    Returns
    -------
    HydrophoneScan
        ``data`` (nx, ny, nt) with the stored dtype; ``source`` is ``str(path)``.

    Raises
    ------
    InputError
        Naming the file and the dataset: missing dataset, wrong shape or units,
        NaN/inf, non-uniform grid, wrong kind, newer schema version.
    """
    f, file = _open_checked(path, KIND_SCAN)
    with f:
        r = _Reader(f, file)
        x, y = r.grid_axes()
        ds = r.node("/data")
        quantity = r.attr_str(ds, "quantity", "/data")
        if quantity not in _QUANTITY_UNITS:
            raise r.error(f"attribute 'quantity' is {quantity!r}, expected 'voltage' or "
                          "'pressure'", "/data")
        data = r.array("/data", units=_QUANTITY_UNITS[quantity], ndim=3,
                       shape=(x.size, y.size, None))
        if data.shape[2] < 2:
            raise r.error(f"expected at least 2 time samples, got shape {data.shape}", "/data")
        adopt_read_only(data)  # the scan keeps the fresh array without a copy
        r.node("/pose", group=True)
        theta = r.array("/pose/theta", units="rad", ndim=1, shape=(3,))
        origin = r.array("/pose/origin", units="m", ndim=1, shape=(3,))
        pose = r.build(Pose, "/pose", theta_x=theta[0], theta_y=theta[1], theta_z=theta[2],
                       origin=tuple(origin))
        grid = r.build(PlaneGrid, "/", x=x, y=y, pose=pose)
        scan = r.build(
            HydrophoneScan, "/",
            data=data,
            grid=grid,
            sampling_rate=r.scalar("/sampling_rate", units="Hz", positive=True),
            start_time=r.scalar("/start_time", units="s"),
            quantity=quantity,
            medium=r.medium(),
            calibration=r.calibration(),
            probe=r.probe(),
            drive=r.drive(),
            source=file,
        )
    return check_measurement(scan, plausibility, file=file)


def read_echo(path: str | os.PathLike, *, plausibility: PlausibilityConfig | None = None
              ) -> EchoRecording:
    """Read an echo recording from a native holoprobe HDF5 file, validating it.

    Parameters
    ----------
    path : str or PathLike
        A file written by :func:`write_echo`.
    plausibility : PlausibilityConfig, optional
        Ranges of the physical values (:mod:`holoprobe.plausibility`; default ranges
        when omitted): a value outside gives one InputError line naming the file, the
        field, the value and the range.

    Returns
    -------
    EchoRecording
        ``rf`` (n_elements, n_samples) with the stored dtype; ``source`` is ``str(path)``.

    Raises
    ------
    InputError
        Naming the file and the dataset (see :func:`read_scan`).
    """
    f, file = _open_checked(path, KIND_ECHO)
    with f:
        r = _Reader(f, file)
        probe = r.probe()
        n_el = None if probe is None else probe.element_count
        rf = r.array("/rf", units=None, ndim=2, shape=(n_el, None))
        unit = r.units(r.node("/rf"), "/rf", None)
        echo = r.build(
            EchoRecording, "/",
            rf=rf,
            sampling_rate=r.scalar("/sampling_rate", units="Hz", positive=True),
            start_time=r.scalar("/start_time", units="s"),
            unit=unit,
            drive=r.drive(),
            probe=probe,
            medium=r.medium(),
            source=file,
        )
    return check_measurement(echo, plausibility, file=file)
