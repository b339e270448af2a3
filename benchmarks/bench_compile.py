"""Compile time of the numba kernels: per kernel, cold and warm.

Run: ``python benchmarks/bench_compile.py [--repeats 1] [--src DIR ...] [--what run|energy]
[--jobs 1] [--stitch stockinette] [--group solver]``

Each measurement runs in a fresh Python process with ``NUMBA_CACHE_DIR`` pointed at a
new, empty temporary directory (cold: every kernel compiles), then again in a fresh
process on the same directory (warm: every kernel loads from numba's on-disk cache).
The child compiles what a command needs (``--what run``: ``knitsweep.model.
compile_kernels``, everything a ``knitsweep run`` task uses; ``--what energy``: the
energy kernels of ``knitsweep energy``) and listens to numba's ``numba:compile``
events (``numba.core.event``): one event per specialisation that numba compiles, nested
when a kernel compiles the callees it calls. The table gives, per function, the number
of specialisations compiled, the inclusive seconds (callees' compilation included,
counted once at the outermost event of that function) and the exclusive seconds (its
own, callees' compile events subtracted); the exclusive column adds up to the compile
total. Times are CPU seconds of the compiling process (compiling is single-threaded,
so on an idle core they are its wall time; on a shared, loaded machine they are what
stays comparable); ``wall`` is the whole ``compile_kernels`` call in the child
(process start-up and imports excluded). ``--group`` compiles one group of kernels
(``knitsweep.compilation.compile_group``) instead of everything.

With ``--jobs N`` > 1 the groups of kernels (``knitsweep.compilation.KERNEL_GROUPS``) compile
in N child processes, whose compile events this process does not see: then only the
wall times count.

``--src`` runs the same measurement against other source trees (e.g. a worktree of
``main``: ``git worktree add /tmp/base main``), alternating trees run by run, so that
on a shared, loaded machine the ratio is measured side by side. Figures are medians
over ``--repeats``.

Not a test: nothing here passes or fails (STYLE.md, "benchmarks kept apart").
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

_CHILD = r"""
import json, sys, time
from numba.core import event

stack, rows = [], {}

class Listener(event.Listener):
    def on_start(self, ev):
        stack.append([time.process_time(), 0.0, ev.data["dispatcher"]])

    def on_end(self, ev):
        t0, inner, disp = stack.pop()
        dt = time.process_time() - t0
        name = f"{disp.py_func.__module__.split('.')[-1]}.{disp.py_func.__qualname__}"
        row = rows.setdefault(name, [0, 0.0, 0.0])
        row[0] += 1
        row[2] += dt - inner
        if not any(d is disp for _, _, d in stack):
            row[1] += dt  # inclusive, once per outermost compile of this function
        if stack:
            stack[-1][1] += dt

t_import = time.perf_counter()
import numba
import knitsweep.model as model
from knitsweep.config import StitchParams
try:
    from knitsweep.compilation import compile_kernels
except ImportError:  # older trees: in knitsweep.model
    compile_kernels = model.compile_kernels
t0, c0 = time.perf_counter(), time.process_time()
what, jobs, stitches = sys.argv[1], int(sys.argv[2]), tuple(sys.argv[3].split(","))
group = sys.argv[4]
new_api = "jobs" in compile_kernels.__code__.co_varnames  # older trees: no jobs, no what
with event.install_listener("numba:compile", Listener()):
    if group:  # one of KERNEL_GROUPS alone, in this process
        from knitsweep.compilation import compile_group
        compile_group(group, None, stitches, what)
    elif new_api:
        compile_kernels(jobs=jobs, what=what, stitches=stitches)
    elif what == "run":
        compile_kernels()
    else:  # what `knitsweep energy` calls
        m = model.CellModel(StitchParams())
        m.energies(m.stitch.start(1))
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
print(json.dumps({"wall": wall, "cpu": cpu, "import": t0 - t_import, "rows": rows,
                  "cache": numba.config.CACHE_DIR}))
