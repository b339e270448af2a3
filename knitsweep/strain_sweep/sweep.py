"""Strain sweeps: the stitch deformed step by step along a load path (docs/model.md §8).

From the zero-force state (a_x0, a_y0) the path's leading period is fixed step by step
(``schedule``), its other controlled period (``paths``: equibiaxial, strip biaxial)
follows by its strain rate, a free period and the shape relax, and each step
warm-starts from the last. Pulled in x or y (the paper's), the other period is free. Every
start of the point is carried along as its own chain (``chains``: each with its own
solver state, merged when two reach the same minimum); at each step the
lowest-energy chain wins. The sweep stops by the reference's rule (after step i >= 2,
(E_{i-2} - E_i)/(a_{i-2} - a_i)/a_perp0 beyond the stop stress, or |strain| beyond the
largest), or as soon as the observables its protocol asks for are determined. A step
that would end the sweep more than 10 % above its stop stress (``STOP_OVERSHOOT``: the
large steps of a stiff jammed curve) is taken again at half its length, down to the
small step, so a curve ends where it was asked to; the stress that decides is the
envelope stress, exact at each step (the length multiplier), since the reference's
rule lags a step behind. A long step near the stop stress whose relaxation ends with
the cores overlapping (it jumped through a tight state) is taken again the same way;
only at the small step does the overlap end the sweep as not knittable.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable

import numpy as np

from ..config import (
    CONVERGED,
    NOT_KNITTABLE,
    Direction,
    Fidelity,
    SolverSettings,
    StartSettings,
    StitchParams,
    SweepProtocol,
)
from ..model import CellModel
from ..paths import load_path
from ..quantities import registered
from ..relax import Chain, Relaxation, Relaxer, merge_chains, single_threaded
from ..relax.zero_force import ZeroForce, pick_lowest, relax_at_rest, zero_force
from ..stitches.topology import stitch_topology
from .rest_skew import relax_skew
from .result import SweepResult, centred_stress
from .schedule import StepControl, observables_determined

STOP_OVERSHOOT = 1.1
"""A sweep ends at most this factor above its stop stress (unless at the small step)."""
MAX_REST_RESTARTS = 5
"""A sweep starts over from a lower zero-force state it finds at most this often."""
STOP_WATCH = 0.5
"""From this fraction of the stop stress on (envelope stress), each step can be taken
again shorter."""


def strain_sweep(
    params: StitchParams,
    zero: ZeroForce,
    direction: Direction,
    protocol: SweepProtocol | None = None,
    fidelity: Fidelity | None = None,
    solver: SolverSettings | None = None,
    progress: Callable[[int, float, float], None] | None = None,
) -> SweepResult:
    """Pull the zero-force stitch in ``direction`` following ``protocol``.

    ``progress(step, strain, stress)`` is called after every step.
    """
    with single_threaded():
        return _sweep(params, zero, direction, protocol or SweepProtocol(),
                      fidelity or Fidelity(), solver or SolverSettings(), progress)  # fmt: skip


def _sweep(params, zero, direction, protocol, fidelity, solver, progress) -> SweepResult:
    """The sweep, started over from each lower zero-force state it finds (``_pull``)."""
    t_start = time.perf_counter()
    model = CellModel(params, fidelity)
    notes: list[str] = []
    restarts = 0
    spent = [0, 0]  # relaxations and energy evaluations of every pull
    upright = zero.best.total_energy
    skew0 = 0.0  # a shear's rest skew (mm): that rest is this sweep's alone
    skewing = (load_path(direction).shears and model.image_group.shears
               and protocol.shear_rest == "relaxed")  # fmt: skip
    if skewing:
        skewed = relax_skew(model, zero.best, solver, protocol.rest_tolerance_mJ)
        if skewed is not None:
            zero = zero.with_lower_minimum(zero.winner, skewed.relaxation, skewed.note)
            skew0 = skewed.skew_mm
            notes.append(skewed.note)
            spent[0] += skewed.relaxations
    while True:
        result, found, note = _pull(model, zero, direction, protocol, solver, progress, t_start,
                                    restarts < MAX_REST_RESTARTS, spent, skew0, skewing)  # fmt: skip
        if note:
            notes.append(note)
        if found is None:
            break
        (zero, skew0), restarts = found, restarts + 1
    result.rest = zero if restarts and not skewing else None
    result.rest_restarts = restarts
    result.rest_found = "; ".join(notes)
    if skew0 != 0.0:
        result.rest_skew = skew0 / zero.best.a_y
        result.rest_skew_fall_mJ = upright - zero.best.total_energy
    result.wall_seconds = time.perf_counter() - t_start
    return result


def _pull(model, zero, direction, protocol, solver, progress, t_start, check_rest, spent,
          skew0=0.0, skewing=False):  # fmt: skip
    """One pull from ``zero`` (its skew ``skew0``, mm; the path's skew adds to it; with
    ``skewing`` a lower rest is relaxed in its skew too): (the sweep, None, a note or "");
    or, with ``check_rest``, as soon as a step's energy falls more than
    ``protocol.rest_tolerance_mJ`` below the zero-force energy and relaxing that step at
    zero force finds a minimum lower by as much, (None, (the zero-force state with that
    minimum, its skew), a note saying so). If it finds none, the pull goes on unchecked
    and its note says so."""
    path = load_path(direction)
    idx = {d: model.stitch.period_index(d) for d in ("x", "y")}
    best = zero.best
    rest = {d: float(best.x[i]) for d, i in idx.items()}  # a_x0, a_y0
    rest["xy"] = rest["y"]  # a shear's coordinate: a_y0 (1 + γ) (paths.LoadPath.leading)
    a0, a_perp0 = rest[path.leading], rest[path.transverse]
    if path.shears:
        if not model.image_group.shears:
            raise ValueError(f"direction = {direction!r}: stitch {model.stitch.name} cannot "
                             "shear (a mirror-symmetric ansatz); shear a free yarn such as "
                             "stockinette_free")  # fmt: skip
        check_rest = check_rest and skewing  # a shear's lower rest: its skew relaxed too
    sign = 1.0 if protocol.mode == "tension" else -1.0
    n_starts = len(zero.relaxations)
    # starts that merged on their way to the zero-force state count as merged there
    merged_into = np.array(zero.merged_into or [-1] * n_starts, dtype=np.int64)
    merged_at = np.where(merged_into >= 0, 0, -1).astype(np.int64)
    chains = _start_chains(zero, merged_into, solver)
    carried = np.zeros(n_starts, dtype=bool)
    carried[[c.start for c in chains]] = True
    chains = merge_chains(chains, model, None, protocol.merge_tolerance_mJ, 0, merged_into,
                          merged_at)  # fmt: skip
    model.skew = skew0
    steps: list[Relaxation] = [best]
    shears = model.image_group.shears  # the force on the skew is measured (σ_xy)
    skew_forces = [model.skew_force(best.x) if shears else 0.0]
    winners = [zero.winner]
    a_values, strains = [a0], [0.0]
    envelope = [0.0]
    eb, ec = [best.bending_energy], [best.contact_energy]
    control = StepControl(protocol, direction, a0, sign)
    a_next = control.first()
    status, stopped_by, reason = "done", "", ""
    n_relax, n_eval = spent
    unfound = ""
    stop = protocol.stop_stress_N_per_mm
    sigma_last = 0.0
    while True:
        # near the stop stress, keep what a step changes, to take it again shorter if it
        # overshoots (far from it nothing is kept: those sweeps are as they always were)
        saved = (copy.deepcopy(chains), merged_into.copy(), merged_at.copy()
                 ) if sigma_last > STOP_WATCH * stop else None  # fmt: skip
        targets = path.targets(rest, (a_next - a0) / a0)
        if path.leading == "xy":  # the skew leads (exactly the schedule's value)
            model.skew = skew0 + (a_next - a0)
        else:
            targets[path.leading] = a_next  # (exactly: the schedule's value)
            if path.shears:  # a ray that shears as it pulls: the skew follows its rate
                model.skew = skew0 + path.rate_xy * (a_next - a0) / a0 * rest["y"]
        for c in chains:
            x = c.x.copy()
            for d, a in targets.items():
                x[idx[d]] = a
            r = c.relaxer.relax(model, x, direction)
            n_relax += 1
            n_eval += r.evaluations
            c.last = r
            if np.all(np.isfinite(r.x)) and math.isfinite(r.total_energy):
                c.x = r.x
        w, step_status = pick_lowest([c.last for c in chains])
        win = chains[w].last
        if not math.isfinite(win.total_energy):
            status, stopped_by = "failed", "no_finite_relaxation"
            reason = f"no finite relaxation at a = {a_next:.6g} mm"
            break
        steps.append(win)
        winners.append(chains[w].start)
        a_values.append(a_next)
        strains.append((a_next - a0) / a0)
        skew_forces.append(model.skew_force(win.x) if shears else 0.0)
        envelope.append(path.conjugate_stress(*win.period_forces, rest["x"], rest["y"],
                                              skew_forces[-1]))  # fmt: skip
        eb.append(win.bending_energy)
        ec.append(win.contact_energy)
        i = len(steps) - 1
        strain = strains[-1]
        e = [b + c for b, c in zip(eb[-3:], ec[-3:], strict=True)]
        sigma_ref = (e[0] - e[-1]) / (a_values[-3] - a_values[-1]) / a_perp0 if i >= 2 else 0.0
        h = abs(a_values[-1] - a_values[-2])
        overshot = (sign * envelope[-1] > STOP_OVERSHOOT * stop
                    and observables_determined(protocol, strains, eb, ec) is None)  # fmt: skip
        if (saved is not None and i >= 3 and h > protocol.step_mm * (1.0 + 1e-9)
                and (overshot or step_status == NOT_KNITTABLE)):  # fmt: skip
            # past the stop stress by more than 10 %, or a long step near it that ended
            # with the cores overlapping: take the step again, half as long
            for values in (steps, winners, a_values, strains, envelope, eb, ec, skew_forces):
                values.pop()
            chains, merged_into[:], merged_at[:] = saved[0], saved[1], saved[2]
            a_next = a_values[-1] + sign * max(h / 2.0, protocol.step_mm)
            continue
        sigma_last = sign * envelope[-1]
        fall = steps[0].total_energy - win.total_energy
        if check_rest and win.status == CONVERGED and fall > protocol.rest_tolerance_mJ:
            found, note = _lower_rest(model, zero, chains[w].start, win, direction, strain, fall,
                                      solver, protocol.rest_tolerance_mJ, skewing,
                                      skew0)  # fmt: skip
            if found is not None:
                spent[:] = n_relax, n_eval
                return None, found, note
            unfound, check_rest = note, False
        if progress is not None:
            progress(i, strain, sigma_ref)
        chains = merge_chains(chains, model, direction, protocol.merge_tolerance_mJ, i,
                              merged_into, merged_at)  # fmt: skip
        determined = observables_determined(protocol, strains, eb, ec)
        if step_status == NOT_KNITTABLE:
            status, stopped_by = "not_knittable", "not_knittable"
            reason = f"cores overlap at strain {strain:.4g}"
        elif i >= 2 and sign * sigma_ref > protocol.stop_stress_N_per_mm:
            stopped_by = "stop_stress"
            reason = f"stress {sigma_ref:.4g} N/mm > {protocol.stop_stress_N_per_mm:g}"
        elif abs(strain) > protocol.max_strain:
            stopped_by = "max_strain"
            reason = f"|strain| {abs(strain):.4g} > {protocol.max_strain:g}"
        elif determined is not None:
            stopped_by, reason = "observables", f"{determined} at strain {strain:.4g}"
        elif i >= protocol.max_steps:
            status, stopped_by = "incomplete", "max_steps"
            reason = f"step limit {protocol.max_steps} reached"
        if stopped_by:
            break
        a_next = control.next(a_values, envelope, eb, ec)
    model.skew = 0.0
    result = _assemble(model, path, steps, winners, a_values, rest, status, reason,
                       stopped_by, n_relax, n_eval, (carried, merged_into, merged_at),
                       time.perf_counter() - t_start, np.array(skew_forces))  # fmt: skip
    return result, None, unfound


def _lower_rest(model, zero, start, step, direction, strain, fall, solver, tolerance,
                skewing=False, skew0=0.0):  # fmt: skip
    """((the zero-force state with the minimum relaxed at zero force from sweep step
    ``step`` of chain ``start``, its skew), or None if that is not lower by the tolerance,
    and a note saying what was found). With ``skewing`` (a shear from a rest at skew
    ``skew0``) the skew relaxes too, from the step's (``rest_skew.relax_skew``, which
    leaves ``model.skew`` the step's)."""
    rest = zero.best.total_energy
    skew = model.skew if skewing else 0.0
    lower = relax_at_rest(model, step.x, solver)
    if skewing and lower.status == CONVERGED:
        skewed = relax_skew(model, lower, solver, 0.0, skew)
        if skewed is not None:
            lower, skew = skewed.relaxation, skewed.skew_mm
    where = (f"the {direction} sweep fell {fall:.3g} mJ below the zero-force energy "
             f"{rest:.7f} mJ at strain {strain:.4g}")  # fmt: skip
    if lower.status != CONVERGED or not rest - lower.total_energy > tolerance:
        return None, (f"{where}; relaxed again at zero force from there: "
                      f"{lower.total_energy:.7f} mJ ({lower.status}), kept the first")  # fmt: skip
    if _crossings(model, lower.x, skew) != _crossings(model, zero.best.x, skew0):
        # another fabric (a free yarn pulled straight, rows apart): not this point's rest
        return None, (f"{where}; relaxed again at zero force from there: "
                      f"{lower.total_energy:.7f} mJ with other crossings than the zero-force "
                      "state's (another fabric), kept the first")  # fmt: skip
    at = f" at gamma0 = {skew / lower.a_y:.5g}" if skewing else ""
    note = (f"{where}; relaxed again at zero force from there: {lower.total_energy:.7f} mJ"
            f"{at}, the zero-force state from then on")  # fmt: skip
    return (zero.with_lower_minimum(start, lower, note), skew), note


