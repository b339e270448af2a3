"""What a worker does with one task, and the small protocol around it.

A task is a value (``PointTask`` or ``SweepTask`` plus, for a sweep, its
point's zero-force record); a reply is ``Reply(task_id, record, error, rank,
host, seconds)``. Records are flat dicts of numbers, strings and numpy arrays:
exactly what the master writes to HDF5. A failing task never takes the run down:
its exception comes back as an error with the traceback, rank and host.
"""

from __future__ import annotations

import contextlib
import signal
import socket
import time
import traceback
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..relax import CONVERGED, NOT_KNITTABLE, Relaxation
from .jobs import JobSpec, PointTask, SweepTask

DONE, FAILED = "done", "failed"
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
    """Raise ``TaskTimeout`` in this (main) thread after ``seconds``."""

    def _alarm(signum, frame):
        raise TaskTimeout(f"task exceeded its wall-time budget of {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def execute(job: JobSpec, task: PointTask | SweepTask, zero: dict | None, rank: int) -> Reply:
    """Run one task under the job's wall-time budget; never raises."""
    from threadpoolctl import threadpool_limits

    t0 = time.perf_counter()
    host = socket.gethostname()
    try:
        with threadpool_limits(1), wall_time_budget(job.run.task_timeout_s):
            if isinstance(task, PointTask):
                record = run_point(job, task)
            else:
                assert zero is not None, "a sweep needs its point's zero-force record"
                record = run_sweep(job, task, zero)
        return Reply(task.task_id, record, None, rank, host, time.perf_counter() - t0)
    except Exception as e:  # isolation: a failing task never takes the run down
        e = _signal_cause(e)
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


def run_point(job: JobSpec, task: PointTask) -> dict[str, Any]:
    from ..model import CellModel
    from ..zero_force import zero_force

    zf = zero_force(task.params, job.fidelity, job.solver, job.starts, task.seed)
    record = zero_force_record(zf)
    best = zf.best
    model = CellModel(task.params, job.fidelity)
    record["status"] = _STATUS.get(zf.status, FAILED)
    record["message"] = zf.message
    if np.all(np.isfinite(best.x)):
        record["thickness"] = model.thickness(best.x)
        if job.store.contact_forces:
            record["contact_forces"] = model.contact_forces_by_class(best.x)
    return record


def zero_force_record(zf) -> dict[str, Any]:
    """The zero-force result as storable arrays (every start, and the winner)."""
    rs: tuple[Relaxation, ...] = zf.relaxations
    return {
        "winner": zf.winner,
        "labels": np.array(zf.labels, dtype=object),
        "stages": np.array(zf.stages, dtype=np.int64),
        "x": np.array([r.x for r in rs]),
        "bending_energy": np.array([r.bending_energy for r in rs]),
        "contact_energy": np.array([r.contact_energy for r in rs]),
        "length": np.array([r.length for r in rs]),
        "start_status": np.array([r.status for r in rs], dtype=object),
        "start_message": np.array([r.message for r in rs], dtype=object),
        "iterations": np.array([r.iterations for r in rs], dtype=np.int64),
        "evaluations": np.array([r.evaluations for r in rs], dtype=np.int64),
        "min_zeta": np.array([r.min_zeta for r in rs]),
        "kkt_residual": np.array([r.kkt_residual for r in rs]),
        "length_residual": np.array([r.length_residual for r in rs]),
        "twist_active": np.array([r.twist_active for r in rs]),
        "relax_seconds": np.array([r.seconds for r in rs]),
    }


def zero_force_from_record(rec: dict[str, Any]):
    """Rebuild the ``ZeroForce`` a sweep needs from a stored record."""
    from ..zero_force import ZeroForce

    rs = []
    for i in range(len(rec["x"])):
        rs.append(
            Relaxation(
                x=np.asarray(rec["x"][i], dtype=float),
                bending_energy=float(rec["bending_energy"][i]),
                contact_energy=float(rec["contact_energy"][i]),
                length=float(rec["length"][i]),
                status=str(rec["start_status"][i]),
                message=str(rec["start_message"][i]),
                iterations=int(rec["iterations"][i]),
                evaluations=int(rec["evaluations"][i]),
                length_residual=float(rec["length_residual"][i]),
                twist_margin=float("nan"),
                twist_active=bool(rec["twist_active"][i]),
                min_zeta=float(rec["min_zeta"][i]),
                kkt_residual=float(rec["kkt_residual"][i]),
                length_multiplier=float("nan"),
                period_forces=(0.0, 0.0),
                seconds=float(rec["relax_seconds"][i]),
            )
        )
    status = CONVERGED if rec["status"] == DONE else str(rec["status"])
    return ZeroForce(tuple(rs), tuple(map(str, rec["labels"])), tuple(rec["stages"]),
                     int(rec["winner"]), status, str(rec["message"]))  # fmt: skip


# ---- sweeps ---------------------------------------------------------------------


def run_sweep(job: JobSpec, task: SweepTask, zero: dict[str, Any]) -> dict[str, Any]:
    from ..model import CellModel
    from ..strain_sweep import strain_sweep

    params = zero["params"]
    zf = zero_force_from_record(zero)
    result = strain_sweep(params, zf, task.direction, job.protocol, job.fidelity, job.solver)
    # an 'incomplete' sweep (step limit) still holds valid steps; its sweep_status says so
    status = {"done": DONE, "incomplete": DONE, "not_knittable": NOT_KNITTABLE}
    record: dict[str, Any] = {
        "status": status.get(result.status, FAILED),
        "message": result.stop_reason,
        "sweep_status": result.status,
        "relaxations": result.relaxations,
        "wall_seconds": result.wall_seconds,
    }
    arrays = result.arrays()
    states = arrays.pop("states")
    record.update(arrays)
    record["total_energy"] = result.total_energy
    if job.store.states:
        record["states"] = states
    if job.store.geometry or job.store.contact_forces:
        model = CellModel(params, job.fidelity)
        if job.store.geometry:
            record["control_points"] = np.array([model.control_points(x) for x in states])
        if job.store.contact_forces:
            record["contact_forces"] = np.array([model.contact_forces_by_class(x) for x in states])
    return record
