"""One characterization run, from inputs (files or objects) to the results object."""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from holoprobe.characterize import (
    CharacterizationConfig,
    MatrixElementMap,
    MatrixFace,
    ReceiveResult,
    TransmitResult,
    channel_levels,
    characterize_matrix_receive,
    characterize_receive,
    characterize_transmit,
    resolve_edge_ambiguity,
    sound_speed_uncertainty,
    with_sound_speed_uncertainty,
)
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import Medium
from holoprobe.io import (
    check_measurement,
    read_drive,
    read_echo_any,
    read_scan_any,
    warm_sha256,
)
from holoprobe.measurement import DriveSignal, EchoRecording, HydrophoneCalibration, HydrophoneScan
from holoprobe.signal import Threads, load_calibration
from holoprobe.transducer import VirtualTransducer
from holoprobe.workflow._outputs import (
    report_figures,
    summary_dict,
    virtual_transducer,
    write_outputs,
)
from holoprobe.workflow._paths import PathLike

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["CharacterizationRun", "characterize"]


@dataclass(frozen=True)
class CharacterizationRun:
    """What one characterization produced, before anything is written.

    Attributes
    ----------
    transmit : TransmitResult
        The transmit estimation (paper Fig. 4).
    receive : ReceiveResult or None
        The receive estimation (paper section III B), when an echo was given.
    inputs : tuple of Path
        The input files (hashed into the provenance, never overwritten by :meth:`save`).
    timings : mapping of str to float
        Seconds of the steps outside the estimation (``"read"``).
    """

    transmit: TransmitResult
    receive: ReceiveResult | None = None
    inputs: tuple[Path, ...] = ()
    timings: Mapping[str, float] = field(default_factory=dict)

    @property
    def summary(self) -> dict[str, Any]:
        """The ``summary.json`` tree (SI units, ``_deg`` for degrees), see
        :func:`holoprobe.workflow.summary_dict`."""
        out = summary_dict(self.transmit, self.receive)
        out["timings"].update({k: float(v) for k, v in self.timings.items()})
        return out

    @property
    def virtual_transducer(self) -> VirtualTransducer | None:
        """The model (``None`` without a transmit impulse response: no drive)."""
        if self.transmit.impulse_response is None:
            return None
        return virtual_transducer(self.transmit, self.summary,
                                  [str(p) for p in self.inputs], self.receive)

    def figures(self) -> list[tuple[str, list[Figure]]]:
        """The figures of ``report.html`` (section heading, figures), see
        :func:`holoprobe.workflow.report_figures`."""
        return report_figures(self.transmit, self.receive)

    def _repr_html_(self) -> str:
        """The summary as a table of value ± standard uncertainty, with the warnings
        (Jupyter shows it when the run is the last expression of a cell)."""
        kind = "transmit and receive" if self.receive is not None else "transmit"
        name = Path(self.transmit.source).name if self.transmit.source else "scan"
        from holoprobe.report import summary_html  # lazily: the report imports matplotlib

        return summary_html(self.summary, title=f"holoprobe {kind} characterization: {name}")

    def save(self, out_dir: PathLike, *, overwrite: bool = False,
             report: bool = True) -> dict[str, Path]:
        """Write summary.json, virtual_transducer.h5, source_velocity.h5 and report.html
        into ``out_dir`` (atomically; inputs are never overwritten).

        Returns
        -------
        dict of str to Path
            The files written, by kind (see :func:`holoprobe.workflow.write_outputs`).
        """
        return write_outputs(self.transmit, out_dir, inputs=list(self.inputs),
                             overwrite=overwrite, report=report,
                             extra_timings=dict(self.timings), receive=self.receive)


def _input_files(paths: list[Path]) -> tuple[Path, ...]:
    files = list(paths)
    for p in paths:
        if p.is_dir():
            files += [q for q in p.iterdir() if q.is_file()]
    return tuple(files)


