"""Virtual receiver: the mirror image of the transducer in the reflector plate.

Receive half of the pipeline, paper section III B (reference_spec 1 R2, 2.9).

Geometry (paper Fig. 7a)
------------------------
The front face of a flat plate passes through (0, 0, d) and is rotated by θy'/2 about
y. Mirroring the transducer point (u, v, 0) across it gives (image method)::

    r'(u, v) = (u cos θy' + d sin θy',  v,  d (1 + cos θy') − u sin θy')
             = Ry(θy') @ (u, v, 0) + (x0', 0, z0'),

    x0' = d sin θy',   z0' = d (1 + cos θy'),   so   x0' = z0' sin θy' / (1 + cos θy').

The pulse-echo experiment is therefore a forward propagation from the virtual source
(all elements fire together) to this *virtual sensor*, times the reflection
coefficient Rp. The transmitted wavefront travels along +z (the aperture, ~28 mm, is
far inside its Fresnel distance at 90 mm), so it reaches the image of element u, at
height z = z0' − u sin θy', at ``t(u) = t(0) − u sin θy' / c0``: the arrival line
across the elements has slope

    s = dt/du = −sin θy' / c0      ⇒      θy' = −asin(s c0)          (exact),

not ``−atan(s c0)`` (the paper's text and the published code use tan: 0.004° too
large at 3°). For comparison, the self-echo of one element alone (its specular
path 2 (d cos(θy'/2) − u sin(θy'/2))) would give ``s = −2 sin(θy'/2)/c0``: the same
to first order, 3.4e-4 relative (0.001° at 3°) apart at third order.

Onset and distance (paper section III B)
----------------------------------------
The onset t0 of the element-averaged echo (tilt removed) is the fastest path from the
virtual source to the centre of the virtual sensor plus the receive lens delay,
which the paper writes for z0' < F as

    c0 t0 = (1 + z0'/F) √((H/2)² + F²) − √((1 − z0'/F)² (H/2)² + F²)

(the ray from the aperture edge, where the lens delay is zero, towards the focus
crosses the sensor plane at y = (H/2)(1 − z0'/F) after (z0'/F)√((H/2)²+F²), and the
lens delays it there by its delay at that y). Written as ``c0 t0 = z0' + Δ(z0')`` the
lens path offset Δ has the piecewise form of reference_spec 2.9 ``compute_lens_offset``
(:func:`lens_path_offset`). The published code evaluates ``z0' ≈ c0 t0 − Δ(c0 t0)``,
one fixed-point step; here ``z0' + Δ(z0') = c0 t0`` is solved exactly with
:func:`scipy.optimize.brentq` (the left side increases monotonically). For the
published numbers (t0 = 60.704 µs) the fixed-point step is 0.27 µm short
(z0' = 89.72732 mm exact, 89.72705 mm fixed-point).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.optimize
from numpy.typing import ArrayLike, NDArray

from holoprobe.characterize._receive import ReceiveConfig
from holoprobe.errors import FitError, InputError
from holoprobe.geometry import Pose, Surface
from holoprobe.measurement import ProbeInfo
from holoprobe.signal import (
    butter_highpass_sos,
    detect_onset,
    envelope,
    fractional_delay,
    mad_sigma,
    sosfiltfilt,
    theil_sen,
    to_frequency,
    to_time,
)

__all__ = [
    "ArrivalLine",
    "SensorLayout",
    "VirtualReceiver",
    "aligned_average",
    "average_onset",
    "echo_arrivals",
    "echo_search_window",
    "estimate_virtual_receiver",
    "fit_arrival_line",
    "lens_path_offset",
    "sensor_distance_from_onset",
    "tilt_aligned_average",
    "tilt_from_slope",
    "virtual_sensor_surface",
]

# --------------------------------------------------------------------------- checks
def _rf_array(rf: ArrayLike, field: str = "rf") -> NDArray[np.float64]:
    x = np.asarray(rf)
    if x.ndim == 1:
        x = x[None, :]
    if x.ndim != 2 or x.shape[1] < 8:
        raise InputError(f"expected element RF of shape (n_elements, n_samples ≥ 8), got "
                         f"{np.shape(rf)}", field=field)
    if not np.issubdtype(x.dtype, np.number) or np.iscomplexobj(x):
        raise InputError(f"expected real numbers, got dtype {x.dtype}", field=field)
    x = x.astype(float)
    if not np.all(np.isfinite(x)):
        raise InputError("contains NaN or inf", field=field)
    return x


def _pos(value: float, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"expected a positive number, got {value!r}", field=name) from None
    if not (np.isfinite(v) and v > 0):
        raise InputError(f"expected a positive number, got {value!r}", field=name)
    return v


def _window_indices(window: tuple[float, float] | None, start_time: float, fs: float,
                    n: int, name: str = "window") -> tuple[int, int]:
    if window is None:
        return 0, n
    try:
        t_a, t_b = (float(v) for v in window)
    except (TypeError, ValueError):
        raise InputError("expected (start, stop) in s", field=name) from None
    i0 = max(0, math.ceil((t_a - start_time) * fs - 1e-9))
    i1 = min(n, math.floor((t_b - start_time) * fs + 1e-9) + 1)
    if i1 - i0 < 8:
        raise InputError(f"the window ({t_a:g}, {t_b:g}) s holds {max(i1 - i0, 0)} samples of "
                         f"a record from {start_time:g} s to {start_time + n / fs:g} s; "
                         f"expected at least 8", field=name)
    return i0, i1


def _parabolic(values: NDArray, k: NDArray) -> NDArray:
    """Sub-sample offset of the maxima at integer indices k (rows of ``values``)."""
    rows = np.arange(values.shape[0])
    km = np.clip(k, 1, values.shape[1] - 2)
    a = values[rows, km - 1]
    b = values[rows, km]
    c = values[rows, km + 1]
    den = a - 2 * b + c
    delta = np.where(den < 0, 0.5 * (a - c) / np.where(den < 0, den, -1.0), 0.0)
    delta = np.clip(delta, -0.5, 0.5)
    return km + delta


# --------------------------------------------------------------------------- arrivals
def echo_arrivals(rf: ArrayLike, sampling_rate: float, *, start_time: float = 0.0,
                  window: tuple[float, float] | None = None,
                  method: Literal["envelope", "xcorr"] = "xcorr",
                  noise_guard: float = ReceiveConfig.noise_guard, min_noise_samples: int = 16,
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Arrival time of the main echo on every element, with its peak SNR.

    ``"envelope"``: the maximum of the envelope ``|hilbert(rf)|`` (per-element mean
    removed) inside ``window``, refined below one sample by a parabola through the
    three samples around it. ``"xcorr"``: every element is cross-correlated with the
    element-average template (elements first aligned on their envelope arrivals); the
    arrival is the template's reference time plus the lag of the correlation maximum
    (parabolic refinement). Neither uses the argmax of the raw RF, which jumps by half
    periods between elements (reference_spec 7 item 7).

    Parameters
    ----------
    rf : array_like, shape (n_el, nt)
        Element RF (time last), any unit.
    sampling_rate : float
        Sampling rate in Hz.
    start_time : float
        Time of the first sample in s (relative to the transmit event).
    window : (float, float), optional
        Interval (start, stop) in s, on the same clock as ``start_time``, that holds the
        main echo (e.g. to skip the transmit crosstalk at the start of a record).
        Default: the whole record.
    method : {"envelope", "xcorr"}
        Estimator, see above.
    noise_guard : float
        The noise of every element is measured on the samples of the window that precede
        the median envelope peak by more than this (s): the pre-echo segment.
    min_noise_samples : int
        Fewest pre-echo samples accepted for a noise estimate.

    Returns
    -------
    arrival_times : ndarray, shape (n_el,)
        Arrival times in s (same clock as ``start_time``).
    quality : ndarray, shape (n_el,)
        Peak SNR: envelope peak / noise standard deviation (amplitude ratio; the noise
        σ is 1.4826 MAD of the pre-echo RF, at least the median of that over the
        elements: a noise-free record's numerical floor does not rank the elements).
    """
    x = _rf_array(rf)
    fs = _pos(sampling_rate, "sampling_rate")
    if method not in ("envelope", "xcorr"):
        raise InputError(f"expected 'envelope' or 'xcorr', got {method!r}", field="method")
    i0, i1 = _window_indices(window, float(start_time), fs, x.shape[1])
    x = x - x.mean(axis=1, keepdims=True)
    env = envelope(x, axis=1, pad=False)
    seg = env[:, i0:i1]
    k = np.argmax(seg, axis=1)
    kf = _parabolic(seg, k) + i0
    peak = seg[np.arange(seg.shape[0]), k]
    guard = round(float(noise_guard) * fs)
    k_med = int(np.median(k)) + i0
    stop = k_med - guard
    pre = x[:, i0:max(stop, i0)]
    if pre.shape[1] < int(min_noise_samples):
        raise InputError(
            f"only {pre.shape[1]} pre-echo samples between the window start "
            f"{start_time + i0 / fs:g} s and {noise_guard:g} s before the median echo peak "
            f"at {start_time + k_med / fs:g} s; expected at least {min_noise_samples} "
            f"(start the window earlier or reduce noise_guard)", field="window")
    sigma = np.asarray(mad_sigma(pre, axis=1), dtype=float)
    # the noise of the receive chains is common: an element whose pre-echo segment is
    # quieter than the median (a noise-free record's numerical floor varies 40x between
    # elements; a digitally zero, disconnected channel) does not thereby become the best
    # one (a zero channel's infinite quality rejected every other element)
    positive = sigma[sigma > 0]
    if positive.size:
        sigma = np.maximum(sigma, float(np.median(positive)))
    with np.errstate(divide="ignore", invalid="ignore"):
        quality = np.where(sigma > 0, peak / sigma, np.inf)
    if method == "envelope":
        return start_time + kf / fs, quality
    # cross-correlation with the element-average template
    t_ref = float(np.median(kf))
    w = x[:, i0:i1]
    aligned = fractional_delay(w, -(kf - i0 - (t_ref - i0)) / fs, fs, pad=True)
    template = aligned.mean(axis=0)
    n = w.shape[1]
    nfft = 2 * n
    spec = to_frequency(w, n=nfft) * np.conj(to_frequency(template, n=nfft))[None, :]
    corr = to_time(spec, nfft)
    corr = np.roll(corr, n, axis=1)  # lag −n … n−1 at index 0 … 2n−1
    kc = np.argmax(corr, axis=1)
    lag = _parabolic(corr, kc) - n
    return start_time + (t_ref + lag) / fs, quality


