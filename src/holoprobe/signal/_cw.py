"""A CW (single-frequency) hologram from a transient one, at any frequency."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError
from holoprobe.measurement import Hologram

__all__ = ["cw_amplitude", "extract_cw"]

_METHODS = ("dft", "fit")


def cw_amplitude(waveforms: NDArray, time: NDArray, frequency: float, *,
                 method: str = "dft") -> NDArray[np.complex128]:
    """Complex amplitude P of ``p(t) ≈ Re{P e^{−iωt}}`` at one frequency, per trace.

    Parameters
    ----------
    waveforms : ndarray, shape (..., nt)
        Real signals (time last), e.g. Pa.
    time : ndarray, shape (nt,)
        Absolute sample times in s (the phase is referred to t = 0, not to the first
        sample).
    frequency : float
        Frequency in Hz (any value, not only a DFT bin).
    method : {"dft", "fit"}
        ``"dft"``: ``P = (2/N) Σ p(t_n) e^{iωt_n}`` — the single-sided spectrum
        scaled to an amplitude, as the holography community extracts a CW hologram
        (exact for a steady tone with a whole number of periods in the record).
        ``"fit"``: least-squares fit of ``a cos ωt + b sin ωt + c`` over the record,
        ``P = a + ib`` — exact for a steady tone of any frequency and record length.

    Returns
    -------
    ndarray, complex, shape (...)
        Amplitude in the unit of ``waveforms``, holoprobe's convention (e^{−iωt}).
    """
    if method not in _METHODS:
        raise InputError(f"expected one of {_METHODS}, got {method!r}", field="method")
    p = np.asarray(waveforms, dtype=float)
    t = np.asarray(time, dtype=float)
    if p.shape[-1] != t.size or t.size < 3:
        raise InputError(f"expected ≥ 3 samples matching the time axis ({t.size}), got "
                         f"shape {p.shape}", field="waveforms")
    if not (np.isfinite(frequency) and frequency > 0):
        raise InputError(f"expected a positive frequency in Hz, got {frequency!r}",
                         field="frequency")
    w = 2 * np.pi * frequency
    flat = p.reshape(-1, t.size)
    if method == "dft":
        amp = flat @ np.exp(1j * w * t) * (2.0 / t.size)
    else:
        basis = np.stack([np.cos(w * t), np.sin(w * t), np.ones_like(t)], axis=1)
        coef, *_ = np.linalg.lstsq(basis, flat.T, rcond=None)
        amp = coef[0] + 1j * coef[1]
    return np.asarray(amp, dtype=np.complex128).reshape(p.shape[:-1])


def extract_cw(hologram: Hologram, frequency: float, *, method: str = "dft") -> Hologram:
    """The CW hologram at ``frequency`` (Hz) of a transient hologram.

    See :func:`cw_amplitude` for the methods. The result keeps the grid, medium,
    geometry and source of ``hologram``.
    """
    if not isinstance(hologram, Hologram) or not hologram.is_transient:
        raise InputError("expected a transient Hologram", field="hologram")
    # (type: ignore below) a transient Hologram has a sampling rate
    f_nyquist = 0.5 * float(hologram.sampling_rate)  # type: ignore[arg-type]
    if not 0 < frequency < f_nyquist:
        raise InputError(f"expected a frequency between 0 and the Nyquist frequency "
                         f"{f_nyquist:g} Hz, got {frequency!r}", field="frequency")
    amp = cw_amplitude(hologram.pressure, hologram.time, frequency, method=method)
    return Hologram(amp, hologram.grid, hologram.medium, frequency=float(frequency),
                    geometry=hologram.geometry, source=hologram.source)