def _with_sound_speed(scan: HydrophoneScan, echo: EchoRecording | None,
                      sound_speed: float | str | None, temperature: float | None):
    """The scan and echo with the water's sound speed replaced (density kept)."""
    if sound_speed is not None and temperature is not None:
        raise InputError("give either --sound-speed or --water-temperature, not both",
                         field="--water-temperature")
    if temperature is not None:
        speed = Medium.water(temperature, density=scan.medium.density).sound_speed
    elif sound_speed is None or sound_speed == "from-data":
        return scan, echo
    else:
        speed = float(sound_speed)
        if not 1300.0 <= speed <= 1700.0:
            raise InputError(f"expected a water sound speed in 1300–1700 m/s, got {speed:g}",
                             field="--sound-speed")
    medium = Medium(scan.medium.density, speed)
    scan = dataclasses.replace(scan, medium=medium)
    if echo is not None:
        echo = dataclasses.replace(echo, medium=medium)
    return scan, echo


def characterize(
    scan: HydrophoneScan | PathLike,
    *,
    drive: DriveSignal | PathLike | None = None,
    calibration: HydrophoneCalibration | PathLike | None = None,
    config: CharacterizationConfig | PathLike | None = None,
    echo: EchoRecording | PathLike | None = None,
    reflection_coefficient: float | None = None,
    overrides: Sequence[str] = (),
    progress: bool = False,
    sound_speed: float | str | None = None,
    water_temperature: float | None = None,
) -> CharacterizationRun:
    """Characterize a probe: transmit from a hydrophone scan (paper Fig. 4) and, with
    ``echo``, receive from a flat-reflector echo (paper section III B).

    Every input is an object or a file to read (native HDF5, the toolkit's .mat files
    or a directory holding them; drives also as CSV).

    Parameters
    ----------
    scan : HydrophoneScan or path
        The hydrophone raster scan.
    drive : DriveSignal or path, optional
        Drive voltage (default: the one stored with the scan).
    calibration : HydrophoneCalibration or path, optional
        Hydrophone sensitivity (.csv or sensitivity.mat); default: the scan's.
    config : CharacterizationConfig or path, optional
        The configuration or a TOML file (default: the defaults).
    echo : EchoRecording or path, optional
        The reflector echo for the receive side.
    reflection_coefficient : float, optional
        Rp of the plate, 0 < |Rp| ≤ 1 (default: estimated from the echo train).
    overrides : sequence of str
        Settings ``section.key=value`` applied on top of ``config`` (the CLI's ``--set``).
    progress : bool
        Show progress bars.
    sound_speed : float or "from-data", optional
        Water sound speed in m/s to use instead of the file's; ``"from-data"``: the
        transmit characterization runs once with the file's value, then again with the
        sound speed it estimated from the scan (``medium.sound_speed_from_data``).
    water_temperature : float, optional
        Water temperature in °C: the pure-water sound speed of Marczak (1997)
        (:func:`holoprobe.geometry.water_sound_speed`) instead of the file's.

    Returns
    -------
    CharacterizationRun
        The results; ``.save(dir)`` writes them.
    """
    if reflection_coefficient is not None and not 0 < abs(reflection_coefficient) <= 1:
        raise InputError(f"expected 0 < |Rp| ≤ 1, got {reflection_coefficient:g}",
                         field="--reflection-coefficient")
    t0 = time.perf_counter()
    paths = [Path(p) for p in (scan, drive, calibration, config, echo)
             if isinstance(p, str | os.PathLike)]
    cfg = CharacterizationConfig.resolve(config, overrides)
    ranges = cfg.plausibility  # plausible physical values of what is read from files
    data = (scan if isinstance(scan, HydrophoneScan)
            else read_scan_any(scan, plausibility=ranges))
    if isinstance(calibration, str | os.PathLike):
        calibration = load_calibration(Path(calibration), plausibility=ranges)
    if isinstance(drive, str | os.PathLike):
        drive = check_measurement(read_drive(drive), ranges, file=str(drive))
    echo_path = None
    recording: EchoRecording | None
    if isinstance(echo, str | os.PathLike):
        echo_path = Path(echo)
        if not echo_path.exists():
            raise InputError("no such file or directory", file=str(echo_path),
                             field="--receive")
        recording = read_echo_any(echo_path, plausibility=ranges)
    else:
        recording = echo
    t_read = time.perf_counter() - t0
    inputs = _input_files(paths)
    with Threads(1, name="holoprobe-sha256") as threads:
        # the provenance's digests (file_sha256 keeps them for save) on the core the
        # estimation leaves idle: reading and hashing release the GIL
        threads.submit(warm_sha256, inputs)
        transmit, receive = _estimate(
            data, recording, cfg, drive=drive, calibration=calibration,
            sound_speed=sound_speed, water_temperature=water_temperature,
            reflection_coefficient=reflection_coefficient, progress=progress,
            echo_path=echo_path)
    return CharacterizationRun(transmit, receive, inputs, {"read": t_read})

