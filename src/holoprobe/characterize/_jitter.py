"""Effective scan-positioning noise from the phase residuals of the measured field.

A stage that puts the hydrophone δr away from its nominal position records the field
delayed by ``δt ≈ n̂·δr / c0`` (n̂ the local direction of propagation): the same delay
at every frequency of that trace. The field itself is smooth: its angular spectrum
lies inside ``|κ| < k``. So, per frequency bin, the part of the scan spectrum outside
that disc is noise, and a trace's delay error shows up as a residual ``r ≈ iωδt·P_s``
in quadrature with the smooth field ``P_s`` and proportional to ω, while additive
noise is circular (as much in phase as in quadrature). The estimator fits, per scan
point, ``δt`` to the quadrature part over the band and the same to the in-phase part;
the difference of their variances is the positioning part, corrected for the share
of the jitter's (white) spatial spectrum that the disc keeps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft
from numpy.typing import NDArray

from holoprobe.geometry import PlaneGrid
from holoprobe.signal import Threads, bin_energy, next_fast_length, workers

__all__ = ["PositioningNoise", "positioning_noise"]


@dataclass(frozen=True)
class PositioningNoise:
    """Result of :func:`positioning_noise` (lengths in m).

    Attributes
    ----------
    rms : float
        Effective rms positioning error along the direction of propagation (NaN when
        the scan does not allow an estimate: too fine a step leaves no room outside the
        propagating disc, or too few points with signal).
    uncertainty : float
        Standard uncertainty of ``rms``.
    kept_fraction : float
        Share of a white jitter pattern that the propagating disc keeps (its effect
        cannot be told from the field; corrected for).
    points : int
        Scan points that took part.
    """

    rms: float
    uncertainty: float
    kept_fraction: float
    points: int


def _disc_lowpass(field: NDArray, inside: NDArray[np.bool_], shape: tuple[int, int]
                  ) -> NDArray[np.complex64]:
    """``ifft2(fft2(field, s=shape) · inside)`` cropped to the field's shape, without
    the 1-D transforms whose input is zero (the padding rows; outside the disc) or whose
    output is masked or cropped away: the same 1-D transforms as the full 2-D ones,
    about half of them, in single precision (the smooth field is the reference of the
    residuals, which are ~1e-2 of it and more: its 1e-7 rounding moves the full-size
    P4-1 estimate by 1e-7 σ, for 0.4 s less CPU)."""
    nx, ny = field.shape
    rows = np.flatnonzero(inside.any(axis=1))
    cols = np.flatnonzero(inside.any(axis=0))
    spec = scipy.fft.fft(scipy.fft.fft(field.astype(np.complex64), n=shape[1], axis=1,
                                       workers=1)[:, cols],
                         n=shape[0], axis=0, workers=1, overwrite_x=True)
    masked = np.zeros((rows.size, shape[1]), np.complex64)
    masked[:, cols] = spec[rows] * inside[np.ix_(rows, cols)]
    half = np.zeros((shape[0], ny), np.complex64)
    half[rows] = scipy.fft.ifft(masked, axis=1, workers=1, overwrite_x=True)[:, :ny]
    return scipy.fft.ifft(half, axis=0, workers=1, overwrite_x=True)[:nx]


def positioning_noise(spectrum: NDArray, grid: PlaneGrid, frequencies: NDArray,
                      sound_speed: float, *, energy_fraction: float = 0.5,
                      max_kept_fraction: float = 0.8,
                      model_error: float = 0.1) -> PositioningNoise:
    """Estimate the effective positioning noise of a scan from its spectrum.

    Parameters
    ----------
    spectrum : ndarray, complex, shape (nx, ny, nb)
        Scan spectrum in the signal band (conjugate Fourier convention).
    grid : PlaneGrid
        Scan grid (steps dx, dy).
    frequencies : ndarray, shape (nb,)
        Hz.
    sound_speed : float
        m/s.
    energy_fraction : float
        Use the strongest points that together hold this fraction of the energy.
    max_kept_fraction : float
        No estimate when the propagating disc keeps more than this share of a white
        pattern (the scan step is too fine to separate jitter from the field).
    model_error : float
        Relative model uncertainty added to the statistical one (the delay picture is
        first order and the kept-share correction assumes white jitter).

    Returns
    -------
    PositioningNoise
    """
    nx, ny, nb = spectrum.shape
    omega = 2 * np.pi * np.asarray(frequencies, dtype=float)
    # the cut at the scan's border rings outside the disc: leave a border of two
    # wavelengths (at the energy-weighted centre of the band) out, and zero-pad
    # against wrap-around
    band_energy = bin_energy(spectrum)
    centre = float(np.sum(band_energy * omega) / max(float(np.sum(band_energy)), 1e-300))
    lam = 2 * np.pi * sound_speed / max(centre, 1e-300)
    bx, by = (int(np.ceil(2 * lam / d)) for d in (grid.dx, grid.dy))
    if nx - 2 * bx < 8 or ny - 2 * by < 8 or nb < 2:
        return PositioningNoise(float("nan"), float("nan"), float("nan"), 0)
    # at least twice the scan against wrap-around, rounded up to a fast FFT length (2n
    # of a prime n, e.g. 241, is a Bluestein transform: twice the CPU of 486)
    px, py = next_fast_length(2 * nx), next_fast_length(2 * ny)
    kx = 2 * np.pi * np.fft.fftfreq(px, grid.dx)[:, None]
    ky = 2 * np.pi * np.fft.fftfreq(py, grid.dy)[None, :]
    kappa2 = kx**2 + ky**2
    smooth = np.empty_like(spectrum)
    kept = np.empty(nb)

    def lowpass(first: int, step: int) -> None:  # every step-th bin from first
        for j in range(first, nb, step):
            inside = kappa2 < (omega[j] / sound_speed) ** 2
            kept[j] = inside.mean()
            smooth[:, :, j] = _disc_lowpass(spectrum[:, :, j], inside, (px, py))

    n_threads = min(workers(), nb)  # the bins are independent; the FFTs release the GIL
    with Threads(n_threads) as threads:
        for i in range(n_threads):
            threads.submit(lowpass, i, n_threads)
    energy = np.sum(np.abs(smooth) ** 2, axis=2)
    border = np.ones((nx, ny), bool)
    border[bx:nx - bx, by:ny - by] = False
    energy[border] = 0.0
    order = np.argsort(energy, axis=None)[::-1]
    cum = np.cumsum(energy.ravel()[order])
    use = order[:int(np.searchsorted(cum, energy_fraction * cum[-1])) + 1]
    if use.size < 16:
        return PositioningNoise(float("nan"), float("nan"), float("nan"), int(use.size))
    ps = smooth.reshape(-1, nb)[use]
    r = spectrum.reshape(-1, nb)[use] - ps  # the residual where it is used
    cross = r * np.conj(ps)
    den = np.sum(omega**2 * np.abs(ps) ** 2, axis=1)
    dt_q = np.sum(omega * cross.imag, axis=1) / den  # delay fit to the quadrature part
    dt_i = np.sum(omega * cross.real, axis=1) / den  # the same on the in-phase part
    wk = np.sum(omega**2 * np.abs(ps) ** 2 * kept, axis=1) / den
    k_mean = float(np.mean(wk))
    var = float(np.var(dt_q) - np.var(dt_i)) / max(1.0 - k_mean, 1e-12)
    n = dt_q.size
    # spread of the two variance estimates (χ² with n − 1 degrees of freedom each)
    u_var = np.sqrt(2.0 / max(n - 1, 1)) * float(np.var(dt_q) + np.var(dt_i)) \
        / max(1.0 - k_mean, 1e-12)
    if k_mean > max_kept_fraction:
        return PositioningNoise(float("nan"), float("nan"), k_mean, n)
    rms_t = np.sqrt(max(var, 0.0))
    u_t = u_var / (2 * rms_t) if rms_t > 0 else np.sqrt(u_var)
    # model error of the first-order delay picture and of the kept-share correction:
    # 3.66 µm for 3.96 µm of isotropic jitter on a 24-element twin (tests)
    u_t = float(np.hypot(u_t, model_error * rms_t))
    return PositioningNoise(float(sound_speed * rms_t), float(sound_speed * u_t), k_mean, n)
