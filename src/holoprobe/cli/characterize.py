"""``holoprobe characterize``: transmit (and, with ``--receive``, receive) characterization."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from holoprobe.cli._app import OutputDirectory

__all__ = ["characterize"]


def _drop_stale_report(out: Path, report: bool) -> None:
    """With ``--no-report --overwrite``, remove the report.html of an earlier run from OUT:
    it would describe other results (and ``holoprobe analyse`` would add to it)."""
    if not report and (out / "report.html").is_file():
        (out / "report.html").unlink()


def _characterize_hologram(path: Path, out: Path, *, config: Path | None,
                           set_: list[str] | None, overwrite: bool, quiet: bool,
                           source: str | None, radius_of_curvature: float | None,
                           aperture: list[float] | None, report: bool = True) -> None:
    """The hologram branch of ``holoprobe characterize``."""
    from holoprobe.errors import InputError
    from holoprobe.workflow import HOLOGRAM_OUTPUT_FILES, characterize_hologram_file

    if aperture is not None and len(aperture) not in (1, 2):
        raise InputError(f"expected one diameter or width and height in m, got {aperture}",
                         field="--aperture")
    if not overwrite:  # fail before the computation, not after it
        for name in HOLOGRAM_OUTPUT_FILES:
            if (out / name).exists():
                raise InputError("exists (pass --overwrite to replace it)",
                                 file=str(out / name))
    ap: float | tuple[float, float] | None = None
    if aperture is not None:
        ap = aperture[0] if len(aperture) == 1 else (aperture[0], aperture[1])
    run = characterize_hologram_file(path, config=config, overrides=set_ or (), source=source,
                                     radius_of_curvature=radius_of_curvature, aperture=ap,
                                     progress=not quiet)
    _drop_stale_report(out, report)
    run.save(out, overwrite=overwrite, report=report)
    if quiet:
        return
    from rich.console import Console

    result = run.result
    s = run.summary
    console = Console(stderr=False)
    al, src, pw = s["alignment"], s["source"], s["acoustic_power"]
    console.print(f"holoprobe characterize (hologram) → {out}")
    console.print(f"axis {np.round(al['axis_direction'], 6).tolist()}  tilt "
                  f"{al['tilt_deg']:.4f}°")
    if al["focus_position"] is not None:
        console.print(f"focus {np.round(np.array(al['focus_position']) * 1e3, 4).tolist()} mm")
    roc = src["radius_of_curvature"]
    console.print(f"source {src['kind']}: aperture {src['aperture_diameter'] * 1e3:.4f} mm"
                  + ("" if roc is None else f", R {roc * 1e3:.4f} mm"))
    console.print(f"power: hologram {pw['hologram']:.5g} W, surface {pw['surface']:.5g} W, "
                  f"inside the aperture {pw['inside_aperture_fraction']:.4f}")
    console.print(f"total {result.timings['total']:.2f} s")
    for w in s["warnings"]:
        console.print(f"[yellow]warning:[/yellow] {w}")


def _convex_dispatch(scan: Path, out: Path, *, array: str | None, drive, sensitivity, config,
                     set_, overwrite: bool, quiet: bool, radius_of_curvature: float | None,
                     receive, reflection_coefficient: float | None = None,
                     report: bool = True) -> bool:
    """Run the convex-array characterization when ``--array convex`` or the scan's probe
    description says so; False for a flat array."""
    from holoprobe.errors import InputError
    from holoprobe.io import probe_array_kind

    if array not in (None, "linear", "convex", "matrix", "sparse", "row-column"):
        raise InputError(f"expected linear, convex, matrix, sparse or row-column, got "
                         f"{array!r}", field="--array")
    kind = array if array is not None else probe_array_kind(scan)
    if kind != "convex":
        return False
    from holoprobe.workflow import CONVEX_OUTPUT_FILES, characterize_convex

    if not overwrite:
        for name in CONVEX_OUTPUT_FILES:
            if (out / name).exists():
                raise InputError("exists (pass --overwrite to replace it)",
                                 file=str(out / name))
    run = characterize_convex(scan, radius_of_curvature=radius_of_curvature, drive=drive,
                              calibration=sensitivity, config=config, overrides=set_ or (),
                              progress=not quiet, echo=receive,
                              reflection_coefficient=reflection_coefficient)
    _drop_stale_report(out, report)
    run.save(out, overwrite=overwrite, report=report)
    if not quiet:
        from rich.console import Console

        s, u = run.summary, run.summary["uncertainty"]
        Console(stderr=False).print(f"convex array: R = {s['radius_of_curvature'] * 1e3:.4g} ± "
                      f"{(u['radius_of_curvature'] or float('nan')) * 1e3:.2g} mm, arc "
                      f"{s['aperture']['width'] * 1e3:.4g} mm "
                      f"({s['aperture']['arc_angle_deg']:.4g}°), "
                      f"{s['elements']['count']} elements → {out}")
        if "receive" in s:
            r, ur, nan = s["receive"], u["receive"], float("nan")
            Console(stderr=False).print(
                f"receive: plate {(r['reflector_distance'] or nan) * 1e3:.4g} ± "
                f"{(ur['reflector_distance'] or nan) * 1e3:.2g} mm from the apex, θy' "
                f"{r['theta_y_deg']:.4g} ± {ur['theta_y_deg'] or nan:.2g}°, Rp "
                f"{r['reflection_coefficient'] or nan:.3g}")
    return True


def characterize(
    scan: Annotated[Path, typer.Argument(help="Scan: native .h5, ScanData.mat, or a "
                                               "directory holding the toolkit's files.")],
    out: OutputDirectory,
    drive: Annotated[Path | None, typer.Option(
        "--drive", help="Drive voltage: TransmitData.mat, native .h5 or CSV (time_s, "
                        "voltage_V). Default: the one stored with the scan.")] = None,
    sensitivity: Annotated[Path | None, typer.Option(
        "--sensitivity", help="Hydrophone calibration: complex CSV (frequency_Hz,"
                              "magnitude_V_per_Pa,phase_rad[,u_…]) or HDF5, deconvolved with "
                              "the [hydrophone] settings; amplitude-only CSV or "
                              "sensitivity.mat.")] = None,
    config: Annotated[Path | None, typer.Option(
        "--config", help="TOML configuration file.")] = None,
    set_: Annotated[list[str] | None, typer.Option(
        "--set", help="Override a setting: section.key=value (repeatable).")] = None,
    overwrite: Annotated[bool, typer.Option(
        "--overwrite", help="Replace existing output files.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bars or table.")] = False,
    receive: Annotated[Path | None, typer.Option(
        "--receive", help="Reflector echo for the receive side: native echo .h5, "
                          "ReceiveData.mat, or a directory holding the toolkit's files.")
    ] = None,
    reflection_coefficient: Annotated[float | None, typer.Option(
        "--reflection-coefficient", help="Reflection coefficient Rp of the plate (default: "
                                         "from the echo train).")] = None,
    sound_speed: Annotated[str | None, typer.Option(
        "--sound-speed", help="Water sound speed in m/s instead of the file's, or "
                              "'from-data' (estimated from the scan, then used).")] = None,
    water_temperature: Annotated[float | None, typer.Option(
        "--water-temperature", help="Water temperature in °C: the sound speed of pure "
                                    "water (Marczak 1997) instead of the file's.")] = None,
    source: Annotated[str | None, typer.Option(
        "--source", help="Holograms: source model spherical-cap | flat-disc | "
                         "flat-rectangle (default: the file's Geometry; array: a transient "
                         "array scan).")] = None,
    radius_of_curvature: Annotated[float | None, typer.Option(
        "--radius-of-curvature", "--radius", help="Holograms and convex arrays: nominal "
                                                  "radius of curvature in m (overrides the "
                                                  "file).")] = None,
    array: Annotated[str | None, typer.Option(
        "--array", help="Array layout: linear | convex | matrix | sparse | row-column "
                        "(default: the scan's probe description, which a row-column array "
                        "needs; convex: docs/convex.md; matrix: a flat "
                        "2-D grid, with --grid and --pitch; sparse: a 2-D grid with only "
                        "the --elements positions populated, or the file's sparse "
                        "ElementPos).")] = None,
    grid: Annotated[str | None, typer.Option(
        "--grid", help="--array matrix|sparse: lattice positions along x and y, e.g. "
                       "32x32.")] = None,
    pitch: Annotated[float | None, typer.Option(
        "--pitch", help="--array matrix|sparse: element pitch in m (both directions; "
                        "default the file's).")] = None,
    transmit_set: Annotated[str | None, typer.Option(
        "--transmit-set", help="Row-column arrays: the set of strips that transmitted, "
                               "columns | rows.")] = None,
    elements: Annotated[Path | None, typer.Option(
        "--elements", help="--array sparse: CSV ix,iy of each element (0-based lattice "
                           "column and row, RF channel order; docs/formats.md).")] = None,
    aperture: Annotated[list[float] | None, typer.Option(
        "--aperture", help="Holograms: nominal aperture in m (diameter; twice for a "
                           "rectangle's width and height; overrides the file).")] = None,
    flattened_order: Annotated[str | None, typer.Option(
        "--flattened-order", help="Holograms: [n, nt] MATLAB data on xGrid/yGrid axis "
                                  "vectors were flattened x fastest or y fastest (x | y; "
                                  "default auto: the smoother reading, x on a square grid, "
                                  "with a warning); = --set hologram.flattened_order=…")
    ] = None,
    report: Annotated[bool, typer.Option(
        "--report/--no-report", help="Write report.html (figures drawn with matplotlib: "
                                     "≈ 1.5-2 s CPU of a full-size run); --no-report "
                                     "writes the other files only.")] = True,
) -> None:
    """Characterize the transmit side of a probe from a hydrophone scan (paper Fig. 4),
    and with --receive the receive side from a flat-reflector echo (paper section III B).

    Writes summary.json, virtual_transducer.h5, source_velocity.h5 and report.html
    into OUT. A hologram (CW or transient, MATLAB HologramSf/HologramTr layout or native)
    is detected from the file and characterized as a single-element source: alignment,
    back-projection onto the aligned surface, power, focal field; OUT gets summary.json,
    source.h5 and report.html.
    """
    from holoprobe.errors import InputError
    from holoprobe.io import measurement_kind

    if reflection_coefficient is not None and receive is None:
        raise InputError("only meaningful with --receive", field="--reflection-coefficient")
    if flattened_order is not None:
        set_ = [*(set_ or []), f"hologram.flattened_order={flattened_order}"]
    if source != "array" and measurement_kind(scan) == "hologram":
        _characterize_hologram(scan, out, config=config, set_=set_, overwrite=overwrite,
                               quiet=quiet, source=source,
                               radius_of_curvature=radius_of_curvature, aperture=aperture,
                               report=report)
        return
    if _convex_dispatch(scan, out, array=array, drive=drive, sensitivity=sensitivity,
                        config=config, set_=set_, overwrite=overwrite, quiet=quiet,
                        radius_of_curvature=radius_of_curvature, receive=receive,
                        reflection_coefficient=reflection_coefficient, report=report):
        return
    from holoprobe.io import probe_array_kind
    from holoprobe.workflow import OUTPUT_FILES
    from holoprobe.workflow import characterize as run_characterization

    row_column = (array or probe_array_kind(scan)) == "row-column"
    if row_column and transmit_set is None:
        raise InputError("a row-column array: say which set of strips transmitted "
                         "(columns or rows)", field="--transmit-set")
    if transmit_set is not None and not row_column:
        raise InputError("only meaningful for a row-column array", field="--transmit-set")
    if elements is not None and array != "sparse":  # it would be ignored without a word
        raise InputError(f"only meaningful with --array sparse, got --array {array}",
                         field="--elements")

    if not overwrite:  # fail before the computation, not after it
        for name in OUTPUT_FILES:
            if (out / name).exists():
                raise InputError("exists (pass --overwrite to replace it)",
                                 file=str(out / name))
    speed: float | str | None = sound_speed
    if sound_speed is not None and sound_speed != "from-data":
        try:
            speed = float(sound_speed)
        except ValueError:
            raise InputError(f"expected a speed in m/s or 'from-data', got {sound_speed!r}",
                             field="--sound-speed") from None
    measurement = (_matrix_scan(scan, grid, pitch, elements, array)
                   if array in ("matrix", "sparse") else scan)
    options: dict[str, Any] = {
        "drive": drive, "calibration": sensitivity, "config": config, "echo": receive,
        "reflection_coefficient": reflection_coefficient, "overrides": set_ or (),
        "progress": not quiet, "sound_speed": speed, "water_temperature": water_temperature}
    if row_column:
        from holoprobe.workflow import characterize_row_column

        run = characterize_row_column(measurement, str(transmit_set), **options)
    else:
        run = run_characterization(measurement, **options)
    _drop_stale_report(out, report)
    run.save(out, overwrite=overwrite, report=report)
    if not quiet:
        _print_summary(run, out)


def _matrix_scan(path: Path, grid: str | None, pitch: float | None,
                 elements: Path | None = None, array: str = "matrix"):
    """The scan at ``path`` described as a flat 2-D matrix array (``--array matrix``):
    ``--grid NXxNY`` elements at ``--pitch`` (default the file's), elements as wide as
    the file's (else the pitch), square. ``--array sparse``: only the ``--elements``
    positions (CSV ix, iy) of that grid, in the CSV's order; without ``--elements`` the
    file's own probe description must be a sparse matrix (it is then used as is)."""
    import dataclasses

    from holoprobe.errors import InputError
    from holoprobe.geometry import ArrayGeometry
    from holoprobe.io import read_element_grid, read_scan_any
    from holoprobe.measurement import ProbeInfo

    if array == "sparse" and elements is None:
        scan = read_scan_any(path)
        if scan.probe is None or scan.probe.array is None \
                or scan.probe.array.layout != "sparse":
            raise InputError("the file's probe description is not a sparse matrix "
                             "(Trans.ElementPos on a lattice with missing positions): give "
                             "--grid and --elements", field="--array")
        return scan
    if elements is not None and array != "sparse":
        raise InputError("only meaningful with --array sparse", field="--elements")
    try:
        nx, ny = (int(v) for v in (grid or "").lower().split("x"))
    except ValueError:
        raise InputError(f"expected elements along x and y like 32x32, got {grid!r}",
                         field="--grid") from None
    if nx < 1 or ny < 1 or nx * ny < 2:
        raise InputError(f"expected at least two elements, got {grid!r}", field="--grid")
    scan = read_scan_any(path)
    old = scan.probe
    p = pitch if pitch is not None else (None if old is None else old.pitch)
    if p is None or not 0 < p < 0.01:
        raise InputError(f"expected a pitch in m (0 < p < 10 mm), got {p!r} (give --pitch)",
                         field="--pitch")
    width = min(old.element_width, p) if old is not None else p
    try:
        layout = ArrayGeometry.matrix(
            nx, ny, p, p, width, width,
            grid_position=None if elements is None else read_element_grid(elements))
    except InputError as exc:
        if exc.file:  # the reader's error names the file and the CSV column already
            raise
        raise InputError(exc.detail, file=str(elements), field="--elements") from None
    probe = ProbeInfo(layout.count, p, width, width,
                      old.center_frequency if old is not None else 3e6, float("inf"),
                      old.name if old is not None else "", layout)
    return dataclasses.replace(scan, probe=probe)


def _print_summary(run, out: Path) -> None:
    """The table of the estimates with their uncertainties, the time and the warnings."""
    from rich.console import Console
    from rich.table import Table

    s = run.summary
    result, rx = run.transmit, run.receive
    u = s["uncertainty"]
    table = Table(title=f"holoprobe characterize → {out}")
    table.add_column("parameter")
    table.add_column("value", justify="right")
    table.add_column("± u", justify="right")

    def row(name, value, unc, scale, unit):
        def fmt(v):
            return ("—" if v is None else f"{v * scale:.4g}")
        table.add_row(name, f"{fmt(value)} {unit}", f"{fmt(unc)}")

    for key in ("theta_x_deg", "theta_y_deg", "theta_z_deg"):
        row(f"scan_plane.{key}", s["scan_plane"][key], u["scan_plane"][key], 1, "°")
    for key in ("x0", "y0", "z0"):
        row(f"scan_plane.{key}", s["scan_plane"][key], u["scan_plane"][key], 1e3, "mm")
    for key in ("width", "height", "center_x", "center_y"):
        row(f"aperture.{key}", s["aperture"][key], u["aperture"][key], 1e3, "mm")
    table.add_row("elements.count", str(s["elements"]["count"]), "")
    for key in ("pitch", "width"):
        row(f"elements.{key}", s["elements"][key], u["elements"][key], 1e3, "mm")
    row("lens_focus", s["lens_focus"], u["lens_focus"], 1e3, "mm")
    row("transmit.onset", s["transmit"]["onset"], u["transmit"]["onset"], 1e9, "ns")
    row("transmit.peak_frequency", s["transmit"]["peak_frequency"], None, 1e-6, "MHz")
    row("transmit.bandwidth_6db", s["transmit"]["bandwidth_6db"], None, 1e-6, "MHz")
    if rx is not None:
        r, ur = s["receive"], u["receive"]
        if ur["theta_x_deg"] is not None:  # estimated (a matrix array)
            row("receive.theta_x_deg", r["theta_x_deg"], ur["theta_x_deg"], 1, "°")
        row("receive.theta_y_deg", r["theta_y_deg"], ur["theta_y_deg"], 1, "°")
        for key in ("sensor_x0", "sensor_y0", "sensor_z0", "reflector_distance"):
            if key in r:
                row(f"receive.{key}", r[key], ur[key], 1e3, "mm")
        row("receive.reflection_coefficient", r["reflection_coefficient"],
            ur["reflection_coefficient"], 1, "")
        row("receive.onset", r["onset"], ur["onset"], 1e6, "µs")
        row("receive.peak_frequency", r["peak_frequency"], None, 1e-6, "MHz")
        row("receive.bandwidth_6db", r["bandwidth_6db"], None, 1e-6, "MHz")
    console = Console(stderr=False)
    console.print(table)
    if "row_column" in s:  # the table is the set's own 1-D frame
        rc = s["row_column"]
        sp = rc["scan_plane"]
        console.print(f"row-column array, {rc['transmit']} transmitting: scan plane in the "
                      f"probe's frame θx {sp['theta_x_deg']:.4f}°, θy {sp['theta_y_deg']:.4f}°, "
                      f"θz {sp['theta_z_deg']:.4f}°, origin "
                      f"{np.round(np.array([sp['x0'], sp['y0'], sp['z0']]) * 1e3, 4).tolist()} mm")
    total = result.timings["total"] + (rx.timings["total"] if rx is not None else 0.0)
    console.print(f"total {total:.1f} s")
    for w in s["warnings"]:
        console.print(f"[yellow]warning:[/yellow] {w}")
