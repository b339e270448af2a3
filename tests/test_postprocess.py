"""The post-processor: a results file reduced to per-sweep metrics, per-series
transitions and per-point regimes; tables; partial files; bad input."""

import csv
import subprocess
import sys

import h5py
import numpy as np
import pytest
from results_factory import write_results

from knitsweep.config import InputError
from knitsweep.quantities import SERIES_PARAMS
from knitsweep.report import phase_diagram, reduce_results
from knitsweep.report.tables import transitions_text
from knitsweep.stitches import TRANSLATION_CLASSES as CONTACT_CLASSES
from knitsweep.store.format import journal_dir
from knitsweep.store.journal import Entry, write_entry


def knitsweep(*args):
    return subprocess.run([sys.executable, "-m", "knitsweep", *args], capture_output=True,
                          text=True, timeout=300)  # fmt: skip


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def tiny(tiny_reference):
    return tiny_reference


@pytest.fixture
def synthetic(tmp_path):
    return write_results(tmp_path / "synthetic.h5")


def transition_of(red, k, direction):
    rows = [t for t in red.transitions if t["k_mN_per_mm2"] == k and t["direction"] == direction]
    assert len(rows) == 1
    return rows[0]


# ---- a real run ----------------------------------------------------------------------


def test_tiny_job_reduces(tiny):
    red = reduce_results(tiny)
    assert not red.partial and red.run_status == "complete"
    assert len(red.points) == 2 and len(red.sweeps) == 4 and not red.problems
    assert {(t["direction"], t["n_points"]) for t in red.transitions} == {("x", 2), ("y", 2)}
    for row in red.sweeps:
        assert row["delta_E_b"] >= 0.0 and row["delta_E_c"] >= 0.0
        gap = row["delta_E_c"] if row["direction"] == "x" else row["delta_E_b"]
        assert row["jamming_gap"] == gap
        assert row["aspect_ratio"] == pytest.approx(row["a_y0_mm"] / row["a_x0_mm"])
        assert row["max_strain"] > 0.0 and row["n_steps"] >= 2
        assert isinstance(row["has_linear_regime"], bool)
        assert row["regime"] in ("jammed_xy", "jammed_y_only", "jammed_x_only", "unjammed")
    assert {c.task_id for c in red.curves} == {r["task_id"] for r in red.sweeps}


def test_tiny_job_cli_tables(tiny, tmp_path):
    out = knitsweep("phase-diagram", str(tiny), "--out", str(tmp_path / "pd"), "--no-figures")
    assert out.returncode == 0, out.stderr
    assert "(L/r)_trans" in out.stdout and "PARTIAL" not in out.stdout
    assert "––" not in out.stdout  # a series without a jammed-regime fit shows one dash
    sweeps = read_csv(tmp_path / "pd" / "sweeps.csv")
    assert len(sweeps) == 4
    for col in ("task_id", "direction", "L_mm", "L_over_r", "k_mN_per_mm2", "Y_sec_N_per_mm",
                "sigma0_N_per_mm", "has_linear_regime", "sigma0_source", "sigma0_reason",
                "stress_discontinuous", "n_switching_drops", "delta_E_b_mJ", "delta_E_c_mJ",
                "aspect_ratio", "area_strain_min", "thickness_strain_max", "regime",
                "partial"):  # fmt: skip
        assert col in sweeps[0], col
    trans = read_csv(tmp_path / "pd" / "transitions.csv")
    for col in ("direction", *SERIES_PARAMS, "status", "L_over_r_trans", "bracket_lower",
                "bracket_upper", "fit_n_points", "fit_L_lo_mm", "fit_L_hi_mm",
                "fit_slope_mJ_per_mm", "fit_intercept_mJ", "fit_max_abs_residual_mJ",
                "fit_mean_abs_residual_mJ", "fit_mse_mJ2", "fit_zero_L_mm", "delta_L_over_r",
                "delta_L_mm", "threshold_mJ"):  # fmt: skip
        assert col in trans[0], col


