"""The ``knitsweep energy`` command, run as a user runs it."""

import json
import subprocess
import sys

import pytest
from conftest import SHIPPED, golden_cases


def knitsweep(*args):
    return subprocess.run(
        [sys.executable, "-m", "knitsweep", *args], capture_output=True, text=True, timeout=300
    )


def test_energy_json_matches_reference(data_dir):
    case = golden_cases()[0]  # init1_paper: Init_1 at the paper's parameters, k = 0.1
    out = knitsweep("energy", "--state", str(SHIPPED / "Init_1.dat"),
                    "--L", "11.6", "--k", "0.1", "--json")  # fmt: skip
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert {"bending_energy", "contact_energy", "total_energy", "length"} <= set(got)
    for key in ("bending_energy", "contact_energy", "total_energy", "length"):
        assert got[key] == pytest.approx(case[key], rel=1e-10)
    # what it was computed with, and in what units (as relax --json says it)
    assert got["parameters"]["L_mm"] == 11.6 and got["parameters"]["k_mN_per_mm2"] == 0.1
    assert got["parameters"]["stitch"] == "stockinette" and got["state"].endswith("Init_1.dat")
    assert got["fidelity"]["samples_per_segment"] == 10
    units = got["units"]
    assert units["total_energy"] == "mJ" and units["length"] == units["a_x"] == "mm"
    assert units["k_mN_per_mm2"] == "mN/mm2"


def test_energy_with_authors_config(data_dir):
    out = knitsweep("energy", "--state", str(SHIPPED / "Init_1.dat"),
                    "--config", str(data_dir / "sampleconfigfile.dat"), "--json")  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout)["contact_energy"] == pytest.approx(
        golden_cases()[0]["contact_energy"], rel=1e-10
    )


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--k", "-1"], "k_mN_per_mm2 = -1.0: must be a finite number in [1e-06, 10000]"),
        (["--r-core", "0.8"], "r_core_mm = 0.8"),
        (["--p", "0.5"], "p = 0.5: must satisfy 1 < p <= 20"),
        (["--samples", "1"], "samples_per_segment = 1"),
        (["--k", "abc"], "Invalid value for '--k'"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(data_dir, args, fragment):
    out = knitsweep("energy", "--state", str(SHIPPED / "Init_1.dat"), *args)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and fragment in lines[0]
    assert "Traceback" not in out.stderr


def test_missing_state_file():
    out = knitsweep("energy", "--state", "no/such/file.dat")
    assert out.returncode == 2
    assert "no/such/file.dat" in out.stderr and "Traceback" not in out.stderr


def test_import_is_quiet_and_light():
    code = (
        "import sys, knitsweep; assert 'numba' not in sys.modules and 'mpi4py' not in sys.modules"
    )
    out = subprocess.run(
        [sys.executable, "-W", "error", "-c", code], capture_output=True, text=True
    )
    assert out.returncode == 0 and out.stdout == "" and out.stderr == ""


def test_relax_json_reports_the_periods_and_writes_the_state(tmp_path):
    """``relax --json`` gives the per-stitch course and wale spacings a_x, a_y; ``--out``
    writes the relaxed state, which ``energy --state`` reads back to the same energy."""
    state = tmp_path / "relaxed.dat"
    out = knitsweep("relax", "--L", "11.0", "--starts", "1", "--preset", "draft", "--json",
                    "--out", str(state))  # fmt: skip
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["converged"] and got["state_file"] == str(state)
    x = [float(v) for v in state.read_text().split()]
    assert (x[-2], x[-1]) == (got["a_x"], got["a_y"]) and 2.0 < got["a_x"] < 4.0
    again = knitsweep("energy", "--state", str(state), "--L", "11.0", "--json")
    assert again.returncode == 0, again.stderr
    assert json.loads(again.stdout)["total_energy"] == pytest.approx(got["total_energy"],
                                                                     rel=1e-6)  # fmt: skip
    bad = knitsweep("relax", "--out", str(tmp_path / "no" / "dir" / "s.dat"))
    assert bad.returncode == 2 and "--out" in bad.stderr and "does not exist" in bad.stderr
