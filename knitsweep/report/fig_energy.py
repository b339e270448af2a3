"""Energy-gap figures: the gaps against L/r (paper Fig. 3, Fig. S15), the jammed-regime
fit and ΔL/r of each series (Fig. 4a, Table S4), the width of the transition ΔL/r
against k (Fig. 4b), and the regimes over k, B, r_core … (Fig. 4c).

Each function takes a :class:`~.reduce.Reduction` and a list for notes, and returns a
matplotlib Figure or raises :class:`~.plotting.SkipFigure` saying what is missing.
Energies in mJ (= N·mm, the paper's "J"); L/r dimensionless.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..analysis.paper import TABLE_S4, at_table_1
from ..analysis.transitions import Transition
from ..paths import load_path
from ..quantities import PARAMETER_NAMES, SERIES_PARAMS
from .declutter import movable
from .path_style import PerPath, path_order
from .plotting import (
    BENDING_COLOUR,
    BRACKET_FILL,
    CONTACT_COLOUR,
    DIRECTION_COLOUR,
    L_OVER_R,
    LINESTYLES,
    MARKERS,
    REGIME_FILL,
    REGIME_LABEL,
    THRESHOLD_COLOUR,
    TRANSITION_LINE,
    SkipFigure,
    caption,
    current_options,
    grid_of_panels,
    label_of,
    legend_columns,
    limit_panels,
    narrow,
    new_figure,
    parameter_axis,
    sci,
    series_keys,
    series_legend,
    series_rows,
    title,
)
from .reduce import Reduction
from .series import series_key
from .tables import series_label

_GAP_SYMBOL = {
    "delta_E_c": r"$\Delta E_c$",
    "delta_E_b": r"$\Delta E_b$",
}
GAP_LABEL = PerPath({}, lambda path: _GAP_SYMBOL[load_path(path).gap])
"""The jamming gap of each load path (a ray's: its leading period's), as a label."""


def _gap_panel(ax: Any, red: Reduction, rows: list[dict], t: Transition | None, d: str,
               log: bool) -> None:  # fmt: skip
    x = np.array([r["L_over_r"] for r in rows])
    gc = np.array([r["delta_E_c"] for r in rows])
    gb = np.array([r["delta_E_b"] for r in rows])
    floor = red.threshold / 50.0
    if t is not None and t.status == "transition":
        ax.axvspan(t.bracket_lower, t.bracket_upper, color=BRACKET_FILL, alpha=0.7, lw=0,
                   label="transition bracket")  # fmt: skip
        ax.axvline(t.L_over_r_trans, color="0.25", ls="--", lw=1.2,
                   label=r"$(L/r)_{\rm trans}$")  # fmt: skip
        ax.text(t.L_over_r_trans, 1.0, f" {t.L_over_r_trans:.2f}", transform=ax.get_xaxis_transform(),
                ha="left", va="top", fontsize="medium", color="0.2")  # fmt: skip
    for g, colour, marker, name in ((gc, CONTACT_COLOUR, "o", r"$\Delta E_c$ (contact)"),
                                    (gb, BENDING_COLOUR, "s", r"$\Delta E_b$ (bending)")):  # fmt: skip
        y = np.maximum(g, floor) if log else g
        ax.plot(x, y, color=colour, marker=marker, label=name, zorder=3)
        if log and np.any(g < floor):
            low = g < floor
            ax.plot(x[low], y[low], ls="none", marker=marker, mfc="white", mec=colour, zorder=4)
    ax.axhline(red.threshold, color=THRESHOLD_COLOUR, ls=":", lw=1.2,
               label=f"threshold {red.threshold:g} mJ")  # fmt: skip
    if not log and t is not None and t.fit is not None:
        _fit_line(ax, t, CONTACT_COLOUR if d == "x" else BENDING_COLOUR, float(x[0]), red.threshold)
    if t is not None and t.status != "transition":
        text = ("jammed at every L" if t.status == "jammed_throughout"
                else "failed: no transition" if t.status == "failed"
                else "unjammed from the first L")  # fmt: skip
        if narrow():
            text = text.replace(" at ", "\nat ").replace(" from ", "\nfrom ")
        movable(ax.text(0.98, 0.45 if log else 0.97, text, transform=ax.transAxes, ha="right",
                        va="center" if log else "top", fontsize="medium", color="0.25",
                        bbox={"fc": "white", "ec": "0.7", "pad": 2.5}))  # fmt: skip
    if log:
        from matplotlib.ticker import LogLocator

        ax.set_yscale("log")
        ax.set_ylim(bottom=floor / 1.6)
        # gaps span many decades: minor ticks at 2 and 5 only (all eight, on every
        # panel, were half of this figure's drawing time)
        ax.yaxis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))
        if np.any(np.minimum(gc, gb) < floor):
            ax.plot([], [], ls="none", marker="o", mfc="white", mec="0.3",
                    label=f"gap < {floor:.0e} mJ (drawn at {floor:.0e})")  # fmt: skip
    else:
        ax.set_ylim(bottom=-0.04 * max(float(np.max(gc)), float(np.max(gb)), red.threshold))
        ax.ticklabel_format(axis="y", style="sci", scilimits=(0, 0), useMathText=True)
    ax.set_xlabel(L_OVER_R)
    ax.set_ylabel("energy gap (mJ)")


def _fit_line(ax: Any, t: Transition, colour: str, x_first: float, threshold: float) -> None:
    """The Table S4 line: solid over the fitted (linear) run, dotted from the densest
    point to its zero; the zero marked (x), and ΔL/r as an arrow from it to
    (L/r)_trans, drawn at three times the threshold."""
    f = t.fit
    run = np.array([t.fit_lower, t.fit_upper])
    ax.plot(run, f.intercept + f.slope * run, color=colour, lw=2.4, alpha=0.45, zorder=2,
            solid_capstyle="butt", label="jammed-regime fit (linear run)")  # fmt: skip
    x0 = t.L_over_r_intercept
    if x0 is None:
        return
    xs = np.array([min(x_first, t.fit_lower), x0])
    ax.plot(xs, f.intercept + f.slope * xs, color=colour, ls=(0, (1, 1.5)), lw=1.3, zorder=2,
            label="fit extended to zero gap")  # fmt: skip
    ax.plot([x0], [0.0], ls="none", marker="x", color=colour, ms=8, mew=1.8, zorder=5)
    if t.delta_L_over_r is not None and t.L_over_r_trans is not None:
        y = 3.0 * threshold
        ax.annotate("", xy=(t.L_over_r_trans, y), xytext=(x0, y),
                    arrowprops={"arrowstyle": "<->", "color": "0.2", "lw": 1.2,
                                "shrinkA": 0, "shrinkB": 0}, zorder=6)  # fmt: skip
        movable(ax.text(max(x0, t.L_over_r_trans), y, f"  ΔL/r = {t.delta_L_over_r:.3f}"
                        + ("\n  (zero beyond the transition)" if t.delta_L_over_r < 0 else ""),
                        ha="left", va="center", fontsize="medium", color="0.2",
                        bbox={"fc": "white", "ec": "none", "alpha": 0.8, "pad": 1.0}))  # fmt: skip


def fig3_energy_gaps(red: Reduction, notes: list[str], log: bool = False) -> Any:
    """Gaps ΔE_c (coral) and ΔE_b (blue) against L/r, one panel per series and
    direction; threshold line, transition bracket shaded (paper Fig. 3; log: Fig. S15)."""
    keys = [k for k in series_keys(red) if len({c.L_mm for c in red.curves if c.series == k}) >= 2]
    if not keys:
        raise SkipFigure("needs a series with sweeps at ≥ 2 values of L")
    keys = limit_panels(keys, "fig3", notes)
    # the paper's figure: the uniaxial paths (the in-plane figure has the others' transitions)
    present = path_order({c.direction for c in red.curves})
    directions = [d for d in present if d in ("x", "y")] or present
    # x and y side by side are too dense for one column: a page-wide figure
    fig = new_figure(max(8.0, 5.2 * len(directions) + 0.4), 3.2 * len(keys) + 1.5,
                     wide=len(directions) > 1)  # fmt: skip
    axes = fig.subplots(len(keys), len(directions), squeeze=False, sharex=True)
    handles: dict[str, Any] = {}
    for i, key in enumerate(keys):
        for j, d in enumerate(directions):
            ax = axes[i, j]
            rows = series_rows(red, key, d)
            if not rows:
                ax.set_axis_off()
                continue
            _gap_panel(ax, red, rows, red.transition_of.get((key, d)), d, log)
            lab = label_of(red, key)
            head = (f"{d}: {GAP_LABEL[d]}" if current_options().width == "column"
                    else f"pulled in {d}: jamming gap {GAP_LABEL[d]}")  # fmt: skip
            ax.set_title(head + (f"\n{lab}" if lab else ""))
            for h, name in zip(*ax.get_legend_handles_labels(), strict=True):
                handles.setdefault(name, h)
            ax.xaxis.set_tick_params(labelbottom=True)
    fig.legend(handles.values(), handles.keys(), loc="outside lower center",
               ncols=legend_columns(min(len(handles), 4)), frameon=False)  # fmt: skip
    scale = "log scale" if log else "linear scale"
    title(fig, red, f"Energy gaps against $L/r$ ({scale})")
    return fig


def _paper_line(key: tuple, d: str) -> Any:
    """Paper Table S4's row for an x series at Table 1's B, r_core, r, p, else None."""
    params = dict(zip(SERIES_PARAMS, key, strict=True))
    return TABLE_S4.get(params["k_mN_per_mm2"]) if d == "x" and at_table_1(params) else None


def fig4a_gap_fit(red: Reduction, notes: list[str]) -> Any:
    """The jamming gap of each series with its Table S4 line (paper Fig. 4a): fitted
    points filled, the curved transition region hollow, the line's zero, (L/r)_trans
    and ΔL/r; the paper's Table S4 line where it has one (x, Table 1 values)."""
    panels = [(key, d) for (key, d), t in sorted(red.transition_of.items()) if t.fit is not None]
    if not panels:
        raise SkipFigure("needs a series with ≥ 2 jammed points (a jammed-regime fit)")
    panels = limit_panels(panels, "fig4a", notes)
    ncols = min(len(panels), 2)  # two panels a row: a page-wide figure
    fig = new_figure(6.4 * ncols + 0.4, 4.2 * -(-len(panels) // ncols) + 1.4, wide=ncols > 1)
    handles: dict[str, Any] = {}
    for ax, (key, d) in zip(grid_of_panels(fig, len(panels), ncols), panels, strict=True):
        t = red.transition_of[(key, d)]
        rows = series_rows(red, key, d)
        r_mm = dict(zip(SERIES_PARAMS, key, strict=True))["r_mm"]
        x = np.array([r["L_over_r"] for r in rows])
        g = np.array([r["jamming_gap"] for r in rows])
        colour = CONTACT_COLOUR if d == "x" else BENDING_COLOUR
        fitted = (x >= t.fit_lower - 1e-12) & (x <= t.fit_upper + 1e-12)
        ax.plot(x[fitted], g[fitted], ls="none", marker="o", color=colour, zorder=4,
                label="fitted: the linear jammed run")  # fmt: skip
        ax.plot(x[~fitted], g[~fitted], ls="none", marker="o", mfc="white", mec=colour, zorder=4,
                label="not fitted (transition region, unjammed)")  # fmt: skip
        _fit_line(ax, t, colour, float(x[0]), red.threshold)
        p = _paper_line(key, d)
        if p is not None:
            xs = np.array([x[0], p.zero_L_mm / r_mm])
            ax.plot(xs, p.intercept_mJ + p.slope_mJ_per_mm * r_mm * xs, color="0.45", ls="--",
                    lw=1.1, zorder=1, label="paper Table S4 line")  # fmt: skip
        if t.status == "transition":
            ax.axvline(t.L_over_r_trans, color="0.25", ls="--", lw=1.2,
                       label=r"$(L/r)_{\rm trans}$")  # fmt: skip
        ax.axhline(red.threshold, color=THRESHOLD_COLOUR, ls=":", lw=1.2,
                   label=f"threshold {red.threshold:g} mJ")  # fmt: skip
        ax.set_ylim(bottom=-0.04 * float(np.max(g[np.isfinite(g)], initial=red.threshold)))
        ax.ticklabel_format(axis="y", style="sci", scilimits=(0, 0), useMathText=True)
        ax.set_xlabel(L_OVER_R)
        ax.set_ylabel(f"{GAP_LABEL[d]} (mJ)")
        lab = label_of(red, key)
        width = t.delta_L_over_r
        fit = (
            f"{t.fit.n_points}-point fit: slope {sci(t.fit.slope / r_mm)} mJ/mm,\n"
            f"intercept {sci(t.fit.intercept)} mJ"
        )
        head = f"pulled in {d}" + (f", {lab}" if lab else "")
        tail = ("" if width is None else f"ΔL/r = {width:.3f}" + (
            " (the line's zero lies past (L/r)$_{\\rm trans}$)" if width < 0 else ""))  # fmt: skip
        ax.set_title("\n".join(filter(None, (head, fit, tail))), fontsize="medium")
        for h, name in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.setdefault(name, h)
    fig.legend(handles.values(), handles.keys(), loc="outside lower center",
               ncols=legend_columns(min(len(handles), 3)), frameon=False)  # fmt: skip
    title(fig, red, "Jammed-regime line fit and transition width ΔL/r (paper Fig. 4a, Table S4)")
    return fig


def fig4b_deltaL_vs_k(red: Reduction, notes: list[str]) -> Any:
    """ΔL/r against k per direction and per other parameters (paper Fig. 4b); error
    bars are the paper's "+0, −one step" of (L/r)_trans."""
    others = [p for p in SERIES_PARAMS if p != "k_mN_per_mm2"]
    groups: dict[tuple, list[dict]] = {}
    for t in red.transitions:
        if t["delta_L_over_r"] is not None:
            groups.setdefault((t["direction"], *(t[p] for p in others)), []).append(t)
    if len({t["k_mN_per_mm2"] for rows in groups.values() for t in rows}) < 2:
        raise SkipFigure("needs ≥ 2 values of k with a transition (and a jammed-regime fit) "
                         "in one series")  # fmt: skip
    fig = new_figure(7.6, 4.8)
    ax = fig.subplots()
    varying_others = [p for p in red.varying if p in others]
    style_of = {o: i for i, o in enumerate(sorted({g[1:] for g in groups}))}
    ks = []
    for j, (g, rows) in enumerate(sorted(groups.items())):
        rows = sorted(rows, key=lambda t: t["k_mN_per_mm2"])
        k = np.array([t["k_mN_per_mm2"] for t in rows])
        dodge = 1.0 + 0.025 * (j - (len(groups) - 1) / 2)  # keep error bars apart
        dl = np.array([t["delta_L_over_r"] for t in rows])
        step = np.array([t["L_over_r_trans"] - t["bracket_lower"] for t in rows])
        i = style_of[g[1:]]
        lab = series_label(dict(zip(others, g[1:], strict=True)), varying_others)
        ax.errorbar(k * dodge, dl, yerr=[step, np.zeros_like(step)], capsize=3,
                    color=DIRECTION_COLOUR[g[0]], marker=MARKERS[i % len(MARKERS)],
                    ls=LINESTYLES[i % len(LINESTYLES)], ms=7,
                    label=f"pulled in {g[0]}" + (f", {lab}" if lab else ""))  # fmt: skip
        ks += list(k)
    parameter_axis(ax, ks)
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set_xlabel(r"compression constant $k$ (mN/mm$^2$)")
    ax.set_ylabel(r"transition width $\Delta L/r$")
    note = (
        "ΔL/r = (L/r)$_{\\rm trans}$ − zero of the line through the linear jammed run; "
        "error bars: +0, −one step of $L/r$; series offset slightly in $k$"
    )
    series_legend(fig, ax, ax.get_legend_handles_labels()[0], frameon=False)
    caption(fig, ax, note.replace("; ", ";\n") if narrow() else note.replace("; e", ";\ne"),
            color="0.35")  # fmt: skip
    title(fig, red, r"Width of the jamming transition $\Delta L/r$ against $k$")
    return fig


def _trans_value(t: dict | None, top: float, bottom: float) -> float:
    """(L/r)_trans for drawing: above the axis if jammed throughout, below if
    unjammed from the start, NaN if the direction was not run or its series failed (no
    transition: ``series.mark_failed``)."""
    if t is None or str(t["status"]).startswith("failed"):
        return np.nan
    if t["status"] == "jammed_throughout":
        return top
    if t["status"] == "unjammed_at_start":
        return bottom
    return t["L_over_r_trans"]


def _regime_panel(ax: Any, xs: np.ndarray, tx: np.ndarray, ty: np.ndarray,
                  lim: tuple) -> set[str]:  # fmt: skip
    """Shade the regimes between the two (L/r)_trans lines over a parameter axis; the
    regimes shaded."""
    bottom, top = lim
    shown: set[str] = set()
    if np.all(np.isfinite(tx)) and np.all(np.isfinite(ty)):
        shown = {"jammed_xy", "unjammed"} if np.any(np.minimum(tx, ty) > bottom) else {"unjammed"}
        shown |= {"jammed_y_only"} if np.any(tx < ty) else set()
        shown |= {"jammed_x_only"} if np.any(tx > ty) else set()
        low, high = np.minimum(tx, ty), np.maximum(tx, ty)
        ax.fill_between(xs, bottom, low, color=REGIME_FILL["jammed_xy"], lw=0)
        ax.fill_between(xs, low, high, where=tx <= ty, interpolate=True, lw=0,
                        color=REGIME_FILL["jammed_y_only"])  # fmt: skip
        ax.fill_between(xs, low, high, where=tx > ty, interpolate=True, lw=0,
                        color=REGIME_FILL["jammed_x_only"])  # fmt: skip
        ax.fill_between(xs, high, top, color=REGIME_FILL["unjammed"], lw=0)
    ax.set_ylim(bottom, top)
    ax.set_xlim(xs[0], xs[-1])
    return shown


def _transition_marks(ax: Any, xs: np.ndarray, rows: list[dict | None], d: str,
                      lim: tuple, label: bool) -> None:  # fmt: skip
    bottom, top = lim
    y = np.array([_trans_value(t, top, bottom) for t in rows])
    colour = TRANSITION_LINE[d]
    # x drawn wide and y narrow on top, so that coinciding transitions show both colours
    wide = d == "x"
    ax.plot(xs, y, color=colour, lw=4.0 if wide else 1.8, marker="o" if wide else "s",
            ms=10 if wide else 5.5, zorder=4 if wide else 5, clip_on=False,
            label=rf"$(L/r)_{{\rm trans}}$, {d}" if label else None)  # fmt: skip
    for xi, t in zip(xs, rows, strict=True):
        if t is None or str(t["status"]).startswith("failed"):
            continue
        if t["status"] == "transition":
            step = t["L_over_r_trans"] - t["bracket_lower"]
            ax.errorbar([xi], [t["L_over_r_trans"]], yerr=[[step], [0.0]], color=colour,
                        capsize=3, lw=1.2, zorder=5)  # fmt: skip
        else:
            up = t["status"] == "jammed_throughout"
            ax.annotate("", xy=(xi, top if up else bottom),
                        xytext=(xi, top - 0.12 * (top - bottom) if up else bottom + 0.12 * (top - bottom)),
                        arrowprops={"arrowstyle": "->", "color": colour, "lw": 1.6},
                        zorder=6)  # fmt: skip


REGIMES = ("jammed_xy", "jammed_y_only", "jammed_x_only", "unjammed")


def _regime_legend(fig: Any, shown: set[str], with_lines: bool, markers: bool = False) -> None:
    """The figure's legend: every regime ``shown`` (in the order of ``REGIMES``), the
    transition lines (``with_lines``) or the sampled sweeps' markers (``markers``)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles = [Patch(color=REGIME_FILL[r], label=REGIME_LABEL[r]) for r in REGIMES if r in shown]
    if markers:
        handles += [Line2D([], [], ls="none", marker="o", ms=7, color=TRANSITION_LINE["x"],
                           label="sweep jammed (gap ≥ threshold)"),
                    Line2D([], [], ls="none", marker="o", ms=7, mfc="white",
                           color=TRANSITION_LINE["x"], label="sweep unjammed")]  # fmt: skip
    if with_lines:
        handles += [Line2D([], [], color=TRANSITION_LINE[d], lw=4.0 if d == "x" else 1.8,
                           marker="o" if d == "x" else "s", ms=10 if d == "x" else 5.5,
                           label=rf"$(L/r)_{{\rm trans}}$, pulled in {d}") for d in "xy"]  # fmt: skip
        handles.append(Line2D([], [], color="0.3", marker=r"$\uparrow$", ls="none", ms=9,
                              label="beyond the sampled $L/r$"))  # fmt: skip
    fig.legend(handles=handles, loc="outside lower center", ncols=legend_columns(3),
               frameon=False)  # fmt: skip


def _lim(red: Reduction) -> tuple[float, float]:
    x = sorted({r["L_over_r"] for r in red.sweeps})
    step = min(np.diff(x)) if len(x) > 1 else 0.5
    return x[0] - 0.6 * step, x[-1] + 0.6 * step


def fig4c_phase_diagram(red: Reduction, notes: list[str]) -> Any:
    """(L/r)_trans in x (orange line) and y (green line) over each varying parameter,
    with the regimes shaded pink / orange / green (paper Fig. 4c). Without a varying
    parameter: the regimes along L/r of the one series."""
    if not red.transitions:
        raise SkipFigure("needs analysed sweeps (no transitions found)")
    by_key = {(tuple(t[p] for p in SERIES_PARAMS), t["direction"]): t for t in red.transitions}
    keys = sorted({k for k, _ in by_key})
    panels = []
    for pi, p in enumerate(SERIES_PARAMS):
        if p not in red.varying or p == "stitch":  # a name, no axis: a panel per stitch
            continue
        groups: dict[tuple, list] = {}
        for k in keys:
            groups.setdefault(k[:pi] + k[pi + 1 :], []).append(k)
        panels += [(p, pi, g, sorted(ks, key=lambda k: k[pi]))
                   for g, ks in groups.items() if len(ks) >= 2]  # fmt: skip
    if not panels:  # no parameter axis (one series, or only the stitch varies): a strip each
        return _regime_strips(red, limit_panels(keys, "fig4c", notes), by_key)
    panels = limit_panels(panels, "fig4c", notes)
    ncols = min(len(panels), 2)
    fig = new_figure(max(8.0, 5.0 * ncols + 0.3), 3.6 * -(-len(panels) // ncols) + 1.3)
    lim = _lim(red)
    shown: set[str] = set()
    for ax, (p, pi, _, ks) in zip(grid_of_panels(fig, len(panels), ncols), panels, strict=True):
        xs = np.array([k[pi] for k in ks])
        rx = [by_key.get((k, "x")) for k in ks]
        ry = [by_key.get((k, "y")) for k in ks]
        tx = np.array([_trans_value(t, lim[1], lim[0]) for t in rx])
        ty = np.array([_trans_value(t, lim[1], lim[0]) for t in ry])
        shown |= _regime_panel(ax, xs, tx, ty, lim)
        for d, rows in (("x", rx), ("y", ry)):
            if any(t is not None for t in rows):
                _transition_marks(ax, xs, rows, d, lim, label=False)
        parameter_axis(ax, xs)
        sym, unit = PARAMETER_NAMES[p].math, PARAMETER_NAMES[p].unit
        ax.set_xlabel(f"${sym}$" + (f" ({unit})" if unit else ""))
        ax.set_ylabel(L_OVER_R)
        ax.grid(False)
        fixed = dict(zip(SERIES_PARAMS, ks[0], strict=True))
        others = series_label(fixed, [q for q in red.varying if q != p])
        ax.set_title(f"at {others}" if others else rf"$(L/r)_{{\rm trans}}$ against ${sym}$")
    _regime_legend(fig, shown, with_lines=True)
    title(fig, red, r"Phase diagram: onset of unjamming $(L/r)_{\rm trans}$ and regimes")
    return fig


def _regime_strips(red: Reduction, keys: list, by_key: dict) -> Any:
    """Each series: the regimes along L/r, with the sampled sweeps marked, a panel each."""
    lim = _lim(red)
    fig = new_figure(8.0, 2.9 * len(keys) + 0.9)
    axes = fig.subplots(len(keys), 1, squeeze=False, sharex=True)[:, 0]
    shown: set[str] = set()
    for ax, key in zip(axes, keys, strict=True):
        shown |= _regime_strip(ax, red, key, by_key, lim)
        ax.xaxis.set_tick_params(labelbottom=True)
        lab = label_of(red, key)
        if lab and len(keys) > 1:
            ax.set_title(lab)
    axes[-1].set_xlabel(L_OVER_R)
    _regime_legend(fig, shown, with_lines=False, markers=True)
    lab = label_of(red, keys[0]) if len(keys) == 1 else ""
    title(fig, red, r"Regimes along $L/r$ " + (f"({lab})" if lab else
                                              "(one series: no parameter varies)"
                                              if len(keys) == 1 else f"({len(keys)} series)"))  # fmt: skip
    return fig


def _regime_strip(ax: Any, red: Reduction, key: tuple, by_key: dict, lim: tuple) -> set[str]:
    """One series' regimes along L/r on ``ax``, with its sampled sweeps marked; the
    regimes shaded."""
    shown: set[str] = set()
    tx = _trans_value(by_key.get((key, "x")), np.inf, -np.inf)
    ty = _trans_value(by_key.get((key, "y")), np.inf, -np.inf)
    if not (np.isnan(tx) or np.isnan(ty)):
        low, high = np.clip(min(tx, ty), *lim), np.clip(max(tx, ty), *lim)
        mid = "jammed_y_only" if tx <= ty else "jammed_x_only"
        for name, a, b in (
            ("jammed_xy", lim[0], low),
            (mid, low, high),
            ("unjammed", high, lim[1]),
        ):
            if b > a:
                ax.axvspan(a, b, color=REGIME_FILL[name], lw=0)
                shown.add(name)
    for yi, d in ((1.0, "x"), (0.0, "y")):
        rows = [r for r in red.sweeps if r["direction"] == d and series_key(r) == key]
        if not rows:
            continue
        xs = [r["L_over_r"] for r in rows]
        face = [TRANSITION_LINE[d] if r["jammed"] else "white" for r in rows]
        ax.scatter(xs, [yi] * len(xs), s=60, c=face, edgecolors=TRANSITION_LINE[d], zorder=4,
                   marker="o" if d == "x" else "s", linewidths=1.5, clip_on=False)  # fmt: skip
        t = by_key.get((key, d))
        if t is not None and t["status"] == "transition":
            ax.plot([t["L_over_r_trans"]] * 2, [yi - 0.3, yi + 0.3], color=TRANSITION_LINE[d],
                    lw=2.2, zorder=3)  # fmt: skip
            ax.text(t["L_over_r_trans"], yi + 0.34, f"{t['L_over_r_trans']:.2f}", ha="center",
                    va="bottom", color=TRANSITION_LINE[d], fontsize="medium")  # fmt: skip
    ax.set_xlim(*lim)
    ax.set_ylim(-0.6, 1.75)
    ax.set_yticks([1.0, 0.0])
    ax.set_yticklabels(["pulled in x", "pulled in y"])
    ax.grid(False)
    return shown
