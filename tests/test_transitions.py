"""Unit tests of knitsweep.analysis.transitions (docs/model.md §9, paper Fig. 4, Table S4).

The main synthetic series uses the k = 0.1 mN/mm² row of paper Table S4: a contact
gap ΔE_c = 0.0176 − 1.55e-3·L (N·mm, L in mm) while positive, zero after, sampled on
the paper's 0.1-mm grid in L with r = 0.74 mm.
"""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from knitsweep.analysis import (
    GAP_THRESHOLD,
    RARE_REGIME,
    REGIMES,
    Transition,
    fit_line,
    group_series,
    linear_jammed_run,
    regime,
    series_transitions,
    transition,
    transition_from_bracket,
)
from knitsweep.analysis.paper import TABLE_S4

R = 0.74  # mm
SLOPE_L = -1.55e-3  # N·mm per mm of L (Table S4, k = 0.1)
INTERCEPT = 0.0176  # N·mm at L = 0
L_ZERO = -INTERCEPT / SLOPE_L  # 11.3548... mm, where the line reaches zero


def grid_L() -> np.ndarray:
    return np.round(10.5 + 0.1 * np.arange(26), 10)  # 10.5 .. 13.0 mm


def linear_gap(L: np.ndarray) -> np.ndarray:
    return np.maximum(INTERCEPT + SLOPE_L * L, 0.0)


def assert_plain(d: dict) -> None:
    json.dumps(d, allow_nan=False)


# ---------------------------------------------------------------- transition


def test_linear_series_transition_bracket_fit_and_width():
    L = grid_L()
    x, gap = L / R, linear_gap(L)
    # By hand: gap(11.3) = 8.5e-5 ≥ 5e-5 (jammed), gap(11.4) = 0 (unjammed).
    assert gap[8] >= GAP_THRESHOLD > gap[9]
    res = transition(x, gap)
    assert res.status == "transition" and res.source == "grid"
    assert res.L_over_r_trans == x[9]  # a grid value, returned as is
    assert (res.bracket_lower, res.bracket_upper) == (x[8], x[9])
    assert res.threshold == 5e-5
    assert (res.n_points, res.n_jammed, res.n_jammed_after) == (26, 9, 0)
    # The jammed points lie on the line, so the fit is exact up to rounding.
    assert res.fit.n_points == 9
    assert res.fit.slope == pytest.approx(SLOPE_L * R, rel=1e-12)
    assert res.fit.intercept == pytest.approx(INTERCEPT, abs=1e-15)
    assert res.fit.max_abs_residual < 1e-16
    assert res.fit.mse < 1e-32
    assert res.L_over_r_intercept == pytest.approx(L_ZERO / R, abs=1e-12)
    assert res.delta_L_over_r == pytest.approx((11.4 - L_ZERO) / R, abs=1e-12)
    assert 0 < res.delta_L_over_r < 0.1 / R
    # Table S4 convention (fit against L in mm): slope/r, same intercept.
    assert res.fit.slope / R == pytest.approx(SLOPE_L, rel=1e-12)
    by_L = transition(L, gap)
    assert by_L.L_over_r_trans == 11.4 and by_L.fit.slope == pytest.approx(SLOPE_L, rel=1e-12)
    assert_plain(res.as_dict())


def test_fit_columns_match_table_s4_definitions():
    rng = np.random.default_rng(42)
    L = grid_L()
    gap = linear_gap(L) + np.where(L < 11.2, 2e-5 * rng.standard_normal(L.size), 0.0)
    res = transition(L / R, gap)
    n = res.n_jammed
    xj, gj = L[:n] / R, gap[:n]
    slope, intercept = np.polyfit(xj, gj, 1)
    resid = gj - (intercept + slope * xj)
    assert res.fit.slope == pytest.approx(slope, rel=1e-10)
    assert res.fit.intercept == pytest.approx(intercept, rel=1e-10)
    assert res.fit.max_abs_residual == pytest.approx(np.max(np.abs(resid)), rel=1e-6)
    assert res.fit.mean_abs_residual == pytest.approx(np.mean(np.abs(resid)), rel=1e-6)
    assert res.fit.mse == pytest.approx(np.mean(resid**2), rel=1e-6)


