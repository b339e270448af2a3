"""Progress of a run, for people and for ``knitsweep status``.

One display serves ``knitsweep run`` and ``knitsweep sweep``. On a terminal it is a
live rich panel (bars for points and sweeps, or the strain of one sweep); elsewhere
(under ``mpirun``, in SLURM logs, piped) it prints one plain line per finished task
(kind, parameters, direction, status, seconds) and a summary line every ``every``
seconds. The ETA weighs the tasks still to do by the measured time of each kind
(a sweep costs ~10 points), divided by the measured throughput of the workers.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from typing import IO, Any

KINDS = ("point", "sweep")


def duration(s: float) -> str:
    """'4m05s', '1h02m', or '--' for an unknown (infinite) duration."""
    if not math.isfinite(s):
        return "--"
    s = round(s)
    return f"{s // 3600}h{s % 3600 // 60:02d}m" if s >= 3600 else f"{s // 60}m{s % 60:02d}s"


def progress_line(c: dict[str, Any]) -> str:
    """One status line from progress counts (the summary line and ``status``)."""
    finished = c["done"] + c["failed"] + c["not_knittable"]
    width = 24
    filled = int(width * min(finished / max(c["total"], 1), 1.0))
    if c.get("finished_at"):
        tail = f"finished in {duration(float(c.get('elapsed_s', math.nan)))}"
    else:
        tail = f"elapsed {duration(float(c.get('elapsed_s', math.nan)))}  ETA " + duration(
            float(c.get("eta_s", math.inf))
        )
    return (f"[{'#' * filled}{'.' * (width - filled)}] {finished}/{c['total']}  "
            f"done {c['done']}  failed {c['failed']}  not_knittable {c['not_knittable']}  "
            f"running {c['running']}  pending {c['pending']}  {tail}")  # fmt: skip


@dataclass
class _Kind:
    total: int = 0
    finished: int = 0
    seconds: float = 0.0  # worker seconds of the tasks finished in this run
    measured: int = 0

    @property
    def mean(self) -> float | None:
        return self.seconds / self.measured if self.measured else None


@dataclass
class RunProgress:
    """What a run has done and what it still has to do, and its display.

    ``varying``: the parameters that vary in the job (shown in the per-task lines,
    with L always). ``show=False``: nothing printed (counts are still kept).
    """

    varying: tuple[str, ...] = ()
    show: bool = True
    stream: IO[str] = field(default_factory=lambda: sys.stderr)
    live: bool | None = None  # None: a live display when the stream is a terminal
    every: float = 30.0
    setup_s: float = 0.0
    """Seconds of the run spent compiling the kernels before tasks could start: the ETA's
    throughput counts only the time after."""
    kinds: dict[str, _Kind] = field(default_factory=lambda: {k: _Kind() for k in KINDS})
    t0: float = field(default_factory=time.monotonic)
    _last_summary: float = 0.0
    _panel: Any = None

    def __post_init__(self) -> None:
        if self.live is None:
            self.live = bool(self.show and getattr(self.stream, "isatty", lambda: False)())

    # -- counts
    def add_tasks(self, kind: str, n: int = 1, finished: int = 0) -> None:
        """``n`` more tasks of ``kind`` (point or sweep), ``finished`` of them already."""
        k = self.kinds[kind]
        k.total += n
        k.finished += finished
        self._refresh()

    def finished(self, kind: str, seconds: float, line: str, measured: bool = True) -> None:
        """A task of ``kind`` ended after ``seconds`` on its worker; ``line`` says how.
        ``measured=False``: it was not computed (e.g. the sweeps of a point that cannot
        be knitted), so its time says nothing about the others'."""
        k = self.kinds[kind]
        k.finished += 1
        if measured:
            k.seconds += seconds
            k.measured += 1
        if self.show and not self.live:
            f = sum(x.finished for x in self.kinds.values())
            t = sum(x.total for x in self.kinds.values())
            print(f"[{f:>{len(str(t))}}/{t} {duration(self.elapsed)}] {line}", file=self.stream,
                  flush=True)  # fmt: skip
        self._refresh()

    @property
    def elapsed(self) -> float:
        return time.monotonic() - self.t0

    def eta(self) -> float:
        """Seconds still to go: the work left, each task at its kind's mean time, over
        the worker seconds done per wall second since the kernels were compiled (``setup_s``);
        inf until measurable."""
        done_work = sum(k.seconds for k in self.kinds.values())
        if done_work <= 0.0:
            return math.inf
        means = {n: k.mean for n, k in self.kinds.items()}
        if means["sweep"] is None and self.kinds["sweep"].total > self.kinds["sweep"].finished:
            if means["point"] is None:
                return math.inf
            means["sweep"] = 10.0 * means["point"]  # measured: a sweep costs ~10 points
        left = sum((k.total - k.finished) * (means[n] or 0.0) for n, k in self.kinds.items())
        return left / (done_work / max(self.elapsed - self.setup_s, 1e-9))

    def counts(self) -> dict[str, float]:
        return {"elapsed_s": self.elapsed, "eta_s": self.eta(),
                **{f"{n}s_total": k.total for n, k in self.kinds.items()},
                **{f"{n}s_finished": k.finished for n, k in self.kinds.items()}}  # fmt: skip

    # -- display
    def summary(self, counts: dict[str, Any], force: bool = False) -> None:
        """The periodic summary line (not on a live display, which shows it all)."""
        t = time.monotonic()
        if not self.show or self.live or (not force and t - self._last_summary < self.every):
            return
        self._last_summary = t
        print(progress_line({**counts, **self.counts()}), file=self.stream, flush=True)

    def __enter__(self) -> RunProgress:
        if self.live:
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

            self._panel = Progress(TextColumn("{task.description:>7}"), BarColumn(),
                                   MofNCompleteColumn(), TextColumn("{task.fields[info]}"),
                                   console=Console(file=self.stream), transient=False)  # fmt: skip
            self._ids = {k: self._panel.add_task(f"{k}s", total=1, info="") for k in KINDS}
            self._panel.start()
            self._refresh()
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._panel is not None:
            self._refresh()
            self._panel.stop()
            self._panel = None

    def _refresh(self) -> None:
        if self._panel is None:
            return
        eta = duration(self.eta())
        for name, k in self.kinds.items():
            mean = "" if k.mean is None else f"{k.mean:.2f} s each"
            info = (
                f"{mean}  elapsed {duration(self.elapsed)}  ETA {eta}" if name == "sweep" else mean
            )
            self._panel.update(self._ids[name], total=max(k.total, 1), completed=k.finished,
                               info=info)  # fmt: skip