def echo_search_window(rf: ArrayLike, sampling_rate: float, *, start_time: float = 0.0,
                       feedthrough_time: float = 10e-6, threshold: float = 8.0,
                       guard: float = 1e-6) -> tuple[float, float]:
    """Interval of the record that may hold the echo: after the transmit feed-through.

    Every real system records the drive coupling into the receive channels at the
    emission. The element-mean envelope (per-element mean removed) is compared with
    ``threshold`` × its median (the median of a record that mostly holds noise is the
    noise level); a run above it that starts within ``feedthrough_time`` of the
    emission (t = 0 on the record's clock) is the feed-through, and the window starts
    ``guard`` after the envelope falls back below the threshold. No echo of a plate in
    front of the probe arrives that early (10 µs: a plate 7.4 mm away).

    Parameters
    ----------
    rf : array_like, shape (n_el, nt)
        Element RF (time last).
    sampling_rate : float
        Hz.
    start_time : float
        Time of the first sample in s after the emission.
    feedthrough_time : float
        Latest start (s after the emission) of a run taken as feed-through.
    threshold : float
        Level in multiples of the median envelope.
    guard : float
        Gap (s) after the feed-through.

    Returns
    -------
    (float, float)
        (start, stop) in s on the record's clock; the whole record when there is no
        feed-through.
    """
    x = _rf_array(rf)
    fs = _pos(sampling_rate, "sampling_rate")
    x = x - x.mean(axis=1, keepdims=True)
    env = envelope(x, axis=1, pad=False).mean(axis=0)
    t = float(start_time) + np.arange(env.size) / fs
    level = float(threshold) * float(np.median(env))
    above = env > level
    end = (t[-1] + 1.0 / fs)
    if not np.any(above):
        return float(t[0]), end
    first = int(np.argmax(above))
    if t[first] > float(feedthrough_time):
        return float(t[0]), end
    below = np.nonzero(~above[first:])[0]
    if below.size == 0:
        return float(t[0]), end
    return float(t[first + int(below[0])] + float(guard)), end


