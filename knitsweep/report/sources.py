"""Where a picture's (or a 3D file's) stitch comes from: a task of a results file (a
point's zero-force state, a sweep's step), a state file, or a relaxation of the
stitch at given parameters (``knitsweep render --stitch NAME --L …`` with neither).
Each gives a :class:`~knitsweep.report.tile.Stitch` with its parameters and a
description of the state drawn."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..config import StitchParams
from ..errors import InputError
from .tile import Stitch


def parameters_line(params: StitchParams) -> str:
    """The stitch's parameters as a picture's subtitle: L, k, B, r, r_core (paper Table 1)."""
    return (f"L = {params.L_mm:g} mm, k = {params.k_mN_per_mm2:g} mN/mm², "
            f"B = {params.B_mN_mm2:g} mN·mm², r = {params.r_mm:g} mm, "
            f"r_core = {params.r_core_mm:g} mm")  # fmt: skip


FROM_FILE = "state of "
"""How a state file's stitch is labelled ("state of garter.dat"): said under the
picture, not in its title, which names what is drawn rather than where it was read."""


def title(stitch: Stitch) -> str:
    """Two lines: the stitch pattern and the state drawn, then its parameters."""
    shown = stitch.label and not stitch.label.startswith(FROM_FILE)
    head = f"{stitch.name}: {stitch.label}" if shown else stitch.name
    return head if stitch.params is None else f"{head}\n{parameters_line(stitch.params)}"


def stitch_from_state(x: np.ndarray, params: StitchParams, label: str = "") -> Stitch:
    """The picture of a state vector of the stitch ``params.stitch`` (docs/model.md §2);
    ``label`` says which state it is."""
    from ..model import CellModel

    model = CellModel(params)
    return drawn(model.control_points(x), float(x[-2]), float(x[-1]), params, label)


def drawn(cp: np.ndarray, a_x: float, a_y: float, params: StitchParams, label: str) -> Stitch:
    """The picture of control points (S, 6, 3) of the stitch ``params.stitch``, in its
    drawing order, with its images as the stitch declares them (``images``: translations,
    or glides with its ``mirror_parity``)."""
    from ..stitches import get_stitch

    geometry = get_stitch(params.stitch)
    order = list(geometry.path_order)
    parity = tuple(geometry.mirror_parity)  # (0, 0) for translations alone
    return Stitch(np.asarray(cp, dtype=float)[order], a_x, a_y, params.r_mm, label,
                  geometry.closing_shift, parity, params)  # fmt: skip


def _find_task(results: Path, task: str) -> Any:
    from ..store.read import iter_entries, read_root

    read_root(results)
    matches = [e for e in iter_entries(results, with_data=True) if e.task_id.startswith(task)]
    if not matches:
        raise InputError(f"task = {task!r}: no point or sweep with this id in {results}")
    if len(matches) > 1:
        raise InputError(f"task = {task!r}: matches {len(matches)} tasks; give more characters")
    return matches[0]


def stitch_from_results(results: str | Path, task: str, step: int | None = None) -> Stitch:
    """The stitch of one task of a results file.

    A point id gives its zero-force state (the lowest-energy start). A sweep id gives
    the state at ``step`` (default 0, the zero-force state); steps other than 0 need
    the sweep's stored ``states`` or ``control_points`` ([store] states or geometry).
    Ids may be abbreviated to a unique prefix.
    """
    from ..store.format import POINTS
    from ..store.read import iter_entries

    results = Path(results)
    e = _find_task(results, task)
    meta, rec = e.meta, e.record
    if meta.get("status") != "done":
        raise InputError(f"task {e.task_id} has status {meta.get('status')!r}: nothing to draw")
    params = StitchParams.from_flat(meta)
    if e.kind == POINTS:
        if step not in (None, 0):
            raise InputError(
                f"strain_step = {step}: a point has only its zero-force state (step 0)"
            )
        x = np.asarray(rec["x"][int(meta.get("winner", 0))], dtype=float)
        return stitch_from_state(x, params, "zero-force state")
    step = 0 if step is None else step
    n = len(rec.get("strain", []))
    if not 0 <= step < n:
        raise InputError(f"strain_step = {step}: sweep {e.task_id} has steps 0..{n - 1}")
    label = f"pulled in {meta['direction']}, step {step} (strain {rec['strain'][step]:.3f})"
    if "control_points" in rec:
        cp = np.asarray(rec["control_points"][step], dtype=float)
        return drawn(cp, float(rec["a_x"][step]), float(rec["a_y"][step]), params, label)
    if "states" in rec:
        return stitch_from_state(np.asarray(rec["states"][step], dtype=float), params, label)
    if step == 0:
        point = next((p for p in iter_entries(results, with_data=True)
                      if p.kind == POINTS and p.task_id == meta.get("point_id")), None)  # fmt: skip
        if point is not None:
            x = np.asarray(point.record["x"][int(point.meta.get("winner", 0))], dtype=float)
            return stitch_from_state(x, params, label)
    raise InputError(
        f"sweep {e.task_id} stores no states or control points; only step 0 can be drawn "
        "(set [store] states = true or geometry = true in the job to keep every step)"
    )


def relaxed_stitch(params: StitchParams, preset: str | None = None, starts: int = 1) -> Stitch:
    """The zero-force state of ``params`` relaxed from the stitch's shipped starts
    (``starts`` of them, the lowest energy kept; the ``preset``'s numerics, default the
    default preset), as ``knitsweep relax`` would."""
    from ..config import StartSettings
    from ..presets import Numerics
    from ..relax.zero_force import zero_force

    n = Numerics.from_preset(preset)
    best = zero_force(params, n.fidelity, n.solver, StartSettings(count=starts)).best
    what = "zero-force state" if best.converged else f"not converged ({best.status})"
    return stitch_from_state(best.x, params, f"{what}, relaxed")


def stitch_to_draw(
    results: Path | None,
    task: str | None,
    step: int | None,
    state: Path | None,
    params: StitchParams | None,
    preset: str | None = None,
    starts: int = 1,
) -> Stitch:
    """The picture's stitch: a task of a results file (at a sweep's ``step``), a state
    file at ``params`` (default paper Table 1), or, with neither, ``params`` relaxed."""
    if results is not None:
        if task is None:
            raise InputError("--results needs --task ID (a point or sweep id)")
        return stitch_from_results(results, task, step)
    if step is not None:
        raise InputError("--strain-step applies to a sweep of a results file, not to --state")
    params = params or StitchParams()
    if state is None:
        return relaxed_stitch(params, preset, starts)
    from ..formats import read_state
    from ..model import CellModel

    x = read_state(state, params.stitch)
    CellModel(params).check_start(x, f"state file {state}")  # before anything is drawn
    return stitch_from_state(x, params, f"{FROM_FILE}{Path(state).name}")
