"""MPI throughput against a serial run of the same job (prints figures).

Whole-process wall seconds of ``knitsweep run JOB`` per executor (default: serial
and ``mpirun -n 3``, i.e. one master and two workers on a 2-core machine; the target
for ``jobs/phase_small.toml`` is >= 1.8x serial). Every configuration runs
``--repeats`` times into a fresh file (numba's cache warm: one run first, not
timed), in turn (A B A B ...) so that a machine whose speed drifts moves all alike;
figures are medians. With ``--baseline OTHER/venv/bin/python`` the other install runs
the same, in turn with this one, from a neutral directory.

Each run's file is compared with this install's first serial file: the same task
ids and every array and scalar of every task bit for bit, except the timings
(``relax_seconds``, ``wall_seconds``, and ``rank``, ``host``, ``seconds``) and each task's
checksum, which covers them.

Run: ``python benchmarks/bench_throughput.py [--job jobs/phase_small.toml]
[--repeats 3] [--configs serial "mpirun -n 3"] [--baseline PY]``.
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TIMINGS = {"relax_seconds", "wall_seconds", "rank", "host", "seconds",
           "sha256"}  # (a task's digest covers its timings)  # fmt: skip


def _time(cmd: list[str], cwd: str) -> float:
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   cwd=cwd, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})  # fmt: skip
    return time.perf_counter() - t


def differences(a: Path, b: Path) -> list[str]:
    """What differs between two results files, timings aside (empty: identical): every
    task's arrays and scalars, read through the store (rows of a table may arrive in
    another order)."""
    from knitsweep.store.read import iter_entries

    ea, eb = ({(e.kind, e.task_id): e for e in iter_entries(f, with_data=True)} for f in (a, b))
    if ea.keys() != eb.keys():
        return ["other task ids"]
    out = []
    for key, x in ea.items():
        y = eb[key]
        for part, va, vb in (("record", x.record, y.record), ("meta", x.meta, y.meta)):
            for name in (set(va) | set(vb)) - TIMINGS:
                if name not in va or name not in vb:
                    out.append(f"{key}/{part}/{name} missing")
                    continue
                u, v = np.asarray(va[name]), np.asarray(vb[name])
                nan = u.dtype.kind in "fc"
                if u.shape != v.shape or not np.array_equal(u, v, equal_nan=nan):
                    out.append(f"{key}/{part}/{name}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--job", type=Path, default=ROOT / "jobs" / "phase_small.toml")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--configs", nargs="+", default=["serial", "mpirun -n 3"],
                    help="serial, '--workers N', 'mpirun -n N'")  # fmt: skip
    ap.add_argument("--baseline", help="the Python of another knitsweep install")
    args = ap.parse_args()
    job = str(args.job.resolve())
    installs = {"this": sys.executable}
    if args.baseline:
        installs["baseline"] = args.baseline

    def command(python: str, config: str, out: str) -> list[str]:
        base = [python, "-m", "knitsweep", "run", job, "--quiet", "--out", out]
        if config == "serial":
            return [*base, "--executor", "serial"]
        if config.startswith("--workers"):
            return [*base, "--workers", config.split()[-1]]
        mpirun = shutil.which("mpirun", path=str(Path(python).parent)) or "mpirun"
        return [mpirun, "-n", config.split()[-1], *base]

    times: dict[tuple[str, str], list[float]] = {}
    problems: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        reference = Path(tmp) / "reference.h5"
        for name, python in installs.items():  # load numba's cache once, untimed
            _time(command(python, "serial", str(reference if name == "this" else
                                               Path(tmp) / f"warm-{name}.h5")), tmp)  # fmt: skip
        for i in range(args.repeats):
            for config in args.configs:
                for name, python in installs.items():
                    out = Path(tmp) / f"{name}-{config.replace(' ', '_')}-{i}.h5"
                    times.setdefault((name, config), []).append(
                        _time(command(python, config, str(out)), tmp)
                    )
                    if name == "this":
                        problems += [f"{out.name}: {d}" for d in differences(reference, out)]
                    out.unlink()
    print(f"throughput of {args.job.name}, whole-process wall seconds on {os.cpu_count()} "
          f"cores, median of {args.repeats}")  # fmt: skip
    head = f"{'executor':<14}" + "".join(f"{n + ' [s]':>14}{'vs serial':>10}" for n in installs)
    print(head + (f"{'this/base':>11}" if args.baseline else ""))
    for config in args.configs:
        line = f"{config:<14}"
        for name in installs:
            t = statistics.median(times[(name, config)])
            line += f"{t:14.2f}{statistics.median(times[(name, 'serial')]) / t:9.2f}x"
        if args.baseline:
            ratio = statistics.median(times[("baseline", config)]) / statistics.median(
                times[("this", config)]
            )
            line += f"{ratio:10.2f}x"
        print(line)
    print(
        "results of this install identical to its serial run (task ids, datasets, "
        "attributes; timings aside):",
        "yes" if not problems else f"NO: {problems[:5]}",
    )
    print("target: mpirun -n 3 on 2 cores >= 1.8x the serial throughput")


if __name__ == "__main__":
    main()
