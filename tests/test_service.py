"""The sweep service: one HDF5 file, resume, refusal, failure isolation, shards, MPI
(integration tier; interrupted runs: test_service_signals.py)."""

import shutil
import time

import h5py
import numpy as np
import pytest
from conftest import MPIRUN, TINY, assert_same_results, physics, stored, stored_meta
from conftest import run_knitsweep as knitsweep

from knitsweep import service
from knitsweep.config import InputError
from knitsweep.service.executors import SerialExecutor
from knitsweep.service.jobs import load_job
from knitsweep.service.master import run_job
from knitsweep.store.format import RESULTS_SCHEMA_VERSION, journal_dir, lock_path


def test_file_schema(tiny_reference):
    with h5py.File(tiny_reference, "r") as f:
        for key in ("schema_version", "knitsweep_version", "git_commit", "job_json", "job_hash",
                    "numpy_version", "scipy_version", "numba_version", "h5py_version",
                    "hdf5_version", "mpi4py_version", "mpi_library_version", "host",
                    "slurm_job_id", "started_at", "finished_at"):  # fmt: skip
            assert key in f.attrs, key
        assert f.attrs["schema_version"] == RESULTS_SCHEMA_VERSION
        assert f.attrs["run_status"] == "complete"
        assert f["points"].attrs["layout"] == f["sweeps"].attrs["layout"] == "table"
        assert len(f["points/task"]) == 2 and len(f["sweeps/task"]) == 4
    points, sweeps = stored(tiny_reference, "points"), stored(tiny_reference, "sweeps", True)
    assert len(points) == 2 and len(sweeps) == 4
    for e in sweeps.values():
        assert e.meta["status"] == "done"
        assert e.record["stress"][0] == 0.0 and e.record["strain"][0] == 0.0
        assert e.record["stress"][-1] > 0.0 and np.all(np.isfinite(e.record["stress"]))
        assert "states" not in e.record  # not asked for
        assert {"seed", "rank", "host", "seconds"} <= set(points[e.meta["point_id"]].meta)
    assert not journal_dir(tiny_reference).exists() and not lock_path(tiny_reference).exists()


def test_rerun_skips_finished_tasks(tiny_reference, tmp_path):
    out = tmp_path / "again.h5"
    shutil.copy(tiny_reference, out)
    summary = service.run(TINY, out, executor="serial", show_progress=False)
    assert summary.skipped == summary.total == 6
    assert_same_results(tiny_reference, out)


def test_other_numerics_are_refused_and_file_kept(tiny_reference, tmp_path):
    out = tmp_path / "kept.h5"
    shutil.copy(tiny_reference, out)
    other = tmp_path / "other.toml"
    other.write_text(TINY.read_text().replace("step_mm = 0.02", "step_mm = 0.01")
                     .replace("[11.4, 12.0]", "[11.4, 12.1]"))  # fmt: skip
    with pytest.raises(InputError, match=r"other settings \(differs in protocol.step_mm\)"):
        service.run(other, out, executor="serial", show_progress=False)
    assert_same_results(tiny_reference, out)


def test_grown_grid_adds_only_the_new_tasks(tiny_reference, tmp_path):
    """Tasks are content-addressed: one more L in the job computes one more point
    and its two sweeps; the finished ones are kept bit for bit."""
    import json

    out = tmp_path / "grown.h5"
    shutil.copy(tiny_reference, out)
    grown = tmp_path / "grown.toml"
    grown.write_text(TINY.read_text().replace("[11.4, 12.0]", "[11.4, 12.0, 12.3]"))
    summary = service.run(grown, out, executor="serial", show_progress=False)
    assert (summary.total, summary.skipped, summary.counts["done"]) == (9, 6, 9)
    with h5py.File(tiny_reference) as f:
        original = f.attrs["job_hash"]
    with h5py.File(out) as f:
        assert f.attrs["grown_from"] == original
        assert json.loads(f.attrs["job_json"])["grid"]["L_mm"] == [11.4, 12.0, 12.3]
    assert set(stored(out, "points")) > set(stored(tiny_reference, "points"))
    s = service.status(out)
    assert (s["done"], s["total"], s["pending"]) == (9, 9, 0)
    ref = physics(tiny_reference)
    now = physics(out)
    for key, rec in ref.items():
        for name, value in rec.items():
            assert np.array_equal(value, now[key][name]), (key, name)


def test_failing_task_is_isolated(tmp_path, monkeypatch):
    import knitsweep.service.worker as tasks

    real = tasks.run_point

    def flaky(job, task, carried=None):
        if task.params.L_mm == 12.0:
            raise RuntimeError("injected failure")
        return real(job, task, carried)

    monkeypatch.setattr(tasks, "run_point", flaky)
    job = load_job(TINY)
    summary = run_job(job, tmp_path / "f.h5", SerialExecutor(job), show_progress=False)
    assert summary.counts == {"done": 3, "failed": 3, "not_knittable": 0}
    points = stored_meta(tmp_path / "f.h5", "points")
    failed = [(tid, m) for tid, m in points.items() if m["status"] == "failed"]
    assert len(failed) == 1
    tid, m = failed[0]
    assert m["error_kind"] == "RuntimeError"
    assert "injected failure" in m["traceback"]
    assert m["rank"] == 0 and m["host"]
    inherited = [s for s in stored_meta(tmp_path / "f.h5", "sweeps").values()
                 if s["point_id"] == tid]  # fmt: skip
    assert len(inherited) == 2
    assert all(s["status"] == "failed" for s in inherited)


