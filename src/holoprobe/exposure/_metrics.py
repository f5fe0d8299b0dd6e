"""Acoustic output quantities of IEC 62127-1 / IEC 62359 (FDA "track 3") from p(t).

Every quantity is computed from sampled pressure waveforms p(t) (Pa) at a set of
points (m, transducer coordinates, z the depth along the beam axis). The
definitions followed:

* peak compressional / rarefactional pressure p_c = max p(t), p_r = −min p(t);
* pulse intensity integral ``PII = ∫ p² dt / (ρ0 c0)`` (J/m², plane-wave
  approximation of the intensity);
* pulse duration ``PD = 1.25 (t_90 − t_10)`` with t_10, t_90 the times at which
  the running integral of p² reaches 10 % and 90 % of its total;
* pulse-average intensity ``I_pa = PII / PD``; temporal-average intensity
  ``I_ta = PII · PRF`` (one pulse per repetition period);
* acoustic-working frequency f_awf: the arithmetic mean of the −3 dB points of the
  amplitude spectrum (IEC "arithmetic-mean acoustic-working frequency", default),
  the zero-crossing frequency, or the spectral centroid;
* derating for an attenuating path of α = 0.3 dB/(cm·MHz):
  ``p_α = p · 10^(−α f z / 20)`` and ``I_α = I · 10^(−α f z / 10)`` with f in MHz and
  z in cm;
* mechanical index ``MI = p_r,α(z_MI) / √f_awf`` with p_r,α in MPa and f_awf in MHz,
  z_MI the depth of the maximum derated PII on the beam axis and f_awf measured at
  that point (IEC 62359); the derating uses that same f_awf, so z_MI and f_awf are
  found together (fixed-point iteration);
* −6 dB beam widths: the width of the pulse-pressure-squared-integral profile at
  −6 dB (a quarter of the maximum PII, i.e. half the pressure amplitude) through
  the spatial-peak point, along x (lateral) and y (elevation).

References
----------
IEC 62127-1:2022, Ultrasonics – Hydrophones – Part 1: Measurement and
characterization of medical ultrasonic fields. IEC 62359:2017, Test methods for the
determination of thermal and mechanical indices. FDA (2019), Marketing Clearance of
Diagnostic Ultrasound Systems and Transducers, Appendix G (track 3).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import Medium
from holoprobe.signal import frequency_axis, next_fast_length, to_frequency

__all__ = [
    "DERATING_DB_PER_CM_MHZ",
    "UNITS",
    "ExposureMetrics",
    "acoustic_working_frequency",
    "beam_width",
    "derating_factor",
    "exposure_metrics",
    "mechanical_index",
    "peak_pressures",
    "pulse_duration",
    "pulse_intensity_integral",
]

DERATING_DB_PER_CM_MHZ = 0.3
"""Standard derating attenuation coefficient of IEC 62359 / FDA, in dB/(cm·MHz)."""

_FREQUENCY_METHODS = ("arithmetic_mean", "zero_crossing", "centroid")


# --------------------------------------------------------------------------- checks
def _waveforms(pressure: ArrayLike, name: str = "pressure") -> NDArray[np.float64]:
    try:
        p = np.asarray(pressure, dtype=float)
    except (TypeError, ValueError):
        raise InputError("expected real pressure samples in Pa", field=name) from None
    if p.ndim == 0 or p.shape[-1] < 2:
        raise InputError(f"expected at least 2 time samples along the last axis, got shape "
                         f"{p.shape}", field=name)
    if not np.all(np.isfinite(p)):
        raise InputError("contains NaN or inf", field=name)
    return p


def _rate(sampling_rate: float) -> float:
    try:
        fs = float(sampling_rate)
    except (TypeError, ValueError):
        raise InputError(f"expected a sampling rate in Hz, got {sampling_rate!r}",
                         field="sampling_rate") from None
    if not (math.isfinite(fs) and fs > 0):
        raise InputError(f"expected a positive sampling rate in Hz, got {fs!r}",
                         field="sampling_rate")
    return fs


# --------------------------------------------------------------------------- waveforms
def peak_pressures(pressure: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Peak compressional and rarefactional pressure of each waveform.

    Parameters
    ----------
    pressure : array_like, shape (..., nt)
        Pressure in Pa, time along the last axis.

    Returns
    -------
    p_c, p_r : ndarray, shape (...)
        ``max p(t)`` and ``−min p(t)`` in Pa (p_r is a positive number for a
        rarefaction).
    """
    p = _waveforms(pressure)
    return p.max(axis=-1), -p.min(axis=-1)


