"""Unit tier: the stitch and solver registries are the one list that validation, help
texts, error messages and the minimisers that run are built from."""

from typing import get_args

import pytest
import typer.main

from knitsweep.cli import app
from knitsweep.config import (
    SOLVER_NAMES,
    SOLVERS,
    SolverSettings,
    StitchParams,
    zero_force_solvers,
)
from knitsweep.errors import InputError, describe_validation_error
from knitsweep.stitches import STITCH_CHOICES, STITCH_NAMES, check_stitch_name, get_stitch


def test_every_registered_solver_is_the_settings_choice_and_has_a_minimiser():
    from knitsweep.relax.relaxer import SOLVERS as BOUND

    allowed = get_args(SolverSettings.model_fields["method"].annotation)
    assert allowed == SOLVER_NAMES == tuple(SOLVERS) == tuple(BOUND)
    for name, solver in BOUND.items():
        assert solver.info is SOLVERS[name] and callable(solver.minimise)


def test_unknown_solver_names_the_registered_ones():
    with pytest.raises(ValueError) as e:
        SolverSettings(method="lbfgs")
    assert "'newton' or 'slsqp'" in describe_validation_error(e.value)


def test_the_energy_goal_says_what_it_bounds_for_each_solver():
    text = SolverSettings.model_fields["ftol"].description
    for info in SOLVERS.values():
        assert f"{info.name}: {info.energy_goal}" in text
    s = SolverSettings(ftol=3e-9)
    assert s.decrement_goal_mJ == s.energy_change_goal_mJ == 3e-9
    assert s.loosened(1e-7).ftol == 1e-7 and s.loosened(1e-12).ftol == 3e-9


def test_stitch_errors_and_help_list_the_registry():
    assert STITCH_CHOICES == ", ".join(STITCH_NAMES)
    for name in STITCH_NAMES:
        assert check_stitch_name(name) == name == get_stitch(name).name
    with pytest.raises(
        InputError,
        match=f"^grid.stitch = 'moss': must be one of {STITCH_CHOICES}, or a knit/purl chart as "
        "chart:KKPP$",
    ):
        check_stitch_name("moss", "grid.stitch")
    with pytest.raises(ValueError) as e:
        StitchParams(stitch="moss")
    assert describe_validation_error(e.value) == (
        f"stitch = 'moss': must be one of {STITCH_CHOICES}, or a knit/purl chart as chart:KKPP"
    )
    assert STITCH_CHOICES in StitchParams.model_fields["stitch"].description
    cli = typer.main.get_command(app)
    for command in ("energy", "relax", "sweep", "render", "compile"):
        stitch = next(p for p in cli.commands[command].params if p.name == "stitch")
        assert STITCH_CHOICES in stitch.help, command


def test_a_job_says_before_computing_where_its_solver_does_not_relax_alone(tmp_path):
    from knitsweep.service.jobs import load_job

    def job(stitches: str, preset: str):
        path = tmp_path / f"{preset}.toml"
        path.write_text(f'schema_version = 1\nname = "j"\npreset = "{preset}"\n'
                        f"[grid]\nL_mm = 11.6\nstitch = {stitches}\n")  # fmt: skip
        return load_job(path)

    notes = job('["stockinette", "garter", "rib"]', "converged").solver_notes()
    assert [n.split(":")[0] for n in notes] == ["garter", "rib"]
    assert all("SLSQP" in n and "newton" in n and "§11" in n for n in notes)
    assert job('["stockinette", "garter"]', "paper").solver_notes() == []  # SLSQP alone
    assert job('"stockinette"', "converged").solver_notes() == []


def test_a_rough_stitch_with_slsqp_chosen_runs_slsqp_alone(monkeypatch):
    """``zero_force_solvers`` says nothing for SLSQP: then no stage of a rough stitch's
    continuation, nor its target, calls Newton."""
    import numpy as np

    from knitsweep.config import Fidelity
    from knitsweep.relax import relaxer
    from knitsweep.relax.continuation import walk_starts
    from knitsweep.relax.zero_force import shipped_source

    def refuse(*args):
        raise AssertionError("Newton ran with SLSQP chosen")

    newton = relaxer.SOLVERS["newton"]
    monkeypatch.setitem(relaxer.SOLVERS, "newton", relaxer.Solver(newton.info, refuse))
    x0 = get_stitch("garter").start(1)  # its yarn is 14.58 mm long
    source = shipped_source("garter").model_copy(update={"L_mm": 14.58})
    target = source.model_copy(update={"L_mm": 14.7})  # two stages
    settings = SolverSettings(method="slsqp", ftol=1e-6, maxiter=200)
    assert zero_force_solvers("garter", "slsqp") == ""
    [(r, stages)], _, _ = walk_starts(target, Fidelity(), [(x0, source)], settings)
    assert stages == 2 and np.all(np.isfinite(r.x))
