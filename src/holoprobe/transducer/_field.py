"""Field prediction: surface velocity of the virtual transducer and the pressure it radiates.

The normal surface velocity of the virtual transducer for a transmit setting is
(paper eqs. transmit-impulse-response and lens-delays)::

    U(x, y; ω) = a_i · H_T(ω) · E_T(ω) / (ρ0 c0) · e^{iω (τ_i + τ_L(y − y_c))}

on element i (x within its width w, |y − y_c| ≤ H/2), zero in the kerfs, with a_i
and τ_i the apodization and delay of element i, τ_L the exact lens delays, and
H_T, E_T the continuous Fourier transforms (holoprobe's conjugate convention,
paper eq. complex-conjugate-fourier: a delay τ is the factor e^{+iωτ}) of the
transmit impulse response (Pa/(V·s)) and the drive (V). The pressure follows by
the forward Rayleigh integral (paper eq. rayleigh-fwd-vp, rigid baffle) evaluated
by :func:`holoprobe.propagation.rayleigh_integral`, or by the angular spectrum
(:func:`holoprobe.propagation.propagate_parallel`) on planes parallel to the
array face.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence

import numpy as np
from numba import njit, prange
from numpy.typing import ArrayLike, NDArray

import holoprobe._numba  # noqa: F401  (threading layer, before any kernel runs)
from holoprobe.errors import InputError
from holoprobe.geometry import PlaneGrid, Surface
from holoprobe.lens import lens_delays
from holoprobe.propagation import propagate_parallel, rayleigh_integral
from holoprobe.signal import continuous_spectrum, next_fast_length, workers
from holoprobe.transducer._lattice import (
    ElementPlan,
    column_tables_field,
    element_plan,
    unique_pairs,
)
from holoprobe.transducer._model import VirtualTransducer
from holoprobe.transducer._scattered import plane_wave_field, scattered_routes
from holoprobe.transducer._table_decimation import decimated_table_spectra
from holoprobe.transducer._tables import table_spectra, table_targets
from holoprobe.transducer._transmit import TransmitSetting

__all__ = [
    "FieldPrediction",
    "drive_spectrum",
    "element_field",
    "element_offsets",
    "element_profile",
    "predict_field",
    "predict_fields",
    "signal_band",
    "surface_velocity",
]


def drive_spectrum(vt: VirtualTransducer, setting: TransmitSetting, frequencies: ArrayLike
                   ) -> NDArray[np.complex128]:
    """``H_T(ω) E_T(ω) / (ρ0 c0)``: the surface velocity spectrum per unit apodization.

    Parameters
    ----------
    vt : VirtualTransducer
        The model (transmit IR in Pa/(V·s)).
    setting : TransmitSetting
        Its drive voltage E_T.
    frequencies : array_like, shape (nf,)
        Frequencies in Hz.

    Returns
    -------
    ndarray, complex, shape (nf,)
        Continuous-time spectrum of the normal velocity in m/s·s (paper eq.
        transmit-impulse-response, u = h_T ⊛ E_T / (ρ0 c0)).
    """
    h = continuous_spectrum(vt.transmit_impulse_response, vt.transmit_sampling_rate,
                            frequencies)
    e = continuous_spectrum(setting.drive.voltage, setting.drive.sampling_rate, frequencies)
    return h * e / vt.medium.impedance


def signal_band(vt: VirtualTransducer, setting: TransmitSetting, *,
                threshold_db: float = -40.0, resolution: float | None = None
                ) -> tuple[float, float]:
    """Band of the transmitted signal: where ``|H_T E_T|²`` is within ``threshold_db`` of its peak.

    Parameters
    ----------
    vt, setting : VirtualTransducer, TransmitSetting
        Transmit IR and drive.
    threshold_db : float
        Energy threshold in dB below the spectral peak (negative).
    resolution : float, optional
        Frequency step in Hz of the search grid (default: a quarter of the
        inverse of the longer of the two records).

    Returns
    -------
    (float, float)
        Lowest and highest frequency in Hz with ``|H_T E_T|²`` above the threshold.
    """
    if not (math.isfinite(threshold_db) and threshold_db < 0):
        raise InputError(f"expected a negative number of dB, got {threshold_db!r}",
                         field="threshold_db")
    duration = max(vt.transmit_impulse_response.size / vt.transmit_sampling_rate,
                   setting.drive.duration)
    df = resolution if resolution is not None else 0.25 / duration
    f_max = 0.5 * min(vt.transmit_sampling_rate, setting.drive.sampling_rate)
    f = np.arange(df, f_max, df)
    power = np.abs(drive_spectrum(vt, setting, f)) ** 2
    if not np.any(power > 0):
        raise InputError("the transmit impulse response times the drive has no energy",
                         field="drive")
    keep = np.flatnonzero(power >= power.max() * 10 ** (threshold_db / 10))
    return float(f[keep[0]]), float(f[keep[-1]])


def _element_sampling(vt: VirtualTransducer, f_max: float, points_per_wavelength: float
                      ) -> tuple[int, int]:
    step = vt.medium.sound_speed / f_max / points_per_wavelength
    return (max(1, math.ceil(vt.element_width / step - 1e-9)),
            max(1, math.ceil(vt.element_height / step - 1e-9)))


def _element_grid(vt: VirtualTransducer, f_max: float, points_per_wavelength: float,
                  lens: bool) -> tuple[NDArray, NDArray, NDArray]:
    """Midpoint sub-samples (ux, uy) of one element about its centre and the lens delays."""
    nx, ny = _element_sampling(vt, f_max, points_per_wavelength)
    w, h = vt.element_width, vt.element_height
    ux = (np.arange(nx) + 0.5) / nx * w - w / 2
    uy = (np.arange(ny) + 0.5) / ny * h - h / 2
    tau_lens = (lens_delays(uy, vt.lens_focus, h, vt.medium.sound_speed)
                if lens and math.isfinite(vt.lens_focus) else np.zeros(ny))
    return ux, uy, tau_lens


def element_profile(vt: VirtualTransducer, u: ArrayLike
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Face of an element across its width, in the element's own frame.

    Parameters
    ----------
    vt : VirtualTransducer
        The model (a convex :attr:`~VirtualTransducer.array` bends its elements).
    u : array_like, shape (n,)
        Arc length from the element centre across the width, in m.

    Returns
    -------
    along, depth : ndarray, shape (n,)
        Position along the element's width direction and along its normal (≤ 0: behind
        the tangent plane), in m: ``(u, 0)`` for a flat element, ``(R sin(u/R),
        −R(1 − cos(u/R)))`` for a strip of a cylinder of radius R (convex array).
    """
    a = np.asarray(u, dtype=float)
    arr = vt.array
    if arr is None or arr.kind != "convex" or arr.radius_of_curvature is None:
        return a, np.zeros_like(a)
    r = float(arr.radius_of_curvature)
    return r * np.sin(a / r), -r * (1.0 - np.cos(a / r))


