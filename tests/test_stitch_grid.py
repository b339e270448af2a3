"""Several stitches in one job (``[grid] stitch = [...]``): every point for every
stitch, a ``stitch`` column in every table, and series (transitions, regimes, the
adaptive search, figure panels) that never mix two stitches."""

import h5py
import pytest
from conftest import TINY, stored_meta

from knitsweep import service
from knitsweep.analysis.transitions import transition
from knitsweep.report import reduce_results
from knitsweep.report.results import load
from knitsweep.report.tables import transitions_text
from knitsweep.service.adaptive import Refiner
from knitsweep.service.jobs import JobSpec, load_job, plan

STITCHES = ("stockinette", "stockinette_free")  # the free yarn holds the stockinette ansatz


def _jobs(directory):
    """The tiny job (draft numerics, k = 0.1) at L = 11.3 and 12.0 mm for stockinette,
    and for both stitches: 2 x 2 points, 8 sweeps, ~15 s serially (the free yarn's
    tasks take 1-3 s each)."""
    alone = TINY.read_text().replace("[11.4, 12.0]", "[11.3, 12.0]")
    both = alone.replace("k_mN_per_mm2 = 0.1", 'k_mN_per_mm2 = 0.1\nstitch = ["stockinette", '
                         '"stockinette_free"]')  # fmt: skip
    (directory / "alone.toml").write_text(alone)
    (directory / "two.toml").write_text(both)
    return directory / "alone.toml", directory / "two.toml"


@pytest.fixture(scope="module")
def two(tmp_path_factory):
    """The stockinette job run, then grown into both stitches in the same file: only
    the free yarn's tasks are new."""
    d = tmp_path_factory.mktemp("two_stitches")
    alone, job = _jobs(d)
    out = d / "two.h5"
    service.run(alone, out, executor="serial", show_progress=False)
    summary = service.run(job, out, executor="serial", show_progress=False)
    assert (summary.total, summary.skipped, summary.counts["failed"]) == (12, 6, 0)
    with h5py.File(out) as f:
        assert f.attrs["grown_from"] == load_job(alone).job_hash
    return job, out


def test_every_point_is_computed_and_recorded_per_stitch(two):
    job_path, out = two
    job = load_job(job_path)
    points, sweeps = plan(job)
    stored, stored_sweeps = stored_meta(out, "points"), stored_meta(out, "sweeps")
    assert set(stored) == {p.task_id for p in points}
    assert set(stored_sweeps) == {s.task_id for s in sweeps}
    for p in points:  # the default stitch is left out of the attributes, as it always was
        assert stored[p.task_id].get("stitch", "stockinette") == p.params.stitch
    # the stockinette tasks are those of the stockinette-only job with the same grid
    alone = JobSpec.model_validate({**job.model_dump(), "grid": {
        **job.grid.model_dump(), "stitch": None}})  # fmt: skip
    assert {p.task_id for p in plan(alone)[0]} == {
        p.task_id for p in points if p.params.stitch == "stockinette"}  # fmt: skip
    assert service.status(out, by="stitch")["by"]["stitch"].keys() == set(STITCHES)


def test_tables_carry_the_stitch_and_transitions_are_per_stitch(two):
    _, out = two
    res = load(out)
    for name in ("points", "sweeps", "curves", "transitions"):
        table = getattr(res, name)
        assert set(table["stitch"]) == set(STITCHES), name
    t = res.transitions
    assert sorted(zip(t["stitch"], t["direction"], strict=True)) == [
        (s, d) for s in STITCHES for d in "xy"]  # fmt: skip
    assert (t["n_points"] == 2).all()  # each stitch's own two sweeps, never the other's
    for row in t.to_dict("records"):  # the transition of that stitch's sweeps alone
        own = res.sweeps.query(f"stitch == '{row['stitch']}' and direction == "
                               f"'{row['direction']}'").sort_values("L_over_r")  # fmt: skip
        alone = transition(list(own["L_over_r"]), list(own["jamming_gap_mJ"]), res.threshold)
        assert row["status"] == alone.status
        assert row["L_over_r_trans"] == pytest.approx(alone.L_over_r_trans)
    stockinette = t[t["stitch"] == "stockinette"]
    assert (stockinette["status"] == "transition").all()  # as the tiny job: 11.3 jams, 12 not
    assert set(res.select(stitch="stockinette_free").points["stitch"]) == {"stockinette_free"}
    red = res.reduction
    assert red.varying == ("stitch",) and "stitch" not in red.constants
    text = transitions_text(red)
    assert text.splitlines()[1].split()[:2] == ["dir", "stitch"]
    assert "stockinette_free" in text


def test_a_stockinette_study_names_its_stitch_only_in_the_column(tiny_reference):
    red = reduce_results(tiny_reference)
    assert {r["stitch"] for r in red.points + red.sweeps + red.transitions} == {"stockinette"}
    assert "stitch" not in red.varying and "stitch" not in red.constants
    assert "stitch" not in transitions_text(red)
    assert set(load(tiny_reference).curves["stitch"]) == {"stockinette"}


