"""The tables of ``knitsweep.load`` as a newcomer meets them: no columns that nothing
filled, no object columns of None, units in ``attrs``, each task's seconds, a refusal in
one line for a column or value that is not there, task ids from ``status --tasks``, and
the example that plots every stitch."""

import json
import subprocess
import sys
from pathlib import Path

import pytest
from results_factory import write_results

import knitsweep
from knitsweep.errors import InputError
from knitsweep.report.results import SelectionError, stored_only
from knitsweep.store.read import iter_entries

ROOT = Path(__file__).resolve().parents[1]
TABLES = ("points", "sweeps", "curves", "transitions", "problems")


@pytest.fixture(scope="module")
def patterns_file(tmp_path_factory):
    """Stockinette and garter series, contact forces not stored."""
    path = tmp_path_factory.mktemp("patterns") / "patterns.h5"
    return write_results(path, contact_forces=False, stitches=("stockinette", "garter"))


def test_columns_no_task_stored_are_left_out_unless_asked(patterns_file):
    res = knitsweep.load(patterns_file)
    for name in TABLES:
        table = getattr(res, name)
        assert not [c for c in table.columns if stored_only(c) and table[c].isna().all()], name
        assert not [c for c in table.columns if table[c].dtype == object], name
    assert not any(c.startswith(("F_", "pair_F_")) for c in res.points.columns)
    assert "packing_fraction" in res.points.columns  # stored by these tasks: kept
    full = knitsweep.load(patterns_file, all_columns=True)
    assert {"F_self_x_N", "F_mirrored_x_N", "pair_F_nn_column_y_N"} <= set(full.points.columns)
    assert full.points["F_self_x_N"].dtype == float and full.points["F_self_x_N"].isna().all()
    assert not [c for c in full.points.columns if full.points[c].dtype == object]
    assert len(full.points.columns) > len(res.points.columns)
    assert full.select(stitch="garter").all_columns  # a selection keeps the choice


def test_stored_forces_are_kept_and_none_means_nan(tmp_path):
    res = knitsweep.load(write_results(tmp_path / "f.h5", stitches=("stockinette", "garter")))
    points = res.points
    done = points["status"] == "done"
    assert points.loc[done, "F_self_x_N"].notna().all() and points["F_self_x_N"].dtype == float
    # the stockinette classes are empty for garter rows, the mirrored one for stockinette's
    garter = points["stitch"] == "garter"
    assert points.loc[garter & done, "F_nn_column_x_N"].isna().all()
    assert points.loc[garter & done, "F_mirrored_x_N"].notna().all()
    assert points.loc[~garter, "F_mirrored_x_N"].isna().all()
    assert points["F_nn_column_x_N"].dtype == float
    assert points["generalised_force_ratio_xy"].dtype == float  # None for garter: NaN
    sweeps = res.sweeps
    assert sweeps["first_switching_drop_strain"].dtype == float
    assert sweeps["has_linear_regime"].dtype in (bool, "boolean")


def test_units_are_in_attrs_as_well_as_in_the_names(patterns_file):
    res = knitsweep.load(patterns_file)
    units = res.sweeps.attrs["units"]
    assert units["Y_sec_N_per_mm"] == "N/mm" and units["L_mm"] == "mm"
    assert units["k_mN_per_mm2"] == "mN/mm2" and units["aspect_ratio"] == "1"
    assert units["direction"] == "" and set(units) == set(res.sweeps.columns)
    assert res.curves.attrs["units"]["stress_N_per_mm"] == "N/mm"
    assert res.points.attrs["long_names"]["L_mm"] == "yarn length per stitch L"
    assert res.select(direction="x").sweeps.attrs["units"]["delta_E_c_mJ"] == "mJ"


def test_each_tasks_seconds_are_in_the_tables(tiny_reference):
    res = knitsweep.load(tiny_reference)
    stored = {e.task_id: e.meta["seconds"] for e in iter_entries(tiny_reference)}
    for table in (res.points, res.sweeps):
        assert table["seconds"].dtype == float
        for tid, seconds in zip(table["task_id"], table["seconds"], strict=True):
            assert seconds == stored[tid] > 0.0
    assert res.sweeps.attrs["units"]["seconds"] == "s"


