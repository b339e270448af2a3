"""Post-processing tier: a series whose refinement failed is never shown as a transition
(issue 34): ``phase-diagram``'s table and CSV, the patterns figure, the HTML report and
``status`` say which point failed and why, and the report's headline counts failures."""

import csv

import pytest
from results_factory import R_MM, write_results

from knitsweep.report.reduce import reduce_results
from knitsweep.report.series import mark_failed

FAILED_L = 10.75  # L/r = 21.5: inside the jammed run of every series, before any transition


@pytest.fixture(scope="module")
def failed_file(tmp_path_factory):
    return write_results(tmp_path_factory.mktemp("failed") / "failed.h5", failed_L=FAILED_L)


def test_a_failed_point_before_the_transition_leaves_no_transition(failed_file):
    red = reduce_results(failed_file)
    assert red.transitions and all(t["status"].startswith(f"failed: point L={FAILED_L:g} mm (")
                                   for t in red.transitions)  # fmt: skip
    for t in red.transitions:
        assert "no start converged" in t["status"] and t["L_over_r_trans"] is None
        assert t["delta_L_over_r"] is None and "length constraint" in t["failure"]
    assert all(tr.status == "failed" for tr in red.transition_of.values())
    assert all(p["regime"] is None for p in red.points)  # no regime from a failed series


def test_a_failed_point_beyond_the_transition_does_not_hide_it(tmp_path):
    red = reduce_results(write_results(tmp_path / "late.h5", failed_L=25.5 * R_MM))
    by = {(t["k_mN_per_mm2"], t["direction"]): t for t in red.transitions}
    assert by[(0.1, "x")]["status"] == "transition" and by[(0.1, "x")]["L_over_r_trans"] == 23.0
    # jammed at every sampled L: a failure anywhere could hold its transition
    assert by[(1.0, "y")]["status"].startswith("failed: point L=12.75 mm")


def test_the_text_table_and_the_csv_mark_the_failed_series(failed_file, tmp_path):
    from knitsweep.report.results import Results
    from knitsweep.report.tables import transitions_text, write_tables

    red = reduce_results(failed_file)
    text = transitions_text(red)
    assert text.count(f"failed: point L={FAILED_L:g} mm") == len(red.transitions)
    write_tables(Results(red), tmp_path / "out")
    with open(tmp_path / "out" / "transitions.csv") as f:
        rows = list(csv.DictReader(f))
    assert rows and all(r["status"].startswith("failed: point L=10.75 mm") for r in rows)
    assert all(r["L_over_r_trans"] == "" for r in rows)


def test_the_patterns_figure_marks_a_failed_series(tmp_path):
    from knitsweep.report.fig_patterns import figP_patterns

    ok = reduce_results(write_results(tmp_path / "ok.h5", ks=(0.1,),
                                      stitches=("stockinette", "stockinette_free")))  # fmt: skip
    notes: list[str] = []
    fig = figP_patterns(ok, notes)
    assert not any("failed" in n for n in notes)
    assert "×: failed" not in fig.axes[0].get_title()
    bad = reduce_results(write_results(tmp_path / "bad.h5", ks=(0.1,), failed_L=FAILED_L,
                                       stitches=("stockinette", "stockinette_free")))  # fmt: skip
    notes = []
    fig = figP_patterns(bad, notes)
    assert "×: failed" in fig.axes[0].get_title()
    assert sum(f"failed: point L={FAILED_L:g} mm" in n for n in notes) == 4  # 2 stitches, x and y
    assert any("no stockinette_free transition" in n for n in notes)


def test_the_report_headline_counts_failures(failed_file, tmp_path):
    from knitsweep.report.html import report_html
    from knitsweep.report.results import load

    page = report_html(load(failed_file))
    # per k: the failed point and its two sweeps; every series lost its transition
    assert "Every run is complete, but 6 of" in page and "tasks failed and 4 of 4 series" in page
    assert "no task failed" not in page
    clean = report_html(load(write_results(tmp_path / "clean.h5")))
    assert "every run is complete; no task failed" in clean