def pulse_intensity_integral(pressure: ArrayLike, sampling_rate: float,
                             medium: Medium | None = None, *,
                             noise_variance: ArrayLike | None = None) -> NDArray[np.float64]:
    """Pulse intensity integral ``PII = ∫ p(t)² dt / (ρ0 c0)`` (IEC 62127-1).

    Parameters
    ----------
    pressure : array_like, shape (..., nt)
        Pressure in Pa, time along the last axis; the record holds the whole pulse.
    sampling_rate : float
        Sampling rate in Hz.
    medium : Medium, optional
        ρ0 and c0 (default water, :class:`holoprobe.geometry.Medium`).
    noise_variance : array_like, broadcastable to ``pressure``, optional
        Variance (Pa²) of zero-mean noise in each sample; its expected contribution
        ``Σ σ²`` to ``Σ p²`` is subtracted (an unbiased PII from a noisy record).

    Returns
    -------
    ndarray, shape (...)
        PII in J/m². The integral is the sum of the samples times 1/fs, exact for a
        band-limited pulse sampled above Nyquist that starts and ends at zero.
    """
    p = _waveforms(pressure)
    fs = _rate(sampling_rate)
    med = Medium() if medium is None else medium
    energy = np.einsum("...t,...t->...", p, p)
    if noise_variance is not None:
        energy = energy - np.sum(np.broadcast_to(noise_variance, p.shape), axis=-1)
    return energy / fs / med.impedance


def pulse_duration(pressure: ArrayLike, sampling_rate: float, *, lower: float = 0.1,
                   upper: float = 0.9, factor: float = 1.25,
                   noise_variance: ArrayLike | None = None) -> NDArray[np.float64]:
    """Pulse duration: ``factor × (t_upper − t_lower)`` of the running integral of p².

    IEC 62127-1: 1.25 times the interval between the times at which the running
    time integral of p² reaches 10 % and 90 % of its final value. The crossing
    times are linearly interpolated between samples of the running sum.

    Parameters
    ----------
    pressure : array_like, shape (..., nt)
        Pressure in Pa, time along the last axis.
    sampling_rate : float
        Sampling rate in Hz.
    lower, upper : float
        Fractions of the total (0 < lower < upper < 1).
    factor : float
        Multiplier (1.25 in IEC 62127-1: it makes PD equal to the length of a
        rectangular pulse).
    noise_variance : array_like, broadcastable to ``pressure``, optional
        Variance (Pa²) of zero-mean noise per sample, subtracted from ``p²`` before the
        running integral (whose noise ramp would otherwise stretch PD); the running
        integral is then made non-decreasing (running maximum).

    Returns
    -------
    ndarray, shape (...)
        Pulse duration in s (NaN for an all-zero waveform).
    """
    p = _waveforms(pressure)
    fs = _rate(sampling_rate)
    if not (0 < lower < upper < 1):
        raise InputError(f"expected 0 < lower < upper < 1, got {lower!r}, {upper!r}",
                         field="lower")
    power = p * p
    if noise_variance is not None:
        power = power - np.broadcast_to(noise_variance, p.shape)
        energy = np.maximum.accumulate(np.maximum(np.cumsum(power, axis=-1), 0.0), axis=-1)
    else:
        energy = np.cumsum(power, axis=-1)
    total = energy[..., -1:]
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = energy / total
    # running integral sampled at the END of each sample interval: sample i covers
    # [i, i+1) / fs, so frac[i] is the value at t = (i + 1) / fs; prepend 0 at t = 0
    frac = np.concatenate([np.zeros((*frac.shape[:-1], 1)), frac], axis=-1)
    flat = frac.reshape(-1, frac.shape[-1])
    out = np.full(flat.shape[0], np.nan)
    for k, row in enumerate(flat):
        if not np.all(np.isfinite(row)):
            continue
        t_lo = _first_crossing(row, lower)
        t_hi = _first_crossing(row, upper)
        out[k] = factor * (t_hi - t_lo) / fs
    return out.reshape(p.shape[:-1])


