"""One convex-array characterization run (issue 16), from a file or a HydrophoneScan."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from holoprobe.characterize import (
    CharacterizationConfig,
    ConvexFace,
    ConvexTransmitResult,
    ReceiveResult,
    characterize_convex_receive,
    characterize_convex_transmit,
)
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import Medium
from holoprobe.io import read_drive, read_echo_any, read_scan_any, write_json
from holoprobe.measurement import (
    DriveSignal,
    EchoRecording,
    HydrophoneCalibration,
    HydrophoneScan,
)
from holoprobe.signal import frequency_axis, load_calibration, next_fast_length, to_frequency
from holoprobe.transducer import VirtualTransducer
from holoprobe.workflow._outputs import (
    _floats,
    _receive_summary,
    element_transmit_weights,
    model_metadata,
    receive_model_fields,
    receive_signal_figures,
    transfer_function_section,
)
from holoprobe.workflow._paths import PathLike

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["CONVEX_OUTPUT_FILES", "ConvexRun", "characterize_convex", "is_convex_scan"]

CONVEX_OUTPUT_FILES = ("summary.json", "report.html", "virtual_transducer.h5")


def is_convex_scan(scan: HydrophoneScan) -> bool:
    """True when the scan's probe description is a convex array."""
    probe = scan.probe
    return probe is not None and probe.array is not None and probe.array.kind == "convex"