def convex_tail_gap(L: np.ndarray) -> np.ndarray:
    """The Table S4 line to L = 10.8 mm, then a convex transition region that leaves
    it tangentially and bends away ever more (the shape of the simulated gaps, paper
    Fig. 4a), a parabola flattening to zero slope at L = 11.91 mm."""
    g0 = INTERCEPT + SLOPE_L * 10.8
    u = np.maximum(L - 10.8, 0.0)
    vertex = -2.0 * g0 / SLOPE_L
    tail = g0 + SLOPE_L * u - SLOPE_L / (2.0 * vertex) * u**2
    return np.where(L <= 10.8, INTERCEPT + SLOPE_L * L, np.where(u < vertex, tail, 0.0))


def test_curved_transition_region_is_left_out_of_the_fit():
    L = grid_L()
    gap = convex_tail_gap(L)
    res = transition(L / R, gap)
    i = int(np.flatnonzero(gap < GAP_THRESHOLD)[0])
    assert res.L_over_r_trans == L[i] / R and res.n_jammed == i
    run = linear_jammed_run(L[:i] / R, gap[:i])
    # the rule: from the dense end, the longest run whose line fits within the gap
    # error; one point more and it does not
    assert run.start == 0 and 3 <= run.stop <= i - 3
    assert fit_line(L[run], gap[run]).max_abs_residual <= GAP_THRESHOLD
    assert fit_line(L[: run.stop + 1], gap[: run.stop + 1]).max_abs_residual > GAP_THRESHOLD
    assert res.fit == fit_line(L[run] / R, gap[run])
    assert (res.fit_lower, res.fit_upper) == (L[0] / R, L[run.stop - 1] / R)
    assert res.fit.max_abs_residual <= res.fit_tolerance == GAP_THRESHOLD
    # the line stays close to the Table S4 one, and ΔL/r runs from its zero to trans
    assert res.fit.slope / R == pytest.approx(SLOPE_L, rel=0.1)
    assert res.delta_L_over_r == pytest.approx(res.L_over_r_trans - res.L_over_r_intercept)
    assert res.delta_L_over_r > 0.2 / R  # the curved region: ~0.28 mm here
    # fitting every jammed point, curved region included, would flatten the slope
    assert fit_line(L[:i], gap[:i]).slope > 0.8 * SLOPE_L  # per mm: L in mm here


def test_linear_jammed_run_rule():
    x = np.arange(8.0)
    line = 1e-3 * (8.0 - x)
    assert linear_jammed_run(x, line) == slice(0, 8)  # exactly linear: every point
    # a point off the line by more than the tolerance ends the run before it
    bent = line.copy()
    bent[5:] += 4e-4
    run = linear_jammed_run(x, bent)
    assert run.stop <= 5 and fit_line(x[run], bent[run]).max_abs_residual <= GAP_THRESHOLD
    assert linear_jammed_run(x, bent, tolerance=1e-3) == slice(0, 8)
    # points that cannot be knitted (gap +inf) are skipped at the dense end only
    inf = line.copy()
    inf[:2] = np.inf
    assert linear_jammed_run(x, inf) == slice(2, 8)
    inf[5] = np.inf
    assert linear_jammed_run(x, inf) == slice(2, 5)
    assert linear_jammed_run(x[:1], line[:1]) == slice(0, 0)
    assert linear_jammed_run([1.0, 2.0, 3.0], [np.inf, 1e-3, np.inf]) == slice(0, 0)
    with pytest.raises(ValueError, match="tolerance"):
        linear_jammed_run(x, line, tolerance=0.0)


def test_all_jammed():
    L = grid_L()[:8]
    res = transition(L / R, linear_gap(L))
    assert res.status == "jammed_throughout"
    assert res.L_over_r_trans is None and res.bracket_upper is None
    assert res.bracket_lower == L[-1] / R  # the transition lies above the series
    assert res.n_jammed == 8 and res.fit.slope == pytest.approx(SLOPE_L * R, rel=1e-12)
    assert res.fit.n_points == 8 and res.fit_upper == L[-1] / R
    assert res.L_over_r_intercept == pytest.approx(L_ZERO / R, abs=1e-12)
    assert res.delta_L_over_r is None
    d = res.as_dict()
    assert d["L_over_r_trans"] is None and d["delta_L_over_r"] is None
    assert_plain(d)


