"""Validation of a virtual transducer against a measured pressure field (paper III C).

The measured field is compared with the field the virtual transducer predicts for the
same transmit setting at the same points and times. The best scale factor is the
least-squares amplitude ``s = Σ x y / Σ y²`` (x measured, y predicted, over all points
and samples); the normalised error is ``‖x − s y‖ / ‖x‖``.

Measured-field file (HDF5, ``format = "holoprobe-measured-field"``, schema 1)
---------------------------------------------------------------------------
Root attributes:

* ``format``: ``"holoprobe-measured-field"``; ``schema_version``: 1;
* ``sampling_rate``: Hz; ``start_time``: time of sample 0 in s, on the clock of the
  transmit setting (t = 0: the earliest element fires).

Datasets, either

* ``points`` (n, 3) in m (transducer coordinates: x lateral, y elevation, z depth)
  and ``pressure`` (n, nt) in Pa; or
* group ``grid`` with datasets ``x`` (nx,) and ``y`` (ny,) in m and attributes
  ``theta_x``, ``theta_y``, ``theta_z`` (rad) and ``origin`` (3,) in m (a
  :class:`holoprobe.geometry.PlaneGrid` with its :class:`~holoprobe.geometry.Pose`),
  and ``pressure`` (nx, ny, nt) in Pa.

Optional: attribute ``description`` (free text). See ``docs/validation.md``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import PlaneGrid, Pose

__all__ = [
    "MEASURED_FIELD_FORMAT",
    "MeasuredField",
    "ValidationResult",
    "least_squares_scale",
    "plot_validation",
    "read_measured_field",
    "validate_field",
    "write_measured_field",
]

MEASURED_FIELD_FORMAT = "holoprobe-measured-field"
_SCHEMA_VERSION = 1


@dataclass(frozen=True, eq=False)
class MeasuredField:
    """A measured pressure field: waveforms at points.

    Attributes
    ----------
    points : ndarray, shape (n, 3)
        Positions in m (transducer coordinates; C order of ``grid`` when there is one).
    pressure : ndarray, shape (n, nt)
        Pressure in Pa.
    sampling_rate : float
        Hz.
    start_time : float
        Time of sample 0 in s (transmit clock).
    grid : PlaneGrid or None
        The plane grid the points come from, if any.
    description : str
        Free text.
    """

    points: NDArray[np.float64]
    pressure: NDArray[np.float64]
    sampling_rate: float
    start_time: float = 0.0
    grid: PlaneGrid | None = None
    description: str = ""

    def __post_init__(self) -> None:
        pts = np.asarray(self.points, dtype=float)
        p = np.asarray(self.pressure, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < 1:
            raise InputError(f"expected points of shape (n, 3) in m, got {pts.shape}",
                             field="points")
        if p.shape[:1] != pts.shape[:1] or p.ndim != 2 or p.shape[1] < 2:
            raise InputError(f"expected pressure of shape ({pts.shape[0]}, nt ≥ 2), got "
                             f"{p.shape}", field="pressure")
        if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(p))):
            raise InputError("contains NaN or inf", field="pressure")
        fs = float(self.sampling_rate)
        if not (math.isfinite(fs) and fs > 0):
            raise InputError(f"expected a positive sampling rate in Hz, got {fs!r}",
                             field="sampling_rate")
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "pressure", p)
        object.__setattr__(self, "sampling_rate", fs)
        object.__setattr__(self, "start_time", float(self.start_time))

    @property
    def time(self) -> NDArray[np.float64]:
        """Sample times in s, shape (nt,)."""
        return self.start_time + np.arange(self.pressure.shape[1]) / self.sampling_rate


def write_measured_field(path: str | os.PathLike, field: MeasuredField, *,
                         overwrite: bool = False) -> Path:
    """Write a :class:`MeasuredField` in the measured-field HDF5 format (atomically)."""
    import h5py

    from holoprobe.io import atomic_write

    target = Path(path)
    with atomic_write(target, overwrite=overwrite) as tmp, h5py.File(tmp, "w") as f:
        f.attrs["format"] = MEASURED_FIELD_FORMAT
        f.attrs["schema_version"] = _SCHEMA_VERSION
        f.attrs["sampling_rate"] = field.sampling_rate
        f.attrs["start_time"] = field.start_time
        f.attrs["description"] = field.description
        if field.grid is not None:
            g = f.create_group("grid")
            g.create_dataset("x", data=field.grid.x)
            g.create_dataset("y", data=field.grid.y)
            pose = field.grid.pose
            for name in ("theta_x", "theta_y", "theta_z"):
                g.attrs[name] = getattr(pose, name)
            g.attrs["origin"] = np.asarray(pose.origin)
            f.create_dataset("pressure", data=field.pressure.reshape(
                field.grid.x.size, field.grid.y.size, -1))
        else:
            f.create_dataset("points", data=field.points)
            f.create_dataset("pressure", data=field.pressure)
    return target


def read_measured_field(path: str | os.PathLike) -> MeasuredField:
    """Read a measured-field HDF5 file (format in the module docstring).

    Raises
    ------
    InputError
        Missing file, wrong format, missing or malformed dataset (named in the message).
    """
    import h5py

    p = Path(path)
    file = str(p)
    if not p.is_file():
        raise InputError("no such measured-field file", file=file)
    try:
        f = h5py.File(p, "r")
    except OSError as exc:
        raise InputError(f"not an HDF5 file ({exc})", file=file) from None
    with f:
        fmt = f.attrs.get("format")
        if isinstance(fmt, bytes):
            fmt = fmt.decode()
        if fmt != MEASURED_FIELD_FORMAT:
            raise InputError(f"expected attribute format = {MEASURED_FIELD_FORMAT!r}, got "
                             f"{fmt!r}", file=file, field="format")
        version = int(f.attrs.get("schema_version", 0))
        if version > _SCHEMA_VERSION:
            raise InputError(f"schema version {version} is newer than this holoprobe reads "
                             f"({_SCHEMA_VERSION})", file=file, field="schema_version")
        for name in ("sampling_rate", "start_time"):
            if name not in f.attrs:
                raise InputError("missing root attribute", file=file, field=name)
        if "pressure" not in f:
            raise InputError("missing dataset (Pa)", file=file, field="pressure")
        pressure = np.asarray(f["pressure"][()], dtype=float)
        grid = None
        if "grid" in f:
            g = f["grid"]
            try:
                pose = Pose(float(g.attrs.get("theta_x", 0.0)), float(g.attrs.get("theta_y", 0.0)),
                            float(g.attrs.get("theta_z", 0.0)),
                            tuple(np.asarray(g.attrs.get("origin", (0.0, 0.0, 0.0)), float)))
                grid = PlaneGrid(np.asarray(g["x"][()], float), np.asarray(g["y"][()], float),
                                 pose)
            except (KeyError, InputError) as exc:
                raise InputError(f"malformed grid ({exc})", file=file, field="grid") from None
            if pressure.ndim != 3 or pressure.shape[:2] != (grid.x.size, grid.y.size):
                raise InputError(f"expected shape ({grid.x.size}, {grid.y.size}, nt), got "
                                 f"{pressure.shape}", file=file, field="pressure")
            points = grid.points()
            pressure = pressure.reshape(points.shape[0], -1)
        elif "points" in f:
            points = np.asarray(f["points"][()], dtype=float)
        else:
            raise InputError("expected a dataset 'points' (n, 3) or a group 'grid'", file=file,
                             field="points")
        desc = f.attrs.get("description", "")
        try:
            return MeasuredField(points, pressure, float(f.attrs["sampling_rate"]),
                                 float(f.attrs["start_time"]), grid,
                                 desc.decode() if isinstance(desc, bytes) else str(desc))
        except InputError as exc:
            raise InputError(exc.detail, file=file, field=exc.field) from None


def least_squares_scale(measured: ArrayLike, predicted: ArrayLike) -> tuple[float, float]:
    """Best amplitude factor s = Σxy/Σy² and the normalised error ‖x − s y‖/‖x‖.

    Parameters
    ----------
    measured, predicted : array_like, same shape
        x and y (any units, the same for both).

    Returns
    -------
    scale : float
        The least-squares factor that multiplies the prediction.
    error : float
        Normalised residual (0: perfect agreement up to the scale).
    """
    x = np.asarray(measured, dtype=float)
    y = np.asarray(predicted, dtype=float)
    if x.shape != y.shape:
        raise InputError(f"expected equal shapes, got {x.shape} and {y.shape}",
                         field="predicted")
    yy = float(np.sum(y * y))
    xx = float(np.sum(x * x))
    if not (yy > 0 and xx > 0):
        raise InputError("the measured or predicted field is zero", field="measured")
    s = float(np.sum(x * y)) / yy
    return s, float(np.linalg.norm(x - s * y) / math.sqrt(xx))


@dataclass(frozen=True, eq=False)
class ValidationResult:
    """Result of :func:`validate_field`.

    Attributes
    ----------
    scale : float
        Least-squares factor s (measured ≈ s × predicted).
    normalised_error : float
        ``‖x − s y‖ / ‖x‖`` over all points and samples.
    peak_error : float
        Largest ``|x − s y|`` over points and samples, relative to ``max |x|``.
    measured : MeasuredField
        The measurement.
    predicted : ndarray, shape (n, nt)
        The unscaled prediction on the measured samples in Pa.
    profile_axis : str
        ``"z"`` (points on the beam axis), ``"x"`` or ``"y"`` (a line through the
        measured maximum): the coordinate of :attr:`profile_index`.
    profile_index : ndarray of int
        Indices of the points of the profile, sorted along ``profile_axis``.
    """

    scale: float
    normalised_error: float
    peak_error: float
    measured: MeasuredField
    predicted: NDArray[np.float64]
    profile_axis: str
    profile_index: NDArray[np.int64]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (no arrays)."""
        return {"scale": self.scale, "normalised_error": self.normalised_error,
                "peak_error": self.peak_error, "n_points": int(self.measured.points.shape[0]),
                "n_samples": int(self.measured.pressure.shape[1]),
                "profile_axis": self.profile_axis}


