"""Packing-fraction figures (paper SI "Contact Volumes", its packing-fraction figure):
φ at zero force against L/r, and φ against strain for each L, from the ``packing_fraction``
a job stores with ``[store] packing_fraction = true`` (the tube quasi-Monte-Carlo
estimator, ``analysis.volumes``; error bars one standard error). The paper's φ ≈ 0.85
(end of jamming at zero strain) is drawn as a line.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..analysis.paper import PHI_END_OF_JAMMING
from .fig_mechanics import _curve_panels
from .plotting import (
    L_OVER_R,
    MARKERS,
    TRANSITION_LINE,
    SkipFigure,
    label_of,
    new_figure,
    series_legend,
    title,
)
from .reduce import Reduction
from .series import series_key

PHI_LABEL = r"packing fraction $\phi = V_{\rm total}/V_{\rm cell}$"


def crossing(xs: Any, ys: Any, level: float) -> float | None:
    """First x where ys falls through ``level`` (linear between neighbours), or None."""
    xs, ys = np.asarray(xs, dtype=float), np.asarray(ys, dtype=float)
    for i in range(len(xs) - 1):
        if ys[i] >= level > ys[i + 1]:
            return float(xs[i] + (ys[i] - level) / (ys[i] - ys[i + 1]) * (xs[i + 1] - xs[i]))
    return None


def figS_packing_fraction_L(red: Reduction, notes: list[str]) -> Any:
    """φ of the zero-force state against L/r for each series (error bars: one
    standard error of the estimator), with the paper's φ ≈ 0.85 and (L/r)_trans in x
    and y; ✕ marks the L/r where φ falls through 0.85."""
    rows = [r for r in red.points if r.get("packing_fraction") is not None]
    if not rows:
        raise SkipFigure("the results file stores no packing fraction "
                         "(set [store] packing_fraction = true in the job)")  # fmt: skip
    fig = new_figure(7.6, 4.8)
    ax = fig.subplots()
    keys = sorted({series_key(r) for r in rows})
    for i, key in enumerate(keys):
        pts = sorted((r for r in rows if series_key(r) == key), key=lambda r: r["L_over_r"])
        x = [r["L_over_r"] for r in pts]
        y = [r["packing_fraction"] for r in pts]
        ax.errorbar(x, y, yerr=[r["packing_fraction_error"] for r in pts], color=f"C{i % 10}",
                    marker=MARKERS[i % len(MARKERS)], ms=4, capsize=2,
                    label=label_of(red, key) or "zero force")  # fmt: skip
        at = crossing(x, y, PHI_END_OF_JAMMING)
        if at is not None:
            ax.plot([at], [PHI_END_OF_JAMMING], "x", color=f"C{i % 10}", ms=9, mew=2)
            ax.annotate(f"L/r = {at:.2f}", (at, PHI_END_OF_JAMMING), textcoords="offset points",
                        xytext=(6, 6), fontsize=9, color=f"C{i % 10}")  # fmt: skip
        for d in "xy":
            t = red.transition_of.get((key, d))
            if t is not None and t.status == "transition":
                ax.axvline(t.L_over_r_trans, color=TRANSITION_LINE[d], ls=":", lw=1.4,
                           label=rf"$(L/r)_{{\rm trans}}$ in {d}" if i == 0 else None)  # fmt: skip
    ax.axhline(PHI_END_OF_JAMMING, color="0.4", ls="--", lw=1.2,
               label=rf"paper: end of jamming, $\phi \approx {PHI_END_OF_JAMMING:g}$")  # fmt: skip
    ax.set_xlabel(L_OVER_R)
    ax.set_ylabel(PHI_LABEL)
    series_legend(fig, ax, ax.get_legend_handles_labels()[0], frameon=True, framealpha=0.9)
    title(fig, red, "Packing fraction at zero force")
    return fig


def figS_packing_fraction_strain(red: Reduction, notes: list[str]) -> Any:
    """φ against strain for each L, x and y pulls (the paper's packing-fraction
    figure), solid where jammed; dashed grey: the paper's φ ≈ 0.85."""
    if not any(c.packing_fraction is not None for c in red.curves):
        raise SkipFigure("the results file stores no packing fraction "
                         "(set [store] packing_fraction = true in the job)")  # fmt: skip
    kept = [c for c in red.curves if c.packing_fraction is not None]
    sub = dataclasses.replace(red, curves=kept)
    fig = _curve_panels(sub, notes, ("x", "y"), "packing fraction", lambda c: c.packing_fraction,
                        PHI_LABEL, "Packing fraction along the sweeps", False)  # fmt: skip
    for ax in fig.axes:
        if ax.get_label() != "<colorbar>" and ax.get_xlabel():
            ax.axhline(PHI_END_OF_JAMMING, color="0.45", ls="--", lw=1.0, zorder=0)
    return fig