def test_none_jammed():
    L = grid_L()[12:]
    res = transition(L / R, linear_gap(L))
    assert res.status == "unjammed_at_start"
    assert res.L_over_r_trans == L[0] / R == res.bracket_upper
    assert res.bracket_lower is None and res.n_jammed == 0
    assert res.fit is None and res.L_over_r_intercept is None and res.delta_L_over_r is None
    assert_plain(res.as_dict())


@pytest.mark.parametrize(
    "gap, status, trans",
    [([1e-3], "jammed_throughout", None), ([1e-6], "unjammed_at_start", 15.0)],
)
def test_single_point(gap, status, trans):
    res = transition([15.0], gap)
    assert res.status == status and res.L_over_r_trans == trans
    assert res.fit is None and res.delta_L_over_r is None


def test_one_jammed_point_gives_no_fit():
    res = transition([15.0, 15.1, 15.2], [1e-3, 0.0, 0.0])
    assert res.status == "transition" and res.L_over_r_trans == 15.1
    assert res.bracket_lower == 15.0 and res.n_jammed == 1
    assert res.fit is None and res.delta_L_over_r is None


def test_threshold_is_strict_and_configurable():
    x = [15.0, 15.1, 15.2]
    assert transition(x, [1e-3, 5e-5, 0.0]).L_over_r_trans == 15.2  # 5e-5 is not below
    assert transition(x, [1e-3, 5e-5, 0.0], threshold=1e-4).L_over_r_trans == 15.1
    with pytest.raises(ValueError, match="threshold"):
        transition(x, [1e-3, 0.0, 0.0], threshold=0.0)


def test_unsorted_input_is_sorted():
    rng = np.random.default_rng(11)
    L = grid_L()
    x, gap = L / R, linear_gap(L)
    ref = transition(x, gap)
    for _ in range(5):
        p = rng.permutation(x.size)
        assert transition(x[p], gap[p]) == ref


def test_reentrant_points_are_counted():
    x = [15.0, 15.1, 15.2, 15.3, 15.4]
    res = transition(x, [2e-3, 1e-3, 0.0, 2e-4, 0.0])
    assert res.L_over_r_trans == 15.2 and res.n_jammed == 2 and res.n_jammed_after == 1


def test_increasing_gap_has_no_intercept():
    res = transition([15.0, 15.1, 15.2], [1e-3, 2e-3, 0.0])
    assert res.fit.slope > 0
    assert res.L_over_r_intercept is None and res.delta_L_over_r is None


@pytest.mark.parametrize(
    "x, gap, match",
    [
        ([15.0, math.nan], [1e-3, 0.0], r"L_over_r: entry 1"),
        ([15.0, 15.1], [1e-3, math.nan], r"gap: entry 1"),
        ([15.0, 15.1], [1e-3, -1e-9], r"gap: entry 1 .* >= 0"),
        ([15.0, 15.1], [1e-3], "same length"),
        ([15.1, 15.0, 15.1], [1e-3, 1e-3, 0.0], "more than once"),
        ([], [], "at least 1"),
    ],
)
def test_bad_input(x, gap, match):
    with pytest.raises(ValueError, match=match):
        transition(x, gap)


# ---------------------------------------------------------------- from a bracket


def test_bracket_without_series():
    res = transition_from_bracket(15.30, 15.32)
    assert res.status == "transition" and res.source == "bracket"
    assert (res.L_over_r_trans, res.bracket_lower, res.bracket_upper) == (15.32, 15.30, 15.32)
    assert res.fit is None and res.n_points == 0 and res.delta_L_over_r is None
    assert_plain(res.as_dict())


