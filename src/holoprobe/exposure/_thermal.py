"""Acoustic output power and thermal indices (IEC 62359).

**Power through a plane** (:func:`holoprobe.propagation.plane_power`,
:func:`plane_pulse_energy`): the normal
intensity integrated over a plane, evaluated in the angular-spectrum domain, where it is
exact for the propagating part (evanescent waves carry no power)::

    W = 1/(2 ρ0 c0) · 1/(4π²) ∫∫ |P̂(kx, ky)|² Re(kz / k) dkx dky

(time average of ``p = Re{P e^{−iωt}}``), with the ring-averaged propagator ``Re Ḡ_pv``
(:func:`holoprobe.propagation.spectral_propagator`, d = 0). ``method="plane_wave"`` gives
the IEC plane-wave approximation ``∫∫ |P|² / (2 ρ0 c0) dA`` instead.

**Power leaving a source plane** (:func:`holoprobe.propagation.source_power`,
:func:`source_pulse_energy`): from
the normal velocity ``U`` on z = 0 in a rigid baffle, ``W = (ρ0 c0 / 2) · 1/(4π²) ∫∫ |Û|²
Re(k / kz) dkx dky`` (the integrable singularity at ``|κ| = k`` handled by the ring-averaged
``Ḡ_vp``). For a baffled piston of area A this is the radiation resistance
``ρ0 c0 A [1 − J1(2ka)/(ka)]`` times ``|u|²/2``, → ``ρ0 c0 |u|² A / 2`` for ka ≫ 1.

**Thermal indices** (:func:`thermal_indices`), IEC 62359:2010 + A1:2017 as implemented
here (powers in mW, frequencies in MHz, lengths in cm, intensities in mW/cm² inside the
formulas; α = 0.3 dB/(cm·MHz) derating ``P_α(z) = P · 10^(−α f z/10)``)::

    D_eq = sqrt(4 A_aprt / π),  z_bp = 1.5 D_eq      (A_aprt: −12 dB output beam area)
    TIS  scanning      = P_1 f_awf / C_TIS1
    TIS  non-scanning  = f_awf / C_TIS1 · max_{z ≥ z_bp} min[P_α(z), I_ta,α(z) · 1 cm²]
    TIB  scanning      = TIS scanning
    TIB  non-scanning  = max_{z ≥ z_bp} min[sqrt(P_α(z) I_ta,α(z)) / C_TIB1, P_α(z) / C_TIB2]
    TIC                = P / (D_eq C_TIC)      (scanning: P_1 and the A_aprt of that 1 cm)

with C_TIS1 = 210 mW·MHz, C_TIB1 = 50 mW/cm, C_TIB2 = 4.4 mW, C_TIC = 40 mW/cm. P_1 is
the bounded output power (through a 1 cm wide window of the scanned aperture for scanning
modes). These are the formulas of the 2010 edition with its 2017 amendment as far as they
could be checked here without the standard's text: the constants and the TIS/TIC forms
agree with the FDA/AIUM output display standard they derive from; the depth rule of the
non-scanning TIB (maximum over z ≥ z_bp of the minimum of the two terms) and the scanning
TIC (P_1 with its own aperture) are this module's reading and are not verified against the
standard's text.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.exposure._metrics import DERATING_DB_PER_CM_MHZ, derating_factor
from holoprobe.geometry import Medium, PlaneGrid
from holoprobe.propagation import plane_power, source_power
from holoprobe.signal import frequency_axis, to_frequency

__all__ = [
    "C_TIB1_MW_PER_CM",
    "C_TIB2_MW",
    "C_TIC_MW_PER_CM",
    "C_TIS1_MW_MHZ",
    "ThermalIndices",
    "beam_area",
    "plane_pulse_energy",
    "source_pulse_energy",
    "thermal_indices",
]

C_TIS1_MW_MHZ = 210.0
C_TIB1_MW_PER_CM = 50.0
C_TIB2_MW = 4.4
C_TIC_MW_PER_CM = 40.0
_MW = 1e3
_CM = 1e2
_MHZ = 1e-6


# --------------------------------------------------------------------------- power
def _check_plane(field: ArrayLike, grid: PlaneGrid, name: str) -> NDArray:
    arr = np.asarray(field)
    if not isinstance(grid, PlaneGrid):
        raise InputError("expected a PlaneGrid", field="grid")
    if arr.ndim != 3 or arr.shape[:2] != grid.shape:
        raise InputError(f"expected shape {grid.shape} + (n,), got {arr.shape}", field=name)
    if not np.all(np.isfinite(arr)):
        raise InputError("contains NaN or inf", field=name)
    return arr


def _pulse_energy(spectra: NDArray, grid: PlaneGrid, frequencies: NDArray, df: float,
                  power_fn) -> float:
    """``∫ dt ∫∫ I dA = 4 Σ_f W(P_f) Δf`` for continuous-time spectra P_f (units·s)."""
    total = 0.0
    for j, f in enumerate(frequencies):
        if f > 0:
            total += 4.0 * df * power_fn(spectra[..., j], grid, float(f))
    return total


def plane_pulse_energy(pressure: ArrayLike, grid: PlaneGrid, sampling_rate: float,
                       medium: Medium | None = None, *, method: str = "angular_spectrum",
                       padding: float = 2.0, band: tuple[float, float] | None = None
                       ) -> float:
    """Acoustic energy (J) of one pulse through a plane: ``∫ dt ∫∫ I_z dA``.

    Parameters
    ----------
    pressure : array_like, real, shape (nx, ny, nt)
        Waveforms on ``grid`` in Pa, time last (the whole pulse in every record).
    grid : PlaneGrid
        Uniform grid (steps ≤ λ/2 at the highest frequency).
    sampling_rate : float
        Hz.
    medium : Medium, optional
        ρ0, c0.
    method, padding
        See :func:`plane_power`.
    band : (float, float), optional
        Only frequencies in this band (Hz) are summed (default all but DC).

    Returns
    -------
    float
        J per pulse; times the PRF is the acoustic output power.
    """
    p = _check_plane(pressure, grid, "pressure")
    nt = p.shape[-1]
    fs = float(sampling_rate)
    spectra = to_frequency(np.asarray(p, float), axis=-1) / fs
    f = frequency_axis(nt, fs)
    keep = np.ones(f.size, bool) if band is None else (f >= band[0]) & (f <= band[1])
    med = Medium() if medium is None else medium

    def power(field, g, freq):
        return plane_power(field, g, freq, med, method=method, padding=padding)

    weights = np.ones(f.size)
    if nt % 2 == 0:
        weights[-1] = 0.5  # the Nyquist bin is its own mirror image
    return _pulse_energy(spectra[..., keep] * np.sqrt(weights[keep]), grid, f[keep],
                         fs / nt, power)


def source_pulse_energy(velocity_spectra: ArrayLike, grid: PlaneGrid, frequencies: ArrayLike,
                        medium: Medium | None = None, *, padding: float = 2.0) -> float:
    """Energy (J) of one pulse leaving a baffled source plane, from continuous-time
    velocity spectra ``(nx, ny, nf)`` in m/s·s on uniformly spaced positive frequencies
    (holoprobe's convention; e.g. :func:`holoprobe.transducer.surface_velocity` binned
    onto a grid)."""
    u = _check_plane(velocity_spectra, grid, "velocity_spectra")
    f = np.asarray(frequencies, float).reshape(-1)
    if f.size != u.shape[-1] or f.size < 2 or np.any(np.diff(f) <= 0):
        raise InputError("expected increasing, uniformly spaced frequencies, one per "
                         "spectrum", field="frequencies")
    med = Medium() if medium is None else medium

    def power(field, g, freq):
        return source_power(field, g, freq, med, padding=padding)

    return _pulse_energy(u, grid, f, float(f[1] - f[0]), power)


def beam_area(intensity: ArrayLike, cell_area: float, *, level_db: float = -12.0) -> float:
    """Area (m²) where a (temporal-average) intensity map is within ``level_db`` of its
    maximum (IEC 62359's −12 dB output beam area ``A_aprt`` at the transducer face)."""
    i = np.asarray(intensity, float)
    if i.size == 0 or not np.any(i > 0):
        raise InputError("expected a non-zero intensity map", field="intensity")
    return float(np.count_nonzero(i >= i.max() * 10 ** (level_db / 10)) * cell_area)


# --------------------------------------------------------------------------- indices
@dataclass(frozen=True)
class ThermalIndices:
    """TIS, TIB, TIC (IEC 62359) and the quantities they come from (SI units)."""

    mode: str
    tis: float
    tib: float
    tic: float
    power: float
    power_1cm: float
    acoustic_working_frequency: float
    aperture_area: float
    equivalent_diameter: float
    breakpoint_depth: float
    depth_tis: float
    depth_tib: float
    attenuation_db_cm_mhz: float

    def to_dict(self) -> dict[str, float | str | None]:
        """JSON-ready dict (keys as the attributes, SI units; None for a non-finite value)."""
        return {k: (v if isinstance(v, str) or math.isfinite(v) else None)
                for k, v in asdict(self).items()}


def thermal_indices(*, power: float, frequency: float, depths: ArrayLike,
                    intensity_ta: ArrayLike, aperture_area: float,
                    mode: str = "non-scanning", power_1cm: float | None = None,
                    aperture_area_1cm: float | None = None,
                    attenuation_db_cm_mhz: float = DERATING_DB_PER_CM_MHZ
                    ) -> ThermalIndices:
    """TIS, TIB and TIC (formulas in the module notes).

    Parameters
    ----------
    power : float
        Acoustic output power P in W.
    frequency : float
        Acoustic-working frequency f_awf in Hz.
    depths : array_like, shape (nz,)
        Depths z along the beam axis in m (increasing).
    intensity_ta : array_like, shape (nz,)
        Temporal-average intensity I_ta(z) on the beam axis in W/m², in water (derated
        here).
    aperture_area : float
        −12 dB output beam area A_aprt in m².
    mode : {"non-scanning", "scanning"}
        The operating mode.
    power_1cm : float, optional
        Bounded output power P_1 in W (scanning: through the 1 cm wide window of the
        scanned aperture; default P).
    aperture_area_1cm : float, optional
        A_aprt of that 1 cm window for the scanning TIC (default ``aperture_area``).
    attenuation_db_cm_mhz : float
        Derating coefficient.

    Returns
    -------
    ThermalIndices
    """
    if mode not in ("non-scanning", "scanning"):
        raise InputError(f"expected 'non-scanning' or 'scanning', got {mode!r}", field="mode")
    z = np.asarray(depths, float).reshape(-1)
    ita = np.asarray(intensity_ta, float).reshape(-1)
    if z.size != ita.size or z.size == 0 or np.any(np.diff(z) <= 0):
        raise InputError("expected increasing depths, one intensity each", field="depths")
    for name, value in (("power", power), ("frequency", frequency),
                        ("aperture_area", aperture_area)):
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"expected a positive number, got {value!r}", field=name)
    p1 = power if power_1cm is None else float(power_1cm)
    f_mhz = frequency * _MHZ
    d_eq = math.sqrt(4 * aperture_area / math.pi)
    z_bp = 1.5 * d_eq
    factor = derating_factor(frequency, z, attenuation_db_cm_mhz=attenuation_db_cm_mhz,
                             quantity="intensity")
    p_a = power * _MW * factor                          # mW
    i_a = ita * factor * _MW / _CM**2                   # mW/cm²
    deep = z >= z_bp
    if not np.any(deep):
        raise InputError(f"the depths (up to {z[-1]:.4g} m) do not reach the break-point "
                         f"depth {z_bp:.4g} m", field="depths")
    tis_z = np.minimum(p_a, i_a * 1.0) * f_mhz / C_TIS1_MW_MHZ
    tib_z = np.minimum(np.sqrt(p_a * i_a) / C_TIB1_MW_PER_CM, p_a / C_TIB2_MW)
    k_tis = int(np.argmax(np.where(deep, tis_z, -np.inf)))
    k_tib = int(np.argmax(np.where(deep, tib_z, -np.inf)))
    if mode == "scanning":
        tis = tib = p1 * _MW * f_mhz / C_TIS1_MW_MHZ
        area_1 = aperture_area if aperture_area_1cm is None else float(aperture_area_1cm)
        tic = p1 * _MW / (math.sqrt(4 * area_1 / math.pi) * _CM * C_TIC_MW_PER_CM)
        depth_tis = depth_tib = 0.0
    else:
        tis, tib = float(tis_z[k_tis]), float(tib_z[k_tib])
        tic = power * _MW / (d_eq * _CM * C_TIC_MW_PER_CM)
        depth_tis, depth_tib = float(z[k_tis]), float(z[k_tib])
    return ThermalIndices(mode=mode, tis=float(tis), tib=float(tib), tic=float(tic),
                          power=float(power), power_1cm=float(p1),
                          acoustic_working_frequency=float(frequency),
                          aperture_area=float(aperture_area), equivalent_diameter=d_eq,
                          breakpoint_depth=z_bp, depth_tis=depth_tis, depth_tib=depth_tib,
                          attenuation_db_cm_mhz=float(attenuation_db_cm_mhz))
