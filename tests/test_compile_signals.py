"""A signal while the kernels compile, in a serial run and in each rank of ``mpirun``:
between two kernels (``KNITSWEEP_TEST_SIGNAL_AT=kernel#<n>``, reached before each
kernel ``compilation.compile_group`` compiles) and within one kernel's compile, at the
moment LLVM hands numba a module's machine code (``llvm#<n>``: inside llvmlite's ctypes
callback, which swallows the exception a signal handler raises there; numba then failed
later with "RuntimeError: no compiled object yet"). Every rank ends with exit code 3 and
one line, no traceback (integration tier: each run compiles into an empty cache)."""

import os
import signal
import subprocess
import sys

import pytest
from conftest import MPIRUN, TINY

from knitsweep.service import signals, worker
from knitsweep.service.jobs import load_job


def run_signalled(tmp_path, at, mpi=0, timeout=600):
    cache = tmp_path / "cache"  # empty: the kernels compile
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "NUMBA_CACHE_DIR": str(cache),
           "KNITSWEEP_TEST_SIGNAL_AT": at}  # fmt: skip
    cmd = [sys.executable, "-m", "knitsweep", "run", str(TINY), "--out", str(tmp_path / "c.h5"),
           "--quiet"]  # fmt: skip
    if mpi:
        cmd = [MPIRUN, "-n", str(mpi), *cmd]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # fmt: skip
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        pytest.fail(f"signal at {at}: still running after {timeout} s")
    return proc.returncode, err


def assert_interrupted(rc, err, at, ranks=1):
    assert rc == 3, f"signal at {at}: exit {rc}: {err}"
    assert "Traceback" not in err and "Error" not in err, f"signal at {at}: {err}"
    lines = [line for line in err.splitlines() if line.startswith("interrupted by SIGTERM")]
    assert len(lines) == ranks, f"signal at {at}: not one line a rank: {err}"


@pytest.mark.slow
@pytest.mark.parametrize("at", ["llvm#20", "kernel#2"])
def test_a_signal_while_compiling_ends_a_serial_run_with_one_line(tmp_path, at):
    assert_interrupted(*run_signalled(tmp_path, at), at)


@pytest.mark.slow
@pytest.mark.mpi
@pytest.mark.parametrize("at", ["llvm#20@0", "kernel#3@0", "kernel#2@1"])
def test_a_signal_while_compiling_ends_every_rank_with_one_line(tmp_path, at):
    if MPIRUN is None:
        pytest.fail("mpirun not found: install the mpich wheel")
    rc, err = run_signalled(tmp_path, at, mpi=2)
    assert_interrupted(rc, err, at, ranks=2)


def test_a_signal_numba_swallowed_is_the_signal(monkeypatch):
    """What numba raises after a signal's exception vanished inside a ctypes callback
    (the signal recorded, the compile failing later) is the signal."""

    def compile_swallowing(*args, **kw):
        signals.request(signal.SIGTERM)  # recorded; its exception swallowed
        raise RuntimeError("no compiled object yet for <Library 'crossover_curve_into'>")

    monkeypatch.setattr(worker, "kernels_cached", lambda job: False)
    monkeypatch.setattr("knitsweep.compilation.compile_kernels", compile_swallowing)
    old = signals.install()
    try:
        with pytest.raises(signals.Interrupted):
            worker.prepare(load_job(TINY))
    finally:
        signals.restore(old)


def test_compile_group_reaches_a_test_point_before_each_kernel():
    from knitsweep.compilation import compile_group

    reached = []
    for group in ("geometry", "contact", "solver"):
        compile_group(group, each_kernel=lambda g=group: reached.append(g))
    assert reached.count("geometry") == 1 and reached.count("solver") == 1
    assert reached.count("contact") >= 4  # energy, neighbour list, contacts, forces, ...


@pytest.mark.slow
@pytest.mark.mpi
def test_a_worker_signalled_while_the_master_compiles_stops_the_run_at_once(tmp_path):
    """SIGTERM to a worker alone (3 s after its MPI_Init) while rank 0 compiles into an
    empty cache: the worker leaves and tells the master, which stops at its next kernel
    (it used to compile every kernel first, minutes on a busy machine, while the worker's
    wait for the job ran out)."""
    if MPIRUN is None:
        pytest.fail("mpirun not found: install the mpich wheel")
    rc, err = run_signalled(tmp_path, "mpi_init+3@1", mpi=2)
    assert_interrupted(rc, err, "mpi_init+3@1", ranks=2)
    probe = (
        "from knitsweep.compilation import kernel_entry_points; "
        "from knitsweep.kernels import cached; print(cached(kernel_entry_points()))"
    )
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    done = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True)
    assert done.stdout.strip() == "False", "the master compiled every kernel first"
