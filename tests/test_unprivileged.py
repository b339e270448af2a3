"""As an ordinary user (``nobody``, with a home of its own): README's first command
(``mpirun -n 2 knitsweep run jobs/demo.toml``, then ``knitsweep phase-diagram demo.h5
--out demo-figures``) works, an interrupted run resumes, and a results file that user
cannot write is refused with one line before any compute (integration). The test runs
as root (as CI does) and drops to nobody with setpriv; without root it fails, as the
multihost tests do, rather than skipping unseen."""

import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

import h5py
import pytest
from conftest import FAULT_PLUGIN, TINY, one_error_line

ROOT = Path(__file__).resolve().parents[1]
VENV_BIN = Path(sys.executable).parent
pytestmark = [pytest.mark.unprivileged, pytest.mark.mpi]


SITE = Path(sysconfig.get_paths()["purelib"])  # this venv's packages
ENV: dict[str, str] = {}  # what nobody's commands need beyond PATH and HOME (the fixture)


def _open_to_others(path: Path) -> bool:
    return all(p.stat().st_mode & 0o005 == 0o005 for p in (path, *path.parents))


@pytest.fixture(scope="module")
def home():
    """A fresh home directory owned by nobody (mode 700), with the repository's jobs/ and,
    where this venv's interpreter lies where nobody cannot reach it (a pyenv under
    /root), ``~/bin/knitsweep`` on the system python with this checkout and the venv's
    packages (as an administrator's shared install would be)."""
    if os.geteuid() != 0:
        pytest.fail("the unprivileged-user tests need root to switch to nobody; run as root")
    for path in (ROOT, VENV_BIN, SITE):
        if not _open_to_others(path):
            pytest.fail(f"nobody cannot read {path}: put the checkout and venv where others can")
    d = Path(tempfile.mkdtemp(prefix="knitsweep-nobody-"))
    shutil.copytree(ROOT / "jobs", d / "jobs")
    shutil.copy(TINY, d / "tiny.toml")
    ENV.clear()
    if not _open_to_others(Path(sys.executable).resolve()):
        system = Path("/usr/bin/python3")
        same = subprocess.run([system, "-c", "import sys; print(sys.version_info[:2])"],
                              capture_output=True, text=True).stdout.strip()  # fmt: skip
        if same != str(sys.version_info[:2]):
            pytest.fail(f"nobody cannot run {Path(sys.executable).resolve()}, and {system} is "
                        f"{same or 'missing'}, not {sys.version_info[:2]}")  # fmt: skip
        (d / "bin").mkdir()
        (d / "bin" / "knitsweep").write_text(
            "#!/usr/bin/python3\nfrom knitsweep.cli import main\nmain()\n"
        )
        (d / "bin" / "knitsweep").chmod(0o755)
        ENV.update(
            PYTHONPATH=f"{ROOT}:{SITE}",
            PATH=f"{d / 'bin'}:{VENV_BIN}:/usr/bin:/bin",
            LD_LIBRARY_PATH=str(VENV_BIN.parent / "lib"),
        )  # the mpich wheel's libmpi
    subprocess.run(["chown", "-R", "nobody:nogroup", str(d)], check=True)
    d.chmod(0o700)
    yield d
    shutil.rmtree(d, ignore_errors=True)


def as_nobody(home: Path, *cmd, extra_env=None, timeout=900) -> subprocess.CompletedProcess:
    env = {"PATH": f"{VENV_BIN}:/usr/bin:/bin", "HOME": str(home), "OPENBLAS_NUM_THREADS": "1",
           "LANG": "C.UTF-8", **ENV, **(extra_env or {})}  # fmt: skip
    env["PYTHONPATH"] = ":".join(filter(None, [str(FAULT_PLUGIN), env.get("PYTHONPATH")]))
    return subprocess.run(["setpriv", "--reuid", "nobody", "--regid", "nogroup", "--clear-groups",
                           *map(str, cmd)], cwd=home, env=env, capture_output=True, text=True,
                          timeout=timeout)  # fmt: skip


@pytest.mark.slow
def test_the_readmes_first_command_works_as_nobody(home):
    run = as_nobody(home, VENV_BIN / "mpirun", "-n", "2", "knitsweep", "run", "jobs/demo.toml")
    assert run.returncode == 0, run.stderr
    assert (home / "demo.h5").stat().st_uid == 65534
    figures = as_nobody(home, "knitsweep", "phase-diagram", "demo.h5", "--out", "demo-figures")
    assert figures.returncode == 0, figures.stderr
    assert any((home / "demo-figures").glob("*.png")), sorted((home / "demo-figures").iterdir())
    assert (home / ".cache" / "knitsweep").is_dir()  # nobody's own kernel cache


def test_an_interrupted_run_resumes_as_nobody(home):
    stopped = as_nobody(home, "knitsweep", "run", "tiny.toml", "--out", "t.h5", "--quiet",
                        extra_env={"KNITSWEEP_TEST_SIGNAL_AT": "handout#3"})  # fmt: skip
    assert stopped.returncode == 3, stopped.stderr
    resumed = as_nobody(home, "knitsweep", "run", "tiny.toml", "--out", "t.h5", "--quiet")
    assert resumed.returncode == 0, resumed.stderr
    assert "already finished" in resumed.stderr and "(0 already finished)" not in resumed.stderr
    with h5py.File(home / "t.h5") as f:
        assert f.attrs["run_status"] == "complete"


def test_a_results_file_nobody_cannot_write_is_refused(home):
    theirs = home / "theirs.h5"
    shutil.copy(TINY.parent.parent / "schema2_tiny.h5", theirs)  # root's, mode 644
    theirs.chmod(0o644)
    before = theirs.read_bytes()
    out = as_nobody(home, "knitsweep", "run", "tiny.toml", "--out", theirs, "--quiet", timeout=120)
    one_error_line(out, str(theirs))
    assert theirs.read_bytes() == before
    assert not [p.name for p in home.iterdir() if p.name.startswith((".theirs", "theirs.h5."))]
