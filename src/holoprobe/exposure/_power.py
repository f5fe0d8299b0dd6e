"""Acoustic output power of a virtual transducer for a transmit setting (IEC 62359).

Two independent evaluations, compared in :class:`OutputPower`:

* **plane**: the field predicted by :func:`holoprobe.transducer.predict_field` on a plane
  parallel to the array at ``depth`` (time-domain records), its pulse energy through the
  plane by :func:`plane_pulse_energy` (exact normal intensity of the propagating waves);
* **source**: the normal velocity of the virtual transducer's surface
  (:func:`holoprobe.transducer.surface_velocity`, binned onto a grid of λ/4 cells) and the
  power it radiates into the half-space (:func:`source_pulse_energy`).

The output power is the pulse energy times the pulse repetition frequency (one transmit per
period). The −12 dB output beam area ``A_aprt`` comes from the same velocity grid
(intensity ∝ Σ_f |U_f|² at the face).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from holoprobe.errors import InputError
from holoprobe.exposure._thermal import beam_area, plane_pulse_energy, source_pulse_energy
from holoprobe.geometry import PlaneGrid, Pose

__all__ = ["OutputPower", "acoustic_output_power", "velocity_grid"]


@dataclass(frozen=True)
class OutputPower:
    """Pulse energies (J), powers (W) and the output beam area of one transmit setting.

    ``power_plane`` is the reported acoustic output power; ``power_source`` the cross-check;
    ``relative_difference = power_plane / power_source − 1``.
    """

    energy_plane: float
    energy_source: float
    power_plane: float | None
    power_source: float | None
    relative_difference: float
    aperture_area: float
    depth: float
    prf: float | None

    def to_dict(self) -> dict[str, float | None]:
        """JSON-ready dict (SI units)."""
        return {k: (None if v is None or not math.isfinite(v) else float(v))
                for k, v in asdict(self).items()}


def velocity_grid(vt: Any, setting: Any, frequencies: NDArray, step: float, margin: float,
                  *, chunk: int = 16) -> tuple[PlaneGrid, NDArray[np.complex128]]:
    """The surface velocity spectra averaged onto square cells of side ``step`` (m) on the
    plane z = 0, the grid extending ``margin`` (m) beyond the aperture.

    The velocity is sampled at sub-element points no farther apart than ``step / 2``
    (:func:`holoprobe.transducer.surface_velocity`), ``chunk`` frequencies at a time.

    Returns
    -------
    grid : PlaneGrid
        Cell centres.
    velocity : ndarray, complex, shape (nx, ny, nf)
        m/s·s (continuous-time spectra, holoprobe's convention).
    """
    from holoprobe.transducer import surface_velocity

    f = np.asarray(frequencies, float)
    out = None
    for s in range(0, f.size, chunk):
        part = f[s:s + chunk]
        # the same sub-element points for every chunk: λ(max of the chunk) / ppw = step / 2
        ppw = 2 * vt.medium.sound_speed / float(part.max()) / step
        surface, velocity = surface_velocity(vt, setting, part, points_per_wavelength=ppw)
        if out is None:
            pts = surface.points
            lo = pts[:, :2].min(axis=0) - margin
            n = np.ceil((pts[:, :2].max(axis=0) + margin - lo) / step).astype(int) + 1
            gx, gy = lo[0] + np.arange(n[0]) * step, lo[1] + np.arange(n[1]) * step
            cell = (np.rint((pts[:, 0] - gx[0]) / step).astype(int) * n[1]
                    + np.rint((pts[:, 1] - gy[0]) / step).astype(int))
            out = np.zeros((n[0] * n[1], f.size), complex)
        np.add.at(out[:, s:s + chunk], cell, velocity * (surface.weights / step**2)[:, None])
    if out is None:
        raise InputError("expected at least one frequency", field="frequencies")
    return PlaneGrid(gx, gy), out.reshape(n[0], n[1], f.size)


def acoustic_output_power(vt: Any, setting: Any, *, depth: float = 2e-3,
                          prf: float | None = None, band_threshold_db: float = -40.0,
                          points_per_wavelength: float = 2.2, margin: float | None = None,
                          source_points_per_wavelength: float = 4.0) -> OutputPower:
    """Acoustic output power of a transmit setting from the predicted field on a plane,
    cross-checked with the power leaving the virtual transducer's surface.

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    setting : TransmitSetting
        Delays, apodization, drive (its ``prf`` is the default PRF).
    depth : float
        Distance of the integration plane from the array face in m.
    prf : float, optional
        Pulse repetition frequency in Hz (default the setting's; None: energies only).
    band_threshold_db : float
        Band of the computation (:func:`holoprobe.transducer.signal_band`).
    points_per_wavelength : float
        Plane sampling at the highest frequency (≥ 2 resolves every propagating wave).
    margin : float, optional
        Extent of the plane beyond the aperture in m (default ``3 depth + 5 λ``: every
        direction up to 72° from the normal leaves through the plane).
    source_points_per_wavelength : float
        Source sampling of the field prediction (``predict_field``'s
        ``points_per_wavelength``). With 4 (default) the plane power was −0.47 % off the
        source power on a 16-element P4-1 (38 s) and −0.14 % on an 8-element piston-like
        array; 2 halves the time but gave +0.55 % and −2.3 % (plane 1 mm away).

    Returns
    -------
    OutputPower
    """
    from holoprobe.transducer import predict_field, signal_band

    if not (math.isfinite(depth) and depth > 0):
        raise InputError(f"expected a positive depth in m, got {depth!r}", field="depth")
    if getattr(vt, "is_curved", False):
        raise InputError("the output power is integrated over a plane parallel to a flat "
                         "face (and cross-checked on it); this model's elements face "
                         "different ways (convex): not implemented", field="vt")
    if points_per_wavelength < 2:
        raise InputError("expected at least 2 points per wavelength", field="points_per_wavelength")
    f_lo, f_hi = signal_band(vt, setting, threshold_db=band_threshold_db)
    c0 = vt.medium.sound_speed
    lam = c0 / f_hi
    extra = 3 * depth + 5 * lam if margin is None else float(margin)
    # source: velocity spectra on a uniform frequency grid; Σ |U(k Δf)|² Δf is the exact
    # energy (Parseval) when the velocity lasts less than 1/Δf (IR + drive + delays + lens)
    delays = setting.element_delays(vt.element_centers(), c0)
    lens = (0.5 * vt.element_height) ** 2 / (2 * vt.lens_focus * c0)  # 0 without a lens
    span = (vt.transmit_impulse_response.size / vt.transmit_sampling_rate
            + setting.drive.duration + float(np.ptp(delays)) + lens)
    df = min(0.9 / span, (f_hi - f_lo) / 16)
    freqs = np.arange(max(f_lo, df), f_hi + 0.5 * df, df)
    grid_s, u = velocity_grid(vt, setting, freqs, lam / 4, 2 * lam)
    energy_source = source_pulse_energy(u, grid_s, freqs, vt.medium)
    area = beam_area(np.sum(np.abs(u) ** 2, axis=-1), grid_s.dx * grid_s.dy, level_db=-12.0)
    # plane: the predicted field at z = depth, sampled at λ/points_per_wavelength
    step = lam / points_per_wavelength
    centers = vt.element_centers()
    hw = 0.5 * (np.ptp(centers[:, 0]) + vt.element_width) + extra
    hh = 0.5 * vt.element_height + extra
    x = centers[:, 0].mean() + np.arange(-hw, hw + step, step)
    y = vt.aperture_center[1] + np.arange(-hh, hh + step, step)
    plane = PlaneGrid(x, y, pose=Pose(origin=(0.0, 0.0, depth)))
    fs = 8.0 * f_hi
    pred = predict_field(vt, setting, plane, sampling_rate=fs, method="angular_spectrum",
                         band_threshold_db=band_threshold_db,
                         points_per_wavelength=source_points_per_wavelength)
    p = pred.pressure.reshape(x.size, y.size, -1)
    energy_plane = plane_pulse_energy(p, PlaneGrid(x, y), pred.sampling_rate, vt.medium,
                                      band=(f_lo, f_hi))
    rate = getattr(setting, "prf", None) if prf is None else prf
    return OutputPower(
        energy_plane=energy_plane, energy_source=energy_source,
        power_plane=None if rate is None else energy_plane * rate,
        power_source=None if rate is None else energy_source * rate,
        relative_difference=energy_plane / energy_source - 1.0, aperture_area=area,
        depth=float(depth), prf=rate)
