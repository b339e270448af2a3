"""Continuation in parameters: a zero-force state walked from the parameters it was
relaxed at to the target in small stages (docs/model.md §7, a knitsweep addition)."""

from __future__ import annotations

import math

import numpy as np

from ..config import NOT_CONVERGED, NOT_KNITTABLE, Fidelity, SolverSettings, StitchParams
from ..model import CellModel
from .relaxer import Relaxer
from .result import Relaxation, with_status


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


def relax_with_continuation(
    target: StitchParams,
    fidelity: Fidelity,
    x_start: np.ndarray,
    start: StitchParams,
    settings: SolverSettings | None = None,
) -> tuple[Relaxation, int]:
    """Zero-force relaxation at ``target``, walking there from a state relaxed at
    ``start`` in small parameter stages (docs/model.md §7). Returns the final
    relaxation and the number of stages used.

    Intermediate stages use a looser tolerance; a stage that ends non-finite or
    with overlapping cores stops the walk, and the last stage's status is kept.
    """
    settings = settings or SolverSettings()
    stages = continuation_path(start, target, settings)
    loose = settings.model_copy(update={"ftol": max(settings.ftol, 1e-7)})
    relaxer = Relaxer(settings)
    x = np.asarray(x_start, dtype=float)
    result = None
    for i, params in enumerate(stages):
        last = i == len(stages) - 1
        result = relaxer.relax(CellModel(params, fidelity), x, None, settings if last else loose)
        if not np.all(np.isfinite(result.x)) or (not last and result.status == NOT_KNITTABLE):
            where = f"at continuation stage {i + 1}/{len(stages)} (L = {params.L_mm:.4g} mm)"
            status = result.status if result.status == NOT_KNITTABLE else NOT_CONVERGED
            return with_status(result, status, f"{result.message} {where}"), i + 1
        x = result.x
    assert result is not None
    return result, len(stages)
