"""Mechanical and geometric figures: stress–strain curves (paper Fig. 1b), Y_sec and σ0
against L/r (Fig. 2e,f), the zero-force aspect ratio against (L/r)² (Fig. 5a), area
strain of y pulls (Fig. 5b), thickness strain of x pulls (Fig. 6g) and the ratio of
contact forces |F_x|/|F_y| at zero strain (Fig. 6h).

Each function takes a :class:`~.reduce.Reduction` and a list for notes, and returns a
matplotlib Figure or raises :class:`~.plotting.SkipFigure` saying what is missing.
Stress in N/mm (2D), strains and L/r dimensionless, forces in N.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from ..analysis.paper import TABLE_S3, at_table_1
from ..analysis.stress_strain import SECANT_STRAIN
from ..quantities import SERIES_PARAMS
from ..stitches import TRANSLATION_CLASSES as CONTACT_CLASSES
from .path_style import STRAIN
from .plotting import (
    DIRECTION_COLOUR,
    L_OVER_R,
    LINESTYLES,
    MARKERS,
    REGIME_FILL,
    REGIME_LABEL,
    TRANSITION_LINE,
    L_colourbar,
    L_colours,
    SkipFigure,
    caption,
    grid_of_panels,
    jammed_legend,
    label_of,
    legend_below,
    legend_columns,
    limit_panels,
    narrow,
    new_figure,
    panel_title,
    series_keys,
    series_legend,
    series_rows,
    title,
    title_overhangs,
)
from .reduce import Reduction, SweepCurves
from .series import series_key

SMALL_STRAIN = 0.1
"""Strain range of the small-strain figures (the jammed regime)."""

CLASS_COLOUR = {  # paper Fig. 6a–d: self green, same row magenta, NN lavender, NNN yellow
    "self": "#2ca02c",
    "same_row": "#c51bd6",
    "nn_column": "#7b68d9",
    "nnn_column": "#d4a20f",
    "same_column": "#7b68d9",  # a knit/purl pattern's (kernels.mirrored.MIRROR_CLASSES)
    "mirrored": "#1f5fbf",
    "other": "#888888",
}
CLASS_LABEL = {
    "self": "self",
    "same_row": "same row",
    "nn_column": "NN same column",
    "nnn_column": "NNN same column",
    "same_column": "same column",
    "mirrored": "mirrored images",
    "other": "other",
}


def _curves(red: Reduction, key: tuple, direction: str) -> list[SweepCurves]:
    return sorted((c for c in red.curves if c.series == key and c.direction == direction),
                  key=lambda c: c.L_mm)  # fmt: skip


def _curve_panels(red: Reduction, notes: list[str], directions: tuple[str, ...], what: str,
                  y_of: Any, ylabel: str, heading: str, zero_line: bool,
                  upto: float | None = None, overlay: Any = None) -> Any:  # fmt: skip
    """Panels (series × directions) of one per-step quantity against strain,
    coloured by L, solid when jammed in that direction and dashed when not; with
    ``upto``, only strains up to it (the jammed regime at small strain).
    ``overlay(ax, curve, colour, xmax)`` draws more on the densest, the middle and
    the loosest curve of a panel (the metric lines); it returns legend handles."""
    present = tuple(d for d in directions if any(c.direction == d for c in red.curves))
    if not present:
        pulls = " or ".join(directions)
        raise SkipFigure(f"needs analysed sweeps pulled in {pulls}")
    keys = sorted({c.series for c in red.curves if c.direction in present})
    keys = limit_panels(keys, what, notes)
    n = len(keys) * len(present)
    ncols = len(present) if len(present) > 1 else 1 if narrow() else min(len(keys), 2)
    if narrow() and " $" in ylabel:  # the symbol alone: a narrow panel is short
        ylabel = "$" + ylabel.split(" $", 1)[1]
    fig = new_figure(max(7.6, 4.9 * ncols + 1.2), 3.3 * -(-n // ncols) + 1.3)
    axes = grid_of_panels(fig, n, ncols)
    cmap, norm = L_colours(red)
    extra: dict[str, Any] = {}
    for i, (key, d) in enumerate((k, d) for k in keys for d in present):
        ax = axes[i]
        lo, hi = 0.0, 0.0
        curves = _curves(red, key, d)
        marked = {0, len(curves) // 2, len(curves) - 1}  # metric lines: 3 curves, legible
        for j, c in enumerate(curves):
            keep = c.strain <= upto * (1.0 + 1e-9) if upto is not None else slice(None)
            y = y_of(c)[keep]
            ax.plot(c.strain[keep], y, color=cmap(norm(c.L_mm)), ls="-" if c.jammed else "--",
                    lw=1.5, marker="." if upto is not None else None, ms=4)  # fmt: skip
            lo, hi = min(lo, float(np.min(y))), max(hi, float(np.max(y)))
            if overlay is not None and j in marked:
                xmax = upto if upto is not None else float(c.strain[-1])
                extra |= overlay(ax, c, cmap(norm(c.L_mm)), xmax)
        if upto is not None:
            pad = 0.05 * (hi - lo) if hi > lo else 1.0
            ax.set_xlim(0.0, upto)
            ax.set_ylim(lo - pad if lo < 0.0 else 0.0, hi + pad)
        if zero_line:
            ax.axhline(0.0, color="0.55", lw=1.0, zorder=0)
        panel_title(ax, f"pulled in {d}", label_of(red, key))
        ax.set_xlabel(STRAIN[d])
        ax.set_ylabel(ylabel)
    jammed_legend(fig, present, list(extra.values()))
    L_colourbar(fig, axes, cmap, norm, below=ncols > 1 and any(map(title_overhangs, axes)))
    title(fig, red, heading)
    return fig


def _metric_lines(red: Reduction) -> Any:
    """The overlay of Fig. 1b: the lines that define the metrics of each sweep, the
    secant to σ(0.02) whose slope is Y_sec (dotted) and the line fitted to the
    softened regime, drawn from ε = 0 where its intercept is σ0 (dash-dotted)."""
    from matplotlib.lines import Line2D

    rows = {r["task_id"]: r for r in red.sweeps}

    def draw(ax: Any, c: SweepCurves, colour: Any, xmax: float) -> dict[str, Any]:
        row = rows.get(c.task_id, {})
        handles = {}
        y_sec, at = row.get("Y_sec_N_per_mm"), SECANT_STRAIN
        if y_sec is not None:
            ax.plot([0.0, at], [0.0, y_sec * at], color=colour, ls=":", lw=1.3, zorder=3)
            ax.plot([at], [y_sec * at], color=colour, marker="o", ms=3.5, mfc="white", zorder=4)
            handles["secant"] = Line2D([], [], color="0.3", ls=":", marker="o", mfc="white",
                                       ms=3.5, label=r"secant to $\sigma(0.02)$: $Y_{\rm sec}$")  # fmt: skip
        s0, slope, hi = row.get("sigma0_N_per_mm"), row.get("softened_slope_N_per_mm"), row.get(
            "sigma0_window_hi")  # fmt: skip
        if s0 is not None and slope is not None:
            end = min(xmax, hi if hi is not None else xmax)
            ax.plot([0.0, end], [s0, s0 + slope * end], color=colour, ls="-.", lw=1.0, zorder=2)
            ax.plot([0.0], [s0], color=colour, marker="D", ms=3.5, zorder=4, clip_on=False)
            handles["sigma0"] = Line2D([], [], color="0.3", ls="-.", marker="D", ms=3.5,
                                       label=r"softened-regime fit, intercept $\sigma_0$")  # fmt: skip
        return handles

    return draw


def fig1b_stress_strain(red: Reduction, notes: list[str]) -> Any:
    """Stress σ (N/mm) against strain, coloured by L (paper Fig. 1b), with the lines
    that define the jamming metrics: the secant whose slope is Y_sec and the
    softened-regime fit whose intercept is σ0."""
    return _curve_panels(red, notes, ("x", "y"), "fig1b", lambda c: c.stress,
                         r"stress $\sigma$ (N/mm)", "Stress–strain curves", False,
                         overlay=_metric_lines(red))  # fmt: skip


def fig1b_stress_strain_small(red: Reduction, notes: list[str]) -> Any:
    """Stress–strain curves at small strain, ε ≤ SMALL_STRAIN, where a jammed fabric shows its
    high tangent modulus (paper Fig. 1b, pink line); dots are the sweep's steps; the
    secant of Y_sec and the σ0 fit as in :func:`fig1b_stress_strain`."""
    return _curve_panels(red, notes, ("x", "y"), "fig1b", lambda c: c.stress,
                         r"stress $\sigma$ (N/mm)", r"Stress–strain curves at small strain",
                         False, upto=SMALL_STRAIN, overlay=_metric_lines(red))  # fmt: skip


def fig5b_area_strain_y(red: Reduction, notes: list[str], upto: float | None = None) -> Any:
    """Area strain a_x a_y/(a_x0 a_y0) − 1 against ε_y for y pulls (paper Fig. 5b):
    unjammed fabrics dip below zero, jammed ones do not; ``upto``: small strains only."""
    heading = "Area strain of pulls in y" + (" at small strain" if upto else "")
    return _curve_panels(red, notes, ("y",), "fig5b", lambda c: c.area_strain,
                         r"area strain $A/A_0 - 1$", heading, True, upto)  # fmt: skip


def fig5c_poisson_strain(red: Reduction, notes: list[str]) -> Any:
    """Poisson's ratio against strain, ν_xy(ε) pulled in x and ν_yx(ε) in y: the
    secant −ε_⊥/ε of the period left free, which the tables give at ε = 0.02."""
    return _curve_panels(red, notes, ("x", "y"), "fig5c", lambda c: c.poisson_ratio,
                         r"Poisson's ratio $-\varepsilon_\perp/\varepsilon$",
                         "Poisson's ratio along uniaxial pulls", True)  # fmt: skip


def fig6g_thickness_strain_x(red: Reduction, notes: list[str], upto: float | None = None) -> Any:
    """Thickness strain Δz/Δz0 − 1 against ε_x for x pulls (paper Fig. 6g): jammed
    fabrics first shrink in z, unjammed ones expand; ``upto``: small strains only."""
    heading = "Thickness (z) strain of pulls in x" + (" at small strain" if upto else "")
    return _curve_panels(red, notes, ("x",), "fig6g", lambda c: c.thickness_strain,
                         r"thickness strain $\Delta z/\Delta z_0 - 1$", heading, True,
                         upto)  # fmt: skip


def _series_legend(fig: Any, ax: Any, red: Reduction, keys: list, loc: str = "best") -> None:
    """The markers and line styles of the series: on ``ax`` at ``loc``, or below the
    axes when they would cover it (``plotting.legend_below``)."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color="0.35", marker=MARKERS[i % len(MARKERS)],
                      ls=LINESTYLES[i % len(LINESTYLES)], label=label_of(red, k))
               for i, k in enumerate(keys)]  # fmt: skip
    if len(keys) > 1:
        series_legend(fig, ax, handles, loc=loc, frameon=False)


