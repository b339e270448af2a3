"""Continuation in parameters: a zero-force state walked from the parameters it was
relaxed at to the target in small stages (docs/model.md §7, a knitsweep addition)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..config import CONVERGED, NOT_CONVERGED, NOT_KNITTABLE, Fidelity, SolverSettings, StitchParams
from ..model import CellModel
from ..stitches import get_stitch
from ..stitches.topology import TOPOLOGY_CHANGED
from .chains import Chain, merge_chains
from .relaxer import Relaxer
from .result import Relaxation, with_status

STAGE_FTOL = 1e-7
"""Energy goal (mJ, ``SolverSettings.ftol``) of a continuation's intermediate stages, at
least: they are not recorded, only walked through."""
ROUGH_SLSQP_MAXITER = 10
"""SLSQP's iteration limit in ``relax_rough``, in units of ``SolverSettings.maxiter``."""


def continuation_path(
    start: StitchParams, target: StitchParams, settings: SolverSettings
) -> list[StitchParams]:
    """Parameter stages from ``start`` to ``target`` (the last one is ``target``).

    L, r, r_core, p and the regularisation move linearly, k and B geometrically,
    each by at most the step allowed in ``settings``.
    """
    f = math.log(settings.continuation_factor)
    n = max(
        1,
        math.ceil(abs(target.L_mm - start.L_mm) / settings.continuation_dL_mm - 1e-9),
        math.ceil(abs(math.log(target.k_mN_per_mm2 / start.k_mN_per_mm2)) / f - 1e-9),
        math.ceil(abs(math.log(target.B_mN_mm2 / start.B_mN_mm2)) / f - 1e-9),
        math.ceil(abs(target.r_mm - start.r_mm) / settings.continuation_dr_mm - 1e-9),
        math.ceil(abs(target.r_core_mm - start.r_core_mm) / settings.continuation_dr_mm - 1e-9),
        math.ceil(abs(target.p - start.p) / settings.continuation_dp - 1e-9),
    )
    stages = []
    for i in range(1, n):
        t = i / n

        def lin(a: float, b: float, t: float = t) -> float:
            return a + t * (b - a)

        def geo(a: float, b: float, t: float = t) -> float:
            return a * (b / a) ** t

        stages.append(
            target.model_copy(
                update={
                    "L_mm": lin(start.L_mm, target.L_mm),
                    "k_mN_per_mm2": geo(start.k_mN_per_mm2, target.k_mN_per_mm2),
                    "B_mN_mm2": geo(start.B_mN_mm2, target.B_mN_mm2),
                    "r_mm": lin(start.r_mm, target.r_mm),
                    "r_core_mm": lin(start.r_core_mm, target.r_core_mm),
                    "p": lin(start.p, target.p),
                    "regularization_mN_mm4": lin(
                        start.regularization_mN_mm4, target.regularization_mN_mm4
                    ),
                }
            )
        )
    stages.append(target)
    return stages


def walk_starts(
    target: StitchParams,
    fidelity: Fidelity,
    starts: list[tuple[np.ndarray, StitchParams]],
    settings: SolverSettings | None = None,
    merge_tolerance: float = 0.0,
) -> tuple[list[tuple[Relaxation, int]], np.ndarray, np.ndarray]:
    """Zero-force relaxations at ``target`` from several starts (state (n,), the
    parameters it was relaxed at), each walked there in small parameter stages
    (docs/model.md §7).

    Starts relaxed at the same parameters (lengths within ``length_tol_mm``) walk the same
    stages, those of the first of them, side by side, and after
    each intermediate stage those at the same minimum merge (``chains.merge_chains``):
    only one walks on. Returns, per start, its last relaxation and the number of stages
    it was relaxed at, and per start the start it merged into and the stage where it did
    (-1 if not). A merged start's relaxation is the one it merged into, at the target.

    Intermediate stages use a looser tolerance; a stage that ends non-finite or with
    overlapping cores stops that start's walk, and that stage's status is kept.
    """
    settings = settings or SolverSettings()
    loose = settings.loosened(STAGE_FTOL)
    n = len(starts)
    merged_into = np.full(n, -1, dtype=np.int64)
    merged_at = np.full(n, -1, dtype=np.int64)
    done: dict[int, tuple[Relaxation, int]] = {}
    # starts relaxed at the same parameters walk one path; lengths that agree within the
    # length tolerance count as the same (the shipped Init states measure 11.28 mm each,
    # to ~1e-7 mm)
    groups: dict[str, list[int]] = {}
    for i, (_, params) in enumerate(starts):
        step = settings.length_tol_mm
        key = params.model_copy(update={"L_mm": round(params.L_mm / step) * step})
        groups.setdefault(key.model_dump_json(), []).append(i)
    stitch = get_stitch(target.stitch)
    rough, path = stitch.rough, settings
    if stitch.stage_dL_mm is not None:
        dl = max(settings.continuation_dL_mm, stitch.stage_dL_mm)
        path = settings.model_copy(update={"continuation_dL_mm": dl})
    for members in groups.values():
        stages = continuation_path(starts[members[0]][1], target, path)
        chains = [Chain(i, np.asarray(starts[i][0], dtype=float), Relaxer(settings), None)
                  for i in members]  # fmt: skip
        for k, params in enumerate(stages):
            last = k == len(stages) - 1
            model = CellModel(params, fidelity)
            for c in chains:
                stage = settings if last else loose
                if rough and not last:
                    c.last = Relaxer(_slsqp(stage)).relax(model, c.x, None)
                else:
                    c.last = relax_zero_force(c.relaxer, model, c.x, stage)
                r = c.last
                if not np.all(np.isfinite(r.x)) or (not last and r.status == NOT_KNITTABLE):
                    where = (
                        f"at continuation stage {k + 1}/{len(stages)} (L = {params.L_mm:.4g} mm)"
                    )
                    status = r.status if r.status == NOT_KNITTABLE else NOT_CONVERGED
                    done[c.start] = with_status(r, status, f"{r.message} {where}"), k + 1
                c.x = r.x
            chains = [c for c in chains if c.start not in done]
            if not last:
                chains = merge_chains(chains, model, None, merge_tolerance, k + 1, merged_into,
                                      merged_at)  # fmt: skip
        done.update({c.start: (c.last, len(stages)) for c in chains})
    for i in np.flatnonzero(merged_into >= 0):
        j = int(merged_into[i])
        while merged_into[j] >= 0:  # it merged into one that merged on
            j = int(merged_into[j])
        r, total = done[j]
        note = f"merged into start {j} at continuation stage {merged_at[i]}/{total}: same minimum"
        done[int(i)] = replace(r, message=note, iterations=0, evaluations=0, seconds=0.0), total
    return [done[i] for i in range(n)], merged_into, merged_at


