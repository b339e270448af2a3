"""The series of a study's table rows (a stitch and fixed k, B, r_core, r, p) and their
transitions: one row per series and direction, (L/r)_trans, its bracket, the Table S4
fit of the linear jammed regime, its zero and ΔL/r (paper Fig. 4a), and the bracket an
adaptive run recorded beside it."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from ..analysis.transitions import Transition, series_transitions
from ..config import FAILED
from ..paths import load_path, path_rank
from ..quantities import NUMERIC_SERIES_PARAMS, PARAM_SYMBOLS, SERIES_PARAMS, value_text
from ..service.adaptive import failure_status
from ..stitches import DEFAULT_STITCH
from ..store.journal import Entry
from ..util.plain_values import plain_value


def series_values(meta: Mapping[str, Any]) -> tuple[Any, ...]:
    """The series of a task's attributes: its stitch (absent: the default) and the
    numbers of ``NUMERIC_SERIES_PARAMS``, in the order of ``SERIES_PARAMS``."""
    return tuple(str(meta.get(k, DEFAULT_STITCH)) if k == "stitch" else float(meta[k])
                 for k in SERIES_PARAMS)  # fmt: skip


def transition_row(
    values: tuple[Any, ...], direction: str, t: Transition, n_missing: int
) -> dict[str, Any]:
    """One row of transitions.csv: the series, (L/r)_trans, bracket, the Table S4 fit of
    the linear jammed regime, its zero and ΔL/r.

    The fit is against L in mm, the form of paper Table S4 (``fit_slope_mJ_per_mm``
    is the slope per unit L/r divided by r; the intercept, at L = 0, is the same in
    both); ``fit_L_lo_mm`` … ``fit_L_hi_mm`` are the points fitted, the linear run of
    :func:`~knitsweep.analysis.transitions.linear_jammed_run`."""
    params = dict(zip(SERIES_PARAMS, values, strict=True))
    r = params["r_mm"]
    trans = t.L_over_r_trans
    fit = t.fit
    zero = t.L_over_r_intercept

    def mm(v: float | None) -> float | None:
        return v * r if v is not None else None

    return {
        "direction": direction,
        **params,
        "gap": load_path(direction).gap,
        "status": t.status,
        "L_over_r_trans": trans,
        "bracket_lower": t.bracket_lower,
        "bracket_upper": t.bracket_upper,
        "L_trans_mm": mm(trans),
        "n_points": t.n_points,
        "n_jammed": t.n_jammed,
        "n_jammed_after": t.n_jammed_after,
        # the last crossing: unjammed at every sampled L/r from here (= the first for a
        # monotone series; None where the largest L/r is jammed)
        "L_over_r_trans_last": t.L_over_r_trans_last,
        "bracket_lower_last": t.bracket_lower_last,
        "L_trans_last_mm": mm(t.L_over_r_trans_last),
        "n_missing": n_missing,
        "fit_n_points": fit.n_points if fit else None,
        "fit_L_lo_mm": mm(t.fit_lower),
        "fit_L_hi_mm": mm(t.fit_upper),
        "fit_slope_mJ_per_mm": fit.slope / r if fit else None,
        "fit_intercept_mJ": fit.intercept if fit else None,
        "fit_max_abs_residual_mJ": fit.max_abs_residual if fit else None,
        "fit_mean_abs_residual_mJ": fit.mean_abs_residual if fit else None,
        "fit_mse_mJ2": fit.mse if fit else None,
        "fit_tolerance_mJ": t.fit_tolerance,
        "fit_zero_L_over_r": zero,
        "fit_zero_L_mm": mm(zero),
        "delta_L_over_r": t.delta_L_over_r,
        "delta_L_mm": mm(t.delta_L_over_r),
        "threshold": t.threshold,
    }


def series_key(row: Mapping[str, Any]) -> tuple[Any, ...]:
    """The series a table row belongs to: its values of ``SERIES_PARAMS`` (its stitch
    first: two stitches are two series)."""
    return tuple(row[k] for k in SERIES_PARAMS)


def transition_rows(
    sweeps: list[dict[str, Any]], problems: list[dict[str, Any]], threshold: float
) -> tuple[dict, list[dict[str, Any]]]:
    """(L/r)_trans of every (series, direction) with at least one analysed sweep.

    Every analysed L counts, so the series of an adaptive job (coarse grid plus
    bisection points) gives its refined bracket here too."""
    missing: dict[tuple[tuple[Any, ...], str], int] = {}
    for p in problems:
        if p["kind"] == "sweep":
            key = (series_key(p), p["direction"])
            missing[key] = missing.get(key, 0) + 1
    found = series_transitions(sweeps, SERIES_PARAMS, threshold)
    out = {key: found[key] for key in sorted(found, key=lambda k: (k[0], path_rank(k[1])))}
    rows = [transition_row(key[0], key[1], t, missing.get(key, 0)) for key, t in out.items()]
    close: dict[tuple[tuple[Any, ...], str], list[float]] = {}
    for s in sweeps:  # [starts] spread: gaps within their spread of the threshold
        if "within_round_off" in s:
            at = close.setdefault((series_key(s), s["direction"]), [])
            at += [s["L_mm"]] if s["within_round_off"] else []
    for key, row in zip(out, rows, strict=True):
        if key in close:
            row["within_round_off"] = bool(close[key])
            row["round_off_at_L_mm"] = ", ".join(f"{L:g}" for L in sorted(close[key])) or "none"
    return out, rows


def add_adaptive_brackets(
    entries: list[Entry], rows: list[dict[str, Any]], notes: list[str]
) -> None:
    """Add the bracket an adaptive job recorded per series (``/series`` groups) to the
    transition rows, and note where it disagrees with the one found here."""
    found = {}
    for e in entries:
        meta = {k: plain_value(v) for k, v in e.meta.items()}
        if all(k in meta for k in ("direction", *NUMERIC_SERIES_PARAMS)):
            found[(series_values(meta), meta["direction"])] = meta
    for row in rows:
        meta = found.get((series_key(row), row["direction"]))
        if meta is None:
            continue
        row["adaptive_status"] = meta.get("status")
        row["adaptive_message"] = meta.get("message")
        row["adaptive_bracket_lower"] = meta.get("bracket_lower")
        row["adaptive_bracket_upper"] = meta.get("bracket_upper")
        hi = meta.get("bracket_upper")
        if meta.get("status") == "done" and hi is not None and row["L_over_r_trans"] is not None:
            if abs(float(hi) - row["L_over_r_trans"]) > 1e-9 * max(1.0, abs(float(hi))):
                notes.append(
                    f"{row['direction']} series {series_text(row)}: the adaptive run bracketed "
                    f"(L/r)_trans at {float(hi):.4f}, this threshold gives "
                    f"{row['L_over_r_trans']:.4f}"
                )


NO_TRANSITION = ("L_over_r_trans", "bracket_lower", "bracket_upper", "L_trans_mm",
                 "delta_L_over_r", "delta_L_mm", "fit_zero_L_over_r", "fit_zero_L_mm")  # fmt: skip
"""The transition's fields that a failed series leaves empty."""