def fig2ef_secant_offset(red: Reduction, notes: list[str]) -> Any:
    """Secant modulus Y_sec at ε = 0.02 and offset stress σ0 (N/mm) against L/r, x pulls
    purple and y pulls blue (paper Fig. 2e,f and S4); ✕ at zero marks a sweep without
    a linear (softened) regime, whose σ0 is undefined."""
    if not any(r["Y_sec_N_per_mm"] is not None for r in red.sweeps):
        raise SkipFigure("needs sweeps that reach the secant strain 0.02")
    from matplotlib.lines import Line2D

    keys = series_keys(red)
    fig = new_figure(11.0, 4.6)
    ax_y, ax_s = fig.subplots(1, 2)
    no_regime = False
    for i, key in enumerate(keys):
        for d in ("x", "y"):
            rows = series_rows(red, key, d)
            if not rows:
                continue
            st = {"color": DIRECTION_COLOUR[d], "marker": MARKERS[i % len(MARKERS)],
                  "ls": LINESTYLES[i % len(LINESTYLES)]}  # fmt: skip
            ys = [
                (r["L_over_r"], r["Y_sec_N_per_mm"])
                for r in rows
                if r["Y_sec_N_per_mm"] is not None
            ]
            if ys:
                ax_y.plot(*zip(*ys, strict=True), **st)
            s0 = [(r["L_over_r"], r["sigma0_N_per_mm"]) for r in rows if r["has_linear_regime"]]
            if s0:
                ax_s.plot(*zip(*s0, strict=True), **st)
            miss = [r["L_over_r"] for r in rows if not r["has_linear_regime"]]
            if miss:
                no_regime = True
                ax_s.plot(miss, np.zeros(len(miss)), ls="none", marker="x", ms=7, mew=1.6,
                          color=DIRECTION_COLOUR[d], clip_on=False, zorder=5)  # fmt: skip
    ax_y.set_ylabel(r"secant modulus $Y_{\rm sec}$ (N/mm)")
    ax_s.set_ylabel(r"offset stress $\sigma_0$ (N/mm)")
    ax_y.set_title(r"(e) $Y_{\rm sec} = \sigma(0.02)/0.02$")
    ax_s.set_title(r"(f) $\sigma_0$: intercept of the" + ("\n" if narrow() else " ")
                   + "softened-regime line")  # fmt: skip
    for ax in (ax_y, ax_s):
        ax.set_xlabel(L_OVER_R)
        low = min((float(np.min(ln.get_ydata())) for ln in ax.get_lines() if len(ln.get_ydata())),
                  default=0.0)  # fmt: skip
        if low >= 0.0:  # a negative σ0 stays in view, below a zero line
            ax.set_ylim(bottom=0.0)
        else:
            ax.axhline(0.0, color="0.55", lw=0.8, zorder=0)
    handles = [Line2D([], [], color=DIRECTION_COLOUR[d], lw=2, label=f"pulled in {d}")
               for d in ("x", "y")]  # fmt: skip
    if no_regime:
        handles.append(Line2D([], [], color="0.3", marker="x", ls="none", ms=7, mew=1.6,
                              label=r"no linear regime ($\sigma_0$ undefined)"))  # fmt: skip
    ax_s.legend(handles=handles, loc="upper right", frameon=False)
    _series_legend(fig, ax_y, red, keys, "upper right")
    title(fig, red, "Stress–strain jamming metrics against $L/r$")
    return fig


