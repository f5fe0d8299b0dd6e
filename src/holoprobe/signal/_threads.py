"""Threads beside the calling one, all joined before the caller goes on.

One idiom for every layer's threads (bins of a spectrum, a background step of a driver, a
writer): NumPy's FFTs and linear algebra, finufft, numba ``nogil`` kernels and h5py
release the GIL, so such work runs in threads. :class:`Threads` is a ``with`` block that
waits for every task it started before the block is left, cancels those not yet started
when the block raises, and lets no task's exception pass unseen.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from types import TracebackType
from typing import Any, TypeVar

__all__ = ["Threads"]

T = TypeVar("T")


class _Task(Future[T]):
    """A :class:`~concurrent.futures.Future` that remembers whether its outcome was
    collected (``result()`` or ``exception()`` returned or raised it)."""

    observed = False

    def result(self, timeout: float | None = None) -> T:
        try:
            return super().result(timeout)
        finally:
            self.observed = self.observed or self.done()

    def exception(self, timeout: float | None = None) -> BaseException | None:
        try:
            return super().exception(timeout)
        finally:
            self.observed = self.observed or self.done()


def _run(task: _Task[T], func: Callable[..., T], args: tuple[Any, ...]) -> None:
    """``func(*args)`` into ``task`` unless it was cancelled before it started."""
    if not task.set_running_or_notify_cancel():
        return
    try:
        value = func(*args)
    except BaseException as error:  # handed to the task, as the pool does
        task.set_exception(error)
    else:
        task.set_result(value)


class Threads:
    """Tasks on threads beside the calling one, joined when the ``with`` block ends.

    ``with Threads(n) as threads:`` then ``threads.submit(func, *args)`` (a
    :class:`~concurrent.futures.Future`, whose ``result()`` or ``exception()`` marks its
    outcome seen) or ``threads.map(func, items)`` (the results, in
    order). Leaving the block waits for every task submitted in it: none runs on after
    it. When the block raises, the tasks not yet started are cancelled, the running ones
    finish, and the block's exception propagates (a task's own exception is then
    dropped). When it does not, the first exception (in submission order) of a task
    whose ``result()``/``exception()`` nobody has called is raised on leaving it: an
    error the caller collected (and handled) inside the block is not raised again.

    Parameters
    ----------
    threads : int
        Threads of the block's own pool (≥ 1), shut down when the block ends.
    name : str
        Prefix of the threads' names.
    pool : ThreadPoolExecutor, optional
        Run the tasks on this pool instead (threads kept by the caller for many blocks);
        only this block's tasks are waited for and cancelled, the pool stays up.
    """

    def __init__(self, threads: int = 1, *, name: str = "holoprobe",
                 pool: ThreadPoolExecutor | None = None) -> None:
        self._own = pool is None
        self._pool = pool if pool is not None else ThreadPoolExecutor(
            max_workers=max(1, int(threads)), thread_name_prefix=name)
        self._futures: list[_Task[Any]] = []

    def submit(self, func: Callable[..., T], *args: Any) -> Future[T]:
        """``func(*args)`` on a thread of the pool; ``.result()`` waits for it (and
        marks its error, if any, as seen: not raised again when the block ends)."""
        task: _Task[T] = _Task()
        self._pool.submit(_run, task, func, args)
        self._futures.append(task)
        return task

    def map(self, func: Callable[[Any], T], items: Iterable[Any]) -> list[T]:
        """``[func(item) for item in items]``, the items on the pool's threads; raises
        the first exception (in the items' order) once the tasks before it are done."""
        return [future.result() for future in [self.submit(func, item) for item in items]]

    def __enter__(self) -> Threads:
        return self

    def __exit__(self, kind: type[BaseException] | None, error: BaseException | None,
                 trace: TracebackType | None) -> None:
        futures, self._futures = self._futures, []
        if kind is not None:
            for future in futures:
                future.cancel()  # not started: never runs
        wait(futures)
        if self._own:
            self._pool.shutdown(wait=True)
        if kind is None:
            for future in futures:
                if future.observed or future.cancelled():
                    continue
                failure = future.exception()
                if failure is not None:
                    raise failure
