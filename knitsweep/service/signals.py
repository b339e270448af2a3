"""SIGINT and SIGTERM in every knitsweep process, from its first moment.

A signal is always *recorded* (``received()``); whether it also *raises*
``Interrupted`` depends on where the process is:

* ``interruptible()`` sections raise at once: start-up (imports, reading the
  job, compiling the kernels) and a task this process computes itself; whatever
  they were doing is redone on resume;
* everywhere else (the default once ``install`` ran, and ``deferred()``
  sections) the signal is only recorded, and the loops that own the process look
  at it: the master between replies, an idle MPI worker while it waits. So a
  journal entry, a checkpoint or an MPI message is never cut in half.

``knitsweep``'s entry point calls ``install(interruptible=True)`` before it
imports anything heavy, so a signal during start-up (MPI_Init included: it runs
``deferred``) ends the process with one line and exit code 3 instead of a
traceback. The state is per process (signals are), hence module-level.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable

SIGNALS = (signal.SIGINT, signal.SIGTERM)
EXIT_INTERRUPTED = 3
"""Exit code of an interrupted knitsweep command (a run keeps what it wrote)."""
MPI_ENV_HINTS = ("PMI_RANK", "PMI_SIZE", "PMI_FD", "PMIX_RANK", "OMPI_COMM_WORLD_SIZE",
                 "MPI_LOCALNRANKS", "HYDRA_CONTROL_FD")  # fmt: skip


def launched_by_mpi() -> bool:
    """True when this process was started by mpirun/mpiexec/srun --mpi."""
    return any(k in os.environ for k in MPI_ENV_HINTS)


class Interrupted(BaseException):
    """SIGINT/SIGTERM reached an interruptible section. A BaseException, so the task
    isolation (``worker.execute`` catches Exception) lets it through."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


_state = {"signum": None, "count": 0, "raise": False}


def _quiet(unraisable) -> None:
    """After an interrupt: objects whose construction the signal cut short (numba's
    compiler, llvmlite) may fail in ``__del__``; that is no news to the user."""


def _handler(signum, frame) -> None:
    _state["count"] += 1
    if _state["signum"] is None:
        _state["signum"] = signum
    if _state["raise"]:
        _state["raise"] = False  # raise once: the clean-up after it runs undisturbed
        _state["unraisablehook"] = _state.get("unraisablehook") or sys.unraisablehook
        sys.unraisablehook = _quiet
        raise Interrupted(signum)


def install(interruptible: bool = False) -> dict | None:
    """Handle SIGINT/SIGTERM in this process (main thread only); returns the handlers
    it replaced (for ``restore``), or None when ours were already installed. A fresh
    install forgets any earlier signal."""
    if threading.current_thread() is not threading.main_thread():
        return None
    if signal.getsignal(signal.SIGINT) is _handler:
        return None
    old = {s: signal.signal(s, _handler) for s in SIGNALS}
    _state.update({"signum": None, "count": 0, "raise": interruptible})
    return old


def restore(old: dict | None) -> None:
    """Put back the handlers ``install`` replaced; the signals they saw are handled
    (a later run in this process starts afresh)."""
    if old:
        for s, h in old.items():
            signal.signal(s, h)
        if _state.get("unraisablehook") is not None:
            sys.unraisablehook = _state.pop("unraisablehook")
        _state.update({"signum": None, "count": 0, "raise": False})


def as_interrupt(e: BaseException) -> Interrupted | None:
    """The ``Interrupted`` that ``e`` is or wraps, else None. A signal's exception
    raised inside library code may come out wrapped: Python wraps an exception raised
    in ``__set_name__`` during class creation (pydantic's models) in RuntimeError, and
    numba one raised as a dispatcher returns in SystemError; the original is then the
    ``__cause__`` or ``__context__`` of what arrives."""
    seen: BaseException | None = e
    for _ in range(20):  # cause chains are short; never loop on a cycle
        if seen is None:
            return None
        if isinstance(seen, Interrupted):
            return seen
        seen = seen.__cause__ or seen.__context__
    return None


