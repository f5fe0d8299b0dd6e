"""The holography community's MATLAB hologram layout (CW ``HologramSf``, transient ``HologramTr``).

A .mat file (v5 or v7.3) with the structs ``Medium`` {soundSpeed, density},
``HologramSf`` {xGrid, yGrid, zPosition, dx, dy, frequency, expSign,
complexPressureAmplitude} or ``HologramTr`` {xGrid, yGrid, zPosition, dx, dy, time,
pressureWaveforms}, and ``Geometry`` {apertureMin, apertureMax, radiusOfCurvature
(absent or empty: flat)}. See ``docs/formats.md``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError, require_instance
from holoprobe.geometry import Medium, PlaneGrid, Pose, SourceGeometry
from holoprobe.io._hologram_grid import GridLayout, resolve_grid
from holoprobe.io._matfile import MatStruct, load_mat, save_mat
from holoprobe.measurement import Hologram

__all__ = ["HOLOGRAM_STRUCTS", "read_hologram_mat", "write_hologram_mat"]

HOLOGRAM_STRUCTS = ("HologramSf", "HologramTr")
"""Variable names that mark a hologram file (CW, transient)."""

_GRID_LAYOUTS = ("meshgrid", "vectors", "nodes", "flattened", "flattened-y")
# flattened points on a non-square grid: the wrong reading shears rows into columns; the
# right one is at least this much smoother (neighbour differences over the variance)
_CLEARLY_SMOOTHER = 0.5


def _rename(exc: InputError, file: str, prefix: str, data_name: str) -> InputError:
    """A noun's InputError with the MATLAB field it came from."""
    names = {"sound_speed": "Medium.soundSpeed", "density": "Medium.density",
             "pressure": f"{prefix}.{data_name}", "frequency": f"{prefix}.frequency",
             "z_position": f"{prefix}.zPosition", "sampling_rate": f"{prefix}.time",
             "start_time": f"{prefix}.time"}
    return InputError(exc.detail, file=file, field=names.get(exc.field or "", exc.field))


def _medium(top: MatStruct) -> Medium:
    if "Medium" not in top:
        raise top.error("missing struct (expected Medium.soundSpeed in m/s and Medium.density "
                        "in kg/m^3)", "Medium")
    m = top.struct("Medium")
    try:
        return Medium(density=m.scalar("density", positive=True),
                      sound_speed=m.scalar("soundSpeed", positive=True))
    except InputError as exc:
        raise _rename(exc, top.file, "", "") from None


def _geometry(top: MatStruct) -> SourceGeometry | None:
    if "Geometry" not in top:
        return None
    g = top.struct("Geometry")
    lo = g.scalar("apertureMin", positive=True)
    hi = g.scalar("apertureMax", positive=True)
    roc = None
    if "radiusOfCurvature" in g and np.asarray(g.values["radiusOfCurvature"]).size:
        roc = g.scalar("radiusOfCurvature", positive=True, allow_inf=True)
        roc = None if np.isinf(roc) else roc
    opening = g.scalar("openingDiameter") if "openingDiameter" in g else 0.0
    kind = "spherical-cap" if roc is not None else (
        "flat-disc" if abs(hi - lo) <= 1e-9 * hi else "flat-rectangle")
    try:
        return SourceGeometry(kind, min(lo, hi), max(lo, hi), roc, opening)
    except InputError as exc:
        names = {"aperture_min": "apertureMin", "aperture_max": "apertureMax",
                 "radius_of_curvature": "radiusOfCurvature",
                 "opening_diameter": "openingDiameter"}
        raise g.error(exc.detail, names.get(exc.field or "", exc.field or "")) from None


def _complex_data(s: MatStruct, key: str) -> NDArray:
    if key not in s:
        raise s.error("missing field", key)
    arr = np.asarray(s.values[key])
    if arr.size == 0:
        raise s.error(f"is empty (shape {arr.shape}): the file holds no pressure data", key)
    if arr.dtype.kind not in "iufc":
        raise s.error(f"expected numbers, got {type(s.values[key]).__name__} "
                      f"(dtype {arr.dtype})", key)
    bad = ~np.isfinite(arr)
    if np.any(bad):
        idx = tuple(int(i) for i in np.argwhere(np.atleast_1d(bad))[0])
        raise s.error(f"contains NaN or inf (first at index {idx}, {int(bad.sum())} in all)",
                      key)
    return arr


