"""Runs interrupted: SIGTERM, kill -9 of every rank at random moments, and signals
during MPI start-up; what was written survives and a rerun completes the job
(integration tier)."""

import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest
from conftest import MPIRUN, TINY, assert_same_results
from conftest import run_knitsweep as knitsweep

from knitsweep import service
from knitsweep.store.format import RESULTS_SCHEMA_VERSION, journal_dir


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
