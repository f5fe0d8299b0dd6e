"""The Fourier convention of holoprobe (paper eq. complex-conjugate-fourier).

A time signal p(t) becomes ``P(ω) = conj(FFT{p})``, so that plane waves read
``exp(i k·r − i ω t)``. Only non-negative frequencies are kept (``rfft`` then
``conj``); the way back is ``irfft(conj(P))``. These two helpers own the
convention: nothing else in holoprobe calls an FFT on time signals directly.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np
import scipy.fft
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "bin_energy",
    "blas_threads",
    "continuous_spectrum",
    "envelope",
    "frequency_axis",
    "next_fast_length",
    "to_frequency",
    "to_time",
    "workers",
]


def bin_energy(field: ArrayLike) -> NDArray[np.float64]:
    """``Σ |field|²`` over every axis but the last (per frequency bin), shape (nf,).

    The same sum as ``np.sum(np.abs(field) ** 2, axis=(0, 1))`` for a (nx, ny, nf)
    field to rounding (accumulated in float64), without its two full-size
    temporaries and the complex modulus (a square root per element): on a
    245 × 166 × 184 complex128 field 32 → 12 ms CPU.
    """
    a = np.asarray(field)
    a = a.reshape(1, 1) if a.ndim == 0 else a
    flat = np.ascontiguousarray(a.reshape(int(np.prod(a.shape[:-1])), a.shape[-1]))
    if np.iscomplexobj(flat):
        parts = flat.view(flat.real.dtype)  # (n, 2 nf): real and imaginary interleaved
        sums = np.einsum("ij,ij->j", parts, parts, dtype=np.float64)
        return sums[0::2] + sums[1::2]
    return np.einsum("ij,ij->j", flat, flat, dtype=np.float64)


def workers() -> int:
    """Number of threads handed to ``scipy.fft`` (all cores available to the process)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


_BLAS: dict[str, Any] = {}


@contextmanager
def blas_threads(limit: int = 1) -> Iterator[None]:
    """Run the block with BLAS/LAPACK (OpenBLAS, MKL) limited to ``limit`` threads.

    For loops over many small matrices (a few hundred rows or fewer): threaded BLAS
    only adds synchronisation there, and on a machine whose cores are shared with other
    jobs its spinning threads cost far more (96 × 96 complex products: 12× the CPU time
    of one thread at load 8, benchmarks/RESULTS.md). Uses ``threadpoolctl``.
    """
    from threadpoolctl import ThreadpoolController

    if "controller" not in _BLAS:  # inspecting the loaded libraries costs milliseconds
        _BLAS["controller"] = ThreadpoolController()
    with _BLAS["controller"].limit(limits=int(limit), user_api="blas"):
        yield


def next_fast_length(n: int) -> int:
    """The smallest length ≥ n that ``scipy.fft`` transforms quickly."""
    return int(scipy.fft.next_fast_len(int(n), real=True))


def to_frequency(signal: ArrayLike, *, n: int | None = None, axis: int = -1) -> NDArray:
    """Time → frequency with the conjugate convention, non-negative frequencies only.

    Parameters
    ----------
    signal : array_like, real
        Time signals; time along ``axis``.
    n : int, optional
        Transform length (zero-padding or truncation), default the signal length.
    axis : int
        The time axis.

    Returns
    -------
    ndarray, complex
        ``conj(rfft(signal, n))``: ``n // 2 + 1`` bins along ``axis`` (unscaled, like
        ``numpy.fft.rfft``). Multiply by the sample interval for a continuous-time
        Fourier transform in units·s.
    """
    signal = np.asarray(signal)
    if np.iscomplexobj(signal):
        raise TypeError("to_frequency expects real time signals")
    spectrum = scipy.fft.rfft(signal, n=n, axis=axis, workers=workers())
    return np.conjugate(spectrum, out=spectrum)  # in place: no second full-size array


def to_time(spectrum: ArrayLike, n: int, *, axis: int = -1) -> NDArray:
    """Frequency → time: the inverse of :func:`to_frequency`.

    Parameters
    ----------
    spectrum : array_like, complex
        ``n // 2 + 1`` non-negative frequency bins along ``axis`` in the conjugate
        convention.
    n : int
        Number of time samples to return.
    axis : int
        The frequency axis.

    Returns
    -------
    ndarray, real
        ``irfft(conj(spectrum), n)``.
    """
    # the conjugate is this function's own copy: the inverse transform may overwrite it
    return scipy.fft.irfft(np.conj(np.asarray(spectrum)), n=n, axis=axis, workers=workers(),
                           overwrite_x=True)


def frequency_axis(n: int, sampling_rate: float) -> NDArray[np.float64]:
    """Frequencies in Hz of the ``n // 2 + 1`` bins returned by :func:`to_frequency`."""
    return np.asarray(np.fft.rfftfreq(int(n), d=1.0 / float(sampling_rate)), dtype=np.float64)


