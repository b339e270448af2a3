"""Does a study's verdict depend on the instruction set the kernels are compiled for?

numba compiles for the host CPU; on a CPU with AVX-512 the kernels' sums round
differently from a generic x86-64's in the last bits. This script runs one job twice
under ``mpirun -n N``, once with the host's code and once with ``NUMBA_CPU_NAME=generic``
in an empty kernel cache, and prints, per series, each build's transition, its status,
the adaptive refinement's status and the failed tasks, then whether the two agree within
the job's adaptive tolerance. Exit code 0 if they do (and neither build failed a task),
1 if not.

    python benchmarks/cpu_reproducibility.py jobs/patterns_k0.1.toml [--ranks 3] [--keep DIR]

Measured on an AMD EPYC with AVX-512 (docs/patterns.md, "Reproducibility"): the
patterns job, 0 failed tasks on both builds (the generic one's seed point at
L = 9.3 mm needed ``[starts] retries``), every transition within the tolerance, rib's in y
by just the tolerance; with the free yarns gauged, every transition the same to 0.001, and
so on an AMD EPYC Zen 3 (AVX2) against the generic build. A verdict near the threshold is the parametrisation's and the
last bits of a relaxation decide it: ``[starts] spread`` measures how far.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib


def run(job: Path, out: Path, ranks: int, env: dict[str, str]) -> tuple[int, float]:
    mpirun = shutil.which("mpirun", path=str(Path(sys.executable).parent)) or "mpirun"
    cmd = [mpirun, "-n", str(ranks), sys.executable, "-m", "knitsweep", "run", str(job),
           "--out", str(out), "--quiet"]  # fmt: skip
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if proc.returncode not in (0, 4):  # 4: finished, some tasks failed
        sys.exit(f"{out.stem}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
    return proc.returncode, time.perf_counter() - t0


def series(path: Path) -> tuple[dict, int]:
    import knitsweep as ks

    res = ks.load(path)
    rows = {(r.stitch, r.direction): r for r in res.transitions.itertuples()}
    return rows, int(res.problems["status"].isin(["failed", "damaged"]).sum())


FINAL = ("done", "unjammed_at_start", "jammed_throughout")
"""The adaptive refinement's statuses of a series that has its answer."""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("job", type=Path)
    ap.add_argument("--ranks", type=int, default=3)
    ap.add_argument("--keep", type=Path, help="keep both results files in this directory")
    a = ap.parse_args()
    spec = tomllib.loads(a.job.read_text())
    r_mm = spec["grid"].get("r_mm", 0.74)
    tol = 2 * spec.get("adaptive", {}).get("tolerance_mm", 0.02) / r_mm
    work = Path(tempfile.mkdtemp(prefix="cpus-"))
    base = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    builds = {
        "host": base,
        "generic": {**base, "NUMBA_CPU_NAME": "generic", "NUMBA_CACHE_DIR": str(work / "cache")},
    }
    found = {}
    for name, env in builds.items():
        code, seconds = run(a.job, work / f"{name}.h5", a.ranks, env)
        rows, problems = series(work / f"{name}.h5")
        found[name] = rows
        print(f"{name:8s} exit {code}, {problems} failed or damaged tasks, {seconds:.0f} s wall")
        if problems:
            found[name + "_failed"] = problems
    print(f"\n{'series':22s} {'host (L/r)_trans':>22s} {'generic (L/r)_trans':>22s}  agree")
    agree = not any(k.endswith("_failed") for k in found)
    for key in sorted(set(found["host"]) | set(found["generic"])):
        h, g = found["host"].get(key), found["generic"].get(key)
        # the same verdict: a transition (refined to the tolerance) or an edge of the range
        # (unjammed at the first point, jammed throughout), the same within the tolerance
        same = (h is not None and g is not None and h.status == g.status
                and h.adaptive_status == g.adaptive_status in FINAL
                and abs(h.L_over_r_trans - g.L_over_r_trans) <= tol)  # fmt: skip
        agree &= same

        def text(r):
            return (
                "-" if r is None else f"{r.L_over_r_trans:.3f} {r.status[:10]}/{r.adaptive_status}"
            )

        print(
            f"{key[0] + ' ' + key[1]:22s} {text(h):>22s} {text(g):>22s}  {'yes' if same else 'NO'}"
        )
    print(f"\ntolerance: {tol:.3f} in L/r (twice the adaptive tolerance); "
          f"{'the builds agree' if agree else 'the builds DISAGREE'}")  # fmt: skip
    if a.keep:
        a.keep.mkdir(parents=True, exist_ok=True)
        for name in builds:
            shutil.copy2(work / f"{name}.h5", a.keep / f"{name}.h5")
    shutil.rmtree(work, ignore_errors=True)
    return 0 if agree else 1


if __name__ == "__main__":
    sys.exit(main())
