"""Compiling the kernels a command uses, once, before work fans out (docs/performance.md,
"Compile time"): per group of kernels with disjoint sources, in child processes side by side when
the cache is cold and cores are idle, each filling numba's shared on-disk cache.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable

from numba.core import event

from .config import Fidelity, StitchParams
from .model import CellModel
from .stitches import DEFAULT_STITCH, get_stitch
from .stitches.images import Glides, Translations, image_group

KERNEL_GROUPS = {
    "geometry": "the stitch's state -> control points + Jacobian kernel (knitsweep.stitches)",
    "contact": "energies, gradients, neighbour list, min zeta, contact forces, a pattern's "
    "checks (kernels.bending, contact, partition, neighbours, forces, cell, checks)",
    "solver": "the Newton-KKT step of the relaxations (kernels.kkt)",
}
"""The kernels a task uses, in groups whose compiled sources are disjoint (no kernel of
one group calls one of another), so that separate processes can compile them side by
side into one numba cache without two of them ever writing the same cache index."""
_GROUP_WEIGHT = {"geometry": 4, "contact": 6, "solver": 2}  # relative compile times


def compile_kernels(
    fidelity: Fidelity | None = None,
    notice: Callable[[str], None] | None = None,
    stitches: tuple[str, ...] = (DEFAULT_STITCH,),
    jobs: int | None = None,
    what: str = "run",
    each_kernel: Callable[[], None] | None = None,
) -> dict[str, float]:
    """Compile (or load from numba's cache) every kernel a task of these ``stitches``
    uses, once, before work fans out to other processes; returns the seconds per
    group (``KERNEL_GROUPS``). ``notice`` is told first when the kernels are not
    cached yet (``compile_notice``), so that a user knows why the first run waits.

    ``what``: ``"run"`` (every kernel of a task), ``"all"`` (those and the ones only the
    post-processing calls: the pair forces by class of ``report``; what ``knitsweep
    compile`` warms) or ``"energy"`` (the geometry and ``cell_energy`` only: what
    ``knitsweep energy`` calls). ``jobs``: processes that
    compile groups side by side when the cache is cold (None: as many as there are
    idle cores, at most one a group; 1: all here). Each fills the shared on-disk
    cache; this process then loads the kernels from it. ``each_kernel`` is called
    before each kernel this process compiles or loads (``compile_group``).
    """
    message = compile_notice(stitches, what)
    if message and notice is not None:
        notice(message)
    groups = ("geometry", "contact") if what == "energy" else tuple(KERNEL_GROUPS)
    seconds: dict[str, float] = {}
    if message:  # a cold cache
        seconds.update(_compile_in_processes(groups, fidelity, stitches, jobs, what))
    for group in groups:
        t0 = time.perf_counter()
        compile_group(group, fidelity, stitches, what, each_kernel)
        seconds[group] = seconds.get(group, 0.0) + time.perf_counter() - t0
    return seconds


def kernel_entry_points(stitches: tuple[str, ...] = (DEFAULT_STITCH,),
                        what: str = "run") -> tuple[str, ...]:  # fmt: skip
    """The kernels (``kernels.kernel`` names) whose compiled versions in numba's cache
    say that a task of these ``stitches`` finds its kernels compiled (``kernels.cached``):
    each stitch's geometry kernel, and every task's kernels, a knit/purl pattern's energy
    and the large states' KKT step where a stitch needs them (``what="energy"``: the
    geometry and the energy only, what ``knitsweep energy`` calls)."""
    from .kernels import ENTRY_POINTS
    from .kernels.kkt_rows import step_kernels

    chosen = [get_stitch(name) for name in stitches]
    geometry = tuple(dict.fromkeys(f"{s.geometry_module}.state_to_control_points"
                                   for s in chosen))  # fmt: skip
    groups = [image_group(s) for s in chosen]
    if what == "energy":  # each group's energy kernel
        return geometry + tuple(dict.fromkeys(e for g in groups for e in g.energy_entry_points))
    own = tuple(dict.fromkeys(e for g in groups for e in g.entry_points))
    steps = tuple(f"{k.py_func.__module__}.{k.py_func.__name__}"
                  for k in step_kernels(max(s.n_state for s in chosen)))  # fmt: skip
    return tuple(dict.fromkeys(geometry + ENTRY_POINTS + own + steps))


COMPILE_SECONDS = {(what, group.name): seconds for group in (Translations, Glides)
                   for what, seconds in group.compile_seconds.items()}  # fmt: skip
"""(what, image group) -> about how long compiling the kernels takes once on an idle machine, s: of what a
command calls (``run``: a task; ``energy``: one energy) for stitches of translations
only (stockinette) or with a knit/purl pattern's glides (garter, rib, seed). Measured
with ``benchmarks/bench_compile.py --jobs 1 --what run|energy --stitch
stockinette|garter`` (an empty cache, one process) on the 2-core project VM
(2026-12-04): the CPU seconds of the compiling process, which are its wall time on an
idle core (numba compiles for the host CPU, here AMD znver5; with
``NUMBA_CPU_NAME=generic`` stockinette's took 25 s, the same within the noise). On a
busy machine the wall time grows with the load: the same runs took
143-304 s (stockinette, load 7.5-10) and 447-526 s (garter, load 14-17), 0.7-2.1 times
the CPU seconds scaled by load/cores (``compile_notice``'s estimate)."""


def compile_notice(stitches: tuple[str, ...] = (DEFAULT_STITCH,), what: str = "run") -> str | None:
    """What to tell a user before the first call compiles the kernels of ``what`` for
    these ``stitches`` (None if numba's cache holds them for this checkout): how long
    that usually takes, and, on a busy machine, how much longer it will take now."""
    import os

    from . import kernels

    if kernels.cached(kernel_entry_points(stitches, what)):
        return None
    kind = "energy" if what == "energy" else "run"
    idle = max(image_group(get_stitch(s)).compile_seconds[kind] for s in stitches)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    cores = cores or 1
    load = os.getloadavg()[0]
    now = (f": this one is, load {load:.1f} on {cores} cores, so expect "
           f"~{_duration(idle * load / cores)} or more" if load > 1.5 * cores else "")  # fmt: skip
    return (f"compiling numerical kernels ({', '.join(stitches)}) once for this checkout: "
            f"~{_duration(idle)} on an idle machine, longer on a busy one{now}; cached in "
            f"{kernels.numba.config.CACHE_DIR}")  # fmt: skip


def _duration(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min"


class CompileClock(event.Listener):
    """Seconds numba spent compiling in this process (``seconds``) while a ``with
    compile_clock()`` block ran: the outermost ``numba:compile`` events (a kernel's
    callees compile inside its event; loading from the cache fires none)."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self._started: list[float] = []

    def on_start(self, ev) -> None:
        self._started.append(time.perf_counter())

    def on_end(self, ev) -> None:
        t0 = self._started.pop()
        if not self._started:
            self.seconds += time.perf_counter() - t0


@contextlib.contextmanager
def compile_clock():
    """A ``CompileClock`` listening to numba's compile events while the block runs."""
    clock = CompileClock()
    with event.install_listener("numba:compile", clock):
        yield clock


def compile_group(
    group: str,
    fidelity: Fidelity | None = None,
    stitches: tuple[str, ...] = (DEFAULT_STITCH,),
    what: str = "run",
    each_kernel: Callable[[], None] | None = None,
) -> None:
    """Compile (or load) the kernels of one of ``KERNEL_GROUPS`` in this process,
    calling ``each_kernel`` (if given) before each one (the signal tests' test point
    between kernels: ``service.signals.COMPILE_STAGES``).

    The contact kernels are compiled for the argument types of the model's calls
    without running them (so without the geometry kernel, which another process
    may be compiling at the same time).
    """  # fmt: skip
    tick = each_kernel or _nothing
    if group == "solver":
        from .kernels.kkt import ROWS_FROM
        from .kernels.kkt_rows import compile_solver

        largest = max(get_stitch(name).n_state for name in stitches)
        tick()
        compile_solver(ROWS_FROM if what == "all" else largest)
        return
    for name in stitches:
        model = CellModel(StitchParams(stitch=name), fidelity)
        if group == "geometry":
            tick()
            model._geometry_of(model.stitch.start(1))
        elif group == "contact":
            _compile_contact(model, what, tick)
        else:
            raise ValueError(f"kernel group {group!r}: one of {', '.join(KERNEL_GROUPS)}")


def _nothing() -> None:
    pass


def _compile_contact(model: CellModel, what: str, tick: Callable[[], None] = _nothing) -> None:
    """The contact kernels of ``model``'s image group (``stitches.images``), compiled for
    the argument types of its calls; ``tick`` is called before each kernel compiles."""
    model.image_group.compile(model, what, tick)


def idle_cores() -> int:
    """Cores of this process's CPU set that the 1-minute load average leaves idle (>= 1)."""
    import os

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, round((cores or 1) - os.getloadavg()[0]))


def _compile_in_processes(groups, fidelity, stitches, jobs, what="run") -> dict[str, float]:
    """Compile ``groups`` in ``jobs`` child processes (largest first, each to the least
    loaded process); {} when one process would do (then the caller compiles here)."""
    import json
    import subprocess
    import sys

    jobs = min(len(groups), idle_cores() if jobs is None else jobs)
    if jobs <= 1:
        return {}
    bins: list[list[str]] = [[] for _ in range(jobs)]
    for g in sorted(groups, key=lambda g: -_GROUP_WEIGHT[g]):
        min(bins, key=lambda b: sum(_GROUP_WEIGHT[x] for x in b)).append(g)
    spec = json.dumps({"fidelity": (fidelity or Fidelity()).model_dump(mode="json"),
                       "stitches": list(stitches), "what": what})  # fmt: skip
    # SIGINT/SIGTERM end a compiling child silently (a Ctrl-C reaches the terminal's
    # whole process group): the process that started it decides what a signal means
    code = (
        "import signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
        "from knitsweep.compilation import _compile_child; _compile_child(sys.argv[1:])"
    )
    procs = [subprocess.Popen([sys.executable, "-c", code, spec, *b], stdout=subprocess.PIPE,
                              text=True) for b in bins]  # fmt: skip
    seconds: dict[str, float] = {}
    try:
        for proc in procs:
            out, _ = proc.communicate()
            if proc.returncode == 0:  # else: this process compiles what is missing
                seconds.update(json.loads(out.strip().splitlines()[-1]))
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.terminate()
                proc.wait()
    return seconds


def _compile_child(argv: list[str]) -> None:
    """Entry point of one compiling process: ``SPEC_JSON GROUP...``; prints
    {group: seconds} as JSON."""
    import json

    spec = json.loads(argv[0])
    fidelity = Fidelity(**spec["fidelity"])
    seconds = {}
    for group in argv[1:]:
        t0 = time.perf_counter()
        compile_group(group, fidelity, tuple(spec["stitches"]), spec.get("what", "run"))
        seconds[group] = time.perf_counter() - t0
    print(json.dumps(seconds), flush=True)