def task_line(kind: str, params: Any, direction: str | None, status: str, seconds: float,
              varying: tuple[str, ...], where: str = "") -> str:  # fmt: skip
    """'sweep x  L=11.4 k=0.1  done  1.32 s  rank 2@host' for a finished task."""
    names = ["L_mm", *(n for n in varying if n != "L_mm")]
    from ..quantities import PARAMETER_NAMES, value_text

    values = " ".join(f"{PARAMETER_NAMES[n].symbol}={value_text(getattr(params, n))}"
                      for n in names)  # fmt: skip
    head = f"{kind} {direction}" if direction else f"{kind}  "
    return f"{head}  {values}  {status}  {seconds:.2f} s" + (f"  {where}" if where else "")


class SweepProgress:
    """The display of one strain sweep (``knitsweep sweep``): a live bar on a
    terminal, else a line every tenth of the way; ``update(step, strain, stress)``
    after every step, the fraction being the larger of strain and stress over
    their stop values."""

    def __init__(self, label: str, max_strain: float, stop_stress: float,
                 stream: IO[str] | None = None, live: bool | None = None) -> None:  # fmt: skip
        self.label, self.max_strain, self.stop_stress = label, max_strain, stop_stress
        self.stream = stream or sys.stderr
        self.live = self.stream.isatty() if live is None else live
        self._next_line = 0.1
        self._panel: Any = None
        self.t0 = time.monotonic()

    def __enter__(self) -> SweepProgress:
        if self.live:
            from rich.console import Console
            from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

            self._panel = Progress(TextColumn("{task.description}"), BarColumn(),
                                   TextColumn("{task.fields[info]}"), TimeElapsedColumn(),
                                   console=Console(file=self.stream))  # fmt: skip
            self._id = self._panel.add_task(self.label, total=1.0, info="")
            self._panel.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._panel is not None:
            self._panel.stop()

    def update(self, step: int, strain: float, stress: float) -> None:
        frac = min(max(abs(strain) / self.max_strain, stress / self.stop_stress, 0.0), 1.0)
        info = f"step {step}  strain {strain:.4f}  stress {stress:.4g} N/mm"
        if self._panel is not None:
            self._panel.update(self._id, completed=frac, info=info)
        elif frac >= self._next_line:
            self._next_line = math.floor(frac * 10 + 1) / 10
            print(f"{self.label}: {info}  ({duration(time.monotonic() - self.t0)})",
                  file=self.stream, flush=True)  # fmt: skip
