"""One progress-bar helper for every long step (rich), silent when disabled."""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import TypeVar

T = TypeVar("T")

__all__ = ["progress_iter", "progress_task"]


def _enabled(enabled: bool | None) -> bool:
    if enabled is None:
        return sys.stderr.isatty()
    return bool(enabled)


def progress_iter(items: Iterable[T], *, total: int | None = None, description: str = "",
                  enabled: bool | None = False) -> Iterator[T]:
    """Iterate over ``items`` showing a rich progress bar on stderr when ``enabled``.

    Parameters
    ----------
    items : iterable
        What to iterate over.
    total : int, optional
        Number of items (default ``len(items)`` when available).
    description : str
        Label of the bar.
    enabled : bool or None
        ``True`` shows the bar, ``False`` hides it, ``None`` shows it on a terminal.
    """
    if not _enabled(enabled):
        yield from items
        return
    from rich.progress import track

    if total is None and hasattr(items, "__len__"):
        # (type: ignore below) hasattr(items, '__len__') makes it Sized; mypy cannot see it
        total = len(items)  # type: ignore[arg-type]
    yield from track(items, total=total, description=description, transient=True)


@contextmanager
def progress_task(total: float, *, description: str = "", enabled: bool | None = False):
    """Context manager yielding ``advance(n)`` for a manually advanced progress bar."""
    if not _enabled(enabled):
        yield lambda n=1: None
        return
    from rich.progress import Progress

    with Progress(transient=True) as progress:
        task = progress.add_task(description, total=total)
        yield lambda n=1: progress.advance(task, n)
