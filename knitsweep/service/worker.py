"""What a worker does with one task, and the small protocol around it.

A task is a value (``PointTask`` or ``SweepTask`` plus, for a sweep, its
point's zero-force record); a reply is ``Reply(task_id, record, error, rank,
host, seconds)``. Records are flat dicts of numbers, strings and numpy arrays,
finished here (energy gaps included): exactly what the master writes to HDF5.
A failing task never takes the run down: its exception comes back as an error
with the traceback, rank and host.
"""

from __future__ import annotations

import contextlib
import signal
import socket
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import CONVERGED, DONE, FAILED, NOT_KNITTABLE
from ..quantities import registered
from . import signals
from .jobs import JobSpec, PointTask, SweepTask

_STATUS = {CONVERGED: DONE, NOT_KNITTABLE: NOT_KNITTABLE}


class TaskTimeout(Exception):
    """The task ran past its wall-time budget."""


@dataclass(frozen=True)
class Reply:
    task_id: str
    record: dict[str, Any] | None
    error: dict[str, Any] | None
    rank: int
    host: str
    seconds: float


@contextlib.contextmanager
def wall_time_budget(seconds: float):
    """Raise ``TaskTimeout`` in this (main) thread after ``seconds``; yields the
    exception once raised (a list, empty until then), so that a caller knows the
    budget ran out even if the code it interrupted wrapped or replaced it."""
    raised: list[TaskTimeout] = []

    def _alarm(signum, frame):
        raised.append(TaskTimeout(f"task exceeded its wall-time budget of {seconds:g} s"))
        raise raised[-1]

    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield raised
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def prepare(
    job: JobSpec,
    notice: Callable[[str], None] | None = None,
    between: Callable[[], None] | None = None,
) -> float:
    """Compile (or load from numba's cache) the kernels this job's tasks use;
    ``notice`` hears first if that means compiling (see ``compile_kernels``), or
    waiting for another process that compiles them (``compile_lock``). ``between``
    is called between kernels (the MPI master: has a worker left on a signal?). The lock
    is only taken while the cache lacks the kernels: ranks that find them cached
    load them side by side. Returns the seconds spent compiling (0.0 when every
    kernel was cached)."""
    from ..compilation import compile_kernels
    from ..relax import single_threaded
    from ..stitches import get_stitch

    for name in job.stitches:  # read now, so that no task opens a file under its budget
        get_stitch(name).shipped_starts()
    with single_threaded():  # (its BLAS inspection reads /proc/self/maps, once)
        pass
    compiled = []

    def heard(message: str) -> None:
        compiled.append(message)
        if notice is not None:
            notice(message)

    def each_kernel() -> None:
        signals.check()  # a signal whose exception numba swallowed (see below) ends it here
        if between is not None:
            between()
        signals.fault_point("kernel")

    signals.fault_point("compiling")  # (the tests' injector arms its llvm point here)
    t0 = time.perf_counter()
    try:
        if not kernels_cached(job):
            with compile_lock(notice, job):
                if not kernels_cached(job):  # nobody compiled them while this one waited
                    compile_kernels(job.fidelity, heard, job.stitches, each_kernel=each_kernel)
        # loads them (at once if just compiled)
        compile_kernels(job.fidelity, heard, job.stitches, each_kernel=each_kernel)
    except Exception:
        # A signal that lands while LLVM emits code is raised inside llvmlite's ctypes
        # callback, which swallows it: numba then misses that module's code and fails
        # later ("RuntimeError: no compiled object yet"). The signal was recorded:
        # the compile was interrupted, whatever numba raises after it.
        if signals.received() is None:
            raise
        raise signals.Interrupted(signals.received()) from None
    return time.perf_counter() - t0 if compiled else 0.0


