"""Adaptive transition search against the paper's uniform grid (prints figures).

The paper's k = 0.1 mN/mm^2 series in x and y: ``jobs/paper_k0.1_L_sweep.toml``
(L = 10.5 … 12.8 mm every 0.1 mm) against ``jobs/adaptive_k0.1.toml`` (0.8 mm
coarse grid, refined to 0.005 mm), both under ``mpirun -n 3``. Reports sweeps,
wall time, the boundary each finds, and whether the adaptive boundary lies in
the grid's bracket.

Run: ``python benchmarks/bench_adaptive.py [--ranks 3] [--grid-results F]
[--adaptive-results F]`` (existing result files are reused instead of rerun).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import time
from pathlib import Path

from knitsweep.analysis import energy_gaps, transition
from knitsweep.store.read import iter_entries, read_root

ROOT = Path(__file__).resolve().parents[1]


def _run(job: Path, out: Path, ranks: int) -> float:
    mpirun = shutil.which("mpirun", path=str(Path(sys.executable).parent)) or "mpirun"
    t = time.perf_counter()
    subprocess.run([mpirun, "-n", str(ranks), sys.executable, "-m", "knitsweep", "run", str(job),
                    "--out", str(out), "--quiet"], check=True)  # fmt: skip
    return time.perf_counter() - t


def _sweeps(path: Path) -> dict[str, dict[float, float]]:
    """direction -> {L: energy gap} of every done sweep."""
    gaps: dict[str, dict[float, float]] = {"x": {}, "y": {}}
    for e in iter_entries(path, with_data=True):
        if e.kind == "sweeps" and e.meta.get("status") == "done":
            d = str(e.meta["direction"])
            g = energy_gaps(e.record["bending_energy"], e.record["contact_energy"])
            gaps[d][float(e.meta["L_mm"])] = g.jamming_gap(d)
    return gaps


def _elapsed(path: Path) -> float:
    from datetime import datetime

    root = read_root(path)
    return (
        datetime.fromisoformat(root["finished_at"]) - datetime.fromisoformat(root["started_at"])
    ).total_seconds()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ranks", type=int, default=3)
    ap.add_argument("--grid-results", type=Path, default=Path("bench_grid_k0.1.h5"))
    ap.add_argument("--adaptive-results", type=Path, default=Path("bench_adaptive_k0.1.h5"))
    args = ap.parse_args()
    walls = {}
    for name, job, out in (("grid", ROOT / "jobs" / "paper_k0.1_L_sweep.toml", args.grid_results),
                           ("adaptive", ROOT / "jobs" / "adaptive_k0.1.toml", args.adaptive_results)):  # fmt: skip
        if out.exists() and read_root(out).get("run_status") == "complete":
            walls[name] = _elapsed(out)
            print(f"{name}: reusing {out} ({walls[name]:.0f} s when it ran)")
        else:
            walls[name] = _run(job, out, args.ranks)
    grid, adaptive = _sweeps(args.grid_results), _sweeps(args.adaptive_results)
    series = {str(e.meta["direction"]): e.meta for e in iter_entries(args.adaptive_results)
              if e.kind == "series"}  # fmt: skip
    r = 0.74
    print()
    print(f"k = 0.1 mN/mm^2, mpirun -n {args.ranks}: uniform 0.1 mm grid vs adaptive")
    print(f"{'':4}{'sweeps grid':>12}{'sweeps adapt.':>14}{'grid bracket (L/r)':>24}"
          f"{'adaptive bracket (L/r)':>26}{'width ratio':>12}{'inside':>8}")  # fmt: skip
    total = {"grid": 0, "adaptive": 0}
    for d in ("x", "y"):
        Ls = sorted(grid[d])
        t = transition([L / r for L in Ls], [grid[d][L] for L in Ls])
        s = series[d]
        lo, hi = float(s["lo_mm"]) / r, float(s["hi_mm"]) / r
        inside = t.bracket_lower <= lo and hi <= t.bracket_upper + 1e-12
        ratio = (t.bracket_upper - t.bracket_lower) / (hi - lo)
        total["grid"] += len(grid[d])
        total["adaptive"] += len(adaptive[d])
        print(f"{d:4}{len(grid[d]):12d}{len(adaptive[d]):14d}"
              f"{f'({t.bracket_lower:.4f}, {t.bracket_upper:.4f}]':>24}"
              f"{f'({lo:.4f}, {hi:.4f}]':>26}{ratio:11.0f}x{inside!s:>8}")  # fmt: skip
    print(f"total sweeps: grid {total['grid']}, adaptive {total['adaptive']} "
          f"({total['grid'] / total['adaptive']:.1f}x fewer); wall time: grid {walls['grid']:.0f} s, "
          f"adaptive {walls['adaptive']:.0f} s ({walls['grid'] / walls['adaptive']:.1f}x)")  # fmt: skip
    print("target: >= 3x fewer sweeps for a 20x narrower bracket, inside the grid's bracket")


if __name__ == "__main__":
    main()
