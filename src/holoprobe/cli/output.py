"""``holoprobe output``: acoustic output quantities (IEC 62127-1 / 62359) of a transmit.

The field of the virtual transducer is predicted
(:func:`holoprobe.transducer.predict_field`) on the beam axis, then on an elevation (y)
and a lateral (x) line through the maximum pulse intensity integral at the depth of
the on-axis maximum (moved off the axis when the maximum lies there);
:func:`holoprobe.exposure.exposure_metrics` turns the waveforms into p_r, p_c, PII,
PD, I_sppa, I_spta, f_awf, derated values, MI and −6 dB beam widths. Lengths are in mm
at this boundary, SI inside and in the JSON.
"""

from __future__ import annotations

import contextlib
import json
import math
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer

from holoprobe.cli._app import VirtualTransducerPath

if TYPE_CHECKING:
    from rich.table import Table

__all__ = ["output"]


def _line(axis: int, center: np.ndarray, half: float, step: float) -> np.ndarray:
    n = max(3, 2 * math.ceil(half / step) + 1)
    s = np.linspace(-half, half, n)
    pts = np.repeat(center[None, :], n, axis=0)
    pts[:, axis] += s
    return pts


def output(
    virtual_transducer: VirtualTransducerPath,
    transmit: Annotated[Path | None, typer.Option(
        "--transmit", help="Transmit setting (TOML).")] = None,
    sequence: Annotated[Path | None, typer.Option(
        "--sequence", help="Transmit sequence (TOML, docs/formats.md): per-transmit and "
                           "worst-case MI, I_sppa and the sequence's I_spta.")] = None,
    lateral_mm: Annotated[float | None, typer.Option(
        "--lateral-mm", help="--sequence: half width of the xz plane searched, mm "
                             "(default: the aperture's half width + 5 mm, or the widest "
                             "focus).")] = None,
    plane_step_mm: Annotated[float, typer.Option(
        help="--sequence: step of the xz plane searched, mm.")] = 0.5,
    prf: Annotated[float | None, typer.Option(
        "--prf", help="Pulse repetition frequency in Hz (default: the setting's).")] = None,
    out: Annotated[Path | None, typer.Option("--out", help="JSON output file.")] = None,
    depth_mm: Annotated[tuple[float, float], typer.Option(
        "--depth-mm", help="Axial range searched for the maximum, mm.")] = (2.0, 120.0),
    axial_step_mm: Annotated[float, typer.Option(help="Axial step in mm.")] = 0.5,
    lateral_step_mm: Annotated[float, typer.Option(
        help="Step of the lateral and elevation lines in mm.")] = 0.1,
    attenuation_db_cm_mhz: Annotated[float, typer.Option(
        help="Derating coefficient in dB/(cm·MHz).")] = 0.3,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing JSON file.")] = False,
    mode: Annotated[str, typer.Option(
        help="Thermal-index mode: non-scanning or scanning (IEC 62359).")] = "non-scanning",
    scan_width_mm: Annotated[float | None, typer.Option(
        help="Scanning mode: width of the scanned aperture in mm (P_1 = P·min(1, 10 mm / "
             "width), the beam swept uniformly).")] = None,
    power_depth_mm: Annotated[float, typer.Option(
        help="Depth of the plane through which the output power is integrated, mm.")] = 2.0,
    thermal: Annotated[bool, typer.Option(
        help="Compute the output power and TIS/TIB/TIC (needs a PRF).")] = True,
    scheduler: Annotated[str | None, typer.Option(
        "--scheduler", help="--sequence: address of a running dask.distributed scheduler "
                            "that computes the fields (default: dask's config key "
                            "scheduler-address / DASK_SCHEDULER_ADDRESS, else in-process).")
    ] = None,
) -> None:
    """Acoustic output table (p_r, PII, I_sppa, I_spta, MI, beam widths, power, TIS, TIB,
    TIC) and JSON."""
    from rich.console import Console

    from holoprobe.errors import InputError
    from holoprobe.exposure import exposure_metrics, pulse_intensity_integral
    from holoprobe.io import atomic_write
    from holoprobe.transducer import (
        TransmitSetting,
        VirtualTransducer,
        predict_field,
        signal_band,
    )

    if (transmit is None) == (sequence is None):
        raise InputError("give either --transmit or --sequence", field="--transmit")
    if sequence is not None:
        _sequence_output(virtual_transducer, sequence, out=out, depth_mm=depth_mm,
                         lateral_mm=lateral_mm, step_mm=plane_step_mm, prf=prf,
                         attenuation_db_cm_mhz=attenuation_db_cm_mhz, overwrite=overwrite,
                         scheduler=scheduler)
        return
    if scheduler is not None:
        raise InputError("--scheduler needs --sequence (one transmit runs in-process)",
                         field="--scheduler")
    assert transmit is not None
    vt = VirtualTransducer.load(virtual_transducer)
    setting = TransmitSetting.from_toml(transmit)
    prf = setting.prf if prf is None else prf
    z0, z1 = (v * 1e-3 for v in depth_mm)
    if not (0 < z0 < z1):
        raise InputError(f"expected 0 < min < max, got {depth_mm}", field="--depth-mm")
    if not (axial_step_mm > 0 and lateral_step_mm > 0):
        raise InputError("expected positive steps in mm", field="--axial-step-mm")
    _, f_hi = signal_band(vt, setting)
    fs = 8.0 * f_hi
    axis = np.zeros((math.floor((z1 - z0) / (axial_step_mm * 1e-3)) + 1, 3))
    axis[:, 2] = z0 + np.arange(axis.shape[0]) * axial_step_mm * 1e-3
    axis[:, 0], axis[:, 1] = vt.aperture_center
    on_axis = predict_field(vt, setting, axis, sampling_rate=fs)
    i_max = int(np.argmax(pulse_intensity_integral(on_axis.pressure, fs, vt.medium)))
    lateral, elevation = _beam_lines(vt, setting, axis[i_max].copy(),
                                     lateral_step_mm * 1e-3, fs)
    parts = (on_axis, lateral, elevation)
    nt = max(p.pressure.shape[1] for p in parts)
    pressure = np.concatenate([np.pad(p.pressure, ((0, 0), (0, nt - p.pressure.shape[1])))
                               for p in parts])
    points = np.concatenate([p.points for p in parts])
    beam_axis = np.zeros(points.shape[0], bool)
    beam_axis[:on_axis.points.shape[0]] = True  # z_MI is searched on the beam axis
    metrics = exposure_metrics(pressure, fs, points, vt.medium, prf=prf,
                               attenuation_db_cm_mhz=attenuation_db_cm_mhz, axis=beam_axis)
    summary = metrics.to_dict()
    thermal_rows: list[tuple[str, str, str]] = []
    if thermal and prf is not None and vt.is_curved:
        summary["thermal_indices_note"] = ("not computed: the output power of a convex "
                                           "model (plane integral) is not implemented")
    elif thermal and prf is not None:
        indices, thermal_rows = _thermal(vt, setting, on_axis, fs, metrics, prf, mode,
                                         scan_width_mm, power_depth_mm * 1e-3)
        summary.update(indices)
    summary.update({"virtual_transducer": str(virtual_transducer), "transmit": str(transmit),
                    "sampling_rate": fs, "axial_range": [z0, z1]})
    if out is not None:
        with atomic_write(out, overwrite=overwrite,
                          protect=[virtual_transducer, transmit]) as tmp:
            tmp.write_text(json.dumps(summary, indent=2))

    Console().print(_output_table(metrics, setting.name or transmit.name,
                                  attenuation_db_cm_mhz, thermal_rows))


