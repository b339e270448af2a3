"""Integration tier: every tutorial's commands, and the README's recipes, as a reader
would paste them.

Each fenced ``bash`` or ``python`` block of docs/tutorials/*.md and README.md is marked either
``<!-- runnable -->`` or ``<!-- not run: why -->`` on the line before it. This test runs
the runnable ones of each tutorial in order, in a fresh directory, where ``jobs/`` holds
small copies of the jobs they name (tests/data/jobs/tutorials/, same names, so the same
output files) and ``examples/`` is the repository's. A block fails the test on a non-zero
exit code.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TUTORIALS = sorted((ROOT / "docs" / "tutorials").glob("*.md"))
PAGES = [*TUTORIALS, ROOT / "README.md"]
SMALL_JOBS = Path(__file__).parent / "data" / "jobs" / "tutorials"
BLOCK = re.compile(
    r"^(<!-- (runnable|not run: [^>]+) -->\n)?```(\w+)[^\n]*\n(.*?)^```$", re.M | re.S
)
JOB = re.compile(r"\bjobs/([\w.+-]+\.toml)\b")


def blocks(path: Path) -> list[tuple[str | None, str, str]]:
    """A page's fenced code blocks: (marker or None, language, code)."""
    return [(m.group(2), m.group(3), m.group(4)) for m in BLOCK.finditer(path.read_text())]


def runnable(path: Path) -> list[tuple[str, str]]:
    return [(lang, code) for mark, lang, code in blocks(path) if mark == "runnable"]


def test_there_are_tutorials_with_runnable_commands():
    names = {p.stem for p in TUTORIALS}
    assert {"first-study", "patterns", "slurm", "results-in-python"} <= names
    for path in PAGES:
        assert runnable(path), f"{path.name} has no runnable block"


@pytest.mark.parametrize("path", PAGES, ids=lambda p: p.stem)
def test_every_command_block_says_whether_it_runs(path):
    unmarked = [code.splitlines()[0] for mark, lang, code in blocks(path)
                if lang in ("bash", "python", "sh") and mark is None]  # fmt: skip
    assert not unmarked, (
        f"{path.name}: blocks without <!-- runnable --> or <!-- not run: why -->: {unmarked}"
    )


@pytest.mark.parametrize("path", PAGES, ids=lambda p: p.stem)
def test_every_job_a_tutorial_runs_has_a_small_copy(path):
    for _, code in runnable(path):
        for name in JOB.findall(code):
            assert (ROOT / "jobs" / name).exists(), f"{path.name} names jobs/{name}: no such job"
            small = SMALL_JOBS / name
            assert small.exists(), f"{path.name} runs jobs/{name}: add a small copy as {small}"
            assert _name(small) == _name(ROOT / "jobs" / name), f"{small}: not the job's name"


def test_the_block_reader_sees_the_markers(tmp_path):
    page = tmp_path / "t.md"
    page.write_text(
        "<!-- runnable -->\n```bash\necho a\n```\n\n```bash\necho b\n```\n"
        "<!-- not run: needs SLURM -->\n```bash\nsbatch x\n```\n```python\nprint(1)\n```\n"
    )
    assert blocks(page) == [("runnable", "bash", "echo a\n"), (None, "bash", "echo b\n"),
                            ("not run: needs SLURM", "bash", "sbatch x\n"),
                            (None, "python", "print(1)\n")]  # fmt: skip


def _name(job: Path) -> str:
    from knitsweep.service.jobs import load_job

    return load_job(job).name


@pytest.mark.slow
@pytest.mark.mpi
@pytest.mark.timeout(600)
@pytest.mark.parametrize("path", PAGES, ids=lambda p: p.stem)
def test_tutorial_commands_run(path, tmp_path):
    (tmp_path / "jobs").mkdir()
    for job in SMALL_JOBS.glob("*.toml"):
        (tmp_path / "jobs" / job.name).write_text(job.read_text())
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    venv_bin = str(Path(sys.executable).parent)
    env = {k: v for k, v in os.environ.items() if not k.startswith("KNITSWEEP_")}
    env.update(PATH=os.pathsep.join([venv_bin, env.get("PATH", "")]), MPLBACKEND="Agg",
               VIRTUAL_ENV=str(Path(sys.executable).parent.parent), COLUMNS="100")  # fmt: skip
    for lang, code in runnable(path):
        argv = ["bash", "-euo", "pipefail", "-c", code] if lang == "bash" else [sys.executable]
        proc = subprocess.run(argv, input=None if lang == "bash" else code, cwd=tmp_path,
                              env=env, capture_output=True, text=True, timeout=480)  # fmt: skip
        assert proc.returncode == 0, (
            f"{path.name}: this {lang} block exited with {proc.returncode}:\n{code}\n"
            f"--- stdout\n{proc.stdout[-3000:]}\n--- stderr\n{proc.stderr[-3000:]}"
        )
