"""MPI throughput against a serial run of the same job (prints figures).

The master must not spin while it waits: with ``mpirun -n 3`` on a 2-core
machine (one master, two workers) a job should run >= 1.8x faster than
serially. Each configuration runs ``--repeats`` times into a fresh file
(numba's cache is warm after the first run); the median wall time is reported.

Run: ``python benchmarks/bench_throughput.py [--job jobs/demo.toml] [--repeats 3]``.
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


def _time(cmd: list[str]) -> float:
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})  # fmt: skip
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--job", type=Path, default=ROOT / "jobs" / "demo.toml")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    mpirun = shutil.which("mpirun", path=str(Path(sys.executable).parent)) or "mpirun"
    base = [sys.executable, "-m", "knitsweep", "run", str(args.job), "--quiet"]
    configs = {
        "serial": lambda out: [*base, "--out", out, "--executor", "serial"],
        "--workers 2": lambda out: [*base, "--out", out, "--workers", "2"],
        "mpirun -n 2": lambda out: [mpirun, "-n", "2", *base, "--out", out],
        "mpirun -n 3": lambda out: [mpirun, "-n", "3", *base, "--out", out],
    }
    print(f"throughput of {args.job.name} on {os.cpu_count()} cores, median of {args.repeats} runs")
    with tempfile.TemporaryDirectory() as tmp:
        _time(configs["serial"](f"{tmp}/warm.h5"))  # compile/load numba's cache once
        times = {}
        for name, make in configs.items():
            runs = []
            for i in range(args.repeats):
                runs.append(_time(make(f"{tmp}/{name.replace(' ', '_')}_{i}.h5")))
            times[name] = statistics.median(runs)
    print(f"{'executor':<16}{'median [s]':>12}{'vs serial':>11}")
    for name, t in times.items():
        print(f"{name:<16}{t:12.2f}{times['serial'] / t:10.2f}x")
    print("target: mpirun -n 3 on 2 cores >= 1.8x the serial throughput")


if __name__ == "__main__":
    main()
