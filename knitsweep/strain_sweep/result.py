"""A strain sweep's result and its lossless record (docs/model.md §8).

Arrays run over steps, step 0 the zero-force state. Stress, in N/mm per unit
transverse width at zero force:

* ``stress``: the discrete derivative of the energy at each step, centred (on uniform
  steps exactly the reference's (E_{j+1} - E_{j-1})/(a_{j+1} - a_{j-1}), attributed to the
  midpoint as the authors' analysis does; second-order on uneven steps), divided by
  a_perp0; backward at the last step, 0 at zero force;
* ``stress_envelope``: dE*/da/a_perp0 at each step from the Lagrange multiplier of the
  length constraint (envelope theorem), free of differencing error;
* ``stress_xx``, ``stress_yy``: the stress tensor's normal components from the period
  forces, F_x/a_y0 and F_y/a_x0 (zero in a free period's direction, to the solver's
  tolerance); ``stress_xy``: its shear component F_s/a_x0 from the force on the wale
  vector's skew (``CellModel.skew_force``): along the other paths the force that holds
  the skew at 0 (0 by symmetry for a left-right mirror-symmetric stitch; 0 for the
  ansatz, which cannot shear).

Along a path that controls both periods (``paths``: equibiaxial, strip biaxial), ``stress``
and ``stress_envelope`` are dE/dε per unit area of the zero-force cell, the sum of the
components weighted by the path's strain rates.

Per start (S of them, the zero-force point's starts): ``carried`` (the start reached a
converged zero-force state and was pulled as a chain), ``merged_into`` (the start whose
chain it joined, or -1) and ``merged_at`` (the step where it did, 0 = the zero-force
state, or -1). ``SweepResult.to_record()`` and ``SweepResult.from_record()`` convert a
sweep to the arrays and scalars a results file stores (its energy gaps included) and
back.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from ..analysis.metrics import EnergyGaps, energy_gaps
from ..quantities import registered
from ..relax.zero_force import ZeroForce


def first_grid_value(a0: float, h: float, sign: float) -> float:
    """The first multiple of h strictly beyond a0 in the pulling direction."""
    n = round(a0 / h)
    start = h * n
    if sign > 0:
        return start if start > a0 else start + h
    return start if start < a0 else start - h


@dataclass
class SweepResult:
    """One strain sweep; per-step arrays run over steps, step 0 is the zero-force state.

    ``stopped_by`` says which rule ended it: ``stop_stress``, ``max_strain``,
    ``observables`` (everything the protocol asked for was determined),
    ``not_knittable``, ``max_steps`` or ``no_finite_relaxation``; ``stop_reason`` says it
    in words. ``rest_restarts``: how often the sweep fell below its zero-force energy by
    more than the protocol's ``rest_tolerance_mJ`` and started over from the lower
    minimum relaxed from there; ``rest`` is then that zero-force state (step 0, the
    point's zero-force state from then on) and ``rest_found`` says where each was found.
    """

    direction: str
    a_fixed: np.ndarray = field(default_factory=lambda: np.empty(0))
    a_x: np.ndarray = field(default_factory=lambda: np.empty(0))
    a_y: np.ndarray = field(default_factory=lambda: np.empty(0))
    strain: np.ndarray = field(default_factory=lambda: np.empty(0))
    stress: np.ndarray = field(default_factory=lambda: np.empty(0))
    stress_envelope: np.ndarray = field(default_factory=lambda: np.empty(0))
    stress_xx: np.ndarray = field(default_factory=lambda: np.empty(0))
    stress_yy: np.ndarray = field(default_factory=lambda: np.empty(0))
    stress_xy: np.ndarray = field(default_factory=lambda: np.empty(0))
    bending_energy: np.ndarray = field(default_factory=lambda: np.empty(0))
    contact_energy: np.ndarray = field(default_factory=lambda: np.empty(0))
    observed: dict[str, np.ndarray] = field(default_factory=dict)
    """The registered step observables (``quantities.registered("step")``: ``thickness``
    …) by name, each (n,); read as attributes too (``result.thickness``)."""
    winner: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    converged: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=bool))
    iterations: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    evaluations: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    min_zeta: np.ndarray = field(default_factory=lambda: np.empty(0))
    length_residual: np.ndarray = field(default_factory=lambda: np.empty(0))
    kkt_residual: np.ndarray = field(default_factory=lambda: np.empty(0))
    relax_seconds: np.ndarray = field(default_factory=lambda: np.empty(0))
    states: np.ndarray = field(default_factory=lambda: np.empty((0, 0)))
    carried: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=bool))
    merged_into: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    merged_at: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    status: str = "done"
    stop_reason: str = ""
    stopped_by: str = ""
    relaxations: int = 0
    evaluations_total: int = 0
    wall_seconds: float = 0.0
    rest_restarts: int = 0
    rest_found: str = ""
    rest: ZeroForce | None = None
    rest_skew: float = 0.0
    """A shear's rest: γ0 = s0/a_y0 of the zero-force state with its skew relaxed
    (``rest_skew.relax_skew``; step 0, this sweep's alone), 0 where the upright state is
    the minimum in shear or the path does not shear."""
    rest_skew_fall_mJ: float = 0.0
    """How far below the point's (upright) zero-force state that rest lies (mJ)."""

    def __getattr__(self, name: str) -> np.ndarray:
        observed = self.__dict__.get("observed", {})
        if name in observed:
            return observed[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def total_energy(self) -> np.ndarray:
        return self.bending_energy + self.contact_energy

    @property
    def energy_gaps(self) -> EnergyGaps:
        """ΔE_b and ΔE_c of this sweep (docs/model.md §9)."""
        return energy_gaps(self.bending_energy, self.contact_energy)

    def arrays(self) -> dict[str, np.ndarray]:
        """The per-step arrays by name (for tables and storage), the registered step
        observables after the energies."""
        out = {}
        for f in fields(self):
            if f.name in _STEP_ARRAYS:
                out[f.name] = getattr(self, f.name)
            elif f.name == "observed":
                out |= self.observed
        return out

    def to_record(self) -> dict[str, Any]:
        """Every field as storable values: the per-step and per-start arrays,
        ``total_energy``, ``sweep_status``, the stop reason as ``message``, the counts
        and the energy gaps (``delta_E_b``, ``delta_E_c`` and the direction's
        ``jamming_gap``)."""
        gaps = self.energy_gaps
        return {
            **self.arrays(),
            **{name: getattr(self, name) for name in _START_ARRAYS},
            "total_energy": self.total_energy,
            "direction": self.direction,
            "sweep_status": self.status,
            "message": self.stop_reason,
            "stopped_by": self.stopped_by,
            "relaxations": self.relaxations,
            "evaluations_total": self.evaluations_total,
            "wall_seconds": self.wall_seconds,
            "rest_energy": float(self.total_energy[0]),
            "rest_restarts": self.rest_restarts,
            "rest_found": self.rest_found,
            "rest_skew": self.rest_skew,
            "rest_skew_fall_mJ": self.rest_skew_fall_mJ,
            "delta_E_b": gaps.delta_E_b,
            "delta_E_c": gaps.delta_E_c,
            "jamming_gap": gaps.jamming_gap(self.direction),
        }

    @classmethod
    def from_record(cls, rec: dict[str, Any]) -> SweepResult:
        """The inverse of ``to_record`` (extra keys are ignored; a record stored
        without ``states`` gets an empty (0, 0) array; one written before starts could
        merge or sweeps could stop early gets empty per-start arrays and empty
        ``stopped_by``/0 total evaluations; one written before an observable was
        registered lacks it)."""
        arrays = {k: np.asarray(rec[k]) for k in (*_STEP_ARRAYS, *_START_ARRAYS) if k in rec}
        observed = {o.name: np.asarray(rec[o.name]) for o in registered("step") if o.name in rec}
        return cls(direction=str(rec["direction"]), **arrays, observed=observed,
                   status=str(rec["sweep_status"]),
                   stop_reason=str(rec["message"]), stopped_by=str(rec.get("stopped_by", "")),
                   relaxations=int(rec["relaxations"]),
                   evaluations_total=int(rec.get("evaluations_total", 0)),
                   wall_seconds=float(rec["wall_seconds"]),
                   rest_restarts=int(rec.get("rest_restarts", 0)),
                   rest_found=str(rec.get("rest_found", "")),
                   rest_skew=float(rec.get("rest_skew", 0.0)),
                   rest_skew_fall_mJ=float(rec.get("rest_skew_fall_mJ", 0.0)))  # fmt: skip


_STEP_ARRAYS = ("a_fixed", "a_x", "a_y", "strain", "stress", "stress_envelope", "stress_xx",
                "stress_yy", "stress_xy", "bending_energy", "contact_energy", "winner", "converged",
                "iterations", "evaluations", "min_zeta", "length_residual", "kkt_residual", "relax_seconds", "states")  # fmt: skip
_START_ARRAYS = ("carried", "merged_into", "merged_at")


def centred_stress(energy: np.ndarray, a: np.ndarray, a_perp0: float) -> np.ndarray:
    """dE/da / a_perp0 at every step (N/mm): the second-order three-point derivative
    on the possibly uneven grid of periods, 0 at the zero-force state (j = 0) and a
    backward difference at the last step.

    On a uniform grid this is exactly the reference's centred difference
    (E_{j+1} - E_{j-1})/(a_{j+1} - a_{j-1}); where the step changes (the first step
    after a_0, the switch to large steps, adaptive steps) it stays second-order
    accurate, where the plain centred difference would be biased by the larger step.
    """
    n = len(energy)
    s = np.zeros(n)
    if n >= 3:
        hm = a[1:-1] - a[:-2]
        hp = a[2:] - a[1:-1]
        s[1:-1] = (
            (hm**2 * energy[2:] - hp**2 * energy[:-2] + (hp**2 - hm**2) * energy[1:-1])
            / (hm * hp * (hm + hp))
            / a_perp0
        )
    if n >= 2:
        s[-1] = (energy[-1] - energy[-2]) / (a[-1] - a[-2]) / a_perp0
    return s