def fig5a_aspect_ratio(red: Reduction, notes: list[str]) -> Any:
    """Zero-force aspect ratio a_y0/a_x0 against (L/r)², symbols filled by regime
    (pink jammed in x and y, orange only in y, green unjammed; paper Fig. 5a)."""
    rows = [r for r in red.points if r.get("aspect_ratio") is not None]
    if len(rows) < 2:
        raise SkipFigure("needs ≥ 2 relaxed points")
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    keys = sorted({series_key(r) for r in rows})
    fig = new_figure(8.0, 5.2)
    ax = fig.subplots()
    if len(keys) == 1:  # one series: shade the regimes along (L/r)², as the paper does
        pts = sorted(rows, key=lambda r: r["L_over_r"])
        x2 = np.array([r["L_over_r"] ** 2 for r in pts])
        edges = np.concatenate([[x2[0] - (x2[1] - x2[0]) / 2], (x2[1:] + x2[:-1]) / 2,
                                [x2[-1] + (x2[-1] - x2[-2]) / 2]])  # fmt: skip
        spans = _regime_spans(red, keys[0], edges[0], edges[-1])
        if spans is None:  # no transition in a direction: each point's own regime
            spans = [(a, b, r["regime"]) for r, a, b in zip(pts, edges[:-1], edges[1:],
                                                           strict=True)]  # fmt: skip
        for a, b, regime in spans:
            if regime is not None:
                ax.axvspan(a, b, color=REGIME_FILL[regime], alpha=0.55, lw=0)
    regimes = set()
    for i, key in enumerate(keys):
        pts = sorted((r for r in rows if series_key(r) == key), key=lambda r: r["L_over_r"])
        x2 = [r["L_over_r"] ** 2 for r in pts]
        ar = [r["aspect_ratio"] for r in pts]
        ax.plot(x2, ar, color="0.45", lw=1.1, ls=LINESTYLES[i % len(LINESTYLES)], zorder=2)
        face = [REGIME_FILL[r["regime"]] if r["regime"] else "white" for r in pts]
        regimes |= {r["regime"] for r in pts if r["regime"]}
        ax.scatter(x2, ar, c=face, edgecolors="0.15", s=55, marker=MARKERS[i % len(MARKERS)],
                   linewidths=1.0, zorder=3)  # fmt: skip
    ax.set_xlabel(r"$(L/r)^2$")
    ax.set_ylabel(r"aspect ratio $a_{y}/a_{x}$ at zero force")
    handles = [Patch(facecolor=REGIME_FILL[g], edgecolor="0.15", label=REGIME_LABEL[g])
               for g in REGIME_FILL if g in regimes]  # fmt: skip
    if len(keys) > 1:
        handles += [Line2D([], [], color="0.45", marker=MARKERS[i % len(MARKERS)], mfc="white",
                           mec="0.15", ls=LINESTYLES[i % len(LINESTYLES)], label=label_of(red, k))
                    for i, k in enumerate(keys)]  # fmt: skip
    if not regimes:
        notes.append("fig5a: regimes need sweeps in both x and y; symbols left white")
    # many series: the legend below the axes (the figure grows), not over the curves
    below = len(keys) > 4 or legend_below(ax, [h.get_label() for h in handles])
    series_legend(fig, ax, handles, below, loc="best", frameon=True, framealpha=0.9)
    title(fig, red, "Zero-force stitch aspect ratio against $(L/r)^2$")
    return fig


