"""What a run is before and after the master's loop: the tasks of a job or of one shard
of it, the parameters its progress lines name, and the summary it returns (its exit
code)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..config import DONE, FAILED
from ..errors import InputError
from .jobs import JobSpec, plan, series_key
from .signals import EXIT_INTERRUPTED

EXIT_TASKS_FAILED = 4
"""Exit code of a run that finished but whose file holds failed tasks (docs/how-to/runs.md)."""


@dataclass
class RunSummary:
    out: Path
    total: int
    counts: dict[str, int] = field(default_factory=lambda: {DONE: 0, FAILED: 0, "not_knittable": 0})
    skipped: int = 0
    interrupted: bool = False
    seconds: float = 0.0
    failures: list[str] = field(default_factory=list)
    storage_error: str = ""
    compile_seconds: float = 0.0  # compiling the kernels before the run (a cold install)
    redone: int = 0  # sweeps computed again from a lower zero-force state a sweep found

    @property
    def exit_code(self) -> int:
        """3 if interrupted, 4 if any task of the file failed (this run's or an earlier
        one's not retried), else 0; a not-knittable point is a result, not a failure."""
        if self.interrupted:
            return EXIT_INTERRUPTED
        return EXIT_TASKS_FAILED if self.counts.get(FAILED, 0) else 0


def parse_shard(text: str | None) -> tuple[int, int] | None:
    """'i/N' -> (i, N) with 0 <= i < N."""
    if text is None:
        return None
    try:
        i, n = (int(v) for v in text.split("/"))
    except ValueError:
        raise InputError(f"shard = {text!r}: must be i/N with integers, e.g. 0/4") from None
    if not (n >= 1 and 0 <= i < n):
        raise InputError(f"shard = {text!r}: need N >= 1 and 0 <= i < N")
    return i, n


def shard_tasks(job: JobSpec, shard: tuple[int, int] | None):
    """The job's tasks, or one shard of them (points i, i+N, …, with their sweeps;
    with ``[starts] carry`` series i, i+N, …, whose points carry from one another)."""
    points, sweeps = plan(job)
    if shard is None:
        return points, sweeps
    i, n = shard
    if job.starts.carry:
        series = list(dict.fromkeys(series_key(p.params) for p in points))
        mine = set(series[i::n])
        points = [p for p in points if series_key(p.params) in mine]
    else:
        points = [p for k, p in enumerate(points) if k % n == i]
    keep = {p.task_id for p in points}
    return points, [s for s in sweeps if s.point_id in keep]


def varying_parameters(job: JobSpec) -> tuple[str, ...]:
    """The grid parameters that take more than one value (ties and the stitch included)."""
    axes = job.grid.axes()
    tied = tuple(n for n, tie in job.grid.ties().items() if len(axes.get(tie.to, ())) > 1)
    stitch = ("stitch",) if len(job.stitches) > 1 else ()
    return stitch + tuple(n for n, v in axes.items() if len(v) > 1) + tied