# --------------------------------------------------------------------------- line fit
@dataclass(frozen=True)
class ArrivalLine:
    """Robust line ``t = intercept + slope · x`` through the echo arrivals.

    Attributes
    ----------
    slope, intercept : float
        s in s/m and the arrival at x = 0 in s.
    slope_uncertainty, intercept_uncertainty : float
        Standard uncertainties (least squares on the used elements, residual scatter).
    used : ndarray of bool, shape (n_el,)
        Elements that entered the final fit.
    residual_rms : float
        RMS residual of the used elements in s.
    """

    slope: float
    intercept: float
    slope_uncertainty: float
    intercept_uncertainty: float
    used: NDArray[np.bool_]
    residual_rms: float


def fit_arrival_line(element_x: ArrayLike, arrival_times: ArrayLike, quality: ArrayLike, *,
                     min_quality: float = 10.0, min_relative_quality: float = 0.25,
                     outlier_threshold: float = 4.0, loss: str = "soft_l1",
                     min_elements: int = 3, max_iterations: int = 10,
                     uncertainty: ArrayLike | None = None) -> ArrivalLine:
    """Fit the arrival line over the usable elements, chosen from the data.

    1. Candidates: finite arrivals with ``quality ≥ max(min_quality,
       min_relative_quality · max(quality))`` (weak or dead elements out).
    2. A robust start (Theil–Sen), then :func:`scipy.optimize.least_squares` with the
       robust ``loss`` scaled by the residuals' 1.4826·MAD.
    3. Elements whose residual exceeds ``outlier_threshold`` robust σ are rejected; an
       ordinary least-squares fit on the rest gives the line and its uncertainties;
       steps 2–3 repeat until the set of used elements stops changing.

    With ``uncertainty`` (each arrival's standard uncertainty) the residuals are those
    divided by it (their robust σ at least 1), the final fit is weighted least squares
    and its covariance is ``(AᵀWA)⁻¹`` times the Birge ratio ``max(1, χ²/dof)``: the
    arrivals of a tilted sensor are far from equally good (the weak end of a 32-element
    twin at −4.9° has 4–5 times the delay noise of the other), and an unweighted fit
    with the common scatter neither uses them well nor gives an honest slope σ.

    Parameters
    ----------
    element_x : array_like, shape (n_el,)
        Lateral element positions in m (virtual transducer coordinates).
    arrival_times : array_like, shape (n_el,)
        Arrival times in s (:func:`echo_arrivals`).
    quality : array_like, shape (n_el,)
        Peak SNR per element (amplitude ratio).
    min_quality : float
        Absolute SNR floor for a usable element.
    min_relative_quality : float
        SNR floor relative to the best element.
    outlier_threshold : float
        Rejection level in robust standard deviations of the residuals.
    loss : str
        Robust loss of :func:`scipy.optimize.least_squares` (``"soft_l1"``, ``"huber"``,
        ``"cauchy"``, ``"linear"``).
    min_elements : int
        Fewest usable elements.
    max_iterations : int
        Largest number of fit / reject rounds.

    Returns
    -------
    ArrivalLine
    """
    x = np.asarray(element_x, dtype=float).reshape(-1)
    t = np.asarray(arrival_times, dtype=float).reshape(-1)
    q = np.asarray(quality, dtype=float).reshape(-1)
    u = np.ones_like(t) if uncertainty is None else np.asarray(
        uncertainty, dtype=float).reshape(-1)
    if not (x.shape == t.shape == q.shape == u.shape):
        raise InputError(f"element_x, arrival_times, quality (and uncertainty) must have the "
                         f"same length, got {x.size}, {t.size}, {q.size}, {u.size}",
                         field="arrival_times")
    ok = np.isfinite(t) & np.isfinite(x) & ~np.isnan(q) & np.isfinite(u) & (u > 0)
    qmax = float(np.max(np.where(ok, q, -np.inf))) if np.any(ok) else 0.0
    floor = max(float(min_quality), float(min_relative_quality) * qmax)
    cand = ok & (q >= floor)
    if cand.sum() < max(int(min_elements), 2):
        raise FitError(f"only {int(cand.sum())} elements have an echo with peak SNR ≥ "
                       f"{floor:.3g} (best {qmax:.3g}); expected at least "
                       f"{max(int(min_elements), 2)}: check the window and the data",
                       field="rf")
    xc, tc = x[cand], t[cand]
    slope0, intercept0 = theil_sen(xc, tc)
    p = np.array([intercept0, slope0])
    used = cand.copy()
    weighted = uncertainty is not None
    floor = 1.0 if weighted else 1e-15  # normalised residuals: robust σ at least 1
    for _ in range(int(max_iterations)):
        r = (t[cand] - (p[0] + p[1] * x[cand])) / u[cand]
        scale = float(mad_sigma(r[used[cand]])) if used.sum() > 2 else 0.0
        scale = max(scale, floor)
        xu, tu, uu = x[used], t[used], u[used]
        sol = scipy.optimize.least_squares(
            lambda pp, xu=xu, tu=tu, uu=uu: (tu - (pp[0] + pp[1] * xu)) / uu, p, loss=loss,
            f_scale=scale)
        p = sol.x
        r = (t - (p[0] + p[1] * x)) / u
        sig = float(mad_sigma(r[used]))
        sig = max(sig, scale)
        new_used = cand & (np.abs(r) <= float(outlier_threshold) * sig)
        if new_used.sum() < max(int(min_elements), 2):
            new_used = used
        if np.array_equal(new_used, used):
            break
        used = new_used
    w = 1.0 / u[used]
    a = np.stack([np.ones(used.sum()), x[used]], axis=1)
    coef, *_ = np.linalg.lstsq(a * w[:, None], t[used] * w, rcond=None)
    r = t[used] - a @ coef
    dof = max(used.sum() - 2, 1)
    s2 = float(np.sum((r * w) ** 2)) / dof
    cov = np.linalg.pinv((a * w[:, None]).T @ (a * w[:, None])) * (max(s2, 1.0) if weighted
                                                                   else s2)
    return ArrivalLine(slope=float(coef[1]), intercept=float(coef[0]),
                       slope_uncertainty=float(np.sqrt(cov[1, 1])),
                       intercept_uncertainty=float(np.sqrt(cov[0, 0])),
                       used=used, residual_rms=float(np.sqrt(np.mean(r**2))))


