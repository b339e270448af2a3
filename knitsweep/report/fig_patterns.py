"""Stitch patterns side by side: the unjamming transition (L/r)_trans, the secant modulus
Y_sec and the zero-force aspect ratio a_y/a_x of each pattern, pulled in x and in y.

Drawn when a study holds two or more stitches (``[grid] stitch = [...]``, e.g.
``jobs/patterns_k0.1.toml``). a_x and a_y are the per-stitch course and wale spacings
for every pattern and the strain is the fabric's, so the patterns compare directly.
Takes a :class:`~.reduce.Reduction` and a list for notes, returns a matplotlib Figure or
raises :class:`~.plotting.SkipFigure`.
"""

from __future__ import annotations

from typing import Any

from ..stitches import STITCH_NAMES
from .plotting import (
    DIRECTION_COLOUR,
    L_OVER_R,
    SkipFigure,
    narrow,
    new_figure,
    panel_title,
    series_rows,
    title,
)
from .reduce import Reduction
from .series import REFERENCE_STITCH, series_key

STITCH_COLOUR = {
    "stockinette": "#444444",
    "stockinette_free": "#9a9a9a",
    "garter": "#d9730d",
    "rib": "#2e8b46",
    "seed": "#b0306a",
}
"""One colour per pattern (others, such as charts: ``OTHER_COLOURS``)."""
OTHER_COLOURS = ("C0", "C3", "C4", "C5", "C9", "C8", "C6", "C7")
"""matplotlib's cycle without its green and orange, which the named patterns' are near."""
DIRECTION_STYLE = {"x": ("-", "o"), "y": ("--", "s")}
"""Line style and marker of a pull in x (across the course) and in y (along the wale)."""


def _colour(stitch: str, i: int) -> str:
    return STITCH_COLOUR.get(stitch, OTHER_COLOURS[i % len(OTHER_COLOURS)])


def _one_series_per_stitch(red: Reduction, notes: list[str]) -> dict[str, tuple[Any, ...]]:
    """Each stitch's series key (stitch, k, B, …); with several per stitch (another
    parameter varies too), the first, and a note saying so."""
    keys: dict[str, list[tuple[Any, ...]]] = {}
    for row in red.sweeps:
        keys.setdefault(str(row["stitch"]), []).append(series_key(row))
    chosen = {}
    known = {name: i for i, name in enumerate(STITCH_NAMES)}  # stockinette, the reference, first
    for stitch, ks in sorted(keys.items(), key=lambda kv: (known.get(kv[0], len(known)), kv[0])):
        unique = sorted(set(ks))
        chosen[stitch] = unique[0]
        if len(unique) > 1:
            notes.append(f"patterns: {stitch} has {len(unique)} series; showing the first")
    return chosen


FAILED_COLOUR = "#c00000"
"""The mark of a series whose refinement failed (no transition)."""


