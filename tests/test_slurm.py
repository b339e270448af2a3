"""SLURM batch templates (slurm/*.sbatch = knitsweep/service/templates/*.sbatch) and
``knitsweep slurm render``.

The tests marked ``slurm`` submit the templates to a real SLURM (a single node
here: ``sudo bash .ci/slurm-up.sh``) and compare the HDF5 they write with a
serial run. They fail, never skip, when SLURM is not there. Jobs are watched
with ``scontrol show job`` every 0.25 s rather than ``sbatch --wait``, which
polls at 2, 8, 32 s.
"""

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest
from conftest import TINY, assert_same_results, stored_meta

import knitsweep
from knitsweep import service
from knitsweep.service.slurm import TEMPLATE_FILES, SlurmScript, render, template_path

REPO = Path(__file__).resolve().parents[1]
DATA = Path(__file__).parent / "data"
VENV = Path(sys.executable).parent.parent
FINAL = {"COMPLETED", "FAILED", "CANCELLED", "TIMEOUT", "NODE_FAIL", "OUT_OF_MEMORY",
         "PREEMPTED", "BOOT_FAIL", "DEADLINE"}  # fmt: skip
START_SLURM = "start it with: sudo bash .ci/slurm-up.sh"


# ---- helpers -------------------------------------------------------------------
def ranks_used(path):
    return {
        int(m["rank"]) for kind in ("points", "sweeps") for m in stored_meta(path, kind).values()
    }


def job_env(**extra):
    """The submitter's environment: this venv and this checkout of knitsweep
    (sbatch passes the environment on), no KNITSWEEP_* settings of the caller."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("KNITSWEEP_")}
    source = str(Path(knitsweep.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [source, env.get("PYTHONPATH")]))
    env["KNITSWEEP_VENV"] = str(VENV)
    env.update(extra)
    return env


def sbatch(args, cwd, env=None):
    """Submit; returns the job id."""
    proc = subprocess.run(["sbatch", "--parsable", *map(str, args)], cwd=cwd, env=env or job_env(),
                          capture_output=True, text=True, timeout=60)  # fmt: skip
    assert proc.returncode == 0, f"sbatch {args}: {proc.stderr}"
    return proc.stdout.strip().split(";")[0]


def job_info(job_id):
    """``scontrol show job`` as one dict per job record (array tasks: several)."""
    proc = subprocess.run(["scontrol", "show", "job", "-o", job_id], capture_output=True,
                          text=True, timeout=30)  # fmt: skip
    assert proc.returncode == 0, f"scontrol show job {job_id}: {proc.stderr}"
    records = []
    for line in proc.stdout.splitlines():
        fields = dict(w.split("=", 1) for w in line.split() if "=" in w)
        if fields:
            records.append(fields)
    return records


def wait_for(job_id, done, log=None, timeout=300.0, what="to finish"):
    """Poll until ``done(record)``; fail (and cancel the job) after ``timeout`` s."""
    t0 = time.monotonic()
    while True:
        records = job_info(job_id)
        if records and done(records[0]):
            return records[0]
        if records and "DependencyNeverSatisfied" in records[0].get("Reason", ""):
            pytest.fail(f"job {job_id}'s dependency failed: {records[0]}")
        if time.monotonic() - t0 > timeout:
            subprocess.run(["scancel", job_id], timeout=30)
            text = Path(log).read_text() if log and Path(log).exists() else "(no log)"
            pytest.fail(f"job {job_id} did not get {what} in {timeout:.0f} s: "
                        f"{records[:1]}\n--- log ---\n{text}")  # fmt: skip
        time.sleep(0.25)


def wait_finished(job_id, log=None, timeout=300.0):
    return wait_for(job_id, lambda r: r["JobState"] in FINAL, log, timeout)


def exit_code(record):
    return int(record["ExitCode"].split(":")[0])


def wait_for_progress(out, job_id, finished=1, timeout=300.0):
    """Until the master's progress file shows ``finished`` tasks (or the job ends)."""
    path = out.with_name(out.name + ".progress.json")
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        try:
            c = json.loads(path.read_text())
            if c["done"] + c["failed"] + c["not_knittable"] >= finished:
                return
        except (FileNotFoundError, ValueError, KeyError):
            pass
        state = job_info(job_id)[0]["JobState"]
        if state in FINAL:
            pytest.fail(f"job {job_id} ended ({state}) before it could be interrupted")
        time.sleep(0.1)
    pytest.fail(f"job {job_id}: no progress in {timeout:.0f} s")


def run_status(path):
    with h5py.File(path, "r") as f:  # opens: the file was closed cleanly
        return str(f.attrs["run_status"]), str(f.attrs["slurm_job_id"])


