"""The band of a transient hologram back-projected onto the source surface, on fewer bins.

A transient record of n samples at fs has bins every fs/n; back-projecting each onto the
source surface (velocity and pressure: four type-3 NUFFTs per bin) is what a transient
characterization costs. The source's velocity, however, is a pulse: it lasts far less
than the record (the record must hold the scan's late edge waves, not the source). The
bins of a record D times shorter (every D-th bin of the record zero-padded to a multiple
of D samples) are the spectrum of the surface waveforms folded with period n/(D fs); a
pulse shorter than that period folds onto itself unchanged, so those bins hold the whole
waveform and its energy (Parseval on the shorter record), exactly, at 1/D of the cost.

Which D is chosen from the data: the largest of 8, 4, 2, 1 that keeps at least 16 bins
across the band and for which the folded velocity (inside the aperture) keeps its signal
energy, less the noise floor, within half of the shorter record
(:func:`folded_energy_outside`). The power leaving the surface also folds
the surface pressure: its correlation with the velocity at lags of the shorter period
enters; measured on the 200 × 200 × 778 twin of an 87 mm bowl it moves the surface power
by 0.001 % with D = 4 (benchmarks/RESULTS.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from holoprobe.characterize._hologram_config import HologramConfig
from holoprobe.characterize._source_surface import UnrolledSurface, backproject_source
from holoprobe.errors import InputError
from holoprobe.geometry import PlaneGrid
from holoprobe.measurement import Hologram
from holoprobe.signal import to_time

__all__ = ["BandProjection", "VelocityGate", "band_spectra", "folded_energy_outside",
           "gated_velocity", "project_band", "pulse_window"]

_LADDER = (8, 4, 2, 1)
# a shortened record must keep at least this many bins across the band: the band's edges
# cut the folded spectrum on coarser cells (16-18 bins: surface power within 1e-5 of every
# bin's on the 87 mm bowl twin; 9-10 bins: 2e-4)
_MIN_BINS = 16
_QUIET = 0.1  # the noise floor of a pulse's folded record lies below this share of its peak


@dataclass(frozen=True)
class BandProjection:
    """Surface velocity and pressure on the bins of a (possibly shortened) record.

    Attributes
    ----------
    frequencies : ndarray, shape (nb,)
        Hz: bins of a record of ``record`` samples at the hologram's sampling rate.
    velocity, pressure : ndarray, complex, shape (n_surface, nb)
        Normal velocity (m/s·s) and pressure (Pa·s) on the surface per bin.
    record : int
        Samples of the record whose ``rfft`` bins ``frequencies`` are.
    decimation : int
        D: the record is the hologram's, zero-padded to ``D × record`` samples, D times
        shortened.
    """

    frequencies: NDArray[np.float64]
    velocity: NDArray[np.complex128]
    pressure: NDArray[np.complex128]
    record: int
    decimation: int


def band_spectra(hologram: Hologram, frequencies: NDArray) -> NDArray[np.complex128]:
    """Spectra (Pa·s, holoprobe's convention, the phase of t = 0 restored) of a transient
    hologram's waveforms at any frequencies: the Fourier integral of the record (zero
    outside it), shape (nx, ny, nf)."""
    rate = hologram.sampling_rate
    if rate is None:
        raise InputError("a CW hologram has no waveforms", field="sampling_rate")
    fs = float(rate)
    wave = np.asarray(hologram.pressure, float)
    t = hologram.start_time + np.arange(wave.shape[-1]) / fs
    phase = 2 * np.pi * np.outer(t, np.asarray(frequencies, float))
    flat = wave.reshape(-1, wave.shape[-1])
    spec = (flat @ np.cos(phase) + 1j * (flat @ np.sin(phase))) / fs
    return spec.reshape(*wave.shape[:-1], -1)


def folded_energy_outside(velocity: NDArray, bins: NDArray, record: int) -> float:
    """Share of the signal energy of waveforms outside their best half-record window.

    Parameters
    ----------
    velocity : ndarray, complex, shape (n, nb)
        Spectra on bins ``bins`` (indices of the ``rfft`` of ``record`` samples).
    bins : ndarray of int, shape (nb,)
    record : int
        Samples of the record.

    Returns
    -------
    float
        (Energy of Σ_points v² outside the circular window of ``record // 2`` samples that
        holds the most, each sample less the noise floor, the profile's 10th percentile) /
        (total less the floor); ≤ 0 when nothing but noise lies outside; ``inf`` when the
        floor is not below a tenth of the peak (no quiet time: not a pulse).
    """
    spec = np.zeros((velocity.shape[0], record // 2 + 1), np.complex128)
    spec[:, bins] = velocity
    return pulse_window(np.sum(to_time(spec, record) ** 2, axis=0))[1]


def pulse_window(energy: NDArray) -> tuple[int, float]:
    """The circular window of half a periodic record that holds a pulse's energy.

    Parameters
    ----------
    energy : ndarray, shape (n,)
        Energy profile of the record (e.g. Σ over waveforms of their squares), circular.

    Returns
    -------
    start : int
        First sample of the window of ``n // 2`` samples holding the most signal (each
        sample less the noise floor, the profile's 10th percentile).
    outside : float
        Share of the signal energy outside it (≤ 0 when nothing but noise is); ``inf``
        when the floor is not below a tenth of the peak (no quiet time: not a pulse).
    """
    record = energy.size
    # summed over many points the noise's energy is nearly flat in time: its level is a low
    # percentile of the profile wherever a tenth of the record is signal-free; a profile
    # that never falls well below its peak (a long wave filling the record) is no pulse
    floor = float(np.percentile(energy, 10))
    signal = energy - floor
    half = record // 2
    running = np.cumsum(np.concatenate([signal, signal[:half]]))
    windows = running[half:half + record] - np.concatenate([[0.0], running[:record - 1]])
    start = int(np.argmax(windows))
    total = float(signal.sum())
    if not floor < _QUIET * energy.max() or not total > 0:
        return start, float("inf")
    return start, float((total - windows[start]) / total)


def _coarse(band: NDArray, record: int, fs: float) -> NDArray[np.intp]:
    """Indices of the bins of a ``record``-sample record whose cells (± half a bin)
    overlap the band's span."""
    step = fs / record
    lo = int(np.ceil(band.min() / step - 0.5 + 1e-9))
    hi = int(np.floor(band.max() / step + 0.5 - 1e-9))
    return np.arange(max(lo, 1), min(hi, record // 2) + 1)


def project_band(hologram: Hologram, unrolled: UnrolledSurface, grid: PlaneGrid,
                 band: NDArray, band_spec: NDArray, inside: NDArray, *,
                 guard_angle: float, cfg: HologramConfig,
                 progress: bool | None = False) -> BandProjection:
    """Back-project a transient hologram's band onto the source on as few bins as exact.

    Parameters
    ----------
    hologram : Hologram
        Transient.
    unrolled : UnrolledSurface
        The aligned source surface.
    grid : PlaneGrid
        The scan grid (scan coordinates, increasing axes), as ``band_spec``'s.
    band : ndarray, shape (nf,)
        Hz: the record's bins kept (:func:`characterize_hologram`'s band).
    band_spec : ndarray, complex, shape (nx, ny, nf)
        Their spectra (Pa·s) on ``grid``: used as they are when every bin is projected.
    inside : ndarray of bool, shape (n_surface,)
        Surface nodes inside the aperture (the compactness check's).
    guard_angle : float
        Padding rule angle (rad).
    cfg : HologramConfig
        ``band_decimation``, ``band_alias_tolerance``, ``band_eps``.
    progress : bool or None

    Returns
    -------
    BandProjection
    """
    fixed = int(cfg.band_decimation)
    if fixed < 0:
        raise InputError(f"expected 0 (from the data) or a decimation ≥ 1, got {fixed}",
                         field="hologram.band_decimation")
    assert hologram.sampling_rate is not None  # transient (the caller checks)
    fs, n = float(hologram.sampling_rate), hologram.n_samples
    ladder = (fixed,) if fixed else _LADDER
    padded = ladder[0] * -(-n // ladder[0])
    medium = hologram.medium
    done: dict[int, tuple[NDArray, NDArray]] = {}  # bin of the padded record → (v, p)
    for d in ladder:
        record = padded // d
        wanted = (np.rint(band * n / fs).astype(int) if padded == n and d == 1
                  else _coarse(band, record, fs) * d)  # as bins of the padded record
        if d > 1 and wanted.size < _MIN_BINS:
            continue
        new = np.array([b for b in wanted if b not in done], int)
        if new.size:
            freqs = new * fs / padded
            same = padded == n and np.array_equal(np.rint(band * n / fs), new)
            spec = band_spec if same else band_spectra(hologram, freqs)
            vel, prs = backproject_source(spec, grid, freqs, medium, unrolled,
                                          guard_angle=guard_angle, with_pressure=True,
                                          progress=progress, eps=cfg.band_eps)
            done.update({int(b): (vel[:, j], prs[:, j]) for j, b in enumerate(new)})
        vel = np.stack([done[int(b)][0] for b in wanted], axis=1)
        if fixed or d == 1 or folded_energy_outside(
                vel[inside], wanted // d, record) <= cfg.band_alias_tolerance:
            prs = np.stack([done[int(b)][1] for b in wanted], axis=1)
            return BandProjection(wanted * fs / padded, vel, prs, record, d)
    raise AssertionError("unreachable: the ladder ends with D = 1")  # pragma: no cover


@dataclass(frozen=True)
class VelocityGate:
    """The surface velocity at one frequency from the surface waveforms gated to the pulse.

    Attributes
    ----------
    velocity : ndarray, complex, shape (n_surface,)
        Normal velocity spectrum (m/s·s) at the frequency, from the gated waveforms.
    start, stop : float
        Span (s) of the gate's flat part on the surface waveforms' time axis (the
        hologram's, t = 0 restored; a pulse that folds over the shortened record's period
        is placed where the ungated spectrum puts it).
    taper : float
        Length (s) of the raised-cosine ramp on each side of that span.
    """

    velocity: NDArray[np.complex128]
    start: float
    stop: float
    taper: float


_FLAT = 2.0  # the noise outside a gate: its thirds' mean energies within this factor
_NEGLIGIBLE = 1e-4  # share of the energy outside a gate below which nothing is checked


def _floor_is_noise(energy: NDArray, lo: int, hi: int) -> bool:
    """Whether what a gate leaves out (``energy`` outside ``lo … hi`` on the peak-centred
    axis, circularly) is noise: negligible, or flat in time. Summed over the aperture the
    noise's envelope energy is stationary; a tail that still decays (a high-Q source
    ringing for most of the record, so the 10th percentile lies on its tail) is not, and
    a gate at a multiple of it would cut signal: its thirds next to the pulse and far
    from it differ by more than ``_FLAT``."""
    lo, hi = max(lo, 0), min(hi, energy.size - 1)
    outside = np.concatenate([energy[hi + 1:], energy[:lo]])  # after the pulse, then before
    if outside.sum() <= _NEGLIGIBLE * energy.sum():
        return True
    if outside.size < 12:
        return False
    means = [float(part.mean()) for part in np.array_split(outside, 3)]
    return max(means) <= _FLAT * min(means)


_ARRIVAL = 1e-3  # an arrival apart from the pulse is kept above this share of its peak energy


def _arrivals_span(energy: NDArray, threshold: float) -> tuple[int, int] | None:
    """First and last sample of the runs of ``energy > threshold`` that reach
    ``_ARRIVAL`` × the peak: the pulse and any later (or earlier) arrival after a quiet
    gap (a reverberation, a second pulse), not the ringing of a band edge far below."""
    above = np.concatenate([[False], energy > threshold, [False]])
    edges = np.flatnonzero(np.diff(above.astype(np.int8)))
    starts, stops = edges[::2], edges[1::2] - 1
    strong = [(a, b) for a, b in zip(starts, stops, strict=True)
              if energy[a:b + 1].max() >= _ARRIVAL * energy.max()]
    if not strong:
        return None
    return int(strong[0][0]), int(strong[-1][1])


def gated_velocity(projected: BandProjection, frequency: float, sampling_rate: float,
                   inside: NDArray, weights: NDArray, reference: NDArray, level: float,
                   taper_periods: float = 2.0) -> VelocityGate | None:
    """The velocity at ``frequency`` from the surface waveforms where the pulse stands out.

    A single element's surface moves for as long as its drive and ringing last, far less
    than the record (which holds the scan's late edge waves); the hologram's noise,
    back-projected, lasts the whole record. The surface waveforms (inverse transform of
    ``projected``'s bins) are kept where the aperture's summed envelope energy
    Σ w |v(t)|² exceeds ``level`` × its noise floor (the 10th percentile over the record),
    from the first to the last such sample of the runs that reach 10⁻³ of its peak (a
    later arrival after a quiet gap, e.g. a reverberation, is kept), with a raised-cosine
    ramp of
    ``taper_periods`` periods of ``frequency`` outside it; their spectrum at ``frequency``
    is the estimate. Samples below the noise are left out, where the signal is weaker
    than the noise that would come with it (``level`` 2: signal energy ≥ noise energy).

    Parameters
    ----------
    projected : BandProjection
        Surface velocity per bin (:func:`project_band`).
    frequency : float
        Hz (the CW analysis frequency).
    sampling_rate : float
        The hologram's, Hz.
    inside : ndarray of bool, shape (n_surface,)
        Nodes inside the aperture (their envelope energy defines the gate).
    weights : ndarray, shape (n_surface,)
        Area of each node, m².
    reference : ndarray, complex, shape (n_surface,)
        The ungated spectrum at ``frequency`` (the full record's bin): fixes which period
        of the shortened record the pulse lies in.
    level : float
        Gate threshold, multiple of the noise floor (> 1).
    taper_periods : float
        Ramp length in periods of ``frequency``.

    Returns
    -------
    VelocityGate or None
        None when the waveforms are no pulse (the floor is not below a tenth of the peak:
        no quiet time to gate), the gate would keep the whole record, or what it leaves
        out is not noise (:func:`_floor_is_noise`: a tail that decays over the record).
    """
    record, fs = projected.record, float(sampling_rate)
    bins = np.rint(projected.frequencies * record / fs).astype(int)
    one_sided = np.zeros((projected.velocity.shape[0], record), np.complex128)
    one_sided[:, bins] = 2.0 * np.conj(projected.velocity)  # analytic signal, exp(+iωt)
    analytic = np.fft.ifft(one_sided, axis=1)                # real part: the waveforms
    energy = weights[inside] @ (np.abs(analytic[inside]) ** 2)
    floor = float(np.percentile(energy, 10))
    if not floor < _QUIET * energy.max():
        return None
    peak = int(np.argmax(energy))
    pos = np.mod(np.arange(record) - peak + record // 2, record)  # peak at record // 2
    centred = np.empty(record)
    centred[pos] = energy                          # energy along the peak-centred axis
    span = _arrivals_span(centred, level * floor)
    if span is None:
        return None
    lo, hi = span
    ramp = max(1, round(taper_periods * fs / frequency))
    if lo - ramp <= 0 and hi + ramp >= record - 1:
        return None
    if not _floor_is_noise(centred, lo - ramp, hi + ramp):
        return None
    shifted = np.arange(record)                    # positions along the peak-centred axis
    window = np.clip(np.minimum(shifted - (lo - ramp - 1), (hi + ramp + 1) - shifted)
                     / (ramp + 1), 0.0, 1.0)
    window = 0.5 - 0.5 * np.cos(np.pi * window)
    order = np.argsort(pos)                        # sample index at each position
    t = (shifted - record // 2 + peak) / fs        # time of each position (one period)
    waves = analytic[:, order].real * window
    gated = waves @ np.exp(2j * np.pi * frequency * t)
    # the shortened record folds time with period record/fs: take the period whose
    # placement agrees with the full record's (ungated) spectrum
    period = record / fs
    shifts = np.array(sorted(range(-projected.decimation, projected.decimation + 1), key=abs))
    turns = np.exp(2j * np.pi * frequency * period * shifts)
    score = np.real(np.vdot(reference[inside] * weights[inside], gated[inside]) * turns)
    m = int(np.flatnonzero(score >= score.max() - 1e-9 * np.abs(score).max())[0])
    start = (lo - record // 2 + peak) / fs + shifts[m] * period
    return VelocityGate(gated * turns[m], start, start + (hi - lo) / fs, ramp / fs)
