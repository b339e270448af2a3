"""Where tasks run: in this process, in local processes, or on MPI ranks.

All three share one small interface (after mpi4py.futures' pool abstraction):
``submit(task, zero)``, ``next_reply(timeout) -> Reply | None``, ``capacity``,
``in_flight`` and ``shutdown(abort)``. The runner does not know which it has,
so most sweep tests need no ``mpiexec``.

MPI protocol (rank 0 is the master, ranks 1..N-1 work): the master broadcasts
the job once, then sends ``(task, zero)`` values tagged TASK and receives
``Reply`` values tagged REPLY; ``None`` tagged STOP ends a worker, which answers
STOPPED before it leaves; a task a worker dropped on a signal comes back as
ABANDONED (the master queues it again unless it is stopping). Each worker holds
up to PREFETCH tasks, so it starts the next one without a round trip. Both sides
wait with ``Iprobe`` and a short sleep (one ``Backoff``) instead of a blocking
receive, because MPICH's blocking receive spins a core: with ``mpirun -n 3`` on 2
cores the master must leave both cores to the workers.

Interrupts: a worker that gets SIGTERM/SIGINT while computing abandons the task
(srun and mpirun deliver the signal to every rank); the master then stops every
worker and waits for them, so the run ends through MPI_Finalize with the
master's exit code. ``MPI_Abort`` is the last resort, for a worker that does not
answer within the grace period (an aborted MPICH run loses its exit code under
srun and leaves shared-memory segments behind).
"""

from __future__ import annotations

import collections
import multiprocessing
import os
import queue
import signal
import socket
import time

from .worker import Reply, execute, prepare, stderr_notice

TASK, REPLY, STOP, STOPPED, ABANDONED = 1, 2, 3, 4, 5
PREFETCH = 2  # tasks held by each MPI worker: the one it computes and the next
ABANDON_WAIT_S = 2.0  # after dropping a task on a signal, wait this long for STOP
MPI_ENV_HINTS = ("PMI_RANK", "PMI_SIZE", "PMI_FD", "PMIX_RANK", "OMPI_COMM_WORLD_SIZE",
                 "MPI_LOCALNRANKS", "HYDRA_CONTROL_FD")  # fmt: skip


def launched_by_mpi() -> bool:
    """True when this process was started by mpirun/mpiexec/srun --mpi."""
    return any(k in os.environ for k in MPI_ENV_HINTS)


class Backoff:
    """Exponential backoff for poll loops (after mpi4py.futures): ``sleep()`` waits
    a little longer each time, from ``start`` up to ``limit`` seconds; ``reset()``
    after something arrived."""

    def __init__(self, start: float = 0.0005, limit: float = 0.005) -> None:
        self.start, self.limit = start, limit
        self.delay = start

    def reset(self) -> None:
        self.delay = self.start

    def sleep(self) -> None:
        time.sleep(self.delay)
        self.delay = min(2.0 * self.delay, self.limit)


class SerialExecutor:
    """Runs each task in this process when the runner asks for the next reply."""

    capacity = 1
    runs_in_master = True

    def __init__(self, job) -> None:
        self.job = job
        self._queue: collections.deque = collections.deque()
        prepare(job, stderr_notice)

    @property
    def in_flight(self) -> int:
        return len(self._queue)

    def submit(self, task, zero: dict | None) -> None:
        self._queue.append((task, zero))

    def next_reply(self, timeout: float) -> Reply | None:
        if not self._queue:
            time.sleep(min(timeout, 0.05))
            return None
        task, zero = self._queue.popleft()
        return execute(self.job, task, zero, rank=0)

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

    runs_in_master = False

    def __init__(self, job, workers: int) -> None:
        self.job = job
        self.capacity = workers
        prepare(job, stderr_notice)  # compile once here; the workers then load numba's cache
        ctx = multiprocessing.get_context("spawn")
        self._pool = ctx.Pool(workers, initializer=_process_worker_init, initargs=(job,))
        self._replies: queue.Queue = queue.Queue()
        self._running = 0
        self._next_rank = 0

    @property
    def in_flight(self) -> int:
        return self._running

    def submit(self, task, zero: dict | None) -> None:
        self._next_rank = self._next_rank % self.capacity + 1
        self._pool.apply_async(
            _process_execute,
            (self.job, task, zero, self._next_rank),
            callback=self._replies.put,
            error_callback=lambda e, t=task: self._replies.put(_lost(t, e)),
        )
        self._running += 1

    def next_reply(self, timeout: float) -> Reply | None:
        try:
            reply = self._replies.get(timeout=timeout)
        except queue.Empty:
            return None
        self._running -= 1
        return reply

    def interrupt(self, grace: float, on_reply) -> bool:
        """Local workers are simply ended; their tasks are redone on resume."""
        self._pool.terminate()
        self._pool.join()
        return True

    def shutdown(self, abort: bool = False) -> None:
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