def bigger_job(tmp_path, n_points=16):
    """tiny.toml with more grid points: enough work to interrupt a run."""
    L = ", ".join(f"{11.0 + 0.05 * i:.2f}" for i in range(n_points))
    job = tmp_path / "bigger.toml"
    job.write_text(TINY.read_text().replace("[11.4, 12.0]", f"[{L}]"))
    return job


# ---- fixtures ------------------------------------------------------------------
@pytest.fixture(scope="session")
def slurm():
    """A SLURM with a responding node, or a failure that says how to start one."""
    if shutil.which("sinfo") is None or shutil.which("sbatch") is None:
        pytest.fail(f"SLURM is not installed (no sinfo/sbatch on PATH); {START_SLURM}")
    proc = subprocess.run(["sinfo", "-h", "-N", "-o", "%T %c"], capture_output=True, text=True,
                          timeout=30)  # fmt: skip
    nodes = [line.split() for line in proc.stdout.splitlines() if line.strip()]
    # idle or mixed; allocated/completing nodes are up too, just busy with others' jobs
    up = [n for n in nodes if n[0] in ("idle", "mixed", "allocated", "completing")]
    if proc.returncode != 0 or not up:
        pytest.fail(f"no usable SLURM node (sinfo: {proc.stdout.strip() or proc.stderr.strip()}); "
                    f"{START_SLURM}")  # fmt: skip
    if not (VENV / "bin" / "activate").is_file():
        pytest.fail(f"the tests must run from a virtualenv ({sys.executable} has no bin/activate)")
    return {"cpus": max(int(n[1]) for n in up)}


@pytest.fixture(scope="module")
def reference(tiny_reference):
    return tiny_reference


def assert_tiny_done(out, reference, job_id):
    s = service.status(out)
    assert (s["done"], s["failed"], s["pending"], s["total"]) == (6, 0, 0, 6), s
    assert run_status(out) == ("complete", job_id)
    assert_same_results(reference, out)


# ---- the MPI template ------------------------------------------------------------
@pytest.mark.slurm
@pytest.mark.mpi
@pytest.mark.parametrize("ntasks", [2, 3])
def test_mpi_template_with_srun(slurm, reference, tmp_path, ntasks):
    out, log = tmp_path / "tiny.h5", tmp_path / "job.out"
    opts = [f"--ntasks={ntasks}", f"--output={log}", "--time=00:10:00"]
    if ntasks > slurm["cpus"]:
        opts.append("--overcommit")  # the master mostly waits; 3 ranks on 2 cores is fine
    job_id = sbatch([*opts, REPO / "slurm" / "knitsweep-mpi.sbatch", TINY, out], tmp_path)
    record = wait_finished(job_id, log)
    text = log.read_text()
    assert (record["JobState"], exit_code(record)) == ("COMPLETED", 0), text
    assert "srun --mpi=pmi2" in text and "knitsweep exited with code 0" in text
    assert_tiny_done(out, reference, job_id)
    assert ranks_used(out) == set(range(1, ntasks)), "not one MPI world of ntasks ranks"


@pytest.mark.slurm
@pytest.mark.mpi
def test_rendered_mpi_script_with_mpirun(slurm, reference, tmp_path):
    out, log = tmp_path / "tiny.h5", tmp_path / "job.out"
    script = tmp_path / "run.sbatch"
    script.write_text(render(SlurmScript(job=TINY, out=out, ntasks=2, time="00:10:00",
                                         launcher="mpirun", venv=VENV)))  # fmt: skip
    env = job_env(KNITSWEEP_LAUNCHER="srun")  # the rendered script's own setting wins
    job_id = sbatch([f"--output={log}", script], tmp_path, env)  # no arguments: baked in
    record = wait_finished(job_id, log)
    text = log.read_text()
    assert (record["JobState"], exit_code(record)) == ("COMPLETED", 0), text
    assert "launcher: mpirun -n 2" in text
    assert_tiny_done(out, reference, job_id)
    assert ranks_used(out) == {1}


# ---- the array and merge templates -------------------------------------------------
@pytest.mark.slurm
def test_array_shards_then_merge_after_ok(slurm, reference, tmp_path):
    shards = tmp_path / "shards"
    array_id = sbatch(["--array=0-1", f"--output={tmp_path}/array-%A_%a.out", "--time=00:10:00",
                       REPO / "slurm" / "knitsweep-array.sbatch", TINY, shards], tmp_path)  # fmt: skip
    merge_log = tmp_path / "merge.out"
    merge_id = sbatch([f"--dependency=afterok:{array_id}", f"--output={merge_log}",
                       REPO / "slurm" / "knitsweep-merge.sbatch", TINY, shards], tmp_path)  # fmt: skip
    record = wait_finished(merge_id, merge_log)
    logs = "\n".join(p.read_text() for p in sorted(tmp_path.glob("*.out")))
    assert (record["JobState"], exit_code(record)) == ("COMPLETED", 0), logs
    tasks = job_info(array_id)
    assert sorted(t["ArrayTaskId"] for t in tasks) == ["0", "1"]
    assert all((t["JobState"], t["ExitCode"]) == ("COMPLETED", "0:0") for t in tasks), tasks
    for i in range(2):
        s = service.status(shards / f"tiny.shard{i}of2.h5")
        assert (s["done"], s["total"], s["run_status"]) == (3, 3, "complete")
    merged = shards / "tiny.h5"
    assert "(complete)" in merge_log.read_text()
    assert run_status(merged)[0] == "complete"
    assert_same_results(reference, merged)