def test_status_says_which_point_failed_and_why(failed_file):
    from knitsweep import service

    s = service.status(failed_file)
    assert s["failed"] == 6 and len(s["failures"]) == 6
    assert any(f.startswith("sweep ") and f"x, L = {FAILED_L:g} mm, stitch = stockinette, k = 0.1"
               in f and "length constraint missed" in f for f in s["failures"])  # fmt: skip


def test_an_adaptive_series_that_failed_is_marked_with_its_message():
    rows = [{"direction": "x", "stitch": "stockinette", "k_mN_per_mm2": 0.1, "B_mN_mm2": 90.0,
             "r_core_mm": 0.325, "r_mm": 0.74, "p": 2.4, "regularization_mN_mm4": 2.0,
             "twist_bound": 0.9, "status": "transition", "L_over_r_trans": 15.5,
             "L_trans_mm": 11.47, "adaptive_status": "failed",
             "adaptive_message": "bracket still 0.04 mm after 40 refinements"}]  # fmt: skip
    from knitsweep.analysis.transitions import transition
    from knitsweep.report.series import series_key

    key = (series_key(rows[0]), "x")
    trans = {key: transition([15.0, 15.5], [1e-4, 0.0])}
    mark_failed(trans, rows, [])
    assert rows[0]["status"] == "failed: bracket still 0.04 mm after 40 refinements"
    assert rows[0]["L_over_r_trans"] is None and trans[key].status == "failed"


def test_the_refiner_names_the_failed_point_of_a_series(data_dir):
    from knitsweep.service.adaptive import Refiner
    from knitsweep.service.jobs import load_job

    job = load_job(data_dir / "jobs" / "tiny_adaptive.toml")
    refiner = Refiner(job)
    base = next(iter(job.points()))
    for L in sorted(job.grid.axes()["L_mm"]):
        meta = {**base.model_copy(update={"L_mm": L}).model_dump(mode="json"), "direction": "x"}
        failed = L == min(job.grid.axes()["L_mm"])
        refiner.observe(meta | ({"status": "failed", "message": "zero-force state: no start "
                                 "converged; best (Init_1): …"} if failed else
                                {"status": "done", "jamming_gap": 1e-3}))  # fmt: skip
    key = refiner.key(base, "x")
    state = dict(refiner.states())[key]
    assert state.status == "failed"
    message = refiner.series_meta(key, state)["message"]
    assert message.startswith("failed: point L=")
    assert "(zero-force state: no start converged)" in message


def test_patterns_are_quoted_against_the_free_stockinette_yarn(tmp_path):
    """Every transition row carries its shift against the free stockinette yarn and the
    ansatz of the same series (the synthetic stitches share their data: shifts 0); the
    text table shows them; without a free yarn there is nothing to quote against."""
    from pathlib import Path

    from knitsweep.report.tables import transitions_text
    from knitsweep.service.jobs import load_job

    red = reduce_results(write_results(tmp_path / "p.h5", ks=(0.1,),
                                       stitches=("stockinette", "stockinette_free", "rib")))  # fmt: skip
    assert {t["stitch"] for t in red.transitions} == {"stockinette", "stockinette_free", "rib"}
    for t in red.transitions:
        assert t["shift_vs_free"] == 0.0 and t["shift_vs_ansatz"] == 0.0
    assert "vs free" in transitions_text(red) and "vs ansatz" in transitions_text(red)
    alone = reduce_results(write_results(tmp_path / "a.h5", ks=(0.1,), stitches=("rib",)))
    assert all(t["shift_vs_free"] is None for t in alone.transitions)
    assert "vs free" not in transitions_text(alone)
    job = load_job(Path(__file__).parents[1] / "jobs" / "patterns_k0.1.toml")
    assert {"stockinette", "stockinette_free"} <= set(job.stitches)
