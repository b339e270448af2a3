"""The sweep service: one HDF5 file, resume, refusal, failure isolation, signals,
MPI and kill -9 (integration tier)."""

import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import TINY, assert_same_results, physics, stored, stored_meta

from knitsweep import service
from knitsweep.config import InputError
from knitsweep.service.executors import SerialExecutor
from knitsweep.service.jobs import load_job
from knitsweep.service.master import run_job
from knitsweep.store.format import RESULTS_SCHEMA_VERSION, journal_dir, lock_path

VENV_BIN = Path(sys.executable).parent
MPIRUN = shutil.which("mpirun", path=str(VENV_BIN)) or shutil.which("mpirun")


def knitsweep(*args, mpi=0, **kw):
    cmd = [sys.executable, "-m", "knitsweep", *args]
    if mpi:
        cmd = [MPIRUN, "-n", str(mpi), *cmd]
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env, **kw)


@pytest.fixture(scope="module")
def twelve(tmp_path_factory):
    """A 36-task job (12 points, fine steps), long enough for eight kills that each
    wait for a result of their own launch, with its serial uninterrupted reference."""
    d = tmp_path_factory.mktemp("twelve")
    job = d / "twelve.toml"
    grid = "[" + ", ".join(f"{11.0 + 0.1 * i:.1f}" for i in range(12)) + "]"
    text = TINY.read_text().replace("[11.4, 12.0]", grid)
    job.write_text(text.replace("step_mm = 0.02", "step_mm = 0.001"))
    reference = d / "reference.h5"
    service.run(job, reference, executor="serial", show_progress=False)
    return job, reference


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


def _wait_for_new_entry(out, proc, since, timeout=120):
    """Until a journal entry newer than ``since`` appears (this launch has a result of
    its own), or the process ends."""
    journal = journal_dir(out)
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout and proc.poll() is None:
        try:
            if any(p.stat().st_mtime > since for p in journal.glob("*.entry")):
                return
        except FileNotFoundError:  # merged into the file meanwhile
            pass
        time.sleep(0.005)


def _wait_for_fresh_progress(out, proc, since, finished=0, timeout=120):
    """Until this launch's master reports ``finished`` tasks, or the process ends."""
    import json

    path = out.with_name(out.name + ".progress.json")
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout and proc.poll() is None:
        try:
            c = json.loads(path.read_text())
            if c["updated"] > since and c["done"] + c["failed"] + c["not_knittable"] >= finished:
                return
        except (FileNotFoundError, ValueError, KeyError):
            pass
        time.sleep(0.05)


@pytest.mark.parametrize("ranks", [0, 3])
def test_sigterm_writes_what_arrived_and_resumes(twelve, tmp_path, ranks):
    """(The 36-task job: 18 tasks could all finish under ``mpirun -n 3`` before the
    signal arrived.)"""
    if ranks and MPIRUN is None:
        pytest.fail("mpirun not found: install the mpich wheel")
    job, reference = twelve
    out = tmp_path / "term.h5"
    cmd = [sys.executable, "-m", "knitsweep", "run", str(job), "--out", str(out), "--quiet"]
    if ranks:
        cmd = [MPIRUN, "-n", str(ranks), *cmd]
    since = time.time()
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})  # fmt: skip
    _wait_for_fresh_progress(out, proc, since, finished=1)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 3, err
    assert "to resume, run the same command again" in err
    with h5py.File(out) as f:  # closed cleanly: opens, and says it was interrupted
        assert f.attrs["run_status"] == "interrupted"
    assert 1 <= service.status(out)["done"] < 36
    assert knitsweep("run", str(job), "--out", str(out), "--quiet", mpi=ranks).returncode == 0
    assert_same_results(reference, out)


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


def _tagged(tag: str) -> dict[int, dict[str, str]]:
    """Live processes whose environment holds RUN_TAG=tag: pid -> environment (hydra
    starts each rank in a session of its own, so process groups do not find them)."""
    found = {}
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            raw = (proc / "environ").read_bytes()
            if f"RUN_TAG={tag}".encode() not in raw:
                continue
            state = (proc / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            env = raw.decode(errors="replace").split("\0")
            found[int(proc.name)] = dict(v.split("=", 1) for v in env if "=" in v)
    return found


def _launch(cmd, tag, **kw):
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "RUN_TAG": tag}
    return subprocess.Popen(cmd, start_new_session=True, env=env, **kw)


