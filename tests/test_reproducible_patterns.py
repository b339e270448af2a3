"""The shipped patterns study gives the same verdicts whatever instruction set numba
compiles the kernels for (docs/model.md §11, "Reproducible").

numba compiles for the host CPU: on a CPU with AVX-512 the kernels' sums round
differently from those of a generic x86-64, in the last bits. A pattern's verdict must
not hang on those bits. The test runs ``jobs/patterns_k0.1.toml`` twice under
``mpirun -n 3``, once with the host's code and once with ``NUMBA_CPU_NAME=generic`` in an
empty kernel cache, and asks of both: no failed task, every series refined to its
tolerance, and the same transitions within that tolerance.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import MPIRUN

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
JOB = ROOT / "jobs" / "patterns_k0.1.toml"

pytestmark = [pytest.mark.slow, pytest.mark.mpi]


def _run(tmp: Path, name: str, env: dict[str, str]):
    import knitsweep as ks

    out = tmp / f"{name}.h5"
    cmd = [MPIRUN, "-n", "3", sys.executable, "-m", "knitsweep", "run", str(JOB),
           "--out", str(out), "--quiet"]  # fmt: skip
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=1800, env=env)
    assert proc.returncode == 0, f"{name}: exit {proc.returncode}\n{proc.stderr[-3000:]}"
    return ks.load(out)


@pytest.fixture(scope="module")
def both_builds(tmp_path_factory):
    assert MPIRUN, "mpirun (the mpich wheel) is needed"
    tmp = tmp_path_factory.mktemp("cpus")
    base = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    host = _run(tmp, "host", base)
    generic_env = {**base, "NUMBA_CPU_NAME": "generic", "NUMBA_CACHE_DIR": str(tmp / "cache")}
    generic = _run(tmp, "generic", generic_env)
    shutil.rmtree(tmp / "cache", ignore_errors=True)
    return host, generic


def _by_series(res):
    t = res.transitions
    return {(row.stitch, row.direction): row for row in t.itertuples()}


def test_no_task_fails_and_every_series_is_refined_on_either_build(both_builds):
    for res, name in zip(both_builds, ("host", "generic"), strict=True):
        assert len(res.problems) == 0, f"{name}: problems\n{res.problems}"
        for key, row in _by_series(res).items():
            assert row.adaptive_status == "done", (name, key, row.adaptive_status)


def test_the_transitions_agree_within_the_tolerance(both_builds):
    job = tomllib.loads(JOB.read_text())
    r_mm = job["grid"]["r_mm"]
    tol = 2 * job["adaptive"]["tolerance_mm"] / r_mm  # each side's bracket is < tolerance
    host, generic = (_by_series(r) for r in both_builds)
    assert host.keys() == generic.keys()
    for key in host:
        a, b = host[key], generic[key]
        assert a.status == b.status, (key, a.status, b.status)
        assert abs(a.L_over_r_trans - b.L_over_r_trans) <= tol, (
            key, a.L_over_r_trans, b.L_over_r_trans, tol)  # fmt: skip