def _beam_lines(vt, setting, center: np.ndarray, step: float, fs: float) -> tuple:
    """The lateral (x) and elevation (y) lines through the maximum pulse intensity
    integral at the depth of ``center`` (m), as two field predictions.

    The maximum at that depth can lie off the axis (elevation near field): the lines are
    moved through it, elevation first, then lateral, then elevation again if needed.
    """
    from holoprobe.exposure import pulse_intensity_integral
    from holoprobe.transducer import predict_field

    def line(axis_index: int, half: float):
        pred = predict_field(vt, setting, _line(axis_index, center, half, step),
                             sampling_rate=fs)
        pii = pulse_intensity_integral(pred.pressure, fs, vt.medium)
        return pred, pred.points[int(np.argmax(pii)), axis_index]

    elevation, center[1] = line(1, vt.aperture_height)
    lateral, x_peak = line(0, 0.5 * vt.aperture_width)
    if abs(x_peak - center[0]) > 0.5 * step:
        center[0] = x_peak
        elevation, center[1] = line(1, vt.aperture_height)
        lateral, _ = line(0, 0.5 * vt.aperture_width)
    return lateral, elevation


def _output_table(metrics, name: str, attenuation_db_cm_mhz: float,
                  thermal_rows: list) -> Table:
    """The rich table of the acoustic output quantities (water and derated)."""
    from rich.table import Table

    def fmt(value: float | None, scale: float, digits: str = ".3g") -> str:
        return "—" if value is None or not math.isfinite(value) else f"{value * scale:{digits}}"

    m = metrics
    table = Table(title=f"acoustic output: {name}")
    table.add_column("quantity")
    table.add_column("water", justify="right")
    table.add_column(f"derated (α = {attenuation_db_cm_mhz:.2g} dB/cm/MHz)", justify="right")
    table.add_row("p_r (MPa)", fmt(m.peak_rarefactional_pressure, 1e-6),
                  fmt(m.peak_rarefactional_pressure_derated, 1e-6))
    table.add_row("p_c (MPa)", fmt(m.peak_compressional_pressure, 1e-6), "")
    table.add_row("PII (J/cm²)", fmt(m.pulse_intensity_integral, 1e-4),
                  fmt(m.pulse_intensity_integral_derated, 1e-4))
    table.add_row("pulse duration (µs)", fmt(m.pulse_duration, 1e6), "")
    table.add_row("I_sppa (W/cm²)", fmt(m.isppa, 1e-4), fmt(m.isppa_derated, 1e-4))
    table.add_row("I_spta (mW/cm²)", fmt(m.ispta, 1e-1), fmt(m.ispta_derated, 1e-1))
    table.add_row("f_awf (MHz)", fmt(m.acoustic_working_frequency, 1e-6), "")
    table.add_row("MI", "", fmt(m.mechanical_index, 1.0))
    table.add_row("depth of max (mm)", fmt(m.depth_of_maximum, 1e3), fmt(m.depth_mi, 1e3))
    table.add_row("−6 dB width lateral (mm)", fmt(m.beam_width_lateral, 1e3), "")
    table.add_row("−6 dB width elevation (mm)", fmt(m.beam_width_elevation, 1e3), "")
    for row in thermal_rows:
        table.add_row(*row)
    return table