@contextlib.contextmanager
def compile_lock(notice: Callable[[str], None] | None = None, job: JobSpec | None = None):
    """Hold the lock file beside numba's kernel cache (``<cache dir>.lock``) while
    the kernels are compiled. With a node-local cache (``NUMBA_CACHE_DIR``
    on a node's /tmp, as the SLURM templates set it) the first rank of a node to
    come compiles, once, and the node's other ranks wait and then load its
    cache, instead of every rank compiling at once. Blocking, but a signal
    interrupts the wait (under ``signals.interruptible``). Without a writable
    cache directory there is nothing to share, so no lock. ``job``: whose kernels the
    notice of a wait is about (None: those every task calls)."""
    import fcntl
    import os

    import numba

    from .. import kernels  # sets numba.config.CACHE_DIR

    path = numba.config.CACHE_DIR.rstrip(os.sep) + ".lock"
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if notice is not None and not (kernels.cached() if job is None
                                           else kernels_cached(job)):  # fmt: skip
                notice(
                    f"waiting for another process of this host to compile the kernels (lock {path})"
                )
            fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


def kernels_cached(job: JobSpec) -> bool:
    """Whether numba's on-disk cache holds the kernels of the job's tasks already: a
    master that does not compute then need not load them (its workers do, at the same
    time)."""
    from ..compilation import kernel_entry_points
    from ..kernels import cached

    return cached(kernel_entry_points(job.stitches))


def stderr_notice(message: str) -> None:
    """A one-line notice for the person running the job."""
    import sys

    print(message, file=sys.stderr, flush=True)


def execute(job: JobSpec, task: PointTask | SweepTask, zero: dict | None, rank: int) -> Reply:
    """Run one task under the job's wall-time budget, single-threaded; never raises."""
    from ..relax import single_threaded

    t0 = time.perf_counter()
    host = socket.gethostname()
    timed_out: list[TaskTimeout] = []
    try:
        with single_threaded(), wall_time_budget(job.run.task_timeout_s) as timed_out:
            if isinstance(task, PointTask):
                record = run_point(job, task, zero)
            else:
                assert zero is not None, "a sweep needs its point's zero-force record"
                record = run_sweep(job, task, zero)
        return Reply(task.task_id, record, None, rank, host, time.perf_counter() - t0)
    except Exception as e:  # isolation: a failing task never takes the run down
        e = _signal_cause(e)
        if timed_out and not isinstance(e, TaskTimeout):  # interrupted code replaced it
            e = timed_out[0]
        kind = "timeout" if isinstance(e, TaskTimeout) else type(e).__name__
        error = {"kind": kind, "message": str(e), "traceback": traceback.format_exc()}
        return Reply(task.task_id, None, error, rank, host, time.perf_counter() - t0)


def _signal_cause(e: Exception) -> Exception:
    """The exception a signal handler raised, if ``e`` wraps one.

    A handler that raises while a numba dispatcher returns surfaces as
    "SystemError: ... returned a result with an exception set", with the handler's
    exception in the cause chain. An interrupt (a BaseException) is re-raised as
    itself; a timeout is returned so that it is recorded as one.
    """
    seen: BaseException | None = e
    while seen is not None:
        if not isinstance(seen, Exception):
            raise seen from None
        if isinstance(seen, TaskTimeout):
            return seen
        seen = seen.__cause__ or seen.__context__
    return e


# ---- zero-force -----------------------------------------------------------------


def run_point(job: JobSpec, task: PointTask, carried: dict | None = None) -> dict[str, Any]:
    """The zero-force record of one point (``ZeroForce.to_record`` plus the task
    status, the winner's registered point observables (``quantities.registered``) and, if
    stored, its contact forces). ``carried``
    (``[starts] carry``): the state ``x`` and ``params`` of the point it starts from."""
    from ..relax.zero_force import Start, start_states, zero_force
    from .retry import retry_failed_starts
    from .spread import point_spread

    start = None if carried is None else (np.asarray(carried["x"]), carried["params"])
    zf = zero_force(task.params, job.fidelity, job.solver, job.starts, task.seed, carried=start)
    if start is not None:
        begin = [Start("carried", *start)]
    else:
        begin = start_states(job.starts, task.seed, job.fidelity, task.params.stitch)
    zf, retried, note = retry_failed_starts(zf, [(s.x, s.params) for s in begin], task.params,
                                            job.fidelity, job.solver, job.starts, task.seed)  # fmt: skip
    record = point_record(job, task.params, zf)
    record |= point_spread(job, task.params, zf, [(s.x, s.params) for s in begin], task.seed)
    if note:
        record["retried"] = retried
        record["retry_message"] = note
    return record


