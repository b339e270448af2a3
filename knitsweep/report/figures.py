"""Which figures ``knitsweep phase-diagram`` writes, and writing them (PNG, Agg).

A figure the results file has no data for is skipped with a reason, never an error.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

from ..util.safe_files import make_output_dir, replace_file
from .fig_energy import fig3_energy_gaps, fig4a_gap_fit, fig4b_deltaL_vs_k, fig4c_phase_diagram
from .fig_forces import figS11_contact_forces_strain
from .fig_inplane import figI_inplane
from .fig_mechanics import (
    SMALL_STRAIN,
    fig1b_stress_strain,
    fig1b_stress_strain_small,
    fig2ef_secant_offset,
    fig5a_aspect_ratio,
    fig5b_area_strain_y,
    fig5c_poisson_strain,
    fig6g_thickness_strain_x,
    fig6h_contact_force_ratio,
)
from .fig_patterns import figP_patterns
from .fig_volumes import figS_packing_fraction_L, figS_packing_fraction_strain
from .plotting import FigureOptions, SkipFigure, finish, style
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
    "fig5c_poisson_strain.png": fig5c_poisson_strain,
    "fig6g_thickness_strain_x.png": fig6g_thickness_strain_x,
    "fig6g_thickness_strain_x_small.png": partial(fig6g_thickness_strain_x, upto=SMALL_STRAIN),
    "fig6h_contact_force_ratio.png": fig6h_contact_force_ratio,
    "figP_patterns.png": figP_patterns,
    "figI_inplane.png": figI_inplane,
    "figS_packing_fraction_L.png": figS_packing_fraction_L,
    "figS_packing_fraction_strain.png": figS_packing_fraction_strain,
    "figS11_contact_forces_strain.png": figS11_contact_forces_strain,
    "figS11_contact_forces_strain_small.png": partial(
        figS11_contact_forces_strain, upto=SMALL_STRAIN
    ),
}
"""File name → figure function (paper figure in the name)."""

CAPTIONS: dict[str, str] = {
    "fig1b_stress_strain.png": "Stress against strain for each yarn length L (colour), pulled "
    "in x and in y; solid curves are jammed, dashed ones unjammed (paper Fig. 1b).",
    "fig1b_stress_strain_small.png": "The same curves up to 10 % strain, where a jammed fabric "
    "is stiff; dots are the computed steps, with the secant and offset-stress fits.",
    "fig2ef_Ysec_sigma0.png": "Secant modulus at 2 % strain (left) and offset stress (right) "
    "against L/r, pulled in x (purple) and y (blue); a cross at zero marks a sweep without a "
    "linear regime (paper Fig. 2e, f).",
    "fig3_energy_gaps.png": "Energy gaps against L/r: contact (coral) and bending (blue); the "
    "fabric is jammed while the gap of its direction exceeds the threshold (dotted); the "
    "shaded band is the transition bracket (paper Fig. 3).",
    "fig3_energy_gaps_log.png": "The energy gaps on a logarithmic scale; hollow markers are "
    "gaps below the drawing floor (paper Fig. S15).",
    "fig4a_gap_fit.png": "The jamming gap of each series with the straight line through its "
    "linear jammed run; ΔL/r is the distance from the line's zero to the transition, "
    "negative when the zero lies beyond it (paper Fig. 4a, Table S4).",
    "fig4b_deltaL_vs_k.png": "Transition width ΔL/r against the compression constant k "
    "(paper Fig. 4b).",
    "fig4c_phase_diagram.png": "Phase diagram: where the fabric is jammed in x and y, only in "
    "y, or unjammed, with the transition lines of each direction (paper Fig. 4c).",
    "fig5a_aspect_ratio.png": "Aspect ratio a_y/a_x of the relaxed stitch against (L/r)², "
    "coloured by regime (paper Fig. 5a).",
    "fig5b_area_strain_y.png": "Area strain of pulls in y: unjammed fabrics lose area at "
    "first, jammed ones do not (paper Fig. 5b).",
    "fig5b_area_strain_y_small.png": "Area strain of pulls in y up to 10 % strain.",
    "fig5c_poisson_strain.png": "Poisson's ratio against strain: the secant −ε_⊥/ε of the "
    "free transverse period, ν_xy pulled in x and ν_yx in y (the tables give it at 2 %).",
    "fig6g_thickness_strain_x.png": "Thickness strain of pulls in x: jammed fabrics first "
    "thin, unjammed ones thicken (paper Fig. 6g).",
    "fig6g_thickness_strain_x_small.png": "Thickness strain of pulls in x up to 10 % strain.",
    "fig6h_contact_force_ratio.png": "Ratio of the x and y contact forces at zero strain "
    "against L/r (paper Fig. 6h).",
    "figI_inplane.png": "The in-plane response along every load path: (a) the unjamming "
    "transition (L/r)_trans of each stitch pulled uniaxially (x, y), equibiaxially, in "
    "strip biaxial and sheared, the bar its bracket; (b) Poisson's ratios against L/r; (c) the "
    "equibiaxial and shear secant moduli; (d) in strip biaxial, the stress holding the "
    "transverse period over the pulled one's.",
    "figP_patterns.png": "Stitch patterns side by side: (a) the unjamming transition "
    "(L/r)_trans of each pattern pulled in x and y, the bar its bracket; (b) the secant "
    "modulus against L/r, one colour per pattern, x solid and y dashed; (c) the zero-force "
    "aspect ratio a_y/a_x of the stitch.",
    "figS_packing_fraction_L.png": "Packing fraction of the zero-force stitch against L/r, "
    "with the paper's 0.85 that marks the end of jamming (SI, contact volumes).",
    "figS_packing_fraction_strain.png": "Packing fraction along the sweeps, pulled in x and "
    "in y (SI, contact volumes).",
    "figS11_contact_forces_strain.png": "Contact forces between the yarn's sampled points by "
    "class and axis along the sweeps; positive forces assist the extension (paper SI).",
    "figS11_contact_forces_strain_small.png": "The contact forces along the sweeps up to 10 % "
    "strain.",
}
"""What each figure shows, for a reader (the HTML report's captions)."""


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
            fig = finish(make(red, notes))
        except SkipFigure as e:
            return FigureOutcome(name, None, str(e), tuple(notes)), {}
        for fmt in options.formats:
            buf = io.BytesIO()
            fig.savefig(buf, format=fmt, metadata=_METADATA.get(fmt))
            files[fmt] = buf.getvalue()
    return FigureOutcome(name, None, None, tuple(notes)), files


_JOB: tuple[Reduction, FigureOptions] | None = None  # what forked renderers draw from


def _render_named(name: str) -> tuple[FigureOutcome, dict[str, bytes]]:
    red, options = _JOB
    return render_figure(red, name, FIGURES[name], options)


def render_figures(
    red: Reduction, options: FigureOptions | None = None, workers: int | None = None
) -> Iterator[tuple[str, FigureOutcome, dict[str, bytes]]]:
    """Every figure of :data:`FIGURES` drawn into memory, in order, as (name, outcome,
    {format: bytes}); each as soon as it (and those before it) is drawn. ``workers``
    (default: the usable cores, at most 4) processes draw in parallel (forked, so
    the reduction is not copied); the bytes are the same as drawn one by one."""
    from ..util.forking import fork_workers, forked_map

    options = options or FigureOptions()
    names = list(FIGURES)
    workers = fork_workers(4 if workers is None else workers)
    if workers <= 1:
        for name in names:
            yield (name, *render_figure(red, name, FIGURES[name], options))
        return
    global _JOB
    _JOB = (red, options)
    try:
        drawn = forked_map(workers, _render_named, names)
        for name, (outcome, files) in zip(names, drawn, strict=True):
            yield name, outcome, files
    finally:
        _JOB = None


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
    out = make_output_dir(out_dir)
    outcomes = []
    for name, outcome, files in render_figures(red, options):
        paths = []
        for fmt, data in files.items():
            path = out / f"{Path(name).stem}.{fmt}"
            replace_file(path, data)  # never through a symbolic link
            paths.append(path)
        if paths:
            extra = tuple(f"also {p.name}" for p in paths[1:])
            outcome = FigureOutcome(name, paths[0], None, outcome.notes + extra)
        outcomes.append(outcome)
        if done is not None:
            done(outcome)
    return outcomes