def figP_patterns(red: Reduction, notes: list[str]) -> Any:
    """(a) (L/r)_trans of each pattern in x and y, the bar its bracket (a triangle at the
    range's end: jammed throughout ▲, unjammed from the first L ▼; a red × where the
    series failed and has no transition), the free stockinette yarn's as lines across;
    (b) each pattern's shift of (L/r)_trans against the free stockinette yarn (the paper's
    ansatz among them), the bar the two brackets together; (c) Y_sec against L/r, one
    colour per pattern, x solid and y dashed; (d) the zero-force aspect ratio a_y0/a_x0
    against L/r."""
    chosen = _one_series_per_stitch(red, notes)
    if len(chosen) < 2:
        raise SkipFigure("needs sweeps of two or more stitch patterns")
    from matplotlib.lines import Line2D

    stitches = list(chosen)
    fig = new_figure(11.0, 8.4, wide=True)  # four panels: page-wide in a journal
    (ax_t, ax_s), (ax_y, ax_a) = fig.subplots(2, 2)
    trans = {(series_key(t), t["direction"]): t for t in red.transitions}
    _reference_lines(ax_t, trans, chosen)
    shifted = _shifts(ax_s, trans, chosen, stitches)
    beyond = failed = False
    curves: list[tuple[list, list, dict]] = []  # Y_sec against L/r, drawn once the scale is known
    for i, stitch in enumerate(stitches):
        key = chosen[stitch]
        colour = _colour(stitch, i)
        for j, d in enumerate(("x", "y")):
            ls, marker = DIRECTION_STYLE[d]
            t = trans.get((key, d))
            pos = i + (j - 0.5) * 0.3
            style = {"color": DIRECTION_COLOUR[d], "mfc": colour, "ls": "none"}
            rows = series_rows(red, key, d)  # by L/r
            if t is not None and t["status"] == "transition":
                value, lower = t["L_over_r_trans"], t["bracket_lower"]
                ax_t.errorbar([pos], [value], yerr=[[value - lower], [0.0]], marker=marker,
                              ms=6, capsize=3, **style)  # fmt: skip
            elif t is not None and str(t["status"]).startswith("failed"):
                failed = True  # never shown as a transition: a cross where it was looked for
                at = t.get("failed_L_over_r") or (rows[len(rows) // 2]["L_over_r"] if rows
                                                  else None)  # fmt: skip
                if at is not None:
                    ax_t.plot([pos], [at], marker="x", ms=9, mew=2.2, color=FAILED_COLOUR,
                              ls="none")  # fmt: skip
                notes.append(f"patterns: {stitch} in {d}: {t['status']}")
            elif t is not None and rows:  # no crossing inside the L range: an arrow out of it
                up, beyond = t["status"] == "jammed_throughout", True
                edge = rows[-1 if up else 0]["L_over_r"]  # the largest L/r, or the smallest
                ax_t.plot([pos], [edge], marker="^" if up else "v", ms=8, **style)
                notes.append(f"patterns: {stitch} in {d}: {t['status'].replace('_', ' ')}")
            rows = [r for r in rows if r["Y_sec_N_per_mm"] is not None]
            if rows:
                curves.append(([r["L_over_r"] for r in rows], [r["Y_sec_N_per_mm"] for r in rows],
                               {"color": colour, "ls": ls, "marker": marker, "ms": 4}))  # fmt: skip
        pts = sorted((r for r in red.points if series_key(r) == key
                      and r.get("aspect_ratio") is not None), key=lambda r: r["L_over_r"])  # fmt: skip
        if pts:
            ax_a.plot([r["L_over_r"] for r in pts], [r["aspect_ratio"] for r in pts],
                      color=colour, marker="o", ms=4)  # fmt: skip
    ax_t.set_xticks(range(len(stitches)))
    ax_t.set_xticklabels(stitches, rotation=30 if narrow() or len(stitches) > 3 else 0)
    ax_t.set_xlim(-0.6, len(stitches) - 0.4)
    ax_t.set_ylabel(r"$(L/r)_{\rm trans}$")
    ax_t.set_title(
        "(a) unjamming transition\nbar: bracket"
        + ("; ▲▼: beyond the L range" if beyond else "")
        + ("; ×: failed" if failed else "")
    )
    if not shifted:
        notes.append(f"patterns: no {REFERENCE_STITCH} transition to quote the patterns against")
        ax_s.text(0.5, 0.5, f"no {REFERENCE_STITCH} transition\nin these results",
                  ha="center", va="center", transform=ax_s.transAxes, color="0.4")  # fmt: skip
        ax_s.set_yticks([])
    ax_y.set_xlabel(L_OVER_R)
    ax_y.set_ylabel(r"secant modulus $Y_{\rm sec}$ (N/mm)")
    positive = [v for _, ys, _ in curves for v in ys if v > 0]
    log = bool(positive) and max(positive) > 10 * min(positive)  # patterns differ by decades
    hidden = 0
    for xs, ys, st in curves:
        if log:  # a secant modulus <= 0 (the stress at 2 % strain below zero) has no place
            keep = [i for i, v in enumerate(ys) if v > 0]
            hidden += len(ys) - len(keep)
            xs, ys = [xs[i] for i in keep], [ys[i] for i in keep]
        ax_y.plot(xs, ys, **st)
    if log:
        ax_y.set_yscale("log")
        if hidden:
            notes.append(f"patterns: {hidden} sweep(s) with Y_sec <= 0 left off the log axis")
    elif min((v for _, ys, _ in curves for v in ys), default=0.0) >= 0.0:
        ax_y.set_ylim(bottom=0.0)
    else:
        ax_y.axhline(0.0, color="0.55", lw=0.8, zorder=0)
    panel_title(ax_y, r"(c) $Y_{\rm sec} = \sigma(0.02)/0.02$")
    ax_a.set_xlabel(L_OVER_R)
    ax_a.set_ylabel(r"aspect ratio $a_{y0}/a_{x0}$")
    panel_title(ax_a, "(d) zero-force stitch shape")
    handles = [Line2D([], [], color=DIRECTION_COLOUR[d], marker=DIRECTION_STYLE[d][1],
                      ls="none", label=f"pulled in {d}") for d in ("x", "y")]  # fmt: skip
    if any((chosen.get(REFERENCE_STITCH), d) in trans for d in ("x", "y")):
        handles.append(Line2D([], [], color=STITCH_COLOUR[REFERENCE_STITCH], lw=1.0,
                              label="free stockinette (x ─, y ‑‑)"))  # fmt: skip
    ax_t.legend(handles=handles, loc="best", frameon=False)
    ax_y.legend(handles=[Line2D([], [], color="0.3", ls=DIRECTION_STYLE[d][0],
                                marker=DIRECTION_STYLE[d][1], ms=4, label=f"pulled in {d}")
                         for d in ("x", "y")], loc="best", frameon=False)  # fmt: skip
    ax_a.legend(handles=[Line2D([], [], color=_colour(s, i), marker="o", ms=4, label=s)
                         for i, s in enumerate(stitches)], loc="best", frameon=False)  # fmt: skip
    title(fig, red, "Stitch patterns against the free stockinette yarn: transition, stiffness "
          "and shape")  # fmt: skip
    return fig


def _reference_lines(ax: Any, trans: dict, chosen: dict[str, tuple[Any, ...]]) -> None:
    """The free stockinette yarn's (L/r)_trans in x (solid) and y (dashed) across panel (a)."""
    key = chosen.get(REFERENCE_STITCH)
    for d in ("x", "y"):
        t = trans.get((key, d))
        if t is not None and t["status"] == "transition":
            ax.axhline(t["L_over_r_trans"], color=STITCH_COLOUR[REFERENCE_STITCH], lw=1.0,
                       ls=DIRECTION_STYLE[d][0], zorder=0)  # fmt: skip


def _shifts(ax: Any, trans: dict, chosen: dict[str, tuple[Any, ...]], stitches: list[str]) -> bool:
    """Panel (b): (L/r)_trans − that of the free stockinette yarn (``shift_vs_free``) for
    every other stitch, x and y, the bar the two brackets' widths added; whether any."""
    drawn = False
    ref = chosen.get(REFERENCE_STITCH)
    others = [s for s in stitches if s != REFERENCE_STITCH]
    for i, stitch in enumerate(others):
        colour = _colour(stitch, stitches.index(stitch))
        for j, d in enumerate(("x", "y")):
            t, r = trans.get((chosen[stitch], d)), trans.get((ref, d))
            if t is None or r is None or t.get("shift_vs_free") is None:
                continue
            err = sum(v["L_over_r_trans"] - v["bracket_lower"] for v in (t, r))
            ax.errorbar([i + (j - 0.5) * 0.3], [t["shift_vs_free"]], yerr=[[err], [err]],
                        marker=DIRECTION_STYLE[d][1], ms=6, capsize=3, ls="none",
                        color=DIRECTION_COLOUR[d], mfc=colour)  # fmt: skip
            drawn = True
    ax.axhline(0.0, color=STITCH_COLOUR[REFERENCE_STITCH], lw=1.0, zorder=0)
    ax.set_xticks(range(len(others)))
    ax.set_xticklabels(others, rotation=30 if narrow() or len(others) > 3 else 0)
    ax.set_xlim(-0.6, len(others) - 0.4)
    ax.set_ylabel(r"$(L/r)_{\rm trans} - (L/r)_{\rm trans,\,free}$")
    ax.set_title("(b) against the free stockinette yarn\nbar: both brackets")
    return drawn
