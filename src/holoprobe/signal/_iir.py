"""Zero-phase Butterworth high-pass filtering in NumPy (no ``scipy.signal``).

:func:`butter_highpass_sos` and :func:`sosfiltfilt` compute what
``scipy.signal.sosfiltfilt(scipy.signal.butter(order, cutoff, "highpass", fs=fs,
output="sos"), x)`` computes, by the same formulas (prototype poles, high-pass
transform, bilinear transform, second-order sections in direct form II transposed,
odd-extension padding and steady-state initial conditions), without importing
``scipy.signal``: that import pulls in ``scipy.stats`` and costs a cold process
≈ 0.3–1 s CPU, more than the filtering of an echo average.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError

__all__ = ["butter_highpass_sos", "sosfiltfilt"]


MIN_RELATIVE_CUTOFF = 1e-5
"""Smallest cut-off of :func:`butter_highpass_sos` as a fraction of the sampling rate.
The poles lie ~2π·cutoff/fs inside z = 1 and the sections' steady state divides by its
square: at 1e-5 an order-2 to -12 zero-phase filtering agrees with scipy's to ≤ 1e-8 of
the record's peak, at 1e-7 to ≤ 2e-4 (both designs lose their digits), at 1e-9 the
poles round onto z = 1 and the initial conditions are singular."""


def butter_highpass_sos(order: int, cutoff: float, sampling_rate: float) -> NDArray[np.float64]:
    """Digital Butterworth high-pass filter as second-order sections.

    The same transfer function as ``scipy.signal.butter(order, cutoff, "highpass",
    fs=sampling_rate, output="sos")`` (frequency response and filtered records equal to
    rounding, ~1e-14): for an odd order the real pole's first-order section first, then
    the complex pole pairs from the one farthest from the unit circle to the nearest;
    the gain in the first section. The sections themselves can differ from scipy's: for
    an odd order with a cut-off above ~fs/4 scipy pairs the zeros with the poles in
    another order.

    Parameters
    ----------
    order : int
        Filter order, ≥ 1.
    cutoff : float
        −3 dB frequency in Hz, :data:`MIN_RELATIVE_CUTOFF` · sampling_rate ≤ cutoff <
        sampling_rate / 2.
    sampling_rate : float
        Hz.

    Returns
    -------
    ndarray, shape (ceil(order / 2), 6)
        Rows ``b0, b1, b2, 1, a1, a2``.
    """
    n = int(order)
    if n < 1:
        raise InputError(f"expected a filter order ≥ 1, got {order}", field="highpass_order")
    fs, fc = float(sampling_rate), float(cutoff)
    if not MIN_RELATIVE_CUTOFF * fs <= fc < 0.5 * fs:
        raise InputError(f"expected a cut-off in [{MIN_RELATIVE_CUTOFF * fs:g}, {0.5 * fs:g})"
                         f" Hz ({MIN_RELATIVE_CUTOFF:g} to 0.5 of the sampling rate "
                         f"{fs:g} Hz), got {fc:g}", field="highpass_cutoff")
    # analog prototype (unit cut-off), pre-warped to the bilinear transform at fs' = 2
    p = -np.exp(1j * np.pi * np.arange(-n + 1, n, 2) / (2 * n))
    warped = 4.0 * np.tan(np.pi * (2.0 * fc / fs) / 2.0)
    k = float(np.real(1.0 / np.prod(-p)))  # low-pass -> high-pass: n zeros at s = 0
    p = warped / p
    k *= float(np.real(4.0**n / np.prod(4.0 - p)))  # bilinear: zeros at z = 1
    pz = (4.0 + p) / (4.0 - p)
    rows = []
    real = pz[np.abs(pz.imag) <= 1e-12 * np.abs(pz)]
    for r in real:  # one for an odd order
        rows.append([1.0, -1.0, 0.0, 1.0, -float(r.real), 0.0])
    pairs = pz[pz.imag > 1e-12 * np.abs(pz)]
    for q in pairs[np.argsort(np.abs(pairs), kind="stable")]:
        rows.append([1.0, -2.0, 1.0, 1.0, -2.0 * float(q.real), float(abs(q) ** 2)])
    sos = np.array(rows)
    sos[0, :3] *= k
    return sos


def _sosfilt_zi(sos: NDArray[np.float64]) -> NDArray[np.float64]:
    """Steady-state initial conditions of each section for a unit step input
    (``scipy.signal.sosfilt_zi``)."""
    zi = np.empty((sos.shape[0], 2))
    scale = 1.0
    for s, (b, a) in enumerate(zip(sos[:, :3], sos[:, 3:], strict=True)):
        # (I - Aᵀ) zi = b[1:] - a[1:] b0 with A the companion matrix of a
        i_minus_a = np.array([[1.0 + a[1], -1.0], [a[2], 1.0]])
        zi[s] = scale * np.linalg.solve(i_minus_a, b[1:] - a[1:] * b[0])
        scale *= b.sum() / a.sum()
    return zi


def _sosfilt(sos: NDArray[np.float64], x: NDArray[np.float64],
             zi: NDArray[np.float64]) -> NDArray[np.float64]:
    """Cascade of second-order sections in direct form II transposed, sample by sample
    (the recursion of ``scipy.signal.sosfilt``)."""
    y = x.tolist()
    for (b0, b1, b2, _, a1, a2), (z0, z1) in zip(sos.tolist(), zi.tolist(), strict=True):
        for i, xi in enumerate(y):
            yi = b0 * xi + z0
            z0 = b1 * xi - a1 * yi + z1
            z1 = b2 * xi - a2 * yi
            y[i] = yi
    return np.array(y)


def sosfiltfilt(sos: ArrayLike, x: ArrayLike) -> NDArray[np.float64]:
    """Zero-phase filtering of a 1-D record by second-order sections, forwards then
    backwards (``scipy.signal.sosfiltfilt(sos, x)`` with its defaults: odd extension of
    3 × (2·sections + 1 − sections without a second-order term) samples at each end,
    steady-state initial conditions).

    Parameters
    ----------
    sos : array_like, shape (n_sections, 6)
        Rows ``b0, b1, b2, 1, a1, a2`` (e.g. from :func:`butter_highpass_sos`).
    x : array_like, shape (nt,)
        The record (any unit).

    Returns
    -------
    ndarray, shape (nt,)
        The filtered record.
    """
    s = np.asarray(sos, dtype=float)
    if s.ndim != 2 or s.shape[1] != 6 or not np.all(s[:, 3] == 1.0):
        raise InputError(f"expected second-order sections of shape (n, 6) with a0 = 1, got "
                         f"shape {s.shape}", field="sos")
    v = np.asarray(x, dtype=float)
    if v.ndim != 1:
        raise InputError(f"expected a 1-D record, got shape {v.shape}", field="x")
    ntaps = 2 * s.shape[0] + 1 - min(int(np.sum(s[:, 2] == 0)), int(np.sum(s[:, 5] == 0)))
    edge = 3 * ntaps
    if v.size <= edge:
        raise InputError(f"expected more than {edge} samples for the filter's padding, got "
                         f"{v.size}", field="x")
    ext = np.concatenate((2 * v[0] - v[edge:0:-1], v, 2 * v[-1] - v[-2:-(edge + 2):-1]))
    zi = _sosfilt_zi(s)
    y = _sosfilt(s, ext, zi * ext[0])
    y = _sosfilt(s, y[::-1], zi * y[-1])[::-1]
    return y[edge:-edge]
