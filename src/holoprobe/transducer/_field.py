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
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.characterize import lens_delays
from holoprobe.errors import InputError
from holoprobe.geometry import PlaneGrid, Surface
from holoprobe.propagation import propagate_parallel, rayleigh_integral
from holoprobe.signal import next_fast_length, to_time
from holoprobe.transducer._model import VirtualTransducer
from holoprobe.transducer._transmit import TransmitSetting

__all__ = [
    "FieldPrediction",
    "continuous_spectrum",
    "drive_spectrum",
    "predict_field",
    "signal_band",
    "surface_velocity",
]


def continuous_spectrum(signal: ArrayLike, sampling_rate: float, frequencies: ArrayLike
                        ) -> NDArray[np.complex128]:
    """Continuous-time Fourier transform of a sampled signal at arbitrary frequencies.

    ``S(f) = Σ_n s[n] e^{+i 2π f n / fs} / fs`` (holoprobe's conjugate convention,
    sample n at t = n / fs): exact for a signal band-limited below fs/2.

    Parameters
    ----------
    signal : array_like, shape (n,)
        Samples (any unit u).
    sampling_rate : float
        fs in Hz.
    frequencies : array_like, shape (nf,)
        Frequencies in Hz (below fs/2 for a meaningful result).

    Returns
    -------
    ndarray, complex, shape (nf,)
        S(f) in u·s.
    """
    s = np.asarray(signal, dtype=float).reshape(-1)
    f = np.asarray(frequencies, dtype=float).reshape(-1)
    t = np.arange(s.size) / float(sampling_rate)
    out = np.empty(f.size, dtype=complex)
    step = max(1, (1 << 22) // max(1, s.size))  # bound the (nf, n) phase matrix
    for i in range(0, f.size, step):
        out[i:i + step] = np.exp(2j * np.pi * np.outer(f[i:i + step], t)) @ s
    return out / float(sampling_rate)


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
    c0 = vt.medium.sound_speed
    tau_el = setting.element_delays(centers, c0)
    apod = setting.element_weights(n_el)
    active = np.flatnonzero(apod != 0) if skip_silent else np.arange(n_el)
    if active.size == 0:
        raise InputError("every element has zero apodization", field="apodization")
    nx, ny = _element_sampling(vt, float(f.max()), points_per_wavelength)
    w, h = vt.element_width, vt.element_height
    ux = (np.arange(nx) + 0.5) / nx * w - w / 2
    uy = (np.arange(ny) + 0.5) / ny * h - h / 2
    yc = vt.aperture_center[1]
    tau_lens = (lens_delays(uy, vt.lens_focus, h, c0) if lens and math.isfinite(vt.lens_focus)
                else np.zeros(ny))
    # points ordered (element, x sub-sample, y sub-sample)
    px = (centers[active, 0][:, None] + ux[None, :])
    xs = np.repeat(px.reshape(-1), ny)
    ys = np.tile(yc + uy, active.size * nx)
    pts = np.stack([xs, ys, np.zeros(xs.size)], axis=-1)
    n_pts = xs.size
    surface = Surface(pts, np.tile([0.0, 0.0, 1.0], (n_pts, 1)),
                      np.full(n_pts, (w / nx) * (h / ny)))
    tau = np.repeat(tau_el[active], nx * ny) + np.tile(tau_lens, active.size * nx)
    amp = np.repeat(apod[active], nx * ny)
    spectrum = drive_spectrum(vt, setting, f)
    velocity = np.exp((2j * np.pi) * tau[:, None] * f[None, :])
    velocity *= amp[:, None]
    velocity *= spectrum[None, :]
    return surface, velocity


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
        ``"rayleigh"`` or ``"angular_spectrum"``.
    """

    def __init__(self, time: NDArray, pressure: NDArray, points: NDArray,
                 frequency_band: tuple[float, float], method: str):
        self.time = time
        self.pressure = pressure
        self.points = points
        self.frequency_band = frequency_band
        self.method = method

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
    """Smallest and largest distance from the target points to the aperture rectangle."""
    xc, yc = vt.aperture_center
    hw = 0.5 * ((vt.element_count - 1) * vt.pitch + vt.element_width)
    hh = 0.5 * vt.element_height
    cx = np.clip(pts[:, 0], xc - hw, xc + hw)
    cy = np.clip(pts[:, 1], yc - hh, yc + hh)
    d_min = np.sqrt((pts[:, 0] - cx) ** 2 + (pts[:, 1] - cy) ** 2 + pts[:, 2] ** 2)
    far_x = np.maximum(np.abs(pts[:, 0] - (xc - hw)), np.abs(pts[:, 0] - (xc + hw)))
    far_y = np.maximum(np.abs(pts[:, 1] - (yc - hh)), np.abs(pts[:, 1] - (yc + hh)))
    d_max = np.sqrt(far_x**2 + far_y**2 + pts[:, 2] ** 2)
    return float(d_min.min()), float(d_max.max())


def _is_parallel_plane(target: object) -> bool:
    if not isinstance(target, PlaneGrid):
        return False
    pose = target.pose
    return (pose.theta_x == 0 and pose.theta_y == 0 and pose.theta_z == 0
            and pose.origin[2] > 0 and target.x.size >= 2 and target.y.size >= 2)


def predict_field(
    vt: VirtualTransducer,
    setting: TransmitSetting,
    points_or_plane: PlaneGrid | Surface | ArrayLike,
    *,
    sampling_rate: float | None = None,
    n_samples: int | None = None,
    start_time: float | None = None,
    method: str = "auto",
    band_threshold_db: float = -40.0,
    oversampling: float = 8.0,
    points_per_wavelength: float = 4.0,
    guard_time: float = 1e-6,
    target_chunk: int = 4096,
    progress: Callable[[int, int], None] | None = None,
) -> FieldPrediction:
    """Pressure time series radiated by the virtual transducer for a transmit setting.

    The surface velocity (:func:`surface_velocity`, paper eqs.
    transmit-impulse-response and lens-delays) is propagated per frequency bin of
    the signal band by the forward Rayleigh integral (``method="rayleigh"``, paper
    eq. rayleigh-fwd-vp, rigid baffle, :func:`holoprobe.propagation.rayleigh_integral`)
    or, for a :class:`PlaneGrid` parallel to the array face (no rotation, z0 > 0),
    by the angular spectrum (``method="angular_spectrum"``,
    :func:`holoprobe.propagation.propagate_parallel`, kind "vp", the velocity
    rasterised on the plane's own grid). Only the bins where ``|H_T E_T|²`` lies
    within ``band_threshold_db`` of its peak are propagated; the rest are zero.

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
        Output length (default: from the first to the last possible arrival plus
        the durations of the IR and the drive and ``guard_time``).
    start_time : float, optional
        Time of output sample 0 in s (default: the earliest possible arrival minus
        ``guard_time``).
    method : {"auto", "rayleigh", "angular_spectrum"}
        ``"auto"``: the Rayleigh integral (exact for any points; the angular
        spectrum is used only when asked for).
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
    progress : callable(done, total), optional
        Called after each chunk of targets.

    Returns
    -------
    FieldPrediction
        ``time`` (nt,) in s and ``pressure`` (n_points, nt) in Pa (unpack as
        ``t, p = predict_field(...)``), plus the points and the band.

    Notes
    -----
    The record is periodic with its length: ``n_samples`` must cover every
    arrival, otherwise late arrivals wrap to the start. Cost of the Rayleigh path:
    N_source × N_target × N_bins kernel terms (numba, parallel).
    """
    if method not in ("auto", "rayleigh", "angular_spectrum"):
        raise InputError(f"expected 'auto', 'rayleigh' or 'angular_spectrum', got {method!r}",
                         field="method")
    pts = _targets(points_or_plane)
    if method == "angular_spectrum" and not _is_parallel_plane(points_or_plane):
        raise InputError("the angular spectrum needs a PlaneGrid parallel to the array face "
                         "(no rotation, origin z > 0, at least 2 × 2 points)", field="method")
    c0 = vt.medium.sound_speed
    f_lo, f_hi = signal_band(vt, setting, threshold_db=band_threshold_db)
    fs = float(sampling_rate) if sampling_rate is not None else oversampling * f_hi
    if not (math.isfinite(fs) and fs > 2 * f_hi):
        raise InputError(f"expected a sampling rate above twice the top of the band "
                         f"({2 * f_hi:g} Hz), got {fs!r}", field="sampling_rate")
    d_min, d_max = _distance_range(vt, pts)
    tau_max = float(setting.element_delays(vt.element_centers(), c0).max())
    t0 = d_min / c0 - guard_time if start_time is None else float(start_time)
    if n_samples is None:
        t_end = (d_max / c0 + tau_max + vt.transmit_impulse_response.size
                 / vt.transmit_sampling_rate + setting.drive.duration + guard_time)
        n = next_fast_length(math.ceil((t_end - t0) * fs))
    else:
        n = int(n_samples)
        if n < 2:
            raise InputError("expected at least 2 samples", field="n_samples")
    freqs = np.fft.rfftfreq(n, 1.0 / fs)
    band = np.flatnonzero((freqs >= f_lo) & (freqs <= f_hi) & (freqs > 0))
    if band.size == 0:
        raise InputError("no frequency bin falls in the signal band; increase n_samples",
                         field="n_samples")
    fb = freqs[band]
    spectrum = np.zeros((pts.shape[0], freqs.size), dtype=complex)
    if method == "angular_spectrum":
        spectrum[:, band] = _angular_spectrum_field(vt, setting, points_or_plane, fb, t0,
                                                    points_per_wavelength)
        if progress is not None:
            progress(pts.shape[0], pts.shape[0])
    else:
        surface, velocity = surface_velocity(vt, setting, fb,
                                             points_per_wavelength=points_per_wavelength)
        ones = np.tile([0.0, 0.0, 1.0], (1, 1))
        chunk = max(1, int(target_chunk))
        for start in range(0, pts.shape[0], chunk):
            sel = pts[start:start + chunk]
            target = Surface(sel, np.repeat(ones, sel.shape[0], axis=0), np.ones(sel.shape[0]))
            spectrum[start:start + chunk, band] = rayleigh_integral(
                velocity, surface, target, fb, vt.medium, kernel="fwd_vp", baffle="rigid",
                time_origin=c0 * t0)
            if progress is not None:
                progress(min(start + chunk, pts.shape[0]), pts.shape[0])
    # continuous spectrum (Pa·s) -> samples: conj(rfft(p)) = P / dt
    pressure = to_time(spectrum * fs, n, axis=-1)
    time = t0 + np.arange(n) / fs
    return FieldPrediction(time, pressure, pts, (f_lo, f_hi),
                           "angular_spectrum" if method == "angular_spectrum" else "rayleigh")


def _angular_spectrum_field(vt: VirtualTransducer, setting: TransmitSetting,
                            plane: PlaneGrid, frequencies: NDArray, t0: float,
                            points_per_wavelength: float) -> NDArray[np.complex128]:
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
    xc, yc = vt.aperture_center
    hw = 0.5 * ((vt.element_count - 1) * vt.pitch + vt.element_width)
    hh = 0.5 * vt.element_height
    ox, oy = plane.pose.origin[0], plane.pose.origin[1]
    x_lo = min(plane.x[0] + ox, xc - hw) - sdx
    x_hi = max(plane.x[-1] + ox, xc + hw) + sdx
    y_lo = min(plane.y[0] + oy, yc - hh) - sdy
    y_hi = max(plane.y[-1] + oy, yc + hh) + sdy
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
