"""Adaptive search for the unjamming transition (L/r)_trans along L, and the
master's bookkeeping of it.

A series is one (k, B, r_core, r, p) with one pulling direction. The job's coarse
grid ``grid.L_mm`` brackets the transition with the jamming rule of
``knitsweep.analysis.transitions`` (the same rule as the post-processor): (lo, hi]
with hi the first L whose energy gap (ΔE_c in x, ΔE_b in y) is below the threshold
and lo the L before it. The bracket then shrinks until hi - lo <= tolerance, one new
L per refinement:

* with two jammed points at least ``secant_span`` apart, the secant through them
  extrapolates the gap to the threshold. In the jammed regime the gap falls
  almost linearly and a little convexly with L (paper Fig. 4a), so this estimate
  sits at or just below the crossing; the proposal aims 0.45 tolerance beyond it,
  and when that is within half a tolerance of hi, 0.9 tolerance below hi, so that
  one evaluation closes the bracket whichever side it lands on;
* otherwise, or when the estimate is useless (outside the bracket, or already
  evaluated), bisection.

Measured on the paper's k = 0.1 mN/mm^2 series (``benchmarks/bench_adaptive.py``):
a 0.8 mm coarse grid and this rule reach a 0.005 mm bracket with about 3x fewer
sweeps than the uniform 0.1 mm grid.

``series_state`` is a pure function of the series' (L, gap) data, so a resumed
run replays the stored gaps and continues with the same proposals. ``Refiner``
feeds it every finished sweep's gap (stored with the sweep) and tells the master
which L to evaluate next or how each series ended.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any, Literal

from ..analysis.transitions import transition
from ..config import DONE, NOT_KNITTABLE, StitchParams
from .id_forms import ADAPTIVE_FORMS, protocol_id_form
from .jobs import JobSpec, digest, fidelity_form, params_form

SeriesStatus = Literal[
    "coarse", "refining", "done", "jammed_throughout", "unjammed_at_start", "failed"
]
FINISHED = ("done", "jammed_throughout", "unjammed_at_start", "failed")
JAMMED_GAP = math.inf  # a point that cannot be knitted is as jammed as it gets


@dataclass(frozen=True)
class SeriesState:
    """Where a series stands, derived from its data alone (lengths in mm)."""

    status: SeriesStatus
    lo: float | None
    hi: float | None
    next_L: float | None
    evaluations: int
    message: str = ""
    last_lo: float | None = None
    last_hi: float | None = None
    """With ``last_crossing``: the bracket of a re-entrant series' last crossing (mm;
    ``last_hi`` None where the largest L is jammed); else None."""

    @property
    def finished(self) -> bool:
        return self.status in FINISHED

    @property
    def upper(self) -> float | None:
        """The upper end of the bracket being refined: the last crossing's once that is
        refined, else the first's."""
        return self.last_hi if self.last_hi is not None and self.status == "refining" else self.hi


def failure_status(L_mm: float, message: str, limit: int = 72) -> str:
    """'failed: point L=9.3 mm (why)': the status of a series that a failed point
    leaves without a transition, its reason cut to the message's first clause."""
    why = str(message).removeprefix("failed: ").strip()
    for stop in ("; ", " ["):
        why = why.split(stop, 1)[0]
    if len(why) > limit:
        why = why[: limit - 1].rstrip() + "…"
    return f"failed: point L={L_mm:g} mm ({why})" if why else f"failed: point L={L_mm:g} mm"


def _on_lattice(L: float) -> float:
    """Proposals on a 1e-6 mm lattice: reproducible ids, no 11.600000000000001."""
    return round(L, 6)