def _regime_spans(red: Reduction, key: tuple, lo: float, hi: float) -> list | None:
    """(start, end, regime) along (L/r)² from ``lo`` to ``hi``, split at each
    direction's (L/r)_trans² (the same boundaries as Fig. 4c); None unless both
    directions have a transition inside the series."""
    trans = {d: red.transition_of.get((key, d)) for d in ("x", "y")}
    if any(t is None or t.status != "transition" for t in trans.values()):
        return None
    tx, ty = (trans[d].L_over_r_trans ** 2 for d in ("x", "y"))
    cuts = sorted({lo, hi, *(b for b in (tx, ty) if lo < b < hi)})
    spans = []
    for a, b in itertools.pairwise(cuts):
        m = 0.5 * (a + b)
        jx, jy = m < tx, m < ty
        regime = ("jammed_xy" if jx and jy else "jammed_y_only" if jy else
                  "jammed_x_only" if jx else "unjammed")  # fmt: skip
        spans.append((a, b, regime))
    return spans


def _table_s3_series(key: tuple) -> bool:
    """Whether a series is Table S3's: k = 0.1 mN/mm² at Table 1's B, r_core, r, p."""
    return at_table_1(dict(zip(SERIES_PARAMS, key, strict=True)), k_mN_per_mm2=0.1)