def point_record(job: JobSpec, params: Any, zf: Any) -> dict[str, Any]:
    """A point's record from its zero-force state ``zf`` (``ZeroForce``): its
    ``to_record`` plus the task status, the winner's energy (``rest_energy``, mJ) and
    thickness and, if stored, its contact forces and the packing fractions."""
    from ..model import CellModel

    record = zf.to_record()
    record["status"] = _STATUS.get(zf.status, FAILED)
    best = zf.best
    model = CellModel(params, job.fidelity)
    if np.all(np.isfinite(best.x)):
        record["rest_energy"] = best.total_energy
        for observable in registered("point"):  # the winner's (``thickness`` …)
            record[observable.name] = getattr(model, observable.method)(best.x)
        if job.store.contact_forces:
            record["contact_forces"] = model.contact_forces_by_class(best.x)
    if job.store.packing_fraction:
        record |= _packing_fractions(model, [r.x for r in zf.relaxations])
    return record


def _packing_fractions(model: Any, states: Any) -> dict[str, np.ndarray]:
    """``packing_fraction`` and ``packing_fraction_error`` (n,) of states (n, n_state)
    (docs/model.md §9, paper SI "Contact Volumes"; over the stitch's mirrored images, §11);
    NaN where a state is not finite."""
    from ..analysis.volumes import packing_fraction

    phi = np.full(len(states), np.nan)
    err = np.full(len(states), np.nan)
    seen: dict[bytes, tuple[float, float]] = {}  # merged chains repeat a state
    for i, x in enumerate(states):
        x = np.asarray(x, dtype=float)
        if np.all(np.isfinite(x)):
            key = x.tobytes()
            if key not in seen:
                seen[key] = packing_fraction(model.control_points(x),
                                             *model.stitch.cell_periods(x), model.params.r_mm,
                                             model.stitch.mirror_parity)  # fmt: skip
            phi[i], err[i] = seen[key]
    return {"packing_fraction": phi, "packing_fraction_error": err}


# ---- sweeps ---------------------------------------------------------------------

REST_POINT = "rest_point"
"""Key of a sweep record that holds its point's new record: the sweep found a lower
zero-force state and started over from it (``strain_sweep``)."""

_SWEEP_STATUS = {"done": DONE, "incomplete": DONE, "not_knittable": NOT_KNITTABLE}
"""Task status of a sweep: an 'incomplete' sweep (step limit) still holds valid
steps; its ``sweep_status`` says so."""


def run_sweep(job: JobSpec, task: SweepTask, zero: dict[str, Any]) -> dict[str, Any]:
    """The record of one sweep (``SweepResult.to_record`` plus the task status and
    the optional per-step observables); ``zero`` is its point's stored record."""
    from ..model import CellModel
    from ..relax.zero_force import ZeroForce
    from ..strain_sweep import strain_sweep
    from .spread import sweep_spread

    params = zero["params"]
    zf = ZeroForce.from_record(zero)
    result = strain_sweep(params, zf, task.direction, job.protocol, job.fidelity, job.solver)
    record = result.to_record()
    record["status"] = _SWEEP_STATUS.get(result.status, FAILED)
    if record["status"] == DONE:
        rest = zf if result.rest is None else result.rest
        record |= sweep_spread(job, params, rest, task.direction, record, int(task.task_id, 16),
                               zero.get("spread_x"))  # fmt: skip
    if result.rest is not None:  # the point's zero-force state from now on (master)
        record[REST_POINT] = point_record(job, params, result.rest) | {
            "rest_found_by": f"{task.direction} sweep",
            "rest_fall_mJ": zf.best.total_energy - result.rest.best.total_energy,
        }
        record["message"] += (f"; started over {result.rest_restarts}x from a lower "
                              "zero-force state")  # fmt: skip
    states = record.pop("states")
    if job.store.states:
        record["states"] = states
    if job.store.geometry or job.store.contact_forces or job.store.packing_fraction:
        model = CellModel(params, job.fidelity)
        if job.store.packing_fraction:
            record |= _packing_fractions(model, states)
        if job.store.geometry:
            record["control_points"] = np.array([model.control_points(x) for x in states])
        if job.store.contact_forces:
            record["contact_forces"] = np.array([model.contact_forces_by_class(x) for x in states])
    return record
