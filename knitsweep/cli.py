"""The ``knitsweep`` command line. It holds no logic: every command builds
validated models and calls one library function, the same one the tests call.

Bad input prints one line ``error: …`` naming the field and exits with code 2.
"""

from __future__ import annotations

import contextlib
import json
import sys
from pathlib import Path
from typing import Annotated

import typer
from pydantic import ValidationError

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    help="Simulate jammed stockinette fabric: energies, relaxations, strain sweeps, "
    "MPI parameter sweeps and phase diagrams (Gonzalez et al. 2025).",
)


@app.callback()
def _root() -> None:
    """knitsweep: stockinette unit-cell simulations (MODEL.md)."""


# ---- shared options (paper units) -------------------------------------------------
LOpt = Annotated[float | None, typer.Option("--L", help="yarn length per stitch L, mm [11.6]")]
BOpt = Annotated[float | None, typer.Option("--B", help="bending modulus B, mN mm^2 [90]")]
KOpt = Annotated[float | None, typer.Option("--k", help="compression constant k, mN/mm^2 [0.6]")]
POpt = Annotated[float | None, typer.Option("--p", help="contact exponent p > 1 [2.4]")]
ROpt = Annotated[float | None, typer.Option("--r", help="yarn radius r, mm [0.74]")]
RcOpt = Annotated[float | None, typer.Option("--r-core", help="core radius r_core < r, mm [0.325]")]
RegOpt = Annotated[
    float | None,
    typer.Option("--regularization", help="curvature-derivative regularisation, mN mm^4 [2]"),
]
SamplesOpt = Annotated[
    int | None, typer.Option("--samples", help="contact samples per segment N [10]")
]
NodesOpt = Annotated[
    int | None, typer.Option("--quadrature-nodes", help="Gauss–Legendre nodes per segment [32]")
]
ImagesOpt = Annotated[
    str | None,
    typer.Option("--images", help="periodic images: 'cutoff' (all that touch) or 'reference'"),
]
ConfigOpt = Annotated[
    Path | None,
    typer.Option("--config", help="an authors' *key value config file (jammed-knits format)"),
]
JsonOpt = Annotated[bool, typer.Option("--json", help="print one JSON object")]


@contextlib.contextmanager
def user_errors():
    """Turn bad input into one line on stderr and exit code 2, never a traceback."""
    from .params import InputError, describe_validation_error

    try:
        yield
    except (InputError, ValidationError) as e:
        typer.echo(f"error: {describe_validation_error(e)}", err=True)
        raise typer.Exit(2) from None


def stitch_inputs(config, **flags):
    """(StitchParams, Fidelity) from defaults < an authors' config < explicit flags."""
    from .formats import read_authors_config
    from .params import Fidelity, StitchParams

    names = {
        "L": "L_mm", "B": "B_mN_mm2", "k": "k_mN_per_mm2", "p": "p", "r": "r_mm",
        "r_core": "r_core_mm", "regularization": "regularization_mN_mm4",
    }  # fmt: skip
    phys: dict = {}
    fid: dict = {}
    if config is not None:
        cfg = read_authors_config(config)
        phys.update(cfg.params.model_dump())
        if cfg.samples_per_segment is not None:
            fid["samples_per_segment"] = cfg.samples_per_segment
    for flag, field in names.items():
        if flags.get(flag) is not None:
            phys[field] = flags[flag]
    for flag, field in (("samples", "samples_per_segment"), ("quadrature_nodes", "quadrature_nodes"),
                        ("images", "images")):  # fmt: skip
        if flags.get(flag) is not None:
            fid[field] = flags[flag]
    return StitchParams(**phys), Fidelity(**fid)


def _print_result(result: dict, as_json: bool, units: dict[str, str]) -> None:
    if as_json:
        typer.echo(json.dumps(result))
        return
    width = max(len(k) for k in result)
    for key, value in result.items():
        unit = units.get(key, "")
        text = f"{value:.12g}" if isinstance(value, float) else str(value)
        typer.echo(f"{key:<{width}}  {text} {unit}".rstrip())


