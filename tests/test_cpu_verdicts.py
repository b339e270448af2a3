"""The cross-CPU comparison: a short pattern series (tests/data/jobs/seed_cpus.toml)
run with the kernels compiled for this host and again for a generic x86-64
(``NUMBA_CPU_NAME=generic``, an empty kernel cache, in a child process) gives the same
verdicts: every point the same status, every sweep jammed or not alike, the energy gaps
within a tenth of the threshold, the transitions within twice the patterns job's
tolerance; and two runs in a row with one build are identical, bit for bit. (Y_sec is not a verdict
and is not compared: a jammed point's moves with the zero-force state it starts from;
``[starts] spread`` measures how far.)"""

import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import DATA

import knitsweep as ks
from knitsweep import service

JOB = DATA / "jobs" / "seed_cpus.toml"
TIMING = {"seconds", "relax_seconds", "wall_seconds", "rank", "host", "started_at", "file"}

pytestmark = pytest.mark.slow


def _tables(path):
    res = ks.load(path)
    points = res.points.drop(columns=[c for c in res.points if c in TIMING])
    sweeps = res.sweeps.drop(columns=[c for c in res.sweeps if c in TIMING])
    return points.sort_values("L_mm").reset_index(drop=True), sweeps.sort_values(
        ["L_mm", "direction"]).reset_index(drop=True)  # fmt: skip


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("host")
    for name in ("a", "b"):
        service.run(JOB, tmp / f"{name}.h5", executor="serial", show_progress=False)
    return tmp / "a.h5", tmp / "b.h5"


@pytest.fixture(scope="module")
def generic(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("generic")
    env = {**os.environ, "NUMBA_CPU_NAME": "generic", "NUMBA_CACHE_DIR": str(tmp / "cache"),
           "OPENBLAS_NUM_THREADS": "1"}  # fmt: skip
    out = tmp / "generic.h5"
    proc = subprocess.run([sys.executable, "-m", "knitsweep", "run", str(JOB), "--out", str(out),
                           "--executor", "serial", "--quiet"], env=env, capture_output=True,
                          text=True, timeout=900)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-2000:]
    return out


def test_two_runs_in_a_row_with_one_build_are_identical(host):
    (pa, sa), (pb, sb) = (_tables(p) for p in host)
    assert pa.equals(pb) and sa.equals(sb)
    assert (pa["status"] != "failed").all()


def test_the_generic_build_gives_the_hosts_verdicts(host, generic):
    (ph, sh), (pg, sg) = _tables(host[0]), _tables(generic)
    assert list(pg["status"]) == list(ph["status"]) and "failed" not in set(ph["status"])
    assert list(sg["status"]) == list(sh["status"])
    done = sh["status"] == "done"
    assert list(sg["jammed"][done]) == list(sh["jammed"][done])
    both = sh["jammed"][done].any() and not sh["jammed"][done].all()
    assert both, "the series no longer straddles seed's transitions: move its L (seed_cpus.toml)"
    threshold = ks.load(host[0]).threshold
    for column in ("delta_E_b_mJ", "delta_E_c_mJ"):  # a tenth of the threshold
        assert np.allclose(sg[column][done], sh[column][done], rtol=0, atol=threshold / 10)
    th, tg = ks.load(host[0]).transitions, ks.load(generic).transitions
    assert list(th["status"]) == list(tg["status"])
    tol = 2 * 0.02 / 0.74  # twice the patterns job's adaptive tolerance, in L/r
    assert np.allclose(th["L_over_r_trans"], tg["L_over_r_trans"], rtol=0, atol=tol)
