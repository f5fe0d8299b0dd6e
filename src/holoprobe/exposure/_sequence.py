"""Acoustic output of a transmit sequence (an imaging mode): per transmit and worst case.

For a sequence whose frame holds transmits t = 1…n, each fired once per frame at
``frame_rate`` (IEC 62359 for scanning modes):

* the temporal-average intensity at a point is ``I_ta(r) = frame_rate · Σ_t PII_t(r)``
  (and derated with each transmit's own f_awf), and I_spta is its spatial maximum;
* MI and I_sppa are per-pulse quantities: each transmit's own value
  (:func:`holoprobe.exposure.exposure_metrics`), and the worst case is the largest
  over the transmits.

Every maximum is reported with where it occurs (transmit index and position).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.exposure._metrics import (
    DERATING_DB_PER_CM_MHZ,
    ExposureMetrics,
    derating_factor,
    exposure_metrics,
    pulse_intensity_integral,
)
from holoprobe.geometry import Medium

__all__ = ["SequenceExposure", "sequence_exposure"]


@dataclass(frozen=True)
class SequenceExposure:
    """Acoustic output of a transmit sequence (SI units).

    Attributes
    ----------
    per_transmit : tuple of ExposureMetrics
        Each transmit's own quantities; its ``ispta`` is its share
        ``frame_rate · PII_sp`` of the temporal average (its ``prf`` is the frame rate).
    names : tuple of str
        Transmit labels.
    prf, frame_rate : float
        Transmit events per second and frames per second (Hz).
    mechanical_index : float
        Worst-case MI over the transmits.
    mechanical_index_transmit : int
        Index of that transmit.
    mechanical_index_position : tuple of 3 floats
        Where (m): the point of maximum derated PII of that transmit.
    isppa, isppa_transmit, isppa_position
        Worst-case spatial-peak pulse-average intensity (W/m²), its transmit, where.
    ispta : float
        Spatial-peak temporal-average intensity of the sequence, max over the points
        of ``frame_rate · Σ_t PII_t`` (W/m²).
    ispta_position : tuple of 3 floats
        Where (m).
    ispta_derated, ispta_derated_position
        The same with each transmit's PII derated at its own f_awf.
    temporal_average_intensity : ndarray, shape (n_points,)
        ``frame_rate · Σ_t PII_t`` at every point (W/m²).
    """

    per_transmit: tuple[ExposureMetrics, ...]
    names: tuple[str, ...]
    prf: float
    frame_rate: float
    mechanical_index: float
    mechanical_index_transmit: int
    mechanical_index_position: tuple[float, float, float]
    isppa: float
    isppa_transmit: int
    isppa_position: tuple[float, float, float]
    ispta: float
    ispta_position: tuple[float, float, float]
    ispta_derated: float
    ispta_derated_position: tuple[float, float, float]
    temporal_average_intensity: NDArray[np.float64]

    def to_dict(self) -> dict[str, object]:
        """JSON-ready dict (SI units, ``units`` entry; per-point array left out)."""
        units = {"mechanical_index": "1 (MPa/sqrt(MHz))", "isppa": "W/m^2",
                 "ispta": "W/m^2", "ispta_derated": "W/m^2", "prf": "Hz",
                 "frame_rate": "Hz", "positions": "m"}
        worst = {
            "mechanical_index": self.mechanical_index,
            "mechanical_index_transmit": self.mechanical_index_transmit,
            "mechanical_index_position": list(self.mechanical_index_position),
            "isppa": self.isppa, "isppa_transmit": self.isppa_transmit,
            "isppa_position": list(self.isppa_position),
            "ispta": self.ispta, "ispta_position": list(self.ispta_position),
            "ispta_derated": self.ispta_derated,
            "ispta_derated_position": list(self.ispta_derated_position),
        }
        return {"prf": self.prf, "frame_rate": self.frame_rate, "transmits": len(self.names),
                "worst_case": worst, "units": units,
                "per_transmit": [dict(m.to_dict(), name=name)
                                 for name, m in zip(self.names, self.per_transmit,
                                                    strict=True)]}


def _position(pts: NDArray, i: int) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in pts[i])
    return (x, y, z)


def sequence_exposure(pressures: Iterable[ArrayLike], sampling_rate: float,
                      points: ArrayLike, medium: Medium | None = None, *, prf: float,
                      frame_rate: float | None = None, names: Sequence[str] | None = None,
                      attenuation_db_cm_mhz: float = DERATING_DB_PER_CM_MHZ,
                      frequency_method: str = "arithmetic_mean") -> SequenceExposure:
    """Per-transmit and worst-case MI, I_sppa and the sequence's I_spta, and where.

    Parameters
    ----------
    pressures : iterable of array_like, each shape (n_points, nt)
        Pressure waveforms (Pa) of each transmit at the same points (a generator
        keeps one transmit in memory at a time).
    sampling_rate : float
        Hz.
    points : array_like, shape (n_points, 3)
        Positions in m (z: depth, for derating).
    medium : Medium, optional
        ρ0, c0 (default water).
    prf : float
        Transmit events per second (Hz).
    frame_rate : float, optional
        Frames per second (default ``prf / n``); ``frame_rate · n ≤ prf``.
    names : sequence of str, optional
        Transmit labels.
    attenuation_db_cm_mhz, frequency_method
        As in :func:`holoprobe.exposure.exposure_metrics`.

    Returns
    -------
    SequenceExposure
    """
    pts = np.asarray(points, dtype=float)
    med = Medium() if medium is None else medium
    prf = float(prf)
    if not (math.isfinite(prf) and prf > 0):
        raise InputError(f"expected a positive PRF in Hz, got {prf!r}", field="prf")
    per: list[ExposureMetrics] = []
    mi_where: list[tuple[float, float, float]] = []
    total = total_derated = None
    for p in pressures:
        m = exposure_metrics(p, sampling_rate, pts, med, prf=1.0,
                             attenuation_db_cm_mhz=attenuation_db_cm_mhz,
                             frequency_method=frequency_method)
        pii = pulse_intensity_integral(np.asarray(p, dtype=float), sampling_rate, med)
        derated = pii * derating_factor(m.acoustic_working_frequency, pts[:, 2],
                                        attenuation_db_cm_mhz=attenuation_db_cm_mhz,
                                        quantity="intensity")
        total = pii if total is None else total + pii
        total_derated = derated if total_derated is None else total_derated + derated
        per.append(m)
        mi_where.append(_position(pts, int(np.argmax(derated))))
    if not per:
        raise InputError("the sequence holds no transmit", field="pressures")
    n = len(per)
    rate = prf / n if frame_rate is None else float(frame_rate)
    if not (math.isfinite(rate) and rate > 0) or rate * n > prf * (1 + 1e-9):
        raise InputError(f"expected 0 < frame_rate ≤ prf / {n} = {prf / n:g} Hz, got "
                         f"{frame_rate!r}", field="frame_rate")
    labels = tuple(names) if names is not None else tuple(f"transmit {i + 1}"
                                                         for i in range(n))
    if len(labels) != n:
        raise InputError(f"expected {n} names, got {len(labels)}", field="names")
    # each transmit's share of the temporal average: its PII once per frame
    per = [_with_rate(m, rate) for m in per]
    assert total is not None and total_derated is not None
    i_mi = int(np.argmax([m.mechanical_index for m in per]))
    i_pa = int(np.argmax([m.isppa for m in per]))
    ita, ita_a = rate * total, rate * total_derated
    i_ta, i_ta_a = int(np.argmax(ita)), int(np.argmax(ita_a))
    return SequenceExposure(
        per_transmit=tuple(per), names=labels, prf=prf, frame_rate=rate,
        mechanical_index=per[i_mi].mechanical_index, mechanical_index_transmit=i_mi,
        mechanical_index_position=mi_where[i_mi],
        isppa=per[i_pa].isppa, isppa_transmit=i_pa,
        isppa_position=per[i_pa].position_of_maximum,
        ispta=float(ita[i_ta]), ispta_position=_position(pts, i_ta),
        ispta_derated=float(ita_a[i_ta_a]), ispta_derated_position=_position(pts, i_ta_a),
        temporal_average_intensity=ita)


def _with_rate(m: ExposureMetrics, rate: float) -> ExposureMetrics:
    """``m`` computed with prf = 1 Hz, its time averages rescaled to ``rate``."""
    from dataclasses import replace

    assert m.ispta is not None and m.ispta_derated is not None
    return replace(m, prf=rate, ispta=m.ispta * rate, ispta_derated=m.ispta_derated * rate)