def _profile(points: NDArray, pressure: NDArray, tol: float) -> tuple[str, NDArray]:
    on_axis = np.flatnonzero((np.abs(points[:, 0]) <= tol) & (np.abs(points[:, 1]) <= tol))
    if np.unique(points[on_axis, 2]).size >= 2:
        return "z", on_axis[np.argsort(points[on_axis, 2])]
    i = int(np.argmax(np.max(np.abs(pressure), axis=1)))
    best = ("x", np.array([i]))
    for axis, others in (("x", (1, 2)), ("y", (0, 2))):
        sel = np.flatnonzero(np.all(np.abs(points[:, others] - points[i, others]) <= tol,
                                    axis=1))
        if sel.size > best[1].size:
            col = 0 if axis == "x" else 1
            best = (axis, sel[np.argsort(points[sel, col])])
    return best


def validate_field(vt: Any, setting: Any, measured: MeasuredField | str | os.PathLike, *,
                   line_tolerance: float = 1e-6, **predict_options: Any) -> ValidationResult:
    """Compare the predicted field with a measured one (paper section III C).

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    setting : TransmitSetting
        The transmit setting of the measurement.
    measured : MeasuredField or path
        The measurement (or its HDF5 file, format in the module docstring).
    line_tolerance : float
        Points within this distance (m) of the z axis form the on-axis profile; when
        there are none, the line through the measured maximum along x (or y).
    **predict_options
        Passed to :func:`holoprobe.transducer.predict_field` (e.g. ``method``,
        ``band_threshold_db``); sampling rate and start time are the measurement's.

    Returns
    -------
    ValidationResult
        The scale factor s = Σxy/Σy², the normalised error and the profiles.

    Notes
    -----
    The prediction is computed on the measurement's time axis (same rate and start
    time; a record long enough to hold every arrival, then cut to the measured
    length), so no time alignment is fitted: a residual delay shows as error.
    """
    from holoprobe.transducer import predict_field

    field = measured if isinstance(measured, MeasuredField) else read_measured_field(measured)
    nt = field.pressure.shape[1]
    pred = predict_field(vt, setting, field.points, sampling_rate=field.sampling_rate,
                         start_time=field.start_time, **predict_options)
    y = np.zeros_like(field.pressure)
    m = min(nt, pred.pressure.shape[1])
    y[:, :m] = pred.pressure[:, :m]
    s, err = least_squares_scale(field.pressure, y)
    peak = float(np.max(np.abs(field.pressure - s * y)) / np.max(np.abs(field.pressure)))
    axis, idx = _profile(field.points, field.pressure, float(line_tolerance))
    return ValidationResult(s, err, peak, field, y, axis, idx)