def mark_failed(transition_of: dict, rows: list[dict[str, Any]],
                problems: list[dict[str, Any]]) -> None:  # fmt: skip
    """A series whose refinement failed is never shown as a transition: one with a
    failed point (its sweep in that direction, or its zero-force state) at or below the
    L where it unjams (anywhere, if it never does), or whose adaptive refinement
    failed (``/series`` status 'failed': a point without a gap, or a bracket still wider
    than the tolerance), gets the status 'failed: point L=… mm (why)' (or 'failed:
    <the refinement's message>'), no (L/r)_trans, bracket or ΔL/r (``failed_L_over_r``:
    the failed point's L/r), and its Transition the status
    'failed' (so that no figure draws it and no regime is read from it); ``failure``
    holds the whole message."""
    failed: dict[tuple, list[tuple[float, str]]] = {}
    paths = list(dict.fromkeys(row["direction"] for row in rows))  # a failed point: every path
    for p in problems:
        if p["status"] != FAILED:
            continue
        for d in [p["direction"]] if p["kind"] == "sweep" else paths:
            failed.setdefault((series_key(p), d), []).append((float(p["L_mm"]), p["message"]))
    for row in rows:
        key = (series_key(row), row["direction"])
        t = transition_of[key]
        limit = math.inf if row["L_trans_mm"] is None else row["L_trans_mm"] * (1.0 + 1e-12)
        inside = sorted(f for f in failed.get(key, []) if f[0] <= limit)
        at = None
        if inside:
            status, why = failure_status(*inside[0]), inside[0][1]
            at = inside[0][0] / row["r_mm"]
        elif row.get("adaptive_status") == "failed":
            why = str(row.get("adaptive_message") or "adaptive refinement failed")
            status = why if why.startswith("failed: ") else f"failed: {why}"
        else:
            continue
        row |= {"status": status, "failure": why, "failed_L_over_r": at,
                **dict.fromkeys(NO_TRANSITION)}  # fmt: skip
        transition_of[key] = replace(t, status="failed", L_over_r_trans=None,
                                     L_over_r_intercept=None, delta_L_over_r=None)  # fmt: skip


REFERENCE_STITCH = "stockinette_free"
"""The stitch every pattern is quoted against: the free periodic yarn (docs/model.md §11),
the patterns' own representation; the paper's ansatz (the default stitch) beside it."""
SHIFTS = {"shift_vs_free": REFERENCE_STITCH, "shift_vs_ansatz": DEFAULT_STITCH}
"""Transition fields: (L/r)_trans minus that of the same series of this stitch."""


def add_reference_shifts(rows: list[dict[str, Any]]) -> None:
    """Each transition row's (L/r)_trans minus that of the free stockinette yarn
    (``shift_vs_free``) and of the paper's ansatz (``shift_vs_ansatz``) in the same
    direction and with the same other parameters; None where either has no transition
    (or the study has no such series)."""
    trans = {(series_key(r), r["direction"]): r["L_over_r_trans"] for r in rows
             if r["status"] == "transition"}  # fmt: skip
    at = SERIES_PARAMS.index("stitch")
    for row in rows:
        mine = trans.get((series_key(row), row["direction"]))
        for field, stitch in SHIFTS.items():
            key = series_key(row)
            ref = trans.get(((*key[:at], stitch, *key[at + 1 :]), row["direction"]))
            row[field] = None if mine is None or ref is None else mine - ref


def series_text(row: Mapping[str, Any]) -> str:
    """'k = 0.1, B = 90, r_core = 0.325, r = 0.74, p = 2.4' (no units; the stitch first
    unless it is the default one)."""
    return ", ".join(f"{PARAM_SYMBOLS[k][0]} = {value_text(row[k])}" for k in SERIES_PARAMS
                     if k != "stitch" or row[k] != DEFAULT_STITCH)  # fmt: skip
