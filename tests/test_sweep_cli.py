"""`knitsweep sweep`: the observables it is asked for, its table file and its last line."""

import re
import subprocess
import sys

import h5py


def _sweep(tmp_path, *args):
    out = tmp_path / "s.h5"
    proc = subprocess.run(
        [sys.executable, "-m", "knitsweep", "sweep", "--direction", "y", "--L", "11.0",
         "--k", "0.1", "--preset", "draft", "--starts", "1", "--out", str(out), *args],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    return proc, out


def test_sweep_stops_once_its_observables_are_determined(tmp_path):
    proc, out = _sweep(tmp_path, "--observables", "energy_gaps")
    assert proc.returncode == 0, proc.stderr
    last = proc.stderr.strip().splitlines()[-1]
    m = re.fullmatch(r"# done: determined: energy gaps .*; (\d+) steps, (\d+) relaxations, "
                     r"[0-9.]+ s", last)  # fmt: skip
    assert m, last
    with h5py.File(out) as f:
        for name in ("strain", "stress", "bending_energy", "contact_energy"):
            assert f[name].shape == (int(m.group(1)),)
        assert "energy gaps" in f.attrs["stop_reason"]


def test_sweep_curve_is_the_default(tmp_path):
    proc, _ = _sweep(tmp_path, "--max-strain", "0.03")
    assert proc.returncode == 0, proc.stderr
    assert re.fullmatch(r"# done: \|strain\| [0-9.]+ > 0\.03; \d+ steps, \d+ relaxations, [0-9.]+ s",
                        proc.stderr.strip().splitlines()[-1])  # fmt: skip


def test_bad_observable_is_one_line_and_exit_2(tmp_path):
    proc, _ = _sweep(tmp_path, "--observables", "energy_gaps,jamming")
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "observables" in proc.stderr


def test_the_table_and_its_file_carry_units_and_inputs(tmp_path):
    """stdout: a comment line of the inputs as JSON, then the CSV with units in its
    column names; the .h5 file holds the same inputs and every array's units."""
    import io
    import json

    import pandas as pd

    from knitsweep.store.sweep_file import INPUTS_PREFIX

    proc, out = _sweep(tmp_path, "--max-strain", "0.03")
    assert proc.returncode == 0, proc.stderr
    first = proc.stdout.splitlines()[0]
    assert first.startswith(INPUTS_PREFIX)
    inputs = json.loads(first[len(INPUTS_PREFIX) :])
    assert inputs["direction"] == "y"
    assert inputs["parameters"]["L_mm"] == 11.0 and inputs["parameters"]["stitch"] == "stockinette"
    assert inputs["parameters"]["k_mN_per_mm2"] == 0.1
    assert inputs["numerics"]["preset"] == "draft" and inputs["numerics"]["seed"] == 0
    assert inputs["numerics"]["protocol"]["max_strain"] == 0.03
    table = pd.read_csv(io.StringIO(proc.stdout), comment="#")
    assert {"strain", "stress_N_per_mm", "bending_energy_mJ", "a_x_mm"} <= set(table.columns)
    with h5py.File(out) as f:
        assert json.loads(f.attrs["inputs_json"]) == inputs
        assert f["stress"].attrs["units"] == "N/mm"
    csv = tmp_path / "s.csv"
    again = subprocess.run(
        [sys.executable, "-m", "knitsweep", "sweep", "--direction", "y", "--L", "11.0",
         "--k", "0.1", "--preset", "draft", "--starts", "1", "--max-strain", "0.03",
         "--out", str(csv)],
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert again.returncode == 0, again.stderr
    assert csv.read_text().splitlines()[0].startswith(INPUTS_PREFIX)
