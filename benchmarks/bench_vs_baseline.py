"""This checkout against another knitsweep install, side by side (prints figures).

Both are run in turn, A B A B ..., each in a fresh process of its own Python, and every
figure is a median over the runs; ratios are taken pair by pair, so that a machine
whose speed drifts (other jobs) moves both alike.

* ``sweep``: one point's full sweep (default x at L = 11.0 mm, k = 0.1 mN/mm^2, the
  default preset, 4 starts): CPU seconds of the zero-force state and of the sweep
  alone, steps, relaxations, evaluations, and Y_sec and the energy gaps of each, with
  their relative difference.
* ``adaptive``: a job under ``mpirun -n 3`` (default ``jobs/adaptive_k0.1.toml``; the
  baseline may need its own copy of the file, ``--baseline-job``): whole-process wall
  seconds and each series' final bracket.

Run: ``python benchmarks/bench_vs_baseline.py --baseline OTHER/venv/bin/python
[--what sweep adaptive] [--runs 3]``.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# one point's sweep, written against both package layouts (before and after the
# split into config / zero_force / strain_sweep)
SWEEP = r"""
import json, sys, time
import numpy as np
from threadpoolctl import threadpool_limits
try:
    from knitsweep.config import StitchParams, StartSettings
    try:
        from knitsweep.relax.zero_force import zero_force
    except ImportError:  # before zero_force moved into relax/
        from knitsweep.zero_force import zero_force
    from knitsweep.strain_sweep import strain_sweep
except ImportError:
    from knitsweep.params import StitchParams
    from knitsweep.multistart import StartSettings, zero_force
    from knitsweep.sweep import strain_sweep
from knitsweep.formats import shipped_state
from knitsweep.model import CellModel
L, k, d, starts = float(sys.argv[1]), float(sys.argv[2]), sys.argv[3], int(sys.argv[4])
threadpool_limits(1)
p = StitchParams(L_mm=L, k_mN_per_mm2=k)
# load the compiled kernels before the clock starts
m, x = CellModel(p), shipped_state(1)
m.energy_and_gradients(x)
m.energy_and_gradients(x, m.neighbour_list(x))
m.min_zeta(x)
m.thickness(x)
try:  # where each version keeps it (none before the compiled step)
    from knitsweep.kernels.kkt_rows import compile_solver
except ImportError:
    try:
        from knitsweep.kernels.kkt import compile_solver
    except ImportError:
        compile_solver = None
if compile_solver is not None:
    compile_solver()
t = time.process_time()
zero = zero_force(p, starts=StartSettings(count=starts))
t_zero = time.process_time() - t
t = time.process_time()
s = strain_sweep(p, zero, d)
t_sweep = time.process_time() - t
eb, ec = np.asarray(s.bending_energy), np.asarray(s.contact_energy)
y_sec = float(np.interp(0.02, s.strain, s.stress)) / 0.02
print(json.dumps({"zero_s": t_zero, "sweep_s": t_sweep, "steps": len(s.strain),
                  "relaxations": s.relaxations,
                  "evaluations": int(getattr(s, "evaluations_total", 0)) or None,
                  "Y_sec": y_sec, "dE_b": float(eb[0] - eb.min()),
                  "dE_c": float(ec[0] - ec.min())}))
