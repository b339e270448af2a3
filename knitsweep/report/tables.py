"""The reduction as CSV files and as a printed table (paper Fig. 4, Table S4).

CSV columns carry their units in their names (``L_mm``, ``Y_sec_N_per_mm``,
``delta_E_c_mJ``, ``F_self_x_N``; ``knitsweep.quantities``); energies and gaps are in
mJ (= N·mm, the paper's "J"); L/r and strains are dimensionless. Empty cells mean "not available" (e.g. σ0 of a sweep
without a linear regime). Every file has a ``partial`` column, true when the
results file is not a complete run.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..quantities import PARAM_SYMBOLS, table_column, value_text
from ..util.safe_files import make_output_dir, replace_file
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
    f = io.StringIO(newline="")
    w = csv.writer(f)
    w.writerow([table_column(c) for c in columns])
    for row in rows:
        w.writerow([_cell(row.get(c)) for c in columns])
    return replace_file(path, f.getvalue().encode())  # never through a symbolic link


def write_tables(
    results: Results, out_dir: str | Path, written_one: Callable[[Path], None] | None = None
) -> list[Path]:
    """Write transitions.csv, sweeps.csv, points.csv and problems.csv into ``out_dir``:
    the DataFrames of ``knitsweep.load`` (same columns, same order) plus ``partial``;
    ``written_one`` hears each path as soon as it is written.

    Returns:
        The paths written, in the order of :data:`TABLES`.
    """
    out = make_output_dir(out_dir)
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


def series_label(values: Mapping[str, Any], names: Iterable[str]) -> str:
    """'stitch = garter, k = 0.1 mN/mm², B = 90 mN·mm²' for the given series parameter
    names."""
    parts = []
    for name in names:
        symbol, unit = PARAM_SYMBOLS[name]
        parts.append(f"{symbol} = {value_text(values[name])}{f' {unit}' if unit else ''}")
    return ", ".join(parts)


@dataclass(frozen=True)
class SummaryColumn:
    """One column of the transitions summary (the text table and the HTML report):
    its header, the fields of ``series.transition_row`` it shows (two for a range) and how
    each is formatted (a ``format`` spec)."""

    header: str
    fields: tuple[str, ...]
    spec: str = ""
    optional: bool = False  # shown only where some row has a value (the text table)
    hide_zero: bool = False  # (optional) a value of 0 counts as none

    def has_value(self, row: Mapping[str, Any]) -> bool:
        """Whether ``row`` has a value to show in this column."""
        return any(row.get(f) is not None and not (self.hide_zero and row[f] == 0)
                   for f in self.fields)  # fmt: skip


TRANSITION_SUMMARY = (
    SummaryColumn("status", ("status",)),
    SummaryColumn("(L/r)_trans", ("L_over_r_trans",), ".3f"),
    SummaryColumn("bracket", ("bracket_lower", "bracket_upper"), ".3f"),
    SummaryColumn("L_trans (mm)", ("L_trans_mm",), ".3f"),
    SummaryColumn("ΔL/r", ("delta_L_over_r",), ".3f"),
    SummaryColumn("vs free", ("shift_vs_free",), "+.3f", optional=True),
    SummaryColumn("vs ansatz", ("shift_vs_ansatz",), "+.3f", optional=True),
    SummaryColumn("fit slope (mJ/mm)", ("fit_slope_mJ_per_mm",), ".3e"),
    SummaryColumn("fit intercept (mJ)", ("fit_intercept_mJ",), ".3e"),
    SummaryColumn("fit L (mm)", ("fit_L_lo_mm", "fit_L_hi_mm"), ".2f"),
    SummaryColumn("n_jam", ("n_jammed",)),
    SummaryColumn("missing", ("n_missing",)),
    SummaryColumn("jammed after", ("n_jammed_after",), optional=True, hide_zero=True),
    SummaryColumn("within round-off at L (mm)", ("round_off_at_L_mm",), optional=True),
)
"""The transitions summary after the direction and the series parameters that vary:
the one list of its columns (``series.transition_row`` holds every field, for the CSV)."""


def _fmt(value: Any, spec: str = ".4g") -> str:
    if value is None:
        return "–"
    return format(value, spec)


def summary_cell(column: SummaryColumn, row: Mapping[str, Any]) -> str:
    """A transitions-summary cell: one value, a bracket '[lo, hi]' or a fitted range
    'lo–hi' (one dash when there is no fit)."""
    values = [row.get(f) for f in column.fields]
    if len(values) == 1:
        v = values[0]
        return _fmt(v, column.spec) if column.spec else ("–" if v is None else str(v))
    lo, hi = values
    if column.header == "bracket":
        return f"[{_fmt(lo, column.spec)}, {_fmt(hi, column.spec)}]"
    return "–" if lo is None or hi is None else f"{lo:{column.spec}}–{hi:{column.spec}}"


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
    shown = [c for c in TRANSITION_SUMMARY
             if not c.optional or any(c.has_value(t) for t in red.transitions)]  # fmt: skip
    head = ["dir", *(PARAM_SYMBOLS[k][0] for k in red.varying), *(c.header for c in shown)]
    body = [[t["direction"], *(value_text(t[k]) for k in red.varying),
             *(summary_cell(c, t) for c in shown)]
            for t in red.transitions]  # fmt: skip
    widths = [max(len(r[i]) for r in [head, *body]) for i in range(len(head))]
    for r in [head, *body]:
        lines.append("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip())
    lines.append(
        "gap: ΔE_c (mJ) for x, ΔE_b (mJ) for y"
        + (
            ""
            if all(t["direction"] in ("x", "y") for t in red.transitions)
            else ", the leading period's along the other paths (ΔE_c for biaxial, strip_x)"
        )
        + f"; threshold {red.threshold:g} mJ; "
        "bracket = (last jammed, first unjammed L/r); fit = jamming gap against L over its "
        "linear jammed run (Table S4)"
        + (
            "; jammed after: points beyond (L/r)_trans whose gap is above the threshold "
            "again (the transition is the first crossing, the paper's definition)"
            if any(t.get("n_jammed_after") for t in red.transitions)
            else ""
        )
        + (
            "; vs free, vs ansatz: (L/r)_trans minus that of the free stockinette yarn and of "
            "the paper's ansatz in the same direction"
            if any(c.header == "vs free" for c in shown)
            else ""
        )
        + (
            "; within round-off: L where a gap lies within its spread over starts "
            "([starts] spread) of the threshold"
            if any(c.fields == ("round_off_at_L_mm",) for c in shown)
            else ""
        )
    )
    return "\n".join(lines)


def problems_text(red: Reduction, limit: int = 20) -> list[str]:
    """One line per failed, not-knittable or unanalysable task (at most ``limit``)."""
    lines = []
    for p in red.problems[:limit]:
        if p["status"] == "damaged":  # its parameters are not trusted either
            lines.append(f"damaged: {p['kind']} {p['task_id']} in {p['file']}: {p['message']}")
            continue
        where = f"{p['direction']}, " if p["direction"] else ""
        lines.append(
            f"{p['status']}: {p['kind']} {p['task_id']} ({where}L = {p['L_mm']:g} mm, "
            f"{series_label(p, red.varying) or 'series'}): {p['message']}"
        )
    if len(red.problems) > limit:
        lines.append(f"… and {len(red.problems) - limit} more (problems.csv)")
    return lines
