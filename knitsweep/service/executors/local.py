"""Executors in this machine without MPI: this process (``SerialExecutor``) or
``--workers N`` local processes (``ProcessExecutor``); both implement
``executors.Executor``."""

from __future__ import annotations

import collections
import multiprocessing
import queue
import signal
import socket
import time

from .. import signals
from ..worker import Reply, execute, kernels_cached, prepare, stderr_notice

__all__ = ["ProcessExecutor", "SerialExecutor"]

SHORT_TASK_S = 0.2
"""After a task this short the serial executor computes the next one without
first letting the master commit (the next is likely as short: results batch)."""


class SerialExecutor:
    """Runs each task in this process when the runner asks for the next reply."""

    capacity = 1

    def __init__(self, job) -> None:
        self.job = job
        self._queue: collections.deque = collections.deque()
        self._last_seconds = 0.0
        self._prepared = False

    @property
    def in_flight(self) -> int:
        return len(self._queue)

    def submit(self, task, zero: dict | None) -> None:
        if not self._prepared:  # the first task: compile (or load) the kernels
            with signals.interruptible():
                self.compile_seconds = prepare(self.job, stderr_notice)
            self._prepared = True
        self._queue.append((task, zero))

    def next_reply(self, timeout: float, idle=None) -> Reply | None:
        if not self._queue:
            if idle is not None:
                idle()
            time.sleep(min(timeout, 0.05))
            return None
        if idle is not None and self._last_seconds >= SHORT_TASK_S:
            idle()  # this process is about to compute for a while
        task, zero = self._queue.popleft()
        with signals.interruptible():  # a signal abandons the task; it is redone on resume
            signals.fault_point("handout")
            reply = execute(self.job, task, zero, rank=0)
        self._last_seconds = reply.seconds
        return reply

    def interrupt(self, grace: float, on_reply) -> bool:
        self._queue.clear()  # the task being computed was abandoned by the signal
        return True

    def shutdown(self, abort: bool = False) -> None:
        self._queue.clear()


def _process_worker_init(job) -> None:
    # the master decides about interrupts; a worker just works
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    prepare(job)  # loads the kernels the master compiled, before the first task


def _process_execute(job, task, zero, rank):
    return execute(job, task, zero, rank)


class ProcessExecutor:
    """Local worker processes (``--workers N``), started with 'spawn'."""

    def __init__(self, job, workers: int) -> None:
        self.job = job
        self._workers = workers
        self._pool = None  # started with the first task
        self._replies: queue.Queue = queue.Queue()
        self._running = 0
        self._next_rank = 0

    @property
    def capacity(self) -> int:
        return self._workers

    @property
    def in_flight(self) -> int:
        return self._running

    def _start(self) -> None:
        with signals.interruptible():  # compile once here; the workers load numba's cache
            if not kernels_cached(self.job):
                self.compile_seconds = prepare(self.job, stderr_notice)
        with signals.deferred():  # a pool is not left half-started
            ctx = multiprocessing.get_context("spawn")
            self._pool = ctx.Pool(self._workers, initializer=_process_worker_init,
                                  initargs=(self.job,))  # fmt: skip

    def submit(self, task, zero: dict | None) -> None:
        if self._pool is None:
            self._start()
        self._next_rank = self._next_rank % self._workers + 1
        self._pool.apply_async(
            _process_execute,
            (self.job, task, zero, self._next_rank),
            callback=self._replies.put,
            error_callback=lambda e, t=task: self._replies.put(_lost(t, e)),
        )
        self._running += 1

    def next_reply(self, timeout: float, idle=None) -> Reply | None:
        if idle is not None and self._replies.empty():
            idle()
        try:
            reply = self._replies.get(timeout=timeout)
        except queue.Empty:
            return None
        self._running -= 1
        return reply

    def interrupt(self, grace: float, on_reply) -> bool:
        """Local workers are simply ended; their tasks are redone on resume."""
        if self._pool is not None:
            self._pool.terminate()
            self._pool.join()
        return True

    def shutdown(self, abort: bool = False) -> None:
        if self._pool is None:
            return
        if abort:
            self._pool.terminate()
        else:
            self._pool.close()
        self._pool.join()


def _lost(task, exc: BaseException) -> Reply:
    error = {
        "kind": type(exc).__name__,
        "message": f"worker process failed: {exc}",
        "traceback": "",
    }
    return Reply(task.task_id, None, error, -1, socket.gethostname(), 0.0)