@dataclass(frozen=True)
class ConvexRun:
    """What one convex-array characterization produced, before anything is written.

    Attributes
    ----------
    result : ConvexTransmitResult
    inputs : tuple of Path
        Input files (never overwritten by :meth:`save`).
    medium : Medium
        The scan's medium (that of the virtual transducer).
    config : CharacterizationConfig or None
        The configuration used (recorded in the model's provenance).
    name : str
        A label for the model (the scan file's stem).
    receive : ReceiveResult or None
        The receive characterization from a flat-reflector echo
        (:func:`~holoprobe.characterize.characterize_convex_receive`), when one was given.
    """

    result: ConvexTransmitResult
    inputs: tuple[Path, ...] = ()
    medium: Medium = field(default_factory=Medium)
    config: CharacterizationConfig | None = None
    name: str = ""
    receive: ReceiveResult | None = None

    def virtual_transducer(self) -> VirtualTransducer:
        """The virtual transducer: the fitted arc (``array``: each element's centre and
        normal on the cylinder of the fitted R, apex at the origin, centre of curvature
        at (0, 0, −R)), arc pitch and element width, aperture height H, lens focus,
        transmit IR (time origin: the onset of the mean surface velocity on the face),
        element map, with a receive result the receive IR and the per-element receive
        gains (``element_sensitivity``) and delays, parameters with their uncertainties
        and provenance.

        Raises
        ------
        InputError
            No transmit impulse response (no drive).
        """
        r = self.result
        ir = r.impulse_response
        if ir is None:
            raise InputError("no transmit impulse response (no drive): no virtual "
                             "transducer", field="drive")
        geo = r.geometry
        cfg = self.config if self.config is not None else CharacterizationConfig()
        kind = "transmit + receive" if self.receive is not None else "transmit"
        params, uncs, prov = model_metadata(self.summary, self.inputs, cfg.to_toml(),
                                            f"holoprobe characterize (convex, {kind})")
        return VirtualTransducer(
            element_count=geo.count, pitch=float(np.ptp(geo.element_angles) / max(
                geo.count - 1, 1) * r.radius_of_curvature) if geo.count > 1
            else float(geo.widths[0]), element_width=float(geo.widths[0]),
            element_height=float(geo.heights[0]),
            transmit_impulse_response=ir.ir, transmit_sampling_rate=ir.sampling_rate,
            lens_focus=r.lens_focus, aperture_width=r.aperture.width,
            aperture_height=r.aperture.height, medium=self.medium, parameters=params,
            uncertainties=uncs, provenance=prov, name=self.name, array=geo,
            **element_transmit_weights(r.element_map, geo.count),
            **receive_model_fields(self.receive, geo.count))

    @property
    def summary(self) -> dict[str, Any]:
        """The ``summary.json`` tree (docs/convex.md); with a receive result also the
        ``receive`` section of a flat array's summary (``sensor_x0``/``sensor_z0``: the
        image of the apex) and ``elements.receive_gain`` (with its uncertainty)."""
        out = self.result.summary()
        rx = self.receive
        if rx is not None:
            out["receive"], out["uncertainty"]["receive"] = _receive_summary(
                rx, rx.config.transfer_function_floor)
            sens = rx.sensitivity
            if sens is not None and sens.amplitude.size == out["elements"]["count"]:
                out["elements"]["receive_gain"] = _floats(sens.amplitude)
                u = sens.amplitude_uncertainty
                unc = out["uncertainty"].get("elements") or {}
                unc["receive_gain"] = None if u is None else _floats(u)
                out["uncertainty"]["elements"] = unc
            out["timings"].update({f"receive.{k}": float(v) for k, v in rx.timings.items()})
            out["warnings"] += [f"receive: {w}" for w in rx.warnings]
        out["inputs"] = [str(p) for p in self.inputs]
        return out

    def figures(self) -> list[tuple[str, list[Figure]]]:
        """Report sections: the arc with the element map, the element map, the IR."""
        from holoprobe.report import (
            plot_array_geometry,
            plot_element_map,
            plot_impulse_response,
        )

        r = self.result
        sections: list[tuple[str, list[Figure]]] = []
        em = r.element_map
        if em is not None:
            geo = r.geometry
            sections.append(("Array", [
                plot_array_geometry(geo.positions, geo.normals, em.relative_amplitude,
                                    widths=geo.widths, dead=em.dead),
                plot_element_map(em.relative_amplitude, em.delay, dead=em.dead,
                                 weak=em.weak, amplitude_uncertainty=em.amplitude_uncertainty)]))
        if r.impulse_response is not None:
            ir, sp = r.impulse_response, r.ir_spectrum
            n = next_fast_length(4 * ir.ir.size)
            spec = np.abs(to_frequency(ir.ir, n=n))
            db = 20 * np.log10(np.maximum(spec / spec.max(), 1e-12))
            sections.append(("Transmit impulse response", [plot_impulse_response(
                np.arange(ir.ir.size) / ir.sampling_rate, ir.ir,
                frequency_axis(n, ir.sampling_rate), db, label="transmit impulse response",
                unit="Pa/(V·s)", peak_frequency=sp.peak_frequency, band=(sp.f_low, sp.f_high),
                max_frequency=min(3 * sp.f_high, 0.5 * ir.sampling_rate))]))
        rx = self.receive
        if rx is not None:
            vr = rx.receiver
            delays = np.asarray(rx.extras["element_delays"])
            line = delays + float(np.mean((vr.arrival_times - delays)[vr.used]))
            sections.append(("Receive from a flat reflector (mirrored arc)",
                             receive_signal_figures(rx, line)))
            if r.impulse_response is not None:
                sections.append(transfer_function_section(r.impulse_response, rx))
        return sections

    def save(self, out_dir: PathLike, *, overwrite: bool = False,
             report: bool = True) -> dict[str, Path]:
        """Write summary.json, report.html and (with a transmit IR)
        virtual_transducer.h5 into ``out_dir`` (atomically)."""
        out = Path(out_dir)
        if not overwrite:
            for name in CONVEX_OUTPUT_FILES:
                if (out / name).exists():
                    raise InputError("exists (pass --overwrite to replace it)",
                                     file=str(out / name))
        out.mkdir(parents=True, exist_ok=True)
        summary = self.summary
        protect = tuple(self.inputs)
        written = {"summary.json": write_json(out / "summary.json", summary,
                                              overwrite=overwrite, protect=protect)}
        if self.result.impulse_response is not None:
            target = out / "virtual_transducer.h5"
            if any(target.resolve() == Path(p).resolve() for p in protect):
                raise InputError("is an input file; choose another output directory",
                                 file=str(target))
            written["virtual_transducer.h5"] = self.virtual_transducer().save(
                target, overwrite=overwrite)
        if report:
            from holoprobe.report import build_report

            keys = ("scan_plane", "radius_of_curvature", "aperture", "lens_focus",
                    "receive", "uncertainty")
            params = {k: summary[k] for k in keys if k in summary}
            written["report.html"] = build_report(
                out / "report.html", title="holoprobe characterize (convex array)",
                parameters=params, sections=self.figures(), warnings=summary["warnings"],
                overwrite=overwrite, protect=protect)
        return written