ENERGY_UNITS = {
    "bending_energy": "mJ",
    "contact_energy": "mJ",
    "total_energy": "mJ",
    "length": "mm",
    "a_x": "mm",
    "a_y": "mm",
    "seconds": "s",
}


@app.command()
def energy(
    state: Annotated[Path, typer.Option("--state", help="a 30-line state (Init) file")],
    L: LOpt = None, B: BOpt = None, k: KOpt = None, p: POpt = None, r: ROpt = None,
    r_core: RcOpt = None, regularization: RegOpt = None, samples: SamplesOpt = None,
    quadrature_nodes: NodesOpt = None, images: ImagesOpt = None, config: ConfigOpt = None,
    as_json: JsonOpt = False,
) -> None:  # fmt: skip
    """Bending, contact and total energy (mJ = N mm) and yarn length (mm) of a state."""
    from .formats import read_state
    from .model import CellModel

    with user_errors():
        params, fidelity = stitch_inputs(
            config, L=L, B=B, k=k, p=p, r=r, r_core=r_core, regularization=regularization,
            samples=samples, quadrature_nodes=quadrature_nodes, images=images,
        )  # fmt: skip
        x = read_state(state)
        result = CellModel(params, fidelity).energies(x).as_dict()
    result["a_x"], result["a_y"] = float(x[-2]), float(x[-1])
    _print_result(result, as_json, ENERGY_UNITS)


StateOpt = Annotated[
    Path | None,
    typer.Option("--state", help="starting state (30-line Init file) [the shipped starts]"),
]
StartsOpt = Annotated[int | None, typer.Option("--starts", help="starts per point [4]")]
SeedOpt = Annotated[int, typer.Option("--seed", help="seed of the perturbed starts")]
PresetOpt = Annotated[
    str | None, typer.Option("--preset", help="fidelity preset: draft, paper, converged, fine")
]
FtolOpt = Annotated[float | None, typer.Option("--ftol", help="SLSQP energy tolerance (mJ)")]


def _numerics(preset, ftol, samples, quadrature_nodes, images, step=None):
    """Fidelity, solver and protocol fields from a preset plus explicit flags."""
    from .presets import DEFAULT_PRESET, preset_settings

    name = preset or DEFAULT_PRESET
    fid = preset_settings(name, "fidelity")
    sol = preset_settings(name, "solver")
    pro = preset_settings(name, "protocol")
    for key, value in (("samples_per_segment", samples), ("quadrature_nodes", quadrature_nodes),
                       ("images", images)):  # fmt: skip
        if value is not None:
            fid[key] = value
    if ftol is not None:
        sol["ftol"] = ftol
    if step is not None:
        pro["step_mm"] = step
    return fid, sol, pro


@app.command()
def relax(
    state: StateOpt = None,
    L: LOpt = None, B: BOpt = None, k: KOpt = None, p: POpt = None, r: ROpt = None,
    r_core: RcOpt = None, regularization: RegOpt = None, samples: SamplesOpt = None,
    quadrature_nodes: NodesOpt = None, images: ImagesOpt = None, config: ConfigOpt = None,
    preset: PresetOpt = None, ftol: FtolOpt = None, starts: StartsOpt = None, seed: SeedOpt = 0,
    as_json: JsonOpt = False,
) -> None:  # fmt: skip
    """Relax the zero-force state at fixed yarn length (both periods free)."""
    import time

    from .formats import read_state
    from .multistart import SHIPPED_SOURCE, StartSettings, zero_force
    from .params import Fidelity, SolverSettings
    from .relax import relax_with_continuation

    with user_errors():
        params, _ = stitch_inputs(config, L=L, B=B, k=k, p=p, r=r, r_core=r_core,
                                  regularization=regularization)  # fmt: skip
        fid, sol, _ = _numerics(preset, ftol, samples, quadrature_nodes, images)
        fidelity, solver = Fidelity(**fid), SolverSettings(**sol)
        t0 = time.perf_counter()
        if state is not None:
            from .model import CellModel

            x0 = read_state(state)
            start = SHIPPED_SOURCE.model_copy(
                update={"L_mm": CellModel(params, fidelity).energies(x0).length}
            )
            best, _ = relax_with_continuation(params, fidelity, x0, start, solver)
        else:
            settings = StartSettings() if starts is None else StartSettings(count=starts)
            best = zero_force(params, fidelity, solver, settings, seed).best
        seconds = time.perf_counter() - t0
    result = {
        "total_energy": best.total_energy, "bending_energy": best.bending_energy,
        "contact_energy": best.contact_energy, "a_x": best.a_x, "a_y": best.a_y,
        "length": best.length, "converged": best.converged, "status": best.status,
        "message": best.message, "iterations": best.iterations, "evaluations": best.evaluations,
        "min_zeta": best.min_zeta, "seconds": seconds,
    }  # fmt: skip
    _print_result(result, as_json, ENERGY_UNITS)
    if not best.converged:
        raise typer.Exit(1)


