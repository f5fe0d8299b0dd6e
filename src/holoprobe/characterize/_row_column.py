"""Row-column arrays (issue 16 stretch): one set of strips seen as a flat 1-D array.

A row-column array (:meth:`holoprobe.geometry.ArrayGeometry.row_column`) transmits with
its ``n_x`` columns (strips along y, placed along x) or its ``n_y`` rows (strips along
x, placed along y). Either set is a flat 1-D array of long elements: the columns are one
along x, the rows one along y. The transmit pipeline's 1-D model (elements along x,
their height along y, no lens) takes the columns as they are and the rows after the
scan is turned by 90° about z: the scan point (u, v) becomes (u', v') = (v, −u), which
puts the rows along x'. The pose found in that frame, ``p = R' (u', v', 0) + r'``, is
turned back into the probe's frame by ``Q = Rz(90°)``: ``R = Q R' Qᵀ``, ``r = Q r'``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import ArrayGeometry, PlaneGrid, Pose
from holoprobe.measurement import HydrophoneScan, ProbeInfo

if TYPE_CHECKING:
    from holoprobe.characterize._matrix_receive import MatrixFace
    from holoprobe.characterize._pipeline import TransmitResult

__all__ = ["ROW_COLUMN_SETS", "RowColumnView", "row_column_face", "row_column_view"]

ROW_COLUMN_SETS = ("columns", "rows")
"""The two sets of strips of a row-column array, in element order."""

_QUARTER = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # Rz(90°)


@dataclass(frozen=True)
class RowColumnView:
    """Which set of a row-column array transmitted, and how its 1-D frame sits.

    Attributes
    ----------
    array : ArrayGeometry
        The whole array (kind ``"row-column"``).
    transmit : {"columns", "rows"}
        The set that transmitted.
    """

    array: ArrayGeometry
    transmit: str

    @property
    def elements(self) -> NDArray[np.int64]:
        """Indices (in the array's numbering) of the transmitting set, in order."""
        return np.flatnonzero(self.array.strip_set == ROW_COLUMN_SETS.index(self.transmit))

    @property
    def rotation(self) -> NDArray[np.float64]:
        """``Q``: the 1-D frame's axes in the probe's frame (identity for the columns,
        Rz(90°) for the rows)."""
        return _QUARTER.copy() if self.transmit == "rows" else np.eye(3)

    def probe_pose(self, pose: Pose) -> Pose:
        """The scan plane's pose in the probe's frame from the one in the 1-D frame (the
        in-plane axes stay the scan's own: (u, v), not (u', v'))."""
        q = self.rotation
        return Pose.from_matrix(q @ pose.rotation @ q.T, q @ pose.origin_array)

    def probe(self, center_frequency: float, name: str = "") -> ProbeInfo:
        """The transmitting set as a flat 1-D :class:`ProbeInfo` (count, pitch, strip
        width, strip length as the element height, no lens)."""
        idx = self.elements
        axis = ROW_COLUMN_SETS.index(self.transmit)
        assert self.array.pitch is not None
        return ProbeInfo(idx.size, self.array.pitch[axis], float(np.median(self.array.widths[idx])),
                         float(np.median(self.array.heights[idx])), center_frequency,
                         float("inf"), name)


def row_column_view(scan: HydrophoneScan, transmit: str
                    ) -> tuple[HydrophoneScan, RowColumnView]:
    """The scan of one set of a row-column array as the scan of a flat 1-D array.

    Parameters
    ----------
    scan : HydrophoneScan
        Its ``probe.array`` is a row-column array.
    transmit : {"columns", "rows"}
        The set that transmitted.

    Returns
    -------
    view_scan : HydrophoneScan
        Columns: the scan with a 1-D probe; rows: also its grid turned by 90° about z
        (``x' = y``, ``y' = −x``, the data re-ordered to match, a copy; the grid's
        nominal pose expressed in the view frame).
    view : RowColumnView
        Maps the results back (:meth:`RowColumnView.probe_pose`, ``elements``).
    """
    probe = scan.probe
    if probe is None or probe.array is None or probe.array.kind != "row-column":
        raise InputError("the scan's probe description is not a row-column array",
                         file=scan.source or None, field="probe.array")
    if transmit not in ROW_COLUMN_SETS:
        raise InputError(f"expected one of {ROW_COLUMN_SETS}, got {transmit!r}",
                         field="transmit")
    view = RowColumnView(probe.array, transmit)
    one_d = view.probe(probe.center_frequency, probe.name)
    if transmit == "columns":
        return dataclasses.replace(scan, probe=one_d), view
    g = scan.grid
    # nominal pose p = R (u, v, 0) + r in the probe frame; (u, v) = Q (u', v'), and the
    # view frame is Qᵀ of the probe's: R' = Qᵀ R Q, r' = Qᵀ r
    q = view.rotation
    pose = Pose.from_matrix(q.T @ g.pose.rotation @ q, q.T @ g.pose.origin_array)
    grid = PlaneGrid(np.asarray(g.y), -np.asarray(g.x)[::-1], pose)
    data = np.ascontiguousarray(np.asarray(scan.data)[::-1].transpose(1, 0, 2))
    return dataclasses.replace(scan, data=data, grid=grid, probe=one_d), view


def row_column_face(result: TransmitResult, view: RowColumnView) -> MatrixFace:
    """The receive step's face of a row-column array from the transmit characterization
    of one set (its 1-D view, :func:`row_column_view`): the whole array (every strip
    receives), the scan pose in the probe's frame, the band.

    The 1-D pose's z0 is the onset convention's (the transmit IR starts at t = 0); the
    face lies where the element map's defocus δ puts it, as for a matrix
    (:func:`~holoprobe.characterize.matrix_face_offset`: δ plus the last pose update's
    z step), so the scan pose is moved back by that along z (the view's turn is about z).
    The steering the strips' delays may hide (:func:`steering_uncertainty` along the
    set's axis) is the face's ``steering`` about the other axis: the columns steer about
    y, the rows about x. δ of a 1-D map carries no σ and is not corrected for the scan
    window (``face_uncertainty`` 0, ``window_corrected`` False: the receive says so; on
    the 12 + 12 test twin the face came 26 µm off for the rows, 1.6 µm for the columns).
    """
    from holoprobe.characterize._elements import ElementMap, steering_uncertainty
    from holoprobe.characterize._matrix_receive import MatrixFace

    emap = result.element_map
    if not isinstance(emap, ElementMap):
        raise InputError("the transmit characterization has no element map "
                         "(elements.enabled = false)", field="element_map")
    last = float(result.history[-1]["update"][2]) if result.history else 0.0
    x0, y0, z0 = result.pose.origin
    pose = view.probe_pose(dataclasses.replace(
        result.pose, origin=(x0, y0, z0 - float(emap.focus_offset) - last)))
    axis = ROW_COLUMN_SETS.index(view.transmit)
    live = np.ones(view.elements.size, bool)
    live[list(emap.dead)] = False
    pos = view.array.positions[view.elements, axis]
    sigma = (steering_uncertainty(emap.delay[live], pos[live], result.medium.sound_speed)
             if live.sum() >= 3 else 0.0)
    steering = (0.0, float(sigma)) if axis == 0 else (float(sigma), 0.0)
    f = np.asarray(result.frequencies, dtype=float)
    return MatrixFace(view.array, pose, (float(f.min()), float(f.max())), math.inf,
                      window_corrected=False, steering=steering)
