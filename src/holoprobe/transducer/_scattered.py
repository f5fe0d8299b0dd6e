"""Fields at scattered points: the plane-wave (NUFFT) path and when ``method="auto"`` takes it.

Element superposition (:func:`holoprobe.transducer.element_field`) and its lattice
(:func:`holoprobe.transducer.element_plan`) reuse work between targets that share
(y, z); a target with its own (y, z) sees every element from its own offset and costs
N_el × (element sub-samples) kernel terms per frequency (≈ 8.5 ms CPU per point on the
P4-1 model). :func:`holoprobe.propagation.rayleigh_plane_waves` evaluates the same
Rayleigh sum through plane waves: a cost per frequency set by the extent of sources and
targets (k·D)² plus a constant per target, so it wins for many scattered points.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import DTypeLike, NDArray

from holoprobe.propagation import plane_wave_cost, rayleigh_plane_waves
from holoprobe.transducer._lattice import unique_pairs
from holoprobe.transducer._model import VirtualTransducer
from holoprobe.transducer._transmit import TransmitSetting

__all__ = ["plane_wave_field", "plane_wave_targets"]

#: targets sharing (y, z) with at least this many others are left to the lattice
LINE_MIN = 32
#: CPU seconds per element kernel term, per plane-wave node and per target term
#: (measured on the 2-core machine: 1.3 ns, ≈ 3 µs and ≈ 0.3 µs)
_T_KERNEL, _T_NODE, _T_TERM = 1.3e-9, 3e-6, 3e-7


def plane_wave_field(vt: VirtualTransducer, setting: TransmitSetting, points: NDArray,
                     frequencies: NDArray, *, points_per_wavelength: float = 4.0,
                     eps: float = 1e-5, dtype: DTypeLike = np.complex128,
                     progress: Callable[[int, int], None] | None = None
                     ) -> NDArray[np.complexfloating]:
    """Pressure spectrum at ``points`` by plane waves from the model's surface velocity.

    The source is :func:`holoprobe.transducer.surface_velocity` (the same sub-element
    point sources as ``method="rayleigh"`` and ``"element"``), propagated by
    :func:`holoprobe.propagation.rayleigh_plane_waves`; the two agree to about ``eps``
    of the largest pressure.

    Parameters
    ----------
    vt, setting : VirtualTransducer, TransmitSetting
        A flat model (``vt.is_curved`` False) and the transmit.
    points : ndarray, shape (n, 3)
        Targets in m, z > 0.
    frequencies : ndarray, shape (nf,)
        Hz.
    points_per_wavelength : float
        Source sub-sampling (as :func:`holoprobe.transducer.surface_velocity`).
    eps : float
        NUFFT tolerance.
    dtype : {numpy.complex128, numpy.complex64}
        Output precision.
    progress : callable(done, total), optional
        Called after each frequency.

    Returns
    -------
    ndarray, complex, shape (n, nf)
        Pressure spectrum in Pa·s.
    """
    from holoprobe.transducer._field import surface_velocity

    surface, velocity = surface_velocity(vt, setting, frequencies,
                                         points_per_wavelength=points_per_wavelength)
    return rayleigh_plane_waves(velocity, surface.points, surface.weights, points,
                                frequencies, vt.medium, eps=eps, dtype=dtype,
                                progress=progress)


def plane_wave_targets(vt: VirtualTransducer, points: NDArray, n_active: int,
                       frequencies: NDArray, element_samples: int,
                       tolerance: float = 1e-9) -> NDArray[np.bool_]:
    """Targets that ``method="auto"`` sends to the plane-wave path (mask, shape (n,)).

    Targets on lines along x (at least :data:`LINE_MIN` sharing (y, z)) stay with the
    element lattice. The others go to plane waves when its estimated work (nodes and
    target terms of :func:`holoprobe.propagation.plane_wave_cost`) costs less than
    their element superposition (``n × n_active × element_samples`` kernel terms per
    frequency); never for a curved model or targets at z ≤ 0.
    """
    none = np.zeros(points.shape[0], dtype=bool)
    if vt.is_curved or points.shape[0] < LINE_MIN or np.any(points[:, 2] <= 0):
        return none
    lone = lone_targets(points, tolerance)
    n_lone = int(lone.sum())
    if n_lone < LINE_MIN:
        return none
    element = n_lone * n_active * element_samples * frequencies.size * _T_KERNEL
    x_lo, x_hi, y_lo, y_hi = vt.face_extent()
    corners = np.array([[x_lo, y_lo, 0.0], [x_hi, y_hi, 0.0]])
    nodes, terms = plane_wave_cost(corners, points[lone], frequencies, vt.medium)
    return lone if nodes * _T_NODE + terms * _T_TERM < element else none


def lone_targets(points: NDArray, tolerance: float = 1e-9) -> NDArray[np.bool_]:
    """Targets that share (y, z) (to ``tolerance``, m) with fewer than :data:`LINE_MIN`
    others: not on a line along x that the element lattice serves (mask, shape (n,))."""
    yz = np.rint(points[:, 1:3] / tolerance).astype(np.int64)
    _, inverse, counts = unique_pairs(yz)
    return counts[inverse] < LINE_MIN


def scattered_routes(vt: VirtualTransducer, points: NDArray, elements: NDArray,
                     frequencies: NDArray, element_samples: tuple[int, int],
                     tolerance: float = 1e-9) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Which targets ``method="auto"`` sends to the column table and to plane waves.

    Targets off the lines along x (:func:`lone_targets`) of a flat 1-D model, at least
    3 λ_min in front of the face, go to the column table
    (:func:`holoprobe.transducer._tables.table_spectra`) when building it costs less
    than their element superposition (table entries × ny against n × n_active × nx × ny
    kernel terms; ``element_samples`` = (nx, ny); free within
    :func:`holoprobe.transducer.shared_table`). Of the rest,
    :func:`plane_wave_targets` picks those for plane waves.

    Returns
    -------
    table, waves : ndarray of bool, shape (n,)
    """
    from holoprobe.transducer._tables import is_shared, table_bytes, table_targets

    f_max = float(np.max(frequencies))
    table = table_targets(vt, points, f_max)
    if table.any():
        table &= lone_targets(points, tolerance)
    if is_shared(vt, frequencies):  # a table built for the whole job: free here
        pass
    elif table.sum() >= LINE_MIN:
        entries = table_bytes(vt, points[table], elements, f_max, itemsize=1)
        if entries >= table.sum() * elements.size * element_samples[0]:
            table[:] = False
    else:
        table[:] = False
    rest = ~table
    waves = np.zeros(points.shape[0], dtype=bool)
    if rest.any():
        waves[rest] = plane_wave_targets(vt, points[rest], elements.size, frequencies,
                                         element_samples[0] * element_samples[1], tolerance)
    return table, waves
