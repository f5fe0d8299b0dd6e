"""Spurious modes of oscillation in the reconstructed surface velocity (paper section III D,
Fig. 9).

The thickness-expander model assumes a surface that moves uniformly, with the lens delays
symmetric in the elevation coordinate y. A wave launched at the element ends and running
along y with opposite signs on the two halves (an antisymmetric, Lamb-like mode) shows up as
the **odd part** of the velocity about the aperture centre, ``(v(y_c + s) − v(y_c − s))/2``,
which the symmetric main pulse does not have. This module measures that odd part after
the main pulse (a narrowband tail): its frequency, its strength relative to the main pulse,
and its dispersion (k–ω map of the elevation–time map).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import ArrayLike, NDArray

from holoprobe.analysis._common import Aperture, as_aperture
from holoprobe.errors import InputError
from holoprobe.geometry import PlaneGrid, uniform_axis_step
from holoprobe.signal import (
    envelope,
    frequency_axis,
    next_fast_length,
    spectrum_summary,
    to_frequency,
)

__all__ = ["ModesResult", "analyse_modes", "modes_figures"]

_MM, _US, _MHZ = 1e3, 1e6, 1e-6


@dataclass(frozen=True)
class ModesResult:
    """Result of :func:`analyse_modes` (SI units; maps are x-/y-averages of the velocity).

    Attributes
    ----------
    time : ndarray, shape (nt,)
        Sample times in s.
    x, y : ndarray, shape (nx,), (ny,)
        Source-grid coordinates in m.
    aperture : Aperture
        The aperture used (given or estimated).
    edge_position : float
        Elevation y (m) of the edge trace.
    edge_trace : ndarray, shape (nt,)
        Velocity (m/s) at ``edge_position``, averaged across x inside the aperture
        (paper Fig. 9a).
    yt_map : ndarray, shape (ny, nt)
        Velocity (m/s) along y averaged across x inside the aperture (paper Fig. 9b).
    xt_map : ndarray, shape (nx, nt)
        Velocity (m/s) along x averaged across y inside the aperture.
    s : ndarray, shape (ns,)
        Distances from the aperture centre along y (m) of the even/odd parts.
    even_map, odd_map : ndarray, shape (ns, nt)
        ``(m(y_c + s) ± m(y_c − s)) / 2`` of ``yt_map`` (m/s).
    snapshot_times : ndarray, shape (n_snap,)
        Times (s) of the cross-sections.
    snapshots : ndarray, shape (n_snap, ny)
        ``yt_map`` at those times (paper Fig. 9c).
    wavenumber : ndarray, shape (nk,)
        Wavenumbers along y in rad/m, increasing (positive: waves travelling towards +y).
    dispersion_frequency : ndarray, shape (nfd,)
        Frequencies of the dispersion map in Hz.
    dispersion : ndarray, shape (nk, nfd)
        Magnitude of the 2-D Fourier transform of the (gated) y–t map (paper Fig. 9d).
    branch_frequency, branch_wavenumber, branch_phase_velocity : ndarray, shape (nb,)
        The dominant branch: per frequency above ``branch_level_db``, the |k| (rad/m) of
        the maximum and ω/|k| (m/s).
    main_peak : float
        Peak envelope of the even part (the main pulse), m/s.
    main_frequency : float
        Peak frequency of the main pulse (even part at the centre), Hz.
    main_end : float
        End of the main pulse (s): its envelope fell below ``main_level_db``.
    tail_window : (float, float)
        Times (s) of the analysed tail.
    frequency : float
        Peak frequency of the odd tail (Hz, sub-bin); nan without a tail window.
    fractional_bandwidth : float
        −6 dB bandwidth of the tail spectrum over its peak frequency.
    strength_db : float
        Peak envelope of the odd tail over ``main_peak``, in dB.
    noise_db : float or None
        The same for the odd part before the main pulse (None: too few samples).
    phase_velocity : float
        ω/|k| of the branch at ``frequency`` (m/s; nan when not traced there).
    present : bool
        The decision (see :func:`analyse_modes`).
    criteria : dict
        The thresholds of the decision.
    warnings : list of str
    """

    time: NDArray[np.float64]
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    aperture: Aperture
    edge_position: float
    edge_trace: NDArray[np.float64]
    yt_map: NDArray[np.float64]
    xt_map: NDArray[np.float64]
    s: NDArray[np.float64]
    even_map: NDArray[np.float64]
    odd_map: NDArray[np.float64]
    snapshot_times: NDArray[np.float64]
    snapshots: NDArray[np.float64]
    wavenumber: NDArray[np.float64]
    dispersion_frequency: NDArray[np.float64]
    dispersion: NDArray[np.float64]
    branch_frequency: NDArray[np.float64]
    branch_wavenumber: NDArray[np.float64]
    branch_phase_velocity: NDArray[np.float64]
    main_peak: float
    main_frequency: float
    main_end: float
    tail_window: tuple[float, float]
    frequency: float
    fractional_bandwidth: float
    strength_db: float
    noise_db: float | None
    phase_velocity: float
    present: bool
    criteria: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def summary(self) -> dict[str, object]:
        """The ``modes`` entry of ``summary.json`` (SI units, JSON-ready)."""

        def num(v: float | None) -> float | None:
            return None if v is None or not math.isfinite(v) else float(v)

        return {
            "present": bool(self.present),
            "frequency_hz": num(self.frequency),
            "strength_db": num(self.strength_db),
            "noise_db": num(self.noise_db),
            "fractional_bandwidth": num(self.fractional_bandwidth),
            "phase_velocity_m_s": num(self.phase_velocity),
            "main_frequency_hz": num(self.main_frequency),
            "main_end_s": num(self.main_end),
            "tail_window_s": [num(self.tail_window[0]), num(self.tail_window[1])],
            "edge_position_m": num(self.edge_position),
            "aperture": {"center_x_m": self.aperture.center_x,
                         "center_y_m": self.aperture.center_y,
                         "width_m": self.aperture.width, "height_m": self.aperture.height},
            "criteria": dict(self.criteria),
            "warnings": list(self.warnings),
        }


# --------------------------------------------------------------------------- helpers


def _axes(grid: PlaneGrid | tuple[ArrayLike, ArrayLike], shape: tuple[int, ...]
          ) -> tuple[NDArray, NDArray]:
    if isinstance(grid, PlaneGrid):
        x, y = np.asarray(grid.x, float), np.asarray(grid.y, float)
    else:
        try:
            x_raw, y_raw = grid
        except (TypeError, ValueError):
            raise InputError("expected a PlaneGrid or (x, y) coordinate vectors in m",
                             field="grid") from None
        x, y = np.asarray(x_raw, float).reshape(-1), np.asarray(y_raw, float).reshape(-1)
    uniform_axis_step(x, "x")
    uniform_axis_step(y, "y")
    if (x.size, y.size) != tuple(shape[:2]):
        raise InputError(f"velocity has shape {shape} but the grid is {x.size} × {y.size}",
                         field="velocity")
    if y.size < 4:
        raise InputError(f"expected at least 4 points along y, got {y.size}", field="y")
    return x, y


def _estimate_aperture(velocity: NDArray, x: NDArray, y: NDArray, level: float) -> Aperture:
    """Bounding box of the points whose RMS velocity is above ``level`` × its maximum."""
    rms = np.sqrt(np.mean(velocity**2, axis=-1))
    peak = float(rms.max())
    if not peak > 0:
        raise InputError("the velocity is zero everywhere", field="velocity")
    mask = rms >= level * peak
    ix = np.flatnonzero(mask.any(axis=1))
    iy = np.flatnonzero(mask.any(axis=0))
    dx = x[1] - x[0] if x.size > 1 else 0.0
    dy = y[1] - y[0]
    return Aperture(0.5 * (x[ix[0]] + x[ix[-1]]), 0.5 * (y[iy[0]] + y[iy[-1]]),
                    x[ix[-1]] - x[ix[0]] + dx, y[iy[-1]] - y[iy[0]] + dy)


def _interp_rows(axis: NDArray, rows: NDArray, at: NDArray) -> NDArray:
    """Linear interpolation of ``rows`` (n, m) along the first axis at positions ``at``."""
    pos = np.interp(at, axis, np.arange(axis.size))
    i0 = np.clip(np.floor(pos).astype(int), 0, axis.size - 2)
    w = (pos - i0)[:, None]
    return (1 - w) * rows[i0] + w * rows[i0 + 1]


def _parabolic_peak(values_db: NDArray, k: int) -> float:
    """Sub-bin offset of a maximum from a parabola through three dB values."""
    if 0 < k < values_db.size - 1 and np.all(np.isfinite(values_db[k - 1:k + 2])):
        a, b, c = values_db[k - 1:k + 2]
        den = a - 2 * b + c
        return float(0.5 * (a - c) / den) if den != 0 else 0.0
    return 0.0


def _tukey(n: int, ramp: int) -> NDArray:
    w = np.ones(n)
    ramp = min(ramp, n // 2)
    if ramp > 0:
        r = 0.5 * (1 - np.cos(np.pi * (np.arange(ramp) + 0.5) / ramp))
        w[:ramp] = r
        w[n - ramp:] = r[::-1]
    return w


def _tail_spectrum(odd: NDArray, fs: float, pad_factor: int
                   ) -> tuple[float, float]:
    """Peak frequency (sub-bin) and fractional −6 dB bandwidth of Σ_s |ODD(s, f)|²."""
    n = next_fast_length(odd.shape[-1] * pad_factor)
    power = np.sum(np.abs(to_frequency(odd, n=n)) ** 2, axis=0)
    f = frequency_axis(n, fs)
    power[0] = 0.0
    if not np.any(power > 0):
        return math.nan, math.nan
    with np.errstate(divide="ignore"):
        db = 10 * np.log10(power / power.max())
    k = int(np.argmax(power))
    peak = f[k] + _parabolic_peak(db, k) * (f[1] - f[0])
    above = db >= -6.0
    lo = k
    while lo > 0 and above[lo - 1]:
        lo -= 1
    hi = k
    while hi < f.size - 1 and above[hi + 1]:
        hi += 1
    bandwidth = f[hi] - f[lo] + (f[1] - f[0])
    return float(peak), float(bandwidth / peak) if peak > 0 else math.nan


def _dispersion(ymap: NDArray, dy: float, fs: float, *, pad_factor: int, taper: float,
                f_max: float) -> tuple[NDArray, NDArray, NDArray, NDArray, int]:
    """|2-D transform| of a y–t map; returns (k shifted, f, magnitude (nk, nf), raw, npad)."""
    ny, nt = ymap.shape
    wy = _tukey(ny, round(0.5 * taper * ny))
    spec_t = to_frequency(ymap * wy[:, None])  # conj convention: e^{−iωt} waves at ω > 0
    f = frequency_axis(nt, fs)
    keep = f <= f_max
    npad = int(next_fast_length(ny * pad_factor))
    spec = np.fft.fft(spec_t[:, keep], n=npad, axis=0)  # space: Σ p(y) e^{−iky}
    k = 2 * np.pi * np.fft.fftfreq(npad, d=dy)
    mag = np.abs(spec)
    return np.fft.fftshift(k), f[keep], np.fft.fftshift(mag, axes=0), mag, npad


def _trace_branch(mag: NDArray, npad: int, dy: float, f: NDArray, level_db: float
                  ) -> tuple[NDArray, NDArray]:
    """Per frequency whose maximum is within ``level_db`` of the global maximum: the |k| of
    the largest folded power |D(k)|² + |D(−k)|² (sub-bin, parabola in dB)."""
    power = mag**2
    j = np.arange(npad // 2 + 1)
    neg = (-j) % npad
    folded = power[j].copy()
    twin = neg != j
    folded[twin] += power[neg[twin]]
    col = folded.max(axis=0)
    if not np.any(col > 0):
        return np.empty(0), np.empty(0)
    sel = np.flatnonzero((col >= col.max() * 10 ** (level_db / 10)) & (f > 0))
    dk = 2 * np.pi / (npad * dy)
    ks = []
    for jf in sel:
        c = folded[:, jf]
        i = int(np.argmax(c))
        with np.errstate(divide="ignore"):
            db = 10 * np.log10(c / c.max())
        ks.append((i + _parabolic_peak(db, i)) * dk)
    return f[sel], np.abs(np.asarray(ks))


# --------------------------------------------------------------------------- main


def analyse_modes(
    velocity: ArrayLike,
    grid: PlaneGrid | tuple[ArrayLike, ArrayLike],
    sampling_rate: float,
    *,
    aperture: object | None = None,
    start_time: float = 0.0,
    aperture_level: float = 0.5,
    edge_distance: float | None = None,
    main_level_db: float = -20.0,
    guard: float = 0.0,
    threshold_db: float = -30.0,
    snr_margin_db: float = 6.0,
    max_fractional_bandwidth: float = 0.5,
    min_noise_samples: int = 8,
    pad_factor: int = 8,
    taper: float = 0.25e-6,
    snapshot_times: ArrayLike | None = None,
    n_snapshots: int = 4,
    dispersion_gate: bool = True,
    dispersion_pad_factor: int = 4,
    dispersion_taper: float = 0.5,
    dispersion_max_frequency: float | None = None,
    branch_level_db: float = -20.0,
) -> ModesResult:
    """Look for a spurious antisymmetric mode in the surface velocity (paper section III D).

    1. Maps: the velocity averaged across x inside the aperture (the y–t map, paper Fig.
       9b) and across y inside the aperture (x–t map); the trace of the y–t map at
       ``edge_distance`` inside the upper y edge (Fig. 9a).
    2. Even and odd parts about the aperture centre: ``e, o = (m(y_c+s) ± m(y_c−s))/2``
       (linear interpolation in y), for ``0 ≤ s ≤ H/2``. The main (thickness-mode) pulse is
       even; an antisymmetric mode is odd.
    3. Main pulse: the Hilbert envelope of ``e`` (maximum over s) peaks at ``main_peak``;
       it ends where that envelope first falls below ``main_level_db`` after its peak. The
       **tail window** runs from that end (+ ``guard``) to the end of the record.
    4. Tail: ``strength_db = 20 log10(max envelope of o in the tail / main_peak)``; its
       frequency is the peak of ``Σ_s |O(s, f)|²`` of the gated odd part (raised-cosine
       ramps of ``taper``, zero-padded ``pad_factor`` times, parabola in dB: sub-bin);
       ``noise_db`` is the same envelope ratio before the main pulse onset (where the even
       envelope first reaches ``main_level_db``), when at least ``min_noise_samples``
       samples are there.
    5. Decision: the mode is **present** when ``strength_db ≥ threshold_db`` (default −30
       dB, i.e. an odd tail above 3 % of the main pulse amplitude), the tail is narrowband
       (−6 dB fractional bandwidth ≤ ``max_fractional_bandwidth``), and, when a noise
       level is known, ``strength_db − noise_db ≥ snr_margin_db``.
    6. Dispersion: the 2-D transform of the y–t map (time-gated to the tail when
       ``dispersion_gate``; Tukey-tapered along y), ``D(k, f) = Σ_y Σ_t m(y, t)
       e^{−iky} e^{+iωt}`` (holoprobe's convention in time, so a wave e^{i(ky−ωt)}
       appears at +k). For every frequency whose maximum is within ``branch_level_db`` of
       the global maximum, the dominant branch is the |k| of the largest ``|D(k)|² +
       |D(−k)|²``; its phase velocity is ω/|k|.

    Parameters
    ----------
    velocity : array_like, shape (nx, ny, nt)
        Normal surface velocity on the source plane (m/s), time last.
    grid : PlaneGrid or (x, y)
        Source-grid coordinates in m (uniform).
    sampling_rate : float
        Hz.
    aperture : Aperture, ApertureFit, dict or (center_x, center_y, width, height), optional
        The active aperture in m. Default: the bounding box of the points whose RMS
        velocity is at least ``aperture_level`` times the largest.
    start_time : float
        Time of sample 0 in s.
    aperture_level : float
        Relative RMS level of the aperture estimate (0.5: −6 dB).
    edge_distance : float, optional
        Distance (m) of the edge trace inside the y edge; default H/10.
    main_level_db, guard : float
        End of the main pulse (dB re its peak envelope) and extra time (s) before the tail.
    threshold_db, snr_margin_db, max_fractional_bandwidth : float
        The decision (step 5).
    min_noise_samples : int
        Fewest samples before the main pulse for a noise level.
    pad_factor : int
        Zero padding of the tail spectrum.
    taper : float
        Ramp length (s) of the tail gate.
    snapshot_times : array_like, optional
        Times (s) of the cross-sections; default ``n_snapshots`` times spread over the part
        of the tail where the odd envelope exceeds half its maximum (over the main pulse
        when there is no tail).
    n_snapshots : int
        Number of default snapshots.
    dispersion_gate : bool
        Gate the y–t map to the tail before the k–ω transform (the main pulse, at k ≈ 0,
        would otherwise dominate).
    dispersion_pad_factor : int
        Zero padding along y of the k–ω transform.
    dispersion_taper : float
        Tukey fraction (0–1) of the taper along y.
    dispersion_max_frequency : float, optional
        Highest frequency kept in the map (Hz; default 3 × the tail or main frequency,
        capped at Nyquist).
    branch_level_db : float
        Level of the branch tracing (dB re the maximum of the map).

    Returns
    -------
    ModesResult

    Raises
    ------
    InputError
        Bad shapes, non-finite values, a non-uniform grid or an aperture outside the grid.
    """
    v, fs = _check_velocity(velocity, sampling_rate, main_level_db=main_level_db,
                            threshold_db=threshold_db, branch_level_db=branch_level_db)
    x, y = _axes(grid, v.shape)
    nt = v.shape[-1]
    t = start_time + np.arange(nt) / fs
    warnings: list[str] = []
    ap = (_estimate_aperture(v, x, y, aperture_level) if aperture is None
          else as_aperture(aperture))
    dy = y[1] - y[0]
    yt, xt = _aperture_maps(v, x, y, ap)
    s, even, odd = _even_odd(y, yt, ap, warnings)
    h_edge = 0.1 * ap.height if edge_distance is None else float(edge_distance)
    edge_y = ap.center_y + 0.5 * ap.height - h_edge
    edge_trace = _interp_rows(y, yt, np.array([np.clip(edge_y, y[0], y[-1])]))[0]
    tail = _main_and_tail(even, odd, t, fs, main_level_db=main_level_db, guard=guard,
                          taper=taper, pad_factor=pad_factor,
                          min_noise_samples=min_noise_samples, warnings=warnings)
    main_peak, gate, env_o, env_e = tail.main_peak, tail.gate, tail.env_odd, tail.env_even
    frequency, fbw, strength_db, noise_db = (tail.frequency, tail.fbw, tail.strength_db,
                                             tail.noise_db)
    main_frequency, main_end_i, tail_i = tail.main_frequency, tail.main_end, tail.tail_start
    present = bool(math.isfinite(strength_db) and strength_db >= threshold_db
                   and math.isfinite(fbw) and fbw <= max_fractional_bandwidth
                   and (noise_db is None or strength_db - noise_db >= snr_margin_db))

    # dispersion of the (gated) y–t map
    f_ref = frequency if math.isfinite(frequency) else main_frequency
    f_max = (min(3.0 * f_ref, 0.5 * fs) if dispersion_max_frequency is None
             else float(dispersion_max_frequency))
    ymap = yt * gate[None, :] if (dispersion_gate and math.isfinite(frequency)) else yt
    k_axis, f_disp, disp, raw, npad = _dispersion(
        ymap, dy, fs, pad_factor=max(1, int(dispersion_pad_factor)),
        taper=float(dispersion_taper), f_max=f_max)
    bf, bk = _trace_branch(raw, npad, dy, f_disp, branch_level_db)
    bv, phase_velocity = _branch_phase_velocity(bf, bk, f_disp, frequency)
    idx = _snapshot_indices(snapshot_times, env_o if math.isfinite(frequency) else env_e,
                            tail_i if math.isfinite(frequency) else 0, n_snapshots, t, fs)
    criteria = {"threshold_db": float(threshold_db), "snr_margin_db": float(snr_margin_db),
                "max_fractional_bandwidth": float(max_fractional_bandwidth),
                "main_level_db": float(main_level_db)}
    return ModesResult(
        time=t, x=x, y=y, aperture=ap, edge_position=float(edge_y), edge_trace=edge_trace,
        yt_map=yt, xt_map=xt, s=s, even_map=even, odd_map=odd,
        snapshot_times=t[idx], snapshots=yt[:, idx].T.copy(), wavenumber=k_axis,
        dispersion_frequency=f_disp, dispersion=disp, branch_frequency=bf,
        branch_wavenumber=bk, branch_phase_velocity=bv, main_peak=main_peak,
        main_frequency=float(main_frequency),
        main_end=float(t[main_end_i]) if main_end_i < nt else math.inf,
        tail_window=tail.window, frequency=float(frequency), fractional_bandwidth=float(fbw),
        strength_db=strength_db, noise_db=noise_db, phase_velocity=float(phase_velocity),
        present=present, criteria=criteria, warnings=warnings)


def _aperture_maps(v: NDArray, x: NDArray, y: NDArray, ap: Aperture
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The y–t map (mean across x inside the aperture) and the x–t map (mean across y)."""
    inx = np.abs(x - ap.center_x) <= 0.5 * ap.width + 1e-9 * ap.width
    iny = np.abs(y - ap.center_y) <= 0.5 * ap.height + 1e-9 * ap.height
    if not inx.any() or not iny.any():
        raise InputError("the aperture does not overlap the grid", field="aperture")
    return v[inx].mean(axis=0), v[:, iny].mean(axis=1)


