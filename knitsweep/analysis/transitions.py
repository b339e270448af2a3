"""The jamming rule: onset of unjamming (L/r)_trans, its bracket, the threshold
crossing, the jammed-regime line fit and the transition width ΔL/r, and regimes
(docs/model.md §9; paper "Energy Markers for Jamming", Fig. 4a-b, SI "Tolerance and
Error", Table S4).

This module is the one definition of the rule; the post-processor, the adaptive
search of a job and the accuracy study all call it. A point is jammed while its gap
is at or above :data:`GAP_THRESHOLD`; (L/r)_trans is the first L/r of a series below
it, and the bracket is (the jammed L/r before it, (L/r)_trans].

The jammed-regime fit (:func:`linear_jammed_run`) is a straight line through the
*linear* part of the jammed regime only: the run of jammed points from the dense end
(smallest L/r) that a line fits within the gap error, :data:`GAP_THRESHOLD`. The
curved transition region just before (L/r)_trans is left out, as in the paper, whose
ΔL/r is the distance from that line's zero to (L/r)_trans (Fig. 4a).

A *series* is one energy gap against L/r, sorted ascending, at fixed k, B, r_core, r,
p and one pulling direction. The gap that marks jamming is ΔE_c for 'x' and ΔE_b for
'y' (paper Fig. 3); the caller chooses it (:func:`group_series` does so for records).
Gaps are in N·mm (the paper's "J"); a gap of +inf stands for a point that cannot be
knitted (as jammed as it gets).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ..paths import load_path
from ._common import PlainDict, check_array, check_direction, check_same_length, check_scalar
from .fitting import LinearFit, fit_line

GAP_THRESHOLD = 5e-5
"""The paper's energy-gap error (N·mm, its "J"): below it a fabric counts as unjammed.
The only definition of this number in knitsweep."""

REGIMES = ("jammed_xy", "jammed_y_only", "jammed_x_only", "unjammed")
"""The regimes of :func:`regime`, as in paper Fig. 4c/5a (plus the rare converse)."""

RARE_REGIME = "jammed_x_only"
"""Jammed in x but not in y: the paper finds it "very unlikely to exist" (Fig. S6);
a result in this regime deserves a second look."""

SERIES_KEYS = ("k", "B", "r_core", "r", "p")

TransitionStatus = Literal["transition", "unjammed_at_start", "jammed_throughout", "failed"]


@dataclass(frozen=True)
class Transition(PlainDict):
    """The onset of unjamming along one series (paper Fig. 4a, Table S4).

    L/r values are dimensionless; gaps and the fit are in N·mm per unit L/r. To
    compare ``fit.slope`` with paper Table S4 (fitted against L in mm), divide it by
    r; the intercept (the value at L = 0) is the same in both.

    Attributes:
        status: 'transition' (a jammed point is followed by an unjammed one),
            'unjammed_at_start' (the first point is already below the threshold) or
            'jammed_throughout' (no point is below it); the post-processor marks a series
            whose refinement failed 'failed' (no transition, ``report.series.mark_failed``).
        L_over_r_trans: (L/r)_trans, the first L/r whose gap < threshold; for
            'unjammed_at_start' the first sampled L/r (an upper bound); None for
            'jammed_throughout'.
        bracket_lower: the last jammed L/r below (L/r)_trans, the paper's "−one step"
            error bar; None for 'unjammed_at_start'; the last sampled L/r for
            'jammed_throughout' (a lower bound on the transition).
        bracket_upper: equals ``L_over_r_trans`` (the paper's "+0").
        threshold: the gap threshold used, N·mm.
        source: 'grid' (:func:`transition`) or 'bracket' (:func:`transition_from_bracket`).
        n_points: number of points of the series.
        n_jammed: points before the transition (all with gap ≥ threshold).
        n_jammed_after: points after the transition whose gap is again ≥ threshold
            (0 for a monotone series; > 0 deserves a look).
        L_over_r_trans_last: the last crossing, from which every sampled L/r is
            unjammed: the sampled L/r after the last jammed one (``L_over_r_trans`` for
            a monotone series; None where the largest L/r is jammed). A re-entrant
            series (``n_jammed_after`` > 0) unjams for good there.
        bracket_lower_last: the last jammed L/r before it (None for a series unjammed
            at every point).
        fit: least-squares line of gap against L/r over the linear jammed run of
            :func:`linear_jammed_run` (≥ 2 points needed), else None. Its
            ``n_points`` are the fitted points, its residuals the Table S4 columns.
        fit_lower, fit_upper: the smallest and largest L/r fitted (None without a fit).
        fit_tolerance: N·mm, the largest |residual| the linear run allows.
        L_over_r_intercept: where that line reaches zero gap, −intercept/slope; None
            without a fit or when the slope is ≥ 0 (a gap that does not decrease has
            no meaningful end of jamming).
        delta_L_over_r: ΔL/r = (L/r)_trans − ``L_over_r_intercept`` (paper Fig. 4a),
            None when either is None.
    """

    status: TransitionStatus
    L_over_r_trans: float | None
    bracket_lower: float | None
    bracket_upper: float | None
    threshold: float
    source: Literal["grid", "bracket"]
    n_points: int
    n_jammed: int
    n_jammed_after: int
    L_over_r_trans_last: float | None
    bracket_lower_last: float | None
    fit: LinearFit | None
    fit_lower: float | None
    fit_upper: float | None
    fit_tolerance: float
    L_over_r_intercept: float | None
    delta_L_over_r: float | None


@dataclass(frozen=True, eq=False)
class GapSeries(PlainDict):
    """One series for :func:`transition`: a gap against L/r at fixed parameters.

    Attributes:
        params: the fixed parameters as ((name, value), ...) in the order of ``keys``.
        direction: the load path ('x', 'y' or a biaxial one).
        L_over_r: shape (n,), strictly increasing (read-only).
        jamming_gap: shape (n,), N·mm, the jamming gap at each L/r (read-only).
    """

    params: tuple[tuple[str, Any], ...]
    direction: str
    L_over_r: np.ndarray
    jamming_gap: np.ndarray


def _series(L_over_r: Any, jamming_gap: Any) -> tuple[np.ndarray, np.ndarray]:
    """Checked copies of a series, sorted by L/r; duplicates and negative gaps refused."""
    x = check_array("L_over_r", L_over_r)
    g = check_array("jamming_gap", jamming_gap, allow_inf=True)
    check_same_length(L_over_r=x, jamming_gap=g)
    if np.any(g < 0.0):
        i = int(np.flatnonzero(g < 0.0)[0])
        raise ValueError(f"jamming_gap: entry {i} is {float(g[i])!r}; energy gaps are >= 0")
    order = np.argsort(x, kind="stable")
    x, g = x[order], g[order]
    same = np.flatnonzero(np.diff(x) == 0.0)
    if same.size:
        raise ValueError(f"L_over_r: the value {float(x[same[0]])!r} appears more than once")
    return x, g


def linear_jammed_run(L_over_r: Any, jamming_gap: Any, tolerance: float = GAP_THRESHOLD) -> slice:
    """Which jammed points the Table S4 line is fitted to: the linear jammed regime.

    The rule, deterministic and on the gaps alone: start at the dense end, the
    smallest L/r with a finite gap (points that cannot be knitted, gap +inf, are
    skipped there and end the run anywhere else), take the first two points, and
    add the next point while the least-squares line through all points taken so far
    leaves every residual within ``tolerance`` (the gap error, paper SI "Tolerance and
    Error"). The first point that bends the data out of that band, and every point
    after it, belong to the curved transition region and are left out (paper Fig. 4a,
    where the fitted line misses the last jammed points).

    Args:
        L_over_r: shape (n,), strictly increasing (the jammed points of a series).
        jamming_gap: shape (n,), N·mm, ≥ 0 (+inf allowed).
        tolerance: N·mm, > 0.

    Returns:
        The slice of the fitted points; empty when fewer than 2 finite points lead
        the series.
    """
    tolerance = check_scalar("tolerance", tolerance, positive=True)
    x, g = _series(L_over_r, jamming_gap)
    finite = np.flatnonzero(np.isfinite(g))
    if finite.size < 2:
        return slice(0, 0)
    start = int(finite[0])
    end = start
    while end < x.size and np.isfinite(g[end]):
        end += 1
    stop = start + 2
    if stop > end:
        return slice(0, 0)
    while (
        stop < end
        and fit_line(x[start : stop + 1], g[start : stop + 1]).max_abs_residual <= tolerance
    ):
        stop += 1
    return slice(start, stop)


def _jammed_line(
    x: np.ndarray, g: np.ndarray, tolerance: float
) -> tuple[LinearFit | None, float | None, float | None, float | None]:
    """(fit, its L/r-intercept, first and last fitted L/r) of the jammed points."""
    run = linear_jammed_run(x, g, tolerance) if x.size else slice(0, 0)
    if run.stop - run.start < 2:
        return None, None, None, None
    fit = fit_line(x[run], g[run])
    x0 = fit.x_intercept if fit.slope < 0.0 else None
    return fit, x0, float(x[run.start]), float(x[run.stop - 1])


def _last_crossing(x, g, threshold, trans, lower) -> tuple[float | None, float | None]:
    """(the sampled L/r after the last jammed one, that jammed L/r): (``trans``,
    ``lower``) where no point beyond ``trans`` is jammed, (None, the last L/r) where the
    last is."""
    jammed = np.flatnonzero(g >= threshold)
    if trans is None or not np.any(x[jammed] > trans):
        return trans, lower
    j = int(jammed[-1])
    return (float(x[j + 1]) if j + 1 < x.size else None), float(x[j])


def _result(
    status: TransitionStatus,
    trans: float | None,
    lower: float | None,
    x: np.ndarray,
    g: np.ndarray,
    n_jammed: int,
    threshold: float,
    source: Literal["grid", "bracket"],
) -> Transition:
    fit, x0, lo, hi = _jammed_line(x[:n_jammed], g[:n_jammed], threshold)
    after = x > trans if trans is not None else np.zeros(x.size, dtype=bool)
    last, last_lower = _last_crossing(x, g, threshold, trans, lower)
    return Transition(
        status=status,
        L_over_r_trans=trans,
        bracket_lower=lower,
        bracket_upper=trans,
        threshold=threshold,
        source=source,
        n_points=int(x.size),
        n_jammed=n_jammed,
        n_jammed_after=int(np.count_nonzero(after & (g >= threshold))),
        L_over_r_trans_last=last,
        bracket_lower_last=last_lower,
        fit=fit,
        fit_lower=lo,
        fit_upper=hi,
        fit_tolerance=threshold,
        L_over_r_intercept=x0,
        delta_L_over_r=(trans - x0) if trans is not None and x0 is not None else None,
    )


def transition(L_over_r: Any, jamming_gap: Any, threshold: float = GAP_THRESHOLD) -> Transition:
    """(L/r)_trans, its bracket, the jammed-regime fit and ΔL/r of one series.

    Paper "Energy Markers for Jamming": (L/r)_trans is "the first stitch length with
    an energy gap below our error threshold"; its error is "+0, −one step" (SI
    "Tolerance and Error"), hence the bracket (previous grid point, (L/r)_trans).
    The jammed points are those before the transition (all with gap ≥ threshold);
    a straight least-squares line through their linear run
    (:func:`linear_jammed_run`, tolerance = the threshold, the gap error) gives the
    Table S4 columns, its L/r-intercept, and ΔL/r = (L/r)_trans − intercept (paper
    Fig. 4a).

    Args:
        L_over_r: shape (n,), n ≥ 1, distinct; sorted here if unsorted (the gap
            follows). Passing L in mm instead gives the same results in mm.
        jamming_gap: shape (n,), N·mm, ≥ 0 (ΔE_c for x, ΔE_b for y).
        threshold: N·mm, > 0 (paper: :data:`GAP_THRESHOLD`). A point is unjammed when gap < threshold.

    Returns:
        :class:`Transition` with ``source='grid'``.

    Raises:
        ValueError: non-finite, negative-gap, duplicated-L/r or mismatched input,
            naming the argument; threshold ≤ 0.
    """
    threshold = check_scalar("threshold", threshold, positive=True)
    x, g = _series(L_over_r, jamming_gap)
    below = np.flatnonzero(g < threshold)
    if below.size == 0:
        return _result("jammed_throughout", None, float(x[-1]), x, g, x.size, threshold, "grid")
    i = int(below[0])
    if i == 0:
        return _result("unjammed_at_start", float(x[0]), None, x, g, 0, threshold, "grid")
    return _result("transition", float(x[i]), float(x[i - 1]), x, g, i, threshold, "grid")


def threshold_crossing(
    L_over_r: Any, jamming_gap: Any, threshold: float = GAP_THRESHOLD
) -> float | None:
    """Where the gap crosses the threshold inside the transition bracket, linearly
    interpolated between the last jammed and the first unjammed point: a continuous
    (L/r)_trans (same units as ``L_over_r``) whose error a study can measure. None
    unless the series has a transition with a finite gap on its jammed side."""
    t = transition(L_over_r, jamming_gap, threshold)
    if t.status != "transition":
        return None
    x, g = _series(L_over_r, jamming_gap)
    i = int(np.searchsorted(x, t.L_over_r_trans))
    if not math.isfinite(g[i - 1]):
        return None
    w = (g[i - 1] - threshold) / (g[i - 1] - g[i])
    return float(x[i - 1] + w * (x[i] - x[i - 1]))


def transition_from_bracket(
    lo: float,
    hi: float,
    L_over_r: Any = None,
    jamming_gap: Any = None,
    threshold: float = GAP_THRESHOLD,
) -> Transition:
    """A transition found by bisection: (L/r)_trans = ``hi``, bracket (``lo``, ``hi``).

    For an adaptive search that has narrowed the onset of unjamming to lo < hi, where
    the gap at ``lo`` is ≥ threshold and the gap at ``hi`` is < threshold. If the
    sampled series (every L/r evaluated, grid and bisection points, any order) is
    given, the jammed points are those with L/r < hi; they must all have gap ≥
    threshold (otherwise ``hi`` is not the first unjammed L/r), and they give the
    fit (over their linear run), its L/r-intercept and ΔL/r exactly as in
    :func:`transition`.

    Args:
        lo, hi: the bracket, lo < hi (L/r, dimensionless).
        L_over_r, jamming_gap: optional sampled series, shape (n,) each (see :func:`transition`).
        threshold: N·mm, > 0.

    Returns:
        :class:`Transition` with ``status='transition'`` and ``source='bracket'``.

    Raises:
        ValueError: lo ≥ hi, only one of L_over_r/jamming_gap given, or a series inconsistent
            with the bracket (a point below hi under the threshold, a point at hi at or
            above it, a point at lo below it).
    """
    lo = check_scalar("lo", lo)
    hi = check_scalar("hi", hi)
    threshold = check_scalar("threshold", threshold, positive=True)
    if not lo < hi:
        raise ValueError(f"bracket (lo, hi) = ({lo!r}, {hi!r}): needs lo < hi")
    if (L_over_r is None) != (jamming_gap is None):
        raise ValueError("L_over_r and jamming_gap: give both or neither")
    if L_over_r is None:
        empty = np.zeros(0)
        return _result("transition", hi, lo, empty, empty, 0, threshold, "bracket")
    x, g = _series(L_over_r, jamming_gap)
    before = x < hi
    if np.any(before & (g < threshold)):
        bad = float(x[np.flatnonzero(before & (g < threshold))[0]])
        raise ValueError(
            f"L_over_r = {bad!r} < hi = {hi!r} has gap below the threshold; "
            "hi is not the first unjammed L/r"
        )
    if np.any((x == hi) & (g >= threshold)):
        raise ValueError(f"the gap at hi = {hi!r} is not below the threshold")
    n_jammed = int(np.count_nonzero(before))
    return _result("transition", hi, lo, x, g, n_jammed, threshold, "bracket")


def _as_trans(name: str, value: Any) -> float:
    if isinstance(value, Transition):
        value = value.L_over_r_trans
    if value is None:
        return float("inf")
    return check_scalar(name, value)


def regime(L_over_r: float, trans_x: Any, trans_y: Any) -> str:
    """Jamming regime at one L/r from the two directions' (L/r)_trans (paper Fig. 4c).

    A direction is jammed at L/r when L/r < its (L/r)_trans. Returns

    * 'jammed_xy': L/r < both;
    * 'jammed_y_only': trans_x ≤ L/r < trans_y;
    * 'jammed_x_only': trans_y ≤ L/r < trans_x — the converse, which the paper finds
      very unlikely (see :data:`RARE_REGIME`): check such a point;
    * 'unjammed': L/r ≥ both.

    Args:
        L_over_r: the L/r to classify.
        trans_x, trans_y: (L/r)_trans per direction, as a float, a :class:`Transition`
            or None. None (and a 'jammed_throughout' Transition) means no unjamming
            was found in the sampled range: that direction is taken as jammed at every
            L/r (its transition lies above the series). For an 'unjammed_at_start'
            Transition, (L/r)_trans is the first sampled L/r, only an upper bound, so
            smaller L/r are classified as jammed by extrapolation.
    """
    x = check_scalar("L_over_r", L_over_r)
    jammed_x = x < _as_trans("trans_x", trans_x)
    jammed_y = x < _as_trans("trans_y", trans_y)
    if jammed_x and jammed_y:
        return "jammed_xy"
    if jammed_y:
        return "jammed_y_only"
    if jammed_x:
        return "jammed_x_only"
    return "unjammed"


def _record_L_over_r(i: int, rec: Mapping[str, Any]) -> float:
    if "L_over_r" in rec:
        return check_scalar(f"records[{i}]['L_over_r']", rec["L_over_r"], positive=True)
    if "L" in rec and "r" in rec:
        L = check_scalar(f"records[{i}]['L']", rec["L"], positive=True)
        return L / check_scalar(f"records[{i}]['r']", rec["r"], positive=True)
    raise ValueError(f"records[{i}]: needs 'L_over_r', or both 'L' and 'r'")


def _record_gap(i: int, rec: Mapping[str, Any], direction: str) -> float:
    name = "jamming_gap" if "jamming_gap" in rec else load_path(direction).gap
    if name not in rec:
        raise ValueError(
            f"records[{i}]: needs 'jamming_gap' or '{name}' for direction {direction!r}"
        )
    return check_scalar(f"records[{i}][{name!r}]", rec[name])


def group_series(
    records: Iterable[Mapping[str, Any]], keys: tuple[str, ...] = SERIES_KEYS
) -> dict[tuple[tuple[Any, ...], str], GapSeries]:
    """Group per-sweep records into series for :func:`transition`.

    Each record is a flat mapping with 'direction' (a load path: 'x', 'y', …), every name in
    ``keys``, 'L_over_r' (or 'L' and 'r', mm, giving L/r = L/r), and the gap: 'jamming_gap'
    if present, else the direction's jamming gap, 'delta_E_c' for x and 'delta_E_b'
    for y (the names of :class:`~knitsweep.analysis.metrics.EnergyGaps`). Other fields
    are ignored. Parameter values are grouped by equality, so give each the same
    float in every record of a series.

    Args:
        records: iterable of mappings, e.g. rows of a results file.
        keys: the parameters held fixed along a series (default k, B, r_core, r, p).

    Returns:
        {(values of ``keys``, direction): :class:`GapSeries`}, in order of first
        appearance, each series sorted by L/r.

    Raises:
        ValueError: a missing or non-finite field (naming the record and field), a bad
            direction, a negative gap, or the same L/r twice in one series.
    """
    keys = tuple(keys)
    collected: dict[tuple[tuple[Any, ...], str], list[tuple[float, float]]] = {}
    for i, rec in enumerate(records):
        if "direction" not in rec:
            raise ValueError(f"records[{i}]: missing 'direction'")
        direction = check_direction(rec["direction"])
        missing = [k for k in keys if k not in rec]
        if missing:
            raise ValueError(f"records[{i}]: missing series key(s) {missing}")
        values = tuple(rec[k] for k in keys)
        point = (_record_L_over_r(i, rec), _record_gap(i, rec, direction))
        collected.setdefault((values, direction), []).append(point)

    series = {}
    for (values, direction), points in collected.items():
        try:
            x, g = _series([p[0] for p in points], [p[1] for p in points])
        except ValueError as e:
            raise ValueError(
                f"series {dict(zip(keys, values, strict=True))} in {direction}: {e}"
            ) from None
        x.flags.writeable = False
        g.flags.writeable = False
        params = tuple(zip(keys, values, strict=True))
        series[(values, direction)] = GapSeries(params, direction, x, g)
    return series


def series_transitions(
    records: Iterable[Mapping[str, Any]],
    keys: tuple[str, ...] = SERIES_KEYS,
    threshold: float = GAP_THRESHOLD,
) -> dict[tuple[tuple[Any, ...], str], Transition]:
    """:func:`transition` of every series of :func:`group_series` (same keys and order)."""
    return {
        key: transition(s.L_over_r, s.jamming_gap, threshold)
        for key, s in group_series(records, keys).items()
    }
