"""Band-limited resampling and fractional delays.

Both work on the periodic, band-limited (trigonometric) interpolant of the samples,
i.e. the signal implied by holoprobe's Fourier convention (paper eq.
complex-conjugate-fourier); the Nyquist bin of an even-length record is treated as a
cosine (half at +f_N, half at −f_N).
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.signal._fourier import frequency_axis, to_frequency, to_time

__all__ = ["fractional_delay", "resample"]

_INTEGER_RTOL = 1e-9


def _axis_index(axis: int, ndim: int, field: str = "axis") -> int:
    axis = int(axis)
    if not -ndim <= axis < ndim:
        raise InputError(f"axis {axis} is out of range for a {ndim}-D array", field=field)
    return axis % ndim


def _real_signal(signal: ArrayLike, field: str = "signal") -> NDArray:
    x = np.asarray(signal)
    if x.ndim == 0:
        raise InputError("expected an array with a time axis", field=field)
    if not np.issubdtype(x.dtype, np.number) or np.iscomplexobj(x):
        raise InputError(f"expected real numbers, got dtype {x.dtype}", field=field)
    return x


def _positive(value: float, field: str) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise InputError(f"expected a positive number, got {value!r}", field=field) from None
    if not (np.isfinite(value) and value > 0):
        raise InputError(f"expected a positive number, got {value!r}", field=field)
    return value


def _spectral_resample(spec: NDArray, n: int, m: int) -> NDArray:
    """Resize a conj-convention half spectrum of an n-sample record to m samples."""
    nb_in = n // 2 + 1
    nb_out = m // 2 + 1
    out = np.zeros((*spec.shape[:-1], nb_out), dtype=complex)
    k = min(nb_in, nb_out)
    out[..., :k] = spec[..., :k]
    if n % 2 == 0 and m > n:
        out[..., n // 2] *= 0.5  # old Nyquist cosine splits into ±f_N
    if m % 2 == 0 and m < n:
        out[..., m // 2] = out[..., m // 2].real  # new Nyquist: keep the cosine half
    return out * (m / n)


def resample(signal: ArrayLike, sampling_rate: float, new_rate: float, *, axis: int = -1,
             method: Literal["fft", "polyphase"] = "fft", n_out: int | None = None,
             eps: float = 1e-12, max_denominator: int = 10_000) -> NDArray:
    """Band-limited resampling to any new sampling rate.

    ``method="fft"`` evaluates the periodic band-limited interpolant of the record
    (low-passed to the new Nyquist frequency when downsampling) at the times
    ``k / new_rate``, ``k = 0 … n_out − 1``. For an integer output length
    ``nt · new_rate / sampling_rate`` this is spectral zero-padding / truncation; for any
    other ratio the Fourier series is evaluated exactly at the new times with a type-2
    non-uniform FFT (finufft, accuracy ``eps``). ``method="polyphase"`` uses
    :func:`scipy.signal.resample_poly` (non-periodic, zero-padded ends) with the ratio
    written as a fraction with denominator ≤ ``max_denominator``.

    Parameters
    ----------
    signal : array_like, real
        Samples; time along ``axis``.
    sampling_rate, new_rate : float
        Old and new sampling rates in Hz.
    axis : int
        Time axis.
    method : {"fft", "polyphase"}
        See above.
    n_out : int, optional
        Number of output samples (fft method); default the samples of one record period,
        ``ceil(nt · new_rate / sampling_rate)``.
    eps : float
        Relative accuracy of the non-uniform FFT (fft method, non-integer lengths).
    max_denominator : int
        Largest denominator of the rate ratio (polyphase method).

    Returns
    -------
    ndarray
        Resampled signal, first sample at the same time as the input's first sample.
    """
    x = _real_signal(signal)
    fs = _positive(sampling_rate, "sampling_rate")
    fr = _positive(new_rate, "new_rate")
    ax = _axis_index(axis, x.ndim)
    n = x.shape[ax]
    ratio = fr / fs
    if method == "polyphase":
        import scipy.signal

        frac = Fraction(ratio).limit_denominator(int(max_denominator))
        if abs(float(frac) - ratio) > _INTEGER_RTOL * ratio:
            raise InputError(f"the rate ratio {ratio:.12g} is not a fraction with denominator "
                             f"≤ {max_denominator}; use method='fft'", field="new_rate")
        return scipy.signal.resample_poly(x.astype(float), frac.numerator, frac.denominator,
                                          axis=ax)
    if method != "fft":
        raise InputError(f"expected 'fft' or 'polyphase', got {method!r}", field="method")
    exact = n * ratio
    if n_out is None:
        near = round(exact)
        n_out = near if abs(exact - near) <= _INTEGER_RTOL * max(exact, 1.0) else math.ceil(exact)
    n_out = int(n_out)
    if n_out < 1:
        raise InputError(f"expected at least one output sample, got {n_out}", field="n_out")
    xm = np.moveaxis(x, ax, -1)
    spec = to_frequency(xm.astype(float, copy=False), axis=-1)
    if abs(exact - round(exact)) <= _INTEGER_RTOL * max(exact, 1.0):
        m = round(exact)
        out = to_time(_spectral_resample(spec, n, m), m, axis=-1)
        if n_out <= m:
            out = out[..., :n_out]
        else:  # periodic continuation
            out = np.take(out, np.arange(n_out) % m, axis=-1)
        return np.moveaxis(out, -1, ax)
    out = _nufft_evaluate(spec, n, fs, np.arange(n_out) / fr, fr / 2, eps)
    return np.moveaxis(out, -1, ax)


def _nufft_evaluate(spec: NDArray, n: int, fs: float, times: NDArray, f_max: float,
                    eps: float) -> NDArray:
    """Evaluate the periodic band-limited interpolant (low-passed to f_max) at ``times``."""
    import finufft

    freqs = frequency_axis(n, fs)
    coef = np.conj(spec)  # FFT-convention coefficients X_k, k ≥ 0
    if n % 2 == 0:
        coef = coef.copy()
        coef[..., -1] *= 0.5
    keep = freqs < f_max * (1 - _INTEGER_RTOL)
    half = freqs <= f_max * (1 + _INTEGER_RTOL)
    weight = np.where(keep, 1.0, np.where(half, 0.5, 0.0))
    coef = coef * weight
    kmax = int(np.nonzero(weight)[0].max()) if np.any(weight) else 0
    pos = coef[..., : kmax + 1]
    # two-sided coefficients k = -kmax .. kmax (X_{-k} = conj(X_k) for a real signal)
    full = np.concatenate([np.conj(pos[..., :0:-1]), pos], axis=-1) / n
    lead = full.shape[:-1]
    full2 = np.ascontiguousarray(full.reshape(-1, full.shape[-1]), dtype=np.complex128)
    theta = np.mod(2 * np.pi * times * fs / n + np.pi, 2 * np.pi) - np.pi
    vals = finufft.nufft1d2(theta, full2, isign=1, eps=eps)
    return np.asarray(vals.real).reshape(*lead, times.size)


def fractional_delay(signal: ArrayLike, delay: ArrayLike, sampling_rate: float, *,
                     axis: int = -1, pad: bool | int = False) -> NDArray:
    """Delay signals by any (non-integer) time: ``y(t) = x(t − delay)``.

    Multiplies the spectrum (holoprobe's convention, paper eq. complex-conjugate-fourier)
    by ``exp(+i 2π f delay)``; the Nyquist bin of an even-length record (a cosine) by
    ``cos(2π f_N delay)``. The shift is circular unless ``pad`` adds zeros.

    Parameters
    ----------
    signal : array_like, real
        Signals; time along ``axis``.
    delay : float or array_like
        Delay in s (negative: advance); a scalar or an array that broadcasts against the
        signal's shape without the time axis (one delay per trace).
    sampling_rate : float
        Sampling rate in Hz.
    axis : int
        Time axis.
    pad : bool or int
        False: circular shift. True: zero-pad by ``ceil(max|delay| · fs) + 1`` samples so
        that nothing wraps around (what leaves the record is lost). An int: that many
        zeros.

    Returns
    -------
    ndarray, same shape as ``signal``
    """
    x = _real_signal(signal)
    fs = _positive(sampling_rate, "sampling_rate")
    ax = _axis_index(axis, x.ndim)
    d = np.asarray(delay, dtype=float)
    if not np.all(np.isfinite(d)):
        raise InputError("contains NaN or inf", field="delay")
    xm = np.moveaxis(x, ax, -1)
    n = xm.shape[-1]
    try:
        np.broadcast_shapes(d.shape, xm.shape[:-1])
    except ValueError:
        raise InputError(f"shape {d.shape} does not broadcast against the traces' shape "
                         f"{xm.shape[:-1]}", field="delay") from None
    if pad is True:
        extra = math.ceil(float(np.max(np.abs(d))) * fs) + 1 if d.size else 0
    elif pad is False:
        extra = 0
    else:
        extra = int(pad)
        if extra < 0:
            raise InputError("expected a non-negative number of samples", field="pad")
    nf = n + extra
    f = frequency_axis(nf, fs)
    phase = 2 * np.pi * f * d[..., None]
    shift = np.exp(1j * phase)
    if nf % 2 == 0:
        shift[..., -1] = np.cos(phase[..., -1])
    spec = to_frequency(xm.astype(float, copy=False), n=nf, axis=-1) * shift
    out = to_time(spec, nf, axis=-1)[..., :n]
    return np.moveaxis(out, -1, ax)