def _vs_table_s3(pts: list[dict]) -> str:
    """The range of |F_x| and |F_y| relative to Table S3 over the L values both have,
    marked "not reproduced" beyond ±10 %."""
    dev = {"x": [], "y": []}
    for r in pts:
        paper = TABLE_S3.get(round(r["L_mm"], 6))
        if paper is not None:
            dev["x"].append(abs(r["pair_F_x_self_row_N"]) / paper[0] - 1.0)
            dev["y"].append(abs(r["pair_F_y_column_N"]) / paper[1] - 1.0)
    if not dev["x"]:
        return ""
    # within 10 % everywhere: reproduced; otherwise say so on the figure
    rng = {a: f"{100 * min(v):+.0f} … {100 * max(v):+.0f} %"
              + ("" if max(map(abs, v)) <= 0.1 else " (not reproduced)")
           for a, v in dev.items()}  # fmt: skip
    return (f"against Table S3 ({len(dev['x'])} L values): |F_x| {rng['x']}, "
            f"|F_y| {rng['y']}")  # fmt: skip


def fig6h_contact_force_ratio(red: Reduction, notes: list[str]) -> Any:
    """(h) Contact-force ratio at zero strain against L/r (paper Fig. 6h, Table S3):
    the x force of the self and same-row contacts over the y force of the NN and NNN
    same-column contacts, from the unweighted pair forces between sampled yarn points
    (``force_columns.pair_force_columns``), with Table S3's ratio beside it and the
    ratio of the generalised forces −∂E_c/∂a (not the paper's quantity) thin; dashed
    line: equal forces. Right: each class's pair force in x and y (N; positive
    extends the fabric) for the first series, with Table S3's |F_x| and |F_y|."""
    rows = [r for r in red.points if r.get("force_ratio_xy") is not None]
    if not rows:
        raise SkipFigure("the results file stores no contact forces "
                         "(set [store] contact_forces = true in the job)")  # fmt: skip
    from matplotlib.lines import Line2D

    keys = sorted({series_key(r) for r in rows})
    fig = new_figure(12.0, 5.3, wide=True)  # two dense panels: page width at least
    ax, ax_c = fig.subplots(1, 2, width_ratios=(1.15, 1.0))
    paper_L = np.array(sorted(TABLE_S3))
    paper = np.array([TABLE_S3[L] for L in paper_L])
    shown_paper = False
    for i, key in enumerate(keys):
        pts = sorted((r for r in rows if series_key(r) == key), key=lambda r: r["L_over_r"])
        colour = f"C{i % 10}" if len(keys) > 1 else "0.15"
        x = [r["L_over_r"] for r in pts]
        ax.plot(x, [r["force_ratio_xy"] for r in pts], color=colour,
                marker=MARKERS[i % len(MARKERS)], label=label_of(red, key) or "simulation")  # fmt: skip
        if all(r.get("generalised_force_ratio_xy") is not None for r in pts):
            ax.plot(x, [r["generalised_force_ratio_xy"] for r in pts], color=colour, lw=0.9,
                    ls=(0, (4, 2)), alpha=0.6)  # fmt: skip
        if _table_s3_series(key):
            r_mm = dict(zip(SERIES_PARAMS, key, strict=True))["r_mm"]
            ax.plot(paper_L / r_mm, paper[:, 0] / paper[:, 1], ls="none", marker="s", ms=8,
                    mfc="none", mec="0.45", mew=1.4, zorder=5)  # fmt: skip
            shown_paper = True
        t = red.transition_of.get((key, "y"))
        if t is not None and t.status == "transition":
            ax.axvline(t.L_over_r_trans, color=colour if len(keys) > 1 else TRANSITION_LINE["y"],
                       ls=":", lw=1.4)  # fmt: skip
    series_handles = ax.get_legend_handles_labels()
    ax.axhline(1.0, color="0.4", ls="--", lw=1.2)
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel(L_OVER_R)
    ax.set_ylabel(r"$|F_x^{\rm self+row}| \,/\, |F_y^{\rm NN+NNN\ column}|$")
    ax.set_title("(h) x force of self + same-row contacts over\n"
                 "y force of NN + NNN same-column contacts, zero strain")  # fmt: skip
    legend = [Line2D([], [], color="0.3", marker="o", label="pair forces (the paper's definition)"),
              Line2D([], [], color="0.3", lw=0.9, ls=(0, (4, 2)), alpha=0.6,
                     label=r"generalised forces $-\partial E_c/\partial a$ (not the paper's)"),
              Line2D([], [], color="0.4", ls="--", label=r"$|F_x| = |F_y|$"),
              Line2D([], [], color="0.4", ls=":", label=r"$(L/r)_{\rm trans}$ in y")]  # fmt: skip
    if shown_paper:
        legend.append(Line2D([], [], ls="none", marker="s", mfc="none", mec="0.45", mew=1.4,
                             label="paper Table S3"))  # fmt: skip
    ax.legend(handles=legend, loc="upper right", frameon=True, framealpha=0.9)
    if len(keys) > 1:
        fig.legend(*series_handles, loc="outside lower center",
                   ncols=legend_columns(min(len(keys), 4)),
                   frameon=False)  # fmt: skip

    pts = sorted((r for r in rows if series_key(r) == keys[0]), key=lambda r: r["L_over_r"])
    x = [r["L_over_r"] for r in pts]
    # hollow markers of falling size, so that classes with equal forces (self and same
    # row coincide in x for the stockinette cell) stay visible on top of each other
    sizes = {c: 9 - 1.2 * j for j, c in enumerate(CONTACT_CLASSES)}
    for j, cls in enumerate(CONTACT_CLASSES):
        for a, ls in (("x", "-"), ("y", "--")):
            ax_c.plot(x, [r[f"pair_F_{cls}_{a}_N"] for r in pts], color=CLASS_COLOUR[cls], ls=ls,
                      lw=1.0, marker=MARKERS[j], ms=sizes[cls], mfc="none", alpha=0.8)  # fmt: skip
    ax_c.plot(x, [abs(r["pair_F_x_self_row_N"]) for r in pts], color="0.1", lw=2.2)
    ax_c.plot(x, [abs(r["pair_F_y_column_N"]) for r in pts], color="0.1", lw=2.2, ls="--")
    handles = [Line2D([], [], color=CLASS_COLOUR[c], marker=MARKERS[j], mfc="none",
                      label=CLASS_LABEL[c]) for j, c in enumerate(CONTACT_CLASSES)]  # fmt: skip
    handles += [Line2D([], [], color="0.3", ls="-", label=r"$F_x$"),
                Line2D([], [], color="0.3", ls="--", label=r"$F_y$"),
                Line2D([], [], color="0.1", lw=2.2, label=r"$|F_x|$ self + same row"),
                Line2D([], [], color="0.1", lw=2.2, ls="--", label=r"$|F_y|$ NN + NNN")]  # fmt: skip
    if _table_s3_series(keys[0]):
        r_mm = dict(zip(SERIES_PARAMS, keys[0], strict=True))["r_mm"]
        ax_c.plot(paper_L / r_mm, paper[:, 0], ls="none", marker="s", mfc="0.3", mec="0.3", ms=5)
        ax_c.plot(paper_L / r_mm, paper[:, 1], ls="none", marker="D", mfc="white", mec="0.3", ms=5)
        handles += [Line2D([], [], ls="none", marker="s", mfc="0.3", mec="0.3",
                           label=r"Table S3 $|F_x|$"),
                    Line2D([], [], ls="none", marker="D", mfc="white", mec="0.3",
                           label=r"Table S3 $|F_y|$")]  # fmt: skip
        text = _vs_table_s3(pts)
        if text:  # a caption line below the panels: inside, it would cover the curves
            caption(fig, ax_c, text.replace(": ", ":\n", 1) if narrow() else text, color="0.25")
    # beside the panel, not over the curves that start high at small L/r
    ax_c.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), frameon=False,
                ncols=1)  # fmt: skip
    ax_c.set_xlabel(L_OVER_R)
    ax_c.set_ylabel("pair force between sampled points (N), + extends")
    panel_title(ax_c, "by contact class", label_of(red, keys[0]))
    ax_c.axhline(0.0, color="0.6", lw=0.8)
    title(fig, red, "Contact forces at zero strain, x against y")
    return fig