# ---- known gaps ----------------------------------------------------------------------


def test_known_transitions(synthetic):
    red = reduce_results(synthetic)
    x = transition_of(red, 0.1, "x")
    assert x["status"] == "transition" and x["gap"] == "delta_E_c"
    assert x["L_over_r_trans"] == 23.0
    assert (x["bracket_lower"], x["bracket_upper"]) == (22.0, 23.0)
    assert x["L_trans_mm"] == pytest.approx(11.5)
    assert x["n_jammed"] == 3 and x["fit_n_points"] == 3 and x["n_missing"] == 1
    assert (x["fit_L_lo_mm"], x["fit_L_hi_mm"]) == pytest.approx((10.0, 11.0))
    assert x["fit_slope_mJ_per_mm"] == pytest.approx(-4e-4, rel=1e-9)  # per mm: divided by r
    assert x["fit_intercept_mJ"] == pytest.approx(4.5e-3, rel=1e-9)
    assert x["fit_zero_L_over_r"] == pytest.approx(22.5, rel=1e-9)
    assert x["fit_zero_L_mm"] == pytest.approx(11.25, rel=1e-9)
    assert x["delta_L_over_r"] == pytest.approx(0.5, rel=1e-8)
    assert x["delta_L_mm"] == pytest.approx(0.25, rel=1e-8)
    assert x["fit_max_abs_residual_mJ"] < 1e-12 and x["fit_tolerance_mJ"] == 5e-5
    y = transition_of(red, 0.1, "y")
    assert (y["L_over_r_trans"], y["bracket_lower"], y["gap"]) == (24.0, 23.0, "delta_E_b")
    assert y["delta_L_over_r"] == pytest.approx(0.5, rel=1e-8)
    assert transition_of(red, 1.0, "x")["delta_L_over_r"] == pytest.approx(0.2, rel=1e-8)
    never = transition_of(red, 1.0, "y")
    assert never["status"] == "jammed_throughout" and never["L_over_r_trans"] is None
    assert never["bracket_lower"] == 24.0
    text = transitions_text(red)  # the fit's L range; a series without a fit shows one dash
    assert "10.00–11.00" in text and "––" not in text


def test_threshold_moves_the_transition(synthetic):
    # 1e-5 at L/r = 23 is jammed under a threshold of 5e-6
    x = transition_of(reduce_results(synthetic, threshold=5e-6), 0.1, "x")
    assert x["L_over_r_trans"] == 24.0 and x["threshold"] == 5e-6


def test_regimes_per_point(synthetic):
    red = reduce_results(synthetic)
    got = {r["L_over_r"]: r["regime"] for r in red.points if r["k_mN_per_mm2"] == 0.1}
    assert got == {19.0: None, 20.0: "jammed_xy", 21.0: "jammed_xy", 22.0: "jammed_xy",
                   23.0: "jammed_y_only", 24.0: "unjammed"}  # fmt: skip
    k1 = {r["L_over_r"]: r["regime"] for r in red.points if r["k_mN_per_mm2"] == 1.0}
    assert k1[24.0] == "jammed_y_only" and k1[23.0] == "jammed_xy"


