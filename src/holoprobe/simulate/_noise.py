"""Measurement imperfections: additive white noise at a defined SNR, quantisation."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError

__all__ = ["add_noise", "noise_std_for_snr", "peak_snr_db", "quantize"]


def noise_std_for_snr(clean: NDArray, snr_db: float) -> float:
    """Noise standard deviation σ that gives a peak SNR of ``snr_db``.

    The SNR of holoprobe's simulator is a **peak** SNR over the whole record::

        SNR_dB = 10·log10( max |s|² / σ² ) = 20·log10( max |s| / σ )

    with ``s`` the clean (noise-free) signal over all traces and samples and σ² the
    variance of the additive white Gaussian noise (one value for the whole record, as for
    one receiver chain).

    Parameters
    ----------
    clean : ndarray
        The clean signal, any shape.
    snr_db : float
        Requested peak SNR in dB.

    Returns
    -------
    float
        σ in the units of ``clean``.
    """
    if not np.isfinite(snr_db):
        raise InputError(f"expected a finite SNR in dB, got {snr_db!r}", field="snr_db")
    peak = float(np.max(np.abs(clean)))
    if peak == 0:
        raise InputError("the clean signal is zero everywhere: no SNR can be defined",
                         field="snr_db")
    return peak * 10.0 ** (-snr_db / 20.0)


def peak_snr_db(clean: NDArray, noise: NDArray) -> float:
    """Peak SNR ``20·log10(max|clean| / std(noise))`` in dB (the simulator's definition)."""
    return float(20.0 * np.log10(np.max(np.abs(clean)) / np.std(noise)))


def add_noise(clean: NDArray, snr_db: float | None, rng: np.random.Generator, *,
              chunk: int = 1 << 22) -> tuple[NDArray, float]:
    """Add white Gaussian noise at a peak SNR (see :func:`noise_std_for_snr`), in place.

    Parameters
    ----------
    clean : ndarray, float
        Signal; overwritten with signal + noise (keeps its dtype).
    snr_db : float or None
        Peak SNR in dB; None adds nothing.
    rng : numpy.random.Generator
        Source of the noise (seeded by the caller for reproducibility).
    chunk : int
        Number of values drawn at once (bounds the memory).

    Returns
    -------
    (data, sigma) : (ndarray, float)
        The same array and the noise standard deviation (0 without noise).
    """
    if snr_db is None:
        return clean, 0.0
    sigma = noise_std_for_snr(clean, snr_db)
    flat = clean.reshape(-1)
    for i in range(0, flat.size, chunk):
        part = flat[i:i + chunk]
        part += (sigma * rng.standard_normal(part.size)).astype(flat.dtype, copy=False)
    return clean, sigma


def quantize(data: NDArray, bits: int | None, full_scale: float | None = None
             ) -> tuple[NDArray, float]:
    """Quantise to ``bits`` bits over ``[−full_scale, full_scale)`` (mid-tread), in place.

    Parameters
    ----------
    data : ndarray, float
        Values; overwritten.
    bits : int or None
        Resolution; None leaves the data alone.
    full_scale : float, optional
        Range limit in the units of ``data``; default the largest |value| (no clipping).

    Returns
    -------
    (data, lsb) : (ndarray, float)
        The array and the step ``2·full_scale / 2**bits`` (0 when not quantised).
    """
    if bits is None:
        return data, 0.0
    if int(bits) != bits or not 2 <= bits <= 32:
        raise InputError(f"expected an integer number of bits in 2..32, got {bits!r}",
                         field="quantization_bits")
    if full_scale is None:
        full_scale = float(np.max(np.abs(data)))
    if not (np.isfinite(full_scale) and full_scale > 0):
        raise InputError(f"expected a positive range, got {full_scale!r}", field="full_scale")
    lsb = 2.0 * full_scale / 2.0 ** int(bits)
    half = 2 ** (int(bits) - 1)
    np.divide(data, lsb, out=data)
    np.rint(data, out=data)
    np.clip(data, -half, half - 1, out=data)
    np.multiply(data, lsb, out=data)
    return data, lsb