"""


def measure(src: Path, what: str, cache: str, jobs: int, stitches: str = "stockinette",
            group: str = "") -> dict:  # fmt: skip
    env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(src))
    load = os.getloadavg()[0]  # the 1-minute load as the measurement starts
    out = subprocess.run([sys.executable, "-c", _CHILD, what, str(jobs), stitches, group], env=env, cwd=src, check=True,
                         capture_output=True, text=True).stdout  # fmt: skip
    return {**json.loads(out.strip().splitlines()[-1]), "load": load}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--src", type=Path, action="append", help="source trees (default: this one)")
    ap.add_argument("--what", default="run", help="run (compile_kernels) or energy")
    ap.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="compiling processes (this tree's "
        "compile_kernels(jobs=...); 1: in the measuring process, where the events are "
        "seen; a loaded machine's scheduler favours more processes, so compare at 1)",
    )
    ap.add_argument(
        "--stitch",
        default="stockinette",
        help="stitches whose kernels compile, "
        "comma-separated (e.g. garter: a knit/purl pattern's own kernels too)",
    )
    ap.add_argument(
        "--group",
        default="",
        help="one group of kernels alone "
        "(knitsweep.compilation.KERNEL_GROUPS, e.g. solver), in the measuring process",
    )
    ap.add_argument("--top", type=int, default=25, help="rows of the per-kernel table")
    ap.add_argument("--json", type=Path, help="also write the raw figures here")
    args = ap.parse_args()
    trees = [s.resolve() for s in (args.src or [ROOT])]
    runs: dict[Path, list[tuple[dict, dict]]] = {t: [] for t in trees}
    for _ in range(args.repeats):
        for tree in trees:  # alternate trees run by run: same load for each
            with tempfile.TemporaryDirectory(prefix="ks-numba-cache-") as cache:
                cold = measure(tree, args.what, cache, args.jobs, args.stitch, args.group)
                warm = measure(tree, args.what, cache, args.jobs, args.stitch, args.group)
            runs[tree].append((cold, warm))
    print(f"compile of what `{args.what}` of {args.stitch} needs"
          f"{f' (group {args.group})' if args.group else ''}, jobs={args.jobs}, "
          f"{args.repeats} run(s) per tree, medians; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")  # fmt: skip
    summary = {}
    for tree in trees:
        colds = [c for c, _ in runs[tree]]
        warms = [w for _, w in runs[tree]]
        names = sorted({n for c in colds for n in c["rows"]},
                       key=lambda n: -statistics.median(c["rows"].get(n, [0, 0, 0])[2] for c in colds))  # fmt: skip
        print(f"\n{tree}")
        print(f"  {'function':44s} {'spec':>4s} {'incl':>8s} {'excl':>8s}  (CPU s)")
        for n in names[: args.top]:
            vals = [c["rows"].get(n, [0, 0.0, 0.0]) for c in colds]
            print(f"  {n:44s} {statistics.median(v[0] for v in vals):4.0f} "
                  f"{statistics.median(v[1] for v in vals):8.2f} "
                  f"{statistics.median(v[2] for v in vals):8.2f}")  # fmt: skip
        n_spec = statistics.median(sum(r[0] for r in c["rows"].values()) for c in colds)
        cold_wall = statistics.median(c["wall"] for c in colds)
        cold_cpu = statistics.median(c["cpu"] for c in colds)
        warm_wall = statistics.median(w["wall"] for w in warms)
        print(f"  {len(names)} functions, {n_spec:.0f} specialisations compiled")
        walls = ", ".join(f"{c['wall']:.1f} (load {c['load']:.1f})" for c in colds)
        print(
            f"  cold: {cold_wall:7.2f} s wall, {cold_cpu:7.2f} s CPU of this process   (runs: {walls})"
        )
        print(f"  warm: {warm_wall:7.2f} s wall   (compiled on a warm cache: "
              f"{statistics.median(len(w['rows']) for w in warms):.0f} functions)")  # fmt: skip
        summary[str(tree)] = {"cold": cold_wall, "cold_cpu": cold_cpu, "warm": warm_wall,
                              "runs": runs[tree]}  # fmt: skip
    if len(trees) > 1:
        base = summary[str(trees[0])]
        for tree in trees[1:]:
            s = summary[str(tree)]
            print(f"\n{tree.name} vs {trees[0].name}: cold {base['cold'] / s['cold']:.2f}x "
                  f"faster (wall), {base['cold_cpu'] / s['cold_cpu']:.2f}x (CPU), warm "
                  f"{base['warm'] / s['warm']:.2f}x")  # fmt: skip
            ratios = [
                bc["wall"] / sc["wall"]
                for (bc, _), (sc, _) in zip(runs[trees[0]], runs[tree], strict=True)
            ]
            print(f"  cold ratio per alternated pair: {', '.join(f'{r:.2f}' for r in ratios)}")
    if args.json:
        args.json.write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
