"""RF of the virtual transducer for point scatterers (linear, single scattering).

For scatterers at r_s with scattering amplitudes a_s (m) the received voltage of
element e is, per frequency (holoprobe's conjugate convention, paper eq.
complex-conjugate-fourier)::

    P_inc(r_s)   = Σ_j a_j^tx E_T(ω) e^{iωτ_j} G(r_s − x_j)              (transmit)
    p_scat(r)    = a_s P_inc(r_s) e^{ik|r − r_s|} / |r − r_s|              (re-radiation)
    P_R,e        = (1/A_e) ∫_e e^{iωτ_L(v)} p_scat dA
                 = Σ_s a_s P_inc(r_s) G(r_s − x_e) · 2π / (−ikρ0c0 A_e)     (reciprocity)
    E_R,e(ω)     = s_e e^{iωδ_e} H_R(ω) P_R,e                               (receive IR)

with G the field of one element with its lens per unit velocity
(:func:`holoprobe.transducer.element_field`, paper eqs. rayleigh-fwd-vp and
lens-delays): by reciprocity the element's receive spatial response (the lens
delays e^{+iωτ_L}, then the average over the element face) is its transmit
response. H_R is the receive impulse response (paper eq.
receive-impulse-response, ``E_R = h_R ⊛ p_R``), s_e and δ_e the element
sensitivity and receive delay when the model has them.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.signal import continuous_spectrum, to_time
from holoprobe.transducer._field import (
    _arrival_bounds,
    _assemble,
    drive_spectrum,
    element_field,
    element_offsets,
    record_band,
    signal_band,
)
from holoprobe.transducer._model import VirtualTransducer
from holoprobe.transducer._transmit import TransmitSetting

__all__ = ["rf_units", "simulate_rf"]


def rf_units(vt: VirtualTransducer) -> str:
    """Unit of the simulated RF: that of h_R times Pa·s (``"ADCL"`` or ``"V"``)."""
    return vt.receive_units.split("/")[0]


def simulate_rf(
    vt: VirtualTransducer,
    setting: TransmitSetting,
    scatterers: ArrayLike,
    amplitudes: ArrayLike,
    *,
    sampling_rate: float | None = None,
    n_samples: int | None = None,
    band_threshold_db: float = -40.0,
    oversampling: float = 8.0,
    points_per_wavelength: float = 4.0,
    guard_time: float = 1e-6,
    dtype: type = np.float64,
    offset_tolerance: float = 1e-9,
    progress: Callable[[int, int], None] | None = None,
) -> NDArray[np.floating]:
    """Per-element received RF for point scatterers (linear, single scattering).

    See the module notes for the model (transmit field at each scatterer,
    spherical re-radiation, reception through each element with its lens by
    reciprocity, receive impulse response: paper eq. receive-impulse-response).

    Parameters
    ----------
    vt : VirtualTransducer
        The model; it needs a receive impulse response.
    setting : TransmitSetting
        Transmit delays, apodization and drive (every element receives).
    scatterers : array_like, shape (n, 3)
        Scatterer positions in m (transducer coordinates, z > 0).
    amplitudes : array_like, shape (n,)
        Scattering amplitudes a_s in m: the scattered pressure is
        ``a_s p_inc(r_s) e^{ikR}/R`` at distance R.
    sampling_rate : float, optional
        Output rate in Hz (default ``oversampling`` × the top of the band).
    n_samples : int, optional
        Record length (default: the latest echo, plus the IR durations and
        ``guard_time``, fits). Sample n is at t = n / fs, t = 0 when the drive of
        an undelayed element starts. The record is periodic: later echoes wrap.
    band_threshold_db : float
        Band selection of ``|H_T E_T|²`` in dB (negative); other bins are zero.
    oversampling : float
        Default rate relative to the top of the band.
    points_per_wavelength : float
        Sub-element sampling (see :func:`holoprobe.transducer.surface_velocity`).
    guard_time : float
        Margin in s after the latest echo.
    dtype : {numpy.float64, numpy.float32}
        Precision of the Rayleigh kernel and of the result.
    offset_tolerance : float
        Scatterer–element offsets closer than this (m) are merged.
    progress : callable(done, total), optional
        Called as the element responses are computed.

    Returns
    -------
    ndarray, shape (n_elements, n_samples)
        Received signal of each element in the unit of the receive IR times
        Pa·s (:func:`rf_units`: ADC levels or V).

    Raises
    ------
    InputError
        No receive impulse response, bad scatterers or amplitudes.
    """
    if not isinstance(vt, VirtualTransducer):
        raise InputError("expected a VirtualTransducer", field="vt")
    if not vt.has_receive:
        raise InputError("the virtual transducer has no receive impulse response; RF needs "
                         "one (characterize with an echo recording)",
                         field="receive_impulse_response")
    h_rx, fs_rx = vt.receive_impulse_response, vt.receive_sampling_rate
    assert h_rx is not None and fs_rx is not None  # has_receive
    if not isinstance(setting, TransmitSetting):
        raise InputError("expected a TransmitSetting", field="setting")
    try:
        pos = np.asarray(scatterers, dtype=float)
        amp = np.asarray(amplitudes, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError("expected numbers", field="scatterers") from None
    if pos.ndim == 1 and pos.size == 3:
        pos = pos[None, :]
    if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] == 0:
        raise InputError(f"expected positions of shape (n, 3) in m, got {pos.shape}",
                         field="scatterers")
    if not np.all(np.isfinite(pos)) or np.any(pos[:, 2] <= 0):
        raise InputError("expected finite positions in front of the probe (z > 0)",
                         field="scatterers")
    if amp.shape != (pos.shape[0],) or not np.all(np.isfinite(amp)):
        raise InputError(f"expected {pos.shape[0]} finite amplitudes (m)", field="amplitudes")
    real = np.dtype(dtype)
    if real not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise InputError(f"expected numpy.float32 or numpy.float64, got {dtype!r}",
                         field="dtype")
    c0 = vt.medium.sound_speed
    f_lo, f_hi = signal_band(vt, setting, threshold_db=band_threshold_db)
    fs = float(sampling_rate) if sampling_rate is not None else oversampling * f_hi
    if not (math.isfinite(fs) and fs > 2 * f_hi):
        raise InputError(f"expected a sampling rate above twice the top of the band "
                         f"({2 * f_hi:g} Hz), got {fs!r}", field="sampling_rate")
    n_el = vt.element_count
    apod, tau = vt.transmit_weights(setting)  # with the model's transmit element map
    everyone = np.arange(n_el)
    if n_samples is None:
        _, t_tx = _arrival_bounds(vt, pos, everyone, tau, True)
        _, t_rx = _arrival_bounds(vt, pos, everyone, np.zeros(n_el), True)
        t_end = (float(np.max(t_tx + t_rx)) + setting.drive.duration + guard_time
                 + vt.transmit_impulse_response.size / vt.transmit_sampling_rate
                 + h_rx.size / fs_rx)
    else:
        t_end = 0.0
    n, band, fb = record_band(t_end, fs, f_lo, f_hi, n_samples)
    offsets, index = element_offsets(vt, pos, everyone, tolerance=offset_tolerance)
    g = element_field(vt, offsets, fb, points_per_wavelength=points_per_wavelength,
                      dtype=real.type, progress=progress)
    cdt = g.dtype
    # transmit: incident pressure at each scatterer (n_s, nf)
    w_tx = (apod[:, None] * drive_spectrum(vt, setting, fb)[None, :]
            * np.exp((2j * np.pi) * tau[:, None] * fb[None, :]))
    p_inc = np.empty((pos.shape[0], fb.size), dtype=cdt)
    _assemble(g, index, w_tx.astype(cdt), p_inc)
    # receive: element-averaged, lens-applied pressure (n_el, nf)
    p_rx = np.empty((n_el, fb.size), dtype=cdt)
    _assemble(g, np.ascontiguousarray(index.T), (amp[:, None] * p_inc).astype(cdt), p_rx)
    k = 2 * np.pi * fb / c0
    area = vt.element_width * vt.element_height
    factor = 2 * np.pi / (-1j * k * vt.medium.impedance * area)
    h_r = continuous_spectrum(h_rx, fs_rx, fb)
    spec = p_rx * (factor * h_r)[None, :]
    if vt.element_sensitivity is not None:
        spec = spec * vt.element_sensitivity[:, None]
    if vt.element_delay is not None:
        spec = spec * np.exp((2j * np.pi) * vt.element_delay[:, None] * fb[None, :])
    full = np.zeros((n_el, (n // 2 + 1)), dtype=complex)
    full[:, band] = spec * fs
    return to_time(full, n, axis=-1).astype(real, copy=False)
