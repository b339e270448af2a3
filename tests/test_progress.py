"""Integration tier: a run you can watch (progress lines off a terminal, the ETA, the
compile notice) and `status` on finished files."""

import math
import os
import subprocess
import sys

import pytest
from conftest import SHIPPED, TINY

from knitsweep import service
from knitsweep.service.progress import RunProgress, progress_line


def _knitsweep(*args, env=None):
    return subprocess.run([sys.executable, "-m", "knitsweep", *args], capture_output=True,
                          text=True, timeout=600, env=env)  # fmt: skip


def test_one_line_per_finished_task_off_a_terminal(tmp_path):
    out = _knitsweep("run", str(TINY), "--out", str(tmp_path / "t.h5"), "--executor", "serial")
    assert out.returncode == 0, out.stderr
    lines = out.stderr.splitlines()
    tasks = [
        line for line in lines if (line.startswith("[") and "] point" in line) or "] sweep" in line
    ]
    assert len(tasks) == 6, out.stderr
    assert sum("] sweep x" in line for line in tasks) == 2
    assert all(" done " in line and " s  rank 0@" in line and "L=" in line for line in tasks)
    assert any("ETA" in line and "done 6" in line for line in lines)  # the final summary
    assert "of 6 tasks (0 already finished)" in lines[-1]


def test_eta_weighs_each_kind_by_its_measured_time():
    p = RunProgress(show=False)
    p.add_tasks("point", 4)
    p.add_tasks("sweep", 8)
    assert p.eta() == math.inf  # nothing measured yet
    p.finished("point", 1.0, "")
    # no sweep measured: a sweep counts as ten points; 3 points + 8 sweeps = 83 s of work
    # left, at (1 s of work per elapsed second) * (elapsed = 1 s) ...
    p.t0 -= 1.0 - p.elapsed  # pretend 1 s has passed
    assert p.eta() == pytest.approx(83.0, rel=0.02)
    p.finished("sweep", 4.0, "")
    # now 3 points (1 s) + 7 sweeps (4 s) = 31 s of work, 5 s of work done in 1 s
    p.t0 -= 1.0 - p.elapsed
    assert p.eta() == pytest.approx(31.0 / 5.0, rel=0.02)


def test_status_of_a_finished_file_shows_wall_time_and_groups(tiny_reference):
    s = service.status(tiny_reference, by="L_mm")
    assert s["elapsed_s"] > 0.0 and s["run_status"] == "complete"
    assert s["by"]["L_mm"] == {"11.4": {"done": 3}, "12.0": {"done": 3}}
    assert "finished in" in progress_line({**s, "finished_at": s["finished_at"]})
    out = _knitsweep("status", str(tiny_reference), "--by", "direction")
    assert out.returncode == 0, out.stderr
    assert "direction = x: done 2" in out.stdout and "finished in" in out.stdout
    bad = _knitsweep("status", str(tiny_reference), "--by", "colour")
    assert bad.returncode == 2 and "by = 'colour'" in bad.stderr


@pytest.mark.slow
def test_compile_notice_before_the_first_compile(tmp_path):
    """With an empty kernel cache, the command says it will compile before it does,
    and only then."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    args = ("energy", "--state", str(SHIPPED / "Init_1.dat"), "--L", "11.6")
    first = _knitsweep(*args, env=env)
    assert first.returncode == 0, first.stderr
    assert first.stderr.startswith("compiling numerical kernels (stockinette) once")
    again = _knitsweep(*args, env=env)
    assert again.returncode == 0 and "compiling" not in again.stderr, again.stderr
