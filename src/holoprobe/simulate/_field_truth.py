"""The twin's true field for any transmit: dense Rayleigh synthesis from its fine source.

The digital twin (:class:`~holoprobe.simulate.ArrayModel`) carries its own drive voltage,
per-element apodization and per-element delays. :func:`simulate_field` radiates that
transmit to arbitrary points with the same source model as the simulated hydrophone scan
(:func:`~holoprobe.simulate.source_groups`: the true impulse response, the exact lens of
paper eq. lens-delays, kerfs, the optional edge mode, a midpoint quadrature at
≤ λ/``points_per_wavelength``) and the dense frequency-domain Rayleigh integral (paper
eq. rayleigh-fwd-vp, rigid baffle) of :func:`~holoprobe.simulate.synthesize_pressure`.
It is the reference a virtual transducer's prediction (``holoprobe.transducer``) is
checked against: nothing in it comes from a characterization.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.geometry import Medium, Surface
from holoprobe.signal import next_fast_length
from holoprobe.simulate._array import ArrayModel
from holoprobe.simulate._scan import _source_time_extent, distance_bounds, synthesize_pressure
from holoprobe.simulate._spectra import signal_band

__all__ = ["simulate_field"]


def simulate_field(
    model: ArrayModel,
    points: ArrayLike,
    *,
    medium: Medium | None = None,
    sampling_rate: float | None = None,
    start_time: float | None = None,
    n_samples: int | None = None,
    band: tuple[float, float] | None = None,
    band_threshold_db: float = -50.0,
    points_per_wavelength: float = 4.0,
    guard_time: float = 0.5e-6,
    group_size: int = 8,
    dtype: type = np.float64,
) -> tuple[NDArray[np.float64], NDArray[np.floating]]:
    """True pressure time series of the twin at arbitrary points for its own transmit.

    The transmit is the model's ``drive``, ``apodization`` and ``delays`` (set them with
    :meth:`ArrayModel.replace`; element e sits at ``x_e`` of
    :meth:`ArrayModel.element_centers` and is driven by ``E_T(t − τ_e)``). The surface
    velocity ``a_e (h_T ⊛ E_T)(t − τ_e − τ_L(y)) / (ρ0 c0)`` (paper eqs.
    transmit-impulse-response and lens-delays, exact lens) is sampled by the model's
    midpoint quadrature and propagated by the dense Rayleigh integral (paper eq.
    rayleigh-fwd-vp, rigid baffle), each group of ``group_size`` points on the short
    record window that holds its signal.

    Parameters
    ----------
    model : ArrayModel
        The twin, with the transmit to radiate.
    points : array_like, shape (n, 3)
        Target points in m (z > 0).
    medium : Medium, optional
        Default water (998 kg/m³, 1481 m/s).
    sampling_rate : float, optional
        Output rate in Hz (default: the impulse-response rate of the model).
    start_time : float, optional
        Time of output sample 0 after the transmit event in s (default: the earliest
        possible arrival at any point minus ``guard_time``).
    n_samples : int, optional
        Output length (default: up to the latest possible end of the signal at any
        point plus ``guard_time``).
    band : (float, float), optional
        Synthesised band in Hz (default: where the surface-velocity spectrum is within
        ``band_threshold_db`` of its peak, :func:`~holoprobe.simulate.signal_band`).
    band_threshold_db : float
        Amplitude level in dB (negative) that delimits the default band.
    points_per_wavelength : float
        Source quadrature steps ≤ λ_min / this.
    guard_time : float
        Margin in s around the arrivals.
    group_size : int
        Target points per Rayleigh call (consecutive points share a record window:
        give nearby points in order).
    dtype : numpy.float64 or numpy.float32
        Precision of the Rayleigh sums and of the output.

    Returns
    -------
    time : ndarray, shape (nt,)
        Sample times in s after the transmit event.
    pressure : ndarray, shape (n, nt)
        Pressure in Pa.

    Raises
    ------
    InputError
        Points not of shape (n, 3), not finite or not in front of the array (z ≤ 0);
        a non-positive rate, guard or group size.
    """
    if not isinstance(model, ArrayModel):
        raise InputError("expected a holoprobe.simulate.ArrayModel", field="model")
    try:
        pts = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise InputError("expected points of shape (n, 3) in m", field="points") from None
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < 1:
        raise InputError(f"expected points of shape (n, 3) in m, got {pts.shape}",
                         field="points")
    if not np.all(np.isfinite(pts)) or np.any(pts[:, 2] <= 0):
        raise InputError("expected finite points in front of the array (z > 0)",
                         field="points")
    medium = medium or Medium()
    fs = float(model.ir_sampling_rate if sampling_rate is None else sampling_rate)
    if not (math.isfinite(fs) and fs > 0):
        raise InputError(f"expected a positive rate in Hz, got {sampling_rate!r}",
                         field="sampling_rate")
    if not (math.isfinite(guard_time) and guard_time >= 0):
        raise InputError(f"expected a margin ≥ 0 s, got {guard_time!r}", field="guard_time")
    if int(group_size) < 1:
        raise InputError(f"expected a positive number of points, got {group_size!r}",
                         field="group_size")
    if not points_per_wavelength > 0:
        raise InputError("expected a positive number", field="points_per_wavelength")
    if band is None:
        band = signal_band(model, medium, threshold_db=band_threshold_db)
    band = (float(band[0]), min(float(band[1]), 0.5 * fs))
    if not 0 < band[0] < band[1]:
        raise InputError(f"expected 0 < f_lo < f_hi ≤ fs/2, got {band}", field="band")
    c0 = medium.sound_speed
    sampling = model.sample_surface(c0 / band[1] / points_per_wavelength)
    near, far = distance_bounds(pts, sampling)
    t_src0, t_src1 = _source_time_extent(model, sampling, medium)
    t0 = (t_src0 + float(near.min()) / c0 - guard_time if start_time is None
          else float(start_time))
    if n_samples is None:
        t_end = t_src1 + float(far.max()) / c0 + guard_time
        n_samples = next_fast_length(max(2, math.ceil((t_end - t0) * fs)))
    n_samples = int(n_samples)
    if n_samples < 2:
        raise InputError(f"expected at least 2 samples, got {n_samples}", field="n_samples")
    targets = Surface(pts, np.broadcast_to([0.0, 0.0, 1.0], pts.shape), np.ones(len(pts)))
    step = int(group_size)
    groups = [np.arange(i, min(i + step, len(pts))) for i in range(0, len(pts), step)]
    pressure = synthesize_pressure(model, sampling, targets, sampling_rate=fs,
                                   n_samples=n_samples, start_time=t0, band=band,
                                   medium=medium, calibration=None, dtype=dtype,
                                   groups=groups, description="true field")
    return t0 + np.arange(n_samples) / fs, pressure