def test_every_executor_implements_the_protocol():
    """Serial, process and MPI executors offer what the master uses, interrupt included."""
    from knitsweep.service.executors import Executor, MPIExecutor, ProcessExecutor

    members = ("capacity", "in_flight", "submit", "next_reply", "interrupt", "shutdown")
    assert all(hasattr(Executor, m) for m in members)
    for cls in (SerialExecutor, ProcessExecutor, MPIExecutor):
        missing = [m for m in members if not hasattr(cls, m)]
        assert not missing, f"{cls.__name__} lacks {missing}"
    job = load_job(TINY)
    assert isinstance(SerialExecutor(job), Executor)


def test_task_wall_time_budget(tmp_path):
    """A 1 ms budget: every zero-force relaxation is cut off, its sweeps inherit."""
    tiny = load_job(TINY)
    job = tiny.model_copy(update={"run": tiny.run.model_copy(update={"task_timeout_s": 0.001})})
    summary = run_job(job, tmp_path / "t.h5", SerialExecutor(job), show_progress=False)
    assert summary.counts["failed"] == 6
    points, sweeps = (
        stored_meta(tmp_path / "t.h5", "points"),
        stored_meta(tmp_path / "t.h5", "sweeps"),
    )
    assert {m.get("error_kind") for m in points.values()} == {"timeout"}
    assert all("failed: timeout" in m["message"] for m in points.values())
    assert all("zero-force state: failed: timeout" in m["message"] for m in sweeps.values())


def test_a_timeout_that_interrupted_code_replaced_is_still_a_timeout(monkeypatch):
    """Code the budget's signal interrupts may wrap or replace the exception (C code
    reporting a pending error as its own): the task is recorded as timed out all the same."""
    from knitsweep.service import worker
    from knitsweep.service.jobs import point_task

    def wrapping_point(job, task, carried=None):
        try:
            while True:
                time.sleep(0.001)
        except worker.TaskTimeout:
            pass  # (no trace of it left in what is raised)
        raise RuntimeError("something else")

    monkeypatch.setattr(worker, "run_point", wrapping_point)
    tiny = load_job(TINY)
    job = tiny.model_copy(update={"run": tiny.run.model_copy(update={"task_timeout_s": 0.01})})
    reply = worker.execute(job, point_task(job, job.points()[0]), None, 0)
    assert reply.error["kind"] == "timeout" and "wall-time budget" in reply.error["message"]


def test_a_prepared_task_opens_no_file(monkeypatch):
    """Once ``prepare`` has run, a task reads nothing from disk (its starts are kept
    in memory): the budget's signal can then never cut a file off half-opened, which
    left an unclosed file behind (a ResourceWarning) when a start was read per task."""
    import builtins
    import io

    from knitsweep.service import worker
    from knitsweep.service.jobs import point_task, sweep_task

    job = load_job(TINY)
    worker.prepare(job)

    def refused(*args, **kwargs):
        raise AssertionError(f"a task opened {args[:1]}")

    def without_files(run):
        def task_without_files(*args):
            with monkeypatch.context() as m:
                m.setattr(builtins, "open", refused)
                m.setattr(io, "open", refused)
                return run(*args)

        return task_without_files

    monkeypatch.setattr(worker, "run_point", without_files(worker.run_point))
    monkeypatch.setattr(worker, "run_sweep", without_files(worker.run_sweep))
    point = point_task(job, job.points()[0])
    reply = worker.execute(job, point, None, 0)
    assert reply.error is None, reply.error
    zero = {**reply.record, "params": point.params}  # as the master hands it on
    sweep = worker.execute(job, sweep_task(job, point.task_id, "x"), zero, 0)
    assert sweep.error is None, sweep.error


def test_shards_merge_into_the_whole_job(tiny_reference, tmp_path):
    shards = [tmp_path / f"s{i}.h5" for i in range(2)]
    for i, path in enumerate(shards):
        service.run(TINY, path, executor="serial", shard=f"{i}/2", show_progress=False)
    assert service.status(shards[0])["total"] == 3
    merged = tmp_path / "merged.h5"
    r = service.merge(merged, shards)
    assert r["complete"] and (r["points"], r["sweeps"]) == (2, 4)
    assert_same_results(tiny_reference, merged)
    with pytest.raises(InputError, match="also an input"):
        service.merge(shards[0], shards)


def test_merge_refuses_other_jobs(tiny_reference, tmp_path):
    other = tmp_path / "other.toml"
    other.write_text(
        TINY.read_text()
        .replace('name = "tiny"', 'name = "tiny"\ndescription = "x"')
        .replace("seed = 7", "seed = 8")
    )
    out = tmp_path / "o.h5"
    service.run(other, out, executor="serial", shard="0/2", show_progress=False)
    with pytest.raises(InputError, match="different jobs"):
        service.merge(tmp_path / "m.h5", [tiny_reference, out])


def test_status_of_a_finished_file(tiny_reference):
    s = service.status(tiny_reference)
    assert (s["done"], s["failed"], s["pending"], s["total"]) == (6, 0, 0, 6)
    assert s["run_status"] == "complete" and not s["live"]


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_mpi_run_matches_serial(tiny_reference, tmp_path, ranks):
    if MPIRUN is None:
        pytest.fail("mpirun not found: install the mpich wheel")
    out = tmp_path / f"mpi{ranks}.h5"
    proc = knitsweep("run", str(TINY), "--out", str(out), mpi=ranks)
    assert proc.returncode == 0, proc.stderr
    assert_same_results(tiny_reference, out)


def test_local_processes_match_serial(tiny_reference, tmp_path):
    out = tmp_path / "proc.h5"
    summary = service.run(TINY, out, workers=2, show_progress=False)
    assert summary.counts["done"] == 6
    assert_same_results(tiny_reference, out)
