"""signal.Threads: every task joined before the block is left, the queued ones cancelled
when the block raises, no task's exception unseen (review, session 11: a background
thread ran on after a later step raised, and three threading idioms did it three ways)."""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

import pytest

from holoprobe.signal import Threads


def _alive(prefix: str) -> list[str]:
    return [t.name for t in threading.enumerate() if t.name.startswith(prefix)]


def test_an_error_in_the_block_cancels_the_queued_tasks_joins_the_running_one_and_propagates():
    ran, started = [], threading.Event()

    def slow(tag: str) -> None:
        started.set()
        time.sleep(0.2)
        ran.append(tag)

    with pytest.raises(KeyError, match="main path"), Threads(1, name="t-raise") as threads:
        threads.submit(slow, "running")
        queued = threads.submit(slow, "queued")
        assert started.wait(5)
        raise KeyError("main path")
    assert ran == ["running"]      # finished before the error reached the caller
    assert queued.cancelled()      # never started
    assert _alive("t-raise") == []


def test_a_task_error_nobody_asked_for_is_raised_on_leaving_the_block():
    def fail() -> None:
        raise ValueError("in a task")

    with pytest.raises(ValueError, match="in a task"), Threads(2, name="t-task") as threads:
        threads.submit(fail)
        threads.submit(time.sleep, 0.05)
    assert _alive("t-task") == []


def test_map_keeps_the_order_and_a_callers_pool_stays_up():
    with ThreadPoolExecutor(max_workers=3, thread_name_prefix="t-kept") as pool:
        with Threads(pool=pool) as threads:
            assert threads.map(lambda x: x * x, range(7)) == [0, 1, 4, 9, 16, 25, 36]
        with pytest.raises(RuntimeError), Threads(pool=pool) as threads:
            late = [threads.submit(time.sleep, 0.1) for _ in range(6)]
            raise RuntimeError
        assert all(f.done() for f in late) and any(f.cancelled() for f in late)
        assert pool.submit(lambda: 5).result() == 5   # not shut down by the blocks


def test_a_task_error_the_caller_collected_in_the_block_is_not_raised_again():
    """Review A (session 12): the error was raised on leaving although result() had
    handed it to the caller, who handled it (fails on the old code)."""
    def fail(tag: str) -> None:
        raise ValueError(tag)

    with Threads(2, name="t-seen") as threads:
        by_result, by_exception = threads.submit(fail, "a"), threads.submit(fail, "b")
        with pytest.raises(ValueError, match="a"):
            by_result.result()
        assert str(by_exception.exception()) == "b"
        with pytest.raises(ValueError, match="c"):
            threads.map(fail, ["c"])
    with pytest.raises(ValueError, match="unseen"), Threads(2, name="t-seen") as threads:
        threads.submit(fail, "seen").exception()
        threads.submit(fail, "unseen")          # nobody asked: raised on leaving
    assert _alive("t-seen") == []
