"""A signal at every stage of start-up, in every rank of ``mpirun -n 3``: imports,
class creation (where Python wraps the signal's exception in RuntimeError), MPI_Init,
the compile, the job's broadcast and the first hand-out. The signal is raised at the
stage itself (``KNITSWEEP_TEST_SIGNAL_AT=<stage>@<rank>``: the tests' fault injector,
tests/fault_plugin, at the named point ``signals.fault_point``),
not at a wall-clock delay. Every rank reports one line and the run ends within
seconds with exit code 3, no traceback, no process left (integration tier). Last, a
worker's side of the MPI protocol against a scripted master (unit tier)."""

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest
from conftest import TINY

from knitsweep.service import signals
from knitsweep.service.signals import STAGES, as_interrupt

VENV_BIN = Path(sys.executable).parent
MPIRUN = shutil.which("mpirun", path=str(VENV_BIN)) or shutil.which("mpirun")


def test_a_wrapped_signal_is_still_the_signal():
    from knitsweep.service.signals import Interrupted

    class Probe:
        def __set_name__(self, owner, name):
            raise Interrupted(signal.SIGTERM)

    with pytest.raises(RuntimeError) as info:
        type("Made", (), {"probe": Probe()})  # what pydantic's class creation does
    assert isinstance(as_interrupt(info.value), Interrupted)
    assert as_interrupt(RuntimeError("other")) is None


def test_the_fault_injector_is_the_tests_and_only_where_asked(tmp_path):
    """knitsweep has no injector of its own: in a process the tests start, the plugin
    (tests/fault_plugin) becomes it with KNITSWEEP_TEST_SIGNAL_AT set, and nothing is
    installed without the variable."""
    probe = ("from knitsweep.service import signals; f = signals.injector; "
             "print(None if f is None else f.__module__)")  # fmt: skip
    env = {k: v for k, v in os.environ.items() if k != "KNITSWEEP_TEST_SIGNAL_AT"}

    def injector(**extra):
        out = subprocess.run([sys.executable, "-c", probe], env={**env, **extra}, cwd=tmp_path,
                             capture_output=True, text=True, timeout=60)  # fmt: skip
        assert out.returncode == 0, out.stderr
        return out.stdout.strip()

    assert injector() == "None"
    assert injector(KNITSWEEP_TEST_SIGNAL_AT="handout#99") == "fault_injection"
    assert signals.fault_point("imports") is None  # this process: no injector, no signal


def test_signal_during_class_creation_in_a_single_process(tmp_path):
    env = {**os.environ, "KNITSWEEP_TEST_SIGNAL_AT": "class", "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run([sys.executable, "-m", "knitsweep", "run", str(TINY), "--out",
                           str(tmp_path / "c.h5")], capture_output=True, text=True, env=env,
                          timeout=120)  # fmt: skip
    assert proc.returncode == 3, proc.stderr
    assert proc.stderr.strip() == "interrupted by SIGTERM", proc.stderr


@pytest.mark.slow
@pytest.mark.mpi
@pytest.mark.parametrize("stage", STAGES)
def test_signal_at_each_start_up_stage_in_each_rank(tmp_path, stage):
    if MPIRUN is None:
        pytest.fail("mpirun not found: install the mpich wheel")
    for rank in range(3):
        out = tmp_path / f"{stage}{rank}.h5"
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1",
               "KNITSWEEP_TEST_SIGNAL_AT": f"{stage}@{rank}"}  # fmt: skip
        cmd = [MPIRUN, "-n", "3", sys.executable, "-m", "knitsweep", "run", str(TINY), "--out",
               str(out), "--quiet"]  # fmt: skip
        t0 = time.monotonic()
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, start_new_session=True)  # fmt: skip
        try:
            _, err = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            pytest.fail(f"signal at {stage} in rank {rank}: still running after 60 s")
        seconds = time.monotonic() - t0
        where = f"signal at {stage} in rank {rank} ({seconds:.1f} s)"
        assert proc.returncode == 3, f"{where}: exit {proc.returncode}: {err}"
        assert "Traceback" not in err and "RuntimeError" not in err, f"{where}: {err}"
        lines = [line for line in err.splitlines() if line.startswith("interrupted by SIGTERM")]
        assert len(lines) == 3, f"{where}: not every rank reported: {err}"
        assert seconds < 30, f"{where}: too slow to end"
        if out.exists():
            with h5py.File(out) as f:
                assert f.attrs["run_status"] == "interrupted"


class _Status:
    tag = source = None

    def Get_tag(self):
        return self.tag

    def Get_source(self):
        return self.source


class _Master:
    """A worker's communicator whose other end plays rank 0: the job first, then a task
    batch and STOP when the worker says it LEFT; records what the worker sends."""

    def __init__(self, job_json):
        from knitsweep.service.executors.protocol import JOB

        self.inbox, self.sent = [(JOB, job_json)], []

    def Get_rank(self):
        return 1

    def Iprobe(self, source, tag, status):
        if self.inbox:
            status.tag, status.source = self.inbox[0][0], 0
        return bool(self.inbox)

    def recv(self, source, tag):
        got, message = self.inbox.pop(0)
        assert got == tag
        return message

    def send(self, message, dest, tag):
        from types import SimpleNamespace

        from knitsweep.service.executors.protocol import LEFT, STOP, TASK

        self.sent.append(tag)
        if tag == LEFT:  # tasks were on their way; then the master stops the run
            self.inbox += [(TASK, [(SimpleNamespace(task_id="p1"), None)]), (STOP, 3)]


def test_a_worker_stopped_while_loading_the_kernels_leaves_through_the_protocol(monkeypatch):
    """The signal's exception comes out of the kernels' loading wrapped (numba hands it
    back as SystemError): the worker still says it LEFT, returns the tasks that arrive
    (ABANDONED) and answers STOP (STOPPED), so nothing the master sent is left unreceived;
    MPI_Finalize failed on such a message (mpirun exit 1, 9 or 11) before."""
    import types

    from knitsweep.service.executors import mpi
    from knitsweep.service.executors.protocol import ABANDONED, LEFT, STOPPED
    from knitsweep.service.jobs import load_job

    fake = types.SimpleNamespace(Status=_Status, ANY_TAG=-1, ANY_SOURCE=-2)
    monkeypatch.setitem(sys.modules, "mpi4py", types.SimpleNamespace(MPI=fake))
    monkeypatch.setitem(sys.modules, "mpi4py.MPI", fake)
    monkeypatch.setattr(signals, "_state", {"signum": None, "count": 0, "raise": False})

    def loading(job, notice):
        signals.request(signal.SIGTERM)
        try:
            raise signals.Interrupted(signal.SIGTERM)
        except signals.Interrupted as e:
            raise SystemError("<numba dispatcher> returned a result with an exception set") from e

    monkeypatch.setattr(mpi, "prepare", loading)
    comm = _Master(load_job(TINY).model_dump_json())
    assert mpi.mpi_worker_loop(comm) == signals.EXIT_INTERRUPTED
    assert comm.sent == [LEFT, ABANDONED, STOPPED] and comm.inbox == []