def _thermal(vt, setting, on_axis, fs: float, metrics, prf: float, mode: str,
             scan_width_mm: float | None, depth: float) -> tuple[dict, list]:
    """Output power (plane, cross-checked with the source) and TIS/TIB/TIC."""
    from holoprobe.errors import InputError
    from holoprobe.exposure import acoustic_output_power, pulse_intensity_integral, thermal_indices

    power = acoustic_output_power(vt, setting, depth=depth, prf=prf)
    # a power (W), not an energy per pulse: acoustic_output_power was given the PRF
    p_plane, p_source = power.power_plane, power.power_source
    assert p_plane is not None and p_source is not None
    p1 = p_plane
    if mode == "scanning":
        if scan_width_mm is None or not scan_width_mm > 0:
            raise InputError("scanning mode needs the scanned width in mm",
                             field="--scan-width-mm")
        p1 = p_plane * min(1.0, 10.0 / scan_width_mm)
    z = on_axis.points[:, 2]
    ita = pulse_intensity_integral(on_axis.pressure, fs, vt.medium) * prf
    ti = thermal_indices(power=p_plane, frequency=metrics.acoustic_working_frequency,
                         depths=z, intensity_ta=ita, aperture_area=power.aperture_area,
                         mode=mode, power_1cm=p1,
                         attenuation_db_cm_mhz=metrics.attenuation_db_cm_mhz)
    rows = [("output power (mW)", f"{p_plane * 1e3:.4g}", f"source: {p_source * 1e3:.4g}"),
            ("TIS / TIB / TIC", "", f"{ti.tis:.3g} / {ti.tib:.3g} / {ti.tic:.3g} ({mode})")]
    return {"acoustic_power": power.to_dict(), "thermal_indices": ti.to_dict()}, rows


def _sequence_points(vt, sequence, depth_mm, lateral_mm, step_mm) -> np.ndarray:
    """The xz plane through the elevation centre searched for a sequence's maxima (m)."""
    from holoprobe.errors import InputError

    z0, z1 = (v * 1e-3 for v in depth_mm)
    if not (0 < z0 < z1):
        raise InputError(f"expected 0 < min < max, got {depth_mm}", field="--depth-mm")
    step = step_mm * 1e-3
    if not (math.isfinite(step) and step > 0):
        raise InputError(f"expected a positive step in mm, got {step_mm!r}",
                         field="--plane-step-mm")
    xc, yc = vt.aperture_center
    if lateral_mm is None:
        reach = [abs(s.delays.point[0] - xc) for s in sequence.settings
                 if s.delays.kind == "focused"]
        half = max([0.5 * vt.aperture_width, *reach]) + 5e-3
    else:
        half = lateral_mm * 1e-3
        if not (math.isfinite(half) and half > 0):
            raise InputError(f"expected a positive half width in mm, got {lateral_mm!r}",
                             field="--lateral-mm")
    # x on the element lattice (step pitch/m through an element centre): the offsets
    # between points and elements repeat, which element superposition exploits
    from holoprobe.cli.field import lattice_axis

    hx = vt.pitch / math.ceil(vt.pitch / step - 1e-9)
    x = lattice_axis(xc - half, xc + half, hx, float(vt.element_centers()[0, 0]))
    z = z0 + np.arange(math.floor((z1 - z0) / step + 1e-9) + 1) * step
    gx, gz = np.meshgrid(x, z, indexing="ij")
    return np.stack([gx.ravel(), np.full(gx.size, yc), gz.ravel()], axis=-1)


