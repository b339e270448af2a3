"""Entry points behind ``knitsweep run``, ``knitsweep status`` and ``knitsweep merge``.

``run`` picks the executor: under ``mpirun -n N`` (N > 1) rank 0 is the master
and ranks 1..N-1 work; otherwise the job runs here, serially or in ``workers``
local processes. Bad input is refused on rank 0 before any work starts, and the
workers are released instead of left waiting.
"""

from __future__ import annotations

import json
import math
import os
import signal
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..config import DONE, FAILED
from ..errors import InputError
from ..stitches import DEFAULT_STITCH
from ..store.checksum import FileCheck
from ..store.format import POINTS, REWRITABLE_SCHEMAS, SERIES, SWEEPS, journal_dir, lock_path
from ..store.journal import scan
from ..store.read import choose_entries, iter_entries, journal_problems, read_progress, read_root
from ..store.writer import writer_alive
from ..util.plain_values import plain_value
from . import signals
from .jobs import JobSpec, load_job

if TYPE_CHECKING:
    from .executors import ExecutorKind

LARGE_GRID_TASKS = 20_000
"""Jobs with more tasks (points and sweeps) than this need ``--max-tasks`` (docs/input-validation.md)."""


def default_output(job: JobSpec, shard: tuple[int, int] | None) -> Path:
    suffix = f".shard{shard[0]}of{shard[1]}" if shard else ""
    return Path(f"{job.name}{suffix}.h5")


def run(
    job_path: str | Path,
    out: str | Path | None = None,
    *,
    executor: ExecutorKind = "auto",
    workers: int = 1,
    shard: str | None = None,
    retry_failed: bool = False,
    show_progress: bool = True,
    max_tasks: int | None = None,
    relabel: bool = False,
):
    """Run a job file; returns the ``RunSummary`` (None on MPI worker ranks).

    Everything that can be refused is checked before any compute: the job, the
    shard, the grid size against ``max_tasks`` (default ``LARGE_GRID_TASKS``),
    whether ``out`` can be written and, for an existing ``out``, that it was made by
    a job of this name and description (``relabel=True``: take it over and give it
    this job's; see ``check_label``)."""
    from .executors import launch, mpi_worker_loop, open_executor, release_workers
    from .master import run_job

    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"workers = {workers!r}: must be an integer >= 1")
    comm, is_worker = launch(executor)
    if is_worker:
        if mpi_worker_loop(comm) == signals.EXIT_INTERRUPTED:  # every rank says so, exit 3
            raise signals.Interrupted(signals.received() or signal.SIGTERM)
        return None
    try:
        with signals.interruptible():  # raises at once for a signal during MPI_Init
            job, shard_t, out = _prepare_run(job_path, out, shard, max_tasks, relabel)
            ex = open_executor(job, executor, workers, comm)  # compiles; hands the job out
    except BaseException as e:  # there is no job: the workers leave (exit 3 on a signal)
        if comm is not None:
            release_workers(comm, None if signals.as_interrupt(e) is None
                            else signals.EXIT_INTERRUPTED)  # fmt: skip
        raise
    return run_job(job, out, ex, shard=shard_t, retry_failed=retry_failed,
                   show_progress=show_progress)  # fmt: skip


def _prepare_run(job_path, out, shard, max_tasks, relabel=False):
    """(job, shard, out) after every check that needs no compute."""
    from .run_plan import parse_shard

    job = load_job(job_path)
    shard_t = parse_shard(shard)
    out = Path(out) if out is not None else default_output(job, shard_t)
    check_grid_size(job, max_tasks)
    check_output(out)
    adopt_empty(out)
    check_label(job, out, relabel)
    # (a resume's stitches were checked when they entered its file, and it may need no kernel)
    check_job_starts(job, already=stitches_in_file(out) if out.exists() else ())
    return job, shard_t, out


def check_job_starts(job: JobSpec, already: tuple[str, ...] = ()) -> None:
    """The shipped starts of every stitch of the job not in ``already`` (docs/patterns.md:
    an overlapping start is refused, naming the segments), before any task's kernels
    compile (this loads the geometry kernels of the stitches it checks)."""
    new = tuple(s for s in job.stitches if s not in already)
    if new:
        from ..relax.zero_force import check_shipped_starts

        check_shipped_starts(new, job.fidelity)


