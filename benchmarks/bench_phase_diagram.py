"""Time ``knitsweep phase-diagram`` on a large results file (prints figures).

By default the file of ``jobs/adaptive_kB.toml`` (803 tasks: (L/r)_trans over 4 x 4
values of (k, B), x and y, adaptive in L), run first if absent (~2 min on 2
cores). Prints, as the median of ``--repeat`` runs, the wall and CPU seconds (this
process and the helpers it forked) of
reading the file (``knitsweep.load``), of drawing every figure one by one and in
parallel (``render_figures``), and of the whole command (a subprocess, imports
included).

Run: ``python benchmarks/bench_phase_diagram.py [--results F] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _timed(fn):
    w, c = time.perf_counter(), _cpu()
    fn()
    return time.perf_counter() - w, _cpu() - c


def _cpu() -> float:
    """CPU seconds of this process and of its children that have ended."""
    import resource

    me, kids = (
        resource.getrusage(resource.RUSAGE_SELF),
        resource.getrusage(resource.RUSAGE_CHILDREN),
    )
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--results", type=Path, default=Path("adaptive_kB.h5"))
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    if not args.results.exists():
        subprocess.run([sys.executable, "-m", "knitsweep", "run", str(ROOT / "jobs" /
                        "adaptive_kB.toml"), "--out", str(args.results), "--quiet"], check=True)  # fmt: skip
    import knitsweep
    from knitsweep.report.figures import render_figures

    rows: dict[str, list[tuple[float, float]]] = {}
    for _ in range(args.repeat):
        res = None

        def load():
            nonlocal res
            res = knitsweep.load(args.results)

        rows.setdefault("load", []).append(_timed(load))
        red = res.reduction
        rows.setdefault("figures, 1 process", []).append(
            _timed(lambda red=red: list(render_figures(red, workers=1)))
        )
        rows.setdefault("figures, parallel", []).append(
            _timed(lambda red=red: list(render_figures(red)))
        )
        with tempfile.TemporaryDirectory() as d:
            cmd = [sys.executable, "-m", "knitsweep", "phase-diagram", str(args.results),
                   "--out", str(Path(d) / "pd")]  # fmt: skip
            t = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True)
            rows.setdefault("phase-diagram command", []).append((time.perf_counter() - t, 0.0))
    print(f"{args.results}: median of {args.repeat} runs")
    for name, vals in rows.items():
        wall = statistics.median(v[0] for v in vals)
        cpu = statistics.median(v[1] for v in vals)
        print(f"  {name:<24} {wall:7.2f} s wall" + (f"  {cpu:7.2f} s CPU (with helpers)"
                                                      if cpu else ""))  # fmt: skip


if __name__ == "__main__":
    main()