def series_state(
    coarse: list[float],
    gaps: dict[float, float | None],
    threshold: float,
    tolerance: float,
    secant_span: float = 0.05,
    max_refinements: int = 40,
    last_crossing: bool = False,
) -> SeriesState:
    """The next step of one series.

    coarse: the job's coarse L values (mm); gaps: every evaluated L -> its gap
    (mJ), ``None`` where the point could not be evaluated, ``JAMMED_GAP`` where it
    cannot be knitted. With ``last_crossing``, once the first crossing is bracketed, a
    series jammed again beyond it has its last crossing (``transitions.Transition``'s
    ``L_over_r_trans_last``) bisected to the tolerance too.
    """
    n = len(gaps)
    if any(L not in gaps for L in coarse):
        return SeriesState("coarse", None, None, None, n, "waiting for the coarse grid")
    failed = sorted(L for L, g in gaps.items() if g is None)
    Ls = sorted(L for L, g in gaps.items() if g is not None)
    if not Ls:
        return SeriesState("failed", None, None, None, n, f"no energy gap at L = {failed} mm")
    t = transition(Ls, [max(gaps[L], 0.0) for L in Ls], threshold)  # noise can dip below 0
    # (L/r)_trans is the first L whose gap is below the threshold: a point without a gap
    # beyond it cannot move it; one at or before it could
    first_unjammed = t.L_over_r_trans if t.status != "jammed_throughout" else math.inf
    if any(L < first_unjammed for L in failed):
        return SeriesState("failed", None, None, None, n, f"no energy gap at L = {failed} mm")
    if t.status == "jammed_throughout":
        return SeriesState("jammed_throughout", Ls[-1], None, None, n,
                           f"jammed at every L up to {Ls[-1]} mm")  # fmt: skip
    hi = t.L_over_r_trans
    exhausted = n - len(set(coarse)) >= max_refinements
    if t.status == "unjammed_at_start":
        first = SeriesState("unjammed_at_start", None, hi, None, n,
                            f"already unjammed at the smallest L, {hi} mm")  # fmt: skip
        return _last(t, gaps, first, last_crossing, tolerance, exhausted, max_refinements)
    lo = t.bracket_lower
    jammed = [L for L in Ls if L < hi]
    if hi - lo <= tolerance * (1.0 + 1e-9):
        first = SeriesState("done", lo, hi, None, n)
        return _last(t, gaps, first, last_crossing, tolerance, exhausted, max_refinements)
    if exhausted:
        return SeriesState("failed", lo, hi, None, n,
                           f"bracket still {hi - lo:.3g} mm after {max_refinements} refinements")  # fmt: skip
    L = _propose(gaps, jammed, lo, hi, threshold, tolerance, secant_span)
    return SeriesState("refining", lo, hi, L, n)


def _last(t, gaps, first: SeriesState, last_crossing: bool, tolerance, exhausted,
          max_refinements) -> SeriesState:  # fmt: skip
    """A series whose first crossing is settled (``first``, how it ends without this): with
    ``last_crossing``, if it is re-entrant, its last crossing's bracket (last jammed L, the
    L after it) bisected to ``tolerance`` (the gap is not monotone there: no secant)."""
    if not last_crossing or t.n_jammed_after == 0:
        return first
    last_lo, last_hi = t.bracket_lower_last, t.L_over_r_trans_last
    if last_hi is None:
        return replace(first, message=f"jammed again up to the largest L, {last_lo} mm",
                       last_lo=last_lo)  # fmt: skip
    if last_hi - last_lo <= tolerance * (1.0 + 1e-9):
        return replace(first, last_lo=last_lo, last_hi=last_hi)
    if exhausted:  # the first crossing, the paper's, stands
        return replace(first, message=f"last crossing's bracket still {last_hi - last_lo:.3g} "
                       f"mm after {max_refinements} refinements", last_lo=last_lo,
                       last_hi=last_hi)  # fmt: skip
    L = _on_lattice(last_lo + (last_hi - last_lo) / 2.0)
    if L in gaps:  # (the lattice's resolution reached)
        return replace(first, last_lo=last_lo, last_hi=last_hi)
    return SeriesState("refining", first.lo, first.hi, L, first.evaluations, "", last_lo, last_hi)


def _propose(gaps, jammed, lo, hi, threshold, tol, span) -> float:
    width = hi - lo
    bisect = _on_lattice(lo + width / 2.0)
    estimate = _secant_estimate(gaps, jammed, lo, threshold, span)
    if estimate is None or not lo < estimate < hi:
        return bisect
    L = estimate + 0.45 * tol
    if L >= hi - 0.5 * tol:
        L = hi - 0.9 * tol  # the crossing is just below hi: close from below
    L = _on_lattice(min(max(L, lo + 0.5 * tol), hi - 0.5 * tol))
    return bisect if L in gaps else L