def _estimate(data: HydrophoneScan, recording: EchoRecording | None,
              cfg: CharacterizationConfig, *, drive: DriveSignal | None,
              calibration: HydrophoneCalibration | None, sound_speed: float | str | None,
              water_temperature: float | None, reflection_coefficient: float | None,
              progress: bool, echo_path: Path | None
              ) -> tuple[TransmitResult, ReceiveResult | None]:
    """The estimation of :func:`characterize` on what it read: the transmit (twice for
    ``sound_speed="from-data"``) and, with a recording, the receive."""
    data, recording = _with_sound_speed(data, recording, sound_speed, water_temperature)
    first_cfg = cfg  # "from-data": the first pass estimates c0 (elements.fit_sound_speed)
    if sound_speed == "from-data":
        first_cfg = cfg.with_overrides(["elements.fit_sound_speed=true"])
        cfg = cfg.with_overrides(["elements.fit_sound_speed=false"])  # known by then
    transmit = characterize_transmit(data, first_cfg, drive=drive, calibration=calibration,
                                     progress=progress)
    if sound_speed == "from-data":
        c_data = transmit.extras.get("sound_speed_from_data", float("nan"))
        if not np.isfinite(c_data):
            raise InputError("the scan does not allow a sound-speed estimate (no element "
                             "map: a single element or elements.enabled = false; or no "
                             "frequency bin whose steep waves the scan step samples)",
                             field="--sound-speed")
        data, recording = _with_sound_speed(data, recording, float(c_data), None)
        first = transmit
        transmit = characterize_transmit(data, cfg, drive=drive, calibration=calibration,
                                         progress=progress)
        extras = dict(transmit.extras)
        extras["sound_speed_from_data"] = first.extras["sound_speed_from_data"]
        extras["sound_speed_from_data_uncertainty"] = first.extras[
            "sound_speed_from_data_uncertainty"]
        transmit = with_sound_speed_uncertainty(  # the data's c0: its own σ
            dataclasses.replace(transmit, extras=extras), sound_speed_uncertainty(
                float(c_data), float(c_data), extras["sound_speed_from_data_uncertainty"]))
    receive = None
    probe = data.probe if data.probe is not None else getattr(recording, "probe", None)
    matrix = isinstance(getattr(transmit, "element_map", None), MatrixElementMap) or (
        probe is not None and probe.array is not None and probe.array.kind == "matrix")
    if recording is not None:
        # a dead edge element: the dead RF channels say which end it is, before the
        # receive step projects the scan onto the elements at the transmit pose
        if not matrix:
            transmit = resolve_edge_ambiguity(transmit, channel_levels(recording.rf),
                                              cfg.elements.receive_dead_threshold)
        try:
            receive = (characterize_matrix_receive(
                recording, MatrixFace.from_transmit(transmit), data, cfg,
                reflection_coefficient=reflection_coefficient, calibration=calibration,
                progress=progress) if matrix else characterize_receive(
                recording, transmit, data, cfg, reflection_coefficient=reflection_coefficient,
                calibration=calibration, progress=progress))
        except (InputError, FitError) as exc:
            if echo_path is None:
                raise
            raise type(exc)(f"receive: {exc.detail}", file=str(echo_path),
                            field=exc.field) from None
    if receive is not None and receive.sensitivity is not None and not matrix:
        transmit = resolve_edge_ambiguity(transmit, receive.sensitivity.amplitude,
                                          cfg.elements.dead_threshold)
    return transmit, receive
