"""What the results file's checksums (a row's ``sha256``, ``knitsweep.store.table``, and the
root's, ``knitsweep.store.checksum``) cost a run.

Runs a job once (serially; default ``jobs/demo.toml``), then with the finished
file's own task records:

* write: every task folded into a fresh results file by the writer (journal and
  checkpoint), with checksums and with the digests switched off (median of
  ``--repeats``); the difference is what the checksums add to a run;
* verify: one full read of the file with its data (what ``status``, resume,
  ``merge`` and the post-processor do), with and without verifying the digests.

Prints the figures and the write overhead as a share of the run's wall time.

    python benchmarks/bench_checksum.py [--job jobs/demo.toml] [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path
from unittest import mock

from knitsweep import service
from knitsweep.service.jobs import load_job
from knitsweep.store import table, writer
from knitsweep.store.read import iter_entries

ROOT = Path(__file__).resolve().parents[1]


def write_all(path: Path, job, entries) -> float:
    t0 = time.perf_counter()
    w = writer.ResultWriter(path, job)
    for e in entries:
        w.add(e.kind, e.task_id, e.record, e.meta)
    w.close("complete")
    return time.perf_counter() - t0


def read_all(path: Path) -> float:
    t0 = time.perf_counter()
    for _ in iter_entries(path, with_data=True):
        pass
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--job", type=Path, default=ROOT / "jobs" / "demo.toml")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    job = load_job(args.job)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        out = tmp / "run.h5"
        t0 = time.perf_counter()
        summary = service.run(args.job, out, executor="serial", show_progress=False)
        run_s = time.perf_counter() - t0
        entries = list(iter_entries(out, with_data=True))
        timings: dict[str, list[float]] = {"on": [], "off": [], "read_on": [], "read_off": []}
        no_digest = mock.patch.object(table, "row_digest", lambda *a: "0" * 64)
        no_root = mock.patch.object(writer, "seal_root", lambda f: None)
        for i in range(args.repeats):
            timings["on"].append(write_all(tmp / f"on{i}.h5", job, entries))
            with no_digest, no_root:
                timings["off"].append(write_all(tmp / f"off{i}.h5", job, entries))
            timings["read_on"].append(read_all(tmp / f"on{i}.h5"))
            with no_digest:  # the rows' digests not computed: the reads compare constants
                timings["read_off"].append(read_all(tmp / f"off{i}.h5"))
        m = {k: statistics.median(v) for k, v in timings.items()}
        n = len(entries)
        digest_ms = statistics.median(
            _time_digests(entries) for _ in range(args.repeats)
        ) * 1e3 / max(n, 1)  # fmt: skip
    extra = m["on"] - m["off"]
    print(f"job {job.name}: {summary.total} tasks, run {run_s:.2f} s (serial, wall)")
    print(f"write every task (journal + checkpoint): {m['on']:.3f} s with checksums, "
          f"{m['off']:.3f} s without (median of {args.repeats})")  # fmt: skip
    print(f"read every task with data:               {m['read_on']:.3f} s verified, "
          f"{m['read_off']:.3f} s unverified")  # fmt: skip
    print(f"one row digest: {digest_ms:.3f} ms per task")
    print(f"checksum cost of the run: {extra:+.3f} s = {100 * extra / run_s:+.2f} % of its wall "
          f"time; verifying on resume: {100 * (m['read_on'] - m['read_off']) / run_s:+.2f} %")  # fmt: skip


def _time_digests(entries) -> float:
    """Seconds to digest every task's row (its id, a JSON of its scalars, its arrays)."""
    import json

    import numpy as np

    rows = []
    for e in entries:
        values = {**e.meta, **e.record}
        arrays = {k: v for k, v in values.items() if isinstance(v, np.ndarray) and v.ndim > 0}
        scalars = {k: str(v) for k, v in values.items() if k not in arrays}
        rows.append((e.task_id, json.dumps(scalars, sort_keys=True), arrays))
    t0 = time.perf_counter()
    for row in rows:
        table.row_digest(*row)
    return time.perf_counter() - t0


if __name__ == "__main__":
    main()
