"""The MPI protocol's tags and the steps a rank takes when it stops before its part:
light (no numpy, no kernels), so that a rank a signal stopped during its imports can
still release the others (``signals.quiet_exit``, ``leave_at_start_up``).

Rank 0 is the master, ranks 1..N-1 work; point to point only. JOB carries the job
(``None``: refused; an int: the exit code the workers leave with), TASK batches of
``(task, zero)``, REPLY batches of replies, STOP (with the run's exit code) ends a
worker, which answers STOPPED; ABANDONED returns the ids of tasks a worker dropped;
LEFT tells the master that a signalled worker leaves.
"""

from __future__ import annotations

import signal
import time

from .. import signals

TASK, REPLY, STOP, STOPPED, ABANDONED, JOB, LEFT = 1, 2, 3, 4, 5, 6, 7
LEAVE_WAIT_S = 10.0  # a worker that left on a signal waits this long for the master's STOP


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


def release_workers(comm, code: int | None = None) -> None:
    """Tell every MPI worker that there is no job: ``None`` (rank 0 refused it) or
    the exit code they leave with (3: rank 0 was interrupted before handing it out)."""
    with signals.deferred():
        for rank in range(1, comm.Get_size()):
            comm.send(code, dest=rank, tag=JOB)
    signals.mpi_handshake_done()


def leave_at_start_up(comm) -> None:
    """This rank ends before its part of the protocol (a signal during its imports,
    class creation or MPI_Init; ``signals.quiet_exit``): rank 0 releases the workers,
    a worker tells the master it LEFT and waits for its STOP (``_leave``), so that no
    rank waits for this one."""
    from mpi4py import MPI

    with signals.deferred():
        if comm.Get_rank() == 0:
            release_workers(comm, signals.EXIT_INTERRUPTED)
        else:
            _leave(comm, MPI.Status(), Backoff())


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
            comm.send([task.task_id for task, _ in message], dest=0, tag=ABANDONED)
        elif tag == JOB and (message is None or isinstance(message, int)):
            return  # the master stopped before handing out the job
