"""Helper processes forked to read or draw in parallel: how many may run (forking is
safe only in a single-threaded, non-daemonic process) and the signals they take."""

from __future__ import annotations

import multiprocessing
import os
import signal
import threading
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

T = TypeVar("T")
R = TypeVar("R")


def fork_workers(limit: int = 4) -> int:
    """How many forked helpers may work at once: the usable cores, at most ``limit``;
    1 (work in this process) where a fork is not safe: no fork start method, other
    threads (a forked thread's locks can deadlock the child), or a daemonic process
    (which may not have children)."""
    if ("fork" not in multiprocessing.get_all_start_methods() or threading.active_count() != 1
            or multiprocessing.current_process().daemon):  # fmt: skip
        return 1
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, min(limit, cores or 1))


def forked_map(workers: int, fn: Callable[[T], R], items: Iterable[T]) -> Iterator[R]:
    """``fn`` of each item by ``workers`` forked helpers (they share this process's
    memory as it was: what ``fn`` needs besides its item goes in a module global set
    before the call), the results in order as they come; the helpers leave by
    themselves once done, or are terminated if the caller stops or fails."""
    with multiprocessing.get_context("fork").Pool(workers, initializer=_helper_signals) as pool:
        yield from pool.imap(fn, items)
        pool.close()  # done: the helpers leave by themselves (terminate() is for errors)
        pool.join()


def _helper_signals() -> None:
    """In a helper: SIGTERM ends it at once (the parent's handler, inherited by the
    fork, would report a stopped job), SIGINT is the parent's to handle."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
