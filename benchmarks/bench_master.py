"""The master's ceiling: results journalled and checkpointed per second (prints figures).

Tasks of zero cost: every rank replaces the worker's ``execute`` (and the kernel
``prepare``) by one that returns a small record at once (two scalars and one
4-element array), so that the run measures only the service around the
computation: scheduling, messages, the journal's fsyncs and the HDF5 checkpoints.
The job has ``--points`` grid points with x and y sweeps (3 tasks each). Two
figures per executor: ``journal``, results journalled per second (the HDF5 fold
replaced by a no-op; every result in the journal at the end, checked), and
``journal+hdf5``, journalled and checkpointed every second into the HDF5 file
(every result in the file at the end, checked). Each is the median over ``--runs``
runs of the results over the seconds from the start of the master's loop to the
end of ``service.run`` (the final checkpoint included; reading the job, planning
the task ids and opening the file excluded), into a fresh file. Under MPI on a
machine of few cores the workers, not the master, may set that rate (each handles
its tasks' messages); so a second table gives a lower bound of the master's ceiling:
results per CPU second of the master's process over the same span (its sleeps while
it waits do not count; its polling between them does).

With ``--baseline OTHER/venv/bin/python`` the other install runs the same, in turn
with this one (A B A B ...), from a neutral directory.

``--replay FILE.h5``: every task returns a copy of the first done point's or sweep's
record of a real results file instead (the same arrays and scalars: a real
checkpoint's cost per result).

``--replay-baseline OLD.h5``: the baseline's own copy of those records (the same job
run by the baseline install), for a baseline that cannot read this version's file.

Run: ``python benchmarks/bench_master.py [--points 1000] [--runs 3] [--baseline PY]
[--replay FILE.h5 [--replay-baseline OLD.h5]]``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

JOB = """schema_version = 1
name = "master_ceiling"
seed = 1
directions = ["x", "y"]
preset = "draft"

[grid]
L_mm = {{ start = 10.0, stop = {stop:.2f}, step = 0.01 }}
k_mN_per_mm2 = [0.1, 0.2, 0.4, 0.8, 1.6]

[run]
checkpoint_s = 1.0
"""

# one run, written against both layouts of the executors (a module before, a package now)
INNER = r"""
import importlib, json, socket, sys, time
import numpy as np
import h5py
from knitsweep import service
from knitsweep.service.worker import Reply
from knitsweep.store import writer as store_writer
from knitsweep.store.format import journal_dir
from knitsweep.store.journal import scan

RECORDS = {}
if len(sys.argv) > 5:  # replay the records of a real results file: real sizes
    from knitsweep.store.read import iter_entries
    keep = ("status", "message")
    for e in iter_entries(sys.argv[5], with_data=True):
        if e.kind not in RECORDS and e.meta.get("status") == "done" and e.kind != "series":
            scalars = {k: v for k, v in e.meta.items() if k.startswith(("E", "delta", "energy",
                       "Y_", "sigma", "n_", "thickness"))}
            RECORDS[e.kind] = {**e.record, **scalars, **{k: e.meta[k] for k in keep}}

def execute(job, task, zero, rank):
    kind = "sweeps" if hasattr(task, "direction") else "points"
    record = dict(RECORDS.get(kind) or {"status": "done", "message": "synthetic",
                                        "E_mJ": 1.0, "energies": np.arange(4.0)})
    return Reply(task.task_id, record, None, rank, socket.gethostname(), 0.0)

for name in ("knitsweep.service.executors", "knitsweep.service.executors.local",
             "knitsweep.service.executors.mpi"):
    try:
        module = importlib.import_module(name)
    except ImportError:
        continue
    if hasattr(module, "execute"):
        module.execute = execute
        module.prepare = lambda job, notice=None: 0.0

job, out, executor, what = sys.argv[1:5]
if what == "journal":  # no HDF5 fold: the results stay in the journal (counted below)
    def checkpoint(self, attrs=None):
        return self.commit() if hasattr(self, "commit") else 0
    def close(self, run_status, attrs=None):
        checkpoint(self)
        self._release_lock()
    store_writer.ResultWriter.checkpoint = checkpoint
    store_writer.ResultWriter.close = close
from knitsweep.service import master as service_master
loop = {}
run_loop = service_master._Master.run
def timed_run(self):
    loop["start"] = time.perf_counter()
    loop["cpu"] = time.process_time()
    return run_loop(self)