def _first_crossing(row: NDArray, level: float) -> float:
    """Fractional sample index where a non-decreasing ``row`` first reaches ``level``."""
    i = int(np.searchsorted(row, level, side="left"))
    if i == 0:
        return 0.0
    a, b = row[i - 1], row[i]
    return i - 1 + (level - a) / (b - a) if b > a else float(i)


def acoustic_working_frequency(pressure: ArrayLike, sampling_rate: float, *,
                               method: str = "arithmetic_mean", level_db: float = -3.0,
                               pad_factor: int = 16, threshold: float = 0.1
                               ) -> NDArray[np.float64]:
    """Acoustic-working frequency of each waveform (IEC 62127-1).

    Parameters
    ----------
    pressure : array_like, shape (..., nt)
        Pressure in Pa, time along the last axis.
    sampling_rate : float
        Sampling rate in Hz.
    method : {"arithmetic_mean", "zero_crossing", "centroid"}
        ``"arithmetic_mean"``: the mean (f1 + f2)/2 of the frequencies where the
        amplitude spectrum, walking outwards from its peak, falls to ``level_db``
        (linear interpolation between bins of the ``pad_factor``-times zero-padded
        spectrum). ``"zero_crossing"``: ``(n − 1) / (2 (t_n − t_1))`` over the n zero
        crossings (linearly interpolated) inside the part of the record where |p|
        exceeds ``threshold`` × its maximum. ``"centroid"``: ``∫ f |P|² df / ∫ |P|² df``.
    level_db : float
        Band level of the arithmetic-mean method, dB re the peak (negative).
    pad_factor : int
        Zero-padding factor of the spectrum (≥ 1).
    threshold : float
        Relative amplitude that delimits the pulse for the zero-crossing method.

    Returns
    -------
    ndarray, shape (...)
        f_awf in Hz (NaN for an all-zero waveform).
    """
    p = _waveforms(pressure)
    fs = _rate(sampling_rate)
    if method not in _FREQUENCY_METHODS:
        raise InputError(f"expected one of {_FREQUENCY_METHODS}, got {method!r}",
                         field="method")
    flat = p.reshape(-1, p.shape[-1])
    out = np.full(flat.shape[0], np.nan)
    if method == "zero_crossing":
        for k, row in enumerate(flat):
            out[k] = _zero_crossing_frequency(row, fs, threshold)
        return out.reshape(p.shape[:-1])
    if int(pad_factor) < 1:
        raise InputError("expected an integer ≥ 1", field="pad_factor")
    if not level_db < 0:
        raise InputError(f"expected a negative level in dB, got {level_db!r}",
                         field="level_db")
    n = next_fast_length(flat.shape[-1] * int(pad_factor))
    mag = np.abs(to_frequency(flat, n=n, axis=-1))
    f = frequency_axis(n, fs)
    for k, m in enumerate(mag):
        peak = m.max()
        if not peak > 0:
            continue
        if method == "centroid":
            out[k] = float(np.sum(f * m * m) / np.sum(m * m))
            continue
        level = peak * 10 ** (level_db / 20)
        i = int(np.argmax(m))
        lo = i
        while lo > 0 and m[lo - 1] > level:
            lo -= 1
        hi = i
        while hi < m.size - 1 and m[hi + 1] > level:
            hi += 1
        f1 = (f[lo] if lo == 0 else
              f[lo - 1] + (level - m[lo - 1]) / (m[lo] - m[lo - 1]) * (f[lo] - f[lo - 1]))
        f2 = (f[hi] if hi == m.size - 1 else
              f[hi] + (m[hi] - level) / (m[hi] - m[hi + 1]) * (f[hi + 1] - f[hi]))
        out[k] = 0.5 * (f1 + f2)
    return out.reshape(p.shape[:-1])


