"""Phase compensation and reciprocity (paper section IV B, Fig. 10).

Two parts of the measurement chain add phase that the characterization does not know: an
analogue low-pass filter (phase from its datasheet group delay) and the hydrophone (assumed
minimum phase: its phase follows from its amplitude calibration by Bode's gain–phase
relation). Both sit behind the measured pressure, so they are *contained* in the transmit
impulse response (deconvolution of the measured pressure by the drive, paper eq.
deconvolution-transmit) and enter the receive impulse response *inversely* (deconvolution of
the RF by the measured pressure, paper eq. deconvolution-receive). Compensation therefore
removes the phase from the transmit IR (``direction=+1`` of
:func:`holoprobe.signal.compensate_phase`) and applies it to the receive IR
(``direction=−1``), every phase in holoprobe's Fourier convention (paper eq.
complex-conjugate-fourier). The published analysis adds a conjugate-convention minimum phase
to an FFT-convention filter phase (reference_spec section 7 item 3): here both are
converted to one convention before they are summed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Literal

import numpy as np
from matplotlib.figure import Figure
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.measurement import HydrophoneCalibration
from holoprobe.signal import (
    PhaseResponse,
    compensate_phase,
    filter_phase_from_group_delay,
    frequency_axis,
    minimum_phase,
    next_fast_length,
    resample,
    to_frequency,
)

__all__ = [
    "PhaseResult",
    "analyse_phase",
    "default_filter_phase",
    "hydrophone_phase",
    "normalised_similarity",
    "phase_figures",
]

_US, _MHZ = 1e6, 1e-6


def default_filter_phase() -> PhaseResponse:
    """Phase of the packaged BLP-15+ low-pass filter datasheet (``data/BLP-15+.txt``)."""
    path = resources.files("holoprobe") / "data" / "BLP-15+.txt"
    with resources.as_file(path) as p:
        return filter_phase_from_group_delay(Path(p), name="BLP-15+")


def hydrophone_phase(calibration: HydrophoneCalibration | tuple[ArrayLike, ArrayLike],
                     frequency: ArrayLike, *,
                     extrapolation: Literal["constant", "slope"] = "constant",
                     convention: Literal["holoprobe", "fft"] = "holoprobe"
                     ) -> NDArray[np.float64]:
    """Minimum phase of a hydrophone from its amplitude calibration (Bode gain–phase).

    A thin layer over :func:`holoprobe.signal.minimum_phase` (exact integral of the
    piecewise-linear log-amplitude, no truncation of the log-frequency range).

    Parameters
    ----------
    calibration : HydrophoneCalibration or (frequency, sensitivity)
        Sensitivity magnitude (any unit) at increasing frequencies (Hz).
    frequency : array_like
        Frequencies (Hz, ≥ 0) where the phase is wanted.
    extrapolation : {"constant", "slope"}
        Outside the calibrated band, hold the magnitude (default: safe for noisy end
        points) or continue the end slopes in log–log (power-law asymptotes).
    convention : {"holoprobe", "fft"}
        Convention of the returned phase.

    Returns
    -------
    ndarray, shape of ``frequency``
        Phase in rad.
    """
    f: ArrayLike
    s: ArrayLike
    if isinstance(calibration, HydrophoneCalibration):
        f, s = calibration.frequency, calibration.sensitivity
    else:
        try:
            f, s = calibration
        except (TypeError, ValueError):
            raise InputError("expected a HydrophoneCalibration or (frequency_Hz, sensitivity)",
                             field="calibration") from None
    return minimum_phase(f, np.abs(np.asarray(s, dtype=float)), at=frequency,
                         extrapolation=extrapolation, convention=convention)


def normalised_similarity(a: ArrayLike, b: ArrayLike) -> tuple[float, int]:
    """Largest normalised cross-correlation of two records and its lag (samples, b after a).

    ``max_l Σ a[n] b[n + l] / (‖a‖ ‖b‖)``: 1 for identical shapes at any delay.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if not (na > 0 and nb > 0):
        return math.nan, 0
    c = np.correlate(b, a, mode="full") / (na * nb)
    i = int(np.argmax(c))
    return float(c[i]), i - (a.size - 1)


