"""The reduction as CSV files and as a printed table (paper Fig. 4, Table S4).

CSV columns carry their units in their names (``L_mm``, ``Y_sec_N_per_mm``,
``delta_E_c_mJ``, ``F_self_x_N``; ``knitsweep.quantities``); energies and gaps are in
mJ (= N·mm, the paper's "J"); L/r and strains are dimensionless. Empty cells mean "not available" (e.g. σ0 of a sweep
without a linear regime). Every file has a ``partial`` column, true when the
results file is not a complete run.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..quantities import PARAM_SYMBOLS, table_column
from .reduce import Reduction
from .results import Results

TABLES = ("transitions.csv", "sweeps.csv", "points.csv", "problems.csv")


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "" if not math.isfinite(value) else f"{value:.10g}"
    return str(value)


def write_csv(path: Path, rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> Path:
    """Write ``rows`` with the given column order (missing keys → empty cells); the
    header names each column as ``knitsweep.quantities`` does (unit suffixes), the
    same names as the DataFrames of ``knitsweep.load``."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow([table_column(c) for c in columns])
        for row in rows:
            w.writerow([_cell(row.get(c)) for c in columns])
    return path


def write_tables(
    results: Results, out_dir: str | Path, written_one: Callable[[Path], None] | None = None
) -> list[Path]:
    """Write transitions.csv, sweeps.csv, points.csv and problems.csv into ``out_dir``:
    the DataFrames of ``knitsweep.load`` (same columns, same order) plus ``partial``;
    ``written_one`` hears each path as soon as it is written.

    Returns:
        The paths written, in the order of :data:`TABLES`.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, frame in zip(TABLES, (results.transitions, results.sweeps, results.points,
                                    results.problems), strict=True):  # fmt: skip
        rows = [{k: _missing(v) for k, v in row.items()} for row in frame.to_dict("records")]
        rows = [{**r, "partial": results.partial} for r in rows]
        written.append(write_csv(out / name, rows, [*frame.columns, "partial"]))
        if written_one is not None:
            written_one(written[-1])
    return written


def _missing(value: Any) -> Any:
    """pandas' missing values (NaN, NA, None) as None: an empty cell."""
    import pandas as pd

    return None if not isinstance(value, (list, tuple)) and pd.isna(value) else value


def series_label(values: Mapping[str, float], names: Iterable[str]) -> str:
    """'k = 0.1 mN/mm², B = 90 mN·mm²' for the given series parameter names."""
    parts = []
    for name in names:
        symbol, unit = PARAM_SYMBOLS[name]
        parts.append(f"{symbol} = {values[name]:g}{f' {unit}' if unit else ''}")
    return ", ".join(parts)


def _fmt(value: Any, spec: str = ".4g") -> str:
    if value is None:
        return "–"
    return format(value, spec)


def _fit_range(lo: float | None, hi: float | None) -> str:
    """'10.50–11.20' (mm), or one dash when there is no fit."""
    return "–" if lo is None or hi is None else f"{lo:.2f}–{hi:.2f}"


def transitions_text(red: Reduction) -> str:
    """The transitions as an aligned text table (one line per series and direction).

    Only the series parameters that vary in the file get a column; the others are
    listed once above the table.
    """
    if not red.transitions:
        return "no analysed sweeps: no transitions"
    lines = []
    if red.constants:
        lines.append("fixed: " + series_label(red.constants, red.constants))
    head = ["dir", *(PARAM_SYMBOLS[k][0] for k in red.varying), "status", "(L/r)_trans",
            "bracket", "L_trans (mm)", "ΔL/r", "fit slope (mJ/mm)", "fit intercept (mJ)", "fit L (mm)",
            "n_jam", "missing"]  # fmt: skip
    body = []
    for t in red.transitions:
        lo, hi = t["bracket_lower"], t["bracket_upper"]
        body.append([
            t["direction"],
            *(f"{t[k]:g}" for k in red.varying),
            t["status"],
            _fmt(t["L_over_r_trans"], ".3f"),
            f"[{_fmt(lo, '.3f')}, {_fmt(hi, '.3f')}]",
            _fmt(t["L_trans_mm"], ".3f"),
            _fmt(t["delta_L_over_r"], ".3f"),
            _fmt(t["fit_slope_mJ_per_mm"], ".3e"),
            _fmt(t["fit_intercept_mJ"], ".3e"),
            _fit_range(t["fit_L_lo_mm"], t["fit_L_hi_mm"]),
            str(t["n_jammed"]),
            str(t["n_missing"]),
        ])  # fmt: skip
    widths = [max(len(r[i]) for r in [head, *body]) for i in range(len(head))]
    for r in [head, *body]:
        lines.append("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip())
    lines.append(
        f"gap: ΔE_c (mJ) for x, ΔE_b (mJ) for y; threshold {red.threshold:g} mJ; "
        "bracket = (last jammed, first unjammed L/r); fit = jamming gap against L over its "
        "linear jammed run (Table S4)"
    )
    return "\n".join(lines)


def problems_text(red: Reduction, limit: int = 20) -> list[str]:
    """One line per failed, not-knittable or unanalysable task (at most ``limit``)."""
    lines = []
    for p in red.problems[:limit]:
        where = f"{p['direction']}, " if p["direction"] else ""
        lines.append(
            f"{p['status']}: {p['kind']} {p['task_id']} ({where}L = {p['L_mm']:g} mm, "
            f"{series_label(p, red.varying) or 'series'}): {p['message']}"
        )
    if len(red.problems) > limit:
        lines.append(f"… and {len(red.problems) - limit} more (problems.csv)")
    return lines