def _exp_sign(s: MatStruct) -> int:
    value = s.scalar("expSign")
    if value not in (1.0, -1.0):
        raise s.error(f"expected +1 (exp(+iωt), MATLAB's fft) or -1 (exp(-iωt)), got {value!r}",
                      "expSign")
    return int(value)


def _check_steps(s: MatStruct, x: NDArray, y: NDArray) -> None:
    for key, axis in (("dx", x), ("dy", y)):
        if key in s:
            d = s.scalar(key, positive=True)
            step = axis[1] - axis[0]
            if abs(d - step) > 0.01 * step:
                raise s.error(f"is {d * 1e3:.6g} mm but the grid steps by {step * 1e3:.6g} mm",
                              key)


def read_hologram_mat(path: str | os.PathLike, *, kind: str | None = None,
                      grid_tolerance: float = 0.01, flattened_order: str = "auto"
                      ) -> Hologram:
    """Read a hologram in the holography community's MATLAB layout (v5 or v7.3).

    Parameters
    ----------
    path : str or PathLike
        The .mat file.
    kind : {None, "cw", "transient"}
        Which struct to read when the file holds both ``HologramSf`` and
        ``HologramTr`` (default: the one present; ``HologramSf`` when both are).
    grid_tolerance : float
        Largest deviation of a grid position from a uniform grid, in steps.
    flattened_order : {"auto", "x", "y"}
        Data of shape [n, nt] (or [n]) on ``xGrid``/``yGrid`` axis vectors, n = nx·ny:
        the index that runs fastest in the flattened points. "x": MATLAB's
        ``reshape(p, [], nt)`` of an [nx, ny, nt] array; "y": of a meshgrid-shaped
        [ny, nx, nt] one. "auto": on a non-square grid the reading whose image is
        smoother (the other is a sheared scramble; "x" with a note when neither is
        clearly smoother); on a square grid "x" with a note in ``Hologram.notes`` (the two
        readings are each other's transpose: the file cannot tell them apart).

    Returns
    -------
    Hologram
        x and y increasing (a decreasing axis reorders the data), ``grid.pose`` at
        (0, 0, zPosition); a CW amplitude is converted to holoprobe's convention
        ``p(t) = Re{P e^{−iωt}}`` (conjugated when ``expSign = +1``).

    Raises
    ------
    InputError
        One line naming the file and the MATLAB field: missing ``Medium``, empty or
        NaN data, grids that disagree with the data, ``expSign`` other than ±1, a
        non-uniform grid, a hologram behind the source, implausible values.
    """
    file = str(path)
    top = MatStruct(load_mat(path, mat_dtype=False), file)   # keeps complex data complex
    present = [k for k in HOLOGRAM_STRUCTS if k in top]
    if not present:
        raise top.error("missing struct: expected HologramSf (CW) or HologramTr (transient)",
                        "HologramSf")
    if kind not in (None, "cw", "transient"):
        raise InputError(f"expected None, 'cw' or 'transient', got {kind!r}", field="kind")
    prefix = present[0] if kind is None else ("HologramSf" if kind == "cw" else "HologramTr")
    if prefix not in top:
        raise top.error("missing struct", prefix)
    medium = _medium(top)
    geometry = _geometry(top)
    s = top.struct(prefix)
    cw = prefix == "HologramSf"
    data_name = "complexPressureAmplitude" if cw else "pressureWaveforms"
    data = _complex_data(s, data_name)
    extra: dict[str, Any] = {}
    if cw:
        sign = _exp_sign(s)
        data = np.conj(data) if sign == 1 else data
        extra["frequency"] = s.scalar("frequency", positive=True)
    else:
        if np.iscomplexobj(data):
            raise s.error("expected real waveforms in Pa, got complex numbers", data_name)
        extra.update(_time_axis(s, data.shape[-1]))
    layout, notes = _layout(s, data, 0 if cw else 1, file, f"{prefix}.{data_name}",
                            grid_tolerance, flattened_order)
    _check_steps(s, layout.x, layout.y)
    z = s.scalar("zPosition")
    try:
        grid = PlaneGrid(layout.x, layout.y, Pose(origin=(0.0, 0.0, z)))
        return Hologram(layout.apply(data), grid, medium, geometry=geometry, source=file,
                        notes=notes, **extra)
    except InputError as exc:
        raise _rename(exc, file, prefix, data_name) from None