def test_bracket_matches_grid_and_uses_bisection_points():
    L = grid_L()
    x, gap = L / R, linear_gap(L)
    grid = transition(x, gap)
    same = transition_from_bracket(x[8], x[9], x, gap)
    assert same.source == "bracket"
    for field in ("L_over_r_trans", "bracket_lower", "fit", "delta_L_over_r", "n_jammed"):
        assert getattr(same, field) == getattr(grid, field)
    # Bisection between 11.3 and 11.4 mm: 11.35 (jammed), 11.325 (jammed), 11.3375 ...
    # the threshold is crossed at L_ZERO − 5e-5/1.55e-3 = 11.32258 mm.
    L_cross = L_ZERO - GAP_THRESHOLD / -SLOPE_L
    lo, hi = 11.3, 11.4
    extra = []
    for _ in range(6):
        mid = 0.5 * (lo + hi)
        extra.append(mid)
        lo, hi = (mid, hi) if mid < L_cross else (lo, mid)
    Ls = np.concatenate([L, extra])
    gs = linear_gap(Ls)
    p = np.random.default_rng(5).permutation(Ls.size)
    res = transition_from_bracket(lo / R, hi / R, Ls[p] / R, gs[p])
    assert res.L_over_r_trans == hi / R and res.bracket_lower == lo / R
    assert lo < L_cross < hi and hi - lo == pytest.approx(0.1 / 2**6, rel=1e-9)
    jammed = Ls < hi
    assert res.n_jammed == np.count_nonzero(jammed)
    # The gap is exactly linear below hi (all points are above the line's zero).
    assert res.fit.slope == pytest.approx(SLOPE_L * R, rel=1e-12)
    assert res.delta_L_over_r == pytest.approx((hi - L_ZERO) / R, abs=1e-12)


def test_bracket_inconsistent_with_series():
    x = [15.0, 15.1, 15.2, 15.3]
    g = [1e-3, 1e-4, 0.0, 0.0]
    with pytest.raises(ValueError, match="not the first unjammed"):
        transition_from_bracket(15.2, 15.3, x, g)
    with pytest.raises(ValueError, match="at hi"):
        transition_from_bracket(15.0, 15.1, x, g)
    with pytest.raises(ValueError, match="lo < hi"):
        transition_from_bracket(15.2, 15.1)
    with pytest.raises(ValueError, match="both or neither"):
        transition_from_bracket(15.0, 15.1, x)


# ---------------------------------------------------------------- regime


@pytest.mark.parametrize(
    "L_over_r, trans_x, trans_y, expected",
    [
        (14.0, 15.0, 16.0, "jammed_xy"),
        (15.0, 15.0, 16.0, "jammed_y_only"),  # trans_x ≤ L/r < trans_y
        (15.9, 15.0, 16.0, "jammed_y_only"),
        (16.0, 15.0, 16.0, "unjammed"),
        (17.0, 15.0, 16.0, "unjammed"),
        (15.5, 16.0, 15.0, "jammed_x_only"),
        (14.9, 15.0, 15.0, "jammed_xy"),
        (15.0, 15.0, 15.0, "unjammed"),
        (99.0, None, None, "jammed_xy"),  # no unjamming found: jammed everywhere
        (16.0, 15.0, None, "jammed_y_only"),
        (16.0, None, 15.0, "jammed_x_only"),
    ],
)
def test_regime_table(L_over_r, trans_x, trans_y, expected):
    assert regime(L_over_r, trans_x, trans_y) == expected
    assert expected in REGIMES


def test_regime_accepts_transitions():
    L = grid_L()
    tx = transition(L / R, linear_gap(L))  # trans 11.4/r
    ty = transition(L / R, linear_gap(L - 0.5))  # trans 11.9/r
    jammed_all = transition(L[:5] / R, linear_gap(L[:5]))
    assert regime(11.0 / R, tx, ty) == "jammed_xy"
    assert regime(11.5 / R, tx, ty) == "jammed_y_only"
    assert regime(12.0 / R, tx, ty) == "unjammed"
    assert regime(12.0 / R, tx, jammed_all) == "jammed_y_only"
    assert regime(11.5 / R, ty, tx) == RARE_REGIME == "jammed_x_only"
    with pytest.raises(ValueError, match="L_over_r"):
        regime(math.nan, tx, ty)
    with pytest.raises(ValueError, match="trans_y"):
        regime(15.0, tx, math.inf)


# ---------------------------------------------------------------- grouping records


