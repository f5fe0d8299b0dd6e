"""Source spectra, the simulated band and the time window of a synthesis."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import Medium
from holoprobe.signal import frequency_axis, next_fast_length, to_frequency
from holoprobe.simulate._array import ArrayModel, SourceSampling

__all__ = ["SynthesisWindow", "continuous_spectrum", "signal_band", "source_spectra"]


def continuous_spectrum(signal: ArrayLike, sampling_rate: float, frequencies: ArrayLike, *,
                        start_time: float = 0.0) -> NDArray[np.complex128]:
    """Continuous-time Fourier transform of a sampled signal at arbitrary frequencies.

    ``X(f) = Δt Σ_n x[n] exp(+2πi f (t0 + nΔt))`` — holoprobe's conjugate convention
    (paper eq. complex-conjugate-fourier), exact for a band-limited signal.

    Parameters
    ----------
    signal : array_like, shape (n,)
        Samples (sample 0 at ``start_time``).
    sampling_rate : float
        Hz.
    frequencies : array_like, shape (nf,)
        Hz.
    start_time : float
        Time of sample 0 in s.

    Returns
    -------
    ndarray, complex, shape (nf,)
        In signal units · s.
    """
    x = np.asarray(signal, dtype=float).reshape(-1)
    f = np.asarray(frequencies, dtype=float).reshape(-1)
    t = start_time + np.arange(x.size) / sampling_rate
    out = np.empty(f.size, dtype=complex)
    block = max(1, (1 << 22) // max(1, x.size))
    for i in range(0, f.size, block):
        out[i:i + block] = np.exp(2j * np.pi * np.outer(f[i:i + block], t)) @ x
    return out / sampling_rate


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


def source_spectra(model: ArrayModel, sampling: SourceSampling, frequencies: ArrayLike,
                   medium: Medium, *, dtype: type = np.complex128) -> NDArray:
    """Normal velocity spectra V(r_j; f) of every quadrature point.

    ``V_j(f) = a_e U(f) exp(iω(τ_lens(y_j) + τ_e))`` on the active aperture, with
    ``U`` the continuous spectrum of :meth:`ArrayModel.surface_velocity`, ``a_e``/``τ_e``
    the element apodization/delay and τ_lens the exact lens delay (paper eq.
    lens-delays); plus the antisymmetric edge mode when the model has one.

    Returns
    -------
    ndarray, complex, shape (n_points, nf)
        m/s·s (continuous spectrum).
    """
    f = np.asarray(frequencies, dtype=float).reshape(-1)
    omega = 2 * np.pi * f
    u = model.surface_velocity(medium)
    spec_u = continuous_spectrum(u, model.ir_sampling_rate, f)
    e = sampling.element
    act = sampling.active
    tau = np.where(act, model.lens_delays(sampling.y, medium), 0.0) + model.delays[e]
    amp = np.where(act, model.apodization[e], 0.0)
    out = (amp[:, None] * spec_u[None, :]) * np.exp(1j * np.outer(tau, omega))
    em = model.edge_mode
    if em is not None and em.amplitude != 0:
        g = em.waveform(model.ir_sampling_rate)
        scale = em.amplitude * np.max(np.abs(u))
        spec_g = continuous_spectrum(g, model.ir_sampling_rate, f,
                                     start_time=-em.waveform_offset)
        half = 0.5 * model.element_height
        ay = np.abs(sampling.y)
        path = np.where(act, half - ay, ay - half)
        use = np.ones(act.shape, bool)
        if em.direction == "inward":
            use = act
        elif em.direction == "outward":
            use = ~act
        weight = np.where(use, scale * np.sign(sampling.y) * model.apodization[e], 0.0)
        if np.isfinite(em.decay_length):
            weight = weight * np.exp(-path / em.decay_length)
        t_edge = em.delay + path / em.phase_speed + model.delays[e]
        out += (weight[:, None] * spec_g[None, :]) * np.exp(1j * np.outer(t_edge, omega))
    return out.astype(dtype, copy=False)


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
