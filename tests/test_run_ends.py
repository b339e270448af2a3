"""How ``knitsweep run`` ends: its exit code when tasks failed, its refusal to write
into a results file of another job's name or description, and its closing line."""

import os
import shutil
import subprocess
import sys

import h5py
import pytest
from conftest import TINY
from conftest import run_knitsweep as knitsweep

from knitsweep import service
from knitsweep.config import InputError
from knitsweep.service.run_plan import EXIT_TASKS_FAILED


def test_a_run_with_failed_tasks_exits_4_and_says_how_many(tmp_path):
    job = tmp_path / "t.toml"
    job.write_text(TINY.read_text().replace("[run]", "[run]\ntask_timeout_s = 0.001"))
    out = tmp_path / "t.h5"
    proc = knitsweep("run", job, "--out", out, "--quiet")
    assert proc.returncode == EXIT_TASKS_FAILED == 4, proc.stderr
    assert "error: 6 of 6 tasks failed (exit code 4)" in proc.stderr
    again = knitsweep("run", job, "--out", out, "--quiet")  # nothing to do, still failed
    assert again.returncode == 4 and "(6 already finished)" in again.stderr


def test_a_complete_run_exits_0(tiny_reference, tmp_path):
    out = tmp_path / "c.h5"
    shutil.copy(tiny_reference, out)
    proc = knitsweep("run", TINY, "--out", out, "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert "compiling the kernels" not in proc.stderr  # warm: no compile time to state


@pytest.mark.parametrize(
    "change, field",
    [
        (('name = "tiny"', 'name = "other"'), "name"),
        (('name = "tiny"', 'name = "tiny"\ndescription = "another study"'), "description"),
    ],
)
def test_another_jobs_label_is_refused_unless_relabel(tiny_reference, tmp_path, change, field):
    out = tmp_path / "r.h5"
    shutil.copy(tiny_reference, out)
    before = out.read_bytes()
    job = tmp_path / "other.toml"
    job.write_text(TINY.read_text().replace(*change))
    with pytest.raises(InputError, match=f"^{field} = .*holds results of a job with {field}"):
        service.run(job, out, executor="serial", show_progress=False)
    proc = knitsweep("run", job, "--out", out, "--quiet")
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1 and "--relabel" in lines[0], proc.stderr
    assert out.read_bytes() == before  # refused before anything was written
    summary = service.run(job, out, executor="serial", show_progress=False, relabel=True)
    assert summary.exit_code == 0 and summary.skipped == 6
    label = load_label(out)
    assert label == ("other", "") if field == "name" else label == ("tiny", "another study")


def load_label(path):
    import json

    with h5py.File(path, "r") as f:
        spec = json.loads(f.attrs["job_json"])
        return str(f.attrs["job_name"]), spec.get("description", "")


def test_a_grown_grid_of_the_same_job_needs_no_relabel(tiny_reference, tmp_path):
    out = tmp_path / "g.h5"
    shutil.copy(tiny_reference, out)
    grown = tmp_path / "grown.toml"
    grown.write_text(TINY.read_text().replace("[11.4, 12.0]", "[11.4, 12.0, 12.3]"))
    summary = service.run(grown, out, executor="serial", show_progress=False)
    assert summary.exit_code == 0 and summary.skipped == 6 and summary.total == 9
    assert load_label(out) == ("tiny", "")


@pytest.mark.slow
def test_a_cold_run_states_its_compile_time(tmp_path):
    """With an empty kernel cache, the closing line's time includes the compilation
    and says how much of it that was, and how much the computing."""
    import re

    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    proc = subprocess.run([sys.executable, "-m", "knitsweep", "run", str(TINY), "--out",
                           str(tmp_path / "cold.h5"), "--quiet"], capture_output=True, text=True,
                          timeout=900, env=env)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    m = re.search(r"in ([\d.]+) s \(([\d.]+) s compiling the kernels, cached from now on; "
                  r"([\d.]+) s computing\)", proc.stderr)  # fmt: skip
    assert m, proc.stderr
    total, compiling, computing = float(m[1]), float(m[2]), float(m[3])
    assert 0 < compiling < total and computing > 0
    assert compiling + computing == pytest.approx(total, abs=0.11)
