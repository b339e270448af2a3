"""Where tasks run: in this process, in local processes, or on MPI ranks.

All three share one small interface (after mpi4py.futures' pool abstraction):
``submit(task, zero)``, ``next_reply(timeout) -> Reply | None``, ``capacity``,
``in_flight`` and ``shutdown(abort)``. The runner does not know which it has,
so most sweep tests need no ``mpiexec``.

MPI protocol (rank 0 is the master, ranks 1..N-1 work), point to point only (no
collective that a signalled rank could leave the others stuck in): the master
compiles the kernels, then sends the job tagged JOB to every worker (``None``: no
job, leave); then ``(task, zero)`` values tagged TASK go out and ``Reply`` values
tagged REPLY come back; ``None`` tagged STOP ends a worker, which answers STOPPED
before it leaves; a task a worker dropped on a signal comes back as ABANDONED.
Each worker holds up to PREFETCH tasks, so it starts the next one without a round
trip. Both sides wait with ``Iprobe`` and a short sleep (one ``Backoff``) instead
of a blocking receive, because MPICH's blocking receive spins a core: with
``mpirun -n 3`` on 2 cores the master must leave both cores to the workers.

Interrupts (``signals``): srun and mpirun deliver SIGTERM/SIGINT to every rank. A
worker that gets one abandons the task it computes, or, idle (also while it
waits for the job), tells the master it is LEFT, answers the tasks still coming
with ABANDONED and leaves at STOP (or after LEAVE_WAIT_S without one); a LEFT
worker stops the whole run as if the master had the signal. The master stops
every worker and waits for them, so the run ends through MPI_Finalize with the
master's exit code. ``MPI_Abort`` is the last resort, for a worker that does not
answer within the grace period (an aborted MPICH run loses its exit code under
srun and leaves shared-memory segments behind).
"""

from __future__ import annotations

import collections
import multiprocessing
import queue
import signal
import socket
import time

from . import signals
from .signals import Interrupted, launched_by_mpi

__all__ = ["MPIExecutor", "ProcessExecutor", "SerialExecutor", "launched_by_mpi",
           "mpi_worker_loop", "release_workers"]  # fmt: skip
from .worker import Reply, execute, prepare, stderr_notice

TASK, REPLY, STOP, STOPPED, ABANDONED, JOB, LEFT = 1, 2, 3, 4, 5, 6, 7
PREFETCH = 2  # tasks held by each MPI worker: the one it computes and the next
LEAVE_WAIT_S = 10.0  # a worker that left on a signal waits this long for the master's STOP
HURRY_S = 2.0  # a second signal while the workers stop: wait at most this much longer


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

    def __init__(self, job) -> None:
        self.job = job
        self._queue: collections.deque = collections.deque()
        with signals.interruptible():
            self.compile_seconds = prepare(job, stderr_notice)

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
        with signals.interruptible():  # a signal abandons the task; it is redone on resume
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

    def __init__(self, job, workers: int) -> None:
        self.job = job
        self.capacity = workers
        with signals.interruptible():  # compile once here; the workers load numba's cache
            self.compile_seconds = prepare(job, stderr_notice)
        with signals.deferred():  # a pool is not left half-started
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


def release_workers(comm) -> None:
    """Tell every MPI worker that there is no job (rank 0 refused it, or was
    interrupted before handing it out)."""
    with signals.deferred():
        for rank in range(1, comm.Get_size()):
            comm.send(None, dest=rank, tag=JOB)