def _layout(s: MatStruct, data: NDArray, trailing: int, file: str, dname: str,
            tolerance: float, flattened_order: str) -> tuple[GridLayout, tuple[str, ...]]:
    """The grid layout of ``data`` and the notes on what the file could not settle: which
    index runs fastest in points flattened on axis vectors (see
    :func:`read_hologram_mat`)."""
    if flattened_order not in ("auto", "x", "y"):
        raise InputError(f"expected 'auto', 'x' or 'y', got {flattened_order!r}",
                         field="flattened_order")
    prefix = dname.split(".")[0]

    def resolve(order: str) -> GridLayout:
        return resolve_grid(s.array("xGrid"), s.array("yGrid"), data.shape, trailing,
                            file=file, xname=f"{prefix}.xGrid", yname=f"{prefix}.yGrid",
                            dname=dname, tolerance=tolerance,
                            flattened_order="x" if order == "auto" else order)

    layout = resolve(flattened_order)
    if layout.flattened is None or flattened_order != "auto":
        return layout, ()
    nx, ny = layout.x.size, layout.y.size
    what = (f"{dname}: its {nx * ny} points on {nx} x and {ny} y axis positions were read "
            "flattened x fastest (MATLAB's reshape(p, [], nt) of an [nx, ny, nt] array)")
    if nx != ny:
        other = resolve("y")
        rough_x, rough_y = _roughness(layout.apply(data)), _roughness(other.apply(data))
        if rough_y < _CLEARLY_SMOOTHER * rough_x:
            return other, ()
        if rough_x < _CLEARLY_SMOOTHER * rough_y:
            return layout, ()
        return layout, (f"{what}: neither that nor y fastest gives a clearly smoother "
                        "image; set hologram.flattened_order (--flattened-order) if it "
                        "was y fastest",)
    return layout, (f"{what}; on a square grid the file cannot tell that from y fastest "
                    "(a meshgrid-shaped [ny, nx, nt] array), which would transpose the "
                    "hologram: set hologram.flattened_order = 'y' (--flattened-order y) if "
                    "so",)


def _roughness(image: NDArray) -> float:
    """Mean squared difference of neighbouring points over twice the variance (≈ 1 for
    unrelated neighbours, small for a sampled wave field); a transient image by its 16
    strongest time samples."""
    a = np.asarray(image)
    if a.ndim == 3:
        strongest = np.argsort(np.sum(np.abs(a) ** 2, axis=(0, 1)))[-16:]
        a = a[:, :, strongest]
    a = a.reshape(a.shape[0], a.shape[1], -1)
    spread = 2 * float(np.mean(np.abs(a - a.mean(axis=(0, 1))) ** 2))
    steps = (float(np.mean(np.abs(np.diff(a, axis=0)) ** 2))
             + float(np.mean(np.abs(np.diff(a, axis=1)) ** 2)))
    return steps / spread if spread > 0 else 0.0


def _time_axis(s: MatStruct, nt: int) -> dict[str, float]:
    t = s.vector("time")
    if t.size != nt:
        raise s.error(f"has {t.size} samples but pressureWaveforms has {nt} along its last "
                      "dimension", "time")
    if nt < 2:
        raise s.error("expected at least 2 time samples", "time")
    i = np.arange(nt)
    dt, t0 = np.polyfit(i, t, 1)          # float32 time vectors carry rounding of ~1e-7 t
    if not dt > 0 or np.max(np.abs(t - (t0 + dt * i))) > 0.01 * dt:
        raise s.error("time samples must increase uniformly (deviations above 1 % of a "
                      "sample)", "time")
    return {"sampling_rate": 1.0 / dt, "start_time": float(t0)}


