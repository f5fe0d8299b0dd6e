"""Fields at many points chunk by chunk: bounded memory, one record length, one table.

:func:`predict_field` holds every record and spectrum of its targets in memory (10⁶
points × 512 samples: 2 GB of float32 records plus the spectra). :class:`FieldStream`
splits the targets into chunks that share the record length and frequency bins of the
whole set (so the chunks equal one call to float32 rounding) and one column table
(:func:`holoprobe.transducer.shared_table`), and yields each chunk's prediction for the
caller to write (``holoprobe field --points`` streams them into ``field.h5``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.transducer._field import (
    FieldPrediction,
    _targets,
    predict_field,
    record_band,
    record_length,
    signal_band,
)
from holoprobe.transducer._model import VirtualTransducer
from holoprobe.transducer._table_decimation import table_frequencies
from holoprobe.transducer._tables import shared_table
from holoprobe.transducer._transmit import TransmitSetting

__all__ = ["FieldStream"]


class FieldStream:
    """The field of one transmit at many points, computed and yielded chunk by chunk.

    Parameters
    ----------
    vt, setting : VirtualTransducer, TransmitSetting
        The model and the transmit.
    points : array_like, shape (n, 3)
        Targets in m.
    sampling_rate : float, optional
        Hz (default ``oversampling`` × the top of the signal band).
    chunk : int
        Targets per chunk (the working memory is about ``chunk`` × (record length × 4 +
        bins × 24) bytes, plus the column table; 65 536 × 512 samples ≈ 0.3 GB). A plane's
        points listed in one chunk keep their lines along x whole for the lattice.
    method, band_threshold_db, points_per_wavelength, guard_time, dtype, oversampling
        As in :func:`holoprobe.transducer.predict_field` (records with
        ``time_window="local"``).

    Attributes
    ----------
    time : ndarray, shape (nt,)
        Sample times of each local record in s (add the chunk's ``time_offset``).
    sampling_rate : float
        Hz.
    frequency_band : (float, float)
        Hz.
    points : ndarray, shape (n, 3)
        m.

    Iterating yields ``(start, FieldPrediction)``: the prediction at ``points[start:start
    + chunk]``.
    """

    def __init__(self, vt: VirtualTransducer, setting: TransmitSetting, points: ArrayLike, *,
                 sampling_rate: float | None = None, chunk: int = 1 << 16,
                 method: str = "auto", band_threshold_db: float = -40.0,
                 points_per_wavelength: float = 4.0, guard_time: float = 1e-6,
                 dtype: type = np.float32, oversampling: float = 8.0):
        if not (isinstance(chunk, int | np.integer) and chunk >= 1):
            raise InputError(f"expected a positive number of points, got {chunk!r}",
                             field="chunk")
        self.vt, self.setting = vt, setting
        self.points = _targets(points)
        self.chunk = int(chunk)
        self.frequency_band = signal_band(vt, setting, threshold_db=band_threshold_db)
        fs = (oversampling * self.frequency_band[1] if sampling_rate is None
              else float(sampling_rate))
        if not (math.isfinite(fs) and fs > 2 * self.frequency_band[1]):
            raise InputError(f"expected a sampling rate above twice the top of the band "
                             f"({2 * self.frequency_band[1]:g} Hz), got {fs!r}",
                             field="sampling_rate")
        self.sampling_rate = fs
        n = record_length(vt, [setting], self.points, fs, guard_time=guard_time)
        self.time = np.arange(n) / fs
        self.method, self.band_threshold_db = method, band_threshold_db
        self.points_per_wavelength, self.guard_time = points_per_wavelength, guard_time
        self.dtype = dtype

    def __len__(self) -> int:
        return math.ceil(self.points.shape[0] / self.chunk)

    def bins(self) -> NDArray[np.float64]:
        """Frequencies (Hz) of the bins every chunk propagates."""
        return record_band(0.0, self.sampling_rate, *self.frequency_band, self.time.size)[2]

    def __iter__(self) -> Iterator[tuple[int, FieldPrediction]]:
        return self.run()

    def run(self, progress: Callable[[int, int], None] | None = None
            ) -> Iterator[tuple[int, FieldPrediction]]:
        """Yield ``(start, prediction)`` per chunk; ``progress(done, total)`` in points."""
        apod, _ = self.vt.transmit_weights(self.setting)
        active = np.flatnonzero(apod != 0)
        n = self.points.shape[0]
        bins = table_frequencies(self.bins(), self.time.size / self.sampling_rate)
        f_tab, f_max = bins if bins is not None else (self.bins(), None)
        with shared_table(self.vt, self.points, f_tab, active, f_max=f_max,
                          points_per_wavelength=self.points_per_wavelength, dtype=self.dtype):
            for s0 in range(0, n, self.chunk):
                s1 = min(n, s0 + self.chunk)

                def report(done: int, total: int, s0: int = s0, s1: int = s1) -> None:
                    if progress is not None:
                        progress(s0 + round((s1 - s0) * done / max(total, 1)), n)

                pred = predict_field(self.vt, self.setting, self.points[s0:s1],
                                     sampling_rate=self.sampling_rate,
                                     n_samples=self.time.size, time_window="local",
                                     method=self.method,
                                     band_threshold_db=self.band_threshold_db,
                                     points_per_wavelength=self.points_per_wavelength,
                                     guard_time=self.guard_time, dtype=self.dtype,
                                     progress=report)
                yield s0, pred