def surface_velocity(vt: VirtualTransducer, setting: TransmitSetting, frequencies: ArrayLike,
                     *, points_per_wavelength: float = 4.0, lens: bool = True,
                     skip_silent: bool = True) -> tuple[Surface, NDArray[np.complex128]]:
    """Normal surface velocity of the virtual transducer for a transmit setting.

    ``U = a_i H_T E_T / (ρ0 c0) · e^{iω(τ_i + τ_L(y − y_c))}`` on every element
    (paper eqs. transmit-impulse-response, lens-delays; the lens height is the
    element height H, i.e. the estimated aperture height), sampled by the
    midpoint rule on sub-elements no larger than λ/``points_per_wavelength`` of
    the highest frequency.

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    setting : TransmitSetting
        Delays, apodization and drive.
    frequencies : array_like, shape (nf,)
        Positive frequencies in Hz.
    points_per_wavelength : float
        Sub-element sampling: at least this many points per wavelength of the
        highest frequency along x and y (default 4: ≤ λ/4).
    lens : bool
        Apply the lens delays (False: a flat element, e.g. for tests).
    skip_silent : bool
        Leave out elements with zero apodization.

    Returns
    -------
    surface : Surface
        Quadrature points on z = 0 (normals +z, weights = sub-element areas in m²).
    velocity : ndarray, complex, shape (surface.size, nf)
        Continuous-time spectrum of the normal velocity in m/s·s at each point.
    """
    if not isinstance(vt, VirtualTransducer):
        raise InputError("expected a VirtualTransducer", field="vt")
    if not isinstance(setting, TransmitSetting):
        raise InputError("expected a TransmitSetting", field="setting")
    f = np.asarray(frequencies, dtype=float).reshape(-1)
    if f.size == 0 or not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise InputError("expected positive, finite frequencies in Hz", field="frequencies")
    if not (math.isfinite(points_per_wavelength) and points_per_wavelength > 0):
        raise InputError("expected a positive number", field="points_per_wavelength")
    n_el = vt.element_count
    centers = vt.element_centers()
    apod, tau_el = vt.transmit_weights(setting)
    active = np.flatnonzero(apod != 0) if skip_silent else np.arange(n_el)
    if active.size == 0:
        raise InputError("every element has zero apodization", field="apodization")
    ux, uy, tau_lens = _element_grid(vt, float(f.max()), points_per_wavelength, lens)
    nx, ny = ux.size, uy.size
    w, h = vt.element_width, vt.element_height
    if vt.is_curved:
        surface = _curved_surface(vt, active, ux, uy)
    else:
        # points ordered (element, x sub-sample, y sub-sample); each element about its
        # own centre (x_e, y_e): y_e = y_c for a 1-D row, the grid row of a matrix array
        px = (centers[active, 0][:, None] + ux[None, :])
        xs = np.repeat(px.reshape(-1), ny)
        ys = (centers[active, 1][:, None, None] + uy[None, None, :]
              + np.zeros((1, nx, 1))).reshape(-1)
        pts = np.stack([xs, ys, np.zeros(xs.size)], axis=-1)
        surface = Surface(pts, np.tile([0.0, 0.0, 1.0], (xs.size, 1)),
                          np.full(xs.size, (w / nx) * (h / ny)))
    tau = np.repeat(tau_el[active], nx * ny) + np.tile(tau_lens, active.size * nx)
    amp = np.repeat(apod[active], nx * ny)
    spectrum = drive_spectrum(vt, setting, f)
    velocity = np.exp((2j * np.pi) * tau[:, None] * f[None, :])
    velocity *= amp[:, None]
    velocity *= spectrum[None, :]
    return surface, velocity


def _curved_surface(vt: VirtualTransducer, active: NDArray, ux: NDArray, uy: NDArray
                    ) -> Surface:
    """Sub-element midpoints of the ``active`` elements on their own (curved) faces,
    ordered (element, u, v) like the flat path: ``c + a u_e + v v_e + d n_e`` with (a, d)
    the element profile (:func:`element_profile`); normals turned with the face."""
    c, ud, vd, nd = (m[active] for m in vt.element_frames())
    along, depth = element_profile(vt, ux)
    nx, ny = ux.size, uy.size
    a = np.repeat(along, ny)[None, :, None]
    d = np.repeat(depth, ny)[None, :, None]
    v = np.tile(uy, nx)[None, :, None]
    pts = c[:, None, :] + a * ud[:, None, :] + v * vd[:, None, :] + d * nd[:, None, :]
    arr = vt.array
    slope = (np.zeros(nx) if arr is None or arr.radius_of_curvature is None
             or arr.kind != "convex" else ux / arr.radius_of_curvature)
    s_, c_ = np.repeat(np.sin(slope), ny)[None, :, None], np.repeat(np.cos(slope), ny)[
        None, :, None]
    nrm = c_ * nd[:, None, :] + s_ * ud[:, None, :]
    n_pts = active.size * nx * ny
    area = (vt.element_width / nx) * (vt.element_height / ny)
    return Surface(pts.reshape(n_pts, 3), nrm.reshape(n_pts, 3), np.full(n_pts, area))


def element_field(vt: VirtualTransducer, offsets: ArrayLike, frequencies: ArrayLike, *,
                  points_per_wavelength: float = 4.0, lens: bool = True,
                  dtype: type = np.float64, chunk: int = 4096,
                  progress: Callable[[int, int], None] | None = None,
                  tables: bool = False) -> NDArray[np.complexfloating]:
    """Spatial response of ONE element (with its lens): pressure per unit velocity spectrum.

    ``G(r; ω) = Σ_sub (−ikρ0c0/2π) e^{iωτ_L(v)} e^{ikR}/R ΔA`` (paper eqs.
    rayleigh-fwd-vp and lens-delays, rigid baffle): the pressure spectrum at
    ``offsets`` from the element centre when the element face moves with a unit
    velocity spectrum delayed by the lens, sampled on the same sub-elements as
    :func:`surface_velocity`. Every element of the array has this response up to
    a lateral shift, so the field of the array is ``Σ_e a_e E(ω) e^{iωτ_e}
    G(r − x_e; ω)``. By reciprocity it is also the element's receive response: a
    point source ``e^{ikR}/R`` at r gives the lens-applied, element-averaged
    pressure ``G(r) · 2π / (−ikρ0c0 A_e)``.

    Parameters
    ----------
    vt : VirtualTransducer
        Element width, height, lens focus and medium.
    offsets : array_like, shape (n, 3)
        Target positions relative to the element centre (x_e, y_c, 0), in m; in the
        element's own frame (along its width, its height, its normal) when the elements
        face different ways (a convex array, whose elements are strips of its cylinder).
    frequencies : array_like, shape (nf,)
        Positive frequencies in Hz (a uniform grid uses the phasor recurrence).
    points_per_wavelength : float
        Sub-element sampling (see :func:`surface_velocity`).
    lens : bool
        Apply the lens delays.
    dtype : {numpy.float64, numpy.float32}
        Precision of the Rayleigh kernel (float32: ~1e-5 relative, twice as fast).
    chunk : int
        Targets per call of the Rayleigh integral (drives ``progress``).
    progress : callable(done, total), optional
        Called after each chunk.
    tables : bool
        Interpolate the columns' responses from tables over ρ where that saves work
        (:func:`holoprobe.transducer.column_tables_field`; ≲ 1e-6 of the peak), the
        rest directly. False: every offset summed directly (the reference).

    Returns
    -------
    ndarray, complex, shape (n, nf)
        G in Pa per (m/s·s of velocity spectrum), i.e. Pa/(m/s).

    Notes
    -----
    When every target lies in the element's mid-plane (v = 0) the element's
    upper and lower halves contribute equally and only one half is summed (the
    lens delays are symmetric in v).
    """
    f = _check_frequencies(frequencies)
    off = _targets(offsets)
    if tables:
        g = column_tables_field(vt, off, f, points_per_wavelength=points_per_wavelength,
                                lens=lens, dtype=dtype)
        if g is not None:
            rest = np.flatnonzero(np.isnan(g[:, 0]))
            if rest.size:
                g[rest] = element_field(vt, off[rest], f,
                                        points_per_wavelength=points_per_wavelength,
                                        lens=lens, dtype=dtype, chunk=chunk)
            if progress is not None:
                progress(off.shape[0], off.shape[0])
            return g
    ux, uy, tau_lens = _element_grid(vt, float(f.max()), points_per_wavelength, lens)
    nx, ny = ux.size, uy.size
    weights = np.full(ny, vt.element_width / nx * vt.element_height / ny)
    if np.all(off[:, 1] == 0.0) and ny > 1:
        half = ny // 2
        keep = np.arange(half, ny)  # v ≥ 0 (the middle row too when ny is odd)
        weights = weights[keep] * np.where(uy[keep] > 0, 2.0, 1.0)
        uy, tau_lens = uy[keep], tau_lens[keep]
        ny = uy.size
    along, depth = element_profile(vt, ux)
    pts = np.stack([np.repeat(along, ny), np.tile(uy, nx), np.repeat(depth, ny)], axis=-1)
    src = Surface(pts, np.tile([0.0, 0.0, 1.0], (nx * ny, 1)), np.tile(weights, nx))
    velocity = np.exp((2j * np.pi) * np.tile(tau_lens, nx)[:, None] * f[None, :])
    return _chunked_rayleigh(velocity, src, off, f, vt, np.dtype(dtype), chunk, progress)