@app.command()
def sweep(
    direction: Annotated[str, typer.Option("--direction", help="pull along x or y")],
    L: LOpt = None, B: BOpt = None, k: KOpt = None, p: POpt = None, r: ROpt = None,
    r_core: RcOpt = None, regularization: RegOpt = None, samples: SamplesOpt = None,
    quadrature_nodes: NodesOpt = None, images: ImagesOpt = None, config: ConfigOpt = None,
    preset: PresetOpt = None, ftol: FtolOpt = None, starts: StartsOpt = None, seed: SeedOpt = 0,
    step: Annotated[float | None, typer.Option("--step", help="small step h (mm) [0.001]")] = None,
    stop_stress: Annotated[float | None, typer.Option("--stop-stress", help="N/mm [0.4]")] = None,
    max_strain: Annotated[float | None, typer.Option("--max-strain", help="[1.0]")] = None,
    compression: Annotated[bool, typer.Option("--compression", help="push instead of pull")] = False,
    out: Annotated[Path | None, typer.Option("--out", help="write the table: .csv or .h5")] = None,
) -> None:  # fmt: skip
    """One point's strain sweep, with a progress bar; prints the stress–strain table."""
    from .multistart import StartSettings, zero_force
    from .params import Fidelity, InputError, SolverSettings
    from .sweep import SweepProtocol, strain_sweep
    from .tables import sweep_table, write_sweep

    with user_errors():
        if direction not in ("x", "y"):
            raise InputError(f"direction = {direction!r}: must be 'x' or 'y'")
        if out is not None and out.suffix not in (".csv", ".h5"):
            raise InputError(f"out = '{out}': must end in .csv or .h5")
        params, _ = stitch_inputs(config, L=L, B=B, k=k, p=p, r=r, r_core=r_core,
                                  regularization=regularization)  # fmt: skip
        fid, sol, pro = _numerics(preset, ftol, samples, quadrature_nodes, images, step)
        for key, value in (("stop_stress_N_per_mm", stop_stress), ("max_strain", max_strain)):
            if value is not None:
                pro[key] = value
        if compression:
            pro["mode"] = "compression"
        fidelity, solver, protocol = Fidelity(**fid), SolverSettings(**sol), SweepProtocol(**pro)
        settings = StartSettings() if starts is None else StartSettings(count=starts)
    zero = zero_force(params, fidelity, solver, settings, seed)
    if not zero.best.converged:
        typer.echo(f"error: no zero-force state: {zero.message}", err=True)
        raise typer.Exit(1)
    with typer.progressbar(length=1000, label=f"{direction} sweep", file=sys.stderr) as bar:
        shown = [0]

        def progress(step_no, strain, stress):
            frac = max(abs(strain) / protocol.max_strain, stress / protocol.stop_stress_N_per_mm)
            target = int(1000 * min(max(frac, 0.0), 1.0))
            if target > shown[0]:
                bar.update(target - shown[0])
                shown[0] = target

        result = strain_sweep(params, zero, direction, protocol, fidelity, solver, progress)
    typer.echo(sweep_table(result))
    typer.echo(f"# {result.status}: {result.stop_reason}; {len(result.strain)} steps, "
               f"{result.relaxations} relaxations, {result.wall_seconds:.1f} s", err=True)  # fmt: skip
    if out is not None:
        write_sweep(out, result, params)


