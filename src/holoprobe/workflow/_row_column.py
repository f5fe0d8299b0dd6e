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
    RowColumnView,
    TransmitResult,
    row_column_view,
)
from holoprobe.errors import InputError
from holoprobe.io import read_scan_any
from holoprobe.measurement import HydrophoneScan

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
        Of :func:`holoprobe.workflow.characterize` (``echo`` is refused: the receive of
        a row-column array is not implemented).

    Returns
    -------
    CharacterizationRun
        The 1-D characterization of the set (angles, element map, IRs and the virtual
        transducer — a flat 1-D array — in the set's own frame: elements along x'; for
        the rows x' = y, y' = −x of the probe); its summary adds
        ``row_column`` (:func:`row_column_summary`: the set, its element numbers in the
        whole array, the scan plane's pose in the probe's frame).
    """
    from holoprobe.workflow._run import characterize

    if options.get("echo") is not None:
        raise InputError("the receive of a row-column array is not implemented",
                         field="--receive")
    source = None if isinstance(scan, HydrophoneScan) else Path(scan)
    if isinstance(scan, HydrophoneScan):
        data = scan
    else:
        cfg = CharacterizationConfig.resolve(options.get("config"),
                                             options.get("overrides", ()))
        data = read_scan_any(scan, plausibility=cfg.plausibility)
    view_scan, view = row_column_view(data, transmit)
    run = characterize(view_scan, **options)
    tx = run.transmit
    extras = {**tx.extras, "row_column_view": view}
    return dataclasses.replace(run, transmit=dataclasses.replace(tx, extras=extras),
                               inputs=(*(() if source is None else (source,)), *run.inputs))


def row_column_summary(result: TransmitResult) -> dict[str, Any] | None:
    """The ``row_column`` summary section, None for another array: ``transmit``
    (columns | rows), ``elements`` (the set's numbers in the whole array, the order of
    every per-element list), ``element_count`` of the whole array, ``strip_length``
    (m) and ``scan_plane`` in the probe's frame (``theta_*_deg``, ``x0``, ``y0``,
    ``z0``; the top-level ``scan_plane`` is in the set's 1-D frame)."""
    view = result.extras.get("row_column_view")
    if not isinstance(view, RowColumnView):
        return None
    pose = view.probe_pose(result.pose)
    tx, ty, tz = pose.angles_deg
    x0, y0, z0 = pose.origin
    idx = view.elements
    return {"transmit": view.transmit, "elements": [int(i) for i in idx],
            "element_count": int(view.array.count),
            "strip_length": float(np.median(view.array.heights[idx])),
            "scan_plane": {"theta_x_deg": tx, "theta_y_deg": ty, "theta_z_deg": tz,
                           "x0": x0, "y0": y0, "z0": z0}}


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