STAGES = ("imports", "class", "mpi_init", "broadcast", "compile", "handout")
"""Start-up stages at which a test can have the signal arrive (``fault_point``; ``class``
is reached by the tests' injector inside JobSpec's class creation)."""
COMPILE_STAGES = ("kernel", "llvm")
"""Fault points inside the compile itself: ``kernel`` is reached before each kernel that
``compilation.compile_group`` compiles (or loads), so ``kernel#<n>`` is between the
(n-1)-th and the n-th; with a delay (``kernel#<n>+<seconds>``) the signal arrives while
numba compiles the n-th. ``llvm`` is reached (by the tests' injector, armed at the point
``compiling`` before the kernels compile) each time LLVM hands numba the machine code of a
module it compiled: the first Python code to run after LLVM's long stretch of C, so where
most signals sent during a compile land."""

injector: Callable[[str], None] | None = None
"""Called with the stage at each ``fault_point``: the tests' fault injector
(tests/fault_plugin, which sends this process a signal at the stage its test names), set
only in processes the tests start; None in every other process."""


def fault_point(stage: str) -> None:
    """A named point of the start-up or the compile (``STAGES``, ``COMPILE_STAGES``) at
    which the tests' fault injector, if installed, may have the signal arrive.

    The one test hook left in production code, and why: the signals under test land in
    child processes (the command line, MPI ranks), at points inside the functions that
    start a run, which a test cannot reach from outside; the injector itself (parsing
    KNITSWEEP_TEST_SIGNAL_AT, sending the signal) lives in the tests. Without one
    installed a point costs a global lookup and a comparison."""
    if injector is not None:
        injector(stage)


def mpi_handshake_done() -> None:
    """This rank has played its part of the MPI start-up (rank 0: the job handed out
    or the workers released; a worker: in its loop), so ``quiet_exit`` needs no more."""
    _state["mpi_done"] = True


def received() -> int | None:
    """The first signal received since ``install``, or None."""
    return _state["signum"]


def count() -> int:
    """How many signals arrived since ``install`` (a second Ctrl-C hurries the stop)."""
    return _state["count"]


def request(signum: int = signal.SIGTERM) -> None:
    """Act as if ``signum`` had arrived (an MPI worker left on a signal of its own)."""
    if _state["signum"] is None:
        _state["signum"] = signum


def check() -> None:
    """Raise ``Interrupted`` if a signal arrived."""
    if _state["signum"] is not None:
        raise Interrupted(_state["signum"])


@contextlib.contextmanager
def interruptible():
    """A section that a signal cuts short with ``Interrupted`` (raised at once if a
    signal came before it)."""
    check()
    old = _state["raise"]
    _state["raise"] = True
    try:
        yield
    finally:
        _state["raise"] = old


@contextlib.contextmanager
def deferred():
    """A section that a signal must not cut: it is only recorded (the section's own
    loops look at ``received()``, or the next ``check`` raises it)."""
    old = _state["raise"]
    _state["raise"] = False
    try:
        yield
    finally:
        _state["raise"] = old


def quiet_exit(leave=None) -> None:
    """The command is done: finish MPI (a signal then is only recorded), then ignore
    SIGINT/SIGTERM for the rest of the interpreter's teardown, where Python would
    put the default handlers back and a late signal would turn a finished run's
    exit code into a kill.

    Under mpirun a rank that a signal stopped before it started MPI still starts
    and finishes it: MPI_Init waits for every rank, and ranks already inside it
    would otherwise wait for this one for ever. ``leave(comm)`` is its part of the
    protocol for a rank that stops before it (the caller passes it:
    ``executors.leave_at_start_up``; this module sits below the executors)."""
    import sys

    _state["raise"] = False
    mpi = sys.modules.get("mpi4py.MPI")
    if mpi is None and launched_by_mpi():
        try:
            from mpi4py import MPI as mpi
        except ImportError:
            mpi = None  # MPI itself could not start: nothing to finish
    if mpi is not None and mpi.Is_initialized() and not mpi.Is_finalized():
        if not _state.get("mpi_done") and mpi.COMM_WORLD.Get_size() > 1 and leave is not None:
            leave(mpi.COMM_WORLD)  # the others must not wait for this rank
        mpi.Finalize()
    if threading.current_thread() is threading.main_thread():
        for s in SIGNALS:
            signal.signal(s, signal.SIG_IGN)