class MPIExecutor:
    """Rank 0's side of the MPI protocol; ranks 1..N-1 run ``mpi_worker_loop``."""

    runs_in_master = False

    def __init__(self, job, comm) -> None:
        self.job = job
        self.comm = comm
        workers = range(1, comm.Get_size())
        # each worker holds its running task and one queued behind it, so that it
        # starts the next one the moment it replies (no round trip to the master)
        self.capacity = PREFETCH * len(workers)
        self._outstanding: dict[int, int] = dict.fromkeys(workers, 0)
        comm.bcast(job.model_dump_json(), root=0)
        prepare(job, stderr_notice)  # compile once, into numba's cache, before the workers load it
        comm.Barrier()

    @property
    def in_flight(self) -> int:
        return sum(self._outstanding.values())

    def submit(self, task, zero: dict | None) -> None:
        rank = min(self._outstanding, key=self._outstanding.__getitem__)
        self.comm.send((task, zero), dest=rank, tag=TASK)
        self._outstanding[rank] += 1

    def _received(self, source: int) -> None:
        self._outstanding[source] = max(0, self._outstanding[source] - 1)

    def next_reply(self, timeout: float) -> Reply | None:
        from mpi4py import MPI

        status = MPI.Status()
        deadline = time.monotonic() + timeout
        backoff = Backoff()
        while not (
            self.comm.Iprobe(source=MPI.ANY_SOURCE, tag=REPLY, status=status)
            or self.comm.Iprobe(source=MPI.ANY_SOURCE, tag=ABANDONED, status=status)
        ):
            if time.monotonic() >= deadline:
                return None
            backoff.sleep()
        source = status.Get_source()
        return self._take(source, status.Get_tag())

    def _take(self, source: int, tag: int) -> Reply:
        """Receive a REPLY or ABANDONED message; an abandoned task becomes a Reply
        with error kind 'abandoned', which the runner queues again."""
        message = self.comm.recv(source=source, tag=tag)
        self._received(source)
        if tag == ABANDONED:
            error = {"kind": "abandoned", "message": "a signal stopped it", "traceback": ""}
            return Reply(message, None, error, source, socket.gethostname(), 0.0)
        return message

    def _stop_all(self, grace: float, on_reply=None) -> bool:
        """STOP to every worker, then take replies (to ``on_reply``) and the
        workers' STOPPED answers for up to ``grace`` seconds; True if all answered."""
        from mpi4py import MPI

        waiting = set(range(1, self.comm.Get_size()))
        for rank in waiting:
            self.comm.send(None, dest=rank, tag=STOP)
        status = MPI.Status()
        deadline = time.monotonic() + grace
        backoff = Backoff()
        while waiting and time.monotonic() < deadline:
            if not self.comm.Iprobe(source=MPI.ANY_SOURCE, tag=MPI.ANY_TAG, status=status):
                backoff.sleep()
                continue
            backoff.reset()
            source, tag = status.Get_source(), status.Get_tag()
            if tag == STOPPED:
                self.comm.recv(source=source, tag=tag)
                waiting.discard(source)
            else:
                reply = self._take(source, tag)
                if on_reply is not None:
                    on_reply(reply)
        return not waiting

    def interrupt(self, grace: float, on_reply) -> bool:
        """Stop handing out work and end every worker; results that still arrive go
        to ``on_reply``. False if some worker did not stop within ``grace``."""
        self._stopped = self._stop_all(grace, on_reply)
        return self._stopped

    def shutdown(self, abort: bool = False) -> None:
        if abort:
            self.comm.Abort(3)  # the last resort: a worker that would not stop
        if not getattr(self, "_stopped", False):
            self._stop_all(grace=60.0)


class _Abandon(BaseException):
    """A signal reached a worker while it computed: drop the task."""


def mpi_worker_loop(comm) -> None:
    """A worker rank: take tasks until told to stop. On SIGTERM/SIGINT it abandons
    the task it is computing (the master redoes it on resume) and waits for STOP."""
    from mpi4py import MPI

    from .jobs import JobSpec

    busy = {"now": False}

    def _on_signal(signum, frame):
        if busy["now"]:
            raise _Abandon

    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    job_json = comm.bcast(None, root=0)
    if job_json is None:  # the master refused the job before any work
        return
    job = JobSpec.model_validate_json(job_json)
    comm.Barrier()  # rank 0 has compiled the kernels into numba's cache
    prepare(job)
    rank = comm.Get_rank()
    status = MPI.Status()
    backoff = Backoff()
    while True:
        backoff.reset()
        while not comm.Iprobe(source=0, tag=MPI.ANY_TAG, status=status):
            backoff.sleep()
        message = comm.recv(source=0, tag=status.Get_tag())
        if status.Get_tag() == STOP:
            comm.send(None, dest=0, tag=STOPPED)
            return
        task, zero = message
        if comm.Iprobe(source=0, tag=STOP):
            comm.send(task.task_id, dest=0, tag=ABANDONED)  # stopping: not started
            continue
        try:
            busy["now"] = True
            reply = execute(job, task, zero, rank)
            busy["now"] = False
        except _Abandon:
            busy["now"] = False
            comm.send(task.task_id, dest=0, tag=ABANDONED)
            # the whole run is probably stopping: give the master's STOP a moment
            # to overtake the task queued behind this one
            deadline = time.monotonic() + ABANDON_WAIT_S
            backoff.reset()
            while time.monotonic() < deadline and not comm.Iprobe(source=0, tag=STOP):
                backoff.sleep()
            continue
        comm.send(reply, dest=0, tag=REPLY)
