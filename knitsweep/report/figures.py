"""Which figures ``knitsweep phase-diagram`` writes, and writing them (PNG, Agg).

A figure the results file has no data for is skipped with a reason, never an error.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

from .fig_energy import fig3_energy_gaps, fig4a_gap_fit, fig4b_deltaL_vs_k, fig4c_phase_diagram
from .fig_mechanics import (
    SMALL_STRAIN,
    fig1b_stress_strain,
    fig1b_stress_strain_small,
    fig2ef_secant_offset,
    fig5a_aspect_ratio,
    fig5b_area_strain_y,
    fig6g_thickness_strain_x,
    fig6h_contact_force_ratio,
)
from .plotting import FigureOptions, SkipFigure, style
from .reduce import Reduction

FIGURES: dict[str, Callable[[Reduction, list[str]], Any]] = {
    "fig1b_stress_strain.png": fig1b_stress_strain,
    "fig1b_stress_strain_small.png": fig1b_stress_strain_small,
    "fig2ef_Ysec_sigma0.png": fig2ef_secant_offset,
    "fig3_energy_gaps.png": fig3_energy_gaps,
    "fig3_energy_gaps_log.png": partial(fig3_energy_gaps, log=True),
    "fig4a_gap_fit.png": fig4a_gap_fit,
    "fig4b_deltaL_vs_k.png": fig4b_deltaL_vs_k,
    "fig4c_phase_diagram.png": fig4c_phase_diagram,
    "fig5a_aspect_ratio.png": fig5a_aspect_ratio,
    "fig5b_area_strain_y.png": fig5b_area_strain_y,
    "fig5b_area_strain_y_small.png": partial(fig5b_area_strain_y, upto=SMALL_STRAIN),
    "fig6g_thickness_strain_x.png": fig6g_thickness_strain_x,
    "fig6g_thickness_strain_x_small.png": partial(fig6g_thickness_strain_x, upto=SMALL_STRAIN),
    "fig6h_contact_force_ratio.png": fig6h_contact_force_ratio,
}
"""File name → figure function (paper figure in the name)."""


@dataclass(frozen=True)
class FigureOutcome:
    """One figure: written to ``path``, or skipped for ``reason``; ``notes`` about it."""

    name: str
    path: Path | None
    reason: str | None
    notes: tuple[str, ...] = ()

    @property
    def line(self) -> str:
        """'wrote DIR/NAME' or 'NAME skipped: REASON'."""
        if self.path is not None:
            return f"wrote {self.path}" + "".join(f" ({n})" for n in self.notes)
        return f"{self.name} skipped: {self.reason}"


def render_figure(
    red: Reduction,
    name: str,
    make: Callable,
    options: FigureOptions | None = None,
) -> tuple[FigureOutcome, dict[str, bytes]]:
    """Draw one figure into memory: (its outcome, {format: the file's bytes} for each of
    ``options.formats``; empty if the figure was skipped)."""
    import io

    options = options or FigureOptions()
    notes: list[str] = []
    files = {}
    with style(options):
        try:
            fig = make(red, notes)
        except SkipFigure as e:
            return FigureOutcome(name, None, str(e), tuple(notes)), {}
        for fmt in options.formats:
            buf = io.BytesIO()
            fig.savefig(buf, format=fmt, metadata=_METADATA.get(fmt))
            files[fmt] = buf.getvalue()
    return FigureOutcome(name, None, None, tuple(notes)), files


# reproducible files: no creation dates in PDF/SVG metadata
_METADATA = {"pdf": {"CreationDate": None}, "svg": {"Date": None}}


def write_figures(
    red: Reduction,
    out_dir: str | Path,
    options: FigureOptions | None = None,
    done: Callable[[FigureOutcome], None] | None = None,
) -> list[FigureOutcome]:
    """Write every figure of :data:`FIGURES` that the reduction has data for, in each
    of ``options.formats``; one outcome per figure (its path: the first format),
    each told to ``done`` as soon as its files are written."""
    options = options or FigureOptions()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    outcomes = []
    for name, make in FIGURES.items():
        outcome, files = render_figure(red, name, make, options)
        paths = []
        for fmt, data in files.items():
            path = out / f"{Path(name).stem}.{fmt}"
            path.write_bytes(data)
            paths.append(path)
        if paths:
            extra = tuple(f"also {p.name}" for p in paths[1:])
            outcome = FigureOutcome(name, paths[0], None, outcome.notes + extra)
        outcomes.append(outcome)
        if done is not None:
            done(outcome)
    return outcomes
