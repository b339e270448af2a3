"""The in-plane response along every load path (``knitsweep.paths``): where each stitch
unjams when pulled uniaxially, equibiaxially or in strip biaxial, its Poisson's ratios,
its equibiaxial secant modulus and the stress that holds the transverse period in strip
biaxial.

Drawn when a study holds sweeps along a path that controls both periods (``directions``
with ``biaxial``, ``strip_x`` or ``strip_y``, e.g. ``jobs/inplane_k0.1.toml``). Takes a
:class:`~.reduce.Reduction` and a list for notes, returns a matplotlib Figure or raises
:class:`~.plotting.SkipFigure`.
"""

from __future__ import annotations

from typing import Any

from ..paths import load_path
from .fig_patterns import _colour, _one_series_per_stitch
from .path_style import PerPath, path_order
from .plotting import (
    DIRECTION_COLOUR,
    L_OVER_R,
    SkipFigure,
    new_figure,
    panel_title,
    series_rows,
    title,
)
from .reduce import Reduction
from .series import series_key

PATH_MARKER = PerPath({"x": "o", "y": "s", "biaxial": "D", "strip_x": ">", "strip_y": "^",
                       "shear": "X", "shear_free": "P"}, lambda _path: "*")  # fmt: skip
"""The marker of each load path in panel (a) (a ray's: a star)."""
LINESTYLE = {"x": "-", "y": "--", "strip_x": "-", "strip_y": "--", "biaxial": "-", "shear": ":",
             "shear_free": "-."}  # fmt: skip