def _zero_crossing_frequency(row: NDArray, fs: float, threshold: float) -> float:
    amp = np.abs(row)
    peak = amp.max()
    if not peak > 0:
        return math.nan
    inside = np.flatnonzero(amp >= threshold * peak)
    seg = row[inside[0]:inside[-1] + 1]
    s = np.signbit(seg)
    idx = np.flatnonzero(s[1:] != s[:-1])
    if idx.size < 2:
        return math.nan
    a, b = seg[idx], seg[idx + 1]
    t = (idx + a / (a - b)) / fs
    return float((t.size - 1) / (2 * (t[-1] - t[0])))


# --------------------------------------------------------------------------- derating
def derating_factor(frequency: ArrayLike, depth: ArrayLike, *,
                    attenuation_db_cm_mhz: float = DERATING_DB_PER_CM_MHZ,
                    quantity: str = "pressure") -> NDArray[np.float64]:
    """Derating factor ``10^(−α f z / 20)`` (pressure) or ``10^(−α f z / 10)`` (intensity).

    Parameters
    ----------
    frequency : array_like
        Acoustic-working frequency in Hz.
    depth : array_like
        Distance z from the transducer face along the beam axis in m (negative
        depths are treated as 0).
    attenuation_db_cm_mhz : float
        α in dB/(cm·MHz), 0.3 by default (IEC 62359, FDA).
    quantity : {"pressure", "intensity"}
        A field amplitude (20 log10) or an energy quantity (10 log10).

    Returns
    -------
    ndarray
        The factor (≤ 1), broadcast over ``frequency`` and ``depth``.
    """
    if quantity not in ("pressure", "intensity"):
        raise InputError(f"expected 'pressure' or 'intensity', got {quantity!r}",
                         field="quantity")
    a = float(attenuation_db_cm_mhz)
    if not (math.isfinite(a) and a >= 0):
        raise InputError(f"expected a non-negative attenuation in dB/(cm·MHz), got {a!r}",
                         field="attenuation_db_cm_mhz")
    f_mhz = np.asarray(frequency, dtype=float) * 1e-6
    z_cm = np.maximum(np.asarray(depth, dtype=float), 0.0) * 1e2
    db = a * f_mhz * z_cm
    return 10.0 ** (-db / (20.0 if quantity == "pressure" else 10.0))


def mechanical_index(rarefactional_pressure: ArrayLike, frequency: ArrayLike,
                     depth: ArrayLike = 0.0, *,
                     attenuation_db_cm_mhz: float = DERATING_DB_PER_CM_MHZ
                     ) -> NDArray[np.float64]:
    """Mechanical index ``MI = p_r,α / √f_awf`` (p_r,α in MPa, f_awf in MHz; IEC 62359).

    Parameters
    ----------
    rarefactional_pressure : array_like
        Peak rarefactional pressure p_r in Pa (positive), measured in water.
    frequency : array_like
        Acoustic-working frequency in Hz.
    depth : array_like
        Depth of the point in m (derating path length; 0: no derating).
    attenuation_db_cm_mhz : float
        Derating coefficient α in dB/(cm·MHz).

    Returns
    -------
    ndarray
        MI (the unit MPa/√MHz is dropped by convention).
    """
    pr = np.asarray(rarefactional_pressure, dtype=float)
    f = np.asarray(frequency, dtype=float)
    if np.any(f <= 0):
        raise InputError("expected positive frequencies in Hz", field="frequency")
    pr_a = pr * derating_factor(f, depth, attenuation_db_cm_mhz=attenuation_db_cm_mhz)
    return pr_a * 1e-6 / np.sqrt(f * 1e-6)


