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