def stitches_in_file(out: Path) -> tuple[str, ...]:
    """The stitches of the job spec a results file holds (a grown job's latest spec);
    none when the file's spec cannot be read (the compatibility check names that)."""
    try:
        spec = json.loads(str(read_root(out)["job_json"]))
    except (InputError, KeyError, ValueError):
        return ()
    grid = spec.get("grid") if isinstance(spec.get("grid"), dict) else {}
    names = grid.get("stitch", spec.get("stitch", DEFAULT_STITCH))
    return tuple(names) if isinstance(names, list) else (str(names),)


def adopt_empty(out: Path) -> Path | None:
    """A 0-byte results file holds no results: kept aside (``<file>.damaged``) so that
    the run starts it anew, its journal folded in (nothing is lost). Not when a copy
    beside it (shadow, spare) holds results that a writer would delete as stale:
    ``recover`` is for that. Returns where the file is kept (None: not adopted)."""
    import sys

    from ..store.salvage import set_aside

    copies = [out.with_name(f".{out.name}.{what}") for what in ("shadow", "spare")]
    if (out.is_symlink() or not out.is_file() or out.stat().st_size or any(map(os.path.lexists, copies))
            or writer_alive(lock_path(out))):  # fmt: skip
        return None
    kept = set_aside(out)
    print(f"warning: {out} was empty (0 bytes, no results): kept as {kept}; this run starts "
          "it anew", file=sys.stderr, flush=True)  # fmt: skip
    return kept


def check_label(job: JobSpec, out: Path, relabel: bool = False) -> None:
    """Refuse to run ``job`` into an existing results file made by a job of another
    ``name`` or ``description`` unless ``relabel``: a mistyped ``--out`` must not
    mix two studies and rename the file. A grown grid of the same job passes (its
    other settings are checked by the writer, ``check_compatible``)."""
    import json

    if not out.exists():
        return
    root = read_root(out)
    try:
        theirs = json.loads(str(root.get("job_json", "{}")))
    except ValueError:
        return  # the writer names the file as unreadable
    for field, mine in (("name", job.name), ("description", job.description)):
        other = theirs.get(field, "") if isinstance(theirs, dict) else ""
        if other != mine and not relabel:
            raise InputError(
                f"{field} = {mine!r}: {out} holds results of a job with {field} {other!r}; "
                "add --relabel to write into it under this job's name and description, or "
                "choose another --out"
            )


def check_grid_size(job: JobSpec, max_tasks: int | None) -> None:
    """Refuse a grid of more than ``max_tasks`` tasks (default LARGE_GRID_TASKS)
    unless asked for explicitly: a mistyped range must not become a week of work."""
    limit = LARGE_GRID_TASKS if max_tasks is None else max_tasks
    n = job.grid.size() * (1 + len(job.directions))
    if n > limit:
        raise InputError(
            f"the job has {n} tasks ({n // (1 + len(job.directions))} grid points), more than "
            f"{limit}; check the grid, or confirm with --max-tasks {n}"
        )


def check_output(out: Path) -> None:
    """Refuse a results file that cannot be written, or whose lock, journal, shadow,
    spare or progress file is a symbolic link, before any compute (``run``, ``merge``)."""
    from ..store.writer import check_no_links
    from ..util.safe_files import check_writable

    check_writable(out, "results file")
    check_no_links(out)


