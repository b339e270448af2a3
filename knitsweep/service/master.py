"""The master loop of ``knitsweep run``: schedule, collect, write, resume.

Each grid point's zero-force relaxation runs once; when it arrives, the point's
sweeps become ready and carry its record with them (a point that is failed or
not knittable passes its verdict to its sweeps without computing them).
Results go to the journal as they arrive, in batches (group commit: the master
commits whenever it would otherwise wait, so a batch holds what arrived during the
previous one's fsync), and into the HDF5 file at checkpoints (``store.writer``). A
result counts as finished (progress line, progress file) once its batch is durable. Running the same job again skips what is finished
(done, not_knittable, and failed unless ``retry_failed``) and redoes the rest.

On SIGTERM or SIGINT (``signals``: recorded, never cutting a write in half) the
master stops handing out work, writes what has arrived, closes the file and
returns exit code 3 (the CLI prints how to resume). A write that the disk refuses
mid-run (full, read-only) stops the run the same way, with one line naming the
cause; nothing already written is lost.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import sys
import time
from collections import deque
from pathlib import Path
from typing import Any

from ..config import DONE, FAILED, StitchParams
from ..errors import InputError, remedy
from ..store.format import POINTS, SERIES, SWEEPS, progress_path, split_record
from ..store.journal import StorageError, atomic_write_bytes
from ..store.writer import ResultWriter
from . import signals
from .adaptive import Refiner
from .jobs import JobSpec, PointTask, SweepTask, params_form, point_task, series_key, sweep_task
from .progress import RunProgress, task_line
from .run_plan import RunSummary, shard_tasks, varying_parameters
from .signals import Interrupted
from .worker import REST_POINT, Reply

COMMIT_AGE_S = 0.2
"""A result waits at most about this long for its batch's commit while replies keep
arriving (the master commits at once when it has nothing else to do)."""


class _Master:
    """Schedules tasks, records replies, and (adaptive jobs) refines each series.

    Everything goes through ``_request(point, directions)``: make sure these
    sweeps of this point get computed (its zero-force task first, if needed).
    """

    def __init__(self, job, points, writer, executor, summary, retry_failed, progress,
                 sweeps=()):  # fmt: skip
        self.job, self.writer, self.executor, self.summary = job, writer, executor, summary
        self._planned = {(s.point_id, s.direction): s for s in sweeps}  # ids hashed once
        self._described: dict[str, dict[str, Any]] = {}
        self.progress: RunProgress = progress
        self._last_file = 0.0
        self._unacknowledged: list[tuple] = []  # progress of results not yet durable
        self._oldest = 0.0  # when the oldest of them arrived
        self.points: dict[str, PointTask] = {}
        self.sweeps: dict[str, SweepTask] = {}
        self.sweeps_of: dict[str, list[SweepTask]] = {}  # waiting for their point
        self.ready_points: deque = deque()
        self.ready_sweeps: deque = deque()
        self.zero: dict[str, dict[str, Any]] = {}  # done points' records, while sweeps need them
        self.carries: dict[str, list[PointTask]] = {}  # ([starts] carry) waiting for a point
        self._planned_at = {(series_key(p.params), p.params.L_mm): p.task_id for p in points}
        self._refined_at: dict[tuple[str, float], str] = {}  # (refined series, L) -> point
        self.finished: dict[str, dict[str, dict[str, Any]]] = {POINTS: {}, SWEEPS: {}, SERIES: {}}
        for e in writer.entries():
            if str(e.meta.get("status")) != FAILED or not retry_failed or e.kind == SERIES:
                self.finished[e.kind][e.task_id] = e.meta
        self._redone: set[str] = set()  # sweeps to compute again: their point's rest moved
        for tid, meta in list(self.finished[SWEEPS].items()):
            point = self.finished[POINTS].get(str(meta.get("point_id")))
            if point is not None and self._stale(meta, point):
                del self.finished[SWEEPS][tid]  # pulled from a zero-force state since replaced
                self._redone.add(tid)
        self.refiner = Refiner(job) if job.mode == "adaptive" else None
        for p in points:
            self._request(p, job.directions)
        assert set(self.carries) <= set(self.points), "a carried point's neighbour is planned"
        if self.refiner is not None:
            for meta in self.finished[SWEEPS].values():
                self.refiner.observe(meta)
                if "point_id" in meta:  # where a resumed refinement carries from
                    params = StitchParams.from_flat(meta)
                    key = self.refiner.key(params, str(meta["direction"]))
                    self._refined_at[(key, params.L_mm)] = str(meta["point_id"])
            self._refine()

    # -- bookkeeping
    def _count(self, status: str) -> None:
        self.summary.counts[status] = self.summary.counts.get(status, 0) + 1

    @property
    def pending(self) -> int:
        waiting = sum(len(v) for v in self.sweeps_of.values())
        waiting += sum(len(v) for v in self.carries.values())
        return len(self.ready_points) + len(self.ready_sweeps) + waiting

    def _request(self, p: PointTask, directions) -> None:
        """Make sure the sweeps of point ``p`` in ``directions`` get computed."""
        pid = p.task_id
        new_point = pid not in self.points
        if new_point:
            self.points[pid] = p
            self.summary.total += 1
            self.progress.add_tasks("point", finished=pid in self.finished[POINTS])
            if pid in self.finished[POINTS]:
                self.summary.skipped += 1
                self._count(str(self.finished[POINTS][pid]["status"]))
        for d in directions:
            s = self._planned.get((pid, d)) or sweep_task(self.job, pid, d)
            if s.task_id in self.sweeps:
                continue
            self.sweeps[s.task_id] = s
            self.summary.total += 1
            self.progress.add_tasks("sweep", finished=s.task_id in self.finished[SWEEPS])
            if s.task_id in self.finished[SWEEPS]:
                self.summary.skipped += 1
                self._count(str(self.finished[SWEEPS][s.task_id]["status"]))
            elif pid in self.finished[POINTS]:
                self._release(s, self.finished[POINTS][pid])
            else:
                self.sweeps_of.setdefault(pid, []).append(s)
        if new_point and pid not in self.finished[POINTS]:
            if p.carried_from is None or p.carried_from in self.finished[POINTS]:
                self.ready_points.append((p, self._carried(p)))
            else:  # its series neighbour first (planned too: sharded by series)
                self.carries.setdefault(p.carried_from, []).append(p)

    def _carried(self, p: PointTask) -> dict[str, Any] | None:
        """What a point starts from: its neighbour's zero-force state and parameters
        (``[starts] carry``), or None (the shipped starts; also when the neighbour failed)."""
        pid = p.carried_from
        if pid is None or str(self.finished[POINTS][pid].get("status")) != DONE:
            return None
        zero = self._payload(pid)
        return {"x": zero["x"][int(zero["winner"])], "params": zero["params"]}

    def _release(self, s: SweepTask, point_meta: dict[str, Any]) -> None:
        """A sweep whose point is finished: queue it, or pass the point's verdict on."""
        status = str(point_meta.get("status", FAILED))
        if status == DONE:
            self.ready_sweeps.append((s, self._payload(s.point_id)))
            return
        meta = self._meta(s, status, f"zero-force state: {point_meta.get('message', status)}")
        self._record_sweep(s, {}, meta)
        self._finished("sweep", 0.0, self._line(s, status, 0.0), measured=False)

    def _finished(self, kind: str, seconds: float, line: str, measured: bool = True) -> None:
        """Report a result once its journal batch is durable (``_commit``)."""
        if not self._unacknowledged:
            self._oldest = time.monotonic()
        self._unacknowledged.append((kind, seconds, line, measured))

    def _commit(self) -> None:
        """Make the results added so far durable (one journal batch), then report them."""
        self.writer.commit()
        for kind, seconds, line, measured in self._unacknowledged:
            self.progress.finished(kind, seconds, line, measured=measured)
        self._unacknowledged = []

    def _payload(self, pid: str) -> dict[str, Any]:
        if pid not in self.zero:
            entry = self.writer.entry(POINTS, pid)
            self.zero[pid] = {**entry.record, **entry.meta}
        planned = self.points.get(pid)
        # a finished point this run never requested (a resumed refinement carries from
        # the refinement before it): its parameters as stored, the same floats
        params = planned.params if planned else StitchParams.from_flat(self.zero[pid])
        return {**self.zero[pid], "params": params}

    def _record_sweep(self, s: SweepTask, record: dict[str, Any], meta: dict[str, Any]) -> None:
        self.writer.add(SWEEPS, s.task_id, record, meta)
        self.finished[SWEEPS][s.task_id] = meta
        self._count(str(meta["status"]))
        if self.refiner is not None:
            if s.task_id in self._redone:  # its series' stored bracket may have used the old gap
                params = self.points[s.point_id].params
                self.finished[SERIES].pop(self.refiner.key(params, s.direction), None)
            self.refiner.observe(meta)
            self._refine()
        self._redone.discard(s.task_id)

    # -- a lower zero-force state found by a sweep (strain_sweep: "no hidden branch")
    def _stale(self, sweep_meta: dict[str, Any], point_meta: dict[str, Any]) -> bool:
        """Whether a sweep was pulled from a zero-force state higher (by more than the
        protocol's rest tolerance) than its point's present one."""
        pulled, rest = sweep_meta.get("rest_energy"), point_meta.get("rest_energy")
        if pulled is None or rest is None:  # written before sweeps checked their rest
            return False
        return float(pulled) > float(rest) + self.job.protocol.rest_tolerance_mJ

    def _new_rest(self, pid: str, record: dict[str, Any], found_by: SweepTask) -> None:
        """A sweep of point ``pid`` found a lower zero-force state and started over from
        it: ``record`` becomes the point's record (flagged ``rest_found_by``), and the
        point's other sweeps already recorded are computed again from it (those still
        running are when they come back, ``_handle``)."""
        record = dict(record)
        status, message = record.pop("status"), record.pop("message")
        arrays, scalars = split_record(record)
        meta = {**self.finished[POINTS][pid], "status": status, "message": message, **scalars}
        self.writer.add(POINTS, pid, arrays, meta)
        self.finished[POINTS][pid] = meta
        self.zero[pid] = {**arrays, **meta}
        for s in [s for s in self.sweeps.values() if s.point_id == pid and s is not found_by]:
            if s.task_id in self.finished[SWEEPS] and self._stale(self.finished[SWEEPS][s.task_id],
                                                                   meta):  # fmt: skip
                del self.finished[SWEEPS][s.task_id]
                self._redo(s)

    def _redo(self, s: SweepTask) -> None:
        """Compute sweep ``s`` again (from its point's present zero-force state): one
        more task for the counts and the display."""
        self._redone.add(s.task_id)
        self.summary.redone += 1
        self.summary.total += 1
        self.progress.add_tasks("sweep")
        self.ready_sweeps.append((s, self._payload(s.point_id)))

    def _refine(self) -> None:
        for key, state in self.refiner.states():
            if state.status == "refining":
                params, direction = self.refiner.point_params(key, state.next_L)
                p = point_task(self.job, params, self._carry_source(key, params, state.upper))
                self._refined_at[(key, params.L_mm)] = p.task_id
                self._request(p, [direction])
            elif state.finished and key not in self.finished[SERIES]:
                meta = self.refiner.series_meta(key, state)
                self.writer.add(SERIES, key, {}, meta)
                self.finished[SERIES][key] = meta

    def _carry_source(self, key: str, params, hi: float) -> str | None:
        """With ``[starts] carry``: the point a refinement starts from, the upper end of
        its series' bracket (refined by this series, or planned), so that the ids stay
        what they were whatever order the results came in."""
        if not self.job.starts.carry:
            return None
        return self._refined_at.get((key, hi)) or self._planned_at.get((series_key(params), hi))

    def _meta(self, task, status: str, message: str, reply: Reply | None = None) -> dict[str, Any]:
        pid = task.point_id if isinstance(task, SweepTask) else task.task_id
        described = self._described.get(pid)
        if described is None:  # a point's parameters (their id form, as files always held
            # them), dumped once for it and its sweeps
            params = self.points[pid].params
            described = {**params_form(params), "L_over_r": params.L_over_r}
            self._described[pid] = described
        meta: dict[str, Any] = {"status": status, "message": message, **described}
        if isinstance(task, SweepTask):
            meta |= {"point_id": task.point_id, "direction": task.direction}
        else:
            meta["seed"] = task.seed
        if reply is not None:
            meta |= {"rank": reply.rank, "host": reply.host, "seconds": reply.seconds}
            if reply.error is not None:
                meta |= {"error_kind": reply.error["kind"], "error_message": reply.error["message"],
                         "traceback": reply.error["traceback"]}  # fmt: skip
        return meta

    # -- the loop
    def run(self) -> str:
        last_checkpoint = time.monotonic()
        while self.ready_points or self.ready_sweeps or self.executor.in_flight:
            if signals.received() is not None:
                return "interrupted"
            while self.executor.in_flight < self.executor.capacity:
                # sweeps first: they complete points and free their zero-force records
                queue = self.ready_sweeps or self.ready_points
                if not queue:
                    break
                task, payload = queue.popleft()
                if isinstance(task, SweepTask):  # its point's zero-force state as it is now
                    payload = self._payload(task.point_id)
                self.executor.submit(task, payload)
            self.progress.setup_s = float(getattr(self.executor, "compile_seconds", 0.0))
            reply = self.executor.next_reply(timeout=0.25, idle=self._commit)
            if reply is not None:
                self._handle(reply)
            if self._unacknowledged and time.monotonic() - self._oldest > COMMIT_AGE_S:
                self._commit()
            if time.monotonic() - last_checkpoint > self.job.run.checkpoint_s:
                self.writer.checkpoint()
                last_checkpoint = time.monotonic()
            self._progress()
        self._commit()
        self._progress(force=True)
        return "complete"

    def _handle(self, reply: Reply) -> None:
        task = self.points.get(reply.task_id) or self.sweeps[reply.task_id]
        if reply.error is not None and reply.error["kind"] == "abandoned":
            # a worker dropped it on a signal: not a result; queue it again
            if isinstance(task, PointTask):
                self.ready_points.appendleft((task, self._carried(task)))
            else:
                self.ready_sweeps.appendleft((task, self._payload(task.point_id)))
            return
        if reply.error is None and isinstance(task, SweepTask):
            point = self.finished[POINTS].get(task.point_id, {})
            if REST_POINT not in reply.record and self._stale(reply.record, point):
                # pulled from a zero-force state that another sweep of the point has since
                # replaced by a lower one: not a result; compute it again from that one
                self.ready_sweeps.append((task, self._payload(task.point_id)))
                return
        if reply.error is not None:
            status = FAILED
            message = f"failed: {reply.error['kind']}: {reply.error['message']}"
            self.summary.failures.append(
                f"{reply.task_id} (rank {reply.rank} on {reply.host}): {message}"
            )
            record = {}
        else:
            record = dict(reply.record)
            status = record.pop("status")
            message = record.pop("message")
            rest = record.pop(REST_POINT, None)
            if rest is not None:
                self._new_rest(task.point_id, rest, task)
        record, scalars = split_record(record)
        meta = self._meta(task, status, message, reply) | scalars
        kind = "sweep" if isinstance(task, SweepTask) else "point"
        where = f"rank {reply.rank}@{reply.host}"
        self._finished(kind, reply.seconds, self._line(task, status, reply.seconds, where))
        if isinstance(task, SweepTask):
            self._record_sweep(task, record, meta)
            return
        self.writer.add(POINTS, task.task_id, record, meta)
        self.finished[POINTS][task.task_id] = meta
        self._count(status)
        if status == DONE:
            self.zero[task.task_id] = {**record, **meta}
        for s in self.sweeps_of.pop(task.task_id, []):
            self._release(s, meta)
        for p in self.carries.pop(task.task_id, []):
            self.ready_points.append((p, self._carried(p)))

    def _line(self, task, status: str, seconds: float, where: str = "") -> str:
        sweep = isinstance(task, SweepTask)
        params = (self.points[task.point_id] if sweep else task).params
        return task_line("sweep" if sweep else "point", params, task.direction if sweep else None,
                         status, seconds, self.progress.varying, where)  # fmt: skip

    def _progress(self, force: bool = False) -> None:
        """The progress file ``knitsweep status`` reads (every second) and the
        display's periodic summary."""
        t = time.monotonic()
        if not force and t - self._last_file < 1.0:
            return
        self._last_file = t
        self._commit()  # the file counts only durable results
        c = self.summary.counts
        counts = {"done": c[DONE], "failed": c[FAILED], "not_knittable": c["not_knittable"],
                  "running": self.executor.in_flight, "pending": self.pending,
                  "total": self.summary.total, "pid": os.getpid(),
                  "host": socket.gethostname(), "updated": time.time(),
                  **self.progress.counts()}  # fmt: skip
        with contextlib.suppress(StorageError):  # only a display; the results matter
            atomic_write_bytes(progress_path(self.writer.path), json.dumps(counts).encode())
        self.progress.summary(counts, force=force)


