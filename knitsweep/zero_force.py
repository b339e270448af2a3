"""Starting states and the multi-start zero-force relaxation (MODEL.md §7).

The energy landscape has local minima; the authors relax each point from 4
slightly different Init files and keep the lowest energy. knitsweep does the
same with the shipped states and/or perturbations drawn from a numpy
``SeedSequence``, so a run is reproducible from its seed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from .config import Fidelity, SolverSettings, StitchParams
from .formats import SHIPPED_STATES, shipped_state
from .kernels.geometry import N_SHAPE
from .model import CellModel
from .relax import CONVERGED, NOT_CONVERGED, NOT_KNITTABLE, Relaxation, relax_with_continuation

# the parameters the shipped Init files were made for (the authors' k = 0.1 mN/mm^2
# study, paper Table 1 otherwise); their length is measured, not assumed
SHIPPED_SOURCE = StitchParams(k_mN_per_mm2=0.1)


class StartSettings(BaseModel):
    """How many starts per point, and where they come from."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    count: int = Field(4, ge=1, le=64, description="starts per point (paper: 4)")
    source: Literal["shipped", "perturbed"] = Field(
        "shipped",
        description="'shipped': the authors' Init_1…Init_7 in turn (then perturbed copies); "
        "'perturbed': Init_1 with seeded random perturbations",
    )
    perturbation: float = Field(
        0.02, ge=0.0, le=0.5, description="relative std of the shape perturbations"
    )


@dataclass(frozen=True)
class Start:
    """A starting state and the parameters it was relaxed at."""

    label: str
    x: np.ndarray
    params: StitchParams


def start_states(
    settings: StartSettings, seed: int, fidelity: Fidelity | None = None
) -> list[Start]:
    """The ``settings.count`` starting states for one point, reproducible from ``seed``."""
    fidelity = fidelity or Fidelity()
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(settings.count)]
    starts = []
    for i in range(settings.count):
        shipped = i % len(SHIPPED_STATES) if settings.source == "shipped" else 0
        x = shipped_state(shipped + 1)
        label = f"Init_{shipped + 1}"
        if settings.source == "perturbed" or i >= len(SHIPPED_STATES):
            noise = settings.perturbation * rngs[i].standard_normal(N_SHAPE)
            x = x.copy()
            x[:N_SHAPE] *= 1.0 + noise
            label += f"+noise[{i}]"
        length = CellModel(SHIPPED_SOURCE, fidelity).energies(x).length
        starts.append(Start(label, x, SHIPPED_SOURCE.model_copy(update={"L_mm": length})))
    return starts


@dataclass(frozen=True)
class ZeroForce:
    """The zero-force state of one point: the winner over all starts."""

    relaxations: tuple[Relaxation, ...]
    labels: tuple[str, ...]
    stages: tuple[int, ...]
    winner: int
    status: str
    message: str

    @property
    def best(self) -> Relaxation:
        return self.relaxations[self.winner]


def pick_lowest(results: list[Relaxation] | tuple[Relaxation, ...]) -> tuple[int, str]:
    """Index of the lowest-energy converged result and the overall status.

    Converged results win over unconverged ones; if every start ended with
    overlapping cores the point is ``not_knittable``.
    """
    finite = [i for i, r in enumerate(results) if np.isfinite(r.total_energy)]
    converged = [i for i in finite if results[i].status == CONVERGED]
    pool = converged or [i for i in finite if results[i].status == NOT_CONVERGED] or finite
    if not pool:
        return 0, NOT_CONVERGED
    best = min(pool, key=lambda i: results[i].total_energy)
    if converged:
        return best, CONVERGED
    if all(r.status == NOT_KNITTABLE for r in results):
        return best, NOT_KNITTABLE
    return best, NOT_CONVERGED


def zero_force(
    params: StitchParams,
    fidelity: Fidelity | None = None,
    solver: SolverSettings | None = None,
    starts: StartSettings | None = None,
    seed: int = 0,
) -> ZeroForce:
    """Relax the zero-force state (both periods free) from every start, walking
    from each start's parameters to ``params``; keep the lowest energy."""
    fidelity = fidelity or Fidelity()
    solver = solver or SolverSettings()
    starts = starts or StartSettings()
    results, labels, stages = [], [], []
    for start in start_states(starts, seed, fidelity):
        r, n = relax_with_continuation(params, fidelity, start.x, start.params, solver)
        results.append(r)
        labels.append(start.label)
        stages.append(n)
    winner, status = pick_lowest(results)
    best = results[winner]
    if status == CONVERGED:
        message = f"lowest of {len(results)} starts: {labels[winner]}"
    else:
        message = f"no start converged; best ({labels[winner]}): {best.message}"
    return ZeroForce(tuple(results), tuple(labels), tuple(stages), winner, status, message)
