"""Chains of relaxations from several starts, and their merging (docs/model.md §7-8).

A point is relaxed from several starts, each walked through the same continuation
stages, and each converged start is then pulled as its own chain of strain steps; the
lowest energy wins (the authors' "4 Init files, keep the lowest"). Often several
starts end in the same minimum: their states then differ only along soft modes, and
relaxing both again at every stage or step repeats the same work. Two chains merge
when, at the same stage or step, both converged, their energies differ by at most the
tolerance, and moving from one state to the other costs at most the tolerance in the
quadratic model of the lower one, ½ δᵀ B δ with δ the state difference projected onto
the tangent of the length constraint and B the Lagrangian's Hessian: a difference
along a soft mode (curvature ~1e-4 mJ/mm²) of 1e-3 mm costs 5·10⁻¹¹ mJ, one along a
stiff mode (~1e2 mJ/mm²) of the same size 5·10⁻⁵ mJ. The chain with the higher energy
(the later start on a tie) stops; the records say which start it joined and where.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import CONVERGED
from ..model import CellModel
from .newton import measure_curvature
from .relaxer import Relaxer, free_entries
from .result import Relaxation


@dataclass
class Chain:
    """One start's relaxations in sequence: its index among the point's starts, its
    latest state (n,) and relaxation, and its solver (neighbour list, curvature)."""

    start: int
    x: np.ndarray
    relaxer: Relaxer
    last: Relaxation


def soft_distance(model: CellModel, keep: Chain, other: Chain, fixed: str | None) -> float:
    """½ |δᵀ B δ| (mJ) between the two chains' states: δ = other.x − keep.x over the
    free entries, projected onto the tangent of ℓ at keep.x; B = ∇²E − λ∇²ℓ at keep's
    state (its carried curvature, or measured there if it has none)."""
    free = free_entries(model.stitch, fixed, model.gauge)
    curv = keep.relaxer.curvature
    prob = keep.relaxer.problem(model, keep.x, free)
    pt = prob.evaluate(keep.x[free])
    if curv is None or not bool(np.all(curv.known[free])):
        curv = measure_curvature(prob, pt)
    delta = (other.x - keep.x)[free]
    delta = delta - (float(pt.a @ delta) / float(pt.a @ pt.a)) * pt.a
    b = curv.lagrangian(keep.last.length_multiplier)[np.ix_(free, free)]
    return 0.5 * abs(float(delta @ b @ delta))


def merge_chains(chains: list[Chain], model: CellModel, fixed: str | None, tolerance: float,
                 where: int, merged_into: np.ndarray, merged_at: np.ndarray) -> list[Chain]:  # fmt: skip
    """The chains that go on after merging those at the same minimum (see the module
    docstring); for each merged one, writes the start it joined into ``merged_into`` and
    ``where`` (the stage or step) into ``merged_at``."""
    if tolerance <= 0.0 or len(chains) < 2:
        return chains

    def energy(c: Chain) -> float:
        e = c.last.total_energy
        return e if c.last.status == CONVERGED and math.isfinite(e) else math.inf

    kept: list[Chain] = []
    for c in sorted(chains, key=lambda c: (energy(c), c.start)):
        if math.isfinite(energy(c)):
            twin = next((k for k in kept if energy(c) - energy(k) <= tolerance
                         and soft_distance(model, k, c, fixed) <= tolerance), None)  # fmt: skip
            if twin is not None:
                merged_into[c.start], merged_at[c.start] = twin.start, where
                continue
        kept.append(c)
    return sorted(kept, key=lambda c: c.start)
