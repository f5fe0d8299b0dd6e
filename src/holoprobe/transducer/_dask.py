"""Fields of transmit sequences on volumes or point lists as a chunked dask graph.

Each chunk (a block of points × a block of transmits) calls the in-process
:func:`predict_fields` with the record length and band of the WHOLE job, so the
chunks agree with one in-process call to float32 rounding. The result is an
:class:`xarray.Dataset` backed by dask arrays (nothing is computed until it is
written or loaded): :func:`holoprobe.io.write_field_zarr` streams it to Zarr chunk
by chunk, on the local threaded scheduler or a ``dask.distributed`` cluster.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from holoprobe.errors import InputError
from holoprobe.transducer._field import (
    arrival_offsets,
    predict_fields,
    record_band,
    record_length,
    union_band,
)
from holoprobe.transducer._model import VirtualTransducer
from holoprobe.transducer._tables import table_handle, use_table
from holoprobe.transducer._transmit import TransmitSetting

__all__ = ["field_dataset"]

# numba's workqueue layer (holoprobe._numba) must not run two parallel kernels at once
# from two threads: on the local threaded scheduler the chunks take turns for the kernels
# (each uses every core) while FFTs, compression and writes of other chunks overlap.
_KERNEL_LOCK = threading.Lock()
_T = TypeVar("_T")


def _distributed_worker_threads() -> int | None:
    """The thread count of the distributed worker running this task (None: not on one)."""
    try:
        from distributed import get_worker
    except ImportError:
        return None
    try:
        return max(1, int(get_worker().state.nthreads))
    except ValueError:
        return None


def _chunk_field(points: NDArray, vt: VirtualTransducer, settings: Sequence[TransmitSetting],
                 fs: float, n: int, band: tuple[float, float], kwargs: dict[str, Any],
                 table: Any = None) -> NDArray[np.float32]:
    """Pressure (n_settings, n_points, n) of one chunk, by :func:`predict_fields` (with
    the job's column table ``table``, :func:`holoprobe.transducer.table_handle`)."""

    def run() -> NDArray[np.float32]:
        out = np.empty((len(settings), points.shape[0], n), dtype=np.float32)
        with use_table(table):
            for k, pred in enumerate(predict_fields(vt, settings, points, sampling_rate=fs,
                                                    n_samples=n, frequency_band=band,
                                                    dtype=np.float32, **kwargs)):
                out[k] = pred.pressure
        return out

    return _run_kernels(run)


def _run_kernels(run: Callable[[], _T]) -> _T:
    """Call ``run`` (which launches numba parallel kernels) safely from a dask thread.

    Always under :data:`_KERNEL_LOCK`: the workqueue layer aborts the process when two
    threads of one process launch parallel kernels at once, whatever their thread
    counts. On a distributed worker a kernel uses as many numba threads as the worker
    has threads (its share of the cores; the worker's threads take turns for kernels).
    """
    import numba

    threads = _distributed_worker_threads()
    with _KERNEL_LOCK:
        if threads is not None:
            most = int(numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]  # set at import
            numba.set_num_threads(min(threads, most))
        return run()


def _block_points(*axes: NDArray) -> NDArray[np.float64]:
    """Points (n, 3) of a block: the grid of 3 axes, or an (n, 3) block of a point list."""
    if len(axes) == 1:
        return np.asarray(axes[0], dtype=float)
    g = np.meshgrid(*axes, indexing="ij")
    return np.stack([a.ravel() for a in g], axis=-1)


def _pressure_block(tx: NDArray, *axes: NDArray, vt, settings, fs, n, band, kwargs,
                    table=None):
    pts = _block_points(*axes)
    out = _chunk_field(pts, vt, [settings[int(i)] for i in tx], fs, n, band, kwargs, table)
    shape = (tx.size, *(a.shape[0] for a in axes[:3] if len(axes) == 3), n)
    return out.reshape(shape) if len(axes) == 3 else out


def _offset_block(tx: NDArray, *axes: NDArray, vt, settings, guard_time):
    pts = _block_points(*axes)
    out = _run_kernels(lambda: np.stack([arrival_offsets(vt, settings[int(i)], pts,
                                                         guard_time=guard_time)
                                         for i in tx]))
    return out.reshape((tx.size, *(a.shape[0] for a in axes))) if len(axes) == 3 else out


def _check_axis(name: str, values: ArrayLike) -> NDArray[np.float64]:
    a = np.asarray(values, dtype=float).ravel()
    if a.size == 0 or not np.all(np.isfinite(a)):
        raise InputError(f"expected a non-empty array of finite coordinates in m, got {a!r}",
                         field=name)
    return a


def _chunk_sizes(n_points: int, n: int, n_tx: int, chunk_bytes: float, ndim: int,
                 shape: tuple[int, ...], transmit_chunk: int | None) -> tuple[int, tuple]:
    """Transmits per chunk and the point chunks of each spatial axis within ``chunk_bytes``."""
    tc = max(1, min(n_tx, transmit_chunk or n_tx))
    budget = max(1, int(chunk_bytes // (4 * n * tc)))  # points per chunk
    if budget < 1:
        raise InputError("chunk_bytes holds less than one record", field="chunk_bytes")
    if ndim == 1:
        return tc, (min(n_points, budget),)
    sizes = list(shape)
    for axis in range(3):  # split x first, then y, then z until a block fits
        rest = math.prod(sizes[axis + 1:]) if axis < 2 else 1
        sizes[axis] = max(1, min(shape[axis], budget // max(1, rest)))
        if math.prod(sizes) <= budget:
            break
    return tc, tuple(sizes)


def field_dataset(vt: VirtualTransducer, settings: TransmitSetting | Sequence[TransmitSetting],
                  *, points: ArrayLike | None = None,
                  volume: tuple[ArrayLike, ArrayLike, ArrayLike] | None = None,
                  sampling_rate: float | None = None, chunk_bytes: float = 64e6,
                  transmit_chunk: int | None = None, band_threshold_db: float = -40.0,
                  points_per_wavelength: float = 4.0, guard_time: float = 1e-6,
                  attrs: dict[str, Any] | None = None, method: str = "auto") -> Any:
    """Predicted pressure of one transmit or a sequence as a lazy, chunked xarray Dataset.

    Parameters
    ----------
    vt : VirtualTransducer
        The model.
    settings : TransmitSetting or sequence of TransmitSetting
        One transmit or a sequence (``TransmitSequence.settings``).
    points : array_like, shape (n, 3), optional
        Target points in m (dims ``("transmit", "point", "time")``).
    volume : (x, y, z), optional
        Axes of a 3-D grid in m (dims ``("transmit", "x", "y", "z", "time")``); give
        exactly one of ``points`` and ``volume``. z > 0 (in front of the probe).
    sampling_rate : float, optional
        Hz (default 8 × the top of the union band).
    chunk_bytes : float
        Largest pressure chunk in bytes (float32): bounds the memory of each task.
    transmit_chunk : int, optional
        Transmits per chunk (default all: the element response is computed once per
        point chunk and shared by the transmits).
    band_threshold_db, points_per_wavelength, guard_time
        As in :func:`predict_field`.
    attrs : dict, optional
        More dataset attributes (provenance).
    method : {"auto", "element"}
        As in :func:`predict_fields` (``"auto"``: lines of targets along x are
        interpolated from the element lattice where that saves work).

    Returns
    -------
    xarray.Dataset
        ``pressure`` (Pa, float32, dask) and ``time_offset`` (s, float64, dask; sample
        k of a record lies at ``time_offset + time[k]``), coordinates ``time`` (s),
        ``transmit`` (index), ``x``/``y``/``z`` (m) for a volume or ``point_x``,
        ``point_y``, ``point_z`` (m) along ``point``; units as attributes. Equal to
        :func:`predict_fields` on the same points to float32 rounding.
    """
    import dask.array as da
    import xarray as xr

    seq = [settings] if isinstance(settings, TransmitSetting) else list(settings)
    if not seq:
        raise InputError("expected at least one transmit setting", field="settings")
    if (points is None) == (volume is None):
        raise InputError("give exactly one of points and volume", field="points")
    if volume is not None:
        axes = tuple(_check_axis(k, v) for k, v in zip("xyz", volume, strict=True))
        if np.any(axes[2] <= 0):
            raise InputError("the volume must lie in front of the probe (z > 0)", field="z")
        sample = _block_points(*axes) if math.prod(a.size for a in axes) <= 1 << 20 else \
            _block_points(axes[0][[0, -1]], axes[1][[0, -1]], axes[2])
        shape = tuple(a.size for a in axes)
    else:
        pts = np.asarray(points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0 or \
                not np.all(np.isfinite(pts)):
            raise InputError(f"expected finite points of shape (n, 3) in m, got {pts.shape}",
                             field="points")
        if np.any(pts[:, 2] <= 0):
            raise InputError("points must lie in front of the probe (z > 0)", field="points")
        sample, shape = pts, (pts.shape[0],)
    band = union_band(vt, seq, band_threshold_db)
    fs = 8.0 * band[1] if sampling_rate is None else float(sampling_rate)
    if not (math.isfinite(fs) and fs > 2 * band[1]):
        raise InputError(f"expected a sampling rate above twice the top of the band "
                         f"({2 * band[1]:g} Hz), got {sampling_rate!r}", field="sampling_rate")
    n = record_length(vt, seq, sample, fs, guard_time=guard_time)
    tc, sizes = _chunk_sizes(math.prod(shape), n, len(seq), chunk_bytes, len(shape), shape,
                             transmit_chunk)
    tx = da.arange(len(seq), chunks=tc)
    common = {"vt": vt, "settings": seq}
    if method not in ("auto", "element"):
        raise InputError(f"expected 'auto' or 'element', got {method!r}", field="method")
    kw = {"points_per_wavelength": points_per_wavelength, "guard_time": guard_time,
          "method": method}
    if volume is not None:
        ins = [a for k, ax in enumerate(axes)
               for a in (da.from_array(ax, chunks=sizes[k]), "xyz"[k])]
        dims: tuple[str, ...] = ("transmit", "x", "y", "z")
        idx = "txyz"
    else:
        ins = [da.from_array(pts, chunks=(sizes[0], 3)), "pc"]
        dims, idx = ("transmit", "point"), "tp"
    table = None
    if volume is None and method == "auto":  # one column table for every chunk of a list
        active = np.flatnonzero(np.any([vt.transmit_weights(s)[0] != 0 for s in seq], axis=0))
        table = table_handle(vt, pts, record_band(0.0, fs, *band, n)[2], active,
                             points_per_wavelength=points_per_wavelength, dtype=np.float32)
    p = da.blockwise(_pressure_block, idx + "n", tx, "t", *ins, new_axes={"n": n},
                     concatenate=True, dtype=np.float32, fs=fs, n=n, band=band, kwargs=kw,
                     table=table, **common)
    off = da.blockwise(_offset_block, idx, tx, "t", *ins, concatenate=True,
                       dtype=np.float64, guard_time=guard_time, **common)
    coords: dict[str, Any] = {"time": ("time", np.arange(n) / fs, {"units": "s"}),
                              "transmit": ("transmit", np.arange(len(seq)))}
    if volume is not None:
        coords.update({k: (k, ax, {"units": "m"}) for k, ax in zip("xyz", axes, strict=True)})
    else:
        coords.update({f"point_{k}": ("point", pts[:, j], {"units": "m"})
                       for j, k in enumerate("xyz")})
    meta = {"format": "holoprobe", "kind": "field_zarr", "schema_version": 1,
            "sampling_rate": fs, "frequency_band": list(band),
            "method": "element" if method == "element" else "lattice",
            "transmit_names": [s.name for s in seq],
            **(attrs or {})}
    return xr.Dataset(
        {"pressure": ((*dims, "time"), p, {"units": "Pa"}),
         "time_offset": (dims, off, {"units": "s", "description":
                                     "sample k of a record is at time_offset + time[k]"})},
        coords=coords, attrs=meta)

