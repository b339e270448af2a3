"""Checkpoint cost against results-file size: the shadow checkpoint (append in place
to a shadow copy, publish by rename) against a whole-file copy per checkpoint.

For each file size a results file is filled with synthetic sweeps (incompressible
``states``-sized arrays, the size of a job that stores states and geometry), then
``--rounds`` checkpoints each fold ``--batch`` new sweeps of ~100 KB into it:

* copy: what knitsweep did before: copy the file, add the sweeps, fsync, rename;
* shadow, first: the first checkpoint of a launch (it makes the shadow by one copy);
* shadow, steady: every later checkpoint (appends twice, copies nothing).

Prints one row per size with the medians (seconds). Needs ~3x the largest size
of free disk in ``--dir``.

    python benchmarks/bench_checkpoint.py --sizes-mb 10,100,1000
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from knitsweep.service.jobs import JobSpec
from knitsweep.store.checksum import seal_root
from knitsweep.store.journal import Entry
from knitsweep.store.table import put_rows
from knitsweep.store.writer import ResultWriter

JOB = JobSpec(schema_version=1, name="bench", grid={"L_mm": 11.6})


def sweep_record(rng: np.random.Generator, steps: int) -> tuple[dict, dict]:
    record = {"states": rng.random((steps, 30)), "control_points": rng.random((steps, 8, 6, 3)),
              "strain": np.linspace(0, 0.2, steps), "stress": rng.random(steps)}  # fmt: skip
    return record, {"status": "done", "message": "", "direction": "x", "L_mm": 11.6}


def fill(path: Path, size_mb: int, rng: np.random.Generator) -> None:
    """A results file of about ``size_mb`` MB: created by the writer, bulk rows added in
    place (1 MiB of incompressible ``states`` each, the shape of a long sweep's)."""
    ResultWriter(path, JOB).close("running")
    bulk = rng.random((4369, 30))  # ~1 MiB of float64
    meta = {"status": "done", "message": "", "direction": "x", "L_mm": 11.6}
    with h5py.File(path, "a") as f:
        for start in range(0, size_mb, 64):
            rows = [Entry("sweeps", f"bulk{i:06d}", {"states": bulk}, meta)
                    for i in range(start, min(size_mb, start + 64))]  # fmt: skip
            put_rows(f["sweeps"], "sweeps", rows)
        seal_root(f)
    with open(path, "rb") as fh:
        os.fsync(fh.fileno())


def copy_checkpoint(path: Path, batch: list) -> float:
    """The former scheme: copy, add, fsync, rename."""
    t0 = time.perf_counter()
    tmp = path.with_name(f".{path.name}.tmp")
    shutil.copyfile(path, tmp)
    with h5py.File(tmp, "a") as f:
        put_rows(f["sweeps"], "sweeps", [Entry("sweeps", *task) for task in batch])
        seal_root(f)
    with open(tmp, "rb") as fh:
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    return time.perf_counter() - t0


def shadow_checkpoints(path: Path, batches: list) -> list[float]:
    writer = ResultWriter(path, JOB)
    times = []
    try:
        for batch in batches:
            for tid, record, meta in batch:
                writer.add("sweeps", tid, record, meta)
            t0 = time.perf_counter()
            writer.checkpoint()
            times.append(time.perf_counter() - t0)
    finally:
        writer.close("running")
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes-mb", default="10,100,1000")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--batch", type=int, default=10, help="new sweeps per checkpoint")
    ap.add_argument("--dir", default=None, help="where to write the files [a temp dir]")
    args = ap.parse_args()
    rng = np.random.default_rng(1)
    root = Path(tempfile.mkdtemp(prefix="bench-checkpoint-", dir=args.dir))
    print(f"{args.batch} new sweeps of {sum(v.nbytes for v in sweep_record(rng, 150)[0].values()) / 1e3:.0f} kB "
          f"per checkpoint, median of {args.rounds}")  # fmt: skip
    print(f"{'file (MB)':>10} {'copy (s)':>10} {'shadow first (s)':>17} {'shadow steady (s)':>18} "
          f"{'copy / steady':>14}")  # fmt: skip
    try:
        for size in (int(s) for s in args.sizes_mb.split(",")):
            path = root / f"r{size}.h5"
            fill(path, size, rng)
            mb = path.stat().st_size / 1e6

            def batches(prefix, n):
                return [[(f"{prefix}{r}_{k}", *sweep_record(rng, 150)) for k in range(args.batch)]
                        for r in range(n)]  # fmt: skip

            copy = statistics.median(copy_checkpoint(path, b) for b in batches("c", args.rounds))
            times = shadow_checkpoints(path, batches("s", args.rounds + 1))
            steady = statistics.median(times[1:])
            print(f"{mb:10.0f} {copy:10.3f} {times[0]:17.3f} {steady:18.3f} {copy / steady:13.0f}x",
                  flush=True)  # fmt: skip
            path.unlink()
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
