"""Where a sweep steps next and when it has done enough (docs/model.md §8).

Steps. ``fixed`` is the authors' schedule: multiples of h from the first one beyond
a_0, then the large step from ``switch_strain`` on. ``adaptive`` starts with h and
chooses every next step from the last three: for the envelope stress (exact at every
step, from the length multiplier) and, while it is below its zero-force value plus
``GAP_MARGIN_MJ`` (its minimum, which sets its energy gap, may lie ahead), each energy
component, the second divided difference y'' estimates the error of interpolating
linearly between steps, |y''| h²/8; the next h makes the largest of these errors,
relative to its tolerance, about 0.8 (at most doubling, at least halving; within
[h, ``max_step_mm``]). So steps are small where the curve bends (the jammed rise, the
dip of an energy component) and large where it is straight.

Stopping. Besides the stop stress and strain (the reference's rule), a sweep stops as
soon as everything its protocol's ``observables`` ask for is determined:
``secant_modulus`` once the step before the last is past 2 % strain (the centred stress
there needs the next step); ``energy_gaps`` once both energies have risen back above
their zero-force values by ``GAP_MARGIN_MJ``, so that the minimum of each along the
sweep (which sets its gap) lies behind; ``curve`` (and ``offset_stress``, whose regime is
the longest over the whole curve) only at the stop stress or strain.
"""

from __future__ import annotations

import math

import numpy as np

from ..analysis.stress_strain import SECANT_STRAIN
from ..analysis.transitions import GAP_THRESHOLD
from ..config import Direction, SweepProtocol
from .result import first_grid_value

GAP_MARGIN_MJ = GAP_THRESHOLD / 5
"""How far (mJ) above its zero-force value an energy component must have risen before
its minimum along the sweep counts as behind it: a fifth of the gap threshold that
marks jamming (``analysis.transitions.GAP_THRESHOLD``)."""
TARGET_ERROR = 0.8
"""Adaptive steps aim at this fraction of each tolerance."""


class StepControl:
    """The values of the pulled period, one step at a time (mm)."""

    def __init__(self, protocol: SweepProtocol, direction: Direction, a0: float,
                 sign: float) -> None:  # fmt: skip
        self.protocol, self.direction, self.a0, self.sign = protocol, direction, a0, sign
        self.h = protocol.step_mm

    def first(self) -> float:
        if self.protocol.step_control == "fixed":
            return first_grid_value(self.a0, self.h, self.sign)
        return self.a0 + self.sign * self.h

    def next(self, a: list[float], stress: list[float], eb: list[float], ec: list[float]) -> float:
        """The step after ``a[-1]``, given the sweep so far (a, envelope stress, E_b, E_c)."""
        p = self.protocol
        if p.step_control == "fixed":
            if abs(a[-1] - self.a0) / self.a0 >= p.switch_strain:
                self.h = p.large_step(self.direction)
            return a[-1] + self.sign * self.h
        if len(a) >= 3:
            tolerance = p.stress_tolerance_N_per_mm + p.stress_rtol * abs(stress[-1])
            ratio = _interpolation_error(a, stress) / tolerance
            for e in (eb, ec):  # an energy matters while its minimum may lie ahead
                if e[-1] < e[0] + GAP_MARGIN_MJ:
                    ratio = max(ratio, _interpolation_error(a, e) / p.energy_tolerance_mJ)
            factor = 2.0 if ratio <= 0.0 else min(2.0, max(0.5, math.sqrt(TARGET_ERROR / ratio)))
            self.h = min(max(self.h * factor, p.step_mm), p.max_step_mm)
        return a[-1] + self.sign * self.h


def _interpolation_error(a: list[float], y: list[float]) -> float:
    """|y''| h²/8 over the last step: the error of linear interpolation there, with y''
    the second divided difference of the last three points."""
    h1, h2 = a[-2] - a[-3], a[-1] - a[-2]
    d2 = 2.0 * ((y[-1] - y[-2]) / h2 - (y[-2] - y[-3]) / h1) / (h1 + h2)
    return abs(d2) * h2 * h2 / 8.0


def observables_determined(protocol: SweepProtocol, strain: list[float], eb: list[float],
                           ec: list[float]) -> str | None:  # fmt: skip
    """Why the sweep may stop now (everything asked for is determined), or None."""
    wanted = set(protocol.observables)
    if "curve" in wanted or len(strain) < 3:
        return None
    done = []
    if "secant_modulus" in wanted:
        if abs(strain[-2]) < SECANT_STRAIN:
            return None
        done.append(
            f"Y_sec (strain {abs(strain[-2]):.4g} >= {SECANT_STRAIN:g} before the last step)"
        )
    if "energy_gaps" in wanted:
        e_b, e_c = np.asarray(eb), np.asarray(ec)
        if not (e_b[-1] >= e_b[0] + GAP_MARGIN_MJ and e_c[-1] >= e_c[0] + GAP_MARGIN_MJ):
            return None
        done.append(f"energy gaps (E_b and E_c {GAP_MARGIN_MJ:g} mJ above their zero-force values)")
    return "determined: " + ", ".join(done)