def relax_zero_force(relaxer: Relaxer, model: CellModel, x: np.ndarray,
                     settings: SolverSettings) -> Relaxation:  # fmt: skip
    """The zero-force relaxation (both periods free) from ``x`` at the model's own
    parameters, as a walk's last stage relaxes it: a ``Stitch.rough`` stitch by
    ``relax_rough`` (the lower of two descents), any other by ``relaxer``."""
    if model.stitch.rough:
        return relax_rough(relaxer, model, x, settings)
    return relaxer.relax(model, x, None, settings)


def relax_rough(relaxer: Relaxer, model: CellModel, x: np.ndarray,
                settings: SolverSettings) -> Relaxation:  # fmt: skip
    """The zero-force state of a ``Stitch.rough`` stitch from ``x``: the lower of two
    minimisers' minima (docs/model.md §11).

    ``relaxer`` relaxes first (Newton, SLSQP finishing where it cannot, with the chain's
    carried curvature; if SLSQP too stops short, SLSQP goes on from there with
    ``ROUGH_SLSQP_MAXITER`` times the iteration limit), then SLSQP alone from ``x`` with
    that limit. The two descents take different paths and land in different minima
    (rib at 11.6 mm: 0.2510962 and 0.2510620 mJ), neither always lower. Kept: the lowest
    converged (else knittable, else one whose cores overlap, else any) result, with the
    iterations, evaluations and seconds of all; if it is not the relaxer's own, the
    relaxer's curvature is dropped (it belongs to another point). With the Newton
    solver, a converged minimum that Newton did not end at (SLSQP's) is relaxed once
    more by Newton, which is kept if it converges no higher: SLSQP stops when E stops
    changing, Newton only where the state is stationary."""
    first = relaxer.relax(model, x, None, settings)
    slsqp = _slsqp(settings)
    tried = [first]
    if first.status == NOT_CONVERGED and np.all(np.isfinite(first.x)):
        tried.append(Relaxer(slsqp).relax(model, first.x, None))
    tried.append(Relaxer(slsqp).relax(model, x, None))

    def rank(r: Relaxation) -> tuple[int, float]:
        # converged, then a fabric that did not converge, then cores that overlap, then
        # a yarn that left its stitch's crossings (rows pulled apart: no state of it)
        e = r.total_energy
        order = (0 if r.status == CONVERGED else 2 if r.status == NOT_KNITTABLE
                 else 3 if r.message.startswith(TOPOLOGY_CHANGED) else 1)  # fmt: skip
        return order, e if math.isfinite(e) else math.inf

    best = min(tried, key=rank)
    if best is not first:
        relaxer.curvature = None
    how = ", ".join(f"{r.total_energy:.7f} mJ ({r.status})" for r in tried)
    message = f"{best.message} [lowest of {len(tried)} descents: {how}]"
    anchor = relaxer.curvature.anchor if relaxer.curvature is not None else None
    newton_ended_there = anchor is not None and np.array_equal(anchor.x, best.x)
    if settings.method == "newton" and best.status == CONVERGED and not newton_ended_there:
        # SLSQP stops on the change of E alone, short of a stationary point: Newton goes
        # on from its minimum, along the soft modes (joints sliding along the yarn)
        polisher = Relaxer(settings)
        polished = polisher.relax(model, best.x, None)
        tried.append(polished)
        if polished.status == CONVERGED and polished.total_energy <= best.total_energy:
            message = f"{message[:-1]}; Newton from there: {polished.total_energy:.7f} mJ]"
            best, relaxer.curvature = polished, polisher.curvature
    return replace(
        best,
        message=message,
        iterations=sum(r.iterations for r in tried),
        evaluations=sum(r.evaluations for r in tried),
        seconds=sum(r.seconds for r in tried),
    )


def _slsqp(settings: SolverSettings) -> SolverSettings:
    """``settings`` with SLSQP as the minimiser, ``ROUGH_SLSQP_MAXITER`` times the limit."""
    return settings.model_copy(
        update={"method": "slsqp", "maxiter": ROUGH_SLSQP_MAXITER * settings.maxiter}
    )