def _even_odd(y: NDArray, yt: NDArray, ap: Aperture, warnings: list[str]
              ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Step 2: s (m) and the even and odd parts of the y–t map about the aperture centre,
    shape (ns, nt) each."""
    dy = y[1] - y[0]
    s_max = min(y[-1] - ap.center_y, ap.center_y - y[0], 0.5 * ap.height)
    if s_max < 2 * dy:
        raise InputError("the aperture centre is too close to the grid edge in y",
                         field="aperture")
    s = np.arange(0.0, s_max + 1e-9 * dy, dy)
    up = _interp_rows(y, yt, ap.center_y + s)
    down = _interp_rows(y, yt, ap.center_y - s)
    if s_max < 0.5 * ap.height - dy:
        warnings.append("the grid does not cover the whole aperture height symmetrically: "
                        f"odd part analysed up to s = {s_max * _MM:.2f} mm")
    return s, 0.5 * (up + down), 0.5 * (up - down)


@dataclass(frozen=True)
class _Tail:
    """Main pulse and tail of the even/odd parts (steps 3 and 4 of :func:`analyse_modes`)."""

    env_even: NDArray[np.float64]  # max over s of the envelopes, shape (nt,)
    env_odd: NDArray[np.float64]
    main_peak: float
    main_frequency: float
    main_end: int  # sample index (nt: never ends)
    tail_start: int
    gate: NDArray[np.float64]  # tail gate (ones without a tail), shape (nt,)
    window: tuple[float, float]  # s (NaN without a tail)
    frequency: float
    fbw: float
    strength_db: float
    noise_db: float | None


def _main_and_tail(even: NDArray, odd: NDArray, t: NDArray, fs: float, *,
                   main_level_db: float, guard: float, taper: float, pad_factor: int,
                   min_noise_samples: int, warnings: list[str]) -> _Tail:
    """Steps 3–4: the main pulse from the even envelope, the tail window after it, the
    odd tail's strength, frequency and bandwidth, and the noise level before the onset."""
    nt = t.size
    env_e = envelope(even).max(axis=0)
    env_o = envelope(odd).max(axis=0)
    main_peak = float(env_e.max())
    if not main_peak > 0:
        raise InputError("the velocity has no even (thickness-mode) part", field="velocity")
    ipk = int(np.argmax(env_e))
    level = main_peak * 10 ** (main_level_db / 20)
    onset = int(np.flatnonzero(env_e >= level)[0])
    below = np.flatnonzero(env_e[ipk:] < level)
    main_end_i = ipk + int(below[0]) if below.size else nt
    tail_i = min(nt, main_end_i + math.ceil(max(guard, 0.0) * fs))
    main_frequency = spectrum_summary(even[0], fs).peak_frequency
    ramp = max(1, round(taper * fs))
    frequency = fbw = math.nan
    strength_db = -math.inf
    if nt - tail_i >= 2 * ramp + 4:
        gate = np.zeros(nt)
        gate[tail_i:] = _tukey(nt - tail_i, ramp)
        strength_db = float(20 * np.log10(max(env_o[tail_i:].max(), 1e-300) / main_peak))
        frequency, fbw = _tail_spectrum(odd * gate, fs, pad_factor)
        tail_window = (float(t[tail_i]), float(t[-1]))
    else:
        gate = np.ones(nt)
        tail_window = (math.nan, math.nan)
        warnings.append("the main pulse lasts until the end of the record: no tail to "
                        "analyse")
    noise_end = onset - math.ceil(max(guard, 0.0) * fs)
    noise_db = (float(20 * np.log10(max(env_o[:noise_end].max(), 1e-300) / main_peak))
                if noise_end >= min_noise_samples else None)
    return _Tail(env_e, env_o, main_peak, main_frequency, main_end_i, tail_i, gate,
                 tail_window, frequency, fbw, strength_db, noise_db)


def _check_velocity(velocity: ArrayLike, sampling_rate: float, **levels_db: float
                    ) -> tuple[NDArray[np.float64], float]:
    """The velocity (nx, ny, nt ≥ 16, finite) and the rate; InputError otherwise, and for
    a level in dB that is not negative."""
    v = np.asarray(velocity, dtype=float)
    if v.ndim != 3:
        raise InputError(f"expected shape (nx, ny, nt), got {v.shape}", field="velocity")
    if v.shape[-1] < 16:
        raise InputError(f"expected at least 16 time samples, got {v.shape[-1]}",
                         field="velocity")
    if not np.all(np.isfinite(v)):
        raise InputError("contains NaN or inf", field="velocity")
    fs = float(sampling_rate)
    if not (math.isfinite(fs) and fs > 0):
        raise InputError(f"expected a positive rate in Hz, got {sampling_rate!r}",
                         field="sampling_rate")
    for name, value in levels_db.items():
        if not (math.isfinite(value) and value < 0):
            raise InputError(f"expected a negative number of dB, got {value!r}", field=name)
    return v, fs


def _branch_phase_velocity(bf: NDArray, bk: NDArray, f_disp: NDArray, frequency: float
                           ) -> tuple[NDArray, float]:
    """Phase velocity 2πf/k along the traced branch, and at the mode's frequency (NaN when
    the branch does not reach it within two frequency bins)."""
    with np.errstate(divide="ignore"):
        bv = np.where(bk > 0, 2 * np.pi * bf / np.where(bk > 0, bk, 1.0), np.inf)
    phase_velocity = math.nan
    if math.isfinite(frequency) and bf.size >= 1 and bf[0] <= frequency <= bf[-1]:
        j = int(np.argmin(np.abs(bf - frequency)))
        if abs(bf[j] - frequency) <= 2 * (f_disp[1] - f_disp[0]):
            k_at = float(np.interp(frequency, bf, bk))
            phase_velocity = 2 * np.pi * frequency / k_at if k_at > 0 else math.inf
    return bv, phase_velocity


def _snapshot_indices(snapshot_times: ArrayLike | None, env: NDArray, start: int,
                      n_snapshots: int, t: NDArray, fs: float) -> NDArray[np.intp]:
    """Sample indices of the snapshots: the given times, or ``n_snapshots`` spread over
    where ``env`` (from sample ``start`` on) exceeds half its maximum."""
    if snapshot_times is None:
        seg = env.copy()
        seg[:start] = 0.0
        strong = np.flatnonzero(seg >= 0.5 * seg.max())
        return np.unique(np.linspace(strong[0], strong[-1], max(1, int(n_snapshots)))
                         .round().astype(int))
    times = np.asarray(snapshot_times, dtype=float).reshape(-1)
    if np.any((times < t[0]) | (times > t[-1])):
        raise InputError(f"expected times within the record [{t[0]:.4g}, {t[-1]:.4g}] s",
                         field="snapshot_times")
    return np.round((times - t[0]) * fs).astype(int)


# --------------------------------------------------------------------------- figures


def modes_figures(result: ModesResult, *, sound_speed: float = 1481.0
                  ) -> list[tuple[Figure, str]]:
    """The four panels of paper Fig. 9 for a :class:`ModesResult`, with captions.

    Parameters
    ----------
    result : ModesResult
    sound_speed : float
        c0 (m/s) for the sound line ω = c0 k in the dispersion map.

    Returns
    -------
    list of (Figure, caption)
    """
    return [_edge_trace_figure(result), _space_time_figure(result),
            _cross_section_figure(result), _dispersion_figure(result, sound_speed)]


def _edge_trace_figure(r: ModesResult) -> tuple[Figure, str]:
    """Paper Fig. 9a: the velocity near the aperture edge, with the verdict."""
    t_us = r.time * _US
    verdict = (f"A narrowband tail at {r.frequency * _MHZ:.3f} MHz, {r.strength_db:.1f} dB "
               "re the main pulse, was found: the mode is present."
               if r.present else "No antisymmetric tail passed the detection criteria: the "
               "mode is reported absent.")
    fig = Figure(figsize=(7.0, 3.0), layout="constrained")
    ax = fig.subplots()
    ax.plot(t_us, r.edge_trace * _MM, color="tab:blue", linewidth=1.0)
    if math.isfinite(r.tail_window[0]):
        ax.axvspan(r.tail_window[0] * _US, r.tail_window[1] * _US, color="tab:orange",
                   alpha=0.15, label="tail window")
        ax.legend(loc="upper right", fontsize="small")
    ax.set_xlabel("time (µs)")
    ax.set_ylabel("normal velocity (mm/s)")
    return fig, ("Surface velocity near the aperture edge (y = "
                 f"{r.edge_position * _MM:.2f} mm, averaged across x; paper Fig. 9a). Look "
                 "for a ringing tail after the broadband main pulse (shaded: the analysed "
                 f"tail window). {verdict}")


def _space_time_figure(r: ModesResult) -> tuple[Figure, str]:
    """Paper Fig. 9b: the y–t and x–t maps."""
    ap = r.aperture
    t_us = r.time * _US
    fig = Figure(figsize=(9.0, 3.4), layout="constrained")
    ax1, ax2 = fig.subplots(1, 2)
    for axis, data, coord, label, half, centre in (
            (ax1, r.yt_map, r.y, "elevation y (mm)", 0.5 * ap.height, ap.center_y),
            (ax2, r.xt_map, r.x, "lateral x (mm)", 0.5 * ap.width, ap.center_x)):
        lim = float(np.abs(data).max()) or 1.0
        im = axis.imshow(data * _MM, aspect="auto", origin="lower", cmap="RdBu_r",
                         vmin=-lim * _MM, vmax=lim * _MM,
                         extent=[t_us[0], t_us[-1], coord[0] * _MM, coord[-1] * _MM])
        for edge in (centre - half, centre + half):
            axis.axhline(edge * _MM, color="k", linestyle=":", linewidth=0.8)
        axis.set_xlabel("time (µs)")
        axis.set_ylabel(label)
        fig.colorbar(im, ax=axis, label="velocity (mm/s)")
    ax1.set_title("averaged across x", fontsize="small")
    ax2.set_title("averaged across y", fontsize="small")
    return fig, ("Space–time maps of the surface velocity (paper Fig. 9b): along the "
                 "elevation y averaged across x inside the aperture (left), along x averaged "
                 "across y (right); dotted lines: aperture edges. Look for slanted stripes "
                 "after the main pulse (waves running along y) with opposite signs on the "
                 "two halves (an antisymmetric mode); the right map should show them only "
                 "weakly.")


def _cross_section_figure(r: ModesResult) -> tuple[Figure, str]:
    """Paper Fig. 9c: cross-sections of the y–t map at the snapshot times."""
    ap = r.aperture
    fig = Figure(figsize=(7.0, 3.2), layout="constrained")
    ax = fig.subplots()
    for ts, snap in zip(r.snapshot_times, r.snapshots, strict=True):
        ax.plot(r.y * _MM, snap * _MM, linewidth=1.0, label=f"t = {ts * _US:.2f} µs")
    ax.axvline(ap.center_y * _MM, color="k", linewidth=0.6)
    for edge in (ap.center_y - 0.5 * ap.height, ap.center_y + 0.5 * ap.height):
        ax.axvline(edge * _MM, color="k", linestyle=":", linewidth=0.8)
    ax.set_xlabel("elevation y (mm)")
    ax.set_ylabel("normal velocity (mm/s)")
    ax.legend(loc="best", fontsize="small")
    return fig, ("Cross-sections of the elevation–time map at selected times (paper "
                 "Fig. 9c); solid line: aperture centre, dotted: edges. An antisymmetric "
                 "mode gives profiles that change sign across the centre, v(−y) = −v(y).")


def _dispersion_figure(r: ModesResult, sound_speed: float) -> tuple[Figure, str]:
    """Paper Fig. 9d: the k–ω map with the traced branch and the sound line."""
    fig = Figure(figsize=(6.0, 4.0), layout="constrained")
    ax = fig.subplots()
    mag = r.dispersion
    with np.errstate(divide="ignore"):
        db = 20 * np.log10(mag / mag.max()) if mag.max() > 0 else np.zeros_like(mag)
    im = ax.imshow(np.maximum(db.T, -40.0), aspect="auto", origin="lower", cmap="magma",
                   extent=(r.wavenumber[0] * 1e-3, r.wavenumber[-1] * 1e-3,
                           r.dispersion_frequency[0] * _MHZ,
                           r.dispersion_frequency[-1] * _MHZ))
    fig.colorbar(im, ax=ax, label="magnitude (dB re max)")
    kk = np.linspace(0, r.wavenumber[-1], 50)
    ax.plot(kk * 1e-3, kk * sound_speed / (2 * np.pi) * _MHZ, "w--", linewidth=0.8,
            label="sound line ω = c0 k")
    ax.plot(-kk * 1e-3, kk * sound_speed / (2 * np.pi) * _MHZ, "w--", linewidth=0.8)
    if r.branch_frequency.size:
        ax.plot(r.branch_wavenumber * 1e-3, r.branch_frequency * _MHZ, "c.", markersize=3,
                label="traced branch |k|")
    ax.set_ylim(r.dispersion_frequency[0] * _MHZ, r.dispersion_frequency[-1] * _MHZ)
    ax.set_xlabel("wavenumber k_y (rad/mm)")
    ax.set_ylabel("frequency (MHz)")
    ax.legend(loc="upper left", fontsize="small")
    pv = (f"Phase velocity at {r.frequency * _MHZ:.2f} MHz: {r.phase_velocity:.0f} m/s."
          if math.isfinite(r.phase_velocity) else "No branch traced at the tail frequency.")
    return fig, ("Dispersion map (k–ω) of the elevation–time map"
                 + (" gated to the tail" if math.isfinite(r.tail_window[0]) else "")
                 + " (paper Fig. 9d); dots: the dominant branch, dashed: the sound line "
                 "(waves to its outside are evanescent in water and cannot be seen by the "
                 "hydrophone). Look for a curved branch: a phase velocity ω/k that falls "
                 f"with k indicates a dispersive (Lamb-like) wave. {pv}")