# --------------------------------------------------------------------------- beam width
def beam_width(positions: ArrayLike, profile: ArrayLike, *, level_db: float = -6.0,
               energy: bool = True) -> float:
    """Width of a beam profile at ``level_db`` below its maximum.

    Walks outwards from the maximum to the first samples below the level on each
    side and interpolates the crossing in dB between the two samples
    around it: a parabola in dB through the two samples around the crossing and
    the next one inwards, the maximum itself refined by a parabola in dB through the
    largest sample and its neighbours (both exact for a Gaussian profile).

    Parameters
    ----------
    positions : array_like, shape (n,)
        Positions along the line in m (any order; sorted internally; values at
        repeated positions are averaged).
    profile : array_like, shape (n,)
        Non-negative values: an energy quantity (PII, p²) when ``energy`` is True
        (level 10 log10), an amplitude otherwise (20 log10).
    level_db : float
        Level re the maximum (negative), −6 dB by default.
    energy : bool
        Whether ``profile`` is an energy (True) or amplitude (False) quantity.

    Returns
    -------
    float
        The width in m, or NaN where the profile does not fall below the level on
        both sides within the samples.
    """
    x = np.asarray(positions, dtype=float).reshape(-1)
    v = np.asarray(profile, dtype=float).reshape(-1)
    if x.shape != v.shape or x.size < 3:
        raise InputError(f"expected positions and profile of the same length ≥ 3, got "
                         f"{x.size} and {v.size}", field="profile")
    if not level_db < 0:
        raise InputError(f"expected a negative level in dB, got {level_db!r}",
                         field="level_db")
    # sort; repeated positions (a point that belongs to two lines, equal to within
    # 1e-9 of the span) are averaged
    order = np.argsort(x, kind="stable")
    x, v = x[order], v[order]
    span = float(x[-1] - x[0])
    group = np.concatenate([[0], np.cumsum(np.diff(x) > 1e-9 * span)])
    counts = np.bincount(group)
    x = np.bincount(group, weights=x) / counts
    v = np.bincount(group, weights=v) / counts
    if x.size < 3:
        raise InputError(f"expected at least 3 distinct positions, got {x.size}",
                         field="positions")
    scale = 10.0 if energy else 20.0
    peak = v.max()
    if not peak > 0:
        return math.nan
    with np.errstate(divide="ignore"):
        db = scale * np.log10(np.maximum(v, 0) / peak)
    i = int(np.argmax(v))
    if 0 < i < v.size - 1 and np.all(np.isfinite(db[i - 1:i + 2])):
        # the maximum lies between samples: refine it by the vertex of a parabola in dB
        c2, c1, _ = np.polyfit(x[i - 1:i + 2] - x[i], db[i - 1:i + 2], 2)
        if c2 < 0 and x[i - 1] - x[i] <= -c1 / (2 * c2) <= x[i + 1] - x[i]:
            db = db + c1 * c1 / (4 * c2)  # minus the vertex height (≥ 0 dB above sample)
    lo = i
    while lo > 0 and db[lo - 1] > level_db:
        lo -= 1
    hi = i
    while hi < v.size - 1 and db[hi + 1] > level_db:
        hi += 1
    if lo == 0 or hi == v.size - 1:
        return math.nan

    def cross(j_in: int, j_out: int, j_inner: int) -> float:
        # parabola in dB through the bracketing samples and the next one inwards
        # (exact for a Gaussian profile); linear in dB when that is not possible
        a, b = db[j_in], db[j_out]
        if not np.isfinite(b):
            return float(x[j_out])
        t = min(max((level_db - a) / (b - a), 0.0), 1.0) if b != a else 0.5
        lin = x[j_in] + t * (x[j_out] - x[j_in])
        if j_inner == j_in:
            return float(lin)
        xs = x[[j_inner, j_in, j_out]]
        coef = np.polyfit(xs - x[j_in], db[[j_inner, j_in, j_out]] - level_db, 2)
        roots = np.roots(coef) + x[j_in]
        lo_x, hi_x = sorted((x[j_in], x[j_out]))
        ok = [r.real for r in roots
              if abs(r.imag) < 1e-12 * (hi_x - lo_x + 1) and lo_x <= r.real <= hi_x]
        return float(ok[0]) if ok else float(lin)

    return cross(hi, hi + 1, max(hi - 1, i)) - cross(lo, lo - 1, min(lo + 1, i))


