"""Adaptive search for the unjamming transition (L/r)_trans along L.

A series is one (k, B, r_core, r, p) with one pulling direction. The job's coarse
grid ``grid.L_mm`` brackets the transition: (lo, hi] with hi the first coarse L
whose energy gap (ΔE_c in x, ΔE_b in y) is below the threshold and lo the L
before it, the same criterion as the post-processor (``analysis.transitions``).
The bracket then shrinks until hi - lo <= tolerance, one new L per refinement:

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
run replays the stored gaps and continues with the same proposals.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

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

    @property
    def finished(self) -> bool:
        return self.status in FINISHED


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
) -> SeriesState:
    """The next step of one series.

    coarse: the job's coarse L values (mm); gaps: every evaluated L -> its gap
    (mJ), ``None`` where the point could not be evaluated, ``JAMMED_GAP`` where it
    cannot be knitted.
    """
    n = len(gaps)
    if any(L not in gaps for L in coarse):
        return SeriesState("coarse", None, None, None, n, "waiting for the coarse grid")
    failed = sorted(L for L, g in gaps.items() if g is None)
    if failed:
        return SeriesState("failed", None, None, None, n, f"no energy gap at L = {failed} mm")
    Ls = sorted(gaps)
    below = [L for L in Ls if gaps[L] < threshold]
    if not below:
        return SeriesState("jammed_throughout", Ls[-1], None, None, n,
                           f"jammed at every L up to {Ls[-1]} mm")  # fmt: skip
    hi = below[0]
    jammed = [L for L in Ls if L < hi]
    if not jammed:
        return SeriesState("unjammed_at_start", None, hi, None, n,
                           f"already unjammed at the smallest L, {hi} mm")  # fmt: skip
    lo = jammed[-1]
    if hi - lo <= tolerance * (1.0 + 1e-9):
        return SeriesState("done", lo, hi, None, n)
    if n - len(set(coarse)) >= max_refinements:
        return SeriesState("failed", lo, hi, None, n,
                           f"bracket still {hi - lo:.3g} mm after {max_refinements} refinements")  # fmt: skip
    L = _propose(gaps, jammed, lo, hi, threshold, tolerance, secant_span)
    return SeriesState("refining", lo, hi, L, n)


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