def figI_inplane(red: Reduction, notes: list[str]) -> Any:
    """(a) (L/r)_trans of each stitch along each load path, the bar its bracket (▼: unjammed
    from the first L, ▲: jammed throughout; hollow: jammed again at a larger L, the first
    crossing shown, as the paper defines it); (b) Poisson's ratios ν_xy (pulled in x, solid)
    and ν_yx (in y, dashed) against L/r, one colour per stitch; (c) the secant moduli at
    0.02: equibiaxial ((σ_xx + σ_yy)/0.02, solid) and in simple shear (G_sec = σ_xy/γ,
    dotted with the periods held, dash-dotted with them free); (d) in strip biaxial, the stress that holds
    the transverse period over the pulled one's, σ_⊥/σ_∥ at 2 % strain (strip_x solid,
    strip_y dashed)."""
    paths = path_order({row["direction"] for row in red.sweeps})
    if all(load_path(d).uniaxial for d in paths):
        raise SkipFigure("needs sweeps along a biaxial or shear path (directions biaxial, "
                         "strip_x, strip_y, shear, shear_free)")  # fmt: skip
    from matplotlib.lines import Line2D

    chosen = _one_series_per_stitch(red, notes)
    stitches = list(chosen)
    fig = new_figure(11.0, 8.4, wide=True)
    (ax_t, ax_p), (ax_b, ax_s) = fig.subplots(2, 2)
    trans = {(series_key(t), t["direction"]): t for t in red.transitions}
    width = 0.8 / len(paths)
    reentrant = False
    for i, stitch in enumerate(stitches):
        key, colour = chosen[stitch], _colour(stitch, i)
        for j, d in enumerate(paths):
            pos = i + (j - (len(paths) - 1) / 2) * width
            style = {"color": DIRECTION_COLOUR[d], "mfc": colour, "ls": "none",
                     "marker": PATH_MARKER[d], "ms": 6}  # fmt: skip
            t, rows = trans.get((key, d)), series_rows(red, key, d)
            if t is not None and t["status"] == "transition":
                value = t["L_over_r_trans"]
                if t.get("n_jammed_after"):  # re-entrant: jammed again beyond the first crossing
                    style["mfc"], reentrant = "white", True
                    notes.append(f"in-plane: {stitch} along {d}: jammed again at "
                                 f"{t['n_jammed_after']} point(s) beyond (L/r)_trans")  # fmt: skip
                ax_t.errorbar([pos], [value], yerr=[[value - t["bracket_lower"]], [0.0]],
                              capsize=3, **style)  # fmt: skip
            elif t is not None and rows and t["status"] in ("jammed_throughout",
                                                            "unjammed_at_start"):  # fmt: skip
                up = t["status"] == "jammed_throughout"
                edge = rows[-1 if up else 0]["L_over_r"]
                ax_t.plot([pos], [edge], **{**style, "marker": "^" if up else "v", "ms": 8})
                notes.append(f"in-plane: {stitch} along {d}: {t['status'].replace('_', ' ')}")
            elif t is not None:
                notes.append(f"in-plane: {stitch} along {d}: {t['status']}")
            if t is not None and rows and t.get("n_jammed_after"):  # where it unjams for good
                reentrant = True
                _last_crossing(ax_t, pos, t, rows, DIRECTION_COLOUR[d])
            for ax, column, wanted in ((ax_p, "poisson_ratio", ("x", "y")),
                                       (ax_b, "Y_sec_N_per_mm", ("biaxial", "shear",
                                                                 "shear_free")),
                                       (ax_s, "transverse_stress_ratio", ("strip_x", "strip_y"))):  # fmt: skip
                if d not in wanted:
                    continue
                pts = [r for r in rows if r.get(column) is not None]
                if pts:
                    ax.plot([r["L_over_r"] for r in pts], [r[column] for r in pts], color=colour,
                            ls=LINESTYLE[d], marker=PATH_MARKER[d], ms=4)  # fmt: skip
    ax_t.set_xticks(range(len(stitches)))
    ax_t.set_xticklabels(stitches, rotation=30 if len(stitches) > 3 else 0)
    ax_t.set_xlim(-0.6, len(stitches) - 0.4)
    ax_t.set_ylabel(r"$(L/r)_{\rm trans}$")
    panel_title(ax_t, "(a) unjamming transition by load path\nbar: bracket; ▲▼: beyond the L "
                "range" + ("; hollow: jammed again beyond,\n"
                           "dotted up to where it unjams for good (—)" if reentrant else ""))  # fmt: skip
    ax_t.legend(handles=[Line2D([], [], color=DIRECTION_COLOUR[d], marker=PATH_MARKER[d],
                                ls="none", label=d) for d in paths],
                loc="best", frameon=False)  # fmt: skip
    ax_p.set_ylabel(r"Poisson's ratio at 2 % strain")
    ax_p.axhline(0.0, color="0.55", lw=0.8, zorder=0)
    panel_title(ax_p, r"(b) $\nu_{xy}$ (pulled in x, ─), $\nu_{yx}$ (in y, ‑‑)")
    ax_b.set_ylabel(r"secant modulus at 0.02 (N/mm)")
    values = [v for line in ax_b.get_lines() for v in line.get_ydata()]
    positive = [v for v in values if v > 0]
    if any(v < 0 for v in values):  # a negative G_sec: the shear's rest is no minimum
        ax_b.set_yscale("symlog", linthresh=0.01)
        ax_b.axhline(0.0, color="0.55", lw=0.8, zorder=0)
        notes.append("in-plane: a negative secant modulus in shear: the energy falls as the "
                     "cell shears, the state it started from is no minimum in shear (the "
                     "sweeps table's fall_below_rest_mJ)")  # fmt: skip
    elif positive and max(positive) > 10 * min(positive):
        ax_b.set_yscale("log")
    panel_title(ax_b, r"(c) equibiaxial $(\sigma_{xx} + \sigma_{yy})/0.02$ ─; shear"
                "\n" r"$G_{\rm sec} = \sigma_{xy}/\gamma$, periods held ···, free -·-")  # fmt: skip
    ax_s.set_ylabel(r"$\sigma_\perp / \sigma_\parallel$ at 2 % strain")
    ax_s.axhline(0.0, color="0.55", lw=0.8, zorder=0)
    panel_title(ax_s, "(d) strip biaxial: the held period's stress\n(strip_x ─, strip_y ‑‑)")
    for ax in (ax_p, ax_b, ax_s):
        ax.set_xlabel(L_OVER_R)
    ax_b.legend(handles=[Line2D([], [], color=_colour(s, i), marker="o", ms=4, label=s)
                         for i, s in enumerate(stitches)], loc="best", frameon=False)  # fmt: skip
    title(fig, red, "In-plane response: uniaxial, biaxial and shear")
    return fig


def _last_crossing(ax, pos: float, t: dict, rows: list, colour: str) -> None:
    """A re-entrant series' last crossing (transitions.csv's ``L_over_r_trans_last``): a
    dotted line from its first crossing (or the first L) to a bar there, or to a ▲ at
    the largest L where it is jammed up to the last point."""
    start = t["L_over_r_trans"]
    last = t.get("L_over_r_trans_last")
    end = last if last is not None else rows[-1]["L_over_r"]
    ax.plot([pos, pos], [start, end], color=colour, ls=":", lw=1.0)
    ax.plot([pos], [end], color=colour, ls="none", marker="_" if last is not None else "^",
            ms=10 if last is not None else 6, mew=1.6)  # fmt: skip
