"""Where tasks run: in this process, in local processes, or on MPI ranks.

Every executor implements one interface, :class:`Executor` (after mpi4py.futures'
pool abstraction): the master submits ``(task, zero)`` pairs while
``in_flight < capacity``, takes replies with ``next_reply(timeout)``, and ends the
executor with ``interrupt(grace, on_reply)`` (a signal: stop the work, hand over
what still arrives) or ``shutdown(abort)`` (the run is over). The master does not
know which executor it has, so most sweep tests need no ``mpiexec``.

``open_executor`` is the one place that chooses: ``launch`` tells this process
whether it is an MPI worker rank (it then serves tasks and returns nothing) or the
process that runs the master, and with which communicator. ``knitsweep run``
(``runs.run``) calls the two and then the master, once each.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Literal, Protocol, runtime_checkable

from ...errors import InputError
from .. import signals
from ..signals import launched_by_mpi

if TYPE_CHECKING:
    from ..jobs import JobSpec, PointTask, SweepTask
    from ..worker import Reply

__all__ = ["Executor", "ExecutorKind", "MPIExecutor", "ProcessExecutor", "SerialExecutor",
           "launch", "launched_by_mpi", "mpi_worker_loop", "open_executor",
           "release_workers"]  # fmt: skip

ExecutorKind = Literal["auto", "serial", "processes", "mpi"]


@runtime_checkable
class Executor(Protocol):
    """What the master needs of a place where tasks run.

    ``capacity``: how many tasks it wants in flight (the master submits while
    ``in_flight < capacity``); ``submit`` hands over a task and, for a sweep, its
    point's zero-force record; ``next_reply`` waits up to ``timeout`` seconds for
    one reply (None if none came; a task dropped on a signal comes back with error
    kind 'abandoned' and is queued again), calling ``idle`` once before it would
    wait (the master then commits its journal batch); ``interrupt`` stops handing out work
    and ends the workers, passing results that still arrive to ``on_reply``
    (False if a worker did not stop within ``grace`` seconds); ``shutdown`` ends
    it after the run (``abort``: at once, the last resort)."""

    @property
    def capacity(self) -> int: ...

    @property
    def in_flight(self) -> int: ...

    def submit(self, task: PointTask | SweepTask, zero: dict | None) -> None: ...

    def next_reply(
        self, timeout: float, idle: Callable[[], None] | None = None
    ) -> Reply | None: ...

    def interrupt(self, grace: float, on_reply: Callable[[Reply], None]) -> bool: ...

    def shutdown(self, abort: bool = False) -> None: ...


def launch(kind: ExecutorKind):
    """Where this process stands: ``(comm, is_worker)``. ``comm`` is MPI_COMM_WORLD
    when the run uses MPI ranks (``kind`` 'mpi', or 'auto' under mpirun/srun with
    more than one rank), else None; ``is_worker`` is True on ranks 1..N-1."""
    if not (kind == "mpi" or (kind == "auto" and launched_by_mpi())):
        return None, False
    comm = _mpi_world()
    if comm.Get_size() > 1:
        return comm, comm.Get_rank() != 0
    if kind == "mpi":
        raise InputError("executor = 'mpi' needs at least 2 ranks (mpirun -n 2 or more)")
    return None, False


def _mpi_world():
    """MPI_COMM_WORLD; MPI_Init runs deferred: a signal during it is recorded, and
    rank 0 raises it only after it can release the workers (``runs.run``)."""
    with signals.deferred():
        signals.fault_point("mpi_init")
        try:
            from mpi4py import MPI
        except ImportError as e:
            if signals.received() is not None:
                raise signals.Interrupted(signals.received()) from None
            raise InputError(f"MPI could not start: {e}") from None
    return MPI.COMM_WORLD


def open_executor(job: JobSpec, kind: ExecutorKind, workers: int, comm=None) -> Executor:
    """The executor of a run: MPI ranks when ``comm`` is given (``launch``), else
    ``workers`` local processes ('processes', or 'auto' with workers > 1), else this
    process. Its first task compiles (or loads) the kernels the job uses and starts
    the workers (interruptible): a run with nothing left to compute starts none."""
    if comm is not None:
        from .mpi import MPIExecutor

        return MPIExecutor(job, comm)
    if kind == "processes" or (kind == "auto" and workers > 1):
        from .local import ProcessExecutor

        return ProcessExecutor(job, workers)
    from .local import SerialExecutor

    return SerialExecutor(job)


def __getattr__(name: str):
    if name in ("SerialExecutor", "ProcessExecutor"):
        from . import local

        return getattr(local, name)
    if name in ("MPIExecutor", "mpi_worker_loop", "release_workers"):
        from . import mpi

        return getattr(mpi, name)
    raise AttributeError(name)