def plot_validation(result: ValidationResult, path: str | os.PathLike, *,
                    overwrite: bool = False) -> Path:
    """Plot the peak-pressure profiles (measured, scaled prediction) to an image file.

    Parameters
    ----------
    result : ValidationResult
        From :func:`validate_field`.
    path : str or PathLike
        Output image (``.png``, ``.svg``, ``.pdf``), written atomically.
    overwrite : bool
        Replace an existing file.

    Returns
    -------
    pathlib.Path
        The written file.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from holoprobe.io import atomic_write

    idx = result.profile_index
    col = {"x": 0, "y": 1, "z": 2}[result.profile_axis]
    pos = result.measured.points[idx, col] * 1e3
    meas = np.max(np.abs(result.measured.pressure[idx]), axis=1) * 1e-3
    pred = np.max(np.abs(result.scale * result.predicted[idx]), axis=1) * 1e-3
    fig, ax = plt.subplots(figsize=(6.0, 3.6), constrained_layout=True)
    ax.plot(pos, meas, "o", ms=3, label="measured")
    ax.plot(pos, pred, "-", label=f"virtual transducer × {result.scale:.3f}")
    label = {"z": "depth z (mm) on axis", "x": "lateral x (mm)", "y": "elevation y (mm)"}
    ax.set_xlabel(label[result.profile_axis])
    ax.set_ylabel("peak |p| (kPa)")
    ax.set_title(f"normalised error {100 * result.normalised_error:.1f} %")
    ax.legend()
    target = Path(path)
    with atomic_write(target, overwrite=overwrite) as tmp:
        fig.savefig(tmp, format=target.suffix.lstrip(".") or "png", dpi=120)
    plt.close(fig)
    return target