def make_records():
    rng = np.random.default_rng(2025)
    recs = []
    for k in (0.1, 1.0):
        for L in grid_L():
            g_c = max(0.0, INTERCEPT + SLOPE_L * (L - 0.3 * k))  # zero at 11.35 + 0.3 k
            g_b = max(0.0, INTERCEPT + SLOPE_L * (L - 0.6 * k))
            base = {"k": k, "B": 90.0, "r_core": 0.325, "r": R, "p": 2.4}
            # x records give L and r; y records give L/r directly.
            recs.append({**base, "direction": "x", "L": L, "delta_E_c": g_c, "delta_E_b": 0.0})
            recs.append(
                {**base, "direction": "y", "L_over_r": L / R, "delta_E_b": g_b, "delta_E_c": 0.0}
            )
    return [recs[i] for i in rng.permutation(len(recs))]


def test_group_series_groups_sorts_and_picks_the_jamming_gap():
    recs = make_records()
    series = group_series(recs)
    assert len(series) == 4
    first = recs[0]
    assert next(iter(series)) == (
        (first["k"], 90.0, 0.325, R, 2.4),
        first["direction"],
    )  # order of first appearance
    L = grid_L()
    for k in (0.1, 1.0):
        sx = series[((k, 90.0, 0.325, R, 2.4), "x")]
        sy = series[((k, 90.0, 0.325, R, 2.4), "y")]
        assert sx.params == (("k", k), ("B", 90.0), ("r_core", 0.325), ("r", R), ("p", 2.4))
        np.testing.assert_array_equal(sx.L_over_r, L / R)
        np.testing.assert_array_equal(sy.L_over_r, L / R)
        np.testing.assert_array_equal(
            sx.jamming_gap, np.maximum(INTERCEPT + SLOPE_L * (L - 0.3 * k), 0)
        )
        np.testing.assert_array_equal(
            sy.jamming_gap, np.maximum(INTERCEPT + SLOPE_L * (L - 0.6 * k), 0)
        )
        assert not sx.L_over_r.flags.writeable and not sx.jamming_gap.flags.writeable
    assert_plain(sx.as_dict())


def test_series_transitions_reduce_records():
    recs = make_records()
    out = series_transitions(recs)
    for key, s in group_series(recs).items():
        assert isinstance(out[key], Transition)
        assert out[key] == transition(s.L_over_r, s.jamming_gap)
    # Larger k jams to larger L (paper Fig. 4c), y beyond x.
    t = {key: v.L_over_r_trans for key, v in out.items()}
    base = (90.0, 0.325, R, 2.4)
    assert t[((0.1, *base), "x")] < t[((1.0, *base), "x")] < t[((1.0, *base), "y")]


def test_group_series_explicit_gap_and_custom_keys():
    recs = [
        {"k": 0.1, "direction": "x", "L_over_r": 15.1, "jamming_gap": 0.0, "delta_E_c": 9.0},
        {"k": 0.1, "direction": "x", "L_over_r": 15.0, "jamming_gap": 1e-3},
    ]
    (s,) = group_series(recs, keys=("k",)).values()
    np.testing.assert_array_equal(s.L_over_r, [15.0, 15.1])
    np.testing.assert_array_equal(s.jamming_gap, [1e-3, 0.0])


@pytest.mark.parametrize(
    "bad, match",
    [
        ({"direction": "z"}, "direction"),
        ({"p": None}, r"records\[1\]\['p'\]"),
        ({"L_over_r": math.nan}, r"records\[1\]\['L_over_r'\]"),
        ({"delta_E_c": math.nan}, r"records\[1\]\['delta_E_c'\]"),
    ],
)
def test_group_series_bad_record(bad, match):
    good = {"k": 0.1, "B": 90.0, "r_core": 0.325, "r": R, "p": 2.4, "direction": "x"}
    recs = [{**good, "L_over_r": 15.0, "delta_E_c": 1e-3}, {**good, "L_over_r": 15.1, **bad}]
    recs[1].setdefault("delta_E_c", 0.0)
    if bad.get("p", 0) is None:
        del recs[1]["p"]
        match = r"records\[1\]: missing series key\(s\) \['p'\]"
    with pytest.raises(ValueError, match=match):
        group_series(recs)


