"""Commands on one stitch: energy, relax, sweep."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..config import SOLVERS
from ..paths import load_path
from .common import (
    RELAX_UNITS,
    BOpt,
    ChartOpt,
    ConfigOpt,
    ImagesOpt,
    JsonOpt,
    KOpt,
    LOpt,
    NodesOpt,
    POpt,
    PresetOpt,
    RcOpt,
    RegOpt,
    ROpt,
    SamplesOpt,
    StitchOpt,
    _print_result,
    app,
    compile_notice,
    flag,
    option,
    stitch_inputs,
    user_errors,
    with_chart,
)


@app.command()
def energy(
    state: Annotated[Path, typer.Option("--state", help="a state (Init) file: one number a line, 30 for stockinette")],
    L: LOpt = None, B: BOpt = None, k: KOpt = None, p: POpt = None, r: ROpt = None,
    r_core: RcOpt = None, regularization: RegOpt = None, stitch: StitchOpt = None, chart: ChartOpt = None,
    samples: SamplesOpt = None,
    quadrature_nodes: NodesOpt = None, images: ImagesOpt = None, config: ConfigOpt = None,
    as_json: JsonOpt = False,
) -> None:  # fmt: skip
    """Bending, contact and total energy (mJ = N mm) and yarn length (mm) of a state;
    --json also gives the parameters, the fidelity and the units."""
    from ..formats import read_state
    from ..model import CellModel

    with user_errors():
        stitch = with_chart(stitch, chart)
        params, fidelity = stitch_inputs(
            config, L=L, B=B, k=k, p=p, r=r, r_core=r_core, regularization=regularization,
            stitch=stitch, samples=samples, quadrature_nodes=quadrature_nodes, images=images,
        )  # fmt: skip
        x = read_state(state, params.stitch)
        model = CellModel(params, fidelity)
        model.check_start(x, f"state file {state}")  # before the kernels compile
        compile_notice(params.stitch, energy_only=True)
        result = model.energies(x).as_dict()
    result["a_x"], result["a_y"] = float(x[-2]), float(x[-1])
    result |= {"parameters": {"stitch": params.stitch, **params.model_dump(),
                              "L_over_r": params.L_mm / params.r_mm},
               "fidelity": fidelity.model_dump(mode="json"), "state": str(state),
               "units": RELAX_UNITS}  # fmt: skip
    _print_result(result, as_json, RELAX_UNITS)


StateOpt = Annotated[
    Path | None,
    option("--state", help="starting state (an Init file)", default="the stitch's shipped starts"),
]
StartsOpt = Annotated[int | None, option("--starts", help="starts per point", default="4")]
SeedOpt = Annotated[int, typer.Option("--seed", help="seed of the perturbed starts")]
FtolOpt = Annotated[float | None, option("--ftol", help="precision goal on the energy (mJ) of "
                                         "the preset's minimiser (the paper preset's is "
                                         "slsqp, the others' newton): " + "; ".join(
                                             f"{s.name}: {s.energy_goal}"
                                             for s in SOLVERS.values()),
                                         default="the preset's")]  # fmt: skip


@app.command()
def relax(
    state: StateOpt = None,
    L: LOpt = None, B: BOpt = None, k: KOpt = None, p: POpt = None, r: ROpt = None,
    r_core: RcOpt = None, regularization: RegOpt = None, stitch: StitchOpt = None, chart: ChartOpt = None,
    samples: SamplesOpt = None,
    quadrature_nodes: NodesOpt = None, images: ImagesOpt = None, config: ConfigOpt = None,
    preset: PresetOpt = None, ftol: FtolOpt = None, starts: StartsOpt = None, seed: SeedOpt = 0,
    as_json: JsonOpt = False,
    out: Annotated[Path | None, option("--out", help="also write the relaxed state to this "
                                       "state file (one number per line, as --state reads)",
                                       default="printed only")] = None,
) -> None:  # fmt: skip
    """Relax the zero-force state at fixed yarn length (both periods free). Its seconds
    are the relaxation's, compile_seconds those of compiling the kernels first (0 once
    cached); --json also gives the parameters, numerics and units."""
    import time

    from ..compilation import compile_clock
    from ..config import StartSettings, zero_force_solvers
    from ..errors import InputError, check_seed
    from ..formats import read_state, write_state
    from ..model import CellModel
    from ..presets import Numerics
    from ..relax.zero_force import zero_force
    from ..util.safe_files import check_writable

    with user_errors():
        stitch = with_chart(stitch, chart)
        check_seed(seed)
        if out is not None:
            check_writable(out, "--out")  # before the relaxation, not after
        params, _ = stitch_inputs(config, L=L, B=B, k=k, p=p, r=r, r_core=r_core,
                                  regularization=regularization, stitch=stitch)  # fmt: skip
        n = Numerics.from_preset(preset, ftol=ftol, samples_per_segment=samples,
                                 quadrature_nodes=quadrature_nodes, images=images)  # fmt: skip
        settings = StartSettings() if starts is None else StartSettings(count=starts)
        x0 = None if state is None else read_state(state, params.stitch)
        if x0 is not None:  # before the kernels compile and any relaxation
            CellModel(params, n.fidelity).check_start(x0, f"state file {state}")
        note = zero_force_solvers(params.stitch, n.solver.method)  # the input is good
        if note:
            typer.echo(f"note: {note}", err=True)
        compile_notice(params.stitch)
        t0 = time.perf_counter()
        with compile_clock() as compiling:  # the kernels compile on first call
            best = zero_force(params, n.fidelity, n.solver, settings, seed, initial=x0).best
        seconds = time.perf_counter() - t0
    result = {
        "total_energy": best.total_energy, "bending_energy": best.bending_energy,
        "contact_energy": best.contact_energy, "a_x": best.a_x, "a_y": best.a_y,
        "length": best.length, "converged": best.converged, "status": best.status,
        "message": best.message, "iterations": best.iterations, "evaluations": best.evaluations,
        "min_zeta": best.min_zeta, "seconds": seconds - compiling.seconds,
        "compile_seconds": compiling.seconds,
        "parameters": {"stitch": params.stitch, **params.model_dump(),
                       "L_over_r": params.L_mm / params.r_mm},
        "numerics": {"preset": n.preset, "fidelity": n.fidelity.model_dump(mode="json"),
                     "solver": n.solver.model_dump(mode="json"),
                     "starts": settings.model_dump(mode="json"), "seed": seed,
                     "state": None if state is None else str(state)},
        "units": RELAX_UNITS,
    }  # fmt: skip
    if out is not None:  # the best state, converged or not (the status says which)
        with user_errors():
            try:
                write_state(out, best.x)
            except OSError as e:  # the disk filled or the directory went away meanwhile
                raise InputError(f"--out {out}: cannot write it ({e.strerror or e})") from None
        result["state_file"] = str(out)
    _print_result(result, as_json, RELAX_UNITS)
    if not best.converged:
        raise typer.Exit(1)


@app.command()
def sweep(
    direction: Annotated[str, typer.Option("--direction", help="load path: x or y (uniaxial), biaxial, strip_x, strip_y, shear, shear_free (free yarns), or ray:<rate_x>,<rate_y> with an optional ,<rate_xy> (free yarns)")],
    L: LOpt = None, B: BOpt = None, k: KOpt = None, p: POpt = None, r: ROpt = None,
    r_core: RcOpt = None, regularization: RegOpt = None, stitch: StitchOpt = None, chart: ChartOpt = None,
    samples: SamplesOpt = None,
    quadrature_nodes: NodesOpt = None, images: ImagesOpt = None, config: ConfigOpt = None,
    preset: PresetOpt = None, ftol: FtolOpt = None, starts: StartsOpt = None, seed: SeedOpt = 0,
    step: Annotated[float | None, option("--step", help="small strain step h of the cell "
                                         "period (mm)", default="the preset's")] = None,
    stop_stress: Annotated[float | None, option("--stop-stress", help="stop once the stress "
                                                "exceeds this (N/mm)", default="0.4")] = None,
    max_strain: Annotated[float | None, option("--max-strain", help="stop at this strain",
                                               default="1.0")] = None,
    compression: Annotated[bool, flag("--compression", help="push instead of pull")] = False,
    observables: Annotated[str | None, option(
        "--observables", help="what the sweep must determine, comma-separated: curve, "
        "secant_modulus, offset_stress, energy_gaps; it stops once they are",
        default="curve, with any preset")] = None,
    step_control: Annotated[str | None, option(
        "--step-control", help="fixed (the authors' steps) or adaptive",
        default="the preset's")] = None,
    out: Annotated[Path | None, option("--out", help="also write the table to this .csv or .h5 file",
                                          default="printed only")] = None,
) -> None:  # fmt: skip
    """One point's strain sweep, with a progress bar; prints the stress–strain table (CSV,
    units in the column names, the inputs on its first line); the last line's seconds are
    the sweep's (its rest state included), those of compiling the kernels on the line
    before."""
    import time

    from ..compilation import compile_clock
    from ..config import StartSettings
    from ..errors import InputError, check_seed
    from ..paths import check_path_for_stitch
    from ..presets import Numerics
    from ..service.progress import SweepProgress
    from ..store.sweep_file import sweep_inputs, sweep_table, write_sweep
    from ..strain_sweep import NoRestState, strain_sweep_from_rest
    from ..util.safe_files import check_writable

    with user_errors():
        stitch = with_chart(stitch, chart)
        check_seed(seed)
        try:
            load_path(direction)
        except ValueError as e:
            raise InputError(str(e)) from None
        if out is not None and out.suffix not in (".csv", ".h5"):
            raise InputError(f"out = '{out}': must end in .csv or .h5")
        if out is not None:
            check_writable(out, "--out")  # before the sweep, not after
        params, _ = stitch_inputs(config, L=L, B=B, k=k, p=p, r=r, r_core=r_core,
                                  regularization=regularization, stitch=stitch)  # fmt: skip
        try:
            check_path_for_stitch(direction, params.stitch)
        except ValueError as e:
            raise InputError(str(e)) from None
        n = Numerics.from_preset(
            preset, ftol=ftol, samples_per_segment=samples, quadrature_nodes=quadrature_nodes,
            images=images, step_mm=step, stop_stress_N_per_mm=stop_stress, max_strain=max_strain,
            mode="compression" if compression else None, step_control=step_control,
            # the whole curve unless asked otherwise, whatever the preset's default
            observables=("curve",) if observables is None else tuple(
                o.strip() for o in observables.split(",") if o.strip()),
        )  # fmt: skip
        protocol = n.protocol
        settings = StartSettings() if starts is None else StartSettings(count=starts)
    compile_notice(params.stitch)
    t0 = time.perf_counter()
    with SweepProgress(f"{direction} sweep", protocol.max_strain,
                       protocol.stop_stress_N_per_mm) as bar, compile_clock() as compiling:  # fmt: skip
        try:
            _, result = strain_sweep_from_rest(params, direction, protocol, n.fidelity, n.solver,
                                               settings, seed, bar.update)  # fmt: skip
        except NoRestState as e:
            typer.echo(f"error: {e}", err=True)
            raise typer.Exit(1) from None
    computing = time.perf_counter() - t0 - compiling.seconds  # the rest state and the sweep
    inputs = sweep_inputs(params, direction, n, settings, seed)
    typer.echo(sweep_table(result, inputs))
    if compiling.seconds:
        typer.echo(f"# compiled the kernels in {compiling.seconds:.1f} s (cached from now on)",
                   err=True)  # fmt: skip
    typer.echo(f"# {result.status}: {result.stop_reason}; {len(result.strain)} steps, "
               f"{result.relaxations} relaxations, "
               f"{computing:.1f} s", err=True)  # fmt: skip
    if out is not None:
        with user_errors():
            try:
                write_sweep(out, result, params, inputs)
            except OSError as e:  # the disk filled or the directory went away meanwhile
                raise InputError(f"--out {out}: cannot write it ({e.strerror or e})") from None