service_master._Master.run = timed_run
t0 = time.perf_counter()
summary = service.run(job, out, executor=executor, show_progress=False, max_tasks=10**6)
end = time.perf_counter()
cpu = time.process_time() - loop.get("cpu", 0.0)
seconds = end - loop.get("start", t0)
if summary is not None:
    if what == "journal":
        stored = len({(e.kind, e.task_id) for e in scan(journal_dir(__import__("pathlib").Path(out)))[0]})
    else:
        with h5py.File(out) as f:
            stored = sum(len(f[k]["task"]) if f[k].attrs.get("layout") == "table" else len(f[k])
                         for k in ("points", "sweeps"))  # tables (schema 3) or groups
    assert stored == summary.total == summary.counts["done"], (stored, summary.total)
    print(json.dumps({"results": stored, "seconds": seconds, "whole_s": end - t0, "cpu_s": cpu}))
"""


def one_run(python: str, job: Path, out: Path, mode: str, what: str, replay=None) -> dict:
    script = out.parent / "inner.py"
    script.write_text(INNER)
    extra = [str(replay)] if replay else []
    if mode == "serial":
        cmd = [python, str(script), str(job), str(out), "serial", what, *extra]
    else:
        n = mode.split()[-1]
        mpirun = shutil.which("mpirun", path=str(Path(python).parent)) or "mpirun"
        cmd = [mpirun, "-n", n, python, str(script), str(job), str(out), "mpi", what, *extra]
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=out.parent, env=env,
                          timeout=900)  # fmt: skip
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1000, help="grid points (5 per L value)")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--modes", nargs="+", default=["serial", "mpirun -n 3"])
    ap.add_argument("--baseline", help="the Python of another knitsweep install")
    ap.add_argument(
        "--replay",
        type=Path,
        help="a results file: each task returns a copy "
        "of its first done point's or sweep's record (real sizes)",
    )
    ap.add_argument(
        "--replay-baseline",
        type=Path,
        help="the baseline's own copy of the --replay results (the same job run by the "
        "baseline install, when it cannot read this version's file)",
    )
    ap.add_argument("--what", nargs="+", default=["journal", "journal+hdf5"])
    args = ap.parse_args()
    installs = {"this": sys.executable}
    if args.baseline:
        installs["baseline"] = args.baseline
    rates: dict[tuple[str, str, str], list[float]] = {}
    ceilings: dict[tuple[str, str, str], list[float]] = {}
    whats = args.what
    with tempfile.TemporaryDirectory() as tmp:
        job = Path(tmp) / "master.toml"
        job.write_text(JOB.format(stop=10.0 + 0.01 * (args.points // 5 - 1) + 0.001))
        for i in range(args.runs):
            for what in whats:
                for mode in args.modes:
                    for name, python in installs.items():
                        d = Path(tmp) / f"{name}-{mode.replace(' ', '_')}-{what}-{i}"
                        d.mkdir()
                        replay = args.replay
                        if name == "baseline" and args.replay_baseline:
                            replay = args.replay_baseline
                        r = one_run(python, job, d / "out.h5", mode, what, replay)
                        key = (name, mode, what)
                        rates.setdefault(key, []).append(r["results"] / r["seconds"])
                        ceilings.setdefault(key, []).append(r["results"] / r["cpu_s"])
                        shutil.rmtree(d)
    n = 3 * (args.points // 5) * 5
    print(f"master throughput, {n} zero-cost tasks (points and x/y sweeps), {os.cpu_count()} "
          f"cores, results per second, median of {args.runs}: 'journal' = journalled (group "
          "commit, no HDF5 fold), 'journal+hdf5' = journalled and checkpointed every 1 s "
          "into the HDF5 file")  # fmt: skip
    for title, table in (("results per second", rates),
                         ("master's ceiling (a lower bound): results per master CPU second", ceilings)):  # fmt: skip
        print(title)
        head = f"{'mode':<14}{'what':<14}" + "".join(f"{name:>12}" for name in installs)
        print(head + (f"{'ratio':>9}" if args.baseline else ""))
        for what in whats:
            for mode in args.modes:
                med = {name: statistics.median(table[(name, mode, what)]) for name in installs}
                line = f"{mode:<14}{what:<14}" + "".join(f"{med[name]:12,.0f}" for name in installs)
                if args.baseline:
                    line += f"{med['this'] / med['baseline']:8.1f}x"
                print(line)
    if args.replay:
        print(f"records replayed from {args.replay}")
    print("target: >= 5,000 results/s")


if __name__ == "__main__":
    main()