def test_figures_name_the_stitch_of_each_series(two):
    from knitsweep.report.fig_energy import fig3_energy_gaps, fig4c_phase_diagram
    from knitsweep.report.plotting import label_of, series_keys, style

    _, out = two
    red = reduce_results(out)
    keys = series_keys(red)
    assert [k[0] for k in keys] == list(STITCHES)
    assert [label_of(red, k) for k in keys] == [f"stitch = {s}" for s in STITCHES]
    notes: list[str] = []
    with style():
        fig = fig3_energy_gaps(red, notes)
        titles = [ax.get_title() for ax in fig.axes if ax.get_title()]
        assert any("stitch = stockinette_free" in t for t in titles)
        assert any(t.endswith("stitch = stockinette") for t in titles)
        fig = fig4c_phase_diagram(red, notes)
    # a panel for each stitch's series (once only the first one's, with a note)
    assert [ax.get_title() for ax in fig.axes] == [f"stitch = {s}" for s in STITCHES]
    assert not any("fig4c" in n for n in notes)


def test_xarray_has_a_stitch_dimension(two):
    pytest.importorskip("xarray")
    _, out = two
    ds = load(out).to_xarray()
    assert list(ds["stitch"].values) == list(STITCHES)
    assert ds["jamming_gap_mJ"].dims[:2] == ("direction", "stitch")
    assert ds["L_over_r_trans"].sizes == {"direction": 2, "stitch": 2}


def test_the_adaptive_search_brackets_each_stitch_separately():
    job = JobSpec(schema_version=1, name="a", mode="adaptive", directions=["x"],
                  grid={"L_mm": [11.0, 12.0], "k_mN_per_mm2": 0.1, "stitch": list(STITCHES)},
                  adaptive={"tolerance_mm": 0.1})  # fmt: skip
    refiner = Refiner(job)
    assert sorted(s["base"].stitch for s in refiner.series.values()) == sorted(STITCHES)
    crossing = {"stockinette": 11.55, "stockinette_free": 11.25}

    def observe(stitch, L):
        meta = {**job.points()[0].model_dump(), "stitch": stitch, "L_mm": L, "direction": "x",
                "status": "done", "jamming_gap": 1e-3 if L < crossing[stitch] else 0.0}  # fmt: skip
        if stitch == "stockinette":
            del meta["stitch"]  # as stored: the default stitch is not written
        refiner.observe(meta)

    for stitch in STITCHES:
        for L in (11.0, 12.0):
            observe(stitch, L)
    for _ in range(10):
        pending = [(k, s) for k, s in refiner.states() if not s.finished]
        if not pending:
            break
        for key, state in pending:
            params, _ = refiner.point_params(key, state.next_L)
            observe(params.stitch, params.L_mm)
    brackets = {refiner.series[k]["base"].stitch: (s.lo, s.hi) for k, s in refiner.states()}
    for stitch, (lo, hi) in brackets.items():
        assert lo < crossing[stitch] <= hi and hi - lo <= 0.1 + 1e-9, stitch
    metas = [refiner.series_meta(k, s) for k, s in refiner.states()]
    assert sorted(m.get("stitch", "stockinette") for m in metas) == sorted(STITCHES)


def test_progress_lines_name_the_stitch_when_a_job_has_several(two):
    from knitsweep.service.master import varying_parameters
    from knitsweep.service.progress import task_line

    job_path, _ = two
    job = load_job(job_path)
    varying = varying_parameters(job)
    assert varying == ("stitch", "L_mm")
    line = task_line("point", job.points()[-1], None, "done", 1.0, varying)
    assert "L=12 stitch=stockinette_free" in line
    alone = JobSpec(schema_version=1, name="t", grid={"L_mm": [11.0, 12.0]})
    assert varying_parameters(alone) == ("L_mm",)


def test_the_patterns_figure_sets_the_stitches_side_by_side(two, tiny_reference):
    """figP_patterns: a tick per stitch with its x and y transitions (the marker at
    (L/r)_trans, the bar down to the bracket's lower end), each stitch's shift against the
    free yarn, a Y_sec curve per stitch and direction, an aspect-ratio curve per stitch; a
    one-stitch study skips it."""
    from knitsweep.report.fig_patterns import figP_patterns
    from knitsweep.report.plotting import SkipFigure, style

    _, out = two
    red = reduce_results(out)
    with style():
        fig = figP_patterns(red, [])
        ax_t, _shift, ax_y, ax_a = fig.axes[:4]  # (b): each stitch against the free yarn
        assert [t.get_text() for t in ax_t.get_xticklabels()] == list(STITCHES)
        drawn = sorted(round(float(c.lines[0].get_ydata()[0]), 9) for c in ax_t.containers)
        want = sorted(round(t["L_over_r_trans"], 9) for t in red.transitions
                      if t["status"] == "transition")  # fmt: skip
        assert drawn == want and len(want) >= 2  # stockinette's two at least
        beyond = [t for t in red.transitions if t["status"] != "transition"]
        triangles = [ln for ln in ax_t.get_lines() if ln.get_marker() in ("^", "v")]
        assert len(triangles) == len(beyond)
        assert len(ax_y.get_lines()) == 2 * len(STITCHES)
        for line in ax_a.get_lines():
            assert list(line.get_xdata()) == sorted(line.get_xdata())
        assert len(ax_a.get_lines()) == len(STITCHES)
        with pytest.raises(SkipFigure, match="two or more stitch patterns"):
            figP_patterns(reduce_results(tiny_reference), [])