def status(path: str | Path, by: str | None = None, tasks: bool = False) -> dict[str, Any]:
    """Counts of a results file (done, failed, not_knittable, running, pending, total),
    its elapsed time and ETA while a run writes it, its wall time once finished.

    While a master is writing the file, every count comes from its progress file, so
    that done + failed + not_knittable + running + pending = total as in its progress
    line; an adaptive job's total grows there as refinements are added. Otherwise the
    counts are the file's own, and the total is the planned task count (updated to the
    tasks it holds when a run closes the file), never less than what it holds.
    ``by``: a parameter (``L_mm``, ``k_mN_per_mm2``, …, ``direction``) to count the
    file's tasks per value of. ``tasks``: also list every finished task (``tasks``: kind,
    id, status, direction, point id, stitch, parameters, seconds; the ids
    ``knitsweep render --results FILE --task ID`` draws).
    """
    path = Path(path)
    root = read_root(path)
    counts = {DONE: 0, FAILED: 0, "not_knittable": 0}
    failures = []
    series = []
    groups: dict[Any, dict[str, int]] = {}
    journalled, problems = scan(journal_dir(path))  # once, before the file (iter_entries)
    check = FileCheck()
    listed: list[dict[str, Any]] = []
    for e in iter_entries(path, journalled=journalled, check=check):
        if e.kind == SERIES:
            series.append(e.meta)
            continue
        s = str(e.meta.get("status", FAILED))
        counts[s] = counts.get(s, 0) + 1
        if by is not None:
            value = e.meta.get(by, "-") if by != "direction" or e.kind != POINTS else "-"
            if by == "stitch" and e.kind in (POINTS, SWEEPS):  # absent: the default stitch
                value = e.meta.get(by, DEFAULT_STITCH)
            group = groups.setdefault(plain_value(value), {})
            group[s] = group.get(s, 0) + 1
        if s == FAILED:
            failures.append(f"{e.kind[:-1]} {e.task_id} ({_where(e.meta)}): "
                            f"{e.meta.get('message', '')}")  # fmt: skip
        if tasks and e.kind in (POINTS, SWEEPS):
            listed.append(task_row(e))
    live = read_progress(path)
    fresh = (
        live is not None
        and time.time() - float(live.get("updated", 0)) < 60
        and writer_alive(lock_path(path))
    )
    if fresh:
        counts = {k: int(live[k]) for k in (DONE, FAILED, "not_knittable")}
        running, pending, total = (int(live[k]) for k in ("running", "pending", "total"))
    else:
        finished = sum(counts.values())
        planned = int(root.get("n_points", 0)) + int(root.get("n_sweeps", 0))
        running, total = 0, max(planned, finished)
        pending = total - finished
    return {
        "file": str(path),
        "job": root.get("job_name", ""),
        "run_status": root.get("run_status", ""),
        "live": bool(fresh),
        "stale": root.get("run_status") == "running" and not fresh,
        "done": counts[DONE],
        "failed": counts[FAILED],
        "not_knittable": counts["not_knittable"],
        "running": running,
        "pending": pending,
        "total": total,
        "started_at": root.get("started_at", ""),
        "finished_at": root.get("finished_at", ""),
        "elapsed_s": float(live.get("elapsed_s", math.nan)) if fresh else _wall_seconds(root),
        "eta_s": float(live.get("eta_s", math.inf)) if fresh else 0.0,
        "failures": failures,
        "by": {by: {str(k): v for k, v in sorted(groups.items(), key=lambda kv: str(kv[0]))}}
        if by is not None
        else {},
        "journal_problems": journal_problems(path, problems),
        "damaged": [f"{kind[:-1]} {tid}: {why}" for kind, tid, why in check.damaged]
        + check.structure,
        "verified": check.verified,
        "unverified": check.unverified,
        "check": check.lines(path),
        "series": {
            "done": sum(m.get("status") == "done" for m in series),
            "total": len(series),
        },
        "failed_series": [
            f"{_where(m)}: {m.get('message', '')}" for m in series if m.get("status") == FAILED
        ],
        **({"tasks": sorted(listed, key=_task_order)} if tasks else {}),
    }


def _where(meta: dict[str, Any]) -> str:
    """'x, L = 9.3 mm, stitch = seed, k = 0.1': a task's or a series' direction and the
    parameters that tell it from its neighbours in a study."""
    parts = [str(meta["direction"])] if meta.get("direction") else []
    if meta.get("L_mm") is not None:
        parts.append(f"L = {plain_value(meta['L_mm']):g} mm")
    parts.append(f"stitch = {meta.get('stitch', DEFAULT_STITCH)}")
    if meta.get("k_mN_per_mm2") is not None:
        parts.append(f"k = {plain_value(meta['k_mN_per_mm2']):g}")
    return ", ".join(parts)


