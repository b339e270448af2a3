import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).parent / "data"
SHIPPED = (Path(__file__).resolve().parents[1] / "knitsweep" / "stitches" / "stockinette"
           / "data")  # the authors' Init_*.dat  # fmt: skip
TINY = DATA / "jobs" / "tiny.toml"  # 2 points, 4 sweeps, coarse numerics: ~2 s serially
VOLATILE = {"seconds", "relax_seconds", "wall_seconds", "rank", "host"}
FAULT_PLUGIN = Path(__file__).resolve().parent / "fault_plugin"
"""The tests' fault injector (``KNITSWEEP_TEST_SIGNAL_AT``): first on the PYTHONPATH of
every process the tests start, whose ``sitecustomize`` installs it where the variable is
set (knitsweep itself has only the named points, ``service.signals.fault_point``)."""
os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(FAULT_PLUGIN),
                                                         os.environ.get("PYTHONPATH")]))  # fmt: skip


VENV_BIN = Path(sys.executable).parent
MPIRUN = shutil.which("mpirun", path=str(VENV_BIN)) or shutil.which("mpirun")
"""The mpich wheel's mpirun beside this Python (else one on PATH; None if neither)."""


def run_knitsweep(*args, mpi=0, timeout=600, **kw):
    """``python -m knitsweep ARGS`` (paths and numbers as text; under ``mpirun -n mpi``
    if ``mpi``), its output captured, BLAS on one thread."""
    cmd = [sys.executable, "-m", "knitsweep", *map(str, args)]
    if mpi:
        cmd = [MPIRUN, "-n", str(mpi), *cmd]
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env, **kw)


def one_error_line(proc, fragment, code=2):
    """A command that failed as the CLI promises: exit ``code``, one line on stderr that
    starts with "error: " and holds ``fragment``, no traceback."""
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == code, proc.stderr
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert fragment in lines[0], lines[0]
    assert "Traceback" not in proc.stderr


def golden_cases():
    return json.loads((DATA / "golden_energy.json").read_text())


def golden_params(case):
    from knitsweep.config import StitchParams

    P = case["params"]
    return StitchParams.from_internal(P["L"], P["bend"], P["reg"], P["r"], P["rc"], P["k"], P["p"])


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA


@pytest.fixture(scope="session")
def init1() -> np.ndarray:
    from knitsweep.formats import read_state

    return read_state(SHIPPED / "Init_1.dat")


def stored(path, kind, with_data=False):
    """Task id -> entry of one kind in a results file (its HDF5 part, without the
    journal), read and verified as knitsweep reads it."""
    from knitsweep.store.format import journal_dir
    from knitsweep.store.read import iter_entries

    assert not journal_dir(path).exists() or not any(journal_dir(path).iterdir()), path
    return {e.task_id: e for e in iter_entries(path, with_data=with_data) if e.kind == kind}


def stored_meta(path, kind):
    """Task id -> scalars (what schema 2 kept as a task group's attributes)."""
    return {tid: e.meta for tid, e in stored(path, kind).items()}


def drop_tasks(path, drop):
    """Remove the tasks ``drop`` ((kind, task id) pairs) from a results file in place,
    as if they had never finished (the other tasks rewritten as they were)."""
    import h5py

    from knitsweep.store.format import KINDS
    from knitsweep.store.table import create_table, put_rows

    kept = {kind: [e for e in stored(path, kind, with_data=True).values()
                   if (kind, e.task_id) not in drop] for kind in KINDS}  # fmt: skip
    with h5py.File(path, "a") as f:
        for kind in KINDS:
            del f[kind]
            put_rows(create_table(f, kind), kind, kept[kind])


def physics(path):
    """Every task's stored arrays and status, minus timings and placement."""
    out = {}
    for kind in ("points", "sweeps"):
        for tid, e in stored(path, kind, with_data=True).items():
            rec = {k: v for k, v in e.record.items() if k not in VOLATILE}
            rec["status"] = e.meta["status"]
            out[(kind, tid)] = rec
    return out


def assert_same_results(a, b):
    """Two results files hold the same tasks with bit-identical arrays."""
    pa, pb = physics(a), physics(b)
    assert pa.keys() == pb.keys()
    for key in pa:
        assert pa[key].keys() == pb[key].keys(), key
        for name in pa[key]:
            assert np.array_equal(pa[key][name], pb[key][name]), (key, name)


@pytest.fixture(scope="session")
def tiny_reference(tmp_path_factory):
    """The tiny job, run serially and uninterrupted (do not modify the file)."""
    from knitsweep import service

    out = tmp_path_factory.mktemp("tiny_reference") / "tiny.h5"
    summary = service.run(TINY, out, executor="serial", show_progress=False)
    assert summary.counts["done"] == summary.total == 6
    return out