def _secant_estimate(gaps, jammed, lo, threshold, span) -> float | None:
    """Where the secant through two jammed points (lo, and one at least ``span``
    below it when there is one) reaches the threshold."""
    finite = [L for L in jammed if math.isfinite(gaps[L])]
    if lo not in finite or len(finite) < 2:
        return None
    far = [L for L in finite if L <= lo - span]
    L1 = far[-1] if far else finite[-2]
    slope = (gaps[lo] - gaps[L1]) / (lo - L1)
    if not slope < 0.0:
        return None
    return lo + (threshold - gaps[lo]) / slope


class Refiner:
    """The adaptive series of a job: their gaps so far and what each needs next."""

    def __init__(self, job: JobSpec) -> None:
        self.job = job
        self.settings = job.adaptive
        self.coarse = sorted(job.grid.axes()["L_mm"])
        self.series: dict[str, dict[str, Any]] = {}
        self._states: dict[str, SeriesState] = {}  # each series' state until its gaps change
        for params in job.points():
            for d in job.directions:
                key = self.key(params, d)
                self.series.setdefault(key, {"base": params, "direction": d, "gaps": {}})

    def key(self, params: StitchParams, direction: str) -> str:
        base = params_form(params, exclude={"L_mm"})  # the id forms, as task ids'
        return digest({"series": base, "direction": direction,
                       "adaptive": ADAPTIVE_FORMS.id_form(self.settings.model_dump(mode="json")),
                       "protocol": protocol_id_form(self.job.protocol.model_dump(mode="json"),
                                                    direction),
                       "fidelity": fidelity_form(self.job.fidelity, params.stitch)})  # fmt: skip

    def observe(self, sweep_meta: dict[str, Any]) -> None:
        """Take one finished sweep's gap (done: its gap; not knittable: jammed;
        failed: unknown)."""
        params = StitchParams.from_flat(sweep_meta)
        key = self.key(params, str(sweep_meta["direction"]))
        if key not in self.series:
            return
        status = str(sweep_meta.get("status"))
        if status == DONE:
            gap = float(sweep_meta["jamming_gap"])
        elif status == NOT_KNITTABLE:
            gap = JAMMED_GAP
        else:
            gap = None
            self.series[key].setdefault("why", {})[params.L_mm] = str(sweep_meta.get("message", ""))
        if gap is not None:
            self.series[key].get("why", {}).pop(params.L_mm, None)
        self.series[key]["gaps"][params.L_mm] = gap
        self._states.pop(key, None)

    def states(self) -> Iterator[tuple[str, SeriesState]]:
        """Every series' state (``series_state`` of its gaps, recomputed only for the
        series whose gaps changed since the last call)."""
        s = self.settings
        for key, series in self.series.items():
            if key not in self._states:
                self._states[key] = series_state(self.coarse, series["gaps"], s.threshold_mJ,
                                                 s.tolerance_mm, s.secant_span_mm,
                                                 s.max_refinements, s.last_crossing)  # fmt: skip
            yield key, self._states[key]

    def point_params(self, key: str, L: float) -> tuple[StitchParams, str]:
        series = self.series[key]
        return series["base"].model_copy(update={"L_mm": L}), series["direction"]

    def series_meta(self, key: str, state: SeriesState) -> dict[str, Any]:
        """The ``/series/<key>`` record: the final bracket (mm and L/r)."""
        series = self.series[key]
        base: StitchParams = series["base"]
        r = base.r_mm
        flat = base.model_dump(mode="json", exclude={"L_mm"})
        message = state.message
        why = series.get("why", {})
        if state.status == "failed" and why and state.message.startswith("no energy gap"):
            L = min(why)
            message = f"{failure_status(L, why[L])}; {message}"
        return {
            "status": state.status,
            "message": message,
            "direction": series["direction"],
            **flat,
            "lo_mm": state.lo,
            "hi_mm": state.hi,
            "L_over_r_trans": None if state.hi is None or state.status != "done" else state.hi / r,
            "bracket_lower": None if state.lo is None else state.lo / r,
            "bracket_upper": None if state.hi is None else state.hi / r,
            "last_lo_mm": state.last_lo,
            "last_hi_mm": state.last_hi,
            "evaluations": state.evaluations,
            "tolerance_mm": self.settings.tolerance_mm,
            "threshold_mJ": self.settings.threshold_mJ,
        }