def characterize_convex(
    scan: HydrophoneScan | PathLike,
    *,
    radius_of_curvature: float | None = None,
    drive: DriveSignal | PathLike | None = None,
    calibration: HydrophoneCalibration | PathLike | None = None,
    config: CharacterizationConfig | PathLike | None = None,
    overrides: Sequence[str] = (),
    progress: bool = False,
    echo: EchoRecording | PathLike | None = None,
    reflection_coefficient: float | None = None,
) -> ConvexRun:
    """Characterize a convex array: transmit from a hydrophone scan and, with ``echo``,
    receive from a flat-reflector echo (the mirrored arc, docs/convex.md "Receive").

    Parameters
    ----------
    scan : HydrophoneScan or path
        The scan (native HDF5 or the toolkit's .mat files).
    radius_of_curvature : float, optional
        Nominal R in m (default: the scan's probe description, ``probe.array``).
    drive, calibration, config, overrides, progress, echo, reflection_coefficient
        As for :func:`holoprobe.workflow.characterize`.

    Returns
    -------
    ConvexRun
        ``.summary``, ``.figures()``, ``.save(dir)``.
    """
    if reflection_coefficient is not None and not 0 < abs(reflection_coefficient) <= 1:
        raise InputError(f"expected 0 < |Rp| ≤ 1, got {reflection_coefficient:g}",
                         field="--reflection-coefficient")
    paths = [Path(p) for p in (scan, drive, calibration, config, echo)
             if isinstance(p, str | os.PathLike)]
    cfg = CharacterizationConfig.resolve(config, overrides)
    ranges = cfg.plausibility
    data = scan if isinstance(scan, HydrophoneScan) else read_scan_any(scan,
                                                                       plausibility=ranges)
    if isinstance(calibration, str | os.PathLike):
        calibration = load_calibration(Path(calibration), plausibility=ranges)
    if isinstance(drive, str | os.PathLike):
        drive = read_drive(drive)
    result = characterize_convex_transmit(data, cfg, radius_of_curvature=radius_of_curvature,
                                          drive=drive, calibration=calibration,
                                          progress=progress)
    receive = None
    if echo is not None:
        receive = _receive(echo, result, data, cfg, reflection_coefficient, calibration,
                           progress)
    name = Path(scan).stem if isinstance(scan, str | os.PathLike) else ""
    return ConvexRun(result, tuple(paths), data.medium, cfg, name, receive)


def _receive(echo: EchoRecording | PathLike, result: ConvexTransmitResult,
             scan: HydrophoneScan, cfg: CharacterizationConfig, rp: float | None,
             calibration: HydrophoneCalibration | None, progress: bool) -> ReceiveResult:
    """The receive step of :func:`characterize_convex`; errors name the echo file."""
    path = Path(echo) if isinstance(echo, str | os.PathLike) else None
    if path is not None and not path.exists():
        raise InputError("no such file or directory", file=str(path), field="--receive")
    recording = (read_echo_any(path, plausibility=cfg.plausibility) if path is not None
                 else echo)
    if not isinstance(recording, EchoRecording):
        raise InputError("expected an EchoRecording or an echo file", field="echo")
    try:
        return characterize_convex_receive(recording, ConvexFace.from_transmit(result), scan,
                                           cfg, reflection_coefficient=rp,
                                           calibration=calibration, progress=progress)
    except (InputError, FitError) as exc:
        if path is None:
            raise
        raise type(exc)(f"receive: {exc.detail}", file=str(path), field=exc.field) from None
