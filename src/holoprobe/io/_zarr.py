"""Chunked Zarr stores of predicted fields (``field.zarr``), written chunk by chunk.

A lazy (dask-backed) :class:`xarray.Dataset` is streamed to a Zarr store: the
metadata and coordinates first, then every chunk as soon as it is computed, so a
volume larger than the memory is written with the memory of a few chunks. The
store is built under a temporary name beside the target and renamed when complete
(atomic like :func:`holoprobe.io.atomic_write`). Layout: docs/formats.md,
"field.zarr".
"""

from __future__ import annotations

import os
import secrets
import shutil
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from holoprobe.errors import InputError

__all__ = ["FIELD_ZARR_KIND", "read_field_zarr", "scheduler_address", "write_field_zarr"]

FIELD_ZARR_KIND = "field_zarr"


def scheduler_address(option: str | None) -> str | None:
    """The dask.distributed scheduler a command uses: ``option``, else dask's config key.

    Parameters
    ----------
    option : str, optional
        The ``--scheduler ADDRESS`` a user gave.

    Returns
    -------
    str or None
        ``option`` when given; otherwise dask's own configuration key
        ``scheduler-address`` (environment ``DASK_SCHEDULER_ADDRESS`` or a dask YAML
        config file) when dask is installed and it is set; None (the local threaded
        scheduler) otherwise.
    """
    if option is not None:
        return str(option)
    try:
        import dask.config
    except ImportError:
        return None
    value = dask.config.get("scheduler-address", None)
    return str(value) if value else None


def _target(path: str | os.PathLike, overwrite: bool, protect: Iterable) -> Path:
    target = Path(path)
    for source in protect:
        src = Path(source)
        if src.exists() and target.exists() and os.path.samefile(src, target):
            raise InputError("refusing to overwrite an input file", file=str(target))
    if target.exists() and not overwrite:
        raise InputError("already exists; pass overwrite=True to replace it", file=str(target))
    if not target.parent.is_dir():
        raise InputError("the output directory does not exist", file=str(target.parent))
    return target


def _slabs(dataset: Any, dim: str) -> list[tuple[int, int]]:
    """Chunk boundaries of ``dataset`` along ``dim`` (those of its dask arrays)."""
    sizes = dataset.chunks[dim]
    bounds, start = [], 0
    for size in sizes:
        bounds.append((start, start + size))
        start += size
    return bounds


def _client(scheduler: Any) -> Any:
    from distributed import Client

    if isinstance(scheduler, Client):
        return scheduler, False
    return Client(str(scheduler)), True


def write_field_zarr(path: str | os.PathLike, dataset: Any, *, scheduler: Any = None,
                     num_workers: int | None = None, progress: bool | None = False,
                     overwrite: bool = False, protect: Iterable[str | os.PathLike] = ()
                     ) -> Path:
    """Compute a lazy field Dataset chunk by chunk into a Zarr store, atomically.

    Parameters
    ----------
    path : str or PathLike
        The store (a directory, conventionally ``field.zarr``).
    dataset : xarray.Dataset
        E.g. :func:`holoprobe.transducer.field_dataset`; its second dimension (``x``
        or ``point``) is written slab by slab along its dask chunks.
    scheduler : str or distributed.Client, optional
        None: dask's local threaded scheduler. A ``dask.distributed`` scheduler
        address (``"tcp://host:8786"``) or a Client: the chunks run on that cluster
        (the workers must see ``path``: a shared file system).
    num_workers : int, optional
        Threads of the local scheduler (default: dask's, the number of cores).
    progress : bool or None
        Progress bar (rich) on stderr; None: on a terminal.
    overwrite, protect
        Replace an existing store; refuse to replace these input paths.

    Returns
    -------
    pathlib.Path
        The store.
    """
    from holoprobe._progress import progress_task

    target = _target(path, overwrite, protect)
    tmp = target.parent / f".{target.name}.{secrets.token_hex(6)}.tmp"
    dim = next(d for d in dataset["pressure"].dims if d != "transmit")
    try:
        dataset.to_zarr(tmp, mode="w-", compute=False, zarr_format=2)  # metadata, coordinates
        parts = []
        for lo, hi in _slabs(dataset, dim):
            part = dataset.isel({dim: slice(lo, hi)})
            part = part.drop_vars([k for k, v in part.variables.items() if dim not in v.dims])
            parts.append(part.to_zarr(tmp, region={dim: slice(lo, hi)}, compute=False,
                                        zarr_format=2))
        with progress_task(len(parts), description=f"writing {target.name}",
                           enabled=progress) as advance:
            if scheduler is None:
                _compute_local(parts, num_workers, advance)
            else:
                _compute_distributed(parts, scheduler, advance)
        if target.exists():
            shutil.rmtree(target)
        os.replace(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return target


def _compute_local(parts: list, num_workers: int | None, advance) -> None:
    """Local threaded scheduler; the bar advances with every task (dask callbacks)."""
    import dask
    from dask.callbacks import Callback

    class _Bar(Callback):
        """Advances the bar by len(parts) / number of tasks after every task."""

        def __init__(self) -> None:
            super().__init__()
            self.step = 0.0

        def _start_state(self, dsk, state) -> None:
            self.step = len(parts) / max(1, len(dsk) - len(state.get("cache", ())))

        def _posttask(self, key, result, dsk, state, worker_id) -> None:
            advance(self.step)

    with _Bar():
        dask.compute(*parts, scheduler="threads", num_workers=num_workers)


def _compute_distributed(parts: list, scheduler: Any, advance) -> None:
    """A dask.distributed cluster; the bar advances as slabs complete (as_completed)."""
    from distributed import as_completed

    client, owned = _client(scheduler)
    try:
        futures = client.compute(parts)
        for future in as_completed(futures):
            future.result()  # raises a worker's exception here
            advance(1)
    finally:
        if owned:
            client.close()


def read_field_zarr(path: str | os.PathLike) -> Any:
    """Open a ``field.zarr`` store (lazily) as an :class:`xarray.Dataset`.

    Raises
    ------
    InputError
        If ``path`` is not a holoprobe field store.
    """
    import xarray as xr

    target = Path(path)
    if not target.is_dir():
        raise InputError("no such Zarr store (a directory)", file=str(target))
    try:
        ds = xr.open_zarr(target)
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(f"not a readable Zarr store: {exc}", file=str(target)) from None
    kind = ds.attrs.get("kind")
    if kind != FIELD_ZARR_KIND:
        raise InputError(f"expected kind {FIELD_ZARR_KIND!r}, got {kind!r}", file=str(target),
                         field="kind")
    return ds