# --------------------------------------------------------------------------- all together
@dataclass(frozen=True)
class ExposureMetrics:
    """Acoustic output quantities of one transmit setting (SI units).

    Attributes
    ----------
    peak_rarefactional_pressure, peak_compressional_pressure : float
        Spatial maxima of p_r and p_c in Pa (water values).
    pulse_intensity_integral : float
        Spatial-peak PII in J/m².
    pulse_duration : float
        Pulse duration at the spatial-peak PII point in s.
    isppa : float
        Spatial-peak pulse-average intensity PII/PD at that point in W/m².
    ispta : float or None
        Spatial-peak temporal-average intensity PII · PRF in W/m² (None without PRF).
    acoustic_working_frequency : float
        f_awf in Hz at the point of maximum derated PII on the beam axis (z_MI): the
        frequency of the MI and of every derating (IEC 62359).
    depth_of_maximum : float
        Depth z of the spatial-peak PII in m.
    position_of_maximum : tuple of 3 floats
        Position of the spatial-peak PII in m.
    mechanical_index : float
        ``p_r,α(z_MI) / √f_awf`` (MPa, MHz).
    depth_mi : float
        z_MI: depth of the maximum derated PII on the beam axis in m.
    peak_rarefactional_pressure_derated : float
        p_r,α at z_MI in Pa.
    pulse_intensity_integral_derated : float
        Maximum derated PII over all points in J/m².
    isppa_derated : float
        Derated I_pa at the point of maximum derated PII in W/m².
    ispta_derated : float or None
        Maximum derated PII × PRF in W/m².
    beam_width_lateral, beam_width_elevation : float
        −6 dB widths (PII profile) along x and y through the spatial-peak point in m
        (NaN where the points do not contain such a line or it does not fall to −6 dB).
    prf : float or None
        Pulse repetition frequency in Hz.
    attenuation_db_cm_mhz : float
        Derating coefficient used.
    frequency_method : str
        How f_awf was computed.
    density, sound_speed : float
        ρ0 (kg/m³) and c0 (m/s) of the medium.
    """

    peak_rarefactional_pressure: float
    peak_compressional_pressure: float
    pulse_intensity_integral: float
    pulse_duration: float
    isppa: float
    ispta: float | None
    acoustic_working_frequency: float
    depth_of_maximum: float
    position_of_maximum: tuple[float, float, float]
    mechanical_index: float
    depth_mi: float
    peak_rarefactional_pressure_derated: float
    pulse_intensity_integral_derated: float
    isppa_derated: float
    ispta_derated: float | None
    beam_width_lateral: float
    beam_width_elevation: float
    prf: float | None
    attenuation_db_cm_mhz: float
    frequency_method: str
    density: float
    sound_speed: float

    def to_dict(self) -> dict[str, object]:
        """Plain JSON-ready dict (SI units; NaN becomes None) with a ``units`` entry."""
        out: dict[str, object] = {}
        for key, value in asdict(self).items():
            if isinstance(value, float) and not math.isfinite(value):
                value = None
            if isinstance(value, tuple):
                value = [float(v) for v in value]
            out[key] = value
        out["units"] = dict(UNITS)
        return out


UNITS = {
    "peak_rarefactional_pressure": "Pa",
    "peak_compressional_pressure": "Pa",
    "pulse_intensity_integral": "J/m^2",
    "pulse_duration": "s",
    "isppa": "W/m^2",
    "ispta": "W/m^2",
    "acoustic_working_frequency": "Hz",
    "depth_of_maximum": "m",
    "position_of_maximum": "m",
    "mechanical_index": "1 (MPa/sqrt(MHz))",
    "depth_mi": "m",
    "peak_rarefactional_pressure_derated": "Pa",
    "pulse_intensity_integral_derated": "J/m^2",
    "isppa_derated": "W/m^2",
    "ispta_derated": "W/m^2",
    "beam_width_lateral": "m",
    "beam_width_elevation": "m",
    "prf": "Hz",
    "attenuation_db_cm_mhz": "dB/(cm*MHz)",
    "density": "kg/m^3",
    "sound_speed": "m/s",
}


