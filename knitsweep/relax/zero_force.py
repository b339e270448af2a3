"""Starting states and the multi-start zero-force relaxation (docs/model.md §7).

The energy landscape has local minima; the authors relax each point from 4
slightly different Init files and keep the lowest energy. knitsweep does the
same with the shipped states and/or perturbations drawn from a numpy
``SeedSequence``, so a run is reproducible from its seed.

Starts relaxed at the same parameters walk the same continuation stages together and
merge where they reach the same minimum (``continuation.walk_starts``); the record says which
start each merged into and at which stage.

``ZeroForce.to_record()`` and ``ZeroForce.from_record()`` convert the result to the
flat arrays and scalars a results file stores and back, losing nothing.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np

from ..config import (
    CONVERGED,
    NOT_CONVERGED,
    NOT_KNITTABLE,
    Fidelity,
    SolverSettings,
    StartSettings,
    StitchParams,
)
from ..model import CellModel
from ..stitches import DEFAULT_STITCH
from ..util.plain_values import plain_value
from .continuation import relax_zero_force, walk_starts
from .relaxer import Relaxer, single_threaded
from .result import Relaxation

# the parameters the shipped Init files were made for (the authors' k = 0.1 mN/mm^2
# study, paper Table 1 otherwise); their length is measured, not assumed
SHIPPED_SOURCE = StitchParams(k_mN_per_mm2=0.1)


@dataclass(frozen=True)
class Start:
    """A starting state and the parameters it was relaxed at."""

    label: str
    x: np.ndarray
    params: StitchParams


def shipped_source(stitch: str = DEFAULT_STITCH) -> StitchParams:
    """The parameters a stitch's shipped starts were made for (``SHIPPED_SOURCE``)."""
    return SHIPPED_SOURCE.model_copy(update={"stitch": stitch})


def start_states(
    settings: StartSettings,
    seed: int,
    fidelity: Fidelity | None = None,
    stitch: str = DEFAULT_STITCH,
) -> list[Start]:
    """The ``settings.count`` starting states of ``stitch`` for one point, reproducible
    from ``seed``: its shipped starts in turn, then (or, with ``source = "perturbed"``,
    always) the first one with seeded noise on the shape parameters."""
    fidelity = fidelity or Fidelity()
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(settings.count)]
    model = CellModel(shipped_source(stitch), fidelity)
    geometry = model.stitch
    starts = []
    for i in range(settings.count):
        shipped = i % geometry.n_starts if settings.source == "shipped" else 0
        x = geometry.start(shipped + 1)
        label = geometry.starts[shipped].removesuffix(".dat")
        if settings.source == "perturbed" or i >= geometry.n_starts:
            noise = settings.perturbation * rngs[i].standard_normal(geometry.n_shape)
            x = x.copy()
            x[: geometry.n_shape] *= 1.0 + noise
            label += f"+noise[{i}]"
        starts.append(_at_own_length(label, x, model))
    return starts


def check_shipped_starts(stitches: tuple[str, ...], fidelity: Fidelity | None = None) -> None:
    """Refuse (InputError naming the stitch, the start, the segment and the image) a
    shipped start whose hard cores overlap, before any compute. The perturbed copies
    are not refused: at the default perturbation (2 %) some of them overlap (measured:
    23 of 240 garter starts, 1 of 240 stockinette), and each such start ends its walk
    as not knittable while the point's other starts go on (``walk_starts``)."""
    for stitch in stitches:
        model = CellModel(shipped_source(stitch), fidelity or Fidelity())
        for i, name in enumerate(model.stitch.starts):
            model.check_start(model.stitch.start(i + 1), f"shipped start {name} of {stitch}")


def _at_own_length(label: str, x: np.ndarray, shipped: CellModel) -> Start:
    """A start from state ``x``: the shipped states' parameters at ``x``'s own yarn
    length (``shipped`` is the model of ``shipped_source``)."""
    length = shipped.energies(x).length
    return Start(label, x, shipped.params.model_copy(update={"L_mm": length}))


# per-start arrays of a stored zero-force record: record name -> Relaxation field
_START_ARRAYS = {
    "x": "x",
    "bending_energy": "bending_energy",
    "contact_energy": "contact_energy",
    "length": "length",
    "start_status": "status",
    "start_message": "message",
    "iterations": "iterations",
    "evaluations": "evaluations",
    "length_residual": "length_residual",
    "twist_margin": "twist_margin",
    "twist_active": "twist_active",
    "min_zeta": "min_zeta",
    "kkt_residual": "kkt_residual",
    "length_multiplier": "length_multiplier",
    "period_forces": "period_forces",
    "relax_seconds": "seconds",
}
assert set(_START_ARRAYS.values()) == {f.name for f in fields(Relaxation)}


