"""Source spectra, the simulated band and the time window of a synthesis."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, Surface
from holoprobe.propagation import rayleigh_integral
from holoprobe.signal import continuous_spectrum, frequency_axis, next_fast_length, to_frequency
from holoprobe.simulate._array import ArrayModel, SourceSampling

__all__ = [
    "SourceGroup",
    "SynthesisWindow",
    "radiate",
    "signal_band",
    "source_groups",
    "source_spectra",
]


def signal_band(model: ArrayModel, medium: Medium, *, threshold_db: float = -40.0,
                include_receive: bool = False, min_frequency: float = 0.0
                ) -> tuple[float, float]:
    """The frequency band that carries signal: where the source spectrum is above a level.

    Parameters
    ----------
    model : ArrayModel
        Its surface velocity ``(h_T ⊛ E_T)/ρ0c0`` (times ``h_R`` when
        ``include_receive``) defines the band; an edge mode widens it to its carrier
        ± 4 envelope bandwidths.
    medium : Medium
        For ρ0c0.
    threshold_db : float
        Level relative to the spectral peak in dB (negative); the band runs from the
        lowest to the highest frequency above it.
    include_receive : bool
        Weight by the receive impulse response (for echo simulations).
    min_frequency : float
        Lower limit in Hz (DC carries no radiated field from a baffled piston).

    Returns
    -------
    (f_lo, f_hi) : tuple of float
        Hz.
    """
    if not threshold_db < 0:
        raise InputError(f"expected a negative level in dB, got {threshold_db!r}",
                         field="band_threshold_db")
    u = model.surface_velocity(medium)
    fs = model.ir_sampling_rate
    n = next_fast_length(max(8 * u.size, 1 << 14))
    spec = np.abs(to_frequency(u, n=n))
    if include_receive:
        spec = spec * np.abs(to_frequency(model.receive_ir, n=n))
    f = frequency_axis(n, fs)
    above = np.nonzero(spec >= spec.max() * 10 ** (threshold_db / 20))[0]
    f_lo, f_hi = float(f[above[0]]), float(f[above[-1]])
    em = model.edge_mode
    if em is not None and em.amplitude != 0:
        bw = em.frequency / (2 * np.pi * em.cycles)  # envelope std in Hz
        f_lo, f_hi = min(f_lo, em.frequency - 4 * bw), max(f_hi, em.frequency + 4 * bw)
    return max(f_lo, min_frequency, f[1]), f_hi


@dataclass(frozen=True)
class SourceGroup:
    """Source points that share one waveform: ``V_j(f) = weight_j · G(f) · e^{iωτ_j}``.

    Attributes
    ----------
    weights : ndarray, shape (n_points,)
        Dimensionless amplitude per quadrature point (0 outside the group).
    delays : ndarray, shape (n_points,)
        Emission delay τ_j per point in s.
    waveform : ndarray, shape (n,)
        Normal velocity G(t) in m/s, sampled at ``sampling_rate``.
    sampling_rate : float
        Hz.
    start_time : float
        Time of the waveform's sample 0 in s.
    """

    weights: NDArray[np.float64]
    delays: NDArray[np.float64]
    waveform: NDArray[np.float64]
    sampling_rate: float
    start_time: float = 0.0

    def spectrum(self, frequencies: ArrayLike) -> NDArray[np.complex128]:
        """Continuous spectrum G(f) in m/s·s at ``frequencies`` (Hz)."""
        return continuous_spectrum(self.waveform, self.sampling_rate, frequencies,
                                   start_time=self.start_time)


def source_groups(model: ArrayModel, sampling: SourceSampling, medium: Medium
                  ) -> list[SourceGroup]:
    """The surface velocity of ``model`` as separable groups (see :class:`SourceGroup`).

    The main group is the thickness mode: ``a_e U(f) exp(iω(τ_lens(y_j) + τ_e))`` on
    the active aperture, with ``U`` the velocity of :meth:`ArrayModel.surface_velocity`,
    ``a_e``/``τ_e`` the element apodization/delay and τ_lens the exact lens delay
    (paper eq. lens-delays). The antisymmetric edge mode, when the model has one, is a
    second group whose delay grows with the distance from the element ends.
    """
    u = model.surface_velocity(medium)
    e = sampling.element
    act = sampling.active
    delays, apodization = np.asarray(model.delays), np.asarray(model.apodization)
    tau = np.where(act, model.lens_delays(sampling.y, medium), 0.0) + delays[e]
    amp = np.where(act, apodization[e], 0.0)
    groups = [SourceGroup(amp, tau, u, model.ir_sampling_rate)]
    em = model.edge_mode
    if em is not None and em.amplitude != 0:
        g = em.waveform(model.ir_sampling_rate)
        scale = em.amplitude * np.max(np.abs(u))
        half = 0.5 * model.element_height
        ay = np.abs(sampling.y)
        path = np.where(act, half - ay, ay - half)
        use = np.ones(act.shape, bool)
        if em.direction == "inward":
            use = act
        elif em.direction == "outward":
            use = ~act
        weight = np.where(use, scale * np.sign(sampling.y) * apodization[e], 0.0)
        if np.isfinite(em.decay_length):
            weight = weight * np.exp(-path / em.decay_length)
        t_edge = em.delay + path / em.phase_speed + delays[e]
        groups.append(SourceGroup(weight, t_edge, g, model.ir_sampling_rate,
                                  start_time=-em.waveform_offset))
    return groups


def source_spectra(model: ArrayModel, sampling: SourceSampling, frequencies: ArrayLike,
                   medium: Medium, *, dtype: type = np.complex128) -> NDArray:
    """Normal velocity spectra V(r_j; f) of every quadrature point, shape (n_points, nf).

    The sum over :func:`source_groups` of ``weight_j G(f) e^{iωτ_j}``, in m/s·s
    (continuous spectrum).
    """
    f = np.asarray(frequencies, dtype=float).reshape(-1)
    omega = 2 * np.pi * f
    out = np.zeros((sampling.surface.size, f.size), dtype=np.complex128)
    for group in source_groups(model, sampling, medium):
        out += (group.weights[:, None] * group.spectrum(f)[None, :]) * np.exp(
            1j * np.outer(group.delays, omega))
    return out.astype(dtype, copy=False)


def radiate(model: ArrayModel, sampling: SourceSampling, targets: Surface,
            frequencies: ArrayLike, medium: Medium, *, time_origin: float = 0.0,
            dtype: type = np.float64, max_memory: int = 1 << 29) -> NDArray:
    """Pressure spectra at ``targets`` by the dense Rayleigh integral (paper eq.
    rayleigh-fwd-vp, rigid baffle), one separable call per source group.

    Returns
    -------
    ndarray, complex, shape (targets.size, nf)
        Pa·s (continuous spectrum), time origin moved to ``time_origin``/c0.
    """
    f = np.asarray(frequencies, dtype=float).reshape(-1)
    out = None
    for group in source_groups(model, sampling, medium):
        part = rayleigh_integral(group.weights, sampling.surface, targets, f, medium,
                                 kernel="fwd_vp", baffle="rigid", time_origin=time_origin,
                                 dtype=dtype, max_memory=max_memory,
                                 source_delays=group.delays)
        part *= group.spectrum(f).astype(part.dtype)[None, :]
        out = part if out is None else out + part
    assert out is not None  # source_groups gives at least the thickness mode
    return out


@dataclass(frozen=True)
class SynthesisWindow:
    """A time window of a record that holds all the signal (plus its frequency grid).

    The field is synthesised on ``n_fft`` samples starting at ``origin`` (a sample time of
    the output record), on the bins ``k·fs/n_fft`` inside the band; everything outside the
    window is zero.
    """

    origin: float
    offset: int
    n_fft: int
    frequencies: NDArray[np.float64]
    bins: NDArray[np.int64]
    n_valid: int
    """Samples of the window (from ``origin``) that can hold signal; later ones hold
    the periodic image of what precedes the record start and must be dropped."""

    @classmethod
    def build(cls, first_arrival: float, last_time: float, start_time: float,
              sampling_rate: float, n_samples: int, band: tuple[float, float],
              *, guard: float = 0.0) -> SynthesisWindow:
        """Window from just before ``first_arrival`` to ``last_time`` (+ ``guard``), in s."""
        t0 = max(start_time, first_arrival - guard)
        offset = math.floor((t0 - start_time) * sampling_rate + 1e-9)
        offset = min(offset, max(0, n_samples - 1))
        origin = start_time + offset / sampling_rate
        # the period covers the whole signal, so what precedes the record start wraps
        # to after last_time, outside the record
        span = max(last_time + guard - min(origin, first_arrival - guard),
                   2.0 / sampling_rate)
        n_fft = next_fast_length(max(16, math.ceil(span * sampling_rate)))
        f = frequency_axis(n_fft, sampling_rate)
        bins = np.nonzero((f >= band[0]) & (f <= band[1]))[0]
        if bins.size == 0:
            raise InputError(f"no frequency bin of a {n_fft}-sample window at "
                             f"{sampling_rate:g} Hz lies in the band {band} Hz",
                             field="sampling_rate")
        n_valid = min(n_fft, math.ceil((last_time + guard - origin) * sampling_rate) + 1)
        return cls(origin, offset, n_fft, f[bins], bins, max(1, n_valid))
