"""The energy density's cost: the shipped job's wall time and states, and warm starts
along the rays against cold starts from the zero-force state.

Run: ``python benchmarks/bench_energy_density.py [--repeats 3] [--ranks 3] [--cold 111]
[--job jobs/energy_density_k0.1.toml] [--results FILE]``

1. ``mpirun -n RANKS knitsweep run JOB`` into a fresh file, ``--repeats`` times (the kernels
   cached by the first): the median whole-process wall time, the sampled states (every
   converged step of every sweep), states per second.
2. Warm against cold, from the last run's file: ``--cold`` states spread over the rays
   (every n-th converged step of each ray), each relaxed again from the point's zero-force
   state with the state's periods imposed and nothing carried (a fresh ``Relaxer``: no
   curvature, no walk), against the sweep's own relaxation of that step (warm-started
   from the step before). Medians of the seconds per state, their ratio, and how many cold
   relaxations ended in another state (lower or higher by more than 1e-9 mJ) or did not
   converge. Seconds
   are wall seconds of the relaxation alone, as the sweep records them.

Not a test: nothing here passes or fails.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def run_job(job: Path, ranks: int, out: Path) -> float:
    out.unlink(missing_ok=True)
    mpirun = str(Path(sys.executable).with_name("mpirun"))
    cmd = [mpirun, "-n", str(ranks), sys.executable, "-m", "knitsweep", "run", str(job),
           "--out", str(out), "--quiet"]  # fmt: skip
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    return time.perf_counter() - t0


def warm_against_cold(path: Path, n_cold: int) -> dict[str, float]:
    import knitsweep
    from knitsweep.config import Fidelity, SolverSettings
    from knitsweep.model import CellModel
    from knitsweep.presets import Numerics
    from knitsweep.relax import Relaxer
    from knitsweep.report.reduce import POINTS, SWEEPS

    res = knitsweep.load(path)
    entries = res.reduction.entries
    (point,) = [e for e in entries if e.kind == POINTS]
    numerics = Numerics.from_preset(point.meta.get("preset", "converged"))
    fidelity: Fidelity = numerics.fidelity
    solver: SolverSettings = numerics.solver
    params = res.points.iloc[0]
    from knitsweep.config import StitchParams

    sp = StitchParams(**{k: params[k] for k in StitchParams.model_fields if k in params})
    model = CellModel(sp, fidelity)
    rest = np.asarray(point.record["x"][int(point.record.get("winner", 0))])
    rays = [e for e in entries if e.kind == SWEEPS and e.meta["direction"].startswith("ray:")]
    per_ray = max(1, n_cold // len(rays))
    warm, cold, failed, lower, higher = [], [], 0, 0, 0
    for e in rays:
        rec = e.record
        ok = np.flatnonzero(np.asarray(rec["converged"], dtype=bool))[1:]
        for i in np.unique(ok[np.linspace(0, len(ok) - 1, per_ray).round().astype(int)]):
            x0 = rest.copy()
            x0[-2], x0[-1] = rec["a_x"][i], rec["a_y"][i]
            t0 = time.perf_counter()
            r = Relaxer(solver).relax(model, x0, fixed=e.meta["direction"])
            cold.append(time.perf_counter() - t0)
            warm.append(float(rec["relax_seconds"][i]))
            d = r.total_energy - rec["total_energy"][i]
            failed += not r.converged
            lower += bool(r.converged and d < -1e-9)
            higher += bool(r.converged and d > 1e-9)
    return {"states": len(cold), "warm_s": statistics.median(warm),
            "cold_s": statistics.median(cold), "failed": failed, "lower": lower,
            "higher": higher}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--ranks", type=int, default=3)
    ap.add_argument("--cold", type=int, default=111)
    ap.add_argument("--job", type=Path, default=ROOT / "jobs" / "energy_density_k0.1.toml")
    ap.add_argument("--results", type=Path, help="skip the runs: part 2 from this file")
    a = ap.parse_args()
    path = a.results
    if path is None:
        path = Path(tempfile.mkdtemp()) / "energy_density.h5"
        walls = [run_job(a.job, a.ranks, path) for _ in range(a.repeats)]
        import knitsweep

        n = len(knitsweep.load(path).energy_density_samples().W)  # the fit's samples
        wall = statistics.median(walls)
        print(f"job {a.job.name} under mpirun -n {a.ranks}: wall {wall:.1f} s median of "
              f"{a.repeats} ({', '.join(f'{w:.1f}' for w in walls)}), {n} states, "
              f"{n / wall:.1f} states/s")  # fmt: skip
    got = warm_against_cold(path, a.cold)
    print(f"warm against cold, {got['states']} states: warm {got['warm_s']:.3f} s, cold "
          f"{got['cold_s']:.3f} s median per state (cold / warm {got['cold_s'] / got['warm_s']:.1f}); "
          f"cold ended {got['lower']}x lower and {got['higher']}x higher than warm (by > 1e-9 "
          f"mJ), {got['failed']}x unconverged")  # fmt: skip


if __name__ == "__main__":
    main()