def tilt_from_slope(slope: float, sound_speed: float) -> float:
    """Virtual-sensor tilt θy' (rad) from the arrival slope: ``θy' = −asin(s c0)``.

    See the module notes for the derivation (a plane wavefront along +z reaches the
    image of element u at ``z0' − u sin θy'``).
    """
    c0 = _pos(sound_speed, "sound_speed")
    v = -float(slope) * c0
    if not abs(v) < 1:
        raise InputError(f"|slope · c0| = {abs(v):.3g} ≥ 1: the arrival line is steeper than "
                         f"a wave along the array; check the element positions and the "
                         f"arrival times", field="slope")
    return math.asin(v)


# --------------------------------------------------------------------------- t0 ↔ z0'
def lens_path_offset(distance: ArrayLike, focus: float, height: float) -> NDArray:
    """Extra fastest-path length Δ(D) that the two lens passes add (m).

    The fastest path between the virtual source and a parallel virtual sensor at
    distance D, both behind a cylindrical lens of focus F over the height H
    (a = H/2, lens delays zero at the edges), is ``D + Δ(D)``
    (reference_spec 2.9 ``compute_lens_offset``; paper section III B for D < F):

    * D < F:        Δ = (1 + D/F)√(F² + a²) − √(F² + (1 − D/F)² a²) − D
      (edge ray towards the focus);
    * F ≤ D < 2F:   Δ = 2√(F² + a²) − 2F (path through the focus);
    * D ≥ 2F:       Δ = √(F² + a²) + √((F − D)² + a²) − D;
    * F = ∞:        Δ = 0.

    Parameters
    ----------
    distance : array_like
        D in m (≥ 0).
    focus : float
        F in m (> 0; ``inf`` for no lens).
    height : float
        H in m.

    Returns
    -------
    ndarray
        Δ in m, same shape as ``distance``.
    """
    d = np.asarray(distance, dtype=float)
    f = float(focus)
    if not f > 0:
        raise InputError(f"expected a positive focus in m (inf: no lens), got {focus!r}",
                         field="focus")
    a = 0.5 * _pos(height, "height")
    if np.isinf(f):
        return np.zeros_like(d)
    s = math.sqrt(f * f + a * a)
    near = (1 + d / f) * s - np.sqrt(f * f + (1 - d / f) ** 2 * a * a) - d
    mid = np.full_like(d, 2 * s - 2 * f)
    far = s + np.sqrt((f - d) ** 2 + a * a) - d
    return np.where(d < f, near, np.where(d < 2 * f, mid, far))


