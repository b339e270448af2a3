"""The zero-force state's skew relaxed: the rest a shear starts from (docs/inplane.md).

A free yarn's zero-force state is relaxed with the wale vector upright, t_w = (0, a_y0):
the skew s_x is held at 0, as the paper's ansatz (mirror-symmetric) holds it. Where the
cell's relaxed energy E*(s) at zero force (both periods free) is not at its minimum there
(rib's one-stitch cell leans and carries a shear stress; tight seed is a saddle), a
shear pulled from s = 0 starts off its path's minimum and measures no modulus or jamming
gap. ``relax_skew`` finds a skew s0 where E* is least: it steps downhill from s = 0
(the force F = dE*/ds, exact by the envelope theorem, gives the way; where F vanishes,
relaxations at ±h tell a minimum from a saddle), doubling the step until F turns, then
closes the bracket on F = 0 by regula falsi (Illinois), each relaxation warm-started
from the nearest state. That is a local minimum; a shear that falls below it further on
relaxes the skew again from there and starts over (``strain_sweep``), as a pull does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..config import CONVERGED, SolverSettings
from ..model import CellModel
from ..relax import Relaxation
from ..relax.zero_force import relax_at_rest

PROBE = 0.01
"""The first step in skew, as a shear γ = s/a_y0."""
FORCE_TOLERANCE_N_PER_MM = 2e-6
"""The skew is relaxed once |σ_xy| = |F|/a_x0 is below this (N/mm): about the precision
of a relaxed state's σ_xy (a mirror-symmetric stitch's, 0 by symmetry, measures up to
10⁻⁶ N/mm)."""
SKEW_TOLERANCE = 1e-9
"""… or the bracket is shorter than this, as a shear."""
MAX_RELAXATIONS = 40
"""At most this many relaxations at zero force."""


@dataclass(frozen=True)
class RestSkew:
    """The zero-force state with its skew relaxed: ``skew_mm`` (s0, the wale vector's x
    component), its ``relaxation`` (periods free), ``fall_mJ`` below the state it started from,
    ``sigma_xy`` (F/a_x0 there, N/mm), ``relaxations`` spent and a ``note`` in words."""

    skew_mm: float
    relaxation: Relaxation
    fall_mJ: float
    sigma_xy: float
    relaxations: int
    note: str

    @property
    def gamma(self) -> float:
        """s0 as a shear of the wale vector, s0/a_y0 (a_y0 of the relaxed state)."""
        return self.skew_mm / self.relaxation.a_y


def relax_skew(model: CellModel, rest: Relaxation, solver: SolverSettings | None = None,
               tolerance_mJ: float = 0.0, skew: float = 0.0) -> RestSkew | None:  # fmt: skip
    """The minimum of the relaxed energy over the skew from zero-force state ``rest`` (at
    skew ``skew``, mm), or None where ``skew`` is that minimum to within ``tolerance_mJ``
    (then nothing changes) or a relaxation on the way did not converge. ``model.skew`` is
    left as it was."""
    solver = solver or SolverSettings()
    entry = model.skew
    spent = [0]
    e0 = rest.total_energy
    h = PROBE * rest.a_y

    def at(s: float, x) -> tuple[Relaxation, float] | None:
        model.skew = s
        spent[0] += 1
        r = relax_at_rest(model, x, solver)
        if r.status != CONVERGED or not math.isfinite(r.total_energy):
            return None
        return r, model.skew_force(r.x)

    try:
        model.skew = skew
        f0 = model.skew_force(rest.x)
        lo = (skew, rest, f0)  # (s, state, F): F points downhill away from lo
        if abs(f0) / rest.a_x > FORCE_TOLERANCE_N_PER_MM:
            way = -math.copysign(1.0, f0)
        else:  # stationary: a minimum or a saddle?
            sides = [(w, at(skew + w * h, rest.x)) for w in (1.0, -1.0)]
            sides = [(w, got) for w, got in sides if got is not None]
            lower = [(w, got) for w, got in sides if got[0].total_energy < e0]
            if not lower:
                return None
            way, (r, f) = min(lower, key=lambda wg: wg[1][0].total_energy)
            lo = (skew + way * h, r, f)
            if f * way > 0.0:  # already past the minimum on that side
                return _found(rest, *_close(at, (skew, rest, f0), lo, way, spent),
                              spent[0], tolerance_mJ)  # fmt: skip
        step = h
        while spent[0] < MAX_RELAXATIONS:  # downhill, doubling, until F turns
            s = lo[0] + way * step
            got = at(s, lo[1].x)
            if got is None:
                return None
            hi = (s, *got)
            if got[1] * way > 0.0 or got[0].total_energy > lo[1].total_energy:
                return _found(rest, *_close(at, lo, hi, way, spent), spent[0],
                              tolerance_mJ)  # fmt: skip
            lo, step = hi, 2.0 * step
        return None
    finally:
        model.skew = entry


def _close(at, lo, hi, way, spent):
    """Regula falsi (Illinois) on F between ``lo`` (F·way < 0) and ``hi`` (F·way ≥ 0 or
    higher in energy): the lowest state found and its (s, F)."""
    best = min((lo, hi), key=lambda p: p[1].total_energy)
    side = 0
    while spent[0] < MAX_RELAXATIONS:
        (s_lo, _, f_lo), (s_hi, _, f_hi) = lo, hi
        if abs(s_hi - s_lo) < SKEW_TOLERANCE * best[1].a_y:
            break
        if f_hi * way > 0.0 and f_lo * way < 0.0:
            s = s_lo - f_lo * (s_hi - s_lo) / (f_hi - f_lo)
            s = min(max(s, min(s_lo, s_hi)), max(s_lo, s_hi))
        else:  # hi is higher but F has not turned: the minimum is between, bisect
            s = 0.5 * (s_lo + s_hi)
        near = lo if abs(s - s_lo) <= abs(s - s_hi) else hi
        got = at(s, near[1].x)
        if got is None:
            break
        p = (s, *got)
        if p[1].total_energy < best[1].total_energy:
            best = p
        if abs(p[2]) / p[1].a_x <= FORCE_TOLERANCE_N_PER_MM:
            break
        if p[2] * way < 0.0:
            lo = p
            if side == -1:
                hi = (hi[0], hi[1], 0.5 * hi[2])
            side = -1
        else:
            hi = p
            if side == 1:
                lo = (lo[0], lo[1], 0.5 * lo[2])
            side = 1
    return best


def _found(rest, s, r, f, relaxations, tolerance_mJ) -> RestSkew | None:
    fall = rest.total_energy - r.total_energy
    if not fall > tolerance_mJ:
        return None
    sigma = f / r.a_x
    note = (f"the skew relaxed at zero force: gamma0 = {s / r.a_y:.5g} (s = {s:.5g} mm), "
            f"{fall:.3g} mJ lower, sigma_xy {sigma:.2g} N/mm there "
            f"({relaxations} relaxations)")  # fmt: skip
    return RestSkew(s, r, fall, sigma, relaxations, note)
