"""`knitsweep compile`: warms a numba cache directory with every kernel a task uses."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import SHIPPED

ENTRY_POINTS = ("cell.cell_energy_listed-", "contact.find_contacts-",
                "forces.contact_forces_by_class-", "kkt.kkt_step-",
                "geometry.state_to_control_points-")  # fmt: skip


def _knitsweep(*args, env=None):
    return subprocess.run([sys.executable, "-m", "knitsweep", *args], capture_output=True,
                          text=True, timeout=1200, env=env)  # fmt: skip


@pytest.mark.parametrize(("flag", "value", "field"), [("--jobs", "0", "jobs = 0"),
                                                      ("--stitch", "cable", "stitch = 'cable'")])  # fmt: skip
def test_bad_input_is_one_line_and_exit_2(tmp_path, flag, value, field):
    out = _knitsweep("compile", "--cache-dir", str(tmp_path / "c"), flag, value)
    assert out.returncode == 2, out.stderr
    assert out.stderr.startswith(f"error: {field}") and len(out.stderr.splitlines()) == 1
    assert not (tmp_path / "c").exists() or not any((tmp_path / "c").rglob("*.nbi"))


@pytest.mark.slow
@pytest.mark.parametrize("jobs", ["1", "2"])
def test_compile_fills_an_empty_cache_that_a_task_then_uses(tmp_path, jobs):
    """An empty --cache-dir gets every task kernel (in 1 or 2 processes); a second call
    loads them; a command under NUMBA_CACHE_DIR=that directory compiles nothing."""
    cache = tmp_path / "node-local"
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    first = _knitsweep("compile", "--cache-dir", str(cache), "--jobs", jobs, "--json", env=env)
    assert first.returncode == 0, first.stderr
    result = json.loads(first.stdout)
    assert not result["was_cached"] and result["cached"]
    assert set(result["groups"]) == {"geometry", "contact", "solver"}
    kernel_dir = Path(result["cache_dir"])
    assert kernel_dir.parent == cache and kernel_dir.name.startswith("knitsweep-kernels-")
    indexes = [p.name for p in kernel_dir.rglob("*.nbi")]
    for entry in ENTRY_POINTS:
        assert any(n.startswith(entry) for n in indexes), entry
    again = _knitsweep("compile", "--cache-dir", str(cache), env=env)
    assert again.returncode == 0, again.stderr
    assert again.stdout.startswith("loaded (already cached) the kernels of stockinette in")
    # a task's kernels come from that cache: nothing compiles, no notice
    env["NUMBA_CACHE_DIR"] = str(cache)
    probe = ("import knitsweep.model as m\n"
             "from numba.core import event\n"
             "from knitsweep.config import StitchParams\n"
             "seen = []\n"
             "class L(event.Listener):\n"
             "    def on_start(self, ev): seen.append(ev.data['dispatcher'].py_func.__name__)\n"
             "    def on_end(self, ev): pass\n"
             "with event.install_listener('numba:compile', L()):\n"
             "    model = m.CellModel(StitchParams(L_mm=11.6))\n"
             "    x = model.stitch.start(1)\n"
             "    model.energy_and_gradients(x, model.neighbour_list(x))\n"
             "    model.energy_and_gradients(x)\n"
             "    model.min_zeta(x)\n"
             "    model.contacts_by_class(x)\n"
             "    model.contact_pair_forces_by_class(x, True)\n"
             "    from knitsweep.kernels.kkt_rows import compile_solver\n"
             "    compile_solver()\n"
             "print(seen)\n")  # fmt: skip
    used = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                          env=env, timeout=600)  # fmt: skip
    assert used.returncode == 0, used.stderr
    assert used.stdout.strip() == "[]", used.stdout
    energy = _knitsweep("energy", "--state", str(SHIPPED / "Init_1.dat"), "--L", "11.6", env=env)
    assert energy.returncode == 0 and "compiling" not in energy.stderr, energy.stderr


def test_a_runs_cache_check_names_the_kernels_its_stitches_need():
    """``kernels.cached`` of a job looks for the kernels its stitches call (each stitch's
    geometry, a knit/purl pattern's energy, the large states' KKT step), so a pattern run
    after a stockinette run compiles its own kernels once, with the notice."""
    from knitsweep.compilation import kernel_entry_points
    from knitsweep.kernels import ENTRY_POINTS, kernel
    from knitsweep.kernels.kkt_rows import kkt_step_rows
    from knitsweep.kernels.pattern_cell import pattern_cell_energy
    from knitsweep.stitches import get_stitch

    def geometry(name):
        return get_stitch(name).control_points

    def kernels_of(*stitches, what="run"):
        return {kernel(name) for name in kernel_entry_points(stitches, what)}

    every_task = {kernel(name) for name in ENTRY_POINTS}
    assert kernels_of("stockinette") == every_task | {geometry("stockinette")}
    assert kernels_of("stockinette", "rib") - every_task == {
        geometry("stockinette"),
        geometry("rib"),
        pattern_cell_energy,
        kkt_step_rows,
    }
    assert kernels_of("stockinette_free") - every_task == {geometry("stockinette_free"),
                                                           pattern_cell_energy,
                                                           kkt_step_rows}  # fmt: skip
    energy = kernels_of("garter", what="energy")
    assert energy == {geometry("garter"), pattern_cell_energy}
