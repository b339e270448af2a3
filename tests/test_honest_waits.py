"""Honest waits: the compile notice appears whenever kernels compile (numba's own cache
index of this checkout decides), and the commands report compile seconds apart from
compute, with units and their inputs."""

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from knitsweep import compilation, kernels
from knitsweep.cli.run_commands import time_split

ROOT = Path(__file__).resolve().parents[1]

_KERNEL = textwrap.dedent("""
    from numba import njit

    @njit(cache=True)
    def double(x):
        return 2.0 * x
""")
_PROBE = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    import tiny_kernel
    from knitsweep.kernels import in_cache
    if sys.argv[2] == "call":
        tiny_kernel.double(1.0)
    print(in_cache(tiny_kernel.double))
""")


def _probe(where: Path, cache: Path, action: str) -> str:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    out = subprocess.run([sys.executable, "-c", _PROBE, str(where), action], env=env,
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_a_kernel_counts_as_cached_only_from_its_own_checkout(tmp_path):
    """numba caches a function per source path: a copy of the same source in another
    directory (another checkout) finds no compiled version, though its index lies in
    the same cache folder, and so it is not "cached" (it will compile)."""
    cache = tmp_path / "cache"
    here, there = tmp_path / "checkout_a", tmp_path / "checkout_b"
    here.mkdir()
    (here / "tiny_kernel.py").write_text(_KERNEL)
    assert _probe(here, cache, "look") == "False"  # nothing compiled yet
    assert _probe(here, cache, "call") == "True"  # compiled (and cached) by the call
    assert _probe(here, cache, "look") == "True"  # a new process finds it
    shutil.copytree(here, there, ignore=shutil.ignore_patterns("__pycache__"))
    assert list(cache.rglob("*.nbi"))  # another checkout's index is in the cache folder
    assert _probe(there, cache, "look") == "False"
    (here / "tiny_kernel.py").write_text(_KERNEL.replace("2.0", "3.0"))  # edited source
    assert _probe(here, cache, "look") == "False"


def test_an_index_of_another_checkout_in_the_cache_folder_is_not_this_ones(tmp_path):
    """The check before a run: index files named like this checkout's kernels, under the
    cache folder but another source path, leave the kernels uncached (the notice shows)."""
    code = ("import os, numba\n"
            "from knitsweep import kernels, compilation\n"
            "other = os.path.join(numba.config.CACHE_DIR, 'kernels_0123456789abcdef')\n"
            "os.makedirs(other)\n"
            "for name in ('cell.cell_energy_listed-30', 'contact.find_contacts-11',\n"
            "             'forces.contact_forces_by_class-40', 'kkt.kkt_step-20'):\n"
            "    open(os.path.join(other, name + '.py311.nbi'), 'wb').close()\n"
            "print(kernels.cached(), compilation.compile_notice() is not None)\n")  # fmt: skip
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, timeout=300)  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "True"]


def test_a_patterns_kernels_have_their_own_notice(monkeypatch):
    """With stockinette's kernels cached but not garter's (its geometry and the pattern
    energy), stockinette needs no notice and garter gets one that names it."""
    from knitsweep.kernels.pattern_cell import pattern_cell_energy
    from knitsweep.stitches import get_stitch

    garter = {pattern_cell_energy, get_stitch("garter").control_points}
    monkeypatch.setattr(kernels, "in_cache", lambda d: d not in garter)
    assert compilation.compile_notice(("stockinette",)) is None
    message = compilation.compile_notice(("garter",))
    assert message is not None and "kernels (garter) once" in message
    idle = compilation.COMPILE_SECONDS[("run", "glides")]
    assert f"~{idle} s on an idle machine, longer on a busy one" in message
    assert compilation.compile_notice(("garter",), "energy") is not None
    names = compilation.kernel_entry_points(("garter",))
    assert "knitsweep.stitches.garter.geometry.state_to_control_points" in names
    assert "knitsweep.kernels.pattern_cell.pattern_cell_energy" in names


def test_the_notice_says_when_this_machine_is_busy(monkeypatch):
    """On a busy machine the notice scales the idle time by the load per core."""
    monkeypatch.setattr(kernels, "in_cache", lambda d: False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    monkeypatch.setattr(os, "getloadavg", lambda: (8.0, 8.0, 8.0))
    idle = compilation.COMPILE_SECONDS[("run", "translations")]
    message = compilation.compile_notice()
    expect = compilation._duration(idle * 8.0 / 2)
    assert (f"~{idle} s on an idle machine, longer on a busy one: this one is, load 8.0 on 2 "
            f"cores, so expect ~{expect} or more;") in message  # fmt: skip
    monkeypatch.setattr(os, "getloadavg", lambda: (0.5, 0.5, 0.5))
    assert "expect" not in compilation.compile_notice()


def test_the_compile_clock_counts_compiling_only():
    from numba import njit

    @njit
    def triple(x):
        return 3.0 * x

    with compilation.compile_clock() as clock:
        triple(1.0)
    first = clock.seconds
    assert first > 0.0
    with compilation.compile_clock() as again:
        triple(2.0)  # compiled already
    assert again.seconds == 0.0


def test_the_eta_does_not_count_the_compile_as_throughput():
    """Two of four points took 1 s each, after 90 s of compiling and 2 s of work: 2 s of
    work are left, at 1 s of work a second, so 2 s to go (not 94 s)."""
    from knitsweep.service.progress import RunProgress

    p = RunProgress(show=False)
    p.add_tasks("point", 4)
    p.finished("point", 1.0, "")
    p.finished("point", 1.0, "")
    p.t0 -= 92.0 - p.elapsed  # 92 s have passed
    assert p.eta() == pytest.approx(92.0, rel=0.02)  # the compile counted as work time
    p.setup_s = 90.0
    assert p.eta() == pytest.approx(2.0, rel=0.05)


def test_the_run_summary_splits_compile_from_compute():
    assert time_split(10.0, 0.0) == ""
    assert time_split(100.0, 94.0) == (" (94.0 s compiling the kernels, cached from now on; "
                                       "6.0 s computing)")  # fmt: skip


def _knitsweep(*args, env=None):
    return subprocess.run([sys.executable, "-m", "knitsweep", *args], capture_output=True,
                          text=True, timeout=1200, env=env)  # fmt: skip


def test_relax_json_carries_units_inputs_and_compile_seconds():
    out = _knitsweep("relax", "--L", "11.0", "--k", "0.1", "--starts", "1", "--preset", "draft",
                     "--json")  # fmt: skip
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["parameters"]["L_mm"] == 11.0 and got["parameters"]["k_mN_per_mm2"] == 0.1
    assert got["parameters"]["stitch"] == "stockinette"
    assert got["numerics"]["preset"] == "draft" and got["numerics"]["starts"]["count"] == 1
    assert got["units"]["total_energy"] == "mJ" and got["units"]["a_x"] == "mm"
    assert got["units"]["seconds"] == got["units"]["compile_seconds"] == "s"
    assert got["units"]["L_mm"] == "mm"
    assert got["compile_seconds"] >= 0.0 and got["seconds"] > 0.0
    text = _knitsweep("relax", "--L", "11.0", "--k", "0.1", "--starts", "1", "--preset", "draft")
    assert text.returncode == 0, text.stderr
    assert "total_energy" in text.stdout and " mJ" in text.stdout
    assert "stitch=stockinette L_mm=11 " in text.stdout and "compile_seconds" in text.stdout
    assert all(line.endswith(" s") for line in text.stdout.splitlines()
               if line.startswith(("seconds", "compile_seconds")))  # fmt: skip


@pytest.mark.slow
def test_a_cold_relax_and_run_say_they_compile_and_count_it_apart(tmp_path):
    """With an empty kernel cache: relax prints the notice, and its JSON counts the
    compile in compile_seconds, not in seconds; a run prints the notice before its first
    task and splits its summary."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    out = _knitsweep("relax", "--L", "11.0", "--starts", "1", "--preset", "draft", "--json",
                     env=env)  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert out.stderr.startswith("compiling numerical kernels (stockinette) once")
    got = json.loads(out.stdout)
    assert got["compile_seconds"] > 1.0
    again = json.loads(_knitsweep("relax", "--L", "11.0", "--starts", "1", "--preset", "draft",
                                  "--json", env=env).stdout)  # fmt: skip
    assert again["compile_seconds"] == 0.0
    assert again["seconds"] < got["compile_seconds"]  # the compile is not in seconds
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "cold_for_run")
    run = _knitsweep("run", str(ROOT / "tests" / "data" / "jobs" / "tiny.toml"), "--out",
                     str(tmp_path / "t.h5"), "--executor", "serial", env=env)  # fmt: skip
    assert run.returncode == 0, run.stderr
    lines = run.stderr.splitlines()
    assert lines[0].startswith("compiling numerical kernels (stockinette) once")
    assert "s compiling the kernels, cached from now on;" in lines[-1]
    assert lines[-1].endswith("s computing)")


@pytest.mark.parametrize("command", [["render", "--out", "a.png"], ["relax"], ["energy"]])
def test_every_command_asks_for_its_stitchs_kernels(monkeypatch, tmp_path, command):
    """render of a relaxation, relax and energy give the notice of the stitch they
    compute (a pattern's own kernels), not stockinette's."""
    from typer.testing import CliRunner

    from knitsweep.cli.application import build_app
    from knitsweep.errors import InputError
    from knitsweep.report import render as rendering
    from knitsweep.stitches import get_stitch

    asked = []

    def notice(stitches=("stockinette",), what="run"):
        asked.append((stitches, what))
        raise InputError("stopped before computing")

    monkeypatch.setattr(compilation, "compile_notice", notice)
    monkeypatch.setattr(rendering, "render", notice)
    state = tmp_path / "rib.dat"
    state.write_text("\n".join(str(float(v)) for v in get_stitch("rib").start(1)))
    args = [*command, "--stitch", "rib"] + (["--state", str(state)] if command == ["energy"]
                                           else [])  # fmt: skip
    out = CliRunner().invoke(build_app(), args)
    assert out.exit_code == 2, out.output
    what = "energy" if command == ["energy"] else "run"
    assert asked == [(("rib",), what)]