@app.command()
def run(
    job: Annotated[Path, typer.Argument(help="job file (TOML), e.g. jobs/demo.toml")],
    out: Annotated[Path | None, typer.Option("--out", help="results file [<job name>.h5]")] = None,
    workers: Annotated[int, typer.Option("--workers", help="local worker processes (no MPI)")] = 1,
    executor: Annotated[
        str, typer.Option("--executor", help="auto (MPI under mpirun), serial, processes, mpi")
    ] = "auto",
    shard: Annotated[str | None, typer.Option("--shard", help="run shard i/N of the grid")] = None,
    retry_failed: Annotated[bool, typer.Option("--retry-failed", help="rerun failed tasks")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", help="no progress bar")] = False,
) -> None:  # fmt: skip
    """Run a job: every grid point's zero-force state and its x/y strain sweeps, into
    one HDF5 file. Under mpirun -n N, rank 0 schedules and N-1 ranks work."""
    from . import service
    from .params import InputError

    with user_errors():
        if executor not in ("auto", "serial", "processes", "mpi"):
            raise InputError(f"executor = {executor!r}: must be auto, serial, processes or mpi")
        summary = service.run(job, out, executor=executor, workers=workers, shard=shard,
                              retry_failed=retry_failed, show_progress=not quiet)  # fmt: skip
    if summary is None:  # an MPI worker rank
        return
    c = summary.counts
    typer.echo(f"{summary.out}: {c['done']} done, {c['failed']} failed, {c['not_knittable']} not "
               f"knittable of {summary.total} tasks ({summary.skipped} already finished) in "
               f"{summary.seconds:.1f} s", err=True)  # fmt: skip
    for line in summary.failures[:10]:
        typer.echo(f"  failed: {line}", err=True)
    raise typer.Exit(summary.exit_code)


@app.command()
def status(
    results: Annotated[Path, typer.Argument(help="results file written by knitsweep run")],
    as_json: JsonOpt = False,
) -> None:
    """Counts of a results file (done, failed, running, pending, rate, ETA), also
    while a run is writing it."""
    from . import service
    from .runner import progress_line

    with user_errors():
        s = service.status(results)
    if as_json:
        typer.echo(json.dumps(s))
        return
    state = (
        " (live)"
        if s["live"]
        else " (its writer is gone: rerun the job to resume)"
        if s["stale"]
        else ""
    )
    typer.echo(f"{s['file']}  job {s['job']}  {s['run_status']}{state}")
    typer.echo(progress_line(s))
    for line in s["failures"][:20]:
        typer.echo(f"  failed {line}")


@app.command()
def merge(
    out: Annotated[Path, typer.Argument(help="merged results file to write")],
    inputs: Annotated[list[Path], typer.Argument(help="shard files of one job")],
) -> None:
    """Combine the shard files of one job (knitsweep run --shard i/N) into one file."""
    from . import service

    with user_errors():
        r = service.merge(out, inputs)
    state = (
        "complete"
        if r["complete"]
        else f"partial: {r['points'] + r['sweeps']} of {r['expected']} tasks"
    )
    typer.echo(f"{r['file']}: {r['points']} points, {r['sweeps']} sweeps ({state})")


@app.command("phase-diagram")
def phase_diagram(
    results: Annotated[Path, typer.Argument(help="results file written by knitsweep run")],
    out: Annotated[
        Path | None,
        typer.Option("--out", help="directory for the CSV and PNG files [<results>_phase_diagram]"),
    ] = None,
    threshold: Annotated[
        float, typer.Option("--threshold", help="energy-gap threshold, mJ [5e-5, the paper's]")
    ] = 5e-5,
    no_figures: Annotated[bool, typer.Option("--no-figures", help="write the tables only")] = False,
    as_json: JsonOpt = False,
) -> None:
    """Jamming transitions (L/r)_trans, ΔL/r and regimes of a results file, as a printed
    table, CSV files and the paper's figures; also on a file a run is still writing."""
    from .postprocess import phase_diagram as make_phase_diagram

    with user_errors():
        report = make_phase_diagram(results, out, threshold, figures=not no_figures)
    if as_json:
        red = report.reduction
        typer.echo(json.dumps({
            "file": str(red.path), "run_status": red.run_status, "partial": red.partial,
            "partial_reason": red.partial_reason, "threshold": red.threshold,
            "transitions": red.transitions, "problems": red.problems,
            "tables": [str(p) for p in report.tables],
            "figures": {f.name: str(f.path) if f.path else f"skipped: {f.reason}"
                        for f in report.figures},
        }))  # fmt: skip
        return
    for line in report.lines():
        typer.echo(line)


@app.command()
def render(
    out: Annotated[Path, typer.Option("--out", help="image to write: .png, .pdf or .svg")],
    results: Annotated[
        Path | None, typer.Option("--results", help="results file written by knitsweep run")
    ] = None,
    task: Annotated[
        str | None, typer.Option("--task", help="point or sweep id in --results (a unique prefix)")
    ] = None,
    step: Annotated[
        int | None, typer.Option("--step", help="strain step of a sweep [0: the zero-force state]")
    ] = None,
    state: Annotated[
        Path | None, typer.Option("--state", help="a 30-line state (Init) file instead")
    ] = None,
    L: LOpt = None, B: BOpt = None, k: KOpt = None, p: POpt = None, r: ROpt = None,
    r_core: RcOpt = None, config: ConfigOpt = None,
    radius: Annotated[
        float | None,
        typer.Option("--radius", help="tube radius to draw, mm (default: r; the paper drew 0.5)"),
    ] = None,
    cells: Annotated[int, typer.Option("--cells", help="stitches per side of the picture")] = 3,
    side: Annotated[str, typer.Option("--side", help="face (knit side) or back (purl side)")] = "face",
    elevation: Annotated[
        float, typer.Option("--elevation", help="view angle above the fabric plane, degrees")
    ] = 72.0,
    width: Annotated[int, typer.Option("--width", help="rendering resolution, pixels across")] = 1100,
) -> None:  # fmt: skip
    """Draw relaxed stitches as yarn tubes, like the paper's Fig. 1a: a task of a results
    file (point, or sweep at --step) or a state file."""
    from . import render as rendering
    from .params import InputError

    with user_errors():
        params = None
        flags = {"L": L, "B": B, "k": k, "p": p, "r": r, "r_core": r_core}
        if state is not None:
            params, _ = stitch_inputs(config, **flags)
        elif config is not None or any(v is not None for v in flags.values()):
            raise InputError("--L, --B, --k, --p, --r, --r-core and --config apply to --state; "
                             "a results file holds its own parameters")  # fmt: skip
        path, stitch = rendering.render(
            out, results=results, task=task, step=step, state=state, params=params,
            radius=radius, cells=cells, side=side, elevation_deg=elevation, width_px=width,
        )  # fmt: skip
    typer.echo(f"wrote {path}: {stitch.label}")


@app.command()
def accuracy(
    L: LOpt = None, B: BOpt = None, k: KOpt = None, p: POpt = None, r: ROpt = None,
    r_core: RcOpt = None, regularization: RegOpt = None,
    settings: Annotated[
        str, typer.Option("--settings", help="comma-separated presets, coarse to fine, each "
                          "optionally 'preset:field=value+field=value'; errors are against the last")
    ] = "draft,paper,converged,fine",
    series: Annotated[
        str | None, typer.Option("--series", help="L values (mm) of the (L/r)_trans series, "
                                 "comma-separated [L-0.2 … L+0.2 in 0.1 steps]")
    ] = None,
    out: Annotated[Path, typer.Option("--out", help="directory for accuracy.csv/png")] = Path(
        "accuracy"
    ),
    workers: Annotated[int, typer.Option("--workers", help="settings computed in parallel")] = 1,
) -> None:  # fmt: skip
    """Measure the speed/accuracy trade: one point at rising fidelity, with time per
    relaxation and per sweep and the error of each observable against the finest."""
    from .accuracy import accuracy_study, table, write_report
    from .params import InputError

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
        from .accuracy import setting

        for spec in specs:
            setting(spec)  # validate every setting before any compute
    results = accuracy_study(params, specs, Ls, workers=workers,
                             progress=lambda m: typer.echo(m, err=True))  # fmt: skip
    typer.echo(table(results))
    for path in write_report(results, out):
        typer.echo(f"wrote {path}", err=True)


# ---- knitsweep slurm … (batch scripts; knitsweep/slurm.py, slurm/README.md) -------
slurm_app = typer.Typer(
    no_args_is_help=True, help="SLURM batch scripts for knitsweep runs (slurm/README.md)."
)
app.add_typer(slurm_app, name="slurm")


@slurm_app.command("render")
def slurm_render(
    job: Annotated[Path, typer.Argument(help="job file (TOML)")],
    out: Annotated[Path, typer.Option("--out", help="results file (mpi) or shard directory "
                                      "(array, merge)")],
    template: Annotated[str, typer.Option("--template", help="mpi, array or merge")] = "mpi",
    nodes: Annotated[int | None, typer.Option("--nodes", help="nodes (mpi)")] = None,
    ntasks: Annotated[int | None, typer.Option("--ntasks", help="MPI ranks, >= 2 (mpi)")] = None,
    time: Annotated[str | None, typer.Option("--time", help="walltime HH:MM:SS")] = None,
    partition: Annotated[str | None, typer.Option("--partition", help="partition")] = None,
    launcher: Annotated[str | None, typer.Option("--launcher", help="srun or mpirun (mpi)")] = None,
    venv: Annotated[Path | None, typer.Option("--venv", help="virtualenv to activate")] = None,
    modules: Annotated[str | None, typer.Option("--modules", help="modules to load, "
                                                "space-separated")] = None,
    shards: Annotated[int | None, typer.Option("--shards", help="array tasks (array)")] = None,
    cpus_per_task: Annotated[int | None, typer.Option("--cpus-per-task", help="local workers "
                                                      "per shard (array)")] = None,
    requeue: Annotated[bool, typer.Option("--requeue", help="requeue after the walltime "
                                          "signal, to resume (mpi, array)")] = False,
    script: Annotated[Path | None, typer.Option("--script", help="write it here, not to stdout")] = None,
) -> None:  # fmt: skip
    """Print (or write) a ready-to-submit batch script: a shipped template with the job,
    output, resources and environment filled in."""
    from .slurm import SlurmScript, render, write_script

    with user_errors():
        text = render(SlurmScript(
            template=template, job=str(job), out=str(out), nodes=nodes, ntasks=ntasks,
            time=time, partition=partition, launcher=launcher,
            venv=None if venv is None else str(venv), modules=modules, shards=shards,
            cpus_per_task=cpus_per_task, requeue=requeue,
        ))  # fmt: skip
    if script is None:
        typer.echo(text, nl=False)
    else:
        typer.echo(f"wrote {write_script(script, text)}: submit it with sbatch", err=True)


def main() -> None:
    """Console-script entry point: usage errors become one line and exit code 2."""
    try:
        rc = app(prog_name="knitsweep", standalone_mode=False)
    except typer.Exit as e:
        rc = e.exit_code
    except typer.Abort:
        typer.echo("aborted", err=True)
        rc = 130
    except Exception as e:  # click's usage errors (typer vendors click privately)
        if not (hasattr(e, "format_message") and hasattr(e, "exit_code")):
            raise
        ctx = getattr(e, "ctx", None)
        if type(e).__name__ == "NoArgsIsHelpError" and ctx is not None:
            typer.echo(ctx.get_help())
            rc = 0
        else:
            where = f"{ctx.command_path}: " if ctx is not None else ""
            typer.echo(f"error: {where}{e.format_message()}", err=True)
            rc = e.exit_code
    sys.exit(rc if isinstance(rc, int) else 0)


if __name__ == "__main__":  # pragma: no cover
    main()