def test_gaps_and_metrics_per_sweep(synthetic):
    red = reduce_results(synthetic)
    for row in red.sweeps:
        from results_factory import gap

        expected = gap(row["k_mN_per_mm2"], row["direction"], row["L_over_r"])
        assert row["jamming_gap"] == pytest.approx(expected, rel=1e-9, abs=1e-15)
        assert row["jammed"] == (expected >= 5e-5)
        assert row["Y_sec_N_per_mm"] is not None and row["Y_sec_N_per_mm"] > 0.0
        widen_x = row["F_self_x_N"] + row["F_same_row_x_N"]
        column_y = row["F_nn_column_y_N"] + row["F_nnn_column_y_N"]
        assert row["generalised_force_ratio_xy"] == pytest.approx(abs(widen_x / column_y))
        assert row["generalised_force_ratio_xy"] != pytest.approx(abs(row["F_x_N"] / row["F_y_N"]))
        assert row["F_self_x_N"] == pytest.approx(0.02)
        # the paper's ratio comes from the pair forces of the stored zero-force state
        pair_x = row["pair_F_self_x_N"] + row["pair_F_same_row_x_N"]
        pair_y = row["pair_F_nn_column_y_N"] + row["pair_F_nnn_column_y_N"]
        assert row["pair_F_x_self_row_N"] == pytest.approx(pair_x)
        assert row["force_ratio_xy"] == pytest.approx(abs(pair_x / pair_y))
        # synthetic curves are smooth and won by one start: σ0 on the envelope, no drops
        assert row["sigma0_source"] == "envelope" and not row["stress_discontinuous"]
    unjammed_y = [r for r in red.sweeps if r["direction"] == "y" and not r["jammed"]]
    assert unjammed_y and all(not r["min_area_at_zero_force"] for r in unjammed_y)


def test_failed_and_not_knittable_are_listed(synthetic, tmp_path):
    report = phase_diagram(synthetic, tmp_path / "pd", figures=False)
    red = report.reduction
    assert {(p["kind"], p["status"]) for p in red.problems} == {
        ("point", "not_knittable"), ("sweep", "not_knittable")}  # fmt: skip
    assert len(red.problems) == 6
    problems = read_csv(tmp_path / "pd" / "problems.csv")
    assert len(problems) == 6 and problems[0]["message"]
    lines = report.lines()
    assert sum(line.startswith("not_knittable: sweep") for line in lines) == 4


def test_failed_sweep_without_arrays(tmp_path):
    path = write_results(tmp_path / "f.h5", ks=(0.1,), not_knittable_L=None)
    with h5py.File(path, "a") as f:
        g = f["sweeps/s0.1_21_x"]
        for name in list(g):
            del g[name]
        g.attrs["status"] = "failed"
        g.attrs["message"] = "failed: timeout: task exceeded its wall-time budget"
        f["sweeps/s0.1_22_y"]["strain"][3] = 0.0  # not increasing: cannot be analysed
    red = reduce_results(path)
    assert {p["task_id"]: p["status"] for p in red.problems} == {
        "s0.1_21_x": "failed", "s0.1_22_y": "done"}  # fmt: skip
    assert "not analysable" in next(p for p in red.problems if p["status"] == "done")["message"]
    assert transition_of(red, 0.1, "x")["n_missing"] == 1


def test_contact_forces_absent(tmp_path):
    path = write_results(tmp_path / "nf.h5", contact_forces=False)
    red = reduce_results(path)
    assert all(r["force_ratio_xy"] is None for r in red.sweeps + red.points)
    assert all(r["generalised_force_ratio_xy"] is None for r in red.sweeps + red.points)
    assert all(r[f"F_{CONTACT_CLASSES[0]}_x_N"] is None for r in red.sweeps)
    assert all(r[f"pair_F_{CONTACT_CLASSES[0]}_x_N"] is None for r in red.points)


# ---- partial files -------------------------------------------------------------------


def test_running_file_is_partial(tmp_path):
    path = write_results(tmp_path / "run.h5", run_status="running")
    report = phase_diagram(path, tmp_path / "pd", figures=False)
    assert report.reduction.partial
    assert report.lines()[0].startswith("PARTIAL (run_status 'running'")
    assert all(r["partial"] == "true" for r in read_csv(tmp_path / "pd" / "transitions.csv"))
    assert all(r["partial"] == "true" for r in read_csv(tmp_path / "pd" / "sweeps.csv"))


