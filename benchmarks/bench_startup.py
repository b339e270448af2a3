"""Warm start-up: whole-process wall seconds of two short commands (prints figures).

* ``mpirun -n 3 knitsweep run JOB`` on a file that already holds every task (start
  MPI, read the job, find nothing to do, release the workers, close the file);
* a one-stitch command, ``knitsweep energy --state Init_1.dat --L 11.6 --k 0.1
  --json`` (start-up, one energy from numba's cache).

numba's cache is warm (each command runs once untimed first). With ``--baseline
OTHER/venv/bin/python`` the other install runs the same commands in turn with this
one (A B A B ...), from a neutral directory; figures are medians of ``--repeats``.
Targets: <= 1.5 s and <= 0.6 s.

Run: ``python benchmarks/bench_startup.py [--repeats 5] [--baseline PY]``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
JOB = ROOT / "tests" / "data" / "jobs" / "tiny.toml"
STATE = ROOT / "knitsweep" / "stitches" / "stockinette" / "data" / "Init_1.dat"


def _time(cmd: list[str], cwd: str) -> float:
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   cwd=cwd, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})  # fmt: skip
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--baseline", help="the Python of another knitsweep install")
    args = ap.parse_args()
    installs = {"this": sys.executable}
    if args.baseline:
        installs["baseline"] = args.baseline
    with tempfile.TemporaryDirectory() as tmp:
        job = Path(tmp) / "tiny.toml"
        shutil.copy(JOB, job)
        commands = {}
        for name, python in installs.items():
            out = Path(tmp) / f"{name}.h5"
            subprocess.run([python, "-m", "knitsweep", "run", str(job), "--out", str(out),
                            "--quiet"], check=True, capture_output=True, cwd=tmp)  # fmt: skip
            mpirun = shutil.which("mpirun", path=str(Path(python).parent)) or "mpirun"
            commands[(name, "mpirun -n 3 run, finished file")] = [
                mpirun, "-n", "3", python, "-m", "knitsweep", "run", str(job), "--out",
                str(out), "--quiet"]  # fmt: skip
            commands[(name, "energy, one stitch")] = [
                python, "-m", "knitsweep", "energy", "--state", str(STATE), "--L", "11.6",
                "--k", "0.1", "--json"]  # fmt: skip
        for cmd in commands.values():
            _time(cmd, tmp)  # warm
        times: dict[tuple[str, str], list[float]] = {}
        for _ in range(args.repeats):
            for key, cmd in commands.items():
                times.setdefault(key, []).append(_time(cmd, tmp))
    print(f"warm start-up, whole-process wall seconds, median of {args.repeats}, "
          f"{os.cpu_count()} cores")  # fmt: skip
    print(f"{'command':<34}" + "".join(f"{n:>10}" for n in installs)
          + (f"{'base/this':>11}" if args.baseline else ""))  # fmt: skip
    for what in ("mpirun -n 3 run, finished file", "energy, one stitch"):
        med = {n: statistics.median(times[(n, what)]) for n in installs}
        line = f"{what:<34}" + "".join(f"{med[n]:10.2f}" for n in installs)
        if args.baseline:
            line += f"{med['baseline'] / med['this']:10.2f}x"
        print(line)
    print("targets: <= 1.5 s and <= 0.6 s")


if __name__ == "__main__":
    main()
