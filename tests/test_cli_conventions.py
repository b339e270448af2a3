"""The command line's conventions: --version, -h on every command, every option
described, defaults shown one way, units in one notation, and a name that means one
thing in every command."""

import os
import re
import subprocess
import sys

import pytest
import typer

from knitsweep import __version__
from knitsweep.cli.application import build_app

# the output, a state file and local workers: one meaning, worded for each command
WORDED_PER_COMMAND = {"--out", "--state", "--workers", "--starts"}  # render: 1 start
OLD_UNIT_NOTATIONS = ("mm^", "mN mm", "mN/mm^", ", mm", ", mJ", ", N/mm", "degrees")


def _commands():
    """(command path, click command) for every command of the app."""
    out = []

    def walk(cmd, path):
        if hasattr(cmd, "commands"):
            for name, sub in cmd.commands.items():
                walk(sub, (*path, name))
        else:
            out.append((" ".join(path), cmd))

    walk(typer.main.get_command(build_app()), ())
    return out


def _options():
    return [(path, p) for path, cmd in _commands() for p in cmd.params
            if p.param_type_name == "option"]  # fmt: skip


def knitsweep(*args):
    env = {**os.environ, "COLUMNS": "200"}
    return subprocess.run([sys.executable, "-m", "knitsweep", *args], capture_output=True,
                          text=True, timeout=120, env=env)  # fmt: skip


def test_version():
    for flag in ("--version", "-V"):
        out = knitsweep(flag)
        assert out.returncode == 0 and out.stdout.strip() == f"knitsweep {__version__}"


@pytest.mark.parametrize("command", [path for path, _ in _commands()])
def test_dash_h_is_help_on_every_command(command):
    out = knitsweep(*command.split(), "-h")
    assert out.returncode == 0, out.stderr
    assert "Usage: knitsweep" in out.stdout and "--help" in out.stdout


def test_every_option_is_described_with_one_notation():
    for path, p in _options():
        name = f"{path} {p.opts[0]}"
        assert p.help and p.help.strip(), f"{name}: no description"
        text = p.help.replace("\\[default: ", "")
        assert "[" not in text, f"{name}: a default or note in brackets outside [default: …]"
        for old in OLD_UNIT_NOTATIONS:
            assert old not in p.help, f"{name}: unit written as {old!r}"
        if p.default is None and p.show_default is not False:
            assert p.is_flag or p.required or p.opts[0] in {"--results", "--task", "--config",
                   "--shard", "--max-tasks", "--nodes", "--ntasks", "--time", "--partition",
                   "--launcher", "--venv", "--modules", "--shards", "--cpus-per-task",
                   "--script", "--by", "--state"} or "\\[default:" in p.help, name  # fmt: skip


def test_a_name_means_one_thing_everywhere():
    helps: dict[str, set[str]] = {}
    for _, p in _options():
        for opt in p.opts:
            helps.setdefault(opt, set()).add(p.help)
    differing = {o: h for o, h in helps.items() if len(h) > 1 and o not in WORDED_PER_COMMAND}
    assert not differing


def test_help_shows_defaults_one_way():
    out = knitsweep("sweep", "-h")
    text = re.sub(r"\s+", " ", out.stdout.replace("│", " "))
    assert "yarn length per stitch L (mm) [default: 11.6]" in text
    assert "[default: 0]" in text  # a real default, as typer shows it
    assert "[default: curve, with any preset]" in text


def test_help_says_what_the_tool_is_and_names_the_stitches():
    from knitsweep.stitches import STITCH_NAMES

    top = re.sub(r"\s+", " ", knitsweep("-h").stdout.replace("│", " "))
    assert "knitted fabric" in top and "knit/purl patterns" in top
    assert "Simulate jammed stockinette fabric" not in top
    assert f"stitches: {', '.join(STITCH_NAMES)}" in top
    for path, p in _options():
        if p.opts[0] == "--stitch":
            assert p.help.startswith(f"stitch pattern: {', '.join(STITCH_NAMES)}"), path
            assert "knitsweep.stitches" not in p.help, path


@pytest.mark.parametrize("command", ["run", "status", "phase-diagram", "render", "sweep"])
def test_flags_show_as_flag_and_no_flag_without_a_type(command):
    out = knitsweep(*command.split(), "-h")
    assert out.returncode == 0, out.stderr
    assert "<bool>" not in out.stdout
    flags = [p for path, p in _options() if path == command and p.is_flag
             and p.opts[0] not in ("--help", "-h")]  # fmt: skip
    assert flags
    for p in flags:
        name = p.opts[0]
        assert p.secondary_opts == [f"--no-{name[2:]}"], name
        assert re.search(rf"{re.escape(name)}\s+--no-{re.escape(name[2:])}", out.stdout), name


def test_render_says_which_flags_a_results_file_overrides(tmp_path):
    out = knitsweep("render", "--results", str(tmp_path / "r.h5"), "--task", "abc",
                    "--stitch", "rib", "--L", "11", "--out", str(tmp_path / "a.png"))  # fmt: skip
    assert out.returncode == 2
    assert out.stderr.strip() == ("error: --L, --stitch: a results file holds its own "
                                  "parameters; drop them to draw --results, or draw a --state "
                                  "or a relaxation (neither --results nor --state) with them")  # fmt: skip
    # without a results file, the parameters are not refused for one (the bad --cells
    # stops the command before anything is drawn)
    alone = knitsweep("render", "--stitch", "rib", "--cells", "0", "--out", str(tmp_path / "a.png"))
    assert alone.returncode == 2 and "cells = 0" in alone.stderr, alone.stderr
    assert "a results file holds its own parameters" not in alone.stderr