def _all_gone(tag: str, timeout: float = 30.0) -> bool:
    t0 = time.monotonic()
    while _tagged(tag):
        if time.monotonic() - t0 > timeout:
            return False
        time.sleep(0.05)
    return True


@pytest.mark.slow
@pytest.mark.mpi
def test_kill_9_campaign_loses_and_duplicates_nothing(twelve, tmp_path):
    """kill -9 the whole run, mpirun alone, the master alone, a worker alone, and the
    master in the middle of checkpoints (every 20 ms), at random moments; the file
    on disk opens after each kill, and the resumed run holds every task exactly
    once, bit-identical to an uninterrupted run."""
    if MPIRUN is None:
        pytest.fail("mpirun not found: install the mpich wheel")
    job, reference = twelve
    busy = tmp_path / "busy.toml"  # [run] settings do not change the job (or its file)
    busy.write_text(job.read_text().replace("checkpoint_s = 0.5", "checkpoint_s = 0.02"))
    assert "checkpoint_s = 0.02" in busy.read_text()
    out = tmp_path / "k9.h5"
    rng = random.Random(20261122)
    targets = ["session", "mpirun", "master", "worker", "checkpoint", "master", "worker",
               "checkpoint"]  # fmt: skip
    landed = []  # kills that hit a run with some but not all tasks finished
    for i, target in enumerate(targets):
        job_file = busy if target == "checkpoint" else job
        cmd = [MPIRUN, "-n", "3", sys.executable, "-m", "knitsweep", "run", str(job_file),
               "--out", str(out), "--quiet"]  # fmt: skip
        since = time.time()
        log = tmp_path / f"launch{i}.log"
        tag = f"k9-{os.getpid()}-{i}"
        before = service.status(out)["done"] if out.exists() else 0
        if before == 36:  # a launch finished the job: the campaign goes on with a new file
            for p in [out, *tmp_path.glob(".k9.h5*"), *tmp_path.glob("k9.h5.*")]:
                shutil.rmtree(p) if p.is_dir() else p.unlink()
            before = 0
        with open(log, "w") as fh:
            proc = _launch(cmd, tag, stdout=fh, stderr=fh)
        _wait_for_new_entry(out, proc, since)  # mid-run: this launch journalled a result
        time.sleep(rng.uniform(0.0, 0.1))  # (results arrive in batches: soon after one)
        if proc.poll() is not None:  # it finished first (a fast machine): not landed
            assert proc.returncode == 0, log.read_text()
            print(f"kill -9 of the {target}: the run had ended ({log.read_text().strip()})")
            continue
        ranks = {env.get("PMI_RANK", "mpirun"): pid for pid, env in _tagged(tag).items()}
        if target == "session":
            for pid in ranks.values():
                os.kill(pid, signal.SIGKILL)
        elif target == "mpirun":
            proc.kill()
        else:
            victim = ranks["1" if target == "worker" else "0"]
            if target == "checkpoint":  # right as a checkpoint writes the shadow copy
                shadow = out.with_name(f".{out.name}.shadow")
                seen = shadow.stat().st_mtime_ns if shadow.exists() else 0
                t0 = time.monotonic()
                while time.monotonic() - t0 < 5 and (
                    not shadow.exists() or shadow.stat().st_mtime_ns == seen
                ):
                    pass
            os.kill(victim, signal.SIGKILL)
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            pytest.fail(f"kill -9 of the {target} left the run hanging: {log.read_text()}")
        if not _all_gone(tag, 15):
            pytest.fail(f"kill -9 of the {target}: ranks left running")
        with h5py.File(out) as f:  # the file on disk always opens
            assert f.attrs["schema_version"] == RESULTS_SCHEMA_VERSION
            assert set(f) >= {"points", "sweeps"}
        done = service.status(out)["done"]
        print(f"kill -9 of the {target}: {before} -> {done} of 36 tasks finished")
        if before < done < 36:  # alive at the kill (checked above), mid-way through the job
            landed.append(f"{target} at {done}/36")
    print(f"kill -9 landed mid-run: {len(landed)} of {len(targets)} ({', '.join(landed)})")
    assert len(landed) >= len(targets) - 2, (
        f"only {len(landed)} of {len(targets)} kills landed mid-run"
    )
    final = knitsweep("run", str(job), "--out", str(out), "--quiet", mpi=3)
    assert final.returncode == 0, final.stderr
    with h5py.File(out) as f:  # each task exactly once
        assert len(f["points/task"]) == 12 and len(f["sweeps/task"]) == 24
    assert not journal_dir(out).exists()
    assert not list(tmp_path.glob(".k9.h5*")), "shadow or temporary files left"
    assert_same_results(reference, out)


