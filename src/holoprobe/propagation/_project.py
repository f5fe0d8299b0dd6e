"""Projection of a field measured on a plane onto any plane or surface: the one-call form.

:func:`project` dispatches to the fast path (:class:`holoprobe.propagation.ProjectionPlan`,
non-uniform FFTs of the padded angular spectrum; see its module for the padding
rule), the dense Rayleigh oracle, or the angular spectrum between parallel planes.
Use a :class:`~holoprobe.propagation.ProjectionPlan` to project the same data onto
several targets without transforming it again.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Surface
from holoprobe.propagation._plan import (
    ProjectionPlan,
    Quantity,
    _check_sampling,
    _direction,
    _target_local,
    _validate_field,
    padded_shape,
)

__all__ = ["padded_shape", "project"]

Method = Literal["auto", "nufft", "rayleigh", "angular_spectrum"]


def _project_nufft(field: NDArray, source: PlaneGrid, target: PlaneGrid | Surface,
                   freqs: NDArray, medium: Medium, *, quantity: Quantity, eps: float,
                   shape: tuple[int, int], time_origin: float, max_memory: int,
                   single_precision: bool, progress: bool | None) -> NDArray[np.complex128]:
    plan = ProjectionPlan(field, source, freqs, medium, eps=eps, padding=shape,
                          allow_undersampled=True, single_precision=single_precision,
                          max_memory=max_memory, cache=False)
    return plan.project(target, quantity=quantity, time_origin=time_origin, progress=progress)


def _project_parallel(field: NDArray, source: PlaneGrid, target: PlaneGrid | Surface,
                      freqs: NDArray, medium: Medium, *, quantity: Quantity,
                      shape: tuple[int, int], time_origin: float,
                      max_memory: int) -> NDArray[np.complex128]:
    """Angular spectrum with averaged propagators onto a parallel, commensurate plane."""
    from holoprobe.propagation._angular_spectrum import propagate_parallel

    why = ("method='angular_spectrum' needs a PlaneGrid target parallel to the source, with "
           "the same steps and its points on the source grid's lattice inside its extent; "
           "use method='nufft'")
    if not isinstance(target, PlaneGrid) or not np.allclose(
            target.pose.rotation, source.pose.rotation, atol=1e-12):
        raise InputError(why, field="target")
    local = _target_local(source, target)
    distance = float(local[0, 2])
    first = local[0, :2]
    steps = np.array([source.dx, source.dy])
    offset = (first - np.array([source.x[0], source.y[0]])) / steps
    same_steps = (target.x.size < 2 or np.isclose(target.dx, source.dx)) and (
        target.y.size < 2 or np.isclose(target.dy, source.dy))
    if not same_steps or not np.allclose(offset, np.round(offset), atol=1e-6):
        raise InputError(why, field="target")
    i0, j0 = (int(v) for v in np.round(offset))
    i1, j1 = i0 + target.x.size, j0 + target.y.size
    if i0 < 0 or j0 < 0 or i1 > source.x.size or j1 > source.y.size:
        raise InputError(why, field="target")
    kind = "pv" if quantity == "normal_velocity" else "pp"
    # backward: point-sampled propagators invert the forward ones exactly, evanescent
    # parts must be filtered; forward: evanescent parts decay by themselves and the
    # ring-averaged propagators reduce the bias of sampling near |κ| = k
    backward = distance < 0
    result = propagate_parallel(field, source, freqs, medium, distance, kind=kind,
                                averaged=not backward, evanescent="hard" if backward else None,
                                padding=shape, max_chunk_bytes=max_memory)
    result = result[i0:i1, j0:j1, :]
    if time_origin:
        result = result * np.exp(-1j * medium.wavenumber(freqs) * time_origin)
    return np.asarray(result, dtype=np.complex128)


def _project_rayleigh(field: NDArray, source: PlaneGrid, target: PlaneGrid | Surface,
                      freqs: NDArray, medium: Medium, *, quantity: Quantity,
                      direction: str, time_origin: float, max_memory: int,
                      dtype: type) -> NDArray[np.complexfloating]:
    from holoprobe.propagation._rayleigh import rayleigh_integral

    target_surface = target.to_surface() if isinstance(target, PlaneGrid) else target
    values = field.reshape(source.size, freqs.size)
    if direction == "backward":
        # paper eqs. rayleigh-bwd-pp / -pv: n2 (data plane) points back towards the source
        data = source.to_surface(flip_normal=True)
        kernel = "bwd_pv" if quantity == "normal_velocity" else "bwd_pp"
    else:
        if quantity == "normal_velocity":
            raise InputError(
                "the Rayleigh method gives the normal velocity only for backward projection "
                "(paper eq. rayleigh-bwd-pv); use method='nufft'",
                field="quantity",
            )
        data = source.to_surface()
        kernel = "fwd_pp"
    result = rayleigh_integral(values, data, target_surface, freqs, medium, kernel=kernel,
                               time_origin=time_origin, dtype=dtype, max_memory=max_memory)
    if isinstance(target, PlaneGrid):
        return result.reshape(*target.shape, freqs.size)
    return result


def project(
    field: ArrayLike,
    source: PlaneGrid,
    target: PlaneGrid | Surface,
    frequencies: ArrayLike,
    medium: Medium | None = None,
    *,
    quantity: Quantity = "pressure",
    method: Method = "auto",
    eps: float = 1e-6,
    guard_angle: float = np.deg2rad(80.0),
    padding: float | tuple[int, int] | None = None,
    time_origin: float = 0.0,
    allow_undersampled: bool = False,
    max_memory: int = 1 << 30,
    rayleigh_dtype: type = np.float64,
    single_precision: bool = False,
    progress: bool | None = False,
) -> NDArray[np.complexfloating]:
    """Project the pressure measured on a plane onto another plane or a surface.

    Parameters
    ----------
    field : array_like, complex, shape (nx, ny, nf)
        Pressure (Pa·s, holoprobe's Fourier convention) on the source plane at the
        given frequencies. The waves must travel along the source plane's normal
        ``source.pose.normal`` (away from the transducer for a scan plane).
    source : PlaneGrid
        The measurement plane (uniform grid, any pose).
    target : PlaneGrid or Surface
        Where the field is wanted. The target must lie entirely on one side of the
        source plane: behind it (backward projection, e.g. onto the transducer
        surface z = 0) or in front of it (forward projection, e.g. onto a virtual
        sensor); the direction follows from the geometry.
    frequencies : array_like, shape (nf,)
        Frequencies in Hz (positive).
    medium : Medium, optional
        Propagation medium (default water at 20 °C).
    quantity : {"pressure", "normal_velocity"}
        What to return on the target. The normal velocity (m/s·s) is along the target
        plane's normal ``target.pose.normal`` or the surface's ``normals``.
    method : {"auto", "nufft", "rayleigh", "angular_spectrum"}
        ``nufft`` (the fast path; ``auto`` picks it), ``rayleigh`` (the dense exact
        oracle, paper eqs. rayleigh-fwd-pp, rayleigh-bwd-pp, rayleigh-bwd-pv) or
        ``angular_spectrum`` (parallel planes on a commensurate grid only).
    eps : float
        Relative tolerance of the non-uniform FFTs.
    guard_angle : float
        Padding rule parameter in rad (see :mod:`holoprobe.propagation._plan`).
    padding : float or (int, int), optional
        Override the automatic padding (a factor or an explicit shape).
    time_origin : float
        Distance r0 in m: results are multiplied by ``exp(−i k r0)`` so that the time
        origin of the output is r0/c0 (keeps forward-projected records short).
    allow_undersampled : bool
        Allow a scan step coarser than λ/2 at the highest frequency.
    max_memory : int
        Bytes allowed for temporaries.
    rayleigh_dtype : numpy dtype
        Real precision of the Rayleigh method (``np.float32`` or ``np.float64``).
    single_precision : bool
        ``nufft`` only: run the non-uniform FFTs in complex64 (about twice as fast;
        relative accuracy floors near 1e-5).
    progress : bool or None
        Show a progress bar (``None``: on a terminal).

    Returns
    -------
    ndarray, complex128 (complex64 with method="rayleigh" and rayleigh_dtype=np.float32)
        Shape (nx_t, ny_t, nf) for a PlaneGrid target, (n, nf) for a Surface.

    Notes
    -----
    Evanescent components of the data are excluded by ``nufft`` and
    ``angular_spectrum``; the backward Rayleigh kernels attenuate them. For data
    that hold no evanescent energy and are captured by the scan, all methods agree.
    """
    medium = Medium() if medium is None else medium
    arr, freqs = _validate_field(field, source, frequencies)
    if not isinstance(target, PlaneGrid | Surface):
        raise InputError("expected a holoprobe.PlaneGrid or holoprobe.Surface", field="target")
    if quantity not in ("pressure", "normal_velocity"):
        raise InputError("expected 'pressure' or 'normal_velocity'", field="quantity")
    if method not in ("auto", "nufft", "rayleigh", "angular_spectrum"):
        raise InputError("expected 'auto', 'nufft', 'rayleigh' or 'angular_spectrum'",
                         field="method")
    if not 1e-15 < eps < 1e-1:
        raise InputError("expected a tolerance between 1e-15 and 0.1", field="eps")
    _check_sampling(source, freqs, medium, allow_undersampled)
    local = _target_local(source, target)
    direction = _direction(local)
    if method == "rayleigh":
        if direction == "on_plane":
            raise InputError("the Rayleigh kernels are singular for a target on the source "
                             "plane; use method='nufft'", field="target")
        return _project_rayleigh(arr, source, target, freqs, medium, quantity=quantity,
                                 direction=direction, time_origin=time_origin,
                                 max_memory=max_memory, dtype=rayleigh_dtype)
    shape = padded_shape(source, target, guard_angle=guard_angle, padding=padding)
    if method == "angular_spectrum":
        return _project_parallel(arr, source, target, freqs, medium, quantity=quantity,
                                 shape=shape, time_origin=time_origin, max_memory=max_memory)
    return _project_nufft(arr, source, target, freqs, medium, quantity=quantity, eps=eps,
                          shape=shape, time_origin=time_origin, max_memory=max_memory,
                          single_precision=single_precision, progress=progress)