def test_missing_tasks_and_journal_entries(tmp_path):
    path = write_results(tmp_path / "j.h5", ks=(0.1,), not_knittable_L=None)
    with h5py.File(path, "a") as f:
        f.attrs["n_sweeps"] = 12  # two sweeps more than the file holds
        group = f["sweeps/s0.1_24_y"]
        meta = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in group.attrs.items()}
        record = {k: group[k][()] for k in group}
        del f["sweeps/s0.1_24_y"]
    journal = journal_dir(path)
    journal.mkdir()
    entry = Entry("sweeps", "s0.1_24_y", record, meta)  # a result not yet checkpointed
    write_entry(journal, entry)
    red = reduce_results(path)
    assert red.partial and "15 of 17 tasks present" in red.partial_reason
    assert any(r["task_id"] == "s0.1_24_y" for r in red.sweeps)
    assert transition_of(red, 0.1, "y")["L_over_r_trans"] == 24.0


# ---- bad input -----------------------------------------------------------------------


def test_bad_threshold(synthetic):
    with pytest.raises(InputError, match="threshold"):
        reduce_results(synthetic, threshold=0.0)


@pytest.mark.parametrize("kind", ["missing", "not_hdf5", "schema", "attributes", "threshold"])
def test_bad_input_is_one_line_and_exit_2(tmp_path, kind):
    path = tmp_path / "bad.h5"
    args = []
    if kind == "not_hdf5":
        path.write_text("not an HDF5 file\n")
    elif kind == "schema":
        with h5py.File(path, "w") as f:
            f.attrs["schema_version"] = 99
    elif kind == "attributes":
        with h5py.File(path, "w") as f:
            f.attrs["schema_version"] = 1
            f.create_group("sweeps/abc").attrs["status"] = "done"
    elif kind == "threshold":
        write_results(path)
        args = ["--threshold", "-1"]
    out = knitsweep("phase-diagram", str(path), "--out", str(tmp_path / "pd"), *args)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), out.stderr
    fragment = {"missing": "no such results file", "not_hdf5": "not a readable HDF5",
                "schema": "schema_version 99", "attributes": "lacks attribute",
                "threshold": "threshold"}[kind]  # fmt: skip
    assert fragment in lines[0]


def test_cli_json(synthetic, tmp_path):
    import json

    out = knitsweep("phase-diagram", str(synthetic), "--out", str(tmp_path / "pd"),
                    "--no-figures", "--json")  # fmt: skip
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["partial"] is False and len(got["transitions"]) == 4 and len(got["problems"]) == 6


def test_no_matplotlib_at_import():
    code = ("import sys, knitsweep.cli, knitsweep.report, knitsweep.report.render; "
            "print('matplotlib' in sys.modules)")  # fmt: skip
    out = subprocess.run([sys.executable, "-W", "error", "-c", code], capture_output=True,
                         text=True, timeout=120)  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_adaptive_series_bracket_is_reported(tmp_path):
    path = write_results(tmp_path / "a.h5", ks=(0.1,), not_knittable_L=None)
    with h5py.File(path, "a") as f:
        g = f.create_group("series/s0.1x")
        for key, value in {"status": "done", "direction": "x", "k_mN_per_mm2": 0.1,
                           "B_mN_mm2": 90.0, "r_core_mm": 0.22, "r_mm": 0.5, "p": 2.4,
                           "regularization_mN_mm4": 2.0, "twist_bound": 0.9,
                           "bracket_lower": 22.9, "bracket_upper": 23.0}.items():  # fmt: skip
            g.attrs[key] = value
    red = reduce_results(path)
    x = transition_of(red, 0.1, "x")
    assert (x["adaptive_status"], x["adaptive_bracket_upper"]) == ("done", 23.0)
    # the same (L/r)_trans as found here (the one note: a synthetic file has no checksums)
    assert [n for n in red.notes if "without checksums" not in n] == []
    assert len(red.points) == 5 and len(red.sweeps) == 10 and not red.problems