def sensor_distance_from_onset(onset: float, focus: float, height: float,
                               sound_speed: float, *, xtol: float = 1e-13) -> float:
    """Distance z0' of the virtual sensor from the receive onset (paper section III B).

    Solves ``z0' + Δ(z0') = c0 t0`` exactly (:func:`lens_path_offset`,
    :func:`scipy.optimize.brentq`); the published code takes one fixed-point step
    ``c0 t0 − Δ(c0 t0)``.

    Parameters
    ----------
    onset : float
        t0 in s (> 0).
    focus, height : float
        Lens focus F (``inf``: no lens) and aperture height H in m.
    sound_speed : float
        c0 in m/s.
    xtol : float
        Absolute tolerance of the root in m.

    Returns
    -------
    float
        z0' in m.

    Examples
    --------
    >>> z = sensor_distance_from_onset(60.704e-6, 0.1806689295, 0.0142790297, 1481.0)
    >>> round(z * 1e3, 4)
    89.7273
    """
    t0 = _pos(onset, "onset")
    c0 = _pos(sound_speed, "sound_speed")
    target = c0 * t0
    lens_path_offset(0.0, focus, height)  # validates focus and height

    def g(dist: float) -> float:
        return dist + float(lens_path_offset(dist, focus, height)) - target

    hi = target
    while g(hi) < 0:
        hi *= 2
    return float(scipy.optimize.brentq(g, 0.0, hi, xtol=xtol, rtol=4 * np.finfo(float).eps))


# --------------------------------------------------------------------------- averaging
def aligned_average(signals: ArrayLike, sampling_rate: float, delays: ArrayLike, *,
                    used: ArrayLike | None = None) -> NDArray:
    """Advance every trace by its own delay and average the used ones.

    Each trace is advanced by ``delays[e]`` (band-limited fractional delay, zero-padded
    so nothing wraps): the arrivals that the delays describe line up at delay 0.

    Parameters
    ----------
    signals : array_like, shape (n_el, nt)
        Element traces (RF or receive pressure), time last.
    sampling_rate : float
        Hz.
    delays : array_like, shape (n_el,)
        Delay of every trace in s (e.g. ``s · x_e`` of a flat array's arrival line, or
        the geometric echo delays of a convex array).
    used : array_like of bool, shape (n_el,), optional
        Elements to average (default all).

    Returns
    -------
    ndarray, shape (nt,)
    """
    y = _rf_array(signals, "signals")
    fs = _pos(sampling_rate, "sampling_rate")
    tau = np.asarray(delays, dtype=float).reshape(-1)
    if tau.size != y.shape[0]:
        raise InputError(f"expected {y.shape[0]} element delays, got {tau.size}",
                         field="delays")
    m = np.ones(tau.size, bool) if used is None else np.asarray(used, bool).reshape(-1)
    if m.size != tau.size or not np.any(m):
        raise InputError(f"expected a non-empty mask of {tau.size} elements", field="used")
    aligned = fractional_delay(y[m], -tau[m], fs, pad=True)
    return aligned.mean(axis=0)


def tilt_aligned_average(signals: ArrayLike, sampling_rate: float, element_x: ArrayLike,
                         slope: float, *, used: ArrayLike | None = None) -> NDArray:
    """Remove the tilt delays ``s · x`` of every element and average the used ones
    (:func:`aligned_average` with the delays ``s · x_e``: every arrival brought to that
    of x = 0).

    Parameters
    ----------
    signals : array_like, shape (n_el, nt)
        Element traces (RF or receive pressure), time last.
    sampling_rate : float
        Hz.
    element_x : array_like, shape (n_el,)
        Element positions in m.
    slope : float
        Arrival slope s in s/m.
    used : array_like of bool, shape (n_el,), optional
        Elements to average (default all).

    Returns
    -------
    ndarray, shape (nt,)
    """
    n = _rf_array(signals, "signals").shape[0]
    x = np.asarray(element_x, dtype=float).reshape(-1)
    if x.size != n:
        raise InputError(f"expected {n} element positions, got {x.size}",
                         field="element_x")
    return aligned_average(signals, sampling_rate, float(slope) * x, used=used)