def _grid_arrays(h: Hologram, layout: str, descending: tuple[bool, bool]
                 ) -> tuple[NDArray, NDArray, NDArray]:
    """xGrid, yGrid and data in the requested MATLAB arrangement."""
    x, y = np.asarray(h.grid.x), np.asarray(h.grid.y)
    data = np.asarray(h.pressure)
    if descending[0]:
        x, data = x[::-1], data[::-1]
    if descending[1]:
        y, data = y[::-1], data[:, ::-1]
    if layout == "vectors":
        return x.reshape(1, -1), y.reshape(1, -1), data
    if layout == "flattened":                        # [n, nt] on axis vectors, x fastest
        return (x.reshape(1, -1), y.reshape(1, -1),
                np.ascontiguousarray(data.reshape((-1, *data.shape[2:]), order="F")))
    if layout == "flattened-y":                      # the same, y fastest
        return (x.reshape(1, -1), y.reshape(1, -1),
                np.ascontiguousarray(data.reshape((-1, *data.shape[2:]))))
    xx, yy = np.meshgrid(x, y)                       # MATLAB meshgrid: (ny, nx)
    data = np.swapaxes(data, 0, 1)                   # (ny, nx, ...)
    if layout == "meshgrid":
        return xx, yy, np.ascontiguousarray(data)
    n = xx.size                                      # nodes, column-major like x(:)
    return (xx.reshape(-1, order="F").reshape(-1, 1), yy.reshape(-1, order="F").reshape(-1, 1),
            np.ascontiguousarray(data.reshape((n, *data.shape[2:]), order="F")))


def write_hologram_mat(path: str | os.PathLike, hologram: Hologram, *, version: str = "5",
                       exp_sign: int = 1, grid_layout: str = "meshgrid",
                       descending: tuple[bool, bool] = (False, False),
                       overwrite: bool = False) -> Path:
    """Write a hologram in the holography community's MATLAB layout, atomically.

    Parameters
    ----------
    path : str or PathLike
        Output .mat file.
    hologram : Hologram
        CW (→ ``HologramSf``) or transient (→ ``HologramTr``).
    version : {"5", "7.3"}
        MAT-file version (v5: scipy.io.savemat; v7.3: hdf5storage).
    exp_sign : {1, -1}
        ``expSign`` of the written CW amplitude (+1: MATLAB's fft convention, the
        conjugate of holoprobe's).
    grid_layout : {"meshgrid", "vectors", "nodes", "flattened", "flattened-y"}
        ``meshgrid``: ``[X, Y] = meshgrid(x, y)`` matrices, data (ny, nx[, nt]);
        ``vectors``: axis row vectors, data (nx, ny[, nt]); ``nodes``: one x, y per
        point (column vectors), data (n[, nt]); ``flattened``: axis row vectors, data
        (nx·ny[, nt]) with x fastest (MATLAB's ``reshape(p, [], nt)``);
        ``flattened-y``: the same with y fastest (``reshape`` of a meshgrid-shaped
        [ny, nx, nt] array; read it with ``flattened_order="y"``).
    descending : (bool, bool)
        Store the x / y axis in decreasing order (as some scanners do).
    overwrite : bool
        Replace an existing file (never the file the hologram was read from).

    Returns
    -------
    pathlib.Path
        The written file.
    """
    require_instance(hologram, Hologram, "hologram")
    if exp_sign not in (1, -1):
        raise InputError(f"expected +1 or -1, got {exp_sign!r}", field="exp_sign")
    if grid_layout not in _GRID_LAYOUTS:
        raise InputError(f"expected one of {_GRID_LAYOUTS}, got {grid_layout!r}",
                         field="grid_layout")
    xg, yg, data = _grid_arrays(hologram, grid_layout, (bool(descending[0]),
                                                        bool(descending[1])))
    h: dict[str, Any] = {"xGrid": xg, "yGrid": yg, "zPosition": hologram.z_position,
                         "dx": hologram.grid.dx, "dy": hologram.grid.dy}
    if hologram.is_transient:
        h["time"] = hologram.time.reshape(1, -1)
        h["pressureWaveforms"] = data
        name = "HologramTr"
    else:
        # (type: ignore below) a CW Hologram has a frequency
        h["frequency"] = float(hologram.frequency)  # type: ignore[arg-type]
        h["expSign"] = float(exp_sign)
        h["complexPressureAmplitude"] = np.conj(data) if exp_sign == 1 else data
        name = "HologramSf"
    variables: dict[str, Any] = {
        "Medium": {"soundSpeed": hologram.medium.sound_speed,
                   "density": hologram.medium.density},
        name: h}
    g = hologram.geometry
    if g is not None:
        geo: dict[str, Any] = {"apertureMin": g.aperture_min, "apertureMax": g.aperture_max}
        if g.radius_of_curvature is not None:
            geo["radiusOfCurvature"] = g.radius_of_curvature
        if g.opening_diameter > 0:
            geo["openingDiameter"] = g.opening_diameter
        variables["Geometry"] = geo
    protect = (hologram.source,) if hologram.source and os.path.exists(hologram.source) else ()
    return save_mat(path, variables, version=version, overwrite=overwrite, protect=protect)