def test_group_series_missing_fields_and_duplicates():
    good = {"k": 0.1, "B": 90.0, "r_core": 0.325, "r": R, "p": 2.4, "direction": "y"}
    with pytest.raises(ValueError, match=r"records\[0\]: needs 'jamming_gap' or 'delta_E_b'"):
        group_series([{**good, "L_over_r": 15.0, "delta_E_c": 1e-3}])
    with pytest.raises(ValueError, match=r"records\[0\]: needs 'L_over_r'"):
        group_series([{**good, "delta_E_b": 1e-3}])
    with pytest.raises(ValueError, match=r"records\[0\]: missing 'direction'"):
        group_series([{"k": 0.1}])
    dup = [{**good, "L": 11.1, "delta_E_b": 1e-3}, {**good, "L_over_r": 11.1 / R, "delta_E_b": 0.0}]
    with pytest.raises(
        ValueError,
        match=r"series \{'k': 0.1.*\} in y: L_over_r: the value 15.0 appears more than once",
    ):
        group_series(dup)


# ------------------------------------------------- the paper's Table S4, on stored gaps


def stored_series():
    data = json.loads((Path(__file__).parent / "data" / "paper_series.json").read_text())
    return data["r_mm"], data["series"]


def test_table_s4_from_stored_gaps():
    """knitsweep's contact gaps of x pulls (tests/data/paper_series.json, written by
    benchmarks/compare_paper.py from jobs/paper_k0.1_L_sweep.toml and
    jobs/paper_table_s4.toml) give paper Table S4's lines: slopes within 15 % and
    zeros within 0.15 mm (measured at k = 0.1 … 2: 1-13 %, 0.003-0.14 mm). A line through every
    jammed point instead misses the paper's slope by a third at k >= 0.5."""
    r, series = stored_series()
    checked = 0
    for s in series.values():
        k = s["k_mN_per_mm2"]
        if s["direction"] != "x" or k not in TABLE_S4:
            continue
        L, gap = np.array(s["L_mm"]), np.array(s["gap_mJ"])
        t = transition(L / r, gap)
        paper = TABLE_S4[k]
        assert t.status == "transition" and t.fit.max_abs_residual <= GAP_THRESHOLD
        assert t.fit.slope / r == pytest.approx(paper.slope_mJ_per_mm, rel=0.15), k
        assert t.L_over_r_intercept * r == pytest.approx(paper.zero_L_mm, abs=0.15), k
        assert t.delta_L_over_r > 0.0
        every = fit_line(L[: t.n_jammed], gap[: t.n_jammed])
        if k >= 0.5:
            assert every.slope / paper.slope_mJ_per_mm < 0.75, k
        checked += 1
    assert checked >= 4


def test_last_crossing_of_a_re_entrant_series():
    """(L/r)_trans is the first crossing (the paper's); the last crossing is where every
    sampled L/r from there on is unjammed: the first for a monotone series, None where the
    largest L/r is jammed."""
    x = np.array([12.0, 12.5, 13.0, 13.5, 14.0, 14.5, 15.0])
    g = np.array([2e-4, 1e-5, 1e-4, 2e-4, 0.0, 0.0, 0.0])  # unjams at 12.5, again at 14.0
    t = transition(x, g, 5e-5)
    assert (t.L_over_r_trans, t.bracket_lower, t.n_jammed_after) == (12.5, 12.0, 2)
    assert (t.L_over_r_trans_last, t.bracket_lower_last) == (14.0, 13.5)
    m = transition(x[[0, 1, 4, 5]], g[[0, 1, 4, 5]], 5e-5)  # monotone
    assert (m.L_over_r_trans_last, m.bracket_lower_last) == (m.L_over_r_trans, m.bracket_lower)
    end = transition(x[:4], g[:4], 5e-5)  # jammed again up to the last point
    assert end.L_over_r_trans_last is None and end.bracket_lower_last == 13.5
    assert transition(x[:1], g[:1], 5e-5).L_over_r_trans_last is None  # jammed throughout
    loose = transition(x[4:], g[4:], 5e-5)
    assert loose.L_over_r_trans_last == 14.0 and loose.bracket_lower_last is None
