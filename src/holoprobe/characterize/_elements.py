"""Per-element map of an array from its back-projected surface velocity.

The back-projected normal velocity ``V(x, y; f)`` on z = 0, integrated over y, is the
``k_y = 0`` slice of its angular spectrum: a 1-D line field ``L(x; f)`` in which every
element of an array is a strip of width w at ``x_e = x_c + (e − (N−1)/2)·p``. The line
field is modelled as ``L = Σ_e c_e(f) b_e(x; f)`` with the basis ``b_e`` the strip's
field carried forward to the scan, cut to the scan's footprint and carried back again
exactly as the back-projection did (1-D angular spectrum, only |k_x| < k back). Two
details of the real measurement are in the basis because they change it visibly:

* the plane of sharpest focus (the face) lies ``δ`` in front of z = 0 (towards the
  scan; δ < 0: behind it): the transmit pipeline puts the detected onset of the mean
  velocity at t = 0 (paper section II F), so z = 0 is a virtual plane set by the
  onset, not by the face (a defocus that grows with k_x; −0.4 mm on the 96-element
  twin: searched on both sides, see :func:`_coarse_start`);
* the water's true sound speed ``c`` may differ from the file's ``c_f``: the
  back-projection then uses the wrong ``k_z`` for the non-paraxial waves, a defocus of
  another shape (paper section II B, angular spectrum). Fitting ``c`` is the sound
  speed *from the data*.

For fixed array centre ``x_c``, offset ``δ``, sound speed ``c`` and pitch ``p`` the
coefficients ``c_e(f)`` follow by (lightly regularised) linear least squares per bin;
the four non-linear parameters minimise the residual (variable projection). Only bins
with ``k·p ≥ min_resolution·π`` resolve neighbouring elements and take part. Each
element's coefficients are then ``A_e U(f) e^{iωτ_e}``: relative amplitude A_e (live
mean 1), delay τ_e (live mean 0), and the common spectrum U.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
import scipy.fft
import scipy.linalg
import scipy.optimize
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import FitError, InputError
from holoprobe.geometry import PlaneGrid
from holoprobe.signal import Threads, blas_threads, workers

__all__ = ["ElementMap", "LineGeometry", "array_aperture", "channel_levels",
           "element_coefficients",
           "element_map_with_sound_speed", "fit_element_map", "fit_sound_speed_stencil",
           "line_field",
           "resolve_edge_ambiguity", "scan_footprint", "sound_speed_from_data",
           "steering_uncertainty"]


def line_field(velocity: ArrayLike, grid: PlaneGrid) -> NDArray[np.complex128]:
    """``∫ V(x, y; f) dy`` over the grid, shape (nx, nf) (units of V times m)."""
    v = np.asarray(velocity)
    if v.ndim != 3 or v.shape[:2] != grid.shape:
        raise InputError(f"expected shape {grid.shape} + (nf,), got {v.shape}",
                         field="velocity")
    return v.sum(axis=1).astype(np.complex128) * grid.dy


@dataclass(frozen=True)
class LineGeometry:
    """The 1-D propagation problem behind a line field.

    Attributes
    ----------
    x : ndarray, shape (nx,)
        Source-grid coordinates of the line field in m (uniform step).
    footprint : (float, float)
        x-range in m of the scan on the source frame (outside it nothing was measured).
    distance : float
        Back-projection distance z0 in m (scan plane to z = 0).
    sound_speed : float
        Sound speed c_f (m/s) the back-projection used.
    local : callable, optional
        Per-element view of the scan (a curved face, whose elements see the scan plane
        each under its own angles): ``local(centers) -> (lo, hi, distance)``, arrays
        (N,) in m: each element's strip basis is carried to a scan parallel to it at
        ``distance`` and cut to ``[lo, hi]`` (the footprint in the line's coordinate
        that subtends, from the element, the angles under which it sees the real
        scan's edges). None: every element sees ``footprint`` at ``distance``.
    """

    x: NDArray[np.float64]
    footprint: tuple[float, float]
    distance: float
    sound_speed: float
    n_pad: int = 0
    kx: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    offset: int = 0
    local: Callable[[NDArray], tuple[NDArray, NDArray, NDArray]] | None = None

    @classmethod
    def build(cls, x: ArrayLike, footprint: tuple[float, float], distance: float,
              sound_speed: float, local: Callable | None = None) -> LineGeometry:
        """Pad the line so that the periodic images stay away (80° spread each way)."""
        x = np.asarray(x, dtype=float)
        if x.size < 4:
            raise InputError("expected at least 4 points along x", field="grid")
        dx = float(x[1] - x[0])
        span = (x[-1] - x[0]) + 2.0 * abs(distance) * np.tan(np.deg2rad(80.0))
        n = 1
        while n < 2 * x.size + span / dx:
            n *= 2
        kx = np.asarray(2.0 * np.pi * np.fft.fftfreq(n, dx), dtype=np.float64)
        return cls(x, (float(footprint[0]), float(footprint[1])), float(distance),
                   float(sound_speed), n, kx, (n - x.size) // 2, local)

    @property
    def step(self) -> float:
        return float(self.x[1] - self.x[0])

    def padded_x(self) -> NDArray[np.float64]:
        return self.x[0] + self.step * (np.arange(self.n_pad) - self.offset)

    @property
    def mask(self) -> NDArray[np.float64]:
        """1 where the padded line lies inside the scan footprint, else 0."""
        xp = self.padded_x()
        return ((xp >= self.footprint[0]) & (xp <= self.footprint[1])).astype(float)

    def element_views(self, centers: NDArray
                      ) -> tuple[NDArray[np.complex128], NDArray[np.float64] | None]:
        """Masks of the padded line, (n_pad,) or (N, n_pad) with ``local``, and the
        elements' distances (N,) (None without ``local``)."""
        if self.local is None:
            return self.mask.astype(complex), None
        lo, hi, distance = (np.asarray(a, dtype=float) for a in self.local(centers))
        xp = self.padded_x()
        mask = (xp >= lo[:, None]) & (xp <= hi[:, None])
        return mask.astype(complex), distance


def _inv_kz(kx: NDArray, k: float, dk: float) -> NDArray[np.complex128]:
    """``k/k_z`` averaged over each k_x bin of width ``dk`` (``k_z = √(k² − k_x²)``,
    ``+i|·|`` when evanescent): the pressure-from-velocity factor ``ρω/k_z`` of a strip,
    integrable but singular at grazing, where point samples would be arbitrary."""
    def primitive(u: NDArray) -> NDArray[np.complex128]:  # ∫ k du / √(k² − u²), u ≥ 0
        inside = u <= k
        out = np.empty(u.shape, complex)
        out[inside] = k * np.arcsin(u[inside] / k)
        out[~inside] = k * (0.5 * np.pi - 1j * np.arccosh(u[~inside] / k))
        return out
    a = np.abs(kx)
    lo = np.maximum(a - 0.5 * dk, 0.0)
    hi = a + 0.5 * dk
    return (primitive(hi) - primitive(lo)) / (hi - lo)


_GL_NODES, _GL_WEIGHTS = np.polynomial.legendre.leggauss(8)


def _inv_kz_propagator(kx: NDArray, k: float, dk: float, z: float
                       ) -> NDArray[np.complex128]:
    """``(k/k_z) e^{i k_z z}`` averaged over each k_x bin of width ``dk`` (``z`` ≥ 0 m).

    Near grazing the phase ``k_z z`` turns by radians within one bin of a short padded
    line (5.8 rad at z = 3.9 mm, k = 1.4e4 rad/m, dk = 82 rad/m): the product of the
    bin averages of ``k/k_z`` and of the phase is then wrong by a part that jumps each
    time k crosses a bin edge, i.e. every few m/s of the trial sound speed (the
    residual of a 16-element twin oscillated with a 9 m/s period and its c fit fell
    22 m/s low). With ``k_x = k sin θ`` (propagating) and ``k_x = k cosh t``
    (evanescent), ``(k/k_z) dk_x`` is ``k dθ`` and ``−i k dt``: smooth integrands,
    averaged here with 8-point Gauss–Legendre on each part of each bin."""
    a = np.abs(kx)
    lo = np.maximum(a - 0.5 * dk, 0.0)
    hi = a + 0.5 * dk
    x, w = _GL_NODES[:, None], 0.5 * _GL_WEIGHTS[:, None]
    # propagating part: θ from asin(lo/k) to asin(min(hi, k)/k)
    t0 = np.arcsin(np.minimum(lo, k) / k)
    t1 = np.arcsin(np.minimum(hi, k) / k)
    th = 0.5 * (t0 + t1) + 0.5 * (t1 - t0) * x
    prop = k * (t1 - t0) * np.sum(w * np.exp(1j * k * z * np.cos(th)), axis=0)
    # evanescent part: t from acosh(max(lo, k)/k) to acosh(hi/k)
    u0 = np.arccosh(np.maximum(lo, k) / k)
    u1 = np.arccosh(np.maximum(hi, k) / k)
    u = 0.5 * (u0 + u1) + 0.5 * (u1 - u0) * x
    evan = -1j * k * (u1 - u0) * np.sum(w * np.exp(-k * z * np.sinh(u)), axis=0)
    return (prop + evan) / (hi - lo)


def _basis(geo: LineGeometry, shifts: NDArray, width: float, frequency: float,
           offset: float, sound_speed: float, mask: NDArray | None = None,
           distance: NDArray | None = None, fft_workers: int = -1
           ) -> NDArray[np.complex128]:
    """Back-projected line fields of unit strips, shape (nx, N) (see module notes).

    ``shifts`` is ``exp(−i k_x (x_e − x_pad0))`` laid out (N, n_pad), shared by all bins
    (each element's row contiguous: the transforms run along rows). ``mask`` is
    ``geo.mask`` as complex (computed here when not given), or one row per element
    with ``distance`` (N,) (:meth:`LineGeometry.element_views`). ``fft_workers``:
    threads of each ``scipy.fft`` call (-1: all cores). A flat face's transforms run
    in the type of ``shifts`` (complex64: ~1e-7 relative); the result is complex128.
    The strip's normal velocity radiates pressure ``ρω/k_z`` in the true water and the
    back-projection turns pressure into velocity with the file's ``k_z/ρω``: at a wrong
    c the steep waves keep a gain ``k_z,f/k_z,t`` besides their phase error.
    """
    kx = geo.kx
    k_f = 2.0 * np.pi * frequency / geo.sound_speed
    k_t = 2.0 * np.pi * frequency / sound_speed
    # forward over the true distance in the true water; the face lies δ in front of z=0
    kz_f = np.sqrt(np.abs(k_f**2 - kx**2))
    sinc = width * np.sinc(kx * width / (2.0 * np.pi)) / geo.step
    if distance is not None:
        assert mask is not None  # one row per element (LineGeometry.element_views)
        kz_t = np.sqrt(k_t**2 - kx**2 + 0j)
        inv_kz = _inv_kz(kx, k_t, abs(float(kx[1] - kx[0])))
        return _local_basis(geo, shifts, inv_kz * sinc, kz_t, kz_f, k_f, offset,
                            sound_speed, mask, distance, fft_workers)
    z_true = (geo.distance - offset) * sound_speed / geo.sound_speed
    fwd = _inv_kz_propagator(kx, k_t, abs(float(kx[1] - kx[0])), z_true) * sinc
    # the transforms overwrite their inputs (no fresh (N, n_pad) array per step)
    dtype = shifts.dtype
    line = shifts * fwd.astype(dtype)[None, :]
    line = scipy.fft.ifft(line, axis=1, workers=fft_workers, overwrite_x=True)
    line *= (geo.mask if mask is None else mask).astype(dtype)[None, :]
    back = np.where(np.abs(kx) < k_f, kz_f / k_f * np.exp(-1j * kz_f * geo.distance), 0.0)
    line = scipy.fft.fft(line, axis=1, workers=fft_workers, overwrite_x=True)
    line *= back.astype(dtype)[None, :]
    out = scipy.fft.ifft(line, axis=1, workers=fft_workers, overwrite_x=True)
    return np.array(out[:, geo.offset:geo.offset + geo.x.size].T, dtype=np.complex128,
                    order="C")


def _local_basis(geo: LineGeometry, shifts: NDArray, strip: NDArray, kz_t: NDArray,
                 kz_f: NDArray, k_f: float, offset: float, sound_speed: float,
                 mask: NDArray, distance: NDArray, fft_workers: int = -1
                 ) -> NDArray[np.complex128]:
    """:func:`_basis` with each element's own distance (N,) and mask (N, n_pad): the
    propagator e^{i k_z D_e} is computed once per element and, in the file's water (the
    convex case), its conjugate carries the field back."""
    ratio = sound_speed / geo.sound_speed
    prop = np.exp(1j * np.multiply.outer(distance * ratio, kz_t))
    fwd = np.exp(-1j * kz_t * offset * ratio) * strip
    line = scipy.fft.ifft(shifts * prop * fwd[None, :], axis=1, workers=fft_workers)
    line *= mask
    inside = np.abs(geo.kx) < k_f
    back = np.where(inside, kz_f / k_f, 0.0)
    if ratio == 1.0:
        back_prop = prop.conj()
    else:
        back_prop = np.exp(-1j * np.multiply.outer(distance, kz_f))
    spec = scipy.fft.fft(line, axis=1, workers=fft_workers)
    spec *= back_prop
    spec *= back[None, :]
    out = scipy.fft.ifft(spec, axis=1, workers=fft_workers)
    return np.ascontiguousarray(out[:, geo.offset:geo.offset + geo.x.size].T)


_LATTICES: dict[tuple[int, float, int, float], NDArray[np.complex128]] = {}


def _element_shifts(geo: LineGeometry, count: int, pitch: float, center: float
                    ) -> NDArray[np.complex128]:
    """``exp(−i k_x (x_e − x_pad0))`` of the ``count`` element centres at ``pitch`` (m)
    around ``center`` (m), shape (N, n_pad): the array's ``e^{−i k_x (x_c − x_pad0)}``
    times the lattice's ``e^{−i k_x (e − (N − 1)/2) p}``, which depends on N, p and the
    padded line only and is kept for the last few of those (the map's searches move
    x_c and δ at a fixed pitch: one exponential of n_pad values per call, not N·n_pad)."""
    key = (int(count), float(pitch), int(geo.n_pad), float(geo.kx[1]))
    lattice = _LATTICES.get(key)
    if lattice is None:
        offsets = (np.arange(count) - 0.5 * (count - 1)) * pitch
        lattice = np.exp(-1j * np.outer(offsets, geo.kx))
        if len(_LATTICES) >= 8:
            _LATTICES.clear()
        _LATTICES[key] = lattice
    return lattice * np.exp(-1j * geo.kx * (center - geo.padded_x()[0]))[None, :]


_POOL: list[ThreadPoolExecutor] = []


def _bin_pool() -> ThreadPoolExecutor:
    """Threads that :func:`element_coefficients` shares its bins with (made once: the
    map calls it a few hundred times per run)."""
    if not _POOL:
        _POOL.append(ThreadPoolExecutor(max_workers=max(1, workers() - 1),
                                        thread_name_prefix="holoprobe-element-bins"))
    return _POOL[0]


def element_coefficients(line: NDArray, geo: LineGeometry, frequencies: NDArray, *,
                         count: int, pitch: float, width: float, center: float,
                         offset: float = 0.0, sound_speed: float | None = None,
                         ridge: float = 1e-4, per_bin: bool = False,
                         misfit_out: NDArray | None = None, noise: bool = True,
                         single: bool = False
                         ) -> tuple[NDArray, float | NDArray, NDArray]:
    """Per-bin least-squares element coefficients of a line field.

    Parameters
    ----------
    line : ndarray, complex, shape (nx, nb)
        :func:`line_field` at ``frequencies``.
    geo : LineGeometry
    frequencies : ndarray, shape (nb,)
        Hz.
    count, pitch, width, center : int, float, float, float
        N, p (m), element width w (m), array centre x_c (m).
    offset : float
        δ in m (the face lies δ in front of z = 0, towards the scan).
    sound_speed : float, optional
        True water sound speed (m/s); default the back-projection's.
    ridge : float
        Tikhonov weight relative to the mean diagonal of BᴴB.
    per_bin : bool
        Return the residual of every bin (``‖L − Bc‖² / Σ‖L‖²``, shape (nb,), summing
        to the total) instead of the total.
    misfit_out : ndarray, complex, shape (nx, nb), optional
        Filled with the misfit ``L − Bc`` of every bin (the residual vector of a
        least-squares fit of the non-linear parameters).
    noise : bool
        Compute ``noise_variance`` (an explicit inverse of BᴴB + λ per bin); False
        (a residual or misfit only) solves by a Cholesky factorisation and returns
        zeros for it (~0.5 ms less per bin at 96 elements).
    single : bool
        A flat face's strip basis transformed in single precision (~1e-7 relative; the
        coarse start's grid searches), the solve in double.

    Returns
    -------
    coefficients : ndarray, complex, shape (N, nb)
    residual : float or ndarray
        ``Σ‖L − Bc‖² / Σ‖L‖²`` (per bin when ``per_bin``).
    noise_variance : ndarray, shape (N, nb)
        Variance of c_e(f) if the misfit ``L − Bc`` of each bin were noise correlated
        over half a wavelength: ``s² · m · diag((BᴴB + λ)⁻¹ BᴴB (BᴴB + λ)⁻¹)`` with
        ``s²`` the misfit power per sample and ``m`` the samples per half wavelength.
    """
    c = geo.sound_speed if sound_speed is None else float(sound_speed)
    centers = center + (np.arange(count) - 0.5 * (count - 1)) * pitch
    shifts = _element_shifts(geo, count, pitch, center)
    mask, distance = geo.element_views(centers)
    if single and distance is None:  # a flat face: its basis transforms in complex64
        shifts, mask = shifts.astype(np.complex64), mask.astype(np.complex64)
    nb = frequencies.size
    coef = np.zeros((count, nb), complex)
    gain = np.zeros((count, nb))
    res = np.zeros(nb)
    norms = np.zeros(nb)
    eye = np.eye(count)
    n_threads = min(workers(), nb)
    fft_workers = 1 if n_threads > 1 else -1  # threads over the bins, not within an FFT

    def fit_bins(first: int) -> None:  # every n_threads-th bin from first
        for j in range(first, nb, n_threads):
            f = float(frequencies[j])
            b = _basis(geo, shifts, width, f, offset, c, mask, distance, fft_workers)
            bh = b.conj().T
            a = bh @ b
            reg = a + ridge * np.trace(a).real / count * eye
            if noise:
                inv = np.linalg.inv(reg)
                coef[:, j] = inv @ (bh @ line[:, j])
            else:  # BᴴB + λ is Hermitian positive definite
                coef[:, j] = scipy.linalg.cho_solve(scipy.linalg.cho_factor(reg),
                                                    bh @ line[:, j])
            diff = line[:, j] - b @ coef[:, j]
            if misfit_out is not None:
                misfit_out[:, j] = diff
            misfit = float(np.linalg.norm(diff) ** 2)
            if noise:
                per_sample = misfit / line.shape[0] * max(1.0, 0.5 * c / f / geo.step)
                gain[:, j] = per_sample * np.real(np.sum((inv @ a) * inv.conj(), axis=1))
            res[j] = misfit
            norms[j] = float(np.linalg.norm(line[:, j]) ** 2)

    with blas_threads(1):  # N × N products per bin: BLAS threads only cost
        # the bins are independent (FFTs and LAPACK release the GIL): this thread takes
        # every n_threads-th bin, the module's pool the others (all joined on leaving)
        with Threads(pool=_bin_pool()) as others:
            for i in range(1, n_threads):
                others.submit(fit_bins, i)
            fit_bins(0)
    total = 0.0
    for value in norms:  # summed in bin order, as one loop would
        total += float(value)
    res /= max(total, 1e-300)
    return coef, (res if per_bin else float(res.sum())), gain


@dataclass(frozen=True)
class ElementMap:
    """Every element's relative amplitude and delay (RF column order, 0-based).

    Attributes
    ----------
    relative_amplitude, amplitude_uncertainty : ndarray, shape (N,)
        A_e relative to the mean of the live (neither dead nor weak) elements, and its
        standard uncertainty.
    delay, delay_uncertainty : ndarray, shape (N,)
        τ_e in s, the live mean removed (a later element has a positive delay).
    dead, weak : tuple of int
        Indices below ``dead_threshold`` / ``weak_threshold``.
    center_x : float
        Array centre on the source frame in m.
    pitch, element_width : float
        m (the pitch refined when asked).
    focus_offset : float
        δ in m: the face (sharpest plane) lies this far in front of z = 0 (towards
        the scan; negative: behind).
    sound_speed, sound_speed_uncertainty : float
        Water sound speed from the data (m/s; NaN when not fitted) and its standard
        uncertainty.
    residual : float
        Relative residual of the line-field model.
    frequencies : ndarray, shape (nb,)
        Bins used (Hz).
    coefficients : ndarray, complex, shape (N, nb)
        c_e(f).
    ambiguous : bool
        An edge element is dead and the array shifted by one pitch (the other edge dead)
        explains the field as well: the transmit scan alone cannot tell the two apart.
    """

    relative_amplitude: NDArray[np.float64]
    amplitude_uncertainty: NDArray[np.float64]
    delay: NDArray[np.float64]
    delay_uncertainty: NDArray[np.float64]
    dead: tuple[int, ...]
    weak: tuple[int, ...]
    center_x: float
    pitch: float
    element_width: float
    focus_offset: float
    sound_speed: float
    sound_speed_uncertainty: float
    residual: float
    frequencies: NDArray[np.float64]
    coefficients: NDArray[np.complex128]
    ambiguous: bool = False

    @property
    def count(self) -> int:
        return int(self.relative_amplitude.size)

    @property
    def offsets(self) -> NDArray[np.float64]:
        """Element centres along the array (m), relative to the array's centre."""
        return np.asarray((np.arange(self.count) - 0.5 * (self.count - 1)) * self.pitch,
                          dtype=np.float64)

    @property
    def live(self) -> NDArray[np.bool_]:
        """True for elements that are neither dead nor weak."""
        mask = np.ones(self.count, bool)
        mask[list(self.dead) + list(self.weak)] = False
        return mask

    @property
    def active_width(self) -> float:
        """Outer-edge width (m) of the span from the first to the last non-dead element."""
        alive = np.setdiff1d(np.arange(self.count), self.dead)
        if alive.size == 0:
            return 0.0
        return float((alive[-1] - alive[0]) * self.pitch + self.element_width)

    def delay_response(self, frequencies: ArrayLike) -> NDArray[np.complex128]:
        """The amplitude-weighted mean of the elements' delay factors,
        ``D(f) = Σ A_e e^{iωτ_e} / Σ A_e`` (dead elements and non-finite delays weigh 0).

        The aperture mean of the element velocities is ``D(f)`` times their common
        velocity: delays spread by σ_τ low-pass it by ``|D| ≈ exp(−(ωσ_τ)²/2)`` (8 ns
        rms: −0.8 % at 2.5 MHz). A model that applies every element's delay to a common
        impulse response needs that response without the spread.

        Parameters
        ----------
        frequencies : array_like, shape (nb,)
            Hz.

        Returns
        -------
        ndarray, complex, shape (nb,)
            D(f); ones when no element is live.
        """
        f = np.asarray(frequencies, dtype=float)
        tau = np.asarray(self.delay, dtype=float)
        amp = np.clip(np.nan_to_num(np.asarray(self.relative_amplitude, dtype=float)),
                      0.0, None)
        amp[list(self.dead)] = 0.0
        amp[~np.isfinite(tau)] = 0.0
        total = float(amp.sum())
        if not total > 0:
            return np.ones(f.shape, dtype=complex)
        phase = np.exp(2j * np.pi * np.outer(f, np.nan_to_num(tau)))
        return np.asarray(phase @ amp / total, dtype=complex)

    def shifted(self, shift: int) -> ElementMap:
        """The same map with the element indices moved by ``shift`` (the other
        hypothesis of an ambiguous map): element e becomes e + shift."""
        def roll(a):
            return np.roll(np.asarray(a), shift, axis=0)
        n = self.count
        return ElementMap(
            roll(self.relative_amplitude), roll(self.amplitude_uncertainty),
            roll(self.delay), roll(self.delay_uncertainty),
            tuple(sorted((d + shift) % n for d in self.dead)),
            tuple(sorted((d + shift) % n for d in self.weak)),
            self.center_x - shift * self.pitch, self.pitch, self.element_width,
            self.focus_offset, self.sound_speed, self.sound_speed_uncertainty,
            self.residual, self.frequencies, roll(self.coefficients), self.ambiguous)


def _amplitudes_and_delays(coef: NDArray, gain: NDArray, frequencies: NDArray, dead: float,
                           weak: float, iterations: int = 4, independent_bins: bool = False):
    """A_e, τ_e and their standard uncertainties from ``c_e(f) = A_e U(f) e^{iωτ_e}``.

    Each bin is weighted by ``|U(f)|² / g_e(f)`` (signal power over the noise gain of
    the element solve); U is the mean over the live elements, re-estimated with their
    delays and amplitudes removed. Uncertainties come from the scatter of the per-bin
    values about the weighted fit, or from the misfit of the line model when that is
    larger (taken as fully correlated across bins: a model error, not noise; with
    ``independent_bins`` as independent noise in each bin — the 2-D matrix solve, whose
    gains are each element's exact noise gain: Monte-Carlo on the 32 × 32 twin).
    """
    omega = 2.0 * np.pi * frequencies
    n = coef.shape[0]
    tau = np.zeros(n)
    amp = np.ones(n)
    ref_mask = np.ones(n, bool)
    for _ in range(iterations):
        ref = np.mean(coef[ref_mask] * np.exp(-1j * np.outer(tau[ref_mask], omega))
                      / amp[ref_mask, None], axis=0)
        wgt = np.abs(ref)[None, :] ** 2 / np.maximum(gain, 1e-300)
        ratio = coef / np.where(np.abs(ref) > 0, ref, 1.0)
        phase = np.angle(ratio * np.exp(-1j * np.outer(tau, omega))) + np.outer(tau, omega)
        tau = (phase * omega * wgt).sum(axis=1) / (omega**2 * wgt).sum(axis=1)
        amp_f = np.real(ratio * np.exp(-1j * np.outer(tau, omega)))
        amp = (amp_f * wgt).sum(axis=1) / wgt.sum(axis=1)
        level = np.median(amp[ref_mask]) if ref_mask.any() else np.median(amp)
        ref_mask = amp >= weak * level
        if not ref_mask.any():
            ref_mask = np.ones(n, bool)
    scale = float(np.mean(amp[ref_mask]))
    nb = omega.size
    corr = nb / max(nb - 1, 1)
    wn = wgt / wgt.sum(axis=1, keepdims=True)
    u_amp = np.sqrt(np.sum(wn**2 * (amp_f - amp[:, None]) ** 2, axis=1) * corr) / scale
    wo = wgt * omega
    u_tau = np.sqrt(np.sum(wo**2 * (phase - np.outer(tau, omega)) ** 2, axis=1) * corr) \
        / (omega**2 * wgt).sum(axis=1)
    rel = np.sqrt(gain) / np.maximum(np.abs(ref), 1e-300)[None, :]  # per-bin rel. error
    if independent_bins:  # the noise of the weighted mean of independent bins
        noise_amp = np.sqrt(np.sum((wn * rel) ** 2, axis=1))
        noise_tau = np.sqrt(np.sum((wo * rel) ** 2, axis=1))
    else:
        noise_amp, noise_tau = np.sum(wn * rel, axis=1), np.sum(wo * rel, axis=1)
    u_amp = np.maximum(u_amp, noise_amp / scale)
    u_tau = np.maximum(u_tau, noise_tau / (omega**2 * wgt).sum(axis=1))
    amp = amp / scale
    tau = tau - float(np.mean(tau[ref_mask]))
    dead_idx = tuple(int(i) for i in np.flatnonzero(amp < dead))
    weak_idx = tuple(int(i) for i in np.flatnonzero((amp >= dead) & (amp < weak)))
    u_tau[list(dead_idx)] = np.inf  # a silent element has no delay
    return amp, u_amp, tau, u_tau, dead_idx, weak_idx


def _objective(geo, line, freqs, count, width, ridge, scales, vector=False):
    """Relative residual as a function of the scaled non-linear parameters (with
    ``vector``: the misfit ``L − Bc`` as real numbers over ``‖L‖``, whose squared norm
    is that residual)."""
    norm = float(np.linalg.norm(line))

    def fun(q):
        center, offset, speed, pitch = (q[0] * scales[0], q[1] * scales[1],
                                        geo.sound_speed + q[2] * scales[2],
                                        scales[3] * (1.0 + q[3] * 1e-2))
        if not (speed > 0 and pitch > 0):
            return np.full(2 * line.size, 1e3) if vector else np.inf
        out = np.empty(line.shape, complex) if vector else None
        res = element_coefficients(line, geo, freqs, count=count, pitch=pitch,
                                   width=width, center=center, offset=offset,
                                   sound_speed=speed, ridge=ridge, misfit_out=out,
                                   noise=False)[1]
        if out is None:
            return res
        return np.concatenate([out.real.ravel(), out.imag.ravel()]) / max(norm, 1e-300)
    return fun


def _coarse_start(geo, line, freqs, count, pitch, width, ridge, search, wavelength,
                  offset_search):
    """Start of the non-linear fit: focus offset δ, then lattice phase, then the whole-pitch
    position of the array centre x_c (grid searches of the residual on ≤ 4 bins).

    The residual depends on δ far more than on x_c (a wrong δ defocuses every steep wave;
    a wrong x_c only the element-scale detail), and on x_c through its phase within one
    pitch far more than through whole pitches (only the ends of the array see those).
    So the three are searched one after the other: δ over ±``offset_search`` wavelengths
    in quarter-wavelength steps (basins are about λ/2 wide), at two lattice phases half a
    pitch apart (one is within a quarter pitch of the truth); the phase in eighths of a
    pitch; whole pitches over ±``search`` around the centroid of the line energy. The
    residuals only rank the grid points: their basis is transformed in single precision
    (1e-7 relative, far below the differences between grid points; half the CPU).
    """
    energy = np.sum(np.abs(line) ** 2, axis=1)
    centroid = float(np.sum(energy * geo.x) / np.sum(energy))
    sel = np.unique(np.linspace(0, freqs.size - 1, min(4, freqs.size)).round().astype(int))
    sub = line[:, sel]

    def residual(center: float, offset: float) -> float:
        return float(element_coefficients(sub, geo, freqs[sel], count=count, pitch=pitch,
                                          width=width, center=center, offset=offset,
                                          ridge=ridge, noise=False, single=True)[1])

    steps = np.arange(-4.0 * offset_search, 4.0 * offset_search + 1e-9) / 4.0
    best = min((residual(centroid + phase * pitch, step * wavelength), step * wavelength)
               for step in steps for phase in (0.0, 0.5))
    offset = best[1]
    phase = min((residual(centroid + ph * pitch, offset), ph)
                for ph in np.arange(8) / 8.0)[1]
    shifts = np.arange(-np.floor(search), np.floor(search) + 1)
    center = min((residual(centroid + (ph + phase) * pitch, offset),
                  centroid + (ph + phase) * pitch) for ph in shifts)[1]
    return center, offset


def fit_element_map(velocity: ArrayLike, grid: PlaneGrid, frequencies: ArrayLike, *,
                    count: int, pitch: float, element_width: float,
                    footprint: tuple[float, float], distance: float, sound_speed: float,
                    min_resolution: float = 1.1, dead_threshold: float = 0.3,
                    weak_threshold: float = 0.7, ridge: float = 1e-4,
                    search_pitches: float = 4.0, fit_pitch: bool = True,
                    fit_sound_speed: bool = True, speed_floor: float = 2.0,
                    offset_search: float = 3.0, speed_bins: int = 6,
                    start: tuple[float, float] | None = None,
                    refine_start: bool = True, optimizer: str = "nelder-mead",
                    edge_silent_threshold: float = 0.1, local_views: Callable | None = None
                    ) -> ElementMap:
    """Fit the element map of an array to its back-projected surface velocity.

    Parameters
    ----------
    velocity : array_like, complex, shape (nx, ny, nf)
        Normal velocity on z = 0 (back-projection, conjugate Fourier convention); the
        lens need not be reversed (it is common to all elements).
    grid : PlaneGrid
        Source-plane grid (x across the elements).
    frequencies : array_like, shape (nf,)
        Hz.
    count, pitch, element_width : int, float, float
        Nominal N, p (m) and w (m), e.g. from the measurement file or a preset.
    footprint : (float, float)
        x-range (m) of the scan on the source frame.
    distance : float
        Back-projection distance z0 in m.
    sound_speed : float
        Sound speed (m/s) the back-projection used (the file's).
    min_resolution, dead_threshold, weak_threshold, ridge, search_pitches, fit_pitch,
    fit_sound_speed
        See :class:`~holoprobe.characterize.ElementsConfig`; with ``fit_sound_speed`` the
        map is the one at the fitted c (:func:`fit_sound_speed_stencil`, after the
        centre and offset at the file's c).
    speed_floor : float
        Model-error floor (m/s) of the sound-speed uncertainty
        (``ElementsConfig.sound_speed_floor``).
    offset_search : float
        Half-range, in wavelengths at the median frequency used, of the search of the
        focus offset δ (``ElementsConfig.offset_search``; δ may have either sign).
    speed_bins : int
        Most frequency bins of the sound-speed fit (:func:`fit_sound_speed_stencil`).
    start : (float, float), optional
        Array centre x_c and offset δ (m) to start the non-linear fit from (e.g. an
        earlier map of the same data); default: the grid searches of the start.
    refine_start : bool
        False: take ``start`` as fitted (no Nelder–Mead over centre and offset; with
        ``fit_sound_speed`` only c and δ are refined), e.g. when ``start`` is the map of
        the same back-projection at the file's c.
    optimizer : {"nelder-mead", "least-squares"}
        The non-linear fit of centre, offset (and pitch): Nelder–Mead on the residual
        (~60 evaluations per parameter), or Levenberg–Marquardt on the misfit vector
        with a forward-difference Jacobian (~4 evaluations per step, a few steps from a
        start within the basin, e.g. an earlier map's or the grid searches': 5–10×
        fewer evaluations at 128 elements); when it does not converge (out of
        evaluations, or failed) Nelder–Mead goes on from where it stopped.
    edge_silent_threshold : float
        A dead edge element below this relative amplitude makes the map ``ambiguous``
        (:class:`~holoprobe.characterize.ElementsConfig`); so does a one-pitch shift
        whose residual is within 5 % of the fit's.
    local_views : callable, optional
        Each element's own view of the scan (:class:`LineGeometry` ``local``, e.g.
        :func:`~holoprobe.characterize.arc_element_views` on a convex face); default
        ``footprint`` at ``distance`` for all.

    Returns
    -------
    ElementMap

    Raises
    ------
    InputError
        Fewer than two elements, no bin that resolves the elements, a non-positive
        pitch or width.
    """
    count = int(count)
    if count < 2:
        raise InputError(f"an element map needs an array, got {count} element(s)",
                         field="count")
    for name, value in (("pitch", pitch), ("element_width", element_width),
                        ("distance", distance), ("sound_speed", sound_speed)):
        if not (np.isfinite(value) and value > 0):
            raise InputError(f"expected a positive number, got {value!r}", field=name)
    f = np.asarray(frequencies, dtype=float).reshape(-1)
    k = 2.0 * np.pi * f / sound_speed
    use = k * pitch >= min_resolution * np.pi
    if use.sum() < 3:
        raise FitError(f"only {int(use.sum())} frequency bin(s) resolve the elements "
                         f"(k·p ≥ {min_resolution:g}π needs f ≥ "
                         f"{min_resolution * sound_speed / (2 * pitch) / 1e6:.3g} MHz)",
                         field="frequencies")
    line = line_field(velocity, grid)[:, use]
    freqs = f[use]
    geo = LineGeometry.build(grid.x, footprint, distance, sound_speed, local_views)
    wavelength = sound_speed / float(np.median(freqs))
    if start is None:
        center0, offset0 = _coarse_start(geo, line, freqs, count, pitch, element_width,
                                         ridge, search_pitches, wavelength, offset_search)
    else:
        center0, offset0 = float(start[0]), float(start[1])
    scales = (pitch, wavelength, 10.0, pitch)
    # the non-linear fit on at most 8 bins spread over the band, the map on all of them
    sel = np.unique(np.linspace(0, freqs.size - 1, min(8, freqs.size)).round().astype(int))
    fun = _objective(geo, line[:, sel], freqs[sel], count, element_width, ridge, scales)
    q0 = np.array([center0 / pitch, offset0 / wavelength, 0.0, 0.0])
    if start is not None and refine_start is False:
        q = q0
    elif optimizer == "least-squares":
        q, converged = _least_squares(_objective(geo, line[:, sel], freqs[sel], count,
                                                 element_width, ridge, scales, vector=True),
                                      q0, fit_pitch)
        if not converged:  # out of evaluations or failed: the robust search from there
            q = _nelder_mead(fun, q if np.all(np.isfinite(q)) else q0, fit_pitch)
    elif optimizer == "nelder-mead":
        q = _nelder_mead(fun, q0, fit_pitch)
    else:
        raise InputError(f"expected 'nelder-mead' or 'least-squares', got {optimizer!r}",
                         field="optimizer")
    center, offset = q[0] * pitch, q[1] * wavelength
    pitch_fit = pitch * (1.0 + q[3] * 1e-2)
    speed = u_speed = float("nan")
    if fit_sound_speed:
        speed, u_speed, offset = fit_sound_speed_stencil(
            line, geo, freqs, count=count, pitch=pitch_fit, width=element_width,
            center=center, offset=offset, ridge=ridge, bins=speed_bins,
            floor=speed_floor)
    c_map = speed if np.isfinite(speed) else sound_speed
    coef, residual, gain = element_coefficients(
        line, geo, freqs, count=count, pitch=pitch_fit, width=element_width, center=center,
        offset=offset, sound_speed=c_map, ridge=ridge)
    amp, u_amp, tau, u_tau, dead, weak = _amplitudes_and_delays(
        coef, gain, freqs, dead_threshold, weak_threshold)
    ambiguous = False
    if dead and (dead[0] == 0 or dead[-1] == count - 1):
        # a silent edge element: the array one pitch over, the other edge dead, radiates
        # the same field (the two residuals differ only by the dead strip's leakage)
        shift, edge = (1, 0) if dead[0] == 0 else (-1, count - 1)
        ambiguous = bool(abs(amp[edge]) < edge_silent_threshold)
        if not ambiguous:
            q_map = np.array([q[0], offset / wavelength, (c_map - sound_speed) / 10.0,
                              q[3]])
            other = fun(q_map + np.array([shift * pitch_fit / pitch, 0.0, 0.0, 0.0]))
            ambiguous = bool(other <= fun(q_map) * 1.05)
    return ElementMap(amp, u_amp, tau, u_tau, dead, weak, float(center), float(pitch_fit),
                      float(element_width), float(offset), float(speed), float(u_speed),
                      float(residual), freqs, coef, ambiguous)


def _nelder_mead(fun, q0: NDArray, fit_pitch: bool) -> NDArray:
    """Centre, focus offset (and pitch) minimising ``fun`` from ``q0`` (scaled)."""
    free = np.array([True, True, False, fit_pitch])

    def reduced(qf):
        q = q0.copy()
        q[free] = qf
        return fun(q)

    steps = np.array([0.05, 0.05, 0.5, 0.1])[free]  # p/20, λ/20, -, 0.1 % pitch
    simplex = np.vstack([q0[free], q0[free] + np.diag(steps)])
    opt = scipy.optimize.minimize(reduced, q0[free], method="Nelder-Mead",
                                  options={"xatol": 2e-3, "fatol": 1e-9,
                                           "maxfev": 60 * int(free.sum()),
                                           "initial_simplex": simplex})
    q = q0.copy()
    q[free] = opt.x
    return q


_LM_EVALUATIONS = 40  # most misfit evaluations of one Levenberg–Marquardt map fit
_LM_TOLERANCE = 1e-3  # stop at a step below this in every scaled parameter


def _least_squares(vec, q0: NDArray, fit_pitch: bool) -> tuple[NDArray, bool]:
    """Centre, focus offset (and pitch) minimising ``‖vec(q)‖²`` from ``q0`` (scaled).

    Levenberg–Marquardt (Marquardt's diagonal scaling) with forward differences of
    fixed scaled steps (p/1000, λ/1000, 1e-5 of the pitch: far below the basins, far
    above the round-off), stopped by an absolute test: a step below ``_LM_TOLERANCE``
    in every scaled parameter (p/1000, λ/1000, 1e-5 of the pitch: < 1 µm of centre,
    offset and, on a C5-2, R) is the last. MINPACK's test (``scipy``'s ``"lm"``) is
    relative to ‖q‖, which is ~0 where a convex pass starts from the last pass's map
    (centre and pitch change ~0 there): it took 49 evaluations for what this does in
    4–9. Returns the point and whether it converged (not when the evaluations ran out
    or a step was not finite)."""
    free = np.array([True, True, False, fit_pitch])
    steps = np.array([1e-3, 1e-3, 0.0, 1e-3])[free]

    def full(x: NDArray) -> NDArray:
        q = q0.copy()
        q[free] = x
        return q

    x = q0[free].astype(float)
    r = vec(full(x))
    cost, used, lam = float(r @ r), 1, 1e-3
    while used + x.size < _LM_EVALUATIONS:
        jac = np.stack([(vec(full(x + h * e)) - r) / h
                        for h, e in zip(steps, np.eye(x.size), strict=True)], axis=1)
        used += x.size
        a, g = jac.T @ jac, jac.T @ r
        # Marquardt's scaling with a floor: a parameter the misfit ignores (a zero column)
        # keeps a damped, zero step instead of a singular system
        scale = np.maximum(np.diag(a), 1e-12 * max(float(np.max(np.diag(a))), 1e-300))
        while used < _LM_EVALUATIONS:
            try:
                dx = -np.linalg.solve(a + lam * np.diag(scale), g)
            except np.linalg.LinAlgError:
                return full(x), False
            if not np.all(np.isfinite(dx)):
                return full(x), False
            if np.max(np.abs(dx)) < _LM_TOLERANCE:
                return full(x + dx), True
            r_new = vec(full(x + dx))
            used += 1
            cost_new = float(r_new @ r_new)
            if cost_new < cost:
                x, r, cost, lam = x + dx, r_new, cost_new, max(0.1 * lam, 1e-7)
                break
            lam *= 10.0
    return full(x), False


def _speed_bins(freqs: NDArray, geo: LineGeometry, bins: int) -> NDArray[np.intp]:
    """Indices of at most ``bins`` bins, spread over those whose waves up to grazing
    (in water up to 3 % slower than the file's) are sampled by the grid: above that the
    scan aliases the steepest waves, which carry the information on c, and a model
    without the aliasing biases c by several m/s (measured on line twins)."""
    k = 2.0 * np.pi * freqs / geo.sound_speed * 1.03
    ok = np.flatnonzero(k < np.pi / geo.step)
    if ok.size == 0:
        return ok
    pick = np.linspace(0, ok.size - 1, min(int(bins), ok.size)).round().astype(int)
    return ok[np.unique(pick)]


def fit_sound_speed_stencil(line: NDArray, geo: LineGeometry, freqs: NDArray, *,
                            count: int, pitch: float, width: float, center: float,
                            offset: float, ridge: float = 1e-4, bins: int = 6,
                            floor: float = 0.0, step: float = 6.0
                            ) -> tuple[float, float, float]:
    """Water sound speed (m/s), its standard uncertainty and the focus offset δ (m) from
    the line field of an array whose centre and pitch are known (an element map).

    The residual of the element model is quadratic in (c, δ) near its minimum; it is
    evaluated on a 3 × 3 stencil (c ± ``step`` m/s, δ ± λ/20) laid along the valley
    where the paraxial defocus stays constant, ``(d − δ) c² = const`` (a wrong c and a
    shifted plane defocus alike to that order: only the steep waves tell them apart),
    and the minimum of the fitted quadratic taken (the stencil moved, at most three
    times, when it lies outside; widened, up to 4 × ``step``, when the fitted quadratic
    has no minimum; NaN when no stencil holds its minimum). ``bins`` alias-free bins
    (:func:`_speed_bins`) take part, each solved once per stencil point: about
    9 × ``bins`` element solves per stencil, a flat face's basis transformed in single
    precision (on the full-size P4-1 scan c moves by 2e-6 m/s, 1e-6 σ; 13 % less CPU).

    The uncertainty combines the curvature of the residual (noise: one independent
    sample per half wavelength of the footprint per bin), half the difference of the
    minima of the low and high halves of the bins (from the same evaluations) and
    ``floor``. Returns NaNs when no bin is alias-free or the residual has no minimum.
    """
    sel = _speed_bins(freqs, geo, bins)
    nan = (float("nan"), float("nan"), float(offset))
    if sel.size == 0:
        return nan
    sub, f_sub = line[:, sel], freqs[sel]
    c_f, d = geo.sound_speed, geo.distance
    h_d = 0.05 * c_f / float(np.median(f_sub))
    grid = np.array([(u, v) for u in (-1.0, 0.0, 1.0) for v in (-1.0, 0.0, 1.0)])
    c0, o0, h = c_f, float(offset), float(step)
    for _ in range(4):
        vals = np.array([element_coefficients(
            sub, geo, f_sub, count=count, pitch=pitch, width=width, center=center,
            offset=_valley(d, o0, c0, c0 + u * h) + v * h_d,
            sound_speed=c0 + u * h, ridge=ridge, per_bin=True, noise=False,
            single=True)[1] for u, v in grid])
        best = _quadratic_minimum(grid, vals.sum(axis=1))
        if best is None:  # too flat for this stencil: the same centre, twice as wide
            hess, inside = None, False
            h *= 2.0
            if h > 4.0 * step:
                break
            continue
        (u, v), hess, r_min = best
        inside = max(abs(u), abs(v)) <= 1.5
        c_new = c0 + u * h
        o0 = _valley(d, o0, c0, c_new) + v * h_d
        c0 = c_new
        if inside:
            break
    if hess is None or not inside:  # no minimum within reach: the data cannot tell
        return nan
    half = sel.size // 2
    halves = [_quadratic_minimum(grid, vals[:, part].sum(axis=1))
              for part in (slice(0, half), slice(half, None))] if half else []
    spread = (0.5 * abs(halves[0][0][0] - halves[1][0][0]) * h
              if len(halves) == 2 and None not in halves else 0.0)
    span = geo.footprint[1] - geo.footprint[0]
    dof = max(float(np.sum(span / (0.5 * c_f / f_sub))) - count * sel.size - 2.0, 1.0)
    cov = np.linalg.inv(hess)
    u_noise = float(np.sqrt(max(2.0 * max(r_min, 0.0) / dof * cov[0, 0], 0.0))) * h
    return (float(c0), float(np.sqrt(u_noise**2 + spread**2 + floor**2)), float(o0))


def _valley(distance: float, offset: float, speed: float, new_speed: float) -> float:
    """δ at ``new_speed`` with the paraxial defocus of (``offset``, ``speed``):
    ``(d − δ) c²`` constant."""
    return distance - (distance - offset) * (speed / new_speed) ** 2


def _quadratic_minimum(points: NDArray, values: NDArray):
    """Minimum of the quadratic fitted to ``values`` at the 2-D ``points``:
    ``((u, v), Hessian, value)``, or None when the quadratic has no minimum."""
    u, v = points[:, 0], points[:, 1]
    design = np.column_stack([np.ones_like(u), u, v, 0.5 * u * u, u * v, 0.5 * v * v])
    a = np.linalg.lstsq(design, values, rcond=None)[0]
    hess = np.array([[a[3], a[4]], [a[4], a[5]]])
    if not (hess[0, 0] > 0 and np.linalg.det(hess) > 0):
        return None
    x = -np.linalg.solve(hess, a[1:3])
    x = np.clip(x, -3.0, 3.0)
    return x, hess, float(a[0] + a[1:3] @ x + 0.5 * x @ hess @ x)


def scan_footprint(scan_grid: PlaneGrid, pose) -> tuple[float, float]:
    """x-range (m) covered by the scan plane (with ``pose``) on the transducer frame."""
    corners = np.array([[u, v, 0.0] for u in (scan_grid.x[0], scan_grid.x[-1])
                        for v in (scan_grid.y[0], scan_grid.y[-1])])
    pts = pose.to_global(corners)
    return float(pts[:, 0].min()), float(pts[:, 0].max())


def _map_options(probe, scan_grid: PlaneGrid, pose, sound_speed: float, config) -> dict:
    """Keywords of :func:`fit_element_map` from the probe, the scan, the pose and the
    ``elements`` config section."""
    return {"count": probe.element_count, "pitch": probe.pitch,
            "element_width": min(probe.element_width, probe.pitch),
            "footprint": scan_footprint(scan_grid, pose), "distance": float(pose.origin[2]),
            "sound_speed": sound_speed, "min_resolution": config.min_resolution,
            "dead_threshold": config.dead_threshold,
            "weak_threshold": config.weak_threshold, "ridge": config.ridge,
            "search_pitches": config.search_pitches, "offset_search": config.offset_search,
            "speed_floor": config.sound_speed_floor, "speed_bins": config.sound_speed_bins,
            "edge_silent_threshold": config.edge_silent_threshold}


PREVIOUS_RESIDUAL_FACTOR = 1.5
"""A map started from the previous pose pass's is kept when its residual is at most this
many times that pass's (full-size P4-1 twin: 9.24e-5 against 9.20e-5). On the line twins
of ``tests/characterize/test_element_map_line.py`` Levenberg–Marquardt from a start up
to half a pitch and a wavelength off lands on the grid searches' map; a start a whole
pitch off ends in the next basin with 180–320 times the residual."""


def array_aperture(aperture, velocity: NDArray, source_grid: PlaneGrid,
                   frequencies: NDArray, *, probe, scan_grid: PlaneGrid, pose,
                   sound_speed: float, config, warnings: list[str],
                   previous: ElementMap | None = None):
    """The aperture explained by the element map of an array (issue: dead elements).

    Fits :func:`fit_element_map` with the file's element count, pitch and width as the
    prior (``config.map_optimizer``). When the profile fit of the aperture disagrees
    with the nominal array width ``N·p`` by more than ``config.width_warning_pitches``
    pitches, or elements are dead or weak, the lateral aperture becomes the array's:
    width ``N·p`` (the band-limited envelope of N strips, the convention of
    :class:`ApertureFit`), centre from the map.

    ``previous`` (the map of the last pose pass, expressed in this pass's frame) starts
    the non-linear fit at its centre and focus offset instead of the grid searches of
    :func:`fit_element_map`'s start; when the fit from there ends with a residual above
    ``PREVIOUS_RESIDUAL_FACTOR`` times the previous map's (another basin), the grid
    searches run after all.

    Returns
    -------
    (ApertureFit, ElementMap or None, float)
        The aperture to use, the map (None when it could not be fitted; a warning says
        why) and the profile-fitted envelope width (m) for the report.
    """
    import dataclasses

    profile_width = float(aperture.width)
    options = {**_map_options(probe, scan_grid, pose, sound_speed, config),
               "fit_pitch": config.fit_pitch, "fit_sound_speed": False,
               "optimizer": config.map_optimizer}
    try:
        emap = None
        if previous is not None:
            emap = fit_element_map(velocity, source_grid, frequencies, **options,
                                   start=(previous.center_x, previous.focus_offset))
            if not emap.residual <= PREVIOUS_RESIDUAL_FACTOR * previous.residual:
                emap = None  # not the previous pass's basin: search from scratch
        if emap is None:
            emap = fit_element_map(velocity, source_grid, frequencies, **options)
    except (InputError, FitError) as exc:
        warnings.append(f"no element map: {exc.detail}")
        return aperture, None, profile_width
    nominal = probe.element_count * emap.pitch
    off = abs(profile_width - nominal) > config.width_warning_pitches * emap.pitch
    if off or emap.dead or emap.weak:
        aperture = dataclasses.replace(aperture, width=float(nominal),
                                       center_x=float(emap.center_x))
    return aperture, emap, profile_width


def channel_levels(rf: ArrayLike) -> NDArray[np.float64]:
    """Energy of every RF channel (its mean removed) relative to the median channel's.

    A dead receive channel carries noise only: its level is far below 1
    (``ElementsConfig.receive_dead_threshold``). Used to place a dead edge element of an
    ambiguous transmit map (:func:`resolve_edge_ambiguity`) before the receive step.
    """
    y = np.asarray(rf, dtype=float)
    if y.ndim != 2:
        raise InputError(f"expected RF of shape (channels, samples), got {y.shape}",
                         field="rf")
    energy = np.sum((y - y.mean(axis=1, keepdims=True)) ** 2, axis=1)
    median = float(np.median(energy))
    return energy / median if median > 0 else np.ones(energy.size)


def steering_uncertainty(delay: ArrayLike, positions: ArrayLike, sound_speed: float) -> float:
    """Standard uncertainty (rad) of the beam steering that an array's element delays
    may hold while the transmit fit shows none.

    A linear trend ``s·x`` of the element delays steers the beam by ``asin(c0 s)``
    exactly like a tilt of the scan plane: no field measurement tells the two apart, and
    the orientation step puts any trend into the fitted angles (the map's delays have
    none). For delays that scatter independently about their common value with the rms
    ``σ_τ`` of the map's residual about its best line, the trend of a draw has the
    standard deviation ``σ_τ / √Σ(x − x̄)²``: the steering it hides is ``c0`` times that
    (0.08° for 24 P4-1 elements with 8 ns rms delays, ~8× less for 96).

    Parameters
    ----------
    delay : array_like, shape (n,)
        Delays of the live elements (s).
    positions : array_like, shape (n,)
        Their centres along the array (m).
    sound_speed : float
        c0 (m/s).

    Returns
    -------
    float
        σ of the steering angle (rad); 0 for fewer than three elements.
    """
    tau = np.asarray(delay, dtype=float).reshape(-1)
    x = np.asarray(positions, dtype=float).reshape(-1)
    if tau.size != x.size:
        raise InputError(f"expected one position per delay, got {x.size} for {tau.size}",
                         field="positions")
    if tau.size < 3:
        return 0.0
    xc = x - x.mean()
    spread = float(np.sum(xc**2))
    if not spread > 0:
        return 0.0
    residual = tau - tau.mean() - xc * float(np.sum(xc * tau)) / spread
    sigma_tau = float(np.sqrt(np.sum(residual**2) / (tau.size - 2)))
    return float(sound_speed) * sigma_tau / float(np.sqrt(spread))


def with_steering(element_map: ElementMap, sound_speed: float) -> tuple[ElementMap, float]:
    """The map with the hidden steering in its delay uncertainties, and that steering's σ.

    The map's delays carry no linear trend (the fitted angles hold it), so the true
    delays' trend is an error of every delay: ``(x − x̄)·σ_ε/c0`` with σ_ε of
    :func:`steering_uncertainty` over the live elements, added in quadrature to each
    element's σ (the same σ_ε joins σ(θy) of the transmit pose). A 2-D matrix map (its
    angles come from the lattice) or fewer than three live elements: unchanged, 0.

    Returns
    -------
    (ElementMap, float)
        The map and σ_ε (rad).
    """
    import dataclasses

    from holoprobe.characterize._matrix import MatrixElementMap

    m = element_map
    if isinstance(m, MatrixElementMap):
        return m, 0.0
    x, live = m.offsets, m.live
    eps = steering_uncertainty(m.delay[live], x[live], sound_speed)
    if not eps > 0:
        return m, 0.0
    trend = np.abs(x - x[live].mean()) * eps / float(sound_speed)
    u = np.asarray(m.delay_uncertainty, dtype=float)
    return dataclasses.replace(m, delay_uncertainty=np.hypot(u, trend)), eps


def resolve_edge_ambiguity(transmit, receive_gain: ArrayLike, dead_threshold: float):
    """Pick the hypothesis of an ambiguous map that the receive channels confirm.

    A dead edge element leaves the transmit field unchanged when the array is moved by
    one pitch and the opposite edge element is declared dead instead
    (:attr:`ElementMap.ambiguous`). The RF columns are in element order, so the dead
    receive channels say which end it is (their levels: the receive gains, or
    :func:`channel_levels` of the echo before the receive step). Returns ``transmit``
    with the map (and the pose's x0 with the posed scan grid) moved by one element when
    the receive data ask for it, else unchanged.
    """
    import dataclasses

    m = transmit.element_map
    if m is None or not m.ambiguous:
        return transmit
    gain = np.asarray(receive_gain, dtype=float).reshape(-1)
    if gain.size != m.count:
        return transmit
    dead_rx = set(int(i) for i in np.flatnonzero(gain < dead_threshold))
    edges = {0, m.count - 1}
    for shift in (0, 1, -1):
        cand = m.shifted(shift) if shift else m
        if set(cand.dead) & edges and set(cand.dead) & edges <= dead_rx:
            if shift == 0:
                return dataclasses.replace(transmit, element_map=dataclasses.replace(
                    m, ambiguous=False))
            pose = transmit.pose
            x0, y0, z0 = pose.origin
            new_pose = dataclasses.replace(pose, origin=(x0 + shift * m.pitch, y0, z0))
            warnings = [*transmit.warnings,
                        f"the dead receive channels {sorted(dead_rx)} place the dead edge "
                        f"element: element map and x0 moved by {shift:+d} element(s)"]
            # the posed scan grid moves with x0: the receive step projects the scan
            # from it onto the elements
            return dataclasses.replace(
                transmit, element_map=dataclasses.replace(cand, ambiguous=False),
                pose=new_pose, scan_grid=transmit.scan_grid.with_pose(new_pose),
                warnings=warnings)
    return transmit


def sound_speed_from_data(velocity: NDArray, source_grid: PlaneGrid, frequencies: NDArray,
                          *, probe, scan_grid: PlaneGrid, pose, sound_speed: float,
                          config) -> tuple[float, float]:
    """Water sound speed (m/s) and its standard uncertainty from the back-projection.

    The element model of :func:`fit_element_map` with ``c`` free: a wrong c0 defocuses
    the non-paraxial waves differently from a shift of the source plane (paper section
    II B). The two are nearly degenerate (both ∝ k_x²/ω at the paraxial order), so the
    uncertainty adds, to the curvature of the residual, half the difference of the
    low-band and high-band estimates and a model-error floor
    (``config.sound_speed_floor``, measured on twins: ``benchmarks/elements.py``).
    Returns ``(nan, nan)`` when no map can be fitted.
    """
    m = element_map_with_sound_speed(velocity, source_grid, frequencies, probe=probe,
                                     scan_grid=scan_grid, pose=pose,
                                     sound_speed=sound_speed, config=config)
    if m is None:
        return float("nan"), float("nan")
    return m.sound_speed, m.sound_speed_uncertainty


def element_map_with_sound_speed(velocity: NDArray, source_grid: PlaneGrid,
                                 frequencies: NDArray, *, probe, scan_grid: PlaneGrid, pose,
                                 sound_speed: float, config,
                                 start: ElementMap | None = None) -> ElementMap | None:
    """The element map fitted with the water's sound speed free (see
    :func:`sound_speed_from_data`); its amplitudes and delays are then free of the
    defocus a wrong c0 leaves in the non-paraxial waves.

    ``start`` (an earlier map of the same back-projection, e.g. the one of
    :func:`array_aperture`) gives the starting centre and focus offset, sparing the grid
    searches and the centre/offset fit (only c and δ are refined: about
    9 × ``sound_speed_bins`` element solves, then the map on every bin). Returns None
    when no map can be fitted.
    """
    begin = None if start is None else (start.center_x, start.focus_offset)
    try:
        return fit_element_map(
            velocity, source_grid, frequencies,
            **_map_options(probe, scan_grid, pose, sound_speed, config), fit_pitch=False,
            fit_sound_speed=True, start=begin, refine_start=start is None)
    except (InputError, FitError):
        return None
