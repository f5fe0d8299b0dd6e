"""Pulse parameters of one deconvolved hydrophone record, with their uncertainties.

p_c, p_r, PII, pulse duration and f_awf (IEC 62127-1) of a
:class:`holoprobe.signal.DeconvolvedPressure`, computed with the functions of
:mod:`holoprobe.exposure` (one definition each). PII and the running integral of the
pulse duration are corrected for the noise bias (the expected ``Σ u_noise²`` that noise
adds to ``Σ p²``). Standard uncertainties (k = 1) come from Monte Carlo draws
(GUM Supplement 1, :meth:`DeconvolvedPressure.draws`): the quantities are non-linear
(maxima, crossing times, −3 dB points), where linear propagation does not hold.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from holoprobe.exposure._metrics import (
    acoustic_working_frequency,
    peak_pressures,
    pulse_duration,
    pulse_intensity_integral,
)
from holoprobe.geometry import Medium
from holoprobe.signal import DeconvolvedPressure, deconvolve_hydrophone

__all__ = ["PULSE_KEYS", "HydrophonePulse", "PulseParameters", "hydrophone_pulse",
           "pulse_parameters"]

PULSE_KEYS = ("p_c_Pa", "p_r_Pa", "pii_J_per_m2", "pulse_duration_s", "f_awf_Hz")
"""Keys of ``pulse.json``; each has an uncertainty ``u_<key>`` (standard, k = 1)."""


@dataclass(frozen=True)
class PulseParameters:
    """IEC 62127-1 pulse parameters and their standard uncertainties (k = 1).

    ``values`` and ``uncertainties`` are keyed by :data:`PULSE_KEYS` (SI units in the
    key names); ``n_draws`` Monte Carlo draws gave the uncertainties.
    """

    values: dict[str, float]
    uncertainties: dict[str, float]
    n_draws: int

    def to_dict(self) -> dict[str, float | int]:
        """``{key: value, "u_" + key: uncertainty, ..., "n_draws": n}``."""
        out: dict[str, float | int] = {}
        for key in PULSE_KEYS:
            out[key] = float(self.values[key])
            out["u_" + key] = float(self.uncertainties[key])
        out["n_draws"] = int(self.n_draws)
        return out


def _parameters(pressure: np.ndarray, fs: float, medium: Medium,
                noise_variance: np.ndarray) -> dict[str, np.ndarray]:
    p_c, p_r = peak_pressures(pressure)
    return {
        "p_c_Pa": p_c,
        "p_r_Pa": p_r,
        "pii_J_per_m2": pulse_intensity_integral(pressure, fs, medium,
                                                 noise_variance=noise_variance),
        "pulse_duration_s": pulse_duration(pressure, fs, noise_variance=noise_variance),
        "f_awf_Hz": acoustic_working_frequency(pressure, fs),
    }


def pulse_parameters(pulse: DeconvolvedPressure, medium: Medium | None = None, *,
                     n_draws: int = 200, seed: int | None = 0) -> PulseParameters:
    """p_c, p_r, PII, PD, f_awf of a deconvolved pulse and their uncertainties.

    Parameters
    ----------
    pulse : DeconvolvedPressure
        From :func:`holoprobe.signal.deconvolve_hydrophone`.
    medium : Medium, optional
        ρ0 c0 for the PII (default water).
    n_draws : int
        Monte Carlo draws (≥ 20).
    seed : int, optional
        Random seed (reproducible by default).

    Returns
    -------
    PulseParameters
    """
    med = Medium() if medium is None else medium
    fs = pulse.sampling_rate
    nv = pulse.u_pressure_noise ** 2
    best = _parameters(pulse.pressure, fs, med, nv)
    draws = _parameters(pulse.draws(max(20, int(n_draws)), seed=seed), fs, med, nv)
    values = {k: float(best[k]) for k in PULSE_KEYS}
    unc = {k: float(np.nanstd(draws[k], ddof=1)) for k in PULSE_KEYS}
    return PulseParameters(values=values, uncertainties=unc, n_draws=max(20, int(n_draws)))


@dataclass(frozen=True)
class HydrophonePulse:
    """A deconvolved record and its pulse parameters (what ``holoprobe hydrophone
    deconvolve`` writes)."""

    pressure: DeconvolvedPressure
    parameters: PulseParameters

    def to_dict(self) -> dict[str, object]:
        """The content of ``pulse.json``: :meth:`PulseParameters.to_dict` plus the
        deconvolution settings (cut-off, offset, noise, calibration name)."""
        p = self.pressure
        out: dict[str, object] = dict(self.parameters.to_dict())
        out.update({
            "uncertainty": "standard uncertainties u_* (k = 1), Monte Carlo (GUM S1)",
            "cutoff_hz": p.cutoff_hz,
            "filter_order": p.config.filter_order,
            "dc_offset_V": p.offset,
            "u_dc_offset_V": p.u_offset,
            "noise_sigma_V": p.noise_sigma,
            "sampling_rate_Hz": p.sampling_rate,
            "calibration": p.calibration.name,
            "calibration_has_phase": p.calibration.phase is not None,
            "calibration_range_Hz": [float(p.calibration.frequency[0]),
                                     float(p.calibration.frequency[-1])],
        })
        return out


def hydrophone_pulse(voltage: np.ndarray, sampling_rate: float, calibration, *,
                     config=None, medium: Medium | None = None, start_time: float = 0.0,
                     n_draws: int = 200, seed: int | None = 0) -> HydrophonePulse:
    """Deconvolve one hydrophone record and compute its pulse parameters (one call).

    Parameters are those of :func:`holoprobe.signal.deconvolve_hydrophone` and
    :func:`pulse_parameters`.

    Returns
    -------
    HydrophonePulse
    """
    dec = deconvolve_hydrophone(voltage, sampling_rate, calibration, config=config,
                                start_time=start_time)
    return HydrophonePulse(dec, pulse_parameters(dec, medium, n_draws=n_draws, seed=seed))