@pytest.mark.parametrize(
    ("where", "fragment"),
    [
        (
            {"stitch": "purl"},
            "no row has stitch = 'purl'; the results hold garter, stockinette "
            "(knitsweep's stitches: stockinette, stockinette_free, garter",
        ),
        ({"stitch": "rib"}, "no row has stitch = 'rib'; the results hold garter, stockinette"),
        ({"L": 11.7}, "no column L; did you mean L_mm?"),
        ({"k": 0.1}, "no column k; did you mean k_mN_per_mm2?"),
        ({"L_mm": 11.7}, "no row has L_mm = 11.7; the results hold 9.5, 10, 10.5, 11, 11.5, 12"),
        ({"direction": "z"}, "no row has direction = 'z'; the results hold x, y"),
        ({"L_mm": [10.0, 11.7]}, "no row has L_mm = 11.7"),
        ({"colour": "red"}, "no column colour (parameters: stitch, L_mm, k_mN_per_mm2"),
    ],
)
def test_select_refuses_what_is_not_there_in_one_line(patterns_file, where, fragment):
    res = knitsweep.load(patterns_file)
    with pytest.raises(SelectionError) as e:
        res.select(**where)
    assert isinstance(e.value, KeyError) and isinstance(e.value, InputError)
    message = str(e.value)
    assert fragment in message and "\n" not in message and len(message) < 200, message
    assert message.startswith("select: ")


def test_select_still_selects(patterns_file):
    res = knitsweep.load(patterns_file)
    garter = res.select(stitch="garter", L_mm=[10.0, 10.5])
    assert set(garter.points["stitch"]) == {"garter"}
    assert set(garter.sweeps["L_mm"]) == {10.0, 10.5}
    assert set(res.select(direction="x").sweeps["direction"]) == {"x"}


def test_status_tasks_lists_every_id_with_its_parameters(tiny_reference, tmp_path):
    out = subprocess.run([sys.executable, "-m", "knitsweep", "status", str(tiny_reference),
                          "--tasks"], capture_output=True, text=True, timeout=300)  # fmt: skip
    assert out.returncode == 0, out.stderr
    ids = {e.task_id: e for e in iter_entries(tiny_reference)}
    listed = [line.split() for line in out.stdout.splitlines() if line.startswith("  point")
              or line.startswith("  sweep")]  # fmt: skip
    assert len(listed) == len(ids) == 6
    for words in listed:
        tid = words[1] if words[0] == "point" else words[2]
        e = ids[tid]
        assert f"L={e.meta['L_mm']:g}" in words and words[-1] == "s"
        assert ("done" in words) and (words[0] == e.kind[:-1])
    assert "render --results" in out.stdout
    js = json.loads(subprocess.run([sys.executable, "-m", "knitsweep", "status",
                                    str(tiny_reference), "--tasks", "--json"],
                                   capture_output=True, text=True, timeout=300).stdout)  # fmt: skip
    assert {t["task_id"] for t in js["tasks"]} == set(ids)
    sweep = next(t for t in js["tasks"] if t["kind"] == "sweep")
    assert sweep["direction"] in ("x", "y") and sweep["point_id"] in ids
    assert sweep["seconds"] == ids[sweep["task_id"]].meta["seconds"]
    # an id from the listing draws
    point = next(t["task_id"] for t in js["tasks"] if t["kind"] == "point")
    drawn = subprocess.run([sys.executable, "-m", "knitsweep", "render", "--results",
                            str(tiny_reference), "--task", point, "--out",
                            str(tmp_path / "p.png"), "--pixels", "200", "--cells", "1"],
                           capture_output=True, text=True, timeout=300)  # fmt: skip
    assert drawn.returncode == 0, drawn.stderr


def test_the_example_plots_every_stitch(patterns_file, tmp_path, monkeypatch, capsys):
    import runpy

    import matplotlib.pyplot as plt

    monkeypatch.setattr(sys, "argv", ["stress_strain_by_L.py", str(patterns_file), "--out",
                                      str(tmp_path / "ss.png")])  # fmt: skip
    plt.close("all")
    runpy.run_path(str(ROOT / "examples" / "stress_strain_by_L.py"), run_name="__main__")
    assert (tmp_path / "ss.png").exists() and "garter" in capsys.readouterr().out
    (fig,) = [plt.figure(n) for n in plt.get_fignums()]
    titles = {ax.get_title() for ax in fig.axes}
    for stitch in ("garter", "stockinette"):
        for direction in "xy":
            # k varies in this file: the panel says which value it shows
            assert f"{stitch}, pulled in {direction}\n(k_mN_per_mm2 = 0.1)" in titles, titles
        # each panel draws its stitch's curves: one per L
        ax = next(a for a in fig.axes if a.get_title().startswith(stitch))
        assert len(ax.get_lines()) == 5
    plt.close("all")