def _sequence_output(vt_path: Path, path: Path, *, out, depth_mm, lateral_mm, step_mm, prf,
                     attenuation_db_cm_mhz, overwrite, scheduler=None) -> None:
    """``holoprobe output --sequence``: every transmit on an xz plane, then the aggregates.

    With a dask.distributed scheduler (``--scheduler`` or dask's ``scheduler-address``)
    the cluster computes the fields into a temporary ``field.zarr`` beside the JSON
    output (on a shared file system for a multi-machine cluster), read back one transmit
    at a time.
    """
    from rich.console import Console
    from rich.table import Table

    from holoprobe._progress import progress_iter
    from holoprobe.exposure import sequence_exposure
    from holoprobe.io import atomic_write, scheduler_address
    from holoprobe.transducer import (
        TransmitSequence,
        VirtualTransducer,
        predict_fields,
        signal_band,
    )

    address = scheduler_address(scheduler)
    vt = VirtualTransducer.load(vt_path)
    seq = TransmitSequence.from_file(path)
    if prf is not None:
        seq = TransmitSequence(seq.settings, prf, None, seq.name)
    points = _sequence_points(vt, seq, depth_mm, lateral_mm, step_mm)
    fs = 8.0 * max(signal_band(vt, s)[1] for s in seq.settings)

    def pressures():
        fields = predict_fields(vt, seq.settings, points, sampling_rate=fs)
        for pred in progress_iter(fields, total=len(seq), description="transmits",
                                  enabled=None):
            yield pred.pressure

    def exposure(records):
        return sequence_exposure(records, fs, points, vt.medium, prf=seq.prf,
                                 frame_rate=seq.frame_rate,
                                 names=[s.name or f"transmit {i + 1}"
                                        for i, s in enumerate(seq.settings)],
                                 attenuation_db_cm_mhz=attenuation_db_cm_mhz)

    if address is None:
        result = exposure(pressures())
    else:
        with _cluster_fields(vt, seq, points, fs, address,
                             Path(out).parent if out is not None else Path.cwd()) as records:
            result = exposure(records)
    summary = result.to_dict()
    summary.update({"virtual_transducer": str(vt_path), "sequence": str(path),
                    "name": seq.name, "sampling_rate": fs,
                    "searched": {"plane": "xz", "y": float(points[0, 1]),
                                 "x_range": [float(points[:, 0].min()),
                                             float(points[:, 0].max())],
                                 "z_range": [float(points[:, 2].min()),
                                             float(points[:, 2].max())],
                                 "step": step_mm * 1e-3}})
    if out is not None:
        with atomic_write(out, overwrite=overwrite, protect=[vt_path, path]) as tmp:
            tmp.write_text(json.dumps(summary, indent=2))
    table = Table(title=f"acoustic output of the sequence {seq.name or path.name} "
                        f"({len(seq)} transmits, PRF {seq.prf:g} Hz, "
                        f"{seq.frame_rate:.4g} frames/s)")
    for column in ("quantity", "value", "transmit", "where (x, y, z) mm"):
        table.add_column(column)

    def where(p) -> str:
        return ", ".join(f"{v * 1e3:.1f}" for v in p)

    r = result
    table.add_row("MI (worst)", f"{r.mechanical_index:.3g}",
                  r.names[r.mechanical_index_transmit], where(r.mechanical_index_position))
    table.add_row("I_sppa (W/cm², worst)", f"{r.isppa * 1e-4:.3g}", r.names[r.isppa_transmit],
                  where(r.isppa_position))
    table.add_row("I_spta (mW/cm²)", f"{r.ispta * 1e-1:.3g}", "all", where(r.ispta_position))
    table.add_row("I_spta,α (mW/cm²)", f"{r.ispta_derated * 1e-1:.3g}", "all",
                  where(r.ispta_derated_position))
    Console().print(table)


@contextlib.contextmanager
def _cluster_fields(vt, seq, points, fs: float, address: str, folder: Path):
    """Per-transmit pressure records computed on a dask.distributed cluster (generator)."""
    from holoprobe.io import read_field_zarr, write_field_zarr
    from holoprobe.transducer import field_dataset

    ds = field_dataset(vt, seq.settings, points=points, sampling_rate=fs)
    with tempfile.TemporaryDirectory(prefix=".holoprobe-output-", dir=folder) as tmp:
        path = write_field_zarr(Path(tmp) / "field.zarr", ds, scheduler=address)
        store = read_field_zarr(path)
        yield (store.pressure.isel(transmit=k).values for k in range(len(seq)))