def _axis_mask(axis: ArrayLike | None, pts: NDArray[np.float64], i_sp: int,
               tol: float) -> NDArray[np.bool_]:
    """Points on the beam axis: the given mask, or the line parallel to z through the
    spatial-peak point."""
    if axis is None:
        return np.all(np.abs(pts[:, :2] - pts[i_sp, :2]) <= tol, axis=1)
    mask = np.asarray(axis)
    if mask.shape != (pts.shape[0],) or mask.dtype != bool or not mask.any():
        raise InputError(f"expected a boolean mask of shape ({pts.shape[0]},) with at least "
                         "one point on the beam axis", field="axis")
    return mask


def _mi_point(p: NDArray[np.float64], fs: float, pii: NDArray[np.float64],
              z: NDArray[np.float64], on_axis: NDArray[np.bool_], f_start: float,
              attenuation: float, method: str, max_iterations: int = 10
              ) -> tuple[int, float]:
    """Index of the maximum derated PII on the axis and f_awf there, found together:
    the derating uses f_awf and f_awf is measured at the maximum (fixed point; on a
    cycle the point of largest derated PII among the visited ones wins)."""
    idx = np.flatnonzero(on_axis)
    f = f_start
    seen: dict[int, tuple[float, float]] = {}
    for _ in range(max_iterations):
        pii_a = pii[idx] * derating_factor(f, z[idx], attenuation_db_cm_mhz=attenuation,
                                           quantity="intensity")
        i = int(idx[np.argmax(pii_a)])
        if i in seen:
            break
        f_i = float(acoustic_working_frequency(p[i], fs, method=method))
        seen[i] = (f_i, float(pii[i] * derating_factor(
            f_i, z[i], attenuation_db_cm_mhz=attenuation, quantity="intensity")))
        f = f_i
    i_best = max(seen, key=lambda k: seen[k][1])
    return i_best, seen[i_best][0]