# --------------------------------------------------------------------------- receiver
@dataclass(frozen=True)
class VirtualReceiver:
    """Pose and timing of the virtual sensor (paper section III B).

    Attributes
    ----------
    theta_y : float
        Tilt θy' in rad (θx' = θz' = 0: not observable with a linear array).
    x0, z0 : float
        Centre (x0', 0, z0') of the virtual sensor in m.
    onset : float
        t0 in s (transmit clock).
    distance : float
        Reflector distance d = z0'/(1 + cos θy') in m.
    theta_y_uncertainty, x0_uncertainty, z0_uncertainty, onset_uncertainty,
    distance_uncertainty : float
        Standard uncertainties (rad, m, m, s, m).
    slope : float
        Arrival slope s in s/m.
    used : ndarray of bool, shape (n_el,)
        Elements used for the line fit and the average.
    arrival_times, quality : ndarray, shape (n_el,)
        Per-element echo arrivals (s) and peak SNR.
    averaged_rf : ndarray, shape (nt,)
        Tilt-aligned, averaged, high-passed RF (for the report, paper Fig. 7c).
    start_time, sampling_rate : float
        Time of the first sample of ``averaged_rf`` (s) and its rate (Hz).
    theta_x, theta_z, y0 : float
        Always 0.
    onset_shift : float
        Delay (s) moved from the echo's onset into the geometry: z0' is that of the
        onset ``onset − onset_shift`` (the receive IR's onset convention; 0 for the
        arrival-line estimate).
    """

    theta_y: float
    x0: float
    z0: float
    onset: float
    distance: float
    theta_y_uncertainty: float = 0.0
    x0_uncertainty: float = 0.0
    z0_uncertainty: float = 0.0
    onset_uncertainty: float = 0.0
    distance_uncertainty: float = 0.0
    slope: float = 0.0
    used: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, bool))
    arrival_times: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    quality: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    averaged_rf: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    start_time: float = 0.0
    sampling_rate: float = 1.0
    theta_x: float = 0.0
    theta_z: float = 0.0
    y0: float = 0.0
    onset_shift: float = 0.0

    @classmethod
    def from_geometry(cls, theta_y: float, onset: float, focus: float, height: float,
                      sound_speed: float) -> VirtualReceiver:
        """Pose from θy' (rad) and t0 (s) alone (exact z0', then d and x0')."""
        z0 = sensor_distance_from_onset(onset, focus, height, sound_speed)
        d = z0 / (1 + math.cos(theta_y))
        return cls(theta_y=float(theta_y), x0=d * math.sin(theta_y), z0=z0,
                   onset=float(onset), distance=d)

    def pose(self) -> Pose:
        """The virtual sensor's :class:`~holoprobe.Pose` (in-plane (u, v) = element coords)."""
        return Pose(self.theta_x, self.theta_y, self.theta_z, (self.x0, self.y0, self.z0))

    def surface(self, probe: ProbeInfo, height: float, *, spacing: float,
                center_y: float = 0.0, element_width: float | None = None,
                ) -> tuple[Surface, SensorLayout]:
        """Sampled virtual sensor, see :func:`virtual_sensor_surface`."""
        return virtual_sensor_surface(self, probe, height, spacing=spacing,
                                      center_y=center_y, element_width=element_width)


def average_onset(average: NDArray, sampling_rate: float, *, start_time: float,
                  window: tuple[float, float], arrival: float, noise_guard: float,
                  highpass_cutoff: float = 0.1e6, highpass_order: int = 3,
                  onset_threshold: float = 5.0, onset_upsample: int = 10,
                  ) -> tuple[NDArray, float, float]:
    """High-passed aligned echo average, its onset t0 and the onset's uncertainty.

    The average (mean removed) is high-passed (zero-phase Butterworth,
    :func:`holoprobe.signal.sosfiltfilt`); its onset is
    :func:`holoprobe.signal.detect_onset` inside ``window`` with the noise σ of the
    samples more than ``noise_guard`` before ``arrival`` (the aligned echo's peak); the
    onset's standard uncertainty is that σ over the signal's slope at the crossing.

    Parameters
    ----------
    average : ndarray, shape (nt,)
        Aligned element average of the echo RF.
    sampling_rate : float
        Hz.
    start_time : float
        Time of sample 0 in s (transmit clock).
    window : (float, float)
        Interval (s) holding the echo and a pre-echo noise segment.
    arrival : float
        Time of the aligned echo's peak in s.
    noise_guard : float
        s, see above.
    highpass_cutoff, highpass_order, onset_threshold, onset_upsample
        See :func:`estimate_virtual_receiver`.

    Returns
    -------
    average : ndarray, shape (nt,)
        The high-passed average.
    onset, onset_uncertainty : float
        t0 and its standard uncertainty in s.
    """
    fs = _pos(sampling_rate, "sampling_rate")
    avg = np.asarray(average, dtype=float)
    if highpass_cutoff and highpass_cutoff > 0:
        if not highpass_cutoff < fs / 2:
            raise InputError(f"expected a cut-off below the Nyquist frequency {fs / 2:g} Hz",
                             field="highpass_cutoff")
        # NumPy, not scipy.signal: importing it (and scipy.stats) costs ≈ 0.3–1 s CPU
        avg = sosfiltfilt(butter_highpass_sos(int(highpass_order), float(highpass_cutoff),
                                              fs), avg)
    i0, i1 = _window_indices(window, float(start_time), fs, avg.size)
    seg = avg[i0:i1]
    t_c = arrival - start_time - i0 / fs  # the arrival, s into the segment
    stop = math.floor((t_c - noise_guard) * fs)
    pre = seg[:max(stop, 0)]
    if pre.size < 16:
        raise InputError(f"only {pre.size} pre-echo samples in the window before the echo "
                         f"(arrival {arrival:g} s); start the window earlier",
                         field="window")
    sigma = float(mad_sigma(pre))
    try:
        onset_rel = detect_onset(seg, fs, threshold=onset_threshold, upsample=onset_upsample,
                                 noise=sigma, allow_wrap=False)
    except FitError as err:
        raise FitError(f"receive onset: {err.detail}", field="rf") from None
    t0 = float(start_time + i0 / fs + onset_rel)
    # onset uncertainty: noise over the signal's slope at the crossing
    tt = np.arange(seg.size) / fs
    deriv = np.gradient(seg, tt)
    slope_at = abs(float(np.interp(onset_rel + 2.0 / fs, tt, deriv)))
    sig_t0 = sigma / slope_at if slope_at > 0 else float("inf")
    return avg, t0, sig_t0