@dataclass(frozen=True)
class ZeroForce:
    """The zero-force state of one point: the winner over all starts. ``merged_into[i]``:
    the start whose walk start i joined (-1 if none), at continuation stage
    ``merged_at[i]``; its relaxation is then that start's."""

    relaxations: tuple[Relaxation, ...]
    labels: tuple[str, ...]
    stages: tuple[int, ...]
    winner: int
    status: str
    message: str
    merged_into: tuple[int, ...] = ()
    merged_at: tuple[int, ...] = ()

    @property
    def best(self) -> Relaxation:
        return self.relaxations[self.winner]

    def with_lower_minimum(self, start: int, lower: Relaxation, note: str) -> ZeroForce:
        """This zero-force state with start ``start``'s relaxation replaced by ``lower``
        (a lower minimum found from that start's chain, e.g. by a strain sweep), which
        wins; ``note`` says how it was found and is added to the message."""
        rs = list(self.relaxations)
        rs[start] = lower
        return replace(self, relaxations=tuple(rs), winner=start, status=CONVERGED,
                       message=f"{self.message}; {note}")  # fmt: skip

    def to_record(self) -> dict[str, Any]:
        """Every field as storable values: per-start arrays (one row per start), the
        winner, the overall status (``relax_status``) and ``message``."""
        rec: dict[str, Any] = {
            "winner": self.winner,
            "relax_status": self.status,
            "message": self.message,
            "labels": np.array(self.labels, dtype=object),
            "stages": np.array(self.stages, dtype=np.int64),
            "merged_into": np.array(self.merged_into, dtype=np.int64),
            "merged_at": np.array(self.merged_at, dtype=np.int64),
        }
        for name, attr in _START_ARRAYS.items():
            values = [getattr(r, attr) for r in self.relaxations]
            dtype = object if isinstance(values[0], str) else None
            rec[name] = np.array(values, dtype=dtype)
        return rec

    @classmethod
    def from_record(cls, rec: dict[str, Any]) -> ZeroForce:
        """The inverse of ``to_record`` (extra keys in ``rec`` are ignored; a record
        written before starts could merge has no merges)."""
        rs = []
        for i in range(len(rec["x"])):
            values = {attr: rec[name][i] for name, attr in _START_ARRAYS.items()}
            rs.append(
                Relaxation(
                    **{
                        k: plain_value(v)
                        for k, v in values.items()
                        if k not in ("x", "period_forces")
                    },
                    x=np.asarray(values["x"], dtype=float).copy(),
                    period_forces=tuple(float(f) for f in values["period_forces"]),
                )
            )
        n = len(rs)
        merged_into = rec.get("merged_into", np.full(n, -1))
        merged_at = rec.get("merged_at", np.full(n, -1))
        return cls(tuple(rs), tuple(str(s) for s in rec["labels"]),
                   tuple(int(s) for s in rec["stages"]), int(rec["winner"]),
                   str(rec["relax_status"]), str(rec["message"]),
                   tuple(int(i) for i in merged_into), tuple(int(i) for i in merged_at))  # fmt: skip


def relax_at_rest(model: CellModel, x: np.ndarray, solver: SolverSettings | None = None
                  ) -> Relaxation:  # fmt: skip
    """The zero-force relaxation (both periods free) from state ``x`` at the model's own
    parameters, as the last stage of a continuation relaxes it
    (``relax.continuation.relax_zero_force``), on one thread."""
    solver = solver or SolverSettings()
    with single_threaded():
        return relax_zero_force(Relaxer(solver), model, x, solver)


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
    initial: np.ndarray | None = None,
    carried: tuple[np.ndarray, StitchParams] | None = None,
) -> ZeroForce:
    """Relax the zero-force state (both periods free) from every start, walking
    from each start's parameters to ``params``; keep the lowest energy.

    ``initial``: one given state (n,) of the stitch to start from instead of ``starts`` (walked
    from the shipped states' parameters at its own yarn length). ``carried``: one state
    and the parameters it is the zero-force state of (a neighbouring point of a series,
    ``[starts] carry``), walked from there instead.
    """
    fidelity = fidelity or Fidelity()
    solver = solver or SolverSettings()
    starts = starts or StartSettings()
    if carried is not None:
        x, source_params = carried
        begin = [Start(f"carried from L = {source_params.L_mm:g} mm", x, source_params)]
    elif initial is None:
        begin = start_states(starts, seed, fidelity, params.stitch)
    else:
        source = CellModel(shipped_source(params.stitch), fidelity)
        begin = [_at_own_length("initial", initial, source)]
    with single_threaded():
        walked, merged_into, merged_at = walk_starts(
            params, fidelity, [(s.x, s.params) for s in begin], solver, starts.merge_tolerance_mJ
        )
    results = [r for r, _ in walked]
    labels = [s.label for s in begin]
    own = [i for i in range(len(results)) if merged_into[i] < 0]  # merged rows are copies
    w, status = pick_lowest([results[i] for i in own])
    winner = own[w]
    best = results[winner]
    merged = len(results) - len(own)
    if status == CONVERGED:
        message = f"lowest of {len(results)} starts: {labels[winner]}"
        message += f" ({merged} merged on the way)" if merged else ""
    else:
        message = f"no start converged; best ({labels[winner]}): {best.message}"
    return ZeroForce(tuple(results), tuple(labels), tuple(n for _, n in walked), winner, status,
                     message, tuple(int(i) for i in merged_into),
                     tuple(int(i) for i in merged_at))  # fmt: skip