@pytest.mark.slow
@pytest.mark.mpi
@pytest.mark.parametrize(("signum", "to_group"), [(signal.SIGINT, True), (signal.SIGTERM, False)])
def test_signal_during_mpi_start_up_ends_every_rank(twelve, tmp_path, signum, to_group):
    """SIGINT to the whole session (a terminal's Ctrl-C) or SIGTERM to mpirun (what
    scancel and a batch system do) in the first seconds of ``mpirun -n 3``: while
    Python imports, during MPI_Init, while rank 0 compiles or hands out the job,
    and as the first tasks run. Every rank ends within seconds, with exit code 3,
    one line per rank and no traceback; a results file, if one was made, opens."""
    if MPIRUN is None:
        pytest.fail("mpirun not found: install the mpich wheel")
    job, _ = twelve  # 36 tasks: ~4 s under mpirun -n 3 on the idle machine (18 took ~3 s)
    landed = every_rank = 0  # signals that arrived before the run was done; all ranks said so
    delays = (0.3, 0.6, 1.0, 1.5, 2.0, 3.0, 4.5)
    for delay in delays:
        out = tmp_path / f"start{delay}.h5"
        cmd = [MPIRUN, "-n", "3", sys.executable, "-m", "knitsweep", "run", str(job), "--out",
               str(out), "--quiet"]  # fmt: skip
        tag = f"start-{os.getpid()}-{signum}-{delay}"
        proc = _launch(cmd, tag, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(delay)
        if to_group:
            os.killpg(proc.pid, signum)
        else:
            proc.send_signal(signum)
        t0 = time.monotonic()
        try:
            _, err = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            pytest.fail(f"{signal.Signals(signum).name} {delay} s after the start: still running "
                        "after 60 s")  # fmt: skip
        seconds = time.monotonic() - t0
        where = f"{signal.Signals(signum).name} {delay} s after the start"
        if proc.returncode == 0 and delay >= 3.0:  # on a quiet machine the run was done
            assert service.status(out)["done"] == 36, f"{where}: exit 0 but unfinished: {err}"
            continue
        landed += 1
        assert proc.returncode == 3, f"{where}: exit {proc.returncode}: {err}"
        assert "Traceback" not in err and "ImportError" not in err, f"{where}: {err}"
        reported = sum(line.startswith("interrupted by") for line in err.splitlines())
        assert 1 <= reported <= 3 and len(err.strip().splitlines()) <= 6, f"{where}: {err}"
        every_rank += reported == 3
        assert seconds < 30, f"{where}: took {seconds:.1f} s to end"
        assert _all_gone(tag, 5), f"{where}: processes left behind"
        if out.exists():
            with h5py.File(out) as f:
                run_status = f.attrs["run_status"]
            # the work was done and the file closed complete when the signal came (the
            # ranks were leaving): exit 3 is then about the teardown, the file is whole
            assert run_status == "interrupted" or (
                run_status == "complete" and service.status(out)["done"] == 36
            ), f"{where}: run_status {run_status}"
            landed -= run_status == "complete"
    print(
        f"start-up signals landed before the run was done: {landed} of {len(delays)}, every "
        f"rank reporting in {every_rank} of them"
    )
    assert landed >= len(delays) - 2, f"only {landed} of {len(delays)} signals landed"


def test_signal_exceptions_are_unwrapped_from_numba_system_errors():
    """A signal handler raising while a numba dispatcher returns surfaces as a
    SystemError with the handler's exception as its cause: an interrupt must still
    propagate, and a timeout still count as a timeout (not a failed task)."""
    from knitsweep.service.worker import TaskTimeout, _signal_cause

    class Stop(BaseException):
        pass

    def wrapped(inner):
        try:
            try:
                raise inner
            except BaseException as cause:
                raise SystemError("returned a result with an exception set") from cause
        except SystemError as e:
            return e

    assert isinstance(_signal_cause(wrapped(TaskTimeout("late"))), TaskTimeout)
    with pytest.raises(Stop):
        _signal_cause(wrapped(Stop()))
    plain = ValueError("a bug")
    assert _signal_cause(plain) is plain