"""


def _sweep_run(python: str, args) -> dict:
    # from a neutral directory: a checkout's own package must not shadow the install's
    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run([python, "-c", SWEEP, str(args.L), str(args.k), args.direction,
                              str(args.starts)], capture_output=True, text=True, check=True,
                             cwd=tmp)  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def _adaptive_run(python: str, job: Path) -> dict:
    mpirun = shutil.which("mpirun", path=str(Path(python).parent)) or "mpirun"
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "r.h5"
        t = time.perf_counter()
        subprocess.run([mpirun, "-n", "3", python, "-m", "knitsweep", "run", str(job.resolve()),
                        "--out", str(out), "--quiet"], check=True, capture_output=True,
                       cwd=tmp)  # fmt: skip
        wall = time.perf_counter() - t
        import h5py

        brackets = {}
        with h5py.File(out) as f:
            for g in f.get("series", {}).values():
                brackets[str(g.attrs["direction"])] = (float(g.attrs["lo_mm"]),
                                                       float(g.attrs["hi_mm"]))  # fmt: skip
    return {"wall_s": wall, "brackets": brackets}


def _median(runs: list[dict], key: str) -> float:
    return statistics.median(r[key] for r in runs)


def compare_sweep(args) -> None:
    runs: dict[str, list[dict]] = {"A": [], "B": []}
    for _ in range(args.runs):
        runs["A"].append(_sweep_run(sys.executable, args))
        runs["B"].append(_sweep_run(args.baseline, args))
    a, b = runs["A"], runs["B"]
    ratio = statistics.median(rb["sweep_s"] / ra["sweep_s"] for ra, rb in zip(a, b, strict=True))
    print(
        f"one full {args.direction} sweep, L = {args.L} mm, k = {args.k} mN/mm^2, default "
        f"preset, {args.starts} starts; medians of {args.runs} alternating runs, CPU seconds"
    )
    print(f"{'':12}{'zero-force s':>13}{'sweep s':>9}{'steps':>7}{'relax.':>8}{'evals':>8}"
          f"{'Y_sec N/mm':>12}{'dE_b mJ':>11}{'dE_c mJ':>11}")  # fmt: skip
    for name, r in (("this (A)", a[-1]), ("baseline (B)", b[-1])):
        runs_ = a if name.startswith("this") else b
        ev = r["evaluations"]
        print(f"{name:12}{_median(runs_, 'zero_s'):13.2f}{_median(runs_, 'sweep_s'):9.2f}"
              f"{r['steps']:7d}{r['relaxations']:8d}{ev if ev else '-':>8}{r['Y_sec']:12.6g}"
              f"{r['dE_b']:11.4e}{r['dE_c']:11.4e}")  # fmt: skip
    ra, rb = a[-1], b[-1]
    rel = {k: abs(ra[k] - rb[k]) / abs(rb[k]) if rb[k] else abs(ra[k]) for k in ("Y_sec", "dE_b",
                                                                              "dE_c")}  # fmt: skip
    print(
        f"sweep {ratio:.1f}x faster (pairwise median of B/A); relative differences: "
        + ", ".join(f"{k} {v:.2e}" for k, v in rel.items())
    )
    print("targets: >= 5x, Y_sec within 1 %, gaps within 2 %")


def compare_adaptive(args) -> None:
    job_a = args.job
    job_b = args.baseline_job or args.job
    pairs = []
    for _ in range(args.runs):
        pairs.append((_adaptive_run(sys.executable, job_a), _adaptive_run(args.baseline, job_b)))
    ratio = statistics.median(b["wall_s"] / a["wall_s"] for a, b in pairs)
    print(
        f"\n{job_a.name} under mpirun -n 3; whole-process wall seconds, medians of "
        f"{args.runs} alternating runs"
    )
    for name, i in (("this (A)", 0), ("baseline (B)", 1)):
        wall = statistics.median(p[i]["wall_s"] for p in pairs)
        br = pairs[-1][i]["brackets"]
        print(f"{name:14}{wall:8.1f} s  " + "  ".join(f"{d}: ({lo:.6f}, {hi:.6f}] mm"
                                                     for d, (lo, hi) in sorted(br.items())))  # fmt: skip
    a, b = pairs[-1][0]["brackets"], pairs[-1][1]["brackets"]
    shift = max(abs(x - y) for d in a for x, y in zip(a[d], b[d], strict=True))
    print(f"{ratio:.1f}x faster (pairwise median); brackets differ by at most {shift:.2g} mm")
    print("targets: >= 8x, the same brackets within 0.01 mm")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", required=True, help="the Python of the other install")
    ap.add_argument("--what", nargs="+", default=["sweep", "adaptive"],
                    choices=["sweep", "adaptive"])  # fmt: skip
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--L", type=float, default=11.0)
    ap.add_argument("--k", type=float, default=0.1)
    ap.add_argument("--direction", default="x", choices=["x", "y"])
    ap.add_argument("--starts", type=int, default=4)
    ap.add_argument("--job", type=Path, default=ROOT / "jobs" / "adaptive_k0.1.toml")
    ap.add_argument("--baseline-job", type=Path, default=None,
                    help="the job file for the baseline (its own schema) [--job]")  # fmt: skip
    args = ap.parse_args()
    if "sweep" in args.what:
        compare_sweep(args)
    if "adaptive" in args.what:
        compare_adaptive(args)


if __name__ == "__main__":
    main()
