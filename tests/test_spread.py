"""``[starts] spread = N``: each point also relaxed from N - 1 copies of its winning start
and each sweep run from N - 1 copies of its zero-force state, perturbed 1e-15 relative
(service/spread.py); the spreads in the tables, and a verdict within its spread of the
threshold said so in the sweeps and transitions tables and the text summary. Off (no
column, no extra relaxation) unless the job asks."""

import numpy as np
import pytest
from conftest import TINY

import knitsweep as ks
from knitsweep import service
from knitsweep.errors import InputError
from knitsweep.report.reduce import reduce_results
from knitsweep.report.tables import transitions_text
from knitsweep.service.jobs import load_job

POINT_COLUMNS = ("E_rest_spread_mJ", "a_x0_spread_mm", "a_y0_spread_mm")
SWEEP_COLUMNS = ("delta_E_b_spread_mJ", "delta_E_c_spread_mJ", "Y_sec_spread_N_per_mm")


def _job(tmp_path, line):
    path = tmp_path / "spread.toml"
    path.write_text(TINY.read_text().replace("[starts]\n", f"[starts]\n{line}\n"))
    return path


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("spread")
    out = {}
    for n in (1, 3):
        job = tmp / f"spread{n}.toml"
        job.write_text(TINY.read_text().replace("[starts]\n", f"[starts]\nspread = {n}\n"))
        out[n] = tmp / f"spread{n}.h5"
        service.run(job, out[n], executor="serial", show_progress=False)
    return out


def test_the_spreads_are_in_the_tables(runs):
    res = ks.load(runs[3])
    for c in POINT_COLUMNS:
        assert (res.points[c] >= 0).all() and np.isfinite(res.points[c]).all()
    assert (res.points["spread_count"] == 3).all()
    for c in SWEEP_COLUMNS:
        assert (res.sweeps[c] >= 0).all()
    assert (res.sweeps["spread_count"] == 3).all()  # from the point's copies' ends
    assert res.sweeps["within_round_off"].dtype == bool
    assert set(res.transitions["round_off_at_L_mm"]) <= {"none", "11.4", "12", "11.4, 12"}


def test_the_spread_is_off_unless_asked(runs):
    res = ks.load(runs[1])
    for c in (*POINT_COLUMNS, *SWEEP_COLUMNS, "within_round_off", "spread_count"):
        assert c not in res.points and c not in res.sweeps
    assert "round_off_at_L_mm" not in res.transitions
    assert "round-off" not in transitions_text(reduce_results([runs[1]]))
    # the one relaxation and sweep the job without spread computes are the spread job's first
    a, b = ks.load(runs[1]), ks.load(runs[3])
    assert np.array_equal(a.sweeps["delta_E_c_mJ"], b.sweeps["delta_E_c_mJ"])


def test_a_gap_within_its_spread_of_the_threshold_is_within_round_off(runs):
    res = ks.load(runs[3])
    row = res.sweeps.iloc[0]
    gap = row["delta_E_c_mJ"] if row["direction"] == "x" else row["delta_E_b_mJ"]
    at = ks.load(runs[3], threshold=float(gap))  # the threshold on the gap itself
    hit = at.sweeps[at.sweeps["task_id"] == row["task_id"]].iloc[0]
    assert hit["within_round_off"]
    series = at.transitions[at.transitions["direction"] == row["direction"]].iloc[0]
    assert f"{row['L_mm']:g}" in series["round_off_at_L_mm"]
    red = reduce_results([runs[3]], threshold=float(gap))
    assert "within round-off" in transitions_text(red)


@pytest.mark.parametrize("value", [0, 17])
def test_spread_out_of_range_is_one_error_naming_the_field(tmp_path, value):
    with pytest.raises(InputError, match=r"starts\.spread.*(1|16)"):
        load_job(_job(tmp_path, f"spread = {value}"))