@dataclass(frozen=True)
class PhaseResult:
    """Result of :func:`analyse_phase` (SI units).

    Attributes
    ----------
    sampling_rate : float
        Common rate (Hz) of the impulse responses below.
    time : ndarray, shape (n,)
        Sample times (s).
    transmit, receive : ndarray, shape (n,)
        Impulse responses as given (receive resampled to ``sampling_rate``), mean removed,
        zero-padded or truncated to ``n``.
    transmit_compensated, receive_compensated : ndarray, shape (n,)
        After compensation (transmit: phase removed; receive: phase applied).
    frequency : ndarray, shape (nf,)
        Hz.
    transmit_tf, receive_tf : ndarray, complex, shape (nf,)
        Transfer functions ``H = conj(FFT{h}) / fs`` (units of h·s).
    filter_phase, hydrophone_phase : ndarray, shape (nf,)
        Phases (rad, holoprobe's convention) of the filter and the hydrophone; zero when
        not used.
    similarity_before, similarity_after : float
        :func:`normalised_similarity` of the normalised transmit and receive IRs.
    lag_before, lag_after : float
        Delay (s) of the receive IR relative to the transmit IR at that maximum.
    notes : list of str
    """

    sampling_rate: float
    time: NDArray[np.float64]
    transmit: NDArray[np.float64]
    receive: NDArray[np.float64]
    transmit_compensated: NDArray[np.float64]
    receive_compensated: NDArray[np.float64]
    frequency: NDArray[np.float64]
    transmit_tf: NDArray[np.complex128]
    receive_tf: NDArray[np.complex128]
    filter_phase: NDArray[np.float64]
    hydrophone_phase: NDArray[np.float64]
    similarity_before: float
    similarity_after: float
    lag_before: float
    lag_after: float
    notes: list[str] = field(default_factory=list)

    def summary(self) -> dict[str, object]:
        """The ``phase`` entry of ``summary.json``."""

        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        return {"similarity_before": num(self.similarity_before),
                "similarity_after": num(self.similarity_after),
                "lag_before_s": num(self.lag_before), "lag_after_s": num(self.lag_after),
                "sampling_rate_hz": self.sampling_rate, "notes": list(self.notes)}


def _ir(values: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.size < 4 or not np.all(np.isfinite(arr)):
        raise InputError("expected a finite 1-D impulse response of at least 4 samples",
                         field=name)
    return arr


def analyse_phase(
    transmit_ir: ArrayLike,
    transmit_rate: float,
    receive_ir: ArrayLike,
    receive_rate: float,
    *,
    filter_phase: PhaseResponse | Callable[[NDArray], NDArray] | None = None,
    hydrophone: HydrophoneCalibration | tuple[ArrayLike, ArrayLike] | None = None,
    hydrophone_extrapolation: Literal["constant", "slope"] = "constant",
    duration: float | None = 2e-6,
    remove_mean: bool = True,
) -> PhaseResult:
    """Transfer functions and phase compensation of transmit and receive IRs (paper IV B).

    Both IRs are brought to the transmit rate (the receive IR by
    :func:`holoprobe.signal.resample`), cut to ``duration``, the mean removed; the phase
    ``φ = φ_filter + φ_hydrophone`` (holoprobe's convention; a callable ``filter_phase``
    must return that convention) is removed from the transmit IR and applied to the
    receive IR (:func:`holoprobe.signal.compensate_phase`, ``direction=+1`` / ``−1``, with
    zero padding so that the shift does not wrap).

    Parameters
    ----------
    transmit_ir, receive_ir : array_like, shape (n_t,), (n_r,)
        h_T and h_R (sample 0 at t = 0).
    transmit_rate, receive_rate : float
        Their sampling rates in Hz.
    filter_phase : PhaseResponse or callable, optional
        Phase of the analogue filter (e.g. :func:`default_filter_phase`); None: none.
    hydrophone : HydrophoneCalibration or (frequency, sensitivity), optional
        Amplitude calibration whose minimum phase is compensated; None: none.
    hydrophone_extrapolation : {"constant", "slope"}
        See :func:`hydrophone_phase`.
    duration : float or None
        Length (s) kept of each IR (None: the longer IR).
    remove_mean : bool
        Subtract the mean of each (cut) IR.

    Returns
    -------
    PhaseResult
    """
    ht = _ir(transmit_ir, "transmit_ir")
    hr = _ir(receive_ir, "receive_ir")
    for name, value in (("transmit_rate", transmit_rate), ("receive_rate", receive_rate)):
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"expected a positive rate in Hz, got {value!r}", field=name)
    fs = float(transmit_rate)
    if not math.isclose(receive_rate, fs, rel_tol=1e-9):
        hr = np.asarray(resample(hr, float(receive_rate), fs), dtype=float)
    n = max(ht.size, hr.size) if duration is None else round(duration * fs)
    if n < 4:
        raise InputError(f"expected a duration of at least 4 samples, got {duration!r} s",
                         field="duration")
    ht = np.pad(ht, (0, max(0, n - ht.size)))[:n]
    hr = np.pad(hr, (0, max(0, n - hr.size)))[:n]
    if remove_mean:
        ht = ht - ht.mean()
        hr = hr - hr.mean()
    nfft = next_fast_length(2 * n)
    f = frequency_axis(nfft, fs)
    notes: list[str] = []
    phi_f = np.zeros(f.size)
    phi_h = np.zeros(f.size)
    if filter_phase is not None:
        phi_f = (np.asarray(filter_phase(f, convention="holoprobe"), float)
                 if isinstance(filter_phase, PhaseResponse)
                 else np.asarray(filter_phase(f), float))
        notes.append("filter phase: " + (getattr(filter_phase, "name", "") or "given"))
    if hydrophone is not None:
        phi_h = hydrophone_phase(hydrophone, f, extrapolation=hydrophone_extrapolation)
        notes.append("hydrophone minimum phase: "
                     + (getattr(hydrophone, "name", "") or "given calibration"))
    phi = phi_f + phi_h
    pad = nfft - n
    ht_c = compensate_phase(ht, fs, phi, direction=1, pad=pad)
    hr_c = compensate_phase(hr, fs, phi, direction=-1, pad=pad)
    tf_t = np.asarray(to_frequency(ht, n=nfft) / fs, dtype=np.complex128)
    tf_r = np.asarray(to_frequency(hr, n=nfft) / fs, dtype=np.complex128)

    def norm(x: NDArray) -> NDArray:
        peak = float(np.max(np.abs(x)))
        return x / peak if peak > 0 else x

    sb, lb = normalised_similarity(norm(ht), norm(hr))
    sa, la = normalised_similarity(norm(ht_c), norm(hr_c))
    return PhaseResult(sampling_rate=fs, time=np.arange(n) / fs, transmit=ht, receive=hr,
                       transmit_compensated=ht_c, receive_compensated=hr_c, frequency=f,
                       transmit_tf=tf_t, receive_tf=tf_r, filter_phase=phi_f,
                       hydrophone_phase=phi_h, similarity_before=sb, similarity_after=sa,
                       lag_before=lb / fs, lag_after=la / fs, notes=notes)