def estimate_virtual_receiver(
    rf: ArrayLike, sampling_rate: float, element_x: ArrayLike, *, focus: float,
    height: float, sound_speed: float = 1481.0, start_time: float = 0.0,
    window: tuple[float, float] | None = None,
    arrival_method: Literal["envelope", "xcorr"] = "xcorr",
    noise_guard: float = ReceiveConfig.noise_guard,
    min_quality: float = 10.0, min_relative_quality: float = 0.25,
    outlier_threshold: float = 4.0, loss: str = "soft_l1", highpass_cutoff: float = 0.1e6,
    highpass_order: int = 3, onset_threshold: float = 5.0, onset_upsample: int = 10,
) -> VirtualReceiver:
    """Virtual receiver from the element RF of the reflector echo (paper section III B).

    1. :func:`echo_arrivals` and :func:`fit_arrival_line` ⇒ slope s, usable elements;
       θy' = −asin(s c0) (:func:`tilt_from_slope`).
    2. :func:`tilt_aligned_average` of the used elements, mean removed, zero-phase
       Butterworth high-pass (:func:`holoprobe.signal.sosfiltfilt`).
    3. Onset t0 (:func:`holoprobe.signal.detect_onset`, noise σ from the pre-echo part
       of the window).
    4. z0' exact (:func:`sensor_distance_from_onset`), d = z0'/(1 + cos θy'),
       x0' = d sin θy'.

    Parameters
    ----------
    rf : array_like, shape (n_el, nt)
        Element RF (time last).
    sampling_rate : float
        Hz.
    element_x : array_like, shape (n_el,)
        Lateral element centres in m (e.g. ``ProbeInfo.element_centers()``).
    focus, height : float
        Lens focus F and aperture height H in m (from the transmit fit).
    sound_speed : float
        c0 in m/s.
    start_time : float
        Time of the first RF sample in s after the transmit event.
    window : (float, float), optional
        Interval (s, transmit clock) holding the main echo and a pre-echo noise segment;
        default the record after the transmit feed-through
        (:func:`echo_search_window`).
    arrival_method, noise_guard : see :func:`echo_arrivals`.
    min_quality, min_relative_quality, outlier_threshold, loss : see
        :func:`fit_arrival_line`.
    highpass_cutoff : float
        Cut-off of the zero-phase high-pass in Hz (0: none).
    highpass_order : int
        Butterworth order (applied forwards and backwards: twice the attenuation).
    onset_threshold, onset_upsample : see :func:`holoprobe.signal.detect_onset`.

    Returns
    -------
    VirtualReceiver
    """
    x_rf = _rf_array(rf)
    fs = _pos(sampling_rate, "sampling_rate")
    c0 = _pos(sound_speed, "sound_speed")
    ex = np.asarray(element_x, dtype=float).reshape(-1)
    if ex.size != x_rf.shape[0]:
        raise InputError(f"expected {x_rf.shape[0]} element positions (one per RF channel), "
                         f"got {ex.size}", field="element_x")
    if window is None:  # never take the transmit feed-through for the echo
        window = echo_search_window(x_rf, fs, start_time=start_time)
    t_arr, q = echo_arrivals(x_rf, fs, start_time=start_time, window=window,
                             method=arrival_method, noise_guard=noise_guard)
    line = fit_arrival_line(ex, t_arr, q, min_quality=min_quality,
                            min_relative_quality=min_relative_quality,
                            outlier_threshold=outlier_threshold, loss=loss)
    theta = tilt_from_slope(line.slope, c0)
    sig_theta = c0 * line.slope_uncertainty / math.cos(theta)
    avg = tilt_aligned_average(x_rf - x_rf.mean(axis=1, keepdims=True), fs, ex, line.slope,
                               used=line.used)
    avg, t0, sig_t0 = average_onset(avg, fs, start_time=start_time, window=window,
                                    arrival=line.intercept, noise_guard=noise_guard,
                                    highpass_cutoff=highpass_cutoff,
                                    highpass_order=highpass_order,
                                    onset_threshold=onset_threshold,
                                    onset_upsample=onset_upsample)
    z0 = sensor_distance_from_onset(t0, focus, height, c0)
    dz = 1e-9
    dzdt = (sensor_distance_from_onset(t0 + dz / c0, focus, height, c0) - z0) / dz * c0
    sig_z0 = abs(dzdt) * sig_t0
    cos_t, sin_t = math.cos(theta), math.sin(theta)
    d = z0 / (1 + cos_t)
    sig_d = math.hypot(sig_z0 / (1 + cos_t), z0 * sin_t / (1 + cos_t) ** 2 * sig_theta)
    x0 = d * sin_t
    # x0' = z0' tan(θ/2): derivative z0'/(2 cos²(θ/2)) w.r.t. θ
    sig_x0 = math.hypot(sig_z0 * math.tan(theta / 2),
                        z0 / (2 * math.cos(theta / 2) ** 2) * sig_theta)
    return VirtualReceiver(
        theta_y=theta, x0=x0, z0=z0, onset=t0, distance=d,
        theta_y_uncertainty=sig_theta, x0_uncertainty=sig_x0, z0_uncertainty=sig_z0,
        onset_uncertainty=sig_t0, distance_uncertainty=sig_d, slope=line.slope,
        used=line.used, arrival_times=t_arr, quality=q, averaged_rf=avg,
        start_time=float(start_time), sampling_rate=fs)


