"""The published MATLAB toolkit's file layout (ScanData.mat, TransmitData.mat, ...).

The toolkit that accompanies the paper keeps one measurement in a directory:

* ``ScanData.mat`` — ``Grid`` (x, y in m, ``z`` scalar 0, dx, dy, dt, Nx, Ny, Nt, ...),
  ``voltage_mV`` [Nx, Ny, Nt] in mV, ``medium`` {sound_speed, density};
* ``TransmitData.mat`` — ``Trans`` (Verasonics probe description) and
  ``Transmit`` {SamplingRate (Hz), VoltageSignal (V)} of the scan experiment;
* ``ReceiveData.mat`` — ``Trans``, ``Transmit`` (drive of the echo experiment) and
  ``Receive`` {RF [Nsamp, Nch] in ADC levels, SamplingRate (Hz)};
* ``sensitivity.mat`` — ``Frequency`` (MHz), ``Sensitivity`` (mV/MPa).

Readers convert to SI and holoprobe's nouns and axis orders; writers produce
exactly that layout (plus one extra struct ``holoprobe`` per file that the
toolkit ignores, holding what the layout cannot: start time, nominal pose,
calibration phase and polarity, echo unit and medium). See ``docs/formats.md``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from holoprobe.errors import InputError, require_instance
from holoprobe.geometry import ArrayGeometry, Medium, PlaneGrid, Pose, uniform_axis_step
from holoprobe.io._matfile import MatStruct, load_mat, save_mat
from holoprobe.io._plausible import check_measurement
from holoprobe.measurement import (
    DriveSignal,
    EchoRecording,
    HydrophoneCalibration,
    HydrophoneScan,
    ProbeInfo,
)
from holoprobe.plausibility import PlausibilityConfig

__all__ = [
    "REFERENCE_FILES",
    "VERASONICS_SOUND_SPEED",
    "probe_from_trans",
    "read_reference_calibration",
    "read_reference_echo",
    "read_reference_scan",
    "trans_from_probe",
    "write_reference_echo",
    "write_reference_scan",
]

REFERENCE_FILES = {
    "scan": "ScanData.mat",
    "transmit": "TransmitData.mat",
    "receive": "ReceiveData.mat",
    "sensitivity": "sensitivity.mat",
}
"""File names of the reference layout, by role."""

VERASONICS_SOUND_SPEED = 1540.0
"""Sound speed (m/s) that Verasonics uses to express ``Trans`` lengths in wavelengths."""

_TRANSMIT_ALIASES = ("TransmitData.mat", "Transmit.mat")  # the toolkit README says Transmit.mat
_EXTRA = "holoprobe"  # extra struct per file, ignored by the MATLAB toolkit
_MV_PER_V = 1e3
_MV_PER_MPA_PER_V_PER_PA = 1e9  # 1 V/Pa = 1e3 mV / 1e-6 MPa
_HZ_PER_MHZ = 1e6
_MM_PER_M = 1e3


# --------------------------------------------------------------------------- helpers


def _wrap(file: str, prefix: str, cls: type, **kwargs: Any) -> Any:
    """Construct a noun; re-raise its InputError with the file and MATLAB field."""
    try:
        return cls(**kwargs)
    except InputError as exc:
        field = f"{prefix}.{exc.field}" if (prefix and exc.field) else (exc.field or prefix)
        raise InputError(exc.detail, file=file, field=field or None) from None


def _resolve(path: str | os.PathLike, default_name: str) -> tuple[Path, Path]:
    """(file, directory) for a path that names a directory or a .mat file."""
    p = Path(path)
    if p.is_dir():
        f = p / default_name
        if not f.is_file():
            raise InputError(f"directory holds no {default_name}", file=str(p))
        return f, p
    if not p.is_file():
        raise InputError("no such file or directory", file=str(p))
    return p, p.parent


def _sibling(directory: Path, names: tuple[str, ...]) -> Path | None:
    for name in names:
        if (directory / name).is_file():
            return directory / name
    return None


def _medium(s: MatStruct) -> Medium:
    return _wrap(s.file, s.prefix, Medium,
                 density=s.scalar("density", positive=True),
                 sound_speed=s.scalar("sound_speed", positive=True))


def _drive(s: MatStruct) -> DriveSignal:
    return _wrap(s.file, s.prefix, DriveSignal,
                 voltage=s.vector("VoltageSignal").astype(float),
                 sampling_rate=s.scalar("SamplingRate", positive=True))


def _extra(top: MatStruct) -> MatStruct | None:
    return top.optional_struct(_EXTRA)


def _row(values: Any) -> np.ndarray:
    return np.asarray(values, dtype=float).reshape(1, -1)


# --------------------------------------------------------------------------- Trans


def probe_from_trans(trans: MatStruct, *,
                     verasonics_sound_speed: float = VERASONICS_SOUND_SPEED) -> ProbeInfo:
    """Convert a Verasonics ``Trans`` struct to a :class:`ProbeInfo` (SI).

    Parameters
    ----------
    trans : MatStruct
        The struct (fields ``numelements``, ``frequency`` in MHz, ``spacingMm``,
        ``spacing`` and ``elementWidth`` in wavelengths, ``elevationApertureMm``,
        optional ``elevationFocusMm``, ``units``, ``name``).
    verasonics_sound_speed : float
        Sound speed in m/s that defines Verasonics' wavelength λ = c / f
        (Verasonics default 1540 m/s); used only where ``spacingMm`` is missing.

    Returns
    -------
    ProbeInfo

    Notes
    -----
    Pitch p = ``spacingMm``; element width w = ``elementWidth · spacingMm / spacing``
    (the ratio cancels whatever sound speed defined the wavelength; the rule of
    the published toolkit). Without ``spacingMm`` both use λ = c/f. With
    ``Trans.units == "mm"`` ``elementWidth`` is already in mm.
    """
    n = trans.integer("numelements", minimum=1)
    f_mhz = trans.scalar("frequency", positive=True)
    lam_mm = verasonics_sound_speed / (f_mhz * _HZ_PER_MHZ) * _MM_PER_M
    if "spacingMm" in trans:
        pitch_mm = trans.scalar("spacingMm", positive=True)
    elif "spacing" in trans:
        pitch_mm = trans.scalar("spacing", positive=True) * lam_mm
    else:
        raise trans.error("missing field (need spacingMm or spacing)", "spacingMm")
    units = trans.string("units", default="wavelengths")
    width = trans.scalar("elementWidth", positive=True)
    if units == "mm":
        width_mm = width
    elif "spacingMm" in trans and "spacing" in trans:
        width_mm = width * pitch_mm / trans.scalar("spacing", positive=True)
    else:
        width_mm = width * lam_mm
    focus_mm = (trans.scalar("elevationFocusMm", allow_inf=True)
                if "elevationFocusMm" in trans else np.inf)
    height_mm = trans.scalar("elevationApertureMm", positive=True)
    radius_mm = _trans_radius_mm(trans, n, pitch_mm, lam_mm if units != "mm" else 1.0)
    array = None
    if radius_mm is not None:
        try:
            array = ArrayGeometry.convex(n, pitch_mm / _MM_PER_M, radius_mm / _MM_PER_M,
                                         width_mm / _MM_PER_M, height_mm / _MM_PER_M)
        except InputError as exc:
            raise trans.error(exc.detail, "radiusMm") from None
    else:
        array = _trans_matrix(trans, n, lam_mm if units != "mm" else 1.0, width_mm, height_mm)
        if array is not None:  # a matrix: elevationApertureMm may be the whole aperture
            height_mm = float(array.heights[0]) * _MM_PER_M
    return _wrap(
        trans.file, trans.prefix, ProbeInfo,
        element_count=n,
        pitch=pitch_mm / _MM_PER_M,
        element_width=width_mm / _MM_PER_M,
        element_height=height_mm / _MM_PER_M,
        center_frequency=f_mhz * _HZ_PER_MHZ,
        lens_focus=focus_mm / _MM_PER_M if focus_mm > 0 else np.inf,
        name=trans.string("name", default=""),
        array=array,
    )


def _trans_matrix(trans: MatStruct, n: int, unit_mm: float, width_mm: float,
                  height_mm: float) -> ArrayGeometry | None:
    """The 2-D matrix layout of a ``Trans`` whose ``ElementPos`` (x, y, z in Trans units)
    holds distinct y on a flat regular grid; None for a 1-D array. Element size: the
    width ``elementWidth``; the height ``elevationApertureMm`` when it fits in the y
    pitch, else the width scaled by p_y/p_x (square-ish elements: the value is then
    the whole aperture's)."""
    if "ElementPos" not in trans:
        return None
    pos = trans.array("ElementPos")
    if pos.ndim != 2 or pos.shape[0] != n or pos.shape[1] < 3 or n < 2:
        return None
    xyz = pos[:, :3] * unit_mm / _MM_PER_M
    if np.ptp(xyz[:, 1]) <= 1e-9:
        return None  # one row: a 1-D array
    if np.ptp(xyz[:, 2]) > 1e-9 or (pos.shape[1] >= 5 and np.ptp(pos[:, 3:5]) > 1e-9):
        raise trans.error("elements at different y on a curved face (z or angles vary): "
                          "only flat 2-D matrix arrays are supported", "ElementPos")
    steps = []
    index = []
    for axis in (0, 1):
        values = np.unique(np.round(xyz[:, axis], 9))
        diffs = np.diff(values)
        step = float(diffs[diffs > 1e-9].min())
        idx = np.rint((xyz[:, axis] - values[0]) / step)
        if np.max(np.abs(xyz[:, axis] - values[0] - idx * step)) > 0.01 * step:
            raise trans.error(f"element {'xy'[axis]} positions are not on a regular grid "
                              f"(step {step * 1e3:.4g} mm)", "ElementPos")
        steps.append(step)
        index.append(idx.astype(np.int64))
    grid_position = np.stack(index, axis=-1)
    shape = (int(grid_position[:, 0].max()) + 1, int(grid_position[:, 1].max()) + 1)
    if np.unique(grid_position, axis=0).shape[0] != n:
        raise trans.error("two elements share a grid position", "ElementPos")
    width = width_mm / _MM_PER_M
    height = height_mm / _MM_PER_M
    if height > steps[1] * (1 + 1e-9):
        height = width * steps[1] / steps[0]
    centre = np.array([xyz[:, 0].min() + 0.5 * (shape[0] - 1) * steps[0],
                       xyz[:, 1].min() + 0.5 * (shape[1] - 1) * steps[1], 0.0])
    try:
        return ArrayGeometry(xyz - centre, np.tile([0.0, 0.0, 1.0], (n, 1)),
                             np.tile([1.0, 0.0, 0.0], (n, 1)), np.full(n, width),
                             np.full(n, height), kind="matrix",
                             grid_shape=shape, grid_position=grid_position,
                             pitch=(steps[0], steps[1]))
    except InputError as exc:
        raise trans.error(exc.detail, "ElementPos") from None


def _trans_radius_mm(trans: MatStruct, n: int, pitch_mm: float, unit_mm: float
                     ) -> float | None:
    """Radius of curvature (mm) of a convex ``Trans``: ``radiusMm``, else ``radius``
    (wavelengths), else from ``ElementPos`` (x, y, z in Trans units, azimuth angle in
    rad): chord between neighbours / (2 sin(Δangle/2)). None for a flat array. When
    both a radius and element angles are given they must agree (angle step = pitch/R)."""
    radius = None
    if "radiusMm" in trans:
        radius = trans.scalar("radiusMm")
    elif "radius" in trans:
        radius = trans.scalar("radius") * unit_mm
    angles = None
    if "ElementPos" in trans:
        pos = trans.array("ElementPos")
        if pos.ndim == 2 and pos.shape[0] == n and pos.shape[1] >= 4 and n > 1 \
                and np.ptp(pos[:, 3]) > 1e-9:
            angles = pos[:, 3]
            if radius is None or not radius > 0:
                chord = np.linalg.norm(np.diff(pos[:, :3], axis=0), axis=1) * unit_mm
                radius = float(np.median(chord / (2 * np.sin(0.5 * np.abs(np.diff(angles))))))
    if radius is None or not radius > 0:
        return None
    if angles is not None:
        step = float(np.median(np.abs(np.diff(angles))))
        if abs(step * radius / pitch_mm - 1) > 0.01:
            raise trans.error(f"element angles step {np.degrees(step):.4g}° but pitch/R = "
                              f"{np.degrees(pitch_mm / radius):.4g}° (radius {radius:.4g} mm)",
                              "ElementPos")
    return float(radius)


def trans_from_probe(probe: ProbeInfo, *,
                     verasonics_sound_speed: float = VERASONICS_SOUND_SPEED) -> dict[str, Any]:
    """A Verasonics-style ``Trans`` struct (as a dict) describing ``probe``.

    Lengths in wavelengths use λ = ``verasonics_sound_speed`` / centre frequency;
    ``spacingMm`` is written too, so :func:`probe_from_trans` recovers the pitch and
    width whatever that sound speed was.
    """
    f_mhz = probe.center_frequency / _HZ_PER_MHZ
    lam_mm = verasonics_sound_speed / probe.center_frequency * _MM_PER_M
    pitch_mm = probe.pitch * _MM_PER_M
    return {
        "name": probe.name,
        "units": "wavelengths",
        "numelements": float(probe.element_count),
        "frequency": f_mhz,
        "spacingMm": pitch_mm,
        "spacing": pitch_mm / lam_mm,
        "elementWidth": probe.element_width * _MM_PER_M / lam_mm,
        "elevationApertureMm": probe.element_height * _MM_PER_M,
        "elevationFocusMm": probe.lens_focus * _MM_PER_M,
        "ConnectorES": np.arange(1, probe.element_count + 1, dtype=float).reshape(-1, 1),
        **_convex_trans_fields(probe, lam_mm),
    }


def _convex_trans_fields(probe: ProbeInfo, lam_mm: float) -> dict[str, Any]:
    """``radiusMm`` and ``ElementPos`` (x, y, z in wavelengths, azimuth and elevation
    angles in rad; Verasonics' layout) of a convex probe; nothing for a flat one."""
    array = probe.array
    if array is not None and array.kind == "matrix":  # element centres, flat, no angles
        pos = np.zeros((array.count, 5))
        pos[:, :3] = array.positions * _MM_PER_M / lam_mm
        return {"ElementPos": pos}
    if array is None or array.radius_of_curvature is None:
        return {}
    pos = np.zeros((array.count, 5))
    pos[:, :3] = array.positions * _MM_PER_M / lam_mm
    pos[:, 3] = array.element_angles
    return {"radiusMm": array.radius_of_curvature * _MM_PER_M, "ElementPos": pos}


# --------------------------------------------------------------------------- reading


def read_reference_calibration(path: str | os.PathLike, *, polarity: int = -1,
                               plausibility: PlausibilityConfig | None = None
                               ) -> HydrophoneCalibration:
    """Read ``sensitivity.mat`` {Frequency (MHz), Sensitivity (mV/MPa)} in SI.

    Parameters
    ----------
    path : str or PathLike
        The file.
    polarity : {-1, 1}
        Hydrophone polarity when the file has no ``holoprobe`` extras. The
        published toolkit inverts the sign when converting voltage to pressure
        (its fibre-optic hydrophone reads a positive pressure as a negative
        voltage), hence the default −1.
    plausibility : PlausibilityConfig, optional
        Ranges of the physical values (:mod:`holoprobe.plausibility`; default ranges
        when omitted): a value outside gives one InputError line naming the file, the
        field, the value and the range.

    Returns
    -------
    HydrophoneCalibration
        Frequency in Hz, sensitivity in V/Pa (= mV/MPa / 1e9).
    """
    file = str(path)
    top = MatStruct(load_mat(path), file)
    freq = top.vector("Frequency")
    sens = top.vector("Sensitivity", length=freq.size)
    phase = None
    name = file
    extra = _extra(top)
    if extra is not None:
        polarity = extra.integer("polarity")
        name = extra.string("name", default=name)
        if "phase" in extra:
            phase = extra.vector("phase", length=freq.size)
    return check_measurement(_wrap(file, "", HydrophoneCalibration,
                                   frequency=freq * _HZ_PER_MHZ,
                                   sensitivity=sens / _MV_PER_MPA_PER_V_PER_PA,
                                   phase=phase, polarity=polarity, name=name),
                             plausibility, file=file)


def read_reference_scan(
    path: str | os.PathLike,
    *,
    sensitivity: str | os.PathLike | None = None,
    transmit: str | os.PathLike | None = None,
    use_siblings: bool = True,
    medium: Medium | None = None,
    hydrophone_polarity: int = -1,
    verasonics_sound_speed: float = VERASONICS_SOUND_SPEED,
    plausibility: PlausibilityConfig | None = None,
) -> HydrophoneScan:
    """Read a hydrophone scan stored in the published toolkit's layout.

    Parameters
    ----------
    path : str or PathLike
        A directory holding ``ScanData.mat`` or the scan .mat file itself.
    sensitivity, transmit : str or PathLike, optional
        ``sensitivity.mat`` (hydrophone calibration) and ``TransmitData.mat``
        (probe ``Trans`` and drive ``Transmit``). By default they are looked up
        next to the scan file.
    use_siblings : bool
        Look up the files above next to the scan file when not given.
    medium : Medium, optional
        Overrides the file's ``medium`` struct (required when the file has none).
    hydrophone_polarity : {-1, 1}
        Polarity for a ``sensitivity.mat`` without holoprobe extras (see
        :func:`read_reference_calibration`).
    verasonics_sound_speed : float
        See :func:`probe_from_trans`, in m/s.

    Returns
    -------
    HydrophoneScan
        ``data`` (nx, ny, nt) in V (``voltage_mV`` / 1000), x and y in m, sampling
        rate 1/``Grid.dt``; calibration, probe and drive when their files exist.
        The nominal pose is the identity moved to z = ``Grid.z`` (holoprobe extras
        win), the start time 0 (the toolkit takes the first sample as the emission).

    Raises
    ------
    InputError
        Naming the file and the MATLAB field (``Grid.dx``, ``voltage_mV`` ...).
    """
    scan_file, directory = _resolve(path, REFERENCE_FILES["scan"])
    file = str(scan_file)
    top = MatStruct(load_mat(scan_file), file)
    grid = top.struct("Grid")
    x = grid.vector("x")
    y = grid.vector("y")
    for key, axis in (("x", x), ("y", y)):
        n_key = "N" + key
        if n_key in grid and grid.integer(n_key) != axis.size:
            raise grid.error(f"is {grid.integer(n_key)} but Grid.{key} has {axis.size} values",
                             n_key)
        try:
            step = uniform_axis_step(axis, grid.name(key))
        except InputError as exc:
            raise InputError(exc.detail, file=file, field=exc.field) from None
        d_key = "d" + key
        if axis.size > 1 and d_key in grid:
            d = grid.scalar(d_key, positive=True)
            if abs(d - step) > 1e-6 * step:
                raise grid.error(f"is {d!r} m but the step of Grid.{key} is {step!r} m", d_key)
    z0 = 0.0
    if "z" in grid:
        z = grid.array("z")
        if z.size != 1:
            raise grid.error(f"expected a scalar (a plane), got shape {z.shape}", "z")
        z0 = float(z.reshape(()))
    dt = grid.scalar("dt", positive=True)
    if "voltage_mV" not in top:
        raise top.error("missing variable (expected the hydrophone voltage in mV)",
                        "voltage_mV")
    raw = np.asarray(top.values["voltage_mV"])
    if "Nt" in grid:
        nt = grid.integer("Nt", minimum=2)
    elif raw.size % max(1, x.size * y.size) == 0:
        nt = raw.size // max(1, x.size * y.size)
    else:
        raise top.error(f"expected shape (Nx, Ny, Nt) = ({x.size}, {y.size}, Nt), "
                        f"got {raw.shape}", "voltage_mV")
    volt_mv = top.array("voltage_mV", shape=(x.size, y.size, nt))
    data = volt_mv / _MV_PER_V

    if medium is None:
        medium = _medium(top.struct("medium"))
    pose = Pose(origin=(0.0, 0.0, z0))
    start_time = 0.0
    extra = _extra(top)
    if extra is not None:
        theta = extra.vector("pose_theta", length=3)
        origin = extra.vector("pose_origin", length=3)
        pose = _wrap(file, extra.prefix, Pose, theta_x=theta[0], theta_y=theta[1],
                     theta_z=theta[2], origin=tuple(origin))
        start_time = extra.scalar("start_time")
    plane = _wrap(file, "Grid", PlaneGrid, x=x, y=y, pose=pose)

    calibration = probe = drive = None
    if sensitivity is None and use_siblings:
        sensitivity = _sibling(directory, (REFERENCE_FILES["sensitivity"],))
    if sensitivity is not None:
        calibration = read_reference_calibration(sensitivity, polarity=hydrophone_polarity)
    if transmit is None and use_siblings:
        transmit = _sibling(directory, _TRANSMIT_ALIASES)
    if transmit is not None:
        ttop = MatStruct(load_mat(transmit), str(transmit))
        if "Trans" not in ttop and "Transmit" not in ttop:
            raise ttop.error("expected the structs Trans and/or Transmit", "Trans")
        if "Trans" in ttop:
            probe = probe_from_trans(ttop.struct("Trans"),
                                     verasonics_sound_speed=verasonics_sound_speed)
        if "Transmit" in ttop:
            drive = _drive(ttop.struct("Transmit"))
    scan = _wrap(file, "", HydrophoneScan,
                 data=data, grid=plane, sampling_rate=1.0 / dt, start_time=start_time,
                 quantity="voltage", medium=medium, calibration=calibration, probe=probe,
                 drive=drive, source=file)
    return check_measurement(scan, plausibility, file=file)


def read_reference_echo(
    path: str | os.PathLike,
    *,
    medium: Medium | None = None,
    use_siblings: bool = True,
    verasonics_sound_speed: float = VERASONICS_SOUND_SPEED,
    plausibility: PlausibilityConfig | None = None,
) -> EchoRecording:
    """Read the reflector echo stored in the published toolkit's layout.

    Parameters
    ----------
    path : str or PathLike
        A directory holding ``ReceiveData.mat`` or that file itself.
    medium : Medium, optional
        The medium; by default the ``holoprobe`` extras of the file, else the
        ``medium`` struct of ``ScanData.mat`` next to it (``use_siblings``), else
        :class:`Medium` defaults (water at 20 °C).
    use_siblings : bool
        Allow reading the medium from a neighbouring ``ScanData.mat``.
    verasonics_sound_speed : float
        See :func:`probe_from_trans`, in m/s.

    Returns
    -------
    EchoRecording
        ``rf`` = ``Receive.RF`` transposed to (n_elements, n_samples), in ADC
        levels (``unit="ADCL"``), start time 0 (the toolkit's time origin);
        probe from ``Trans`` and drive from ``Transmit`` when present.
    """
    rec_file, directory = _resolve(path, REFERENCE_FILES["receive"])
    file = str(rec_file)
    top = MatStruct(load_mat(rec_file), file)
    receive = top.struct("Receive")
    probe = (probe_from_trans(top.struct("Trans"), verasonics_sound_speed=verasonics_sound_speed)
             if "Trans" in top else None)
    drive = _drive(top.struct("Transmit")) if "Transmit" in top else None
    if "RF" not in receive:
        raise receive.error("missing field", "RF")
    raw = np.asarray(receive.values["RF"])
    if probe is not None:
        n_ch = probe.element_count
        if raw.size % n_ch or (raw.ndim == 2 and raw.shape[1] != n_ch):
            raise receive.error(f"expected shape (Nsamp, {n_ch}) (one column per element of "
                                f"Trans), got {raw.shape}", "RF")
        rf = receive.array("RF", shape=(raw.size // n_ch, n_ch))
    else:
        rf = receive.array("RF")
        if rf.ndim == 1:
            rf = rf.reshape(-1, 1)
        if rf.ndim != 2:
            raise receive.error(f"expected shape (Nsamp, Nch), got {rf.shape}", "RF")
    fs = receive.scalar("SamplingRate", positive=True)
    unit = "ADCL"
    start_time = 0.0
    extra = _extra(top)
    if extra is not None:
        unit = extra.string("unit", default=unit)
        start_time = extra.scalar("start_time")
        if medium is None and "density" in extra:
            medium = _wrap(file, extra.prefix, Medium,
                           density=extra.scalar("density", positive=True),
                           sound_speed=extra.scalar("sound_speed", positive=True))
    if medium is None and use_siblings:
        scan_file = _sibling(directory, (REFERENCE_FILES["scan"],))
        if scan_file is not None:
            stop = MatStruct(load_mat(scan_file, variable_names=["medium"]), str(scan_file))
            if "medium" in stop:
                medium = _medium(stop.struct("medium"))
    echo = _wrap(file, "Receive", EchoRecording,
                 rf=np.ascontiguousarray(rf.T), sampling_rate=fs, start_time=start_time,
                 unit=unit, drive=drive, probe=probe, medium=medium or Medium(), source=file)
    return check_measurement(echo, plausibility, file=file)


# --------------------------------------------------------------------------- writing


def _kspace(n: int, d: float) -> tuple[np.ndarray, float]:
    """The toolkit's ``get_kspace``: 2π(ceil(-N/2):ceil(N/2-1))/(N d), step 2π/(N d)."""
    idx = np.arange(int(np.ceil(-n / 2)), int(np.ceil(n / 2 - 1)) + 1, dtype=float)
    return 2 * np.pi * idx / (n * d), 2 * np.pi / (n * d)


def _check_targets(paths: list[Path], overwrite: bool, protect: tuple[str, ...]) -> None:
    for p in paths:
        for src in protect:
            if p.exists() and os.path.exists(src) and os.path.samefile(p, src):
                raise InputError("refusing to overwrite an input file", file=str(p))
        if p.exists() and not overwrite:
            raise InputError("already exists; pass overwrite=True to replace it", file=str(p))


def write_reference_scan(
    directory: str | os.PathLike,
    scan: HydrophoneScan,
    *,
    version: str = "5",
    overwrite: bool = False,
    verasonics_sound_speed: float = VERASONICS_SOUND_SPEED,
) -> list[Path]:
    """Write a scan in the published toolkit's layout (ScanData.mat and friends).

    Parameters
    ----------
    directory : str or PathLike
        Output directory (created if missing).
    scan : HydrophoneScan
        A voltage scan (``quantity="voltage"``) with at least 2 points along x and y.
    version : {"5", "7.3"}
        MAT-file version (7.3 needs the optional package hdf5storage).
    overwrite : bool
        Replace existing files (checked for all files before any is written).
    verasonics_sound_speed : float
        Sound speed in m/s for the wavelength units of ``Trans``.

    Returns
    -------
    list of pathlib.Path
        ``ScanData.mat``, then ``sensitivity.mat`` (if the scan has a calibration)
        and ``TransmitData.mat`` (if it has a probe or a drive).
    """
    require_instance(scan, HydrophoneScan, "scan")
    if scan.quantity != "voltage":
        raise InputError("the reference layout stores hydrophone voltage (voltage_mV); "
                         "write a pressure scan with holoprobe.io.write_scan", field="quantity")
    nx, ny = scan.grid.shape
    if nx < 2 or ny < 2:
        raise InputError(f"the reference layout needs at least 2 points along x and y, got "
                         f"{(nx, ny)}", field="grid")
    out = Path(directory)
    targets = [out / REFERENCE_FILES["scan"]]
    if scan.calibration is not None:
        targets.append(out / REFERENCE_FILES["sensitivity"])
    if scan.probe is not None or scan.drive is not None:
        targets.append(out / REFERENCE_FILES["transmit"])
    protect = (scan.source,) if scan.source else ()
    _check_targets(targets, overwrite, protect)

    dx, dy = scan.grid.dx, scan.grid.dy
    kx, dkx = _kspace(nx, dx)
    ky, dky = _kspace(ny, dy)
    kz, dkz = _kspace(1, dx)
    nt = scan.n_samples
    grid = {
        "x": _row(scan.grid.x), "y": _row(scan.grid.y), "z": 0.0,
        "Nx": float(nx), "Ny": float(ny), "Nz": 1.0,
        "dx": dx, "dy": dy, "dz": dx,
        "kx": _row(kx), "ky": _row(ky), "kz": _row(kz),
        "dkx": dkx, "dky": dky, "dkz": dkz,
        "Nt": float(nt), "dt": 1.0 / scan.sampling_rate,
        "full_size": np.array([[nx], [ny], [1]], dtype=float),
    }
    pose = scan.grid.pose
    variables = {
        "Grid": grid,
        "voltage_mV": np.asarray(scan.data) * _MV_PER_V,
        "medium": {"sound_speed": scan.medium.sound_speed, "density": scan.medium.density},
        _EXTRA: {
            "schema_version": 1.0,
            "start_time": scan.start_time,
            "pose_theta": _row([pose.theta_x, pose.theta_y, pose.theta_z]),
            "pose_origin": _row(pose.origin),
            "source": scan.source,
        },
    }
    written = [save_mat(targets[0], variables, version=version, overwrite=overwrite,
                        protect=protect)]
    if scan.calibration is not None:
        cal = scan.calibration
        extra: dict[str, Any] = {"polarity": float(cal.polarity), "name": cal.name}
        if cal.phase is not None:
            extra["phase"] = _row(cal.phase)
        written.append(save_mat(
            out / REFERENCE_FILES["sensitivity"],
            {"Frequency": _row(cal.frequency / _HZ_PER_MHZ),
             "Sensitivity": _row(cal.sensitivity * _MV_PER_MPA_PER_V_PER_PA),
             _EXTRA: extra},
            version=version, overwrite=overwrite, protect=protect))
    if scan.probe is not None or scan.drive is not None:
        tvars: dict[str, Any] = {}
        if scan.probe is not None:
            tvars["Trans"] = trans_from_probe(scan.probe,
                                              verasonics_sound_speed=verasonics_sound_speed)
        if scan.drive is not None:
            tvars["Transmit"] = {"SamplingRate": scan.drive.sampling_rate,
                                 "VoltageSignal": _row(scan.drive.voltage)}
        written.append(save_mat(out / REFERENCE_FILES["transmit"], tvars, version=version,
                                overwrite=overwrite, protect=protect))
    return written


def write_reference_echo(
    directory: str | os.PathLike,
    rec: EchoRecording,
    *,
    version: str = "5",
    overwrite: bool = False,
    verasonics_sound_speed: float = VERASONICS_SOUND_SPEED,
) -> Path:
    """Write an echo recording as the toolkit's ``ReceiveData.mat``.

    Parameters
    ----------
    directory : str or PathLike
        Output directory (created if missing).
    rec : EchoRecording
        The recording; ``Receive.RF`` is ``rec.rf`` transposed to [Nsamp, Nch].
    version, overwrite, verasonics_sound_speed
        As for :func:`write_reference_scan`.

    Returns
    -------
    pathlib.Path
        The written ``ReceiveData.mat``.
    """
    require_instance(rec, EchoRecording, "rec")
    target = Path(directory) / REFERENCE_FILES["receive"]
    protect = (rec.source,) if rec.source else ()
    _check_targets([target], overwrite, protect)
    variables: dict[str, Any] = {
        "Receive": {"RF": np.ascontiguousarray(np.asarray(rec.rf).T),
                    "SamplingRate": rec.sampling_rate},
        _EXTRA: {"schema_version": 1.0, "start_time": rec.start_time, "unit": rec.unit,
                 "density": rec.medium.density, "sound_speed": rec.medium.sound_speed,
                 "source": rec.source},
    }
    if rec.probe is not None:
        variables["Trans"] = trans_from_probe(rec.probe,
                                              verasonics_sound_speed=verasonics_sound_speed)
    if rec.drive is not None:
        variables["Transmit"] = {"SamplingRate": rec.drive.sampling_rate,
                                 "VoltageSignal": _row(rec.drive.voltage)}
    return save_mat(target, variables, version=version, overwrite=overwrite, protect=protect)