def phase_figures(result: PhaseResult) -> list[tuple[Figure, str]]:
    """Paper Fig. 10 for a :class:`PhaseResult`: transfer functions, compensation phases,
    normalised IRs before and after compensation, with captions."""
    from holoprobe.report import plot_transfer_functions

    r = result
    figs: list[tuple[Figure, str]] = []
    fig = plot_transfer_functions(r.frequency, r.transmit_tf, r.receive_tf,
                                  max_frequency=min(r.frequency[-1], 10e6))
    figs.append((fig, "Normalised transmit and receive transfer functions (Fourier "
                 "transforms of the impulse responses; paper Fig. 10a). Look at how close "
                 "the magnitudes are: reciprocity makes H_R/H_T nearly independent of "
                 "frequency."))

    fig = Figure(figsize=(7.0, 3.0), layout="constrained")
    ax = fig.subplots()
    band = r.frequency <= min(r.frequency[-1], 15e6)
    ax.plot(r.frequency[band] * _MHZ, r.filter_phase[band], label="filter (group delay)")
    ax.plot(r.frequency[band] * _MHZ, r.hydrophone_phase[band],
            label="hydrophone (minimum phase)")
    ax.plot(r.frequency[band] * _MHZ, (r.filter_phase + r.hydrophone_phase)[band], "k--",
            label="total")
    ax.set_xlabel("frequency (MHz)")
    ax.set_ylabel("phase, holoprobe convention (rad)")
    ax.legend(loc="best", fontsize="small")
    figs.append((fig, "Phase of the measurement chain that is compensated, in holoprobe's "
                 "convention (a delay τ has phase +2πfτ): the low-pass filter from its "
                 "datasheet group delay and the hydrophone's minimum phase from its "
                 "amplitude calibration (Bode). Look for a nearly linear rise: the chain "
                 "mostly delays the signal."))

    for before, title, letter in ((True, "before", "b"), (False, "after", "c")):
        ht = r.transmit if before else r.transmit_compensated
        hr = r.receive if before else r.receive_compensated
        sim = r.similarity_before if before else r.similarity_after
        fig = Figure(figsize=(7.0, 3.0), layout="constrained")
        ax = fig.subplots()
        for h, label, color in ((ht, "transmit", "tab:blue"), (hr, "receive", "tab:red")):
            peak = float(np.max(np.abs(h))) or 1.0
            ax.plot(r.time * _US, h / peak, color=color, linewidth=1.1, label=label)
        ax.set_xlabel("time (µs)")
        ax.set_ylabel("normalised impulse response (1)")
        ax.legend(loc="best", fontsize="small")
        figs.append((fig, f"Normalised transmit and receive impulse responses {title} "
                     f"compensating the phase of the measurement chain (paper Fig. 10{letter}"
                     f"). Similarity (largest normalised cross-correlation): {sim:.3f}. "
                     "Compare the shapes: after compensation they should be closer."))
    return figs
