"""Commands on one stitch: energy, relax, sweep."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from .common import (
    ENERGY_UNITS,
    BOpt,
    ConfigOpt,
    ImagesOpt,
    JsonOpt,
    KOpt,
    LOpt,
    NodesOpt,
    POpt,
    RcOpt,
    RegOpt,
    ROpt,
    SamplesOpt,
    _print_result,
    app,
    stitch_inputs,
    user_errors,
)


@app.command()
def energy(
    state: Annotated[Path, typer.Option("--state", help="a 30-line state (Init) file")],
    L: LOpt = None, B: BOpt = None, k: KOpt = None, p: POpt = None, r: ROpt = None,
    r_core: RcOpt = None, regularization: RegOpt = None, samples: SamplesOpt = None,
    quadrature_nodes: NodesOpt = None, images: ImagesOpt = None, config: ConfigOpt = None,
    as_json: JsonOpt = False,
) -> None:  # fmt: skip
    """Bending, contact and total energy (mJ = N mm) and yarn length (mm) of a state."""
    from ..formats import read_state
    from ..model import CellModel

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
    from ..presets import DEFAULT_PRESET, preset_settings

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

    from ..config import Fidelity, SolverSettings
    from ..formats import read_state
    from ..relax import relax_with_continuation
    from ..zero_force import SHIPPED_SOURCE, StartSettings, zero_force

    with user_errors():
        params, _ = stitch_inputs(config, L=L, B=B, k=k, p=p, r=r, r_core=r_core,
                                  regularization=regularization)  # fmt: skip
        fid, sol, _ = _numerics(preset, ftol, samples, quadrature_nodes, images)
        fidelity, solver = Fidelity(**fid), SolverSettings(**sol)
        t0 = time.perf_counter()
        if state is not None:
            from ..model import CellModel

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
    from ..config import Fidelity, InputError, SolverSettings
    from ..report.sweep_table import sweep_table, write_sweep
    from ..strain_sweep import SweepProtocol, strain_sweep
    from ..zero_force import StartSettings, zero_force

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
