"""Commands that read results or measure: phase-diagram, render, accuracy."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from .common import (
    BOpt,
    ChartOpt,
    ConfigOpt,
    JsonOpt,
    KOpt,
    LOpt,
    POpt,
    PresetOpt,
    RcOpt,
    RegOpt,
    ROpt,
    StitchOpt,
    app,
    check_range,
    compile_notice,
    flag,
    option,
    stitch_inputs,
    user_errors,
    with_chart,
)

ThresholdOpt = Annotated[
    float | None,
    option(
        "--threshold",
        help="energy-gap threshold between jammed and unjammed (mJ)",
        default="5·10⁻⁵, the paper's",
    ),
]


@app.command("phase-diagram")
def phase_diagram(
    results: Annotated[
        list[Path],
        typer.Argument(help="results file(s) written by knitsweep run; several combine"),
    ],
    out: Annotated[
        Path | None,
        option("--out", help="directory for the CSV and figure files",
               default="<first results>_phase_diagram"),
    ] = None,
    threshold: ThresholdOpt = None,
    figures: Annotated[bool, flag("--figures", help="the figures as well as the tables")] = True,
    formats: Annotated[
        str, typer.Option("--format", help="figure formats, comma-separated: png, pdf, svg")
    ] = "png",
    width: Annotated[
        str, typer.Option("--width", help="figure width: auto, column (3.4 in) or page "
                          "(7.0 in), journal widths with 7-8 pt fonts")
    ] = "auto",
    title: Annotated[bool, flag("--title", help="figures with titles")] = True,
    style: Annotated[
        str | None, option("--style", help="matplotlib style (name or file), or knitsweep",
                           default="your matplotlibrc")
    ] = None,
    as_json: JsonOpt = False,
) -> None:  # fmt: skip
    """Jamming transitions (L/r)_trans, ΔL/r and regimes of one or several results files,
    as a printed table, CSV files and the paper's figures; also on a file a run is
    still writing."""
    from ..analysis.transitions import GAP_THRESHOLD
    from ..report import phase_diagram as make_phase_diagram
    from ..report.plotting import FigureOptions
    from ..util.safe_files import check_output_dir

    with user_errors():
        threshold = GAP_THRESHOLD if threshold is None else threshold
        if out is not None:
            check_output_dir(out, "--out")
        options = FigureOptions(tuple(f.strip() for f in formats.split(",") if f.strip()), width,
                                title, style)  # fmt: skip
        # as JSON: the object alone on stdout, each file on stderr as it is written
        progress = (lambda line: line.startswith("wrote ") and typer.echo(line, err=True)
                    ) if as_json else typer.echo  # fmt: skip
        report = make_phase_diagram(results, out, threshold, figures=figures,
                                    options=options, progress=progress)  # fmt: skip
    if as_json:
        red = report.reduction
        typer.echo(json.dumps({
            "files": [str(p) for p in red.paths], "run_status": red.run_status,
            "partial": red.partial,
            "partial_reason": red.partial_reason, "threshold": red.threshold,
            "transitions": red.transitions, "problems": red.problems,
            "tables": [str(p) for p in report.tables],
            "figures": {f.name: str(f.path) if f.path else f"skipped: {f.reason}"
                        for f in report.figures},
        }))  # fmt: skip
        return


@app.command()
def report(
    results: Annotated[list[Path], typer.Argument(help="results file(s) written by knitsweep run")],
    out: Annotated[Path, typer.Option("--out", help="the page to write (.html)")] = Path(
        "report.html"
    ),
    threshold: ThresholdOpt = None,
) -> None:  # fmt: skip
    """One self-contained HTML page of results files: figures inline, the transitions,
    sweep metrics and zero-force states, failures, the job specs and provenance."""
    from ..analysis.transitions import GAP_THRESHOLD
    from ..report.html import write_report

    with user_errors():
        path = write_report(results, out, GAP_THRESHOLD if threshold is None else threshold,
                            progress=lambda line: typer.echo(line, err=True))  # fmt: skip
    typer.echo(f"wrote {path}")


@app.command()
def render(
    out: Annotated[Path, typer.Option("--out", help="file to write: a picture (.png, .pdf, "
                                      ".svg) or the tile's yarn in 3D (.vtp, .vtu for "
                                      "ParaView; .ply, .obj for Blender)")],
    results: Annotated[
        Path | None, typer.Option("--results", help="results file written by knitsweep run")
    ] = None,
    task: Annotated[
        str | None, typer.Option("--task", help="point or sweep id in --results (a unique prefix)")
    ] = None,
    step: Annotated[
        int | None, option("--strain-step", help="which strain step of a sweep to draw (an "
                           "index)", default="0, the zero-force state")
    ] = None,
    state: Annotated[
        Path | None, option("--state", help="a state (Init) file instead",
                            default="without --results: the stitch relaxed at the parameters")
    ] = None,
    L: LOpt = None, B: BOpt = None, k: KOpt = None, p: POpt = None, r: ROpt = None,
    r_core: RcOpt = None, stitch: StitchOpt = None, chart: ChartOpt = None, config: ConfigOpt = None,
    preset: PresetOpt = None,
    starts: Annotated[int, option("--starts", help="starts per point (relaxing: neither "
                                  "--state nor --results)", default="1")] = 1,
    radius: Annotated[
        float | None,
        option("--radius", help="tube radius to draw (mm)", default="the yarn radius r"),
    ] = None,
    core: Annotated[bool, flag("--core", help="draw the incompressible cores (radius "
                                       "r_core) instead of the yarn")] = False,
    cells: Annotated[str | None, option(
        "--cells", help="cells across and rows: N or NxM (a cell is a stitch, a chart's the "
        "stitches of its row)",
        default="two repeats of the pattern each way, at least 3")] = None,
    side: Annotated[str, typer.Option("--side", help="face (knit side) or back (purl side)")] = "face",
    elevation: Annotated[
        float, typer.Option("--elevation", help="view angle above the fabric plane (°)")
    ] = 72.0,
    width: Annotated[int, typer.Option("--pixels", help="image width (pixels)")] = 1100,
    highlight: Annotated[bool, flag("--highlight", help="wash out all stitches but the "
                                            "unit cell")] = False,
    contact_volumes: Annotated[bool, flag(
        "--contact-volumes", help="draw the stitch's contact volumes by class instead (paper "
        "Fig. 6a-e)")] = False,
    volume_points: Annotated[int, typer.Option(
        "--volume-points", help="--contact-volumes: tube points, a power of 2")] = 1 << 15,
) -> None:  # fmt: skip
    """Draw relaxed stitches as yarn tubes, like the paper's Fig. 1a, or with
    --contact-volumes their contact volumes (Fig. 6a-e), or write the tile's yarn as a 3D
    file: a task of a results file (point, or sweep at --strain-step), a state file, or
    the stitch relaxed at the parameters given (--stitch, --L, ...)."""
    from ..errors import InputError
    from ..report import render as rendering

    with user_errors():
        stitch = with_chart(stitch, chart)
        params = None
        flags = {"L": L, "B": B, "k": k, "p": p, "r": r, "r_core": r_core, "stitch": stitch}
        given = [f"--{n.replace('_', '-')}" for n, v in {**flags, "config": config}.items()
                 if v is not None]  # fmt: skip
        if results is not None and given:
            raise InputError(f"{', '.join(given)}: a results file holds its own parameters; "
                             "drop them to draw --results, or draw a --state or a relaxation "
                             "(neither --results nor --state) with them")  # fmt: skip
        if results is None:
            params, _ = stitch_inputs(config, **flags)
        if results is not None or state is not None:
            if preset is not None or starts != 1:
                raise InputError("--preset and --starts apply to a relaxation (neither "
                                 "--results nor --state)")  # fmt: skip
        else:
            from ..presets import check_preset

            if preset is not None:
                check_preset(preset)
            check_range("starts", starts, 1, 64)
        grid = parse_cells(cells)
        if results is None and state is None:
            compile_notice(params.stitch if params is not None else None)
        if contact_volumes:
            from ..report.contact_volumes import render_contact_volumes

            path, drawn = render_contact_volumes(
                out, results=results, task=task, step=step, state=state, params=params,
                samples=volume_points, preset=preset, starts=starts,
            )  # fmt: skip
        else:
            path, drawn = rendering.render(
                out, results=results, task=task, step=step, state=state, params=params,
                radius=radius, cells=grid, side=side, elevation_deg=elevation, width_px=width,
                highlight=highlight, core=core, preset=preset, starts=starts,
            )  # fmt: skip
    typer.echo(f"wrote {path}: {drawn.name}, {drawn.label}")


def parse_cells(cells: str | None) -> tuple[int, int] | None:
    """``--cells``: "N" (N × N) or "NxM" (N across, M rows)."""
    from ..errors import InputError

    if cells is None:
        return None
    parts = cells.lower().replace("×", "x").split("x")
    try:
        values = [int(v) for v in parts]
    except ValueError:
        values = []
    if len(values) not in (1, 2):
        raise InputError(f"cells = {cells!r}: give N or NxM (stitches across x rows)")
    return (values[0], values[-1])


@app.command()
def accuracy(
    L: LOpt = None, B: BOpt = None, k: KOpt = None, p: POpt = None, r: ROpt = None,
    r_core: RcOpt = None, regularization: RegOpt = None,
    settings: Annotated[
        str, typer.Option("--settings", help="comma-separated presets, coarse to fine, each "
                          "optionally 'preset:field=value+field=value'; errors are against the last")
    ] = "draft,paper,converged,fine",
    series: Annotated[
        str | None, option("--series", help="L values of the (L/r)_trans series, "
                           "comma-separated (mm)", default="11.3,…,11.7, the k = 0.1 transition")
    ] = None,
    out: Annotated[Path, typer.Option("--out", help="directory for accuracy.csv/png")] = Path(
        "accuracy"
    ),
    workers: Annotated[int, typer.Option("--workers", help="local worker processes (no MPI), "
                       "one setting each")] = 1,
    reference: Annotated[str | None, option(
        "--reference", help="the setting errors are measured against",
        default="the last")] = None,
) -> None:  # fmt: skip
    """Measure the speed/accuracy trade: one point at rising fidelity, with CPU time per
    relaxation, per sweep and per point and the error of each observable against the
    finest (or --reference)."""
    from ..config import StitchParams
    from ..errors import InputError
    from ..studies.accuracy import accuracy_study, table, write_report

    with user_errors():
        params, _ = stitch_inputs(None, L=L if L is not None else 11.0, B=B,
                                  k=k if k is not None else 0.1, p=p, r=r, r_core=r_core,
                                  regularization=regularization)  # fmt: skip
        specs = [s.strip() for s in settings.split(",") if s.strip()]
        if len(specs) < 2:
            raise InputError("settings: give at least two, coarse to fine")
        try:
            Ls = None if series is None else [float(v) for v in series.split(",")]
        except ValueError:
            raise InputError(f"series = {series!r}: comma-separated numbers (mm)") from None
        for value in Ls or []:  # each L of the series is a valid stitch
            StitchParams(**{**params.model_dump(), "L_mm": value})
        check_range("workers", workers, 1, 256)
        from ..studies.accuracy import setting

        for spec in specs:
            setting(spec)  # validate every setting before any compute
        if reference is not None and reference not in specs:
            raise InputError(f"reference = {reference!r}: must be one of --settings")
        from ..util.safe_files import check_output_dir

        check_output_dir(out, "--out")  # before any compute, as in every command
    compile_notice()
    results = accuracy_study(params, specs, Ls, workers=workers,
                             progress=lambda m: typer.echo(m, err=True), reference=reference)  # fmt: skip
    typer.echo(table(results))
    for path in write_report(results, out):
        typer.echo(f"wrote {path}", err=True)


@app.command("energy-density")
def energy_density(
    results: Annotated[list[Path], typer.Argument(help="results file(s) of a job that swept "
                       "one point along rays (e.g. jobs/energy_density_k0.1.toml)")],
    out: Annotated[Path, typer.Option("--out", help="the energy density file to write (.json)")
                   ] = Path("energy_density.json"),
    stitch: Annotated[str | None, option("--point-stitch", help="the stitch of the point to "
                                         "fit", default="the files' only one")] = None,
    L: Annotated[float | None, option("--point-L", help="the yarn length of the point to "
                                      "fit (mm)", default="the files' only one")] = None,
    knots: Annotated[str | None, option("--knots", help="knot intervals per strain, "
                     "comma-separated: eps_xx,eps_yy, or eps_xx,eps_yy,gamma with a shear",
                     default="64,48; 32,24,16 with a shear")] = None,
    smoothing: Annotated[float, typer.Option("--smoothing", help="weight of the spline's "
                         "curvature penalty, relative to the data's")] = 1e-2,
    held_out: Annotated[bool, flag("--held-out", help="measure the error between rays: "
                        "each ray left out of the fit in turn and predicted")] = True,
    figure: Annotated[bool, flag("--figure", help="draw <out>.png as well")] = True,
) -> None:  # fmt: skip
    """Fit the fabric's in-plane energy density W(eps_xx, eps_yy[, gamma]) (N/mm, per
    undeformed area) to one point's swept states and stresses, write it for
    `knitsweep.load_energy_density` and print the fit's errors and where it is not convex."""
    import knitsweep

    from ..analysis.energy_density import VARIABLES, fit_energy_density, held_out_errors
    from ..errors import InputError
    from ..report.fig_energy_density import density_summary, energy_density_figure

    with user_errors():
        try:
            intervals = None if knots is None else tuple(int(v) for v in knots.split(","))
        except ValueError:
            raise InputError(f"knots = {knots!r}: integers, e.g. 64,48 or 24,18,16") from None
        for v in intervals or ():
            check_range("knots", v, 2, 400)
        check_range("smoothing", smoothing, 0.0, 1e6)
        if out.suffix != ".json":
            raise InputError(f"out = {str(out)!r}: the energy density is written as .json")
        res = knitsweep.load(*results)
        try:
            samples = res.energy_density_samples(stitch, L)
        except ValueError as e:
            raise InputError(str(e)) from None
        if intervals is not None and len(intervals) != samples.dim:
            raise InputError(f"knots = {knots!r}: {samples.dim} numbers, one per strain "
                             f"({', '.join(VARIABLES[: samples.dim])})")  # fmt: skip
    fit = fit_energy_density(samples, intervals, smoothing)
    if held_out:
        fit.fit["held_out_error"] = held_out_errors(samples, intervals, smoothing)
    fit.save(out)
    typer.echo(density_summary(fit))
    typer.echo(f"wrote {out}")
    if figure:
        typer.echo(f"wrote {energy_density_figure(fit, samples, out.with_suffix('.png'))}")
