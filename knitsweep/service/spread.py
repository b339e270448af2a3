"""The spread of a point's observables over starts that differ by round-off (``[starts] spread``).

A free yarn's relaxation can end where the last bits of its arithmetic send it (the
patterns' transitions moved with the instruction set the kernels were compiled for,
docs/patterns.md, "Reproducibility"). With ``[starts] spread = N`` each point is also
relaxed from N - 1 copies of its winning start, perturbed by ``SPREAD_PERTURBATION``
(1e-15) relative (seeded from the task), and each sweep is also run from the copies'
zero-force ends (``spread_x`` of the point's record); the records store the spread
(max - min over the N) of the zero-force energy and periods and of the sweep's energy
gaps and Y_sec, the tables a ``…_spread`` column each. A jamming verdict whose gap lies
within its spread of the threshold is "within round-off" (``within_round_off`` in the
sweeps table, ``round_off_at_L_mm`` in the transitions table).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from ..config import CONVERGED, SPREAD_PERTURBATION

POINT_SPREADS = {"spread_rest_energy": "E_rest", "spread_a_x0": "a_x0", "spread_a_y0": "a_y0"}
"""Point record field -> what it is the spread of (the points table's column stem)."""
SWEEP_SPREADS = {"spread_delta_E_b": "delta_E_b", "spread_delta_E_c": "delta_E_c",
                 "spread_Y_sec": "Y_sec"}  # fmt: skip
"""Sweep record field -> what it is the spread of (the sweeps table's column stem)."""


def _copies(x: np.ndarray, n: int, seed: Any) -> list[np.ndarray]:
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    out = []
    for _ in range(n):
        c = np.array(x, dtype=float)
        c *= 1.0 + SPREAD_PERTURBATION * rng.standard_normal(c.size)
        out.append(c)
    return out


def _spread(values: list[float]) -> float:
    finite = [v for v in values if v is not None and np.isfinite(v)]
    return float(max(finite) - min(finite)) if len(finite) > 1 else float("nan")


def point_spread(job: Any, params: Any, zf: Any, begin: list[tuple[np.ndarray, Any]],
                 seed: int) -> dict[str, Any]:  # fmt: skip
    """The spread fields of a converged point ``zf`` (``POINT_SPREADS`` and
    ``spread_count``: of how many relaxations, the winner's included); {} when the job
    asks for none or the point did not converge."""
    from ..relax import single_threaded, walk_starts

    n = job.starts.spread
    if n < 2 or zf.status != CONVERGED:
        return {}
    x0, source = begin[zf.winner]
    copies = [(x, source) for x in _copies(x0, n - 1, [seed, 0x5D])]
    with single_threaded():  # no merging: each copy walks to its own end
        walked, _, _ = walk_starts(params, job.fidelity, copies, job.solver, 0.0)
    ends = [zf.best, *(r for r, _ in walked if r.status == CONVERGED)]
    out = {
        "spread_rest_energy": _spread([r.total_energy for r in ends]),
        "spread_a_x0": _spread([float(r.x[-2]) for r in ends]),
        "spread_a_y0": _spread([float(r.x[-1]) for r in ends]),
        "spread_count": len(ends),
    }
    if len(ends) > 1:  # the copies' ends, which the point's sweeps start from too
        out["spread_x"] = np.array([r.x for r in ends[1:]])
    return out


def _observables(record: dict[str, Any], direction: str) -> tuple[float, float, float | None]:
    from ..analysis.metrics import sweep_metrics

    names = ("strain", "stress", "bending_energy", "contact_energy", "a_x", "a_y", "thickness")
    arrays = {k: np.asarray(record[k], dtype=float) for k in names}
    m = sweep_metrics(direction, **arrays, stress_envelope=record.get("stress_envelope"),
                      winner=record.get("winner"))  # fmt: skip
    return m.gaps.delta_E_b, m.gaps.delta_E_c, m.secant.Y_sec


def sweep_spread(job: Any, params: Any, zf: Any, direction: str, record: dict[str, Any],
                 seed: int, ends: Any = None) -> dict[str, Any]:  # fmt: skip
    """The spread fields (``SWEEP_SPREADS``, ``spread_count``) of the sweep whose record
    is ``record`` (its step arrays), from more sweeps: one from each of the point's copies'
    zero-force ends ``ends`` (its ``spread_x``, each relaxed at rest again to have its
    energies), or, where the point has none (no copy converged), ``job.starts.spread - 1``
    copies of ``zf``'s winning state perturbed; {} when the job asks for none."""
    from ..model import CellModel
    from ..relax.zero_force import relax_at_rest
    from ..strain_sweep import strain_sweep

    n = job.starts.spread
    if n < 2:
        return {}
    found = [_observables(record, direction)]
    model = CellModel(params, job.fidelity)
    states = list(ends) if ends is not None else _copies(zf.best.x, n - 1, [seed, 0x5E])
    for x in states:
        rest = relax_at_rest(model, np.asarray(x, dtype=float), job.solver)
        if rest.status != CONVERGED:
            continue
        rs = list(zf.relaxations)
        rs[zf.winner] = rest
        other = strain_sweep(params, replace(zf, relaxations=tuple(rs)), direction,
                             job.protocol, job.fidelity, job.solver)  # fmt: skip
        if other.status in ("done", "incomplete"):
            found.append(_observables(other.to_record(), direction))
    out = {name: _spread([f[i] for f in found]) for i, name in enumerate(SWEEP_SPREADS)}
    return out | {"spread_count": len(found)}
