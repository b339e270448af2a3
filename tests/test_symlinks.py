"""No file outside the output directory is ever written or deleted through a symbolic
link: every file knitsweep creates, replaces or deletes beside a results file (lock,
journal directory and entries, shadow, spare, progress file) and every output of
``phase-diagram``, ``report``, ``render``, ``merge`` and ``run`` is refused with one
line when a link stands in its place. Run as root and as an ordinary user (nobody)
in a directory that is not sticky, where anyone may plant a link (integration)."""

import os
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

import pytest
from conftest import TINY, one_error_line

ROOT = Path(__file__).resolve().parents[1]
INIT_1 = ROOT / "knitsweep" / "stitches" / "stockinette" / "data" / "Init_1.dat"
SITE = Path(sysconfig.get_paths()["purelib"])  # this venv's packages, for the system python


def _readable_by_others(path: Path) -> bool:
    """Whether every directory down to ``path`` lets other users in (not under /root)."""
    return all(p.stat().st_mode & 0o005 == 0o005 for p in (path, *path.parents))


def as_user(user: str, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    """``python -m knitsweep ARGS`` as ``user`` (root: this interpreter; nobody: the
    system python with this checkout and its venv's packages, since /root is private)."""
    env = {"PATH": "/usr/bin:/bin", "OPENBLAS_NUM_THREADS": "1", "HOME": str(cwd),
           "MPLCONFIGDIR": str(cwd / ".mpl")}  # fmt: skip
    if user == "root":
        cmd = [sys.executable, "-m", "knitsweep", *args]
        env["PYTHONPATH"] = str(ROOT)
    else:
        cmd = ["setpriv", "--reuid", user, "--regid", "nogroup", "--clear-groups",
               "/usr/bin/python3", "-m", "knitsweep", *args]  # fmt: skip
        env["PYTHONPATH"] = f"{ROOT}:{SITE}"
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)


@pytest.fixture(params=["root", "nobody"])
def user(request):
    if os.geteuid() != 0:
        pytest.skip("switching users needs root (as CI has)")
    if request.param == "nobody":
        system = Path("/usr/bin/python3")
        if not system.exists():
            pytest.skip("no system python for the ordinary user")
        same = subprocess.run([system, "-c", "import sys; print(sys.version_info[:2])"],
                              capture_output=True, text=True).stdout.strip()  # fmt: skip
        if same != str(sys.version_info[:2]):
            pytest.skip(
                f"the system python is {same}, this venv's packages are for {sys.version_info[:2]}"
            )
        for needed in (ROOT, SITE):
            if not _readable_by_others(needed):
                pytest.skip(f"the ordinary user cannot read {needed}")
    return request.param


@pytest.fixture
def shared(tiny_reference):
    """A world-writable, non-sticky directory holding a copy of the tiny results, and
    a victim file and directory outside it that links will point at (under a fresh
    directory of /tmp that every user can reach: pytest's own are private)."""
    tmp_path = Path(tempfile.mkdtemp(prefix="knitsweep-links-"))
    yield from _shared(tmp_path, tiny_reference)
    shutil.rmtree(tmp_path, ignore_errors=True)


def _shared(tmp_path, tiny_reference):
    d = tmp_path / "shared"
    d.mkdir()
    os.chmod(d, 0o777)  # no sticky bit: anyone may rename or plant files here
    assert not os.stat(d).st_mode & 0o1000
    shutil.copy(tiny_reference, d / "t.h5")
    os.chmod(d / "t.h5", 0o666)
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    os.chmod(victim, 0o666)
    vdir = tmp_path / "victim_dir"
    vdir.mkdir()
    (vdir / "keep.txt").write_text("keep\n")
    os.chmod(vdir, 0o777)
    os.chmod(vdir / "keep.txt", 0o666)
    os.chmod(tmp_path, 0o755)
    yield d, victim, vdir


def untouched(victim: Path, vdir: Path) -> None:
    assert victim.read_text() == "precious\n"
    assert sorted(p.name for p in vdir.iterdir()) == ["keep.txt"]


@pytest.mark.parametrize("name, what", [
    ("n.h5.lock", "lock file"), (".n.h5.shadow", "shadow copy"), (".n.h5.spare", "spare copy"),
    ("n.h5.progress.json", "progress file"), ("n.h5", "results file"),
])  # fmt: skip
def test_run_refuses_a_link_beside_its_results_file(shared, user, name, what):
    d, victim, vdir = shared
    (d / name).symlink_to(victim)
    proc = as_user(user, "run", str(TINY), "--out", "n.h5", cwd=d)
    one_error_line(proc, f"{what} ")
    assert "symbolic link" in proc.stderr
    untouched(victim, vdir)


def test_a_linked_journal_is_never_cleaned_or_written(shared, user):
    d, _victim, vdir = shared
    (vdir / "junk.entry").write_text("not an entry")  # what a cleaner would delete
    os.chmod(vdir / "junk.entry", 0o666)
    (d / "t.h5.journal").symlink_to(vdir)
    one_error_line(as_user(user, "run", str(TINY), "--out", "t.h5", cwd=d), "journal directory")
    merged = as_user(user, "merge", "m.h5", "t.h5", cwd=d)  # an input's: read, never through
    assert merged.returncode == 0 and "journal directory is a symbolic link" in merged.stderr
    status = as_user(user, "status", "t.h5", cwd=d)
    assert status.returncode == 0 and "symbolic link" in status.stdout
    assert sorted(p.name for p in vdir.iterdir()) == ["junk.entry", "keep.txt"]


def test_a_linked_journal_entry_is_not_read_and_not_deleted(shared, user):
    d, victim, vdir = shared
    journal = d / "t.h5.journal"
    journal.mkdir()
    os.chmod(journal, 0o777)
    (journal / "sweeps-abc.entry").symlink_to(victim)
    status = as_user(user, "status", "t.h5", cwd=d)
    assert status.returncode == 0 and "symbolic link, not read" in status.stdout
    untouched(victim, vdir)
    assert (journal / "sweeps-abc.entry").is_symlink()


@pytest.mark.parametrize("command", ["phase-diagram-dir", "phase-diagram-file", "report",
                                     "render", "merge", "recover"])  # fmt: skip
def test_outputs_are_never_written_through_a_link(shared, user, command):
    d, victim, vdir = shared
    if command == "phase-diagram-dir":
        (d / "pd").symlink_to(vdir)
        args = ("phase-diagram", "t.h5", "--out", "pd", "--no-figures")
    elif command == "phase-diagram-file":
        (d / "pd").mkdir()
        os.chmod(d / "pd", 0o777)
        (d / "pd" / "transitions.csv").symlink_to(victim)
        args = ("phase-diagram", "t.h5", "--out", "pd", "--no-figures")
    elif command == "report":
        (d / "r.html").symlink_to(victim)
        args = ("report", "t.h5", "--out", "r.html")
    elif command == "render":
        (d / "r.png").symlink_to(victim)
        args = ("render", "--out", "r.png", "--state", str(INIT_1))
    elif command == "merge":
        (d / "m.h5").symlink_to(victim)
        args = ("merge", "m.h5", "t.h5")
    else:
        (d / "m.h5").symlink_to(victim)
        args = ("recover", "m.h5")
    proc = as_user(user, *args, cwd=d)
    assert proc.returncode == 2, proc.stderr
    assert "symbolic link" in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    untouched(victim, vdir)