def _crossings(model: CellModel, x: np.ndarray, skew: float) -> tuple:
    """How the rows of state ``x`` (its wale vector's skew ``skew``, mm) cross one another
    in projection (``topology.stitch_topology``: what a relaxation of a pattern must keep), for
    any stitch."""
    return stitch_topology(model.stitch, model.control_points(x), x, skew)


def _start_chains(zero: ZeroForce, merged_into: np.ndarray, solver: SolverSettings) -> list[Chain]:
    """A chain for every start whose own zero-force state converged (the winner alone
    if none did)."""
    chains = [Chain(i, r.x.copy(), Relaxer(solver), r) for i, r in enumerate(zero.relaxations)
              if r.status == CONVERGED and merged_into[i] < 0 and np.all(np.isfinite(r.x))]  # fmt: skip
    if not chains:
        best = zero.best
        chains = [Chain(zero.winner, best.x.copy(), Relaxer(solver), best)]
    return chains


def _assemble(model, path, steps, winners, a_values, rest, status, reason,
              stopped_by, n_relax, n_eval, starts, wall, skew_forces) -> SweepResult:  # fmt: skip
    a0, a_perp0 = rest[path.leading], rest[path.transverse]
    a = np.array(a_values)
    eb = np.array([s.bending_energy for s in steps])
    ec = np.array([s.contact_energy for s in steps])
    fx, fy = np.array([s.period_forces for s in steps]).T
    carried, merged_into, merged_at = starts
    return SweepResult(
        direction=path.name,
        a_fixed=a,
        a_x=np.array([s.a_x for s in steps]),
        a_y=np.array([s.a_y for s in steps]),
        strain=(a - a0) / a0,
        stress=centred_stress(eb + ec, a, a_perp0),
        stress_envelope=path.conjugate_stress(fx, fy, rest["x"], rest["y"], skew_forces),
        stress_xx=fx / rest["y"],
        stress_yy=fy / rest["x"],
        stress_xy=skew_forces / rest["x"],
        bending_energy=eb,
        contact_energy=ec,
        observed=_step_observables(model, steps),
        winner=np.array(winners, dtype=np.int64),
        converged=np.array([s.status == CONVERGED for s in steps]),
        iterations=np.array([s.iterations for s in steps], dtype=np.int64),
        evaluations=np.array([s.evaluations for s in steps], dtype=np.int64),
        min_zeta=np.array([s.min_zeta for s in steps]),
        length_residual=np.array([s.length_residual for s in steps]),
        kkt_residual=np.array([s.kkt_residual for s in steps]),
        relax_seconds=np.array([s.seconds for s in steps]),
        states=np.array([s.x for s in steps]),
        carried=carried,
        merged_into=merged_into,
        merged_at=merged_at,
        status=status,
        stop_reason=reason,
        stopped_by=stopped_by,
        relaxations=n_relax,
        evaluations_total=n_eval,
        wall_seconds=wall,
    )


def _step_observables(model: CellModel, steps: list[Relaxation]) -> dict[str, np.ndarray]:
    """Every registered step observable (``quantities.registered("step")``) of every
    step's state, (n,) each, by name."""
    return {o.name: np.array([getattr(model, o.method)(s.x) for s in steps])
            for o in registered("step")}  # fmt: skip


class NoRestState(RuntimeError):
    """No start of a point reached a converged zero-force state."""


def strain_sweep_from_rest(
    params: StitchParams,
    direction: Direction,
    protocol: SweepProtocol | None = None,
    fidelity: Fidelity | None = None,
    solver: SolverSettings | None = None,
    starts: StartSettings | None = None,
    seed: int = 0,
    progress: Callable[[int, float, float], None] | None = None,
) -> tuple[ZeroForce, SweepResult]:
    """One point from scratch: its zero-force state (every start), then the sweep.

    Raises:
        NoRestState: no start reached a zero-force state to pull from.
    """
    zero = zero_force(params, fidelity, solver, starts, seed)
    if not zero.best.converged:
        raise NoRestState(f"no zero-force state: {zero.message}")
    return zero, strain_sweep(params, zero, direction, protocol, fidelity, solver, progress)