# ---- walltime signal: interrupt, exit 3, resume --------------------------------------
@pytest.fixture(scope="module")
def bigger(tmp_path_factory):
    """A 16-point job (48 tasks) and its serial results."""
    tmp = tmp_path_factory.mktemp("bigger")
    job = bigger_job(tmp)
    out = tmp / "reference.h5"
    assert service.run(job, out, executor="serial", show_progress=False).counts["done"] == 48
    return job, out


def interrupt(job_id, out):
    """What --signal=B:TERM@120 does before the walltime: SIGTERM to the batch shell."""
    wait_for_progress(out, job_id)
    proc = subprocess.run(["scancel", "--signal=TERM", "--batch", job_id], capture_output=True,
                          text=True, timeout=30)  # fmt: skip
    assert proc.returncode == 0, proc.stderr


@pytest.mark.slurm
@pytest.mark.mpi
def test_interrupted_run_exits_3_and_resubmission_resumes(slurm, bigger, tmp_path):
    job, reference = bigger
    out, log = tmp_path / "bigger.h5", tmp_path / "job.out"
    args = ["--ntasks=2", f"--output={log}", REPO / "slurm" / "knitsweep-mpi.sbatch", job, out]
    env = job_env(KNITSWEEP_LAUNCHER="mpirun")
    first = sbatch(args, tmp_path, env)
    interrupt(first, out)
    record = wait_finished(first, log)
    text = log.read_text()
    assert (record["JobState"], exit_code(record)) == ("FAILED", 3), text
    assert "knitsweep exited with code 3" in text and "to resume, submit the same job" in text
    assert "to resume, run the same command again" in text  # the master's own line
    assert run_status(out) == ("interrupted", first)
    s = service.status(out)
    assert 1 <= s["done"] < s["total"] == 48 and not s["live"]

    second = sbatch(args, tmp_path, env)  # the same command again
    record = wait_finished(second, log)
    text = log.read_text()
    assert (record["JobState"], exit_code(record)) == ("COMPLETED", 0), text
    assert f"({s['done']} already finished)" in text
    assert service.status(out)["done"] == 48
    assert run_status(out) == ("complete", first)  # the file remembers the job that began it
    assert_same_results(reference, out)


@pytest.mark.slurm
@pytest.mark.mpi
def test_interrupted_srun_run_requeues_and_resumes(slurm, bigger, tmp_path):
    job, reference = bigger
    out, log = tmp_path / "bigger.h5", tmp_path / "job.out"
    job_id = sbatch(["--ntasks=2", f"--output={log}", REPO / "slurm" / "knitsweep-mpi.sbatch",
                     job, out], tmp_path, job_env(KNITSWEEP_REQUEUE="1"))  # fmt: skip
    interrupt(job_id, out)
    wait_for(job_id, lambda r: r["Restarts"] == "1" and r["JobState"] in ("PENDING", "RUNNING"),
             log, timeout=120, what="requeued")  # fmt: skip
    text = log.read_text()
    assert "to resume, run the same command again" in text
    # the workers stopped and MPI finalized: srun itself returned knitsweep's 3
    assert "knitsweep exited with code 3" in text and "exited with 137" not in text
    assert f"interrupted: requeueing job {job_id}" in text
    # SLURM holds a requeued job for ~2 min (its credential lifetime). Skip the wait,
    # but only once the old credential's revocation is in the past: slurmd compares
    # whole seconds and refuses a start in the same second ("credential revoked").
    time.sleep(3)
    subprocess.run(["scontrol", "update", f"JobId={job_id}", "StartTime=now"], timeout=30)
    record = wait_finished(job_id, log)
    text = log.read_text()
    assert (record["JobState"], exit_code(record)) == ("COMPLETED", 0), text
    assert record["Restarts"] == "1"
    assert f"job {job_id} (restart 1)" in text and "knitsweep exited with code 0" in text
    assert run_status(out) == ("complete", job_id)
    assert_same_results(reference, out)


