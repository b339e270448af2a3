"""Strain sweeps: the stitch pulled step by step in x or y (docs/model.md §8).

From the zero-force state (a_x0, a_y0) one period is fixed on a grid of
multiples of the step h (the first value is the first multiple beyond a_0),
the other period and the shape relax, and each step warm-starts from the last.
Every start of the point is carried along as its own chain; at each step the
lowest-energy chain wins (the authors' "4 Init files, keep the lowest").

Stress, in N/mm per unit transverse width at zero force:
* ``stress``: the discrete derivative of the energy at each step, centred
  (on uniform steps exactly the reference's (E_{j+1} - E_{j-1})/(a_{j+1} - a_{j-1}),
  attributed to the midpoint as the authors' analysis does; second-order on
  uneven steps), divided by a_perp0; backward at the last step, 0 at zero force;
* ``stress_envelope``: dE*/da/a_perp0 at each step from the Lagrange multiplier
  of the length constraint (envelope theorem), free of differencing error.
The stop rule is the reference's: after step i >= 2, stop when
(E_{i-2} - E_i)/(a_{i-2} - a_i)/a_perp0 exceeds the stop stress, or |strain| > max.

``SweepResult.to_record()`` and ``SweepResult.from_record()`` convert a sweep to the
arrays and scalars a results file stores (its energy gaps included) and back.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from .analysis.metrics import EnergyGaps, energy_gaps
from .config import (
    CONVERGED,
    NOT_KNITTABLE,
    Direction,
    Fidelity,
    SolverSettings,
    StartSettings,
    StitchParams,
    SweepProtocol,
)
from .model import CellModel
from .relax import Relaxation, relax
from .state import IDX_AX, IDX_AY, N_STATE
from .zero_force import ZeroForce, pick_lowest, zero_force


def first_grid_value(a0: float, h: float, sign: float) -> float:
    """The first multiple of h strictly beyond a0 in the pulling direction."""
    n = round(a0 / h)
    start = h * n
    if sign > 0:
        return start if start > a0 else start + h
    return start if start < a0 else start - h


@dataclass
class SweepResult:
    """One strain sweep; arrays run over steps, step 0 is the zero-force state."""

    direction: str
    a_fixed: np.ndarray = field(default_factory=lambda: np.empty(0))
    a_x: np.ndarray = field(default_factory=lambda: np.empty(0))
    a_y: np.ndarray = field(default_factory=lambda: np.empty(0))
    strain: np.ndarray = field(default_factory=lambda: np.empty(0))
    stress: np.ndarray = field(default_factory=lambda: np.empty(0))
    stress_envelope: np.ndarray = field(default_factory=lambda: np.empty(0))
    bending_energy: np.ndarray = field(default_factory=lambda: np.empty(0))
    contact_energy: np.ndarray = field(default_factory=lambda: np.empty(0))
    thickness: np.ndarray = field(default_factory=lambda: np.empty(0))
    winner: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    converged: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=bool))
    iterations: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    evaluations: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    min_zeta: np.ndarray = field(default_factory=lambda: np.empty(0))
    length_residual: np.ndarray = field(default_factory=lambda: np.empty(0))
    kkt_residual: np.ndarray = field(default_factory=lambda: np.empty(0))
    relax_seconds: np.ndarray = field(default_factory=lambda: np.empty(0))
    states: np.ndarray = field(default_factory=lambda: np.empty((0, N_STATE)))
    status: str = "done"
    stop_reason: str = ""
    relaxations: int = 0
    wall_seconds: float = 0.0

    @property
    def total_energy(self) -> np.ndarray:
        return self.bending_energy + self.contact_energy

    @property
    def energy_gaps(self) -> EnergyGaps:
        """ΔE_b and ΔE_c of this sweep (docs/model.md §9)."""
        return energy_gaps(self.bending_energy, self.contact_energy)

    def arrays(self) -> dict[str, np.ndarray]:
        """The per-step arrays by name (for tables and storage)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name in _STEP_ARRAYS}

    def to_record(self) -> dict[str, Any]:
        """Every field as storable values: the per-step arrays, ``total_energy``,
        ``sweep_status``, the stop reason as ``message``, the counts and the energy
        gaps (``delta_E_b``, ``delta_E_c`` and the direction's ``energy_gap``)."""
        gaps = self.energy_gaps
        return {
            **self.arrays(),
            "total_energy": self.total_energy,
            "direction": self.direction,
            "sweep_status": self.status,
            "message": self.stop_reason,
            "relaxations": self.relaxations,
            "wall_seconds": self.wall_seconds,
            "delta_E_b": gaps.delta_E_b,
            "delta_E_c": gaps.delta_E_c,
            "energy_gap": gaps.jamming_gap(self.direction),
        }

    @classmethod
    def from_record(cls, rec: dict[str, Any]) -> SweepResult:
        """The inverse of ``to_record`` (extra keys are ignored; a record stored
        without ``states`` gets an empty (0, 30) array)."""
        arrays = {k: np.asarray(rec[k]) for k in _STEP_ARRAYS if k in rec}
        return cls(direction=str(rec["direction"]), **arrays, status=str(rec["sweep_status"]),
                   stop_reason=str(rec["message"]), relaxations=int(rec["relaxations"]),
                   wall_seconds=float(rec["wall_seconds"]))  # fmt: skip


