"""Projection of a field measured on a plane onto any plane or surface.

The fast path of DESIGN.md ("Propagation: the fast path and the exact path"):
the field P(u, v; ω) on a source plane with pose (R, r0) is zero-padded and
Fourier transformed to its angular spectrum P̂(κu, κv). Every propagating
component (|κ| < k) is a plane wave with wave vector k' = (κu, κv, +kz) in plane
coordinates, k = R k' in transducer coordinates, so for any point r

    p(r) = Σ_κ [P̂(κ) e^{−i k·r0} Δκu Δκv / 4π²] e^{i k·r},

and the normal velocity on a surface with unit normal n is the same sum with
each term multiplied by (k·n)/(k ρ0 c0). For targets on a uniform grid of a
plane this is a 2-D type-1 non-uniform FFT; for arbitrary points a 3-D type-3
NUFFT (finufft). The sum is exact for planar source data without evanescent
waves, the same assumption as the backward Rayleigh integral, so it agrees with
the dense Rayleigh oracle to the NUFFT tolerance.

Padding rule
------------
Zero padding to a period L makes the discrete angular spectrum describe the
data repeated every L. An image of the data at lateral distance L influences a
target at distance |w| from the source plane only through waves travelling at
angles θ with |w|·tan θ ≥ the gap between image and target. The padded period
along each in-plane axis is therefore chosen as

    L ≥ (extent of the union of the data and the target, projected on the
         source plane) + 2 |w|_max tan(guard_angle) + one step,

rounded up to a fast FFT length, with ``guard_angle`` (default 80°) a keyword.
Energy travelling at larger angles (rare in a measurement that captures the
field) can still alias; raise ``guard_angle`` or pass ``padding`` explicitly.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Literal

import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

from holoprobe._progress import progress_iter
from holoprobe.errors import InputError
from holoprobe.geometry import Medium, PlaneGrid, Surface
from holoprobe.signal import next_fast_length, workers

__all__ = ["padded_shape", "project"]

Quantity = Literal["pressure", "normal_velocity"]
Method = Literal["auto", "nufft", "rayleigh", "angular_spectrum"]

_PLANE_TOL = 1e-9  # m: a target closer than this to the source plane lies on it


def _validate_field(field: ArrayLike, source: PlaneGrid, frequencies: ArrayLike
                    ) -> tuple[NDArray, NDArray[np.float64]]:
    if not isinstance(source, PlaneGrid):
        raise InputError("expected a holoprobe.PlaneGrid for the source plane", field="source")
    freqs = np.atleast_1d(np.asarray(frequencies, dtype=float))
    if freqs.ndim != 1:
        raise InputError(f"expected a 1-D vector of frequencies, got shape {freqs.shape}",
                         field="frequencies")
    if not np.all(np.isfinite(freqs)) or np.any(freqs <= 0):
        raise InputError("expected finite, positive frequencies in Hz", field="frequencies")
    arr = np.asarray(field)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    expected = (*source.shape, freqs.size)
    if arr.shape != expected:
        raise InputError(
            f"expected shape (nx, ny, nf) = {expected} to match the source grid and the "
            f"frequencies, got {arr.shape}",
            field="field",
        )
    if not np.all(np.isfinite(arr)):
        raise InputError("contains NaN or inf", field="field")
    if source.x.size < 2 or source.y.size < 2:
        raise InputError("the source grid needs at least 2 points along x and y",
                         field="source")
    return arr, freqs


def _check_sampling(source: PlaneGrid, freqs: NDArray, medium: Medium,
                    allow_undersampled: bool) -> None:
    wavelength = medium.sound_speed / freqs.max()
    step = max(source.dx, source.dy)
    if step > wavelength / 2 * (1 + 1e-9) and not allow_undersampled:
        raise InputError(
            f"scan step {step * 1e3:.4g} mm is coarser than λ/2 = {wavelength / 2 * 1e3:.4g} mm "
            f"at the highest frequency {freqs.max() / 1e6:.4g} MHz; lower the band or pass "
            "allow_undersampled=True",
            field="source",
        )


def _target_local(source: PlaneGrid, target: PlaneGrid | Surface) -> NDArray[np.float64]:
    """Target points in source-plane coordinates (u, v, w), shape (n, 3)."""
    points = target.points() if isinstance(target, PlaneGrid) else target.points
    return source.pose.to_local(points)


def _direction(local: NDArray[np.float64]) -> Literal["forward", "backward", "on_plane"]:
    w = local[:, 2]
    if np.all(np.abs(w) <= _PLANE_TOL):
        return "on_plane"
    if np.all(w >= -_PLANE_TOL):
        return "forward"
    if np.all(w <= _PLANE_TOL):
        return "backward"
    raise InputError(
        f"the target straddles the source plane (its points lie from w = {w.min() * 1e3:.4g} "
        f"to {w.max() * 1e3:.4g} mm along the source normal); split it into the parts in front "
        "of and behind the plane",
        field="target",
    )


def padded_shape(source: PlaneGrid, target: PlaneGrid | Surface, *,
                 guard_angle: float = np.deg2rad(80.0),
                 padding: float | tuple[int, int] | None = None) -> tuple[int, int]:
    """Zero-padded grid size for projecting from ``source`` onto ``target``.

    Parameters
    ----------
    source : PlaneGrid
        The plane holding the data.
    target : PlaneGrid or Surface
        Where the field is wanted.
    guard_angle : float
        Largest propagation angle (rad) whose periodic images are kept away from the
        target (see the module notes).
    padding : float or (int, int), optional
        Override: a factor applied to the source size, or an explicit shape.

    Returns
    -------
    (int, int)
        Padded size (npx, npy), at least the source size, FFT friendly.
    """
    nx, ny = source.shape
    if padding is not None:
        if np.ndim(padding) == 0:
            factor = float(padding)  # type: ignore[arg-type]
            if not factor >= 1:
                raise InputError("a padding factor must be ≥ 1", field="padding")
            shape = (int(np.ceil(nx * factor)), int(np.ceil(ny * factor)))
        else:
            shape = tuple(int(v) for v in padding)  # type: ignore[union-attr]
            if len(shape) != 2 or shape[0] < nx or shape[1] < ny:
                raise InputError(f"expected (npx, npy) ≥ {(nx, ny)}, got {padding}",
                                 field="padding")
        return (next_fast_length(shape[0]), next_fast_length(shape[1]))
    if not 0 <= guard_angle < np.pi / 2:
        raise InputError("expected an angle in [0, π/2) rad", field="guard_angle")
    local = _target_local(source, target)
    w_max = np.max(np.abs(local[:, 2]))
    guard = 2.0 * w_max * np.tan(guard_angle)
    sizes = []
    for axis, coords, step in ((0, source.x, source.dx), (1, source.y, source.dy)):
        # an image of the data shifted by L must stay `guard` away from the target:
        # L ≥ (extent of data ∪ target) + guard
        union = max(coords[-1], local[:, axis].max()) - min(coords[0], local[:, axis].min())
        n_min = int(np.ceil((union + guard) / step)) + 1
        sizes.append(next_fast_length(max(n_min, coords.size)))
    return (sizes[0], sizes[1])


def _wave_vectors(kx: NDArray, ky: NDArray, k: float
                  ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """Indices and kz of the propagating components |κ| < k of a (kx, ky) grid."""
    kr2 = kx[:, None] ** 2 + ky[None, :] ** 2
    ix, iy = np.nonzero(kr2 < k * k)
    kz = np.sqrt(k * k - kr2[ix, iy])
    return ix, iy, kz


class _PlaneTransform:
    """Σ_j c_j exp(i k_j · r) on the points r of a target plane grid (2-D type-1 NUFFT).

    The plane waves are those of a padded angular spectrum on the source plane; the
    strengths and NUFFT coordinates come from one fused numba pass over the spectrum
    (:func:`holoprobe.propagation._project_numba.plane_wave_terms`). One instance per
    thread: it owns a single-threaded finufft plan (threads work on different
    frequencies, which scales better than finufft's own threads on small problems).
    """

    def __init__(self, source: PlaneGrid, target: PlaneGrid, kx: NDArray, ky: NDArray,
                 eps: float, dtype: type, *, velocity: bool, time_origin: float,
                 impedance: float, scale: float):
        import finufft

        nxt, nyt = target.shape
        dxt = target.dx if nxt > 1 else 1.0
        dyt = target.dy if nyt > 1 else 1.0
        # finufft's output index m carries mode m − n//2: reference the phase there
        ref = np.array([target.x[0] + (nxt // 2) * dxt, target.y[0] + (nyt // 2) * dyt, 0.0])
        rs, rt = source.pose.rotation, target.pose.rotation
        to_target = rt.T @ rs  # local source wave vector → components along the target axes
        # phase of each plane wave: −κ·(x0, y0) on the source grid, −k·r0_s for the source
        # pose, +k·r0_t + q·ref for the target grid; all linear in k' = (κx, κy, kz)
        self.phase_vector = (-np.array([source.x[0], source.y[0], 0.0])
                             + rs.T @ (target.pose.origin_array - source.pose.origin_array)
                             + to_target.T @ ref)
        self.time_origin = time_origin
        self.x_map = to_target[0] * dxt
        self.y_map = to_target[1] * dyt
        self.velocity = velocity
        self.velocity_vector = rs.T @ target.pose.normal / impedance
        self.scale = scale
        self.dtype = dtype
        self.real = np.float32 if dtype == np.complex64 else np.float64
        self.plan = finufft.Plan(1, (nxt, nyt), eps=eps, isign=1, dtype=dtype, nthreads=1)
        self.kx = np.ascontiguousarray(kx, dtype=float)
        self.ky = np.ascontiguousarray(ky, dtype=float)
        size = kx.size * ky.size
        self.c = np.empty(size, dtype)
        self.xs = np.empty(size, self.real)
        self.ys = np.empty(size, self.real)

    def __call__(self, spectrum: NDArray, k: float) -> NDArray | None:
        from holoprobe.propagation._project_numba import plane_wave_terms

        count = plane_wave_terms(spectrum, self.kx, self.ky, k, self.phase_vector,
                                 -k * self.time_origin, self.x_map, self.y_map,
                                 self.velocity_vector / k, self.velocity, self.scale,
                                 self.c, self.xs, self.ys)
        if count == 0:
            return None
        xs, ys = self.xs[:count], self.ys[:count]
        if max(np.abs(xs).max(), np.abs(ys).max()) >= 3 * np.pi:  # finufft wants [−3π, 3π)
            np.mod(xs + np.pi, 2 * np.pi, out=xs)
            xs -= np.pi
            np.mod(ys + np.pi, 2 * np.pi, out=ys)
            ys -= np.pi
        self.plan.setpts(xs, ys)
        return self.plan.execute(self.c[:count])


class _PointTransform:
    """Σ_j c_j exp(i φ_j) exp(i k_j · r) at arbitrary points r (3-D type-3 NUFFT)."""

    def __init__(self, points: NDArray[np.float64], eps: float, dtype: type, n_trans: int = 1):
        import finufft

        self.centre = 0.5 * (points.max(axis=0) + points.min(axis=0))
        self.real = np.float32 if dtype == np.complex64 else np.float64
        self.shifted = np.ascontiguousarray((points - self.centre).T, dtype=self.real)
        self.dtype = dtype
        self.plan = finufft.Plan(3, 3, n_trans=n_trans, eps=eps, isign=1, dtype=dtype,
                                 nthreads=1)

    def __call__(self, coef: NDArray, kvec: NDArray[np.float64], phase: NDArray) -> NDArray:
        c = np.ascontiguousarray(coef * np.exp(1j * (phase + kvec @ self.centre)),
                                 dtype=self.dtype)
        kt = np.ascontiguousarray(kvec.T, dtype=self.real)
        s = self.shifted
        self.plan.setpts(kt[0], kt[1], kt[2], s[0], s[1], s[2])
        return self.plan.execute(c)


def _project_nufft(field: NDArray, source: PlaneGrid, target: PlaneGrid | Surface,
                   freqs: NDArray, medium: Medium, *, quantity: Quantity, eps: float,
                   shape: tuple[int, int], time_origin: float, max_memory: int,
                   single_precision: bool, progress: bool | None) -> NDArray[np.complex128]:
    npx, npy = shape
    dx, dy = source.dx, source.dy
    kx = 2 * np.pi * np.fft.fftfreq(npx, dx)
    ky = 2 * np.pi * np.fft.fftfreq(npy, dy)
    dkx, dky = 2 * np.pi / (npx * dx), 2 * np.pi / (npy * dy)
    scale = dx * dy * dkx * dky / (4 * np.pi**2)
    rot = source.pose.rotation
    r0 = source.pose.origin_array
    is_plane = isinstance(target, PlaneGrid)
    velocity = quantity == "normal_velocity"
    cdtype = np.complex64 if single_precision else np.complex128
    n_threads = workers()
    if is_plane:
        transforms = [_PlaneTransform(source, target, kx, ky, eps, cdtype, velocity=velocity,
                                      time_origin=time_origin, impedance=medium.impedance,
                                      scale=scale)
                      for _ in range(n_threads)]
        out = np.zeros((*target.shape, freqs.size), dtype=np.complex128)
    else:
        transforms = [_PointTransform(target.points, eps, cdtype, 3 if velocity else 1)
                      for _ in range(n_threads)]
        out = np.zeros((target.size, freqs.size), dtype=np.complex128)

    def one_frequency(transform, spectrum: NDArray, n: int) -> None:
        k = 2 * np.pi * freqs[n] / medium.sound_speed
        if is_plane:
            result = transform(spectrum, k)
            if result is not None:
                out[:, :, n] = result
            return
        ix, iy, kz = _wave_vectors(kx, ky, k)
        if ix.size == 0:
            return
        kvec = np.stack([kx[ix], ky[iy], kz], axis=-1) @ rot.T  # transducer coordinates
        # P̂(κ) = Σ P(x_i, y_j) e^{−iκ·(x_i, y_j)} dx dy (the grid's own coordinates),
        # the plane origin r0 and the time origin enter as phases
        phase = -(kx[ix] * source.x[0] + ky[iy] * source.y[0] + kvec @ r0 + k * time_origin)
        coef = spectrum[ix, iy] * scale
        if velocity:
            stacked = (kvec.T / (k * medium.impedance)) * coef[None, :]
            out[:, n] = np.einsum("dn,nd->n", transform(stacked, kvec, phase), target.normals)
        else:
            out[:, n] = transform(coef, kvec, phase)

    def worker(index: int, spectra: NDArray, start: int, stop: int) -> None:
        for j in range(start + index, stop, n_threads):
            one_frequency(transforms[index], spectra[j - start], j)

    # padded spectra are computed a few frequencies at a time in one reused buffer (no
    # page faults, cache friendly): the data go into its corner, the y-transform runs
    # over the data rows only, the x-transform over all rows
    nx, ny = source.shape
    chunk = int(max(1, min(4 * n_threads, max_memory // (16 * npx * npy), freqs.size)))
    buffer = np.empty((chunk, npx, npy), dtype=np.complex128)
    starts = range(0, freqs.size, chunk)
    with ThreadPoolExecutor(max_workers=n_threads) as pool:
        for start in progress_iter(starts, description="projecting", enabled=progress):
            stop = min(start + chunk, freqs.size)
            spectra = buffer[: stop - start]
            spectra.fill(0.0)
            spectra[:, :nx, :ny] = np.moveaxis(field[:, :, start:stop], 2, 0)
            spectra[:, :nx, :] = scipy.fft.fft(spectra[:, :nx, :], axis=2, workers=n_threads)
            spectra[:] = scipy.fft.fft(spectra, axis=1, overwrite_x=True, workers=n_threads)
            for future in [pool.submit(worker, i, spectra, start, stop)
                           for i in range(n_threads)]:
                future.result()
    return out


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
                      dtype: type) -> NDArray[np.complex128]:
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
) -> NDArray[np.complex128]:
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
        Padding rule parameter in rad (see module notes).
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
    ndarray, complex128
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