class MPIExecutor:
    """Rank 0's side of the MPI protocol; ranks 1..N-1 run ``mpi_worker_loop``.
    Creating it compiles the kernels (interruptible) and hands the job out."""

    def __init__(self, job, comm) -> None:
        self.job = job
        self.comm = comm
        self._outstanding: dict[int, int] = dict.fromkeys(range(1, comm.Get_size()), 0)
        self._left: set[int] = set()
        self._sends: list = []  # requests of tasks not yet received by their worker
        self._stopped = False
        with signals.interruptible():  # compile once, into numba's cache, before the workers
            self.compile_seconds = prepare(job, stderr_notice)
        with signals.deferred():
            for rank in self._outstanding:
                comm.send(job.model_dump_json(), dest=rank, tag=JOB)

    @property
    def capacity(self) -> int:
        # each worker holds its running task and one queued behind it, so that it
        # starts the next one the moment it replies (no round trip to the master)
        return PREFETCH * (len(self._outstanding) - len(self._left))

    @property
    def in_flight(self) -> int:
        return sum(self._outstanding.values())

    def submit(self, task, zero: dict | None) -> None:
        live = [r for r in self._outstanding if r not in self._left]
        rank = min(live, key=self._outstanding.__getitem__)
        # isend: a large task must not block the master until its worker is free
        self._sends = [r for r in self._sends if not r.Test()]
        self._sends.append(self.comm.isend((task, zero), dest=rank, tag=TASK))
        self._outstanding[rank] += 1

    def next_reply(self, timeout: float) -> Reply | None:
        from mpi4py import MPI

        status = MPI.Status()
        deadline = time.monotonic() + timeout
        backoff = Backoff()
        while True:
            if self.comm.Iprobe(source=MPI.ANY_SOURCE, tag=MPI.ANY_TAG, status=status):
                source, tag = status.Get_source(), status.Get_tag()
                if tag != LEFT:
                    return self._take(source, tag)
                signum = self.comm.recv(source=source, tag=LEFT)
                self._left.add(source)  # it waits for STOP; the run stops as on a signal
                signals.request(signum)
                return None
            if time.monotonic() >= deadline:
                return None
            backoff.sleep()

    def _take(self, source: int, tag: int) -> Reply:
        """Receive a REPLY or ABANDONED message; an abandoned task becomes a Reply
        with error kind 'abandoned', which the runner queues again."""
        message = self.comm.recv(source=source, tag=tag)
        self._outstanding[source] = max(0, self._outstanding[source] - 1)
        if tag == ABANDONED:
            error = {"kind": "abandoned", "message": "a signal stopped it", "traceback": ""}
            return Reply(message, None, error, source, socket.gethostname(), 0.0)
        return message

    def _stop_all(self, grace: float, on_reply=None) -> bool:
        """STOP to every worker, then take replies (to ``on_reply``) and the
        workers' STOPPED answers for up to ``grace`` seconds (a further signal
        shortens the wait); True if all answered."""
        from mpi4py import MPI

        waiting = set(self._outstanding)
        with signals.deferred():
            for rank in waiting:
                self._sends.append(self.comm.isend(None, dest=rank, tag=STOP))
        status = MPI.Status()
        deadline = time.monotonic() + grace
        seen = signals.count()
        backoff = Backoff()
        while waiting and time.monotonic() < deadline:
            if signals.count() > seen:  # a second Ctrl-C: do not wait the whole grace
                seen = signals.count()
                deadline = min(deadline, time.monotonic() + HURRY_S)
            if not self.comm.Iprobe(source=MPI.ANY_SOURCE, tag=MPI.ANY_TAG, status=status):
                backoff.sleep()
                continue
            backoff.reset()
            source, tag = status.Get_source(), status.Get_tag()
            if tag in (STOPPED, LEFT):
                self.comm.recv(source=source, tag=tag)
                if tag == STOPPED:
                    waiting.discard(source)
            else:
                reply = self._take(source, tag)
                if on_reply is not None:
                    on_reply(reply)
        if not waiting:  # every worker received all it was sent, STOP last
            for request in self._sends:
                request.Wait()
            self._sends = []
        return not waiting

    def interrupt(self, grace: float, on_reply) -> bool:
        """Stop handing out work and end every worker; results that still arrive go
        to ``on_reply``. False if some worker did not stop within ``grace``."""
        self._stopped = self._stop_all(grace, on_reply)
        return self._stopped

    def shutdown(self, abort: bool = False) -> None:
        if not abort and not self._stopped:
            self._stopped = self._stop_all(grace=60.0)
            abort = not self._stopped
        if abort:
            self.comm.Abort(3)  # the last resort: a worker that would not stop


def mpi_worker_loop(comm) -> None:
    """A worker rank: wait for the job, then take tasks until told to stop. A
    signal abandons the task being computed (the master redoes it on resume); a
    signalled worker then leaves (``_leave``)."""
    with signals.deferred():
        _worker(comm)


def _probe(comm, status, backoff: Backoff) -> bool:
    """Wait for the master's next message; False if a signal came first."""
    from mpi4py import MPI

    backoff.reset()
    while not comm.Iprobe(source=0, tag=MPI.ANY_TAG, status=status):
        if signals.received() is not None:
            return False
        backoff.sleep()
    return True


def _worker(comm) -> None:
    from mpi4py import MPI

    from .jobs import JobSpec

    status = MPI.Status()
    backoff = Backoff()
    message = None
    while True:  # the job first (a STOP cannot come before it)
        if not _probe(comm, status, backoff):
            return _leave(comm, status, backoff)
        message = comm.recv(source=0, tag=status.Get_tag())
        if status.Get_tag() == JOB:
            break
    if message is None:  # the master refused the job before any work
        return None
    job = JobSpec.model_validate_json(message)
    try:
        with signals.interruptible():
            prepare(job)  # rank 0 has compiled the kernels into numba's cache
    except Interrupted:
        return _leave(comm, status, backoff)
    rank = comm.Get_rank()
    while True:
        if not _probe(comm, status, backoff):
            return _leave(comm, status, backoff)
        message = comm.recv(source=0, tag=status.Get_tag())
        if status.Get_tag() == STOP:
            comm.send(None, dest=0, tag=STOPPED)
            return None
        task, zero = message
        if comm.Iprobe(source=0, tag=STOP):
            comm.send(task.task_id, dest=0, tag=ABANDONED)  # stopping: not started
            continue
        try:
            with signals.interruptible():
                reply = execute(job, task, zero, rank)
        except Interrupted:
            comm.send(task.task_id, dest=0, tag=ABANDONED)
            return _leave(comm, status, backoff)
        comm.send(reply, dest=0, tag=REPLY)


def _leave(comm, status, backoff: Backoff) -> None:
    """A signalled worker: tell the master (LEFT), answer the tasks it still sends
    with ABANDONED and leave at its STOP, or after LEAVE_WAIT_S without one."""
    from mpi4py import MPI

    comm.send(int(signals.received() or signal.SIGTERM), dest=0, tag=LEFT)
    deadline = time.monotonic() + LEAVE_WAIT_S
    backoff.reset()
    while time.monotonic() < deadline:
        if not comm.Iprobe(source=0, tag=MPI.ANY_TAG, status=status):
            backoff.sleep()
            continue
        tag = status.Get_tag()
        message = comm.recv(source=0, tag=tag)
        if tag == STOP:
            comm.send(None, dest=0, tag=STOPPED)
            return
        if tag == TASK:
            comm.send(message[0].task_id, dest=0, tag=ABANDONED)
        elif tag == JOB and message is None:
            return  # the master stopped before handing out the job
