"""The MPI executor (``executors.Executor``): rank 0's side and the workers' loop.

MPI protocol (rank 0 is the master, ranks 1..N-1 work), point to point only (no
collective that a signalled rank could leave the others stuck in): the master
compiles the kernels, then sends the job tagged JOB to every worker (``None``: no
job, leave); then lists of ``(task, zero)`` values tagged TASK go out and lists of
``Reply`` values tagged REPLY come back (batches: one message carries every task
the master hands a worker at once, and every reply a worker has ready); ``None``
tagged STOP ends a worker, which answers STOPPED before it leaves; tasks a worker
dropped on a signal (or had not started at STOP) come back as a list of task ids
tagged ABANDONED.

Each worker holds a queue of about ``QUEUE_S`` seconds of work (at least PREFETCH
tasks, at most MAX_DEPTH; the master measures the task times), so it starts the
next task the moment it finishes one, and sends its replies when half its queue is
done (or REPLY_EVERY_S has passed): the master refills the queue while the worker
computes the other half, and no task waits on a round trip. Both sides wait with
``Iprobe`` and a short sleep (one ``Backoff``) instead of a blocking receive,
because MPICH's blocking receive spins a core: with ``mpirun -n 3`` on 2 cores the
master must leave both cores to the workers.

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
import math
import socket
import time

from .. import signals
from ..signals import Interrupted
from ..worker import Reply, execute, kernels_cached, prepare, stderr_notice
from .protocol import (
    ABANDONED,
    JOB,
    LEFT,
    REPLY,
    STOP,
    STOPPED,
    TASK,
    Backoff,
    _leave,
    release_workers,
)

__all__ = ["MPIExecutor", "mpi_worker_loop", "release_workers"]

PREFETCH = 2  # tasks held by each MPI worker at least: the one it computes and the next
MAX_DEPTH = 64  # … and at most
QUEUE_S = 0.05  # seconds of work each worker holds (from the measured task times)
REPLY_EVERY_S = 0.02  # a worker sends the replies it has at least this often
HURRY_S = 2.0  # a second signal while the workers stop: wait at most this much longer


class MPIExecutor:
    """Rank 0's side of the MPI protocol; ranks 1..N-1 run ``mpi_worker_loop``.
    The first task compiles the kernels (interruptible) and hands the job out; a
    run with nothing to compute releases the workers at once."""

    def __init__(self, job, comm) -> None:
        self.job = job
        self.comm = comm
        self._outstanding: dict[int, int] = dict.fromkeys(range(1, comm.Get_size()), 0)
        self._queued: dict[int, list] = {rank: [] for rank in self._outstanding}  # not sent
        self._ready: collections.deque = collections.deque()  # received, not yet taken
        self._left: set[int] = set()
        self._sends: list = []  # requests of tasks not yet received by their worker
        self._stopped = False
        self._task_s: float | None = None  # running mean of the tasks' compute time
        self._started = False

    def _start(self) -> None:
        with signals.interruptible():  # compile once, into numba's cache, before the workers
            signals.fault_point("compile")
            if not kernels_cached(self.job):  # (cached: the workers load them, all at once)
                self.compile_seconds = prepare(self.job, stderr_notice, self._worker_left)
            signals.fault_point("broadcast")
        with signals.deferred():
            for rank in self._outstanding:
                self.comm.send(self.job.model_dump_json(), dest=rank, tag=JOB)
        signals.mpi_handshake_done()
        self._started = True

    def _worker_left(self) -> None:
        """While this rank compiles (minutes on a cold cache): a worker that a signal of
        its own ended (LEFT) stops the run now, not once the compile is over (it waits
        for the job's hand-out only LEAVE_WAIT_S)."""
        from mpi4py import MPI

        status = MPI.Status()
        if self.comm.Iprobe(source=MPI.ANY_SOURCE, tag=LEFT, status=status):
            signum = self.comm.recv(source=status.Get_source(), tag=LEFT)
            self._left.add(status.Get_source())
            signals.request(signum)
            raise Interrupted(signum)

    @property
    def depth(self) -> int:
        """Tasks each worker holds: about QUEUE_S seconds of work, PREFETCH..MAX_DEPTH."""
        if self._task_s is None:
            return PREFETCH
        return int(min(MAX_DEPTH, max(PREFETCH, math.ceil(QUEUE_S / max(self._task_s, 1e-6)))))

    @property
    def capacity(self) -> int:
        return self.depth * (len(self._outstanding) - len(self._left))

    @property
    def in_flight(self) -> int:
        return sum(self._outstanding.values()) + len(self._ready)

    def submit(self, task, zero: dict | None) -> None:
        signals.fault_point("handout")  # (deferred here: the master's loop sees it)
        if not self._started:
            self._start()
        live = [r for r in self._outstanding if r not in self._left]
        rank = min(live, key=self._outstanding.__getitem__)
        self._queued[rank].append((task, zero))
        self._outstanding[rank] += 1
        if len(self._queued[rank]) >= max(1, self.depth // 2):
            self._flush(rank)

    def _flush(self, rank: int | None = None) -> None:
        """Send the queued tasks, one message per worker (isend: a large batch must
        not block the master until its worker takes it)."""
        self._sends = [r for r in self._sends if not r.Test()]
        for r in self._queued if rank is None else (rank,):
            if self._queued[r]:
                self._sends.append(self.comm.isend(self._queued[r], dest=r, tag=TASK))
                self._queued[r] = []

    def next_reply(self, timeout: float, idle=None) -> Reply | None:
        from mpi4py import MPI

        if self._ready:
            return self._ready.popleft()
        self._flush()
        status = MPI.Status()
        deadline = time.monotonic() + timeout
        backoff = Backoff()
        first = True
        while True:
            if self.comm.Iprobe(source=MPI.ANY_SOURCE, tag=MPI.ANY_TAG, status=status):
                source, tag = status.Get_source(), status.Get_tag()
                if tag != LEFT:
                    self._ready.extend(self._take(source, tag))
                    return self._ready.popleft() if self._ready else None
                signum = self.comm.recv(source=source, tag=LEFT)
                self._left.add(source)  # it waits for STOP; the run stops as on a signal
                signals.request(signum)
                return None
            if first and idle is not None:
                idle()  # nothing came: the master commits before it waits
                first = False
                continue
            if time.monotonic() >= deadline:
                return None
            backoff.sleep()

    def _take(self, source: int, tag: int) -> list[Reply]:
        """Receive a REPLY or ABANDONED message; an abandoned task becomes a Reply
        with error kind 'abandoned', which the runner queues again."""
        message = self.comm.recv(source=source, tag=tag)
        self._outstanding[source] = max(0, self._outstanding[source] - len(message))
        if tag == ABANDONED:
            error = {"kind": "abandoned", "message": "a signal stopped it", "traceback": ""}
            host = socket.gethostname()
            return [Reply(task_id, None, error, source, host, 0.0) for task_id in message]
        for reply in message:
            s = float(reply.seconds)
            self._task_s = s if self._task_s is None else 0.8 * self._task_s + 0.2 * s
        return message

    def _stop_all(self, grace: float, on_reply=None, code: int = 0) -> bool:
        """STOP to every worker, then take replies (to ``on_reply``) and the
        workers' STOPPED answers for up to ``grace`` seconds (a further signal
        shortens the wait); True if all answered. Tasks not yet sent are dropped
        (they are redone on resume)."""
        from mpi4py import MPI

        if not self._started:  # the workers still wait for the job: there is none
            release_workers(self.comm, code or None)
            self._started = True
            return True
        for rank, tasks in self._queued.items():
            self._outstanding[rank] -= len(tasks)
            tasks.clear()
        while self._ready:
            reply = self._ready.popleft()
            if on_reply is not None:
                on_reply(reply)
        waiting = set(self._outstanding)
        with signals.deferred():
            for rank in waiting:
                self._sends.append(self.comm.isend(code, dest=rank, tag=STOP))
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
                for reply in self._take(source, tag):
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
        self._stopped = self._stop_all(grace, on_reply, signals.EXIT_INTERRUPTED)
        return self._stopped

    def shutdown(self, abort: bool = False) -> None:
        if not abort and not self._stopped:
            self._stopped = self._stop_all(grace=60.0)
            abort = not self._stopped
        if abort:
            self.comm.Abort(3)  # the last resort: a worker that would not stop


def mpi_worker_loop(comm) -> int:
    """A worker rank: wait for the job, then take tasks until told to stop; returns
    the run's exit code (3: interrupted, by a signal of its own or the master's). A
    signal abandons the task being computed (the master redoes it on resume); a
    signalled worker then leaves (``_leave``)."""
    signals.mpi_handshake_done()
    with signals.deferred():
        code = _worker(comm)
    return signals.EXIT_INTERRUPTED if signals.received() is not None else int(code or 0)


def _probe(comm, status, backoff: Backoff) -> bool:
    """Wait for the master's next message; False if a signal came first."""
    from mpi4py import MPI

    backoff.reset()
    while not comm.Iprobe(source=0, tag=MPI.ANY_TAG, status=status):
        if signals.received() is not None:
            return False
        backoff.sleep()
    return True


def _worker(comm) -> int | None:
    from mpi4py import MPI

    from ..jobs import JobSpec

    status = MPI.Status()
    backoff = Backoff()
    message = None
    while True:  # the job first (a STOP cannot come before it)
        if not _probe(comm, status, backoff):
            return _leave(comm, status, backoff)
        message = comm.recv(source=0, tag=status.Get_tag())
        if status.Get_tag() == JOB:
            break
    signals.fault_point("broadcast")  # recorded here; the compile below raises it
    if message is None or isinstance(message, int):  # no job: refused, or interrupted
        return message
    job = JobSpec.model_validate_json(message)
    try:
        with signals.interruptible():
            signals.fault_point("compile")
            # loads the cache rank 0 filled, if this node shares it; else one rank of
            # the node compiles (``worker.compile_lock``) and the others wait
            prepare(job, _rank_notice(comm.Get_rank()))
    except BaseException as e:  # a signal's exception may arrive wrapped (``as_interrupt``)
        if signals.as_interrupt(e) is None and signals.received() is None:
            raise
        return _leave(comm, status, backoff)
    return _serve(comm, job, status, backoff)


def _serve(comm, job, status, backoff: Backoff) -> int | None:
    """Compute the tasks the master sends, from a local queue; replies go back in
    batches (half the last batch of tasks done, REPLY_EVERY_S passed, or the queue
    empty: never while the master could be waiting on them for nothing)."""
    from mpi4py import MPI

    rank = comm.Get_rank()
    queue: collections.deque = collections.deque()
    replies: list[Reply] = []
    low = 0  # send the replies when the queue is down to this many tasks
    sent_at = time.monotonic()

    def send_replies() -> None:
        nonlocal replies, sent_at
        if replies:
            comm.send(replies, dest=0, tag=REPLY)
            replies = []
        sent_at = time.monotonic()

    while True:
        while not queue or comm.Iprobe(source=0, tag=MPI.ANY_TAG, status=status):
            if not queue:
                send_replies()  # before waiting: the master needs them
                if not _probe(comm, status, backoff):
                    return _leave(comm, status, backoff)
            tag = status.Get_tag()
            message = comm.recv(source=0, tag=tag)
            if tag == STOP:
                send_replies()
                if queue:  # stopping: not started
                    comm.send([task.task_id for task, _ in queue], dest=0, tag=ABANDONED)
                comm.send(None, dest=0, tag=STOPPED)
                return message  # the run's exit code
            if tag == TASK:
                queue.extend(message)
                low = len(queue) // 2
        task, zero = queue.popleft()
        try:
            with signals.interruptible():
                signals.fault_point("handout")
                reply = execute(job, task, zero, rank)
        except Interrupted:
            send_replies()
            comm.send([task.task_id] + [t.task_id for t, _ in queue], dest=0, tag=ABANDONED)
            return _leave(comm, status, backoff)
        replies.append(reply)
        if len(queue) <= low or time.monotonic() - sent_at >= REPLY_EVERY_S:
            send_replies()


def _rank_notice(rank: int):
    """``stderr_notice`` with this worker's rank and host in front."""
    host = socket.gethostname()
    return lambda message: stderr_notice(f"rank {rank} on {host}: {message}")