def exposure_metrics(pressure: ArrayLike, sampling_rate: float, points: ArrayLike,
                     medium: Medium | None = None, *, prf: float | None = None,
                     attenuation_db_cm_mhz: float = DERATING_DB_PER_CM_MHZ,
                     frequency_method: str = "arithmetic_mean",
                     beam_level_db: float = -6.0, line_tolerance: float = 1e-6,
                     axis: ArrayLike | None = None) -> ExposureMetrics:
    """All acoustic output quantities from pressure waveforms at a set of points.

    Parameters
    ----------
    pressure : array_like, shape (n_points, nt)
        Pressure in Pa; each row one whole pulse at one point.
    sampling_rate : float
        Sampling rate in Hz.
    points : array_like, shape (n_points, 3)
        Positions in m (z: depth along the beam axis, used for derating).
    medium : Medium, optional
        ρ0, c0 (default water).
    prf : float, optional
        Pulse repetition frequency in Hz (needed for I_spta).
    attenuation_db_cm_mhz : float
        Derating coefficient α (0.3 dB/(cm·MHz)).
    frequency_method : str
        See :func:`acoustic_working_frequency`.
    beam_level_db : float
        Level of the beam widths (−6 dB re the maximum PII).
    line_tolerance : float
        Points whose coordinates differ by less than this (m) from the spatial-peak
        point's y and z (lateral line) or x and z (elevation line) form the beam
        width profiles; by default also the beam axis (same x and y).
    axis : array_like of bool, shape (n_points,), optional
        Which points lie on the beam axis (where z_MI is searched, IEC 62359);
        default: the line parallel to z through the spatial-peak PII point.

    Returns
    -------
    ExposureMetrics

    Notes
    -----
    The spatial peak is the point of maximum PII (water values). z_MI is the depth
    of the maximum derated PII *on the beam axis*; f_awf is measured there and is the
    frequency of the derating of every point and of the MI; since the derating
    depends on f_awf, z_MI and f_awf are iterated to a fixed point (IEC 62359, IEC
    62127-1). The other derated quantities take the maximum derated PII over all
    points, derated with that f_awf. A field computed on the axis and on lateral and
    elevation lines through the maximum is enough (``holoprobe output`` does so).
    """
    p = _waveforms(pressure)
    if p.ndim != 2:
        raise InputError(f"expected shape (n_points, nt), got {p.shape}", field="pressure")
    fs = _rate(sampling_rate)
    try:
        pts = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise InputError("expected points (n, 3) in m", field="points") from None
    if pts.shape != (p.shape[0], 3) or not np.all(np.isfinite(pts)):
        raise InputError(f"expected finite points of shape ({p.shape[0]}, 3) in m, got "
                         f"{pts.shape}", field="points")
    med = Medium() if medium is None else medium
    if prf is not None:
        prf = float(prf)
        if not (math.isfinite(prf) and prf > 0):
            raise InputError(f"expected a positive PRF in Hz, got {prf!r}", field="prf")
    pc, pr = peak_pressures(p)
    pii = pulse_intensity_integral(p, fs, med)
    if not np.any(pii > 0):
        raise InputError("the pressure is zero everywhere", field="pressure")
    i_sp = int(np.argmax(pii))
    tol = float(line_tolerance)
    z = pts[:, 2]
    on_axis = _axis_mask(axis, pts, i_sp, tol)
    f_sp = float(acoustic_working_frequency(p[i_sp], fs, method=frequency_method))
    i_mi, f_awf = _mi_point(p, fs, pii, z, on_axis, f_sp, attenuation_db_cm_mhz,
                            frequency_method)
    pd_sp = float(pulse_duration(p[i_sp], fs))
    pii_a = pii * derating_factor(f_awf, z, attenuation_db_cm_mhz=attenuation_db_cm_mhz,
                                  quantity="intensity")
    i_da = int(np.argmax(pii_a))
    pd_da = float(pulse_duration(p[i_da], fs))
    pr_a = float(pr[i_mi] * derating_factor(f_awf, z[i_mi],
                                            attenuation_db_cm_mhz=attenuation_db_cm_mhz))
    mi = pr_a * 1e-6 / math.sqrt(f_awf * 1e-6)
    x0, y0, z0 = pts[i_sp]
    same_z = np.abs(pts[:, 2] - z0) <= tol
    lat = same_z & (np.abs(pts[:, 1] - y0) <= tol)
    ele = same_z & (np.abs(pts[:, 0] - x0) <= tol)
    bw_lat = (beam_width(pts[lat, 0], pii[lat], level_db=beam_level_db)
              if lat.sum() >= 3 else math.nan)
    bw_ele = (beam_width(pts[ele, 1], pii[ele], level_db=beam_level_db)
              if ele.sum() >= 3 else math.nan)
    return ExposureMetrics(
        peak_rarefactional_pressure=float(pr.max()),
        peak_compressional_pressure=float(pc.max()),
        pulse_intensity_integral=float(pii[i_sp]),
        pulse_duration=pd_sp,
        isppa=float(pii[i_sp] / pd_sp),
        ispta=None if prf is None else float(pii[i_sp] * prf),
        acoustic_working_frequency=f_awf,
        depth_of_maximum=float(z0),
        position_of_maximum=(float(x0), float(y0), float(z0)),
        mechanical_index=float(mi),
        depth_mi=float(z[i_mi]),
        peak_rarefactional_pressure_derated=pr_a,
        pulse_intensity_integral_derated=float(pii_a[i_da]),
        isppa_derated=float(pii_a[i_da] / pd_da),
        ispta_derated=None if prf is None else float(pii_a[i_da] * prf),
        beam_width_lateral=float(bw_lat),
        beam_width_elevation=float(bw_ele),
        prf=prf,
        attenuation_db_cm_mhz=float(attenuation_db_cm_mhz),
        frequency_method=frequency_method,
        density=med.density,
        sound_speed=med.sound_speed,
    )
