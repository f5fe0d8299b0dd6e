"""Row-column arrays in the workflow (issue 16 stretch): the transmitting set of strips
characterized as a flat 1-D array (:func:`holoprobe.characterize.row_column_view`), the
pose turned back into the probe's frame, the strips' map on a picture of the array."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from holoprobe.characterize import (
    CharacterizationConfig,
    ReceiveResult,
    RowColumnView,
    TransmitResult,
    characterize_matrix_receive,
    row_column_face,
    row_column_view,
)
from holoprobe.errors import FitError, InputError
from holoprobe.io import read_echo_any, read_scan_any
from holoprobe.measurement import EchoRecording, HydrophoneCalibration, HydrophoneScan
from holoprobe.signal import load_calibration

if TYPE_CHECKING:
    from holoprobe.workflow._run import CharacterizationRun

__all__ = ["characterize_row_column", "row_column_section", "row_column_summary"]


def characterize_row_column(scan: HydrophoneScan | str | os.PathLike, transmit: str,
                            **options: Any) -> CharacterizationRun:
    """Characterize the transmit side of one set of strips of a row-column array.

    Parameters
    ----------
    scan : HydrophoneScan or path
        A scan whose ``probe.array`` is a row-column array
        (:meth:`holoprobe.geometry.ArrayGeometry.row_column`).
    transmit : {"columns", "rows"}
        The set that transmitted during the scan.
    **options
        Of :func:`holoprobe.workflow.characterize`. With ``echo`` (an
        :class:`EchoRecording` or a file with one channel per strip of the whole array,
        columns then rows) the receive follows: every strip receives the echo of the
        plate (:func:`holoprobe.characterize.characterize_matrix_receive` on
        :func:`holoprobe.characterize.row_column_face`, in the probe's frame: d, θx',
        θy', the receive IR and a gain per strip).

    Returns
    -------
    CharacterizationRun
        The 1-D characterization of the set (angles, element map, IRs and the virtual
        transducer — a flat 1-D array — in the set's own frame: elements along x'; for
        the rows x' = y, y' = −x of the probe); its summary adds
        ``row_column`` (:func:`row_column_summary`: the set, its element numbers in the
        whole array, the scan plane's pose in the probe's frame; with a receive the
        strips' receive gains).
    """
    from holoprobe.workflow._run import characterize

    echo = options.pop("echo", None)
    source = None if isinstance(scan, HydrophoneScan) else Path(scan)
    cfg = CharacterizationConfig.resolve(options.get("config"), options.get("overrides", ()))
    if isinstance(scan, HydrophoneScan):
        data = scan
    else:
        data = read_scan_any(scan, plausibility=cfg.plausibility)
    echo_path = None if echo is None or isinstance(echo, EchoRecording) else Path(echo)
    if echo_path is not None:
        if not echo_path.exists():
            raise InputError("no such file or directory", file=str(echo_path),
                             field="--receive")
        echo = read_echo_any(echo_path, plausibility=cfg.plausibility)
    view_scan, view = row_column_view(data, transmit)
    run = characterize(view_scan, **options)
    tx = run.transmit
    extras = {**tx.extras, "row_column_view": view}
    tx = dataclasses.replace(tx, extras=extras)
    receive = None
    if echo is not None:
        # the transmit may have fixed c0 (--sound-speed, from-data): the scan it used
        medium = tx.medium
        try:
            receive = characterize_matrix_receive(
                dataclasses.replace(echo, medium=medium), row_column_face(tx, view),
                dataclasses.replace(data, medium=medium), cfg,
                reflection_coefficient=options.get("reflection_coefficient"),
                calibration=run_calibration(options.get("calibration"), cfg),
                progress=options.get("progress"))
        except (InputError, FitError) as exc:
            if echo_path is None:
                raise
            raise type(exc)(f"receive: {exc.detail}", file=str(echo_path),
                            field=exc.field) from None
    inputs = (*(() if source is None else (source,)), *run.inputs,
              *(() if echo_path is None else (echo_path,)))
    return dataclasses.replace(run, transmit=tx, receive=receive, inputs=inputs)


def run_calibration(calibration: Any, config: CharacterizationConfig
                    ) -> HydrophoneCalibration | None:
    """The hydrophone calibration of ``characterize``'s ``calibration`` option (a
    :class:`HydrophoneCalibration`, a file, or None)."""
    if calibration is None or isinstance(calibration, HydrophoneCalibration):
        return calibration
    return load_calibration(Path(calibration), plausibility=config.plausibility)


def row_column_summary(result: TransmitResult, receive: ReceiveResult | None = None
                       ) -> dict[str, Any] | None:
    """The ``row_column`` summary section, None for another array: ``transmit``
    (columns | rows), ``elements`` (the set's numbers in the whole array, the order of
    every per-element list), ``element_count`` of the whole array, ``strip_length``
    (m) and ``scan_plane`` in the probe's frame (``theta_*_deg``, ``x0``, ``y0``,
    ``z0``; the top-level ``scan_plane`` is in the set's 1-D frame). With a receive:
    ``receive_gain`` and ``receive_gain_uncertainty``, one per strip of the whole array
    (columns then rows; the top-level ``receive`` section's pose is in the probe's
    frame)."""
    view = result.extras.get("row_column_view")
    if not isinstance(view, RowColumnView):
        return None
    pose = view.probe_pose(result.pose)
    tx, ty, tz = pose.angles_deg
    x0, y0, z0 = pose.origin
    idx = view.elements
    out: dict[str, Any] = {
        "transmit": view.transmit, "elements": [int(i) for i in idx],
        "element_count": int(view.array.count),
        "strip_length": float(np.median(view.array.heights[idx])),
        "scan_plane": {"theta_x_deg": tx, "theta_y_deg": ty, "theta_z_deg": tz,
                       "x0": x0, "y0": y0, "z0": z0}}
    sens = None if receive is None else receive.sensitivity
    if sens is not None and sens.amplitude.size == view.array.count:
        out["receive_gain"] = [float(v) for v in sens.amplitude]
        u = sens.amplitude_uncertainty
        out["receive_gain_uncertainty"] = None if u is None else [float(v) for v in u]
    return out


def row_column_section(result: TransmitResult) -> list[tuple[str, list]]:
    """The array's strips drawn in the probe's frame, the transmitting set coloured by
    its relative amplitudes (the other set grey, dead strips crossed); [] for another
    array or without an element map."""
    from holoprobe import report as rp

    view = result.extras.get("row_column_view")
    m = result.element_map
    if not isinstance(view, RowColumnView) or m is None:
        return []
    a = view.array
    values = np.full(a.count, np.nan)
    values[view.elements] = m.relative_amplitude
    along_x = np.abs(a.width_directions[:, 0]) > np.abs(a.width_directions[:, 1])
    fig = rp.plot_array_geometry(a.positions, a.normals, values,
                                 widths=np.where(along_x, a.widths, a.heights),
                                 heights=np.where(along_x, a.heights, a.widths),
                                 dead=[int(view.elements[i]) for i in m.dead],
                                 label=f"relative transmit amplitude of the {view.transmit} (1)")
    return [("Row-column array (the transmitting strips)", [fig])]