def _chunked_rayleigh(velocity: NDArray, source: Surface, pts: NDArray, f: NDArray,
                      vt: VirtualTransducer, real: np.dtype, chunk: int,
                      progress: Callable[[int, int], None] | None
                      ) -> NDArray[np.complexfloating]:
    """Forward Rayleigh sum (fwd_vp, rigid) from ``source`` at ``pts`` in chunks of targets."""
    out = np.empty((pts.shape[0], f.size), dtype=np.result_type(real, np.complex64))
    normals = np.tile([0.0, 0.0, 1.0], (1, 1))
    step = max(1, int(chunk))
    for start in range(0, pts.shape[0], step):
        sel = pts[start:start + step]
        target = Surface(sel, np.repeat(normals, sel.shape[0], axis=0), np.ones(sel.shape[0]))
        out[start:start + step] = rayleigh_integral(
            velocity, source, target, f, vt.medium, kernel="fwd_vp", baffle="rigid",
            dtype=real)
        if progress is not None:
            progress(min(start + step, pts.shape[0]), pts.shape[0])
    return out


def _check_frequencies(frequencies: ArrayLike) -> NDArray[np.float64]:
    try:
        f = np.asarray(frequencies, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError("expected positive frequencies in Hz", field="frequencies") from None
    if f.size == 0 or not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise InputError("expected positive, finite frequencies in Hz", field="frequencies")
    return f


def element_offsets(vt: VirtualTransducer, points: ArrayLike, elements: ArrayLike, *,
                    tolerance: float = 1e-9) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Distinct positions of target points relative to the elements, folded by symmetry.

    Every element (with its lens) is symmetric in x about its centre and in y
    about the lens axis y_c, so its response at (u, v, z) equals that at
    (|u|, |v|, z). Target points on a grid whose lateral step divides the pitch
    see the elements from few distinct offsets: for an xz plane of n_x × n_z
    points and N elements about (n_x + m(N − 1))/2 × n_z offsets instead of
    N n_x n_z (m = pitch / step).

    Parameters
    ----------
    vt : VirtualTransducer
        Element centres.
    points : array_like, shape (n, 3)
        Target points in m.
    elements : array_like of int, shape (n_el,)
        Indices of the elements to use.
    tolerance : float
        Offsets closer than this (m) in every coordinate are merged (the phase
        error is k·tolerance).

    Returns
    -------
    offsets : ndarray, shape (n_unique, 3)
        Distinct (|u|, |v|, z) in m.
    index : ndarray of int, shape (n_el, n)
        Row of ``offsets`` seen by element ``elements[j]`` from point i.
    """
    pts = _targets(points)
    el = np.asarray(elements, dtype=int).reshape(-1)
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise InputError("expected a positive length in m", field="tolerance")
    centers = vt.element_centers()
    if vt.is_curved:  # elements facing different ways (convex): each one's own frame
        return _offsets_2d(centers[el], pts, tolerance, local=_local_coordinates(vt, pts, el))
    if not np.allclose(centers[el, 1], centers[el[:1], 1]):  # a 2-D layout (matrix)
        return _offsets_2d(centers[el], pts, tolerance)
    xe = centers[el, 0]
    yc = vt.aperture_center[1]
    v = np.abs(pts[:, 1] - yc)
    vz = np.stack([np.rint(v / tolerance), np.rint(pts[:, 2] / tolerance)], axis=-1)
    first_vz, inv_vz, _ = unique_pairs(vz)
    u = np.abs(pts[None, :, 0] - xe[:, None])  # (n_el, n)
    uq = np.rint(u / tolerance).astype(np.int64)
    base = int(uq.max()) + 1
    if base * (first_vz.size + 1) >= 2**62:
        raise InputError("targets too far from the array for the offset tolerance",
                         field="tolerance")
    key = inv_vz[None, :].astype(np.int64) * base + uq
    _, first, index = np.unique(key.reshape(-1), return_index=True, return_inverse=True)
    e_of, p_of = np.divmod(first, pts.shape[0])
    offsets = np.stack([u[e_of, p_of], v[p_of], pts[p_of, 2]], axis=-1)
    return offsets, index.reshape(el.size, pts.shape[0]).astype(np.int64)


def _local_coordinates(vt: VirtualTransducer, pts: NDArray, elements: NDArray
                       ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Coordinates of the points in each element's frame, each of shape (n_el, n):
    along its width, along its height and along its normal, from its centre (m)."""
    c, ud, vd, nd = (m[elements] for m in vt.element_frames())
    d = pts[None, :, :] - c[:, None, :]
    return (np.einsum("enk,ek->en", d, ud), np.einsum("enk,ek->en", d, vd),
            np.einsum("enk,ek->en", d, nd))


def _offsets_2d(centers: NDArray, pts: NDArray, tolerance: float,
                local: tuple[NDArray, NDArray, NDArray] | None = None
                ) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """:func:`element_offsets` for elements at different y (or, with ``local``, the
    points' coordinates in each element's frame): the distinct ``(|x − x_e|, |y − y_e|,
    z)`` (``(|u|, |v|, w)``) over every element and point."""
    if local is not None:
        u, v, z = np.abs(local[0]), np.abs(local[1]), local[2]
    else:
        u = np.abs(pts[None, :, 0] - centers[:, 0:1])
        v = np.abs(pts[None, :, 1] - centers[:, 1:2])
        z = np.broadcast_to(pts[None, :, 2], u.shape)
    key = np.stack([np.rint(a / tolerance).astype(np.int64).reshape(-1) for a in (u, v, z)],
                   axis=-1)
    _, first, index = np.unique(key, axis=0, return_index=True, return_inverse=True)
    offsets = np.stack([u.reshape(-1)[first], v.reshape(-1)[first], z.reshape(-1)[first]],
                       axis=-1)
    return offsets, index.reshape(centers.shape[0], pts.shape[0]).astype(np.int64)


def _assemble(g: NDArray, index: NDArray, weights: NDArray, out: NDArray) -> None:
    """out[i, :] = Σ_e weights[e, :] · g[index[e, i], :] (complex; parallel over points i).

    ``g`` and ``out`` go to the kernel as their real views (re, im pairs) with the
    weights' real and imaginary parts apart, which LLVM vectorizes (:func:`_assemble_pairs`).
    """
    real = np.empty(0, dtype=g.dtype).real.dtype
    w = weights.astype(g.dtype, copy=False)
    _assemble_pairs(np.ascontiguousarray(g).view(real), np.ascontiguousarray(index),
                    np.ascontiguousarray(w.real), np.ascontiguousarray(w.imag),
                    out.view(real))


@njit(parallel=True, cache=True, fastmath=True)
def _assemble_pairs(g, index, wr, wi, out):  # pragma: no cover - compiled
    """out[i, 2b:2b+2] = Σ_e (wr + i wi)[e, b] · g[index[e, i], 2b:2b+2] (complex as pairs)."""
    n_el, n_pts = index.shape
    nf = wr.shape[1]
    for i in prange(n_pts):
        acc = np.zeros(2 * nf, dtype=out.dtype)
        for e in range(n_el):
            src = g[index[e, i]]
            c = wr[e]
            d = wi[e]
            for k in range(nf):
                x = src[2 * k]
                y = src[2 * k + 1]
                acc[2 * k] += c[k] * x - d[k] * y
                acc[2 * k + 1] += c[k] * y + d[k] * x
        out[i, :] = acc


def _arrival_bounds(vt: VirtualTransducer, pts: NDArray, elements: NDArray, tau_el: NDArray,
                    lens: bool, chunk: int = 1 << 20) -> tuple[NDArray, NDArray]:
    """Earliest and latest possible arrival (s) at each point from the active elements.

    Distances to each element's rectangle plus its delay; the latest adds the
    largest lens delay. A flat face in one parallel pass; a curved one chunked over
    points so that no (n_el, n) array exceeds ``chunk`` entries.
    """
    c0 = vt.medium.sound_speed
    xe = vt.element_centers()[elements, 0]
    ye = vt.element_centers()[elements, 1]
    curved = vt.is_curved
    hw, hh = 0.5 * vt.element_width, 0.5 * vt.element_height
    lens_max = (float(lens_delays(np.zeros(1), vt.lens_focus, vt.element_height, c0)[0])
                if lens and math.isfinite(vt.lens_focus) else 0.0)
    t_min = np.empty(pts.shape[0])
    t_max = np.empty(pts.shape[0])
    if not curved:  # one parallel pass, no (n_el, n) temporaries
        _flat_bounds(np.ascontiguousarray(pts, dtype=float), np.ascontiguousarray(xe),
                     np.ascontiguousarray(ye), np.ascontiguousarray(tau_el, dtype=float),
                     hw, hh, c0, lens_max, t_min, t_max)
        return t_min, t_max
    step = max(1, chunk // max(1, xe.size))
    for s0 in range(0, pts.shape[0], step):
        sl = slice(s0, s0 + step)
        # a curved face lies within its sagitta behind the tangent plane
        u, v, w = _local_coordinates(vt, pts[sl], elements)
        u, v = np.abs(u), np.abs(v)
        sag = -float(element_profile(vt, np.array([hw]))[1][0])
        z2 = np.maximum(np.abs(w + 0.5 * sag) - 0.5 * sag, 0.0) ** 2
        z2f = (np.abs(w) + sag) ** 2
        near = np.sqrt(np.maximum(u - hw, 0.0) ** 2 + np.maximum(v - hh, 0.0) ** 2 + z2)
        far = np.sqrt((u + hw) ** 2 + (v + hh) ** 2 + z2f)
        t_min[sl] = (near / c0 + tau_el[:, None]).min(axis=0)
        t_max[sl] = (far / c0 + tau_el[:, None]).max(axis=0) + lens_max
    return t_min, t_max


@njit(parallel=True, cache=True, nogil=True)
def _flat_bounds(pts, xe, ye, tau, hw, hh, c0, lens_max, t_min, t_max
                 ):  # pragma: no cover - compiled
    """:func:`_arrival_bounds` of a flat face (the same expressions, per point)."""
    for p in prange(pts.shape[0]):
        z2 = pts[p, 2] ** 2
        lo, hi = np.inf, -np.inf
        for e in range(xe.size):
            u = abs(pts[p, 0] - xe[e])
            v = abs(pts[p, 1] - ye[e])
            near = math.sqrt(max(u - hw, 0.0) ** 2 + max(v - hh, 0.0) ** 2 + z2)
            far = math.sqrt((u + hw) ** 2 + (v + hh) ** 2 + z2)
            lo = min(lo, near / c0 + tau[e])
            hi = max(hi, far / c0 + tau[e])
        t_min[p] = lo
        t_max[p] = hi + lens_max


class FieldPrediction:
    """Result of :func:`predict_field`.

    Attributes
    ----------
    time : ndarray, shape (nt,)
        Sample times in s (t = 0: the earliest element fires).
    pressure : ndarray, shape (n_points, nt)
        Pressure in Pa at each target point (C order of a PlaneGrid).
    points : ndarray, shape (n_points, 3)
        Target points in m.
    frequency_band : (float, float)
        Band in Hz that was propagated.
    method : str
        ``"element"``, ``"rayleigh"`` or ``"angular_spectrum"``.
    time_offset : ndarray, shape (n_points,)
        Start of each point's record in s: sample n of point i is at
        ``time_offset[i] + time[n]``. Zero with a common time axis
        (``time_window="common"``); the per-point start with ``"local"``.
    """

    def __init__(self, time: NDArray, pressure: NDArray, points: NDArray,
                 frequency_band: tuple[float, float], method: str,
                 time_offset: NDArray | None = None):
        self.time = time
        self.pressure = pressure
        self.points = points
        self.frequency_band = frequency_band
        self.method = method
        self.time_offset = (np.zeros(points.shape[0]) if time_offset is None
                            else np.asarray(time_offset, dtype=float))

    @property
    def sampling_rate(self) -> float:
        """Sampling rate of the records in Hz."""
        return float(1.0 / (self.time[1] - self.time[0])) if self.time.size > 1 else math.inf

    def __iter__(self):  # allows ``t, p = predict_field(...)``
        return iter((self.time, self.pressure))

    @property
    def peak_positive(self) -> NDArray[np.float64]:
        """Peak compressional pressure per point in Pa, shape (n_points,)."""
        return self.pressure.max(axis=1)

    @property
    def peak_negative(self) -> NDArray[np.float64]:
        """Peak rarefactional pressure per point in Pa (positive number), shape (n_points,)."""
        return -self.pressure.min(axis=1)


def _targets(points_or_plane: PlaneGrid | Surface | ArrayLike) -> NDArray[np.float64]:
    if isinstance(points_or_plane, PlaneGrid):
        return points_or_plane.points()
    if isinstance(points_or_plane, Surface):
        return np.asarray(points_or_plane.points)
    try:
        pts = np.asarray(points_or_plane, dtype=float)
    except (TypeError, ValueError):
        raise InputError("expected a PlaneGrid, a Surface or points (n, 3) in m",
                         field="points") from None
    if pts.ndim == 1 and pts.size == 3:
        pts = pts[None, :]
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0:
        raise InputError(f"expected points of shape (n, 3) in m, got {pts.shape}",
                         field="points")
    if not np.all(np.isfinite(pts)):
        raise InputError("contains NaN or inf", field="points")
    return pts


def _distance_range(vt: VirtualTransducer, pts: NDArray) -> tuple[float, float]:
    """Smallest and largest distance from the target points to the aperture rectangle
    (to the elements' boxes on a curved face)."""
    if vt.is_curved:
        everyone = np.arange(vt.element_count)
        t_min, t_max = _arrival_bounds(vt, pts, everyone, np.zeros(everyone.size), False)
        c0 = vt.medium.sound_speed
        return float(t_min.min()) * c0, float(t_max.max()) * c0
    x_lo, x_hi, y_lo, y_hi = vt.face_extent()
    cx = np.clip(pts[:, 0], x_lo, x_hi)
    cy = np.clip(pts[:, 1], y_lo, y_hi)
    d_min = np.sqrt((pts[:, 0] - cx) ** 2 + (pts[:, 1] - cy) ** 2 + pts[:, 2] ** 2)
    far_x = np.maximum(np.abs(pts[:, 0] - x_lo), np.abs(pts[:, 0] - x_hi))
    far_y = np.maximum(np.abs(pts[:, 1] - y_lo), np.abs(pts[:, 1] - y_hi))
    d_max = np.sqrt(far_x**2 + far_y**2 + pts[:, 2] ** 2)
    return float(d_min.min()), float(d_max.max())


def _is_parallel_plane(target: object) -> bool:
    if not isinstance(target, PlaneGrid):
        return False
    pose = target.pose
    return (pose.theta_x == 0 and pose.theta_y == 0 and pose.theta_z == 0
            and pose.origin[2] > 0 and target.x.size >= 2 and target.y.size >= 2)


def record_band(span: float, sampling_rate: float, f_lo: float, f_hi: float,
                n_samples: int | None) -> tuple[int, NDArray[np.intp], NDArray[np.float64]]:
    """Record length and the bins of the signal band for a prediction.

    Parameters
    ----------
    span : float
        Time the record must cover in s (used when ``n_samples`` is None).
    sampling_rate : float
        Hz.
    f_lo, f_hi : float
        Signal band in Hz.
    n_samples : int, optional
        Explicit record length.

    Returns
    -------
    (int, ndarray, ndarray)
        Record length n, indices of the band's rfft bins, and their frequencies in Hz.
    """
    if n_samples is None:
        n = next_fast_length(math.ceil(span * sampling_rate))
    else:
        n = int(n_samples)
        if n < 2:
            raise InputError("expected at least 2 samples", field="n_samples")
    freqs = np.fft.rfftfreq(n, 1.0 / sampling_rate)
    band = np.flatnonzero((freqs >= f_lo) & (freqs <= f_hi) & (freqs > 0))
    if band.size == 0:
        raise InputError("no frequency bin falls in the signal band; increase n_samples",
                         field="n_samples")
    return n, band, np.asarray(freqs[band], dtype=np.float64)


def predict_field(
    vt: VirtualTransducer,
    setting: TransmitSetting,
    points_or_plane: PlaneGrid | Surface | ArrayLike,
    *,
    sampling_rate: float | None = None,
    n_samples: int | None = None,
    start_time: float | None = None,
    method: str = "auto",
    time_window: str = "common",
    band_threshold_db: float = -40.0,
    oversampling: float = 8.0,
    points_per_wavelength: float = 4.0,
    guard_time: float = 1e-6,
    target_chunk: int = 4096,
    dtype: type = np.float64,
    offset_tolerance: float = 1e-9,
    progress: Callable[[int, int], None] | None = None,
) -> FieldPrediction:
    """Pressure time series radiated by the virtual transducer for a transmit setting.

    The surface velocity (:func:`surface_velocity`, paper eqs.
    transmit-impulse-response and lens-delays) is propagated per frequency bin of
    the signal band by the forward Rayleigh integral (paper eq. rayleigh-fwd-vp,
    rigid baffle) or, for a :class:`PlaneGrid` parallel to the array face (no
    rotation, z0 > 0), by the angular spectrum. Only the bins where ``|H_T E_T|²``
    lies within ``band_threshold_db`` of its peak are propagated; the rest are zero.

    Methods:

    * ``"lattice"`` (what ``"auto"`` picks): ``"element"``, except that targets
      sharing (y, z) with others (lines along x: planes, volume grids, lists of such
      points) are interpolated along x from nodes of the element lattice
      ``x_0 + j·pitch/m`` (step ≤ λ_min/3.2) with a 16- or 20-tap Kaiser-windowed sinc
      (:func:`holoprobe.transducer.element_plan`): at those nodes the target–element
      offsets repeat, so a line of n targets needs about (its length + the array
      length)/step element responses instead of n·N. The field along x is
      band-limited (lateral wavenumbers ≤ k plus decayed evanescent ones), so the
      interpolation adds ~1e-6 of the peak pressure (2e-6 measured on the P4-1 preset,
      tested against the dense sum);
      targets nearer the face than the depth where that bound holds, lone targets and
      lines where the lattice saves nothing are computed directly.
      ``FieldPrediction.method`` says ``"lattice"`` when any target was interpolated.
    * ``"table"``: the field of every element is summed from ONE table of an element
      column's response over (elevation, distance from the column), interpolated with
      8 taps per axis (:func:`holoprobe.transducer.table_spectra`; flat 1-D arrays,
      targets at least 3 λ_min in front of the face, nearer ones by ``"element"``): the
      same quadrature as ``"rayleigh"``, ≈ 1e-5 of the peak pressure from it, at a cost
      per target and frequency of ~8 × (its range of distances to the array)/(λ_min/5)
      + ~14 N_el multiply-adds — for many scattered targets (10⁴–10⁶ points). ``"auto"``
      sends targets that share no line along x here when building the table costs less
      than their element superposition (``FieldPrediction.method`` ``"table"``, or
      ``"lattice+table"`` when split). A target whose arrivals spread over less than
      0.6/D of the record is evaluated on every D-th bin (D ≤ 4) and interpolated to
      every bin in frequency (:mod:`holoprobe.transducer._table_decimation`; ≈ 2e-5 of
      the peak pressure).
    * ``"plane_waves"``: the same sub-element point sources as ``"rayleigh"``
      propagated by Weyl's plane-wave expansion, evaluated with type-3 NUFFTs per
      frequency and depth slab of targets
      (:func:`holoprobe.propagation.rayleigh_plane_waves`): a cost per frequency set
      by the extent of the array and the targets plus a constant per target, for many
      scattered targets (10⁵–10⁶ points). Evanescent waves are included; agrees with
      ``"element"`` to ~4e-5 of the peak pressure (NUFFT tolerance 1e-5). Flat models,
      targets at z > 0. ``"auto"`` sends targets that share no line along x with
      others and that the table does not serve (a 2-D matrix array) here when its
      estimated cost is lower than their element superposition
      (:func:`holoprobe.transducer.plane_wave_targets`); ``FieldPrediction.method``
      then says ``"plane_waves"`` (or ``"lattice+plane_waves"`` when split).
    * ``"element"``: the field of ONE element with its
      lens, :func:`element_field`, is evaluated at the distinct offsets between
      the targets and the element centres (:func:`element_offsets`, folded by the
      element's symmetry), then summed over the elements with their apodization,
      drive and delay phases ``a_e E(ω) e^{iωτ_e}``. The same quadrature as
      ``"rayleigh"`` (identical sub-elements), so the two agree to rounding; on a
      grid whose lateral step divides the pitch it needs ~N/2 times fewer kernel
      evaluations.
    * ``"rayleigh"``: the dense sum over every sub-element of the array
      (:func:`holoprobe.propagation.rayleigh_integral`): the reference.
    * ``"angular_spectrum"``: :func:`holoprobe.propagation.propagate_parallel`,
      kind "vp", the velocity accumulated on the plane's own grid.

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    setting : TransmitSetting
        Delays, apodization, drive.
    points_or_plane : PlaneGrid or Surface or array_like, shape (n, 3)
        Where the pressure is wanted (m, transducer coordinates).
    sampling_rate : float, optional
        Output rate in Hz (default ``oversampling`` × the top of the band).
    n_samples : int, optional
        Output length (default: every possible arrival, plus the durations of
        the IR and the drive and ``guard_time``, fits in the record).
    start_time : float, optional
        Time of output sample 0 in s with a common window (default: the earliest
        possible arrival minus ``guard_time``). Not used with ``"local"``.
    method : str
        ``"auto"``, ``"lattice"``, ``"element"``, ``"table"``, ``"plane_waves"``,
        ``"rayleigh"`` or ``"angular_spectrum"``: see above.
    time_window : {"common", "local"}
        ``"common"``: one time axis for every point (``time`` absolute).
        ``"local"``: each point's record starts at its own earliest possible
        arrival minus ``guard_time`` (``FieldPrediction.time_offset``), and all
        records share the length of the longest arrival spread: a much shorter
        record (fewer frequency bins, less memory) for large planes.
    band_threshold_db : float
        Energy threshold of the band selection in dB (negative).
    oversampling : float
        Default output rate relative to the top of the band.
    points_per_wavelength : float
        Source sub-sampling (see :func:`surface_velocity`).
    guard_time : float
        Margin in s before the first and after the last arrival.
    target_chunk : int
        Target points per call of the Rayleigh integral (bounds the memory and
        drives ``progress``).
    dtype : {numpy.float64, numpy.float32}
        Precision of the kernel and of the returned pressure (float32: ~1e-5
        relative, half the memory, about twice as fast).
    offset_tolerance : float
        ``"element"``: offsets closer than this (m) are merged.
    progress : callable(done, total), optional
        Called as the work advances.

    Returns
    -------
    FieldPrediction
        ``time`` (nt,) in s and ``pressure`` (n_points, nt) in Pa (unpack as
        ``t, p = predict_field(...)``), plus the points, the band and the
        per-point ``time_offset``.

    Notes
    -----
    The record is periodic with its length: ``n_samples`` must cover every
    arrival, otherwise late arrivals wrap to the start. Cost of the dense path:
    N_source × N_target × N_bins kernel terms; of the element path:
    N_source/N × N_offsets × N_bins plus N × N_target × N_bins multiply-adds.
    """
    if method not in ("auto", "lattice", "element", "table", "plane_waves", "rayleigh",
                      "angular_spectrum"):
        raise InputError(f"expected 'auto', 'lattice', 'element', 'table', 'plane_waves', "
                         f"'rayleigh' or 'angular_spectrum', got {method!r}", field="method")
    if time_window not in ("common", "local"):
        raise InputError(f"expected 'common' or 'local', got {time_window!r}",
                         field="time_window")
    real = np.dtype(dtype)
    if real not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise InputError(f"expected numpy.float32 or numpy.float64, got {dtype!r}",
                         field="dtype")
    pts = _targets(points_or_plane)
    if method == "angular_spectrum" and vt.is_curved:
        raise InputError("the angular spectrum needs a flat face; this model's elements "
                         "face different ways (convex): use 'auto' or 'rayleigh'",
                         field="method")
    if method == "angular_spectrum" and not _is_parallel_plane(points_or_plane):
        raise InputError("the angular spectrum needs a PlaneGrid parallel to the array face "
                         "(no rotation, origin z > 0, at least 2 × 2 points)", field="method")
    if method == "angular_spectrum" and time_window == "local":
        raise InputError("the angular spectrum path needs time_window='common'",
                         field="time_window")
    if method == "plane_waves" and (vt.is_curved or np.any(pts[:, 2] <= 0)):
        raise InputError("plane waves need a flat model and targets in front of it "
                         "(z > 0): use 'auto', 'element' or 'rayleigh'", field="method")
    c0 = vt.medium.sound_speed
    f_lo, f_hi = signal_band(vt, setting, threshold_db=band_threshold_db)
    fs = float(sampling_rate) if sampling_rate is not None else oversampling * f_hi
    if not (math.isfinite(fs) and fs > 2 * f_hi):
        raise InputError(f"expected a sampling rate above twice the top of the band "
                         f"({2 * f_hi:g} Hz), got {fs!r}", field="sampling_rate")
    tails = (vt.transmit_impulse_response.size / vt.transmit_sampling_rate
             + setting.drive.duration + guard_time)
    apod, tau_all = vt.transmit_weights(setting)
    active = np.flatnonzero(apod != 0)
    if active.size == 0:
        raise InputError("every element has zero apodization", field="apodization")
    t_min: NDArray | None = None
    t_max: NDArray | None = None
    if time_window == "local":
        t_min, t_max = _arrival_bounds(vt, pts, active, tau_all[active], True)
        offsets_t = t_min - guard_time
        t0 = 0.0
        span = float(np.max(t_max - t_min)) + guard_time + tails
    else:
        d_min, d_max = _distance_range(vt, pts)
        t0 = d_min / c0 - guard_time if start_time is None else float(start_time)
        offsets_t = None
        span = d_max / c0 + float(tau_all.max()) + tails - t0
    n, band, fb = record_band(span, fs, f_lo, f_hi, n_samples)
    if method == "angular_spectrum":
        assert isinstance(points_or_plane, PlaneGrid)  # _is_parallel_plane, checked above
        spec = _angular_spectrum_field(vt, setting, points_or_plane, fb, 0.0,
                                       points_per_wavelength)
        if progress is not None:
            progress(pts.shape[0], pts.shape[0])
    else:
        spec, method = _point_spectra(vt, setting, pts, fb, method, active, tau_all, apod,
                                      points_per_wavelength, real, offset_tolerance,
                                      target_chunk, progress, (n / fs, t_min, t_max))
    pressure = _records(spec, fb, band, n, fs, t0, offsets_t, real)
    time = t0 + np.arange(n) / fs
    return FieldPrediction(time, pressure, pts, (f_lo, f_hi), method, offsets_t)


def _point_spectra(vt: VirtualTransducer, setting: TransmitSetting, pts: NDArray,
                   fb: NDArray, method: str, active: NDArray, tau_all: NDArray,
                   apod: NDArray, points_per_wavelength: float, real: np.dtype,
                   tolerance: float, chunk: int,
                   progress: Callable[[int, int], None] | None,
                   record: tuple[float, NDArray | None, NDArray | None] | None = None
                   ) -> tuple[NDArray[np.complexfloating], str]:
    """Field spectra (n_points, nf) by the element, lattice, table, plane-wave or dense method.

    ``"auto"`` sends scattered targets to the column table or plane waves where that is
    estimated to be cheaper (:func:`scattered_routes`) and the rest to the lattice.
    Returns the spectra and the name of the method(s) used, joined by ``+``.
    """
    if method == "rayleigh":
        return _rayleigh_method(vt, setting, pts, fb, points_per_wavelength, real, chunk,
                                progress), method
    complex_dtype = np.result_type(real, np.complex64)
    waves = np.zeros(pts.shape[0], dtype=bool)
    table = np.zeros(pts.shape[0], dtype=bool)
    if method == "plane_waves":
        waves[:] = True
    elif method == "table":
        table = table_targets(vt, pts, float(fb.max()))
        method = "element"
    elif method == "auto":
        table, waves = scattered_routes(
            vt, pts, active, fb, _element_sampling(vt, float(fb.max()), points_per_wavelength),
            tolerance)
        method = "lattice"
    spec = np.empty((pts.shape[0], fb.size), dtype=complex_dtype)
    rest = np.flatnonzero(~(waves | table))
    names = []
    parts = [m for m in (rest.size, table.any(), waves.any()) if m]
    if rest.size:
        spec[rest], n_interp = _element_method(
            vt, setting, pts[rest], fb, active, tau_all, apod, points_per_wavelength, real,
            tolerance, chunk, progress if len(parts) == 1 else None,
            lattice=method == "lattice")
        names.append("lattice" if n_interp else "element")
    if table.any():
        got = _table_method(vt, setting, pts[table], fb, active, tau_all, apod,
                            points_per_wavelength, real, record, table, progress)
        if table.all():  # no copy (a stream's chunk of 65 536 × ~100 bins: 54 MB)
            spec = got
        else:
            spec[table] = got
        names.append("table")
    if waves.any():
        spec[waves] = plane_wave_field(vt, setting, pts[waves], fb,
                                       points_per_wavelength=points_per_wavelength,
                                       dtype=complex_dtype, progress=progress)
        names.append("plane_waves")
    return spec, "+".join(names)


def _table_method(vt: VirtualTransducer, setting: TransmitSetting, pts: NDArray,
                  fb: NDArray, active: NDArray, tau_all: NDArray, apod: NDArray,
                  points_per_wavelength: float, real: np.dtype,
                  record: tuple[float, NDArray | None, NDArray | None] | None,
                  mask: NDArray, progress: Callable[[int, int], None] | None
                  ) -> NDArray[np.complexfloating]:
    """Field spectra (n_points, nf) from the column table: on every D-th bin where the
    targets' arrival spread allows (:mod:`holoprobe.transducer._table_decimation`,
    ``record`` = the record length in s and, when known, every target's arrival bounds
    (``mask`` picks ``pts`` among them)), otherwise on every bin."""
    drive = drive_spectrum(vt, setting, fb)
    if record is not None:
        period, t_min, t_max = record
        bounds = ((t_min[mask], t_max[mask]) if t_min is not None and t_max is not None
                  else _arrival_bounds(vt, pts, active, tau_all[active], True))
        spec = decimated_table_spectra(
            vt, pts, fb, period, active, apod[active], tau_all[active], drive, bounds,
            points_per_wavelength=points_per_wavelength, dtype=real.type, progress=progress)
        if spec is not None:
            return spec
    weights = (apod[active, None] * drive[None, :]
               * np.exp((2j * np.pi) * tau_all[active, None] * fb[None, :]))
    return table_spectra(vt, pts, fb, active, [weights],
                         points_per_wavelength=points_per_wavelength, dtype=real.type,
                         progress=progress)[0]


def _rayleigh_method(vt: VirtualTransducer, setting: TransmitSetting, pts: NDArray,
                     fb: NDArray, points_per_wavelength: float, real: np.dtype, chunk: int,
                     progress: Callable[[int, int], None] | None
                     ) -> NDArray[np.complexfloating]:
    """Field spectra (n_points, nf) by the dense Rayleigh sum over every sub-element."""
    surface, velocity = surface_velocity(vt, setting, fb,
                                         points_per_wavelength=points_per_wavelength)
    return _chunked_rayleigh(velocity, surface, pts, fb, vt, real, chunk, progress)


def _records(spec: NDArray, fb: NDArray, band: NDArray, n: int, fs: float, t0: float,
             offsets_t: NDArray | None, real: np.dtype) -> NDArray:
    """Pressure records (n_points, n) from band spectra (n_points, nf), per-point origins.

    Each record's time origin moves by a delay of −t (factor e^{−iωt}), then the
    continuous spectrum (Pa·s) becomes samples (conj(rfft(p)) = P / dt): the rfft bins
    ``conj(P e^{−iωt}) fs`` are filled in one parallel pass (:func:`_band_bins`) and
    inverted; chunked over points (one reused block of bins, zero outside the band).
    """
    import scipy.fft

    n_pts = spec.shape[0]
    omega = 2 * np.pi * fb
    cdtype = np.result_type(real, np.complex64)
    # ≤ 128 MiB of bins (~1/4 of them in the band): a stream's chunk of 65 536 complex64
    # records of ≤ 512 samples is one block, whose transform is returned without a copy
    rows = max(1, (1 << 27) // (np.dtype(cdtype).itemsize * (n // 2 + 1)))
    full = np.zeros((min(rows, n_pts), n // 2 + 1), dtype=cdtype)  # zero outside the band
    shifts = (np.full(n_pts, float(t0)) if offsets_t is None
              else np.ascontiguousarray(offsets_t, dtype=float))
    spec = np.ascontiguousarray(spec)
    bins = np.asarray(band, dtype=np.int64)
    d_omega = float(omega[1] - omega[0]) if omega.size > 1 else 0.0
    uniform = omega.size > 1 and np.allclose(np.diff(omega), d_omega, rtol=1e-9, atol=0)
    pressure = None
    for s0 in range(0, n_pts, rows):
        s1 = min(s0 + rows, n_pts)
        block = full[:s1 - s0]
        _band_bins(spec[s0:s1], omega, d_omega if uniform else 0.0, shifts[s0:s1], float(fs),
                   bins, block)
        part = scipy.fft.irfft(block, n, axis=-1, workers=workers())
        if s1 - s0 == n_pts:
            return part.astype(real, copy=False)
        if pressure is None:
            pressure = np.empty((n_pts, n), dtype=real)
        pressure[s0:s1] = part
    return pressure if pressure is not None else np.empty((0, n), dtype=real)


@njit(parallel=True, cache=True, nogil=True)
def _band_bins(spec, omega, d_omega, shifts, fs, bins, out):  # pragma: no cover - compiled
    """out[i, bins[b]] = conj(spec[i, b] e^{−iω_b shifts[i]}) fs (parallel over points).
    With ``d_omega`` ≠ 0 (ω uniform with that step) the phasor goes by recurrence: one
    sincos pair per point instead of one per bin (≈ 1e-14 rad after 200 bins)."""
    n_pts, nf = spec.shape
    for i in prange(n_pts):
        s = shifts[i]
        if d_omega != 0.0:
            rot = complex(math.cos(omega[0] * s), -math.sin(omega[0] * s))
            turn = complex(math.cos(d_omega * s), -math.sin(d_omega * s))
            for b in range(nf):
                z = spec[i, b] * rot
                out[i, bins[b]] = complex(z.real * fs, -z.imag * fs)
                rot *= turn
        else:
            for b in range(nf):
                ph = omega[b] * s
                z = spec[i, b] * complex(math.cos(ph), -math.sin(ph))
                out[i, bins[b]] = complex(z.real * fs, -z.imag * fs)


def predict_fields(vt: VirtualTransducer, settings: Sequence[TransmitSetting],
                   points: PlaneGrid | Surface | ArrayLike, *, sampling_rate: float,
                   band_threshold_db: float = -40.0, points_per_wavelength: float = 4.0,
                   guard_time: float = 1e-6, dtype: type = np.float32,
                   offset_tolerance: float = 1e-9, target_chunk: int = 4096,
                   n_samples: int | None = None,
                   frequency_band: tuple[float, float] | None = None,
                   method: str = "auto") -> Iterator[FieldPrediction]:
    """Fields of several transmit settings at the same points, one element response for all.

    Element superposition (see :func:`predict_field`) splits the field into the response
    of one element at the distinct target–element offsets, which does not depend on the
    transmit, and per-transmit weights ``a_e E(ω) e^{iωτ_e}``. Here the response is
    computed once, on the union of the settings' signal bands and one record length
    that holds the longest arrival spread, and each setting only costs the weighted
    sum and the inverse FFTs: a sequence of n transmits costs about one prediction plus
    n cheap assemblies. Per-point time windows (``time_window="local"``).

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    settings : sequence of TransmitSetting
        The transmits (e.g. ``TransmitSequence.settings``).
    points : PlaneGrid or Surface or array_like, shape (n, 3)
        Targets in m.
    sampling_rate : float
        Output rate in Hz (above twice the top of every band).
    band_threshold_db, points_per_wavelength, guard_time, dtype, offset_tolerance, target_chunk
        As in :func:`predict_field`.
    n_samples : int, optional
        Record length (default: the longest arrival spread at ``points``); give it, and
        ``frequency_band``, to make chunks of points or of transmits computed
        separately share one record (what :func:`field_dataset` does).
    frequency_band : (float, float), optional
        Band in Hz to propagate (default: the union of the settings' signal bands).
    method : {"auto", "element"}
        ``"auto"``: targets on lines along x are interpolated from the element lattice
        where that saves work (see :func:`predict_field`, method ``"lattice"``), and
        scattered ones come from the column table (method ``"table"``, one table for
        every setting) where that is cheaper;
        ``"element"``: the element response at every target offset (exact superposition).

    Yields
    ------
    FieldPrediction
        One per setting, in order; the same as ``predict_field(vt, setting, points,
        time_window="local", n_samples=n)`` with the common record length n when the
        settings share their drive.
    """
    if method not in ("auto", "element"):
        raise InputError(f"expected 'auto' or 'element', got {method!r}", field="method")
    pts = _targets(points)
    settings = list(settings)
    if not settings:
        raise InputError("expected at least one transmit setting", field="settings")
    f_lo, f_hi = (union_band(vt, settings, band_threshold_db) if frequency_band is None
                  else (float(frequency_band[0]), float(frequency_band[1])))
    fs = float(sampling_rate)
    if not (math.isfinite(fs) and fs > 2 * f_hi):
        raise InputError(f"expected a sampling rate above twice the top of the band "
                         f"({2 * f_hi:g} Hz), got {fs!r}", field="sampling_rate")
    laws, span = [], 0.0
    for s in settings:
        apod, tau = vt.transmit_weights(s)
        active = np.flatnonzero(apod != 0)
        if active.size == 0:
            raise InputError("every element has zero apodization", field="apodization")
        t_min, t_max = _arrival_bounds(vt, pts, active, tau[active], True)
        tails = (vt.transmit_impulse_response.size / vt.transmit_sampling_rate
                 + s.drive.duration + guard_time)
        span = max(span, float(np.max(t_max - t_min)) + guard_time + tails)
        laws.append((apod, tau, t_min - guard_time))
    n, band, fb = record_band(span, fs, f_lo, f_hi, n_samples)
    real = np.dtype(dtype)
    elements = np.flatnonzero(np.any([law[0] != 0 for law in laws], axis=0))
    table = (scattered_routes(vt, pts, elements, fb, _element_sampling(
        vt, float(fb.max()), points_per_wavelength), offset_tolerance)[0]
        if method == "auto" else np.zeros(pts.shape[0], dtype=bool))
    weights = [apod[elements, None] * drive_spectrum(vt, s, fb)[None, :]
               * np.exp((2j * np.pi) * tau[elements, None] * fb[None, :])
               for s, (apod, tau, _) in zip(settings, laws, strict=True)]
    tabled = (table_spectra(vt, pts[table], fb, elements, weights,
                            points_per_wavelength=points_per_wavelength, dtype=real.type)
              if table.any() else None)
    rest = np.flatnonzero(~table)
    names = []
    if rest.size:
        plan = _plan(vt, pts[rest], elements, fb, points_per_wavelength, offset_tolerance,
                     method == "auto")
        g = element_field(vt, plan.offsets, fb, points_per_wavelength=points_per_wavelength,
                          dtype=real.type, chunk=target_chunk, tables=method == "auto")
        names.append("lattice" if plan.interpolated else "element")
    if tabled is not None:
        names.append("table")
    time = np.arange(n) / fs
    for k, (w, (_, _, offsets_t)) in enumerate(zip(weights, laws, strict=True)):
        spec = np.empty((pts.shape[0], fb.size), dtype=np.result_type(real, np.complex64))
        if rest.size:
            nodes = np.empty((plan.index.shape[1], fb.size), dtype=g.dtype)
            _assemble(g, plan.index, w.astype(g.dtype), nodes)
            spec[rest] = plan.apply(nodes)
        if tabled is not None:
            spec[table] = tabled[k]
        yield FieldPrediction(time, _records(spec, fb, band, n, fs, 0.0, offsets_t, real),
                              pts, (f_lo, f_hi), "+".join(names), offsets_t)


def union_band(vt: VirtualTransducer, settings: Sequence[TransmitSetting],
               threshold_db: float = -40.0) -> tuple[float, float]:
    """Union of the settings' signal bands (:func:`signal_band`) in Hz."""
    bands = [signal_band(vt, s, threshold_db=threshold_db) for s in settings]
    return min(b[0] for b in bands), max(b[1] for b in bands)


def record_length(vt: VirtualTransducer, settings: Sequence[TransmitSetting],
                  points: ArrayLike, sampling_rate: float, *, guard_time: float = 1e-6,
                  chunk: int = 1 << 16) -> int:
    """Record length (samples) :func:`predict_fields` uses for ``settings`` at ``points``.

    The longest arrival spread over the points and settings plus the IR, drive and
    guard durations, at ``sampling_rate`` (Hz), rounded up to a fast FFT length.
    Points are visited in chunks of ``chunk`` (bounded memory for large volumes).
    """
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    span = 0.0
    for s in settings:
        apod, tau = vt.transmit_weights(s)
        active = np.flatnonzero(apod != 0)
        if active.size == 0:
            raise InputError("every element has zero apodization", field="apodization")
        tails = (vt.transmit_impulse_response.size / vt.transmit_sampling_rate
                 + s.drive.duration + guard_time)
        for s0 in range(0, pts.shape[0], chunk):
            t_min, t_max = _arrival_bounds(vt, pts[s0:s0 + chunk], active, tau[active], True)
            span = max(span, float(np.max(t_max - t_min)) + guard_time + tails)
    return next_fast_length(math.ceil(span * float(sampling_rate)))


def arrival_offsets(vt: VirtualTransducer, setting: TransmitSetting, points: ArrayLike, *,
                    guard_time: float = 1e-6) -> NDArray[np.float64]:
    """Start of each point's local record in s (``FieldPrediction.time_offset``), (n,)."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    apod, tau = vt.transmit_weights(setting)
    active = np.flatnonzero(apod != 0)
    t_min, _ = _arrival_bounds(vt, pts, active, tau[active], True)
    return t_min - guard_time


def _element_method(vt: VirtualTransducer, setting: TransmitSetting, pts: NDArray,
                    fb: NDArray, active: NDArray, tau_all: NDArray, apod: NDArray,
                    points_per_wavelength: float, real: np.dtype, tolerance: float,
                    chunk: int, progress: Callable[[int, int], None] | None,
                    lattice: bool = False) -> tuple[NDArray[np.complexfloating], int]:
    """Field spectrum (n_points, nf) by superposing one element's field (see predict_field).

    Also returns the number of targets interpolated from the element lattice.
    """
    plan = _plan(vt, pts, active, fb, points_per_wavelength, tolerance, lattice)
    total = plan.offsets.shape[0] + pts.shape[0]

    def report(done: int, _: int) -> None:
        if progress is not None:
            progress(done, total)

    g = element_field(vt, plan.offsets, fb, points_per_wavelength=points_per_wavelength,
                      dtype=real.type, chunk=chunk, progress=report, tables=lattice)
    complex_dtype = g.dtype
    weights = (apod[active, None] * drive_spectrum(vt, setting, fb)[None, :]
               * np.exp((2j * np.pi) * tau_all[active, None] * fb[None, :]))
    out = np.empty((plan.index.shape[1], fb.size), dtype=complex_dtype)
    _assemble(g, plan.index, weights.astype(complex_dtype), out)
    if progress is not None:
        progress(total, total)
    return plan.apply(out).astype(complex_dtype, copy=False), plan.interpolated


def _plan(vt: VirtualTransducer, pts: NDArray, elements: NDArray, fb: NDArray,
          points_per_wavelength: float, tolerance: float, lattice: bool) -> ElementPlan:
    """:func:`element_plan` for the band ``fb`` with the element's sub-sample count."""
    nx, ny = _element_sampling(vt, float(fb.max()), points_per_wavelength)
    return element_plan(vt, pts, elements, float(fb.max()), lattice=lattice,
                        element_samples=nx * ny, tolerance=tolerance)


def _angular_spectrum_field(vt: VirtualTransducer, setting: TransmitSetting,
                            plane: PlaneGrid, frequencies: NDArray, t0: float,
                            points_per_wavelength: float) -> NDArray[np.complexfloating]:
    """Pressure spectrum on a plane parallel to the array face by the angular spectrum.

    The surface velocity is averaged onto the cells of a source grid with the
    plane's steps (refined by an integer factor until it is at most
    λ/``points_per_wavelength``), propagated with ``propagate_parallel`` (kind
    "vp", no evanescent filter: d > 0), and decimated back to the plane's grid.
    """
    c0 = vt.medium.sound_speed
    dx, dy = plane.dx, plane.dy
    step = c0 / float(frequencies.max()) / points_per_wavelength
    rx, ry = max(1, math.ceil(dx / step - 1e-9)), max(1, math.ceil(dy / step - 1e-9))
    sdx, sdy = dx / rx, dy / ry
    # source grid: the plane's x/y refined, extended to cover the aperture
    fx_lo, fx_hi, fy_lo, fy_hi = vt.face_extent()
    ox, oy = plane.pose.origin[0], plane.pose.origin[1]
    x_lo = min(plane.x[0] + ox, fx_lo) - sdx
    x_hi = max(plane.x[-1] + ox, fx_hi) + sdx
    y_lo = min(plane.y[0] + oy, fy_lo) - sdy
    y_hi = max(plane.y[-1] + oy, fy_hi) + sdy
    i0 = math.floor((x_lo - (plane.x[0] + ox)) / sdx)
    i1 = math.ceil((x_hi - (plane.x[0] + ox)) / sdx)
    j0 = math.floor((y_lo - (plane.y[0] + oy)) / sdy)
    j1 = math.ceil((y_hi - (plane.y[0] + oy)) / sdy)
    gx = plane.x[0] + ox + np.arange(i0, i1 + 1) * sdx
    gy = plane.y[0] + oy + np.arange(j0, j1 + 1) * sdy
    grid = PlaneGrid(gx, gy)
    # sample the velocity finely and accumulate it into the source cells (area average)
    surface, velocity = surface_velocity(vt, setting, frequencies,
                                         points_per_wavelength=4 * points_per_wavelength)
    ix = np.rint((surface.points[:, 0] - gx[0]) / sdx).astype(int)
    iy = np.rint((surface.points[:, 1] - gy[0]) / sdy).astype(int)
    flat = ix * gy.size + iy
    src = np.zeros((gx.size * gy.size, frequencies.size), dtype=complex)
    np.add.at(src, flat, velocity * (surface.weights / (sdx * sdy))[:, None])
    src = src.reshape(gx.size, gy.size, frequencies.size)
    distance = plane.pose.origin[2]
    # periodic images of the source must stay out of the plane's region: pad each axis
    # to the grid extent plus 2·distance (every angle up to 45° off the normal clears)
    pad = (gx.size + math.ceil(2 * distance / sdx), gy.size + math.ceil(2 * distance / sdy))
    out = propagate_parallel(src, grid, frequencies, vt.medium, distance, kind="vp",
                             evanescent=None, padding=pad)
    out = out[-i0::rx][:plane.x.size, -j0::ry][:, :plane.y.size]
    # move the time origin to t0 (a delay of −t0: factor e^{−iωt0})
    out = out * np.exp(-2j * np.pi * frequencies * t0)[None, None, :]
    return out.reshape(plane.size, frequencies.size)