def _on_disk(out: Path, master: _Master | None) -> int:
    """How many of this run's tasks the disk holds after a write failed (the file and
    its journal as read back now: results received but never made durable, or lost
    with a journal deleted under the run, are not counted)."""
    from ..store.read import iter_entries

    if master is None:
        return 0
    ours = {POINTS: master.points, SWEEPS: master.sweeps}
    try:
        return len({(e.kind, e.task_id) for e in iter_entries(out)
                    if e.task_id in ours.get(e.kind, ())})  # fmt: skip
    except Exception:  # the file itself unreadable: nothing can be counted on
        return 0


def run_job(
    job: JobSpec,
    out: str | Path,
    executor,
    *,
    shard: tuple[int, int] | None = None,
    retry_failed: bool = False,
    show_progress: bool = True,
) -> RunSummary:
    """Run every unfinished task of ``job`` (or of one shard) on ``executor``,
    writing the results file ``out``. SIGINT/SIGTERM and a refused write end it
    with ``summary.interrupted`` (exit code 3)."""
    old = signals.install()
    try:
        with signals.deferred():
            return _run_job(job, Path(out), executor, shard, retry_failed, show_progress)
    finally:
        signals.restore(old)


def _run_job(job, out, executor, shard, retry_failed, show_progress) -> RunSummary:
    t0 = time.monotonic()
    if shard is not None and job.mode == "adaptive":
        executor.shutdown(abort=False)
        raise InputError("shard: an adaptive job refines series as results arrive and cannot "
                         "be split into shards; run it whole (under MPI for many workers)")  # fmt: skip
    points, sweeps = shard_tasks(job, shard)
    extra = {"shard": f"{shard[0]}/{shard[1]}" if shard else "", "n_points": len(points),
             "n_sweeps": len(sweeps)}  # fmt: skip
    try:
        writer = ResultWriter(out, job, extra)
    except BaseException:
        executor.shutdown(abort=False)  # nothing was handed out; release the workers
        raise
    for note in job.solver_notes():
        print(f"note: {note}", file=sys.stderr, flush=True)
    for path, why in writer.malformed:
        print(f"warning: journal entry {path.name} was malformed ({why}): its task is "
              "recomputed", file=sys.stderr, flush=True)  # fmt: skip
    for kind, tid, why in writer.check.damaged:
        print(f"warning: {out}: {kind[:-1]} {tid} is damaged ({why}): it is not used, and "
              "is recomputed", file=sys.stderr, flush=True)  # fmt: skip
    summary = RunSummary(out, 0)
    status = "interrupted"
    master = None
    stopped_cleanly = True
    failure: StorageError | None = None

    def keep(reply: Reply) -> None:  # results that arrive while the workers stop
        nonlocal failure
        try:
            master._handle(reply)
        except StorageError as e:
            failure = failure or e

    progress = RunProgress(varying_parameters(job), show=show_progress)
    try:
        with progress:
            master = _Master(job, points, writer, executor, summary, retry_failed, progress,
                             sweeps)  # fmt: skip
            status = master.run()
    except Interrupted:
        pass
    except StorageError as e:  # the disk refused a write: stop as on a signal
        failure = e
    finally:
        try:
            summary.interrupted = status == "interrupted"
            if summary.interrupted and master is not None:
                stopped_cleanly = executor.interrupt(job.run.stop_grace_s, keep)
        finally:
            sizes = {"run_seconds": writer.previous_run_seconds + time.monotonic() - t0}
            if master is not None:
                sizes |= {"n_points": len(master.points), "n_sweeps": len(master.sweeps)}
            try:
                writer.close(status, sizes)
            except StorageError as e:
                failure = failure or e
            with contextlib.suppress(OSError):
                progress_path(out).unlink(missing_ok=True)
            summary.seconds = time.monotonic() - t0
            # the executor compiled the kernels with its first task, inside the run
            summary.compile_seconds = float(getattr(executor, "compile_seconds", 0.0))
    written = sum(summary.counts.values())
    if failure is not None:
        written = _on_disk(out, master)
        summary.interrupted = True
        summary.storage_error = str(failure)
        print(f"error: {failure.strerror or failure}; {written} of {summary.total} tasks are in {out} (with its "
              f"journal); {remedy(failure)} and run the same command again to resume",
              file=sys.stderr, flush=True)  # fmt: skip
    elif summary.interrupted:
        name = signal.Signals(signals.received() or signal.SIGINT).name
        print(f"\ninterrupted by {name}: {written} of {summary.total} tasks are in {out}; to "
              "resume, run the same command again (finished tasks are skipped)", file=sys.stderr,
              flush=True)  # fmt: skip
    executor.shutdown(abort=not stopped_cleanly)
    return summary