_STEP_ARRAYS = ("a_fixed", "a_x", "a_y", "strain", "stress", "stress_envelope", "bending_energy",
                "contact_energy", "thickness", "winner", "converged", "iterations", "evaluations",
                "min_zeta", "length_residual", "kkt_residual", "relax_seconds", "states")  # fmt: skip


def centred_stress(energy: np.ndarray, a: np.ndarray, a_perp0: float) -> np.ndarray:
    """dE/da / a_perp0 at every step (N/mm): the second-order three-point derivative
    on the possibly uneven grid of periods, 0 at the zero-force state (j = 0) and a
    backward difference at the last step.

    On a uniform grid this is exactly the reference's centred difference
    (E_{j+1} - E_{j-1})/(a_{j+1} - a_{j-1}); where the step changes (the first step
    after a_0, and the switch to large steps) it stays second-order accurate,
    where the plain centred difference would be biased by the larger step.
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
    protocol = protocol or SweepProtocol()
    fidelity = fidelity or Fidelity()
    solver = solver or SolverSettings()
    t_start = time.perf_counter()
    model = CellModel(params, fidelity)
    idx, other = (IDX_AX, IDX_AY) if direction == "x" else (IDX_AY, IDX_AX)
    best = zero.best
    a0, a_perp0 = float(best.x[idx]), float(best.x[other])
    sign = 1.0 if protocol.mode == "tension" else -1.0
    chains = [r.x.copy() for r in zero.relaxations if r.status == CONVERGED and r.x is not None]
    if not chains:
        chains = [best.x.copy()]
    steps: list[Relaxation] = [best]
    winners = [zero.winner]
    a_values = [a0]
    a_next = first_grid_value(a0, protocol.step_mm, sign)
    h = protocol.step_mm
    status, reason, n_relax = "done", "", 0
    while True:
        results = []
        for c, xc in enumerate(chains):
            x = xc.copy()
            x[idx] = a_next
            r = relax(model, x, direction, solver)
            n_relax += 1
            results.append(r)
            if np.all(np.isfinite(r.x)) and math.isfinite(r.total_energy):
                chains[c] = r.x
        w, step_status = pick_lowest(results)
        win = results[w]
        if not math.isfinite(win.total_energy):
            status, reason = "failed", f"no finite relaxation at a = {a_next:.6g} mm"
            break
        steps.append(win)
        winners.append(w)
        a_values.append(a_next)
        i = len(steps) - 1
        strain = (a_next - a0) / a0
        e = np.array([s.total_energy for s in steps])
        sigma_ref = (e[i - 2] - e[i]) / (a_values[i - 2] - a_values[i]) / a_perp0 if i >= 2 else 0.0
        if progress is not None:
            progress(i, strain, sigma_ref)
        if step_status == NOT_KNITTABLE:
            status, reason = "not_knittable", f"cores overlap at strain {strain:.4g}"
            break
        if i >= 2 and sign * sigma_ref > protocol.stop_stress_N_per_mm:
            reason = f"stress {sigma_ref:.4g} N/mm > {protocol.stop_stress_N_per_mm:g}"
            break
        if abs(strain) > protocol.max_strain:
            reason = f"|strain| {abs(strain):.4g} > {protocol.max_strain:g}"
            break
        if i >= protocol.max_steps:
            status, reason = "incomplete", f"step limit {protocol.max_steps} reached"
            break
        if abs(strain) >= protocol.switch_strain:
            h = protocol.large_step(direction)
        a_next = a_next + sign * h
    return _assemble(model, direction, steps, winners, a_values, a0, a_perp0, status, reason,
                     n_relax, time.perf_counter() - t_start)  # fmt: skip


def _assemble(model, direction, steps, winners, a_values, a0, a_perp0, status, reason, n_relax,
              wall) -> SweepResult:  # fmt: skip
    idx = IDX_AX if direction == "x" else IDX_AY
    a = np.array(a_values)
    eb = np.array([s.bending_energy for s in steps])
    ec = np.array([s.contact_energy for s in steps])
    forces = np.array([s.period_forces[0 if idx == IDX_AX else 1] for s in steps])
    envelope = forces / a_perp0
    return SweepResult(
        direction=direction,
        a_fixed=a,
        a_x=np.array([s.a_x for s in steps]),
        a_y=np.array([s.a_y for s in steps]),
        strain=(a - a0) / a0,
        stress=centred_stress(eb + ec, a, a_perp0),
        stress_envelope=envelope,
        bending_energy=eb,
        contact_energy=ec,
        thickness=np.array([model.thickness(s.x) for s in steps]),
        winner=np.array(winners, dtype=np.int64),
        converged=np.array([s.status == CONVERGED for s in steps]),
        iterations=np.array([s.iterations for s in steps], dtype=np.int64),
        evaluations=np.array([s.evaluations for s in steps], dtype=np.int64),
        min_zeta=np.array([s.min_zeta for s in steps]),
        length_residual=np.array([s.length_residual for s in steps]),
        kkt_residual=np.array([s.kkt_residual for s in steps]),
        relax_seconds=np.array([s.seconds for s in steps]),
        states=np.array([s.x for s in steps]),
        status=status,
        stop_reason=reason,
        relaxations=n_relax,
        wall_seconds=wall,
    )


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