def continuous_spectrum(signal: ArrayLike, sampling_rate: float, frequencies: ArrayLike, *,
                        start_time: float = 0.0) -> NDArray[np.complex128]:
    """Continuous-time Fourier transform of a sampled signal at arbitrary frequencies.

    ``X(f) = Δt Σ_n x[n] exp(+2πi f (t0 + nΔt))`` — holoprobe's conjugate convention
    (paper eq. complex-conjugate-fourier), exact for a signal band-limited below fs/2.
    The one implementation for drives, impulse responses and simulated sources.

    Parameters
    ----------
    signal : array_like, shape (n,)
        Samples (any unit u), sample 0 at ``start_time``.
    sampling_rate : float
        fs in Hz.
    frequencies : array_like, shape (nf,)
        Frequencies in Hz (below fs/2 for a meaningful result).
    start_time : float
        Time of sample 0 in s.

    Returns
    -------
    ndarray, complex, shape (nf,)
        X(f) in u·s.

    Examples
    --------
    A unit sample at t = 0 has the flat spectrum Δt:

    >>> x = continuous_spectrum([1.0, 0.0, 0.0], 1e6, [0.0, 1e5])
    >>> [complex(round(v.real * 1e6, 12), round(v.imag * 1e6, 12)) for v in x]
    [(1+0j), (1+0j)]
    """
    x = np.asarray(signal, dtype=float).reshape(-1)
    f = np.asarray(frequencies, dtype=float).reshape(-1)
    grid = _fft_grid(f, float(sampling_rate), x.size)
    if grid is not None:  # f on the bins of a DFT of length m ≥ n: one FFT, same sums
        k0, m = grid
        bins = np.conj(np.fft.fft(x, m))[(k0 + np.arange(f.size)) % m]
        spectrum: NDArray[np.complex128] = bins * np.exp(2j * np.pi * f * start_time)
        return spectrum / sampling_rate
    t = start_time + np.arange(x.size) / sampling_rate
    out = np.empty(f.size, dtype=np.complex128)
    block = max(1, (1 << 22) // max(1, x.size))  # bound the (nf, n) phase matrix
    for i in range(0, f.size, block):
        out[i:i + block] = np.exp(2j * np.pi * np.outer(f[i:i + block], t)) @ x
    out /= sampling_rate
    return out


def _fft_grid(f: NDArray[np.float64], sampling_rate: float, n: int
              ) -> tuple[int, int] | None:
    """(k0, m) when ``f = (k0 + k)·fs/m`` (k = 0, 1, …, to 1e-9 of a bin) with m ≥ n:
    then the sums of :func:`continuous_spectrum` are the DFT bins k0 + k of the signal
    zero-padded to m samples. None for short or irregular grids (summed directly)."""
    if f.size < 32 or n == 0:
        return None
    df = (f[-1] - f[0]) / (f.size - 1)
    if not (df > 0 and np.all(np.abs(np.diff(f) - df) <= 1e-9 * df)):
        return None
    m, k0 = sampling_rate / df, f[0] / df
    if abs(m - round(m)) > 1e-9 * m or abs(k0 - round(k0)) > 1e-6 or round(m) < n:
        return None
    if round(m) > 64 * max(n, f.size):  # a sparse grid: the direct sum is cheaper
        return None
    return round(k0), round(m)


def analytic_signal(signal: ArrayLike, *, n: int | None = None, axis: int = -1
                    ) -> NDArray[np.complex128]:
    """Analytic signal ``x + i H{x}`` along ``axis`` (the FFT method).

    The same as ``scipy.signal.hilbert(signal, N=n, axis=axis)`` (which would import
    scipy.signal and with it scipy.stats: ≈ 2 s of start-up): the FFT of the record
    (zero-padded or cut to n samples), its negative frequencies removed and the positive
    ones doubled, transformed back.

    Parameters
    ----------
    signal : array_like, real
        Samples (any unit u, any shape).
    n : int, optional
        Transform length (default: the record's).
    axis : int
        Time axis.

    Returns
    -------
    ndarray, complex
        In u, n samples along ``axis``.

    Examples
    --------
    >>> z = analytic_signal(np.cos(2 * np.pi * np.arange(8) / 8))
    >>> bool(np.allclose(z, np.exp(2j * np.pi * np.arange(8) / 8)))
    True
    """
    x = np.asarray(signal, dtype=float)
    size = x.shape[axis] if n is None else int(n)
    if size <= 0:
        raise ValueError("analytic_signal needs at least one sample")
    spectrum = scipy.fft.fft(x, n=size, axis=axis, workers=workers())
    h = np.zeros(size)
    h[0] = 1.0
    if size % 2 == 0:
        h[size // 2] = 1.0
        h[1:size // 2] = 2.0
    else:
        h[1:(size + 1) // 2] = 2.0
    shape = [1] * x.ndim
    shape[axis] = size
    return scipy.fft.ifft(spectrum * h.reshape(shape), axis=axis, workers=workers())


def envelope(signal: ArrayLike, *, axis: int = -1, pad: bool = True) -> NDArray[np.float64]:
    """Magnitude of the analytic signal along ``axis`` (the Hilbert envelope).

    Parameters
    ----------
    signal : array_like, real
        Samples (any unit u, any shape).
    axis : int
        Time axis.
    pad : bool
        Zero-pad the record to twice its length first, so that its end does not wrap
        onto its start (``False``: the plain, circular analytic signal, as
        ``scipy.signal.hilbert``).

    Returns
    -------
    ndarray
        |analytic signal| in u, same shape as ``signal``. Its magnitude does not
        depend on the sign convention of the transform.

    Examples
    --------
    >>> t = np.arange(400) / 400.0
    >>> env = envelope(np.cos(2 * np.pi * 20 * t), pad=False)
    >>> bool(np.allclose(env, 1.0))
    True
    """
    x = np.asarray(signal, dtype=float)
    if not pad:
        return np.abs(analytic_signal(x, axis=axis))
    n = x.shape[axis]
    analytic = analytic_signal(x, n=2 * n, axis=axis)
    return np.abs(np.take(analytic, np.arange(n), axis=axis))
