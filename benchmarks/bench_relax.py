"""Relaxation and sweep benchmark (prints figures; not a pass/fail test).

1. Zero-force relaxation from Init_1 at L = 11.6 mm, k = 0.1 mN/mm^2 (one start),
   against the authors' code on this machine (tests/data/relaxed_reference.json).
2. One full x sweep at h = 0.001 mm with 4 starts (the paper's protocol), and the
   same in y: wall time, relaxations per sweep, evaluations per relaxation.

Run: ``python benchmarks/bench_relax.py [--repeats N]``. Single-threaded (BLAS
pinned to one thread, as knitsweep's tasks run).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

from threadpoolctl import threadpool_limits

from knitsweep.config import Numerics, StartSettings, StitchParams
from knitsweep.formats import shipped_state
from knitsweep.model import CellModel
from knitsweep.relax import relax
from knitsweep.strain_sweep import strain_sweep
from knitsweep.zero_force import zero_force

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5, help="runs per relaxation figure")
    ap.add_argument("--sweep-repeats", type=int, default=3, help="runs per sweep figure")
    args = ap.parse_args()
    ref = json.loads((DATA / "relaxed_reference.json").read_text())
    case = ref["cases"][0]
    params = StitchParams(L_mm=11.6, k_mN_per_mm2=0.1)
    x0 = shipped_state(1)
    threadpool_limits(1)

    print("knitsweep relaxation benchmark (single-threaded, one core)")
    print(f"authors' code: {case['seconds']:.1f} s, {case['iterations']} iterations, "
          f"{case['energy_evaluations']} energy evaluations (finite differences)")  # fmt: skip
    print()
    print(f"{'zero-force relaxation from Init_1':<44}{'median [ms]':>12}{'iters':>7}{'evals':>7}"
          f"{'E - E_ref [mJ]':>16}{'speed-up':>11}")  # fmt: skip
    for preset in ("paper", "converged"):
        numerics = Numerics.from_preset(preset)
        model = CellModel(params, numerics.fidelity)
        solver = numerics.solver
        relax(model, x0, settings=solver)  # JIT warm-up
        times, r = [], None
        for _ in range(args.repeats):
            t = time.perf_counter()
            r = relax(model, x0, settings=solver)
            times.append(time.perf_counter() - t)
        med = statistics.median(times)
        label = f"  preset {preset!r} (ftol {solver.ftol:g})"
        print(f"{label:<44}{med * 1e3:12.1f}{r.iterations:7d}"
              f"{r.evaluations:7d}{r.total_energy - case['total_energy']:16.2e}"
              f"{case['seconds'] / med:10.0f}x")  # fmt: skip

    print()
    print(f"{'full sweep, h = 0.001 mm, 4 starts':<36}{'median [s]':>11}{'steps':>7}"
          f"{'relax.':>8}{'evals/relax':>12}{'ms/relax':>10}")  # fmt: skip
    zero = zero_force(params, starts=StartSettings(count=4))
    for direction in ("x", "y"):
        times, s = [], None
        for _ in range(args.sweep_repeats):
            t = time.perf_counter()
            s = strain_sweep(params, zero, direction)
            times.append(time.perf_counter() - t)
        med = statistics.median(times)
        evals = s.evaluations[1:].mean()
        label = f"  {direction}: {s.stop_reason}"
        print(f"{label:<36}{med:11.2f}{len(s.strain):7d}{s.relaxations:8d}"
              f"{evals:12.1f}{med / s.relaxations * 1e3:10.2f}")  # fmt: skip
    print()
    print("targets: relaxation >= 1,000x faster than the authors'; one full sweep <= 30 s")


if __name__ == "__main__":
    main()