def task_row(e) -> dict[str, Any]:
    """One finished task of a results file as plain data: kind (point, sweep), id,
    status, direction and point id (a sweep's), stitch, parameters, seconds."""
    from ..quantities import PARAMETERS

    row = {"kind": e.kind[:-1], "task_id": e.task_id, "status": str(e.meta.get("status", "")),
           "direction": str(e.meta.get("direction", "")),
           "point_id": str(e.meta.get("point_id", "")),
           "stitch": str(e.meta.get("stitch", DEFAULT_STITCH))}  # fmt: skip
    row |= {p: plain_value(e.meta[p]) for p in PARAMETERS if p != "stitch" and p in e.meta}
    row["seconds"] = plain_value(e.meta.get("seconds"))
    return row


def _task_order(row: dict[str, Any]) -> tuple:
    """Points before sweeps; then by stitch, the parameters, L, direction."""
    from ..quantities import NUMERIC_SERIES_PARAMS

    return (row["kind"] != "point", row["stitch"],
            *(row.get(p, 0.0) for p in NUMERIC_SERIES_PARAMS), row.get("L_mm", 0.0),
            row["direction"])  # fmt: skip


def _wall_seconds(root: dict[str, Any]) -> float:
    """The wall time of the runs into a file: ``run_seconds`` (every run, resumes
    added up), else the span from its start to its end."""
    if "run_seconds" in root:
        return float(root["run_seconds"])
    from datetime import datetime

    try:
        span = datetime.fromisoformat(root["finished_at"]) - datetime.fromisoformat(
            root["started_at"]
        )
    except (KeyError, TypeError, ValueError):
        return math.nan
    return span.total_seconds()


def merge(out: str | Path, inputs: list[str | Path]) -> dict[str, Any]:
    """Combine shard files of one job (``knitsweep run --shard i/N``) into ``out``.

    Every input must come from the same job (same job hash and schema); a task
    present in several inputs is taken once, a 'done' result winning over a
    failed one. Returns counts of what ``out`` holds.
    """
    from ..store.writer import ResultWriter
    from .jobs import JobSpec, plan

    if not inputs:
        raise InputError("merge needs at least one input file")
    out = Path(out)
    seen: dict[Path, str] = {}
    for p in inputs:
        real = Path(p).resolve()
        if real in seen:
            raise InputError(f"{p} is given twice (also as {seen[real]}); name each shard once")
        if real == out.resolve():
            raise InputError(f"{out} is also an input; merge into a new file")
        seen[real] = str(p)
    check_output(out)
    roots = [read_root(p) for p in inputs]
    old = [str(p) for p, r in zip(inputs, roots, strict=True)
           if r.get("schema_version") not in REWRITABLE_SCHEMAS]  # fmt: skip
    if old:
        raise InputError(f"{', '.join(old)}: results schema older than {REWRITABLE_SCHEMAS[0]}; "
                         "merge them with the knitsweep version that wrote them")  # fmt: skip
    hashes = {r["job_hash"] for r in roots}
    if len(hashes) != 1:
        names = ", ".join(
            f"{p} ({r['job_name']}, {r['job_hash']})" for p, r in zip(inputs, roots, strict=True)
        )
        raise InputError(f"inputs come from different jobs: {names}")
    job = JobSpec.model_validate_json(roots[0]["job_json"])
    points, sweeps = plan(job)
    checks = {str(p): FileCheck() for p in inputs}
    chosen = choose_entries(e for path in inputs
                            for e in iter_entries(path, with_data=True, check=checks[str(path)]))  # fmt: skip
    writer = ResultWriter(out, job, {"n_points": len(points), "n_sweeps": len(sweeps),
                                     "shard": "", "merged_from": ", ".join(map(str, inputs))})  # fmt: skip
    try:
        for e in chosen.values():
            writer.add(e.kind, e.task_id, e.record, e.meta)
    finally:
        complete = sum(kind != SERIES for kind, _ in chosen) == len(points) + len(sweeps)
        writer.close("complete" if complete else "partial")
    n_sweeps = sum(kind == SWEEPS for kind, _ in chosen)
    n_points = sum(kind == POINTS for kind, _ in chosen)
    return {"file": str(out), "points": n_points, "sweeps": n_sweeps,
            "expected": len(points) + len(sweeps), "complete": complete,
            "problems": [f"{p}: {line}" for p, c in checks.items() for line in c.lines(p)]
            + [f"{p}: malformed journal entry {line}: not merged" for p in inputs
               for line in journal_problems(p)]}  # fmt: skip