# --------------------------------------------------------------------------- surface
@dataclass(frozen=True)
class SensorLayout:
    """How the points of a virtual-sensor :class:`Surface` map to elements.

    Points are element-major: element e owns points ``e·n_per_element`` …
    ``(e+1)·n_per_element − 1``.

    Attributes
    ----------
    element_count, points_per_element : int
    u, v : ndarray, shape (n,)
        In-plane coordinates of the points in m (u lateral, v elevation).
    weights : ndarray, shape (n,)
        Area weights in m².
    height : float
        Element height H in m (lens delays are zero at v − center_y = ±H/2).
    center_y : float
        Elevation of the lens centre in m.
    """

    element_count: int
    points_per_element: int
    u: NDArray[np.float64]
    v: NDArray[np.float64]
    weights: NDArray[np.float64]
    height: float
    center_y: float = 0.0


def virtual_sensor_surface(receiver: VirtualReceiver | Pose, probe: ProbeInfo, height: float,
                           *, spacing: float, center_y: float = 0.0,
                           element_width: float | None = None,
                           ) -> tuple[Surface, SensorLayout]:
    """Sample every element of the virtual sensor (midpoint rule, element-major).

    Each element (width w, height H, centred at ``probe.element_centers()`` laterally
    and at ``center_y`` in elevation) is split into ``ceil(w/spacing) × ceil(H/spacing)``
    equal cells; the points are the cell centres with the cell areas as weights, placed
    by the receiver's pose (the in-plane point (u, v, 0) is the mirror image of the
    transducer point (u, v, 0)); normals face the source (``−R @ (0, 0, 1)``).

    Parameters
    ----------
    receiver : VirtualReceiver or Pose
        Where the virtual sensor is.
    probe : ProbeInfo
        Element count, positions and width.
    height : float
        Element height H in m (the fitted aperture height).
    spacing : float
        Largest point spacing in m (λ/4 at the highest frequency is ample).
    center_y : float
        Elevation centre of the elements in m.
    element_width : float, optional
        Override the probe's element width (m).

    Returns
    -------
    surface : Surface
        n = element_count · points_per_element points.
    layout : SensorLayout
    """
    pose = receiver.pose() if isinstance(receiver, VirtualReceiver) else receiver
    if not isinstance(pose, Pose):
        raise InputError("expected a VirtualReceiver or a Pose", field="receiver")
    if not isinstance(probe, ProbeInfo):
        raise InputError("expected a holoprobe.measurement.ProbeInfo", field="probe")
    h = _pos(height, "height")
    ds = _pos(spacing, "spacing")
    w = _pos(probe.element_width if element_width is None else element_width,
             "element_width")
    nw = max(1, math.ceil(w / ds - 1e-9))
    nh = max(1, math.ceil(h / ds - 1e-9))
    du = (np.arange(nw) + 0.5) / nw * w - w / 2
    dv = (np.arange(nh) + 0.5) / nh * h - h / 2 + float(center_y)
    xe = probe.element_centers()
    uu = (xe[:, None, None] + du[None, :, None] + 0 * dv[None, None, :]).reshape(-1)
    vv = np.broadcast_to(dv[None, None, :], (xe.size, nw, nh)).reshape(-1)
    local = np.stack([uu, vv, np.zeros(uu.size)], axis=-1)
    pts = pose.to_global(local)
    normals = np.broadcast_to(-pose.normal, pts.shape).copy()
    weights = np.full(uu.size, w * h / (nw * nh))
    layout = SensorLayout(element_count=int(xe.size), points_per_element=nw * nh, u=uu,
                          v=vv.copy(), weights=weights, height=h, center_y=float(center_y))
    return Surface(pts, normals, weights), layout