# ---- knitsweep slurm render (no SLURM needed) -----------------------------------------
def knitsweep_cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "knitsweep", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=120)  # fmt: skip


def test_slurm_dir_holds_the_shipped_templates():
    for name, file in TEMPLATE_FILES.items():
        user_copy = REPO / "slurm" / file
        assert user_copy.resolve() == template_path(name).resolve(), "one source of truth"
        text = template_path(name).read_text()
        assert text.startswith("#!/bin/bash\n")
        assert subprocess.run(["bash", "-n", str(user_copy)]).returncode == 0


def test_render_fills_in_the_values(tmp_path):
    out = tmp_path / "results.h5"
    script = tmp_path / "run.sbatch"
    proc = knitsweep_cli("slurm", "render", TINY, "--out", out, "--nodes", 2, "--ntasks", 8,
                         "--time", "1-12:00:00", "--partition", "compute", "--launcher", "mpirun",
                         "--venv", VENV, "--modules", "gcc openmpi/4.1", "--requeue",
                         "--script", script)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    text = script.read_text()
    lines = text.splitlines()
    for line in ("#SBATCH --nodes=2", "#SBATCH --ntasks=8", "#SBATCH --time=1-12:00:00",
                 "#SBATCH --partition=compute", f"JOB=${{1:-{TINY.resolve()}}}",
                 f"OUT=${{2:-{out}}}", "KNITSWEEP_LAUNCHER=mpirun", f"KNITSWEEP_VENV={VENV.resolve()}",
                 "KNITSWEEP_MODULES='gcc openmpi/4.1'", "KNITSWEEP_REQUEUE=1",
                 "#SBATCH --signal=B:TERM@120"):  # fmt: skip
        assert line in lines, line
    assert os.access(script, os.X_OK)
    assert subprocess.run(["bash", "-n", str(script)]).returncode == 0
    # stdout by default; unset values keep the template's defaults
    plain = knitsweep_cli("slurm", "render", TINY, "--out", out)
    assert plain.returncode == 0 and "#SBATCH --ntasks=2" in plain.stdout.splitlines()
    assert "KNITSWEEP_LAUNCHER=${KNITSWEEP_LAUNCHER:-srun}" in plain.stdout.splitlines()


def test_render_array_and_merge(tmp_path):
    array = render(SlurmScript(template="array", job=TINY, out=tmp_path / "shards", shards=4,
                               cpus_per_task=2, partition="short"))  # fmt: skip
    lines = array.splitlines()
    assert "#SBATCH --array=0-3" in lines and "#SBATCH --cpus-per-task=2" in lines
    assert "#SBATCH --partition=short" in lines
    assert f"OUTDIR=${{2:-{tmp_path / 'shards'}}}" in lines
    merge = render(SlurmScript(template="merge", job=TINY, out=tmp_path / "shards",
                               time="00:05:00"))  # fmt: skip
    assert "#SBATCH --time=00:05:00" in merge.splitlines()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--time", "90:00"], "error: time = '90:00': must be HH:MM:SS or D-HH:MM:SS"),
        (["--time", "01:60:00"], "error: time = '01:60:00': must be HH:MM:SS"),
        (["--time", "00:02:00"], "error: time = '00:02:00': must be longer than 120 s"),
        (["--ntasks", "1"], "error: ntasks = 1: Input should be greater than or equal to 2"),
        (["--launcher", "ssh"], "error: launcher = 'ssh': Input should be 'srun' or 'mpirun'"),
        (["--partition", "a b"], "error: partition = 'a b': must be a partition name"),
        (["--venv", "/"], "error: venv = '/': not a virtualenv"),
        (["--shards", "4"], "error: shards = 4: the mpi template does not take it"),
        (["--template", "pbs"], "error: template = 'pbs': Input should be 'mpi', 'array' or"),
        (["--out", "/no/such/dir/x.h5"], "error: out = '/no/such/dir/x.h5': directory"),
    ],
)
def test_render_refuses_bad_values_in_one_line(tmp_path, args, message):
    base = ["slurm", "render", TINY, "--out", tmp_path / "r.h5"]
    proc = knitsweep_cli(*base, *args)
    assert proc.returncode == 2
    assert proc.stderr.startswith(message), proc.stderr
    assert proc.stderr.count("\n") == 1 and proc.stdout == ""


def test_render_refuses_a_bad_job(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(TINY.read_text().replace("seed = 7", "seed = -1"))
    for job, message in ((tmp_path / "none.toml", "error: job = '"), (bad, "error: job file")):
        proc = knitsweep_cli("slurm", "render", job, "--out", tmp_path / "r.h5")
        assert proc.returncode == 2 and proc.stderr.startswith(message), proc.stderr
        assert proc.stderr.count("\n") == 1
