"""One relaxation's problem: the energy and the length constraint over the free entries.

docs/model.md §7: the state x (n,) splits into free entries z and, in a strain step,
the one fixed period. ``Problem`` evaluates E, ∇E, ℓ and ∇ℓ at z in one kernel call
(caching the last point, so that a solver asking for E, then ∇E, then ℓ pays once) and
counts the calls. The bounds are the stitch's (``Stitch.bounds``) widened to contain
the start, plus the twist bound cos(tw) >= c_tw written as a bound on tw itself.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..model import CellModel, NeighbourList
from ..stitches import Stitch


@dataclass(frozen=True)
class Point:
    """One evaluation over the free entries: z (n,), total energy E (mJ), its gradient
    g (n,) (mJ per state unit), the length residual c = ℓ - L (mm) and ∇ℓ a (n,);
    ge and gl are ∇E and ∇ℓ over the whole state (n,)."""

    z: np.ndarray
    energy: float
    g: np.ndarray
    c: float
    a: np.ndarray
    ge: np.ndarray
    gl: np.ndarray

    @property
    def multiplier(self) -> float:
        """Least-squares Lagrange multiplier of the length constraint, g ≈ λ a."""
        return float(self.a @ self.g) / float(self.a @ self.a)

    @property
    def finite(self) -> bool:
        # a sum of squares is finite only if every entry is (or overflows, far beyond
        # any physical gradient)
        return math.isfinite(self.energy + self.c + float(self.ge @ self.ge + self.gl @ self.gl))


@dataclass(frozen=True)
class Minimum:
    """What every minimiser returns: the best point ``z`` (n,) it reached (also on
    failure), whether it ``converged``, its ``message``, its ``iterations``, and what it
    carries to the next relaxation of a chain (Newton: its ``newton.Curvature``; None
    for a minimiser that carries nothing)."""

    z: np.ndarray
    converged: bool
    message: str
    iterations: int
    carried: Any = None


class Problem:
    """E, ∇E, ℓ, ∇ℓ of ``model`` over the free entries ``free`` of the state ``x_full``
    (the other entries stay at their values in ``x_full``)."""

    def __init__(self, model: CellModel, x_full: np.ndarray, free: np.ndarray,
                 neighbours: NeighbourList | None = None) -> None:  # fmt: skip
        self.model = model
        self.x = np.array(x_full, dtype=float)
        # a Verlet list of the contact candidates: the same sums, ~15 % faster
        self.neighbours = neighbours if neighbours is not None else model.neighbour_list(self.x)
        self.free = free
        self.L = model.ip.L
        self.stitch = model.stitch
        self.bound = model.ip.twist_bound if self.stitch.twist_index is not None else -1.0
        self.evaluations = 0
        self._last: Point | None = None
        self.last_full: tuple | None = None  # (Energies, grad E (n,), grad l (n,)) at _last

    @property
    def last_point(self) -> Point | None:
        """The point of the latest kernel call."""
        return self._last

    def full(self, z: np.ndarray) -> np.ndarray:
        x = self.x.copy()
        x[self.free] = z
        return x

    def evaluate(self, z: np.ndarray) -> Point:
        """The point at z (one kernel call unless z is the last point evaluated)."""
        last = self._last
        if last is not None and bool((z == last.z).all()):  # np.array_equal's test, cheaper
            return last
        e, ge, gl = self.model.energy_and_gradients(self.full(z), self.neighbours)
        self.evaluations += 1
        point = Point(z.copy(), e.objective, ge[self.free], e.length - self.L, gl[self.free],
                      ge, gl)  # fmt: skip
        self._last, self.last_full = point, (e, ge, gl)
        return point

    # the callbacks SLSQP asks for, one by one
    def energy(self, z):
        return self.evaluate(z).energy

    def energy_grad(self, z):
        return self.evaluate(z).g

    def length(self, z):
        return self.evaluate(z).c

    def length_grad(self, z):
        return self.evaluate(z).a

    def twist(self, z):
        return twist_margin(self.full(z), self.bound, self.stitch)

    def twist_grad(self, z):
        return twist_gradient(self.full(z), self.stitch)[self.free]

    def bounds(self, x0: np.ndarray) -> list[tuple[float | None, float | None]]:
        """The stitch's bounds of the free entries, each widened to contain the start
        (SciPy's format: None where unbounded)."""
        lo, hi = _widened(self.model, x0, self.free)
        return [(None if math.isinf(a) else float(a), None if math.isinf(b) else float(b))
                for a, b in zip(lo, hi, strict=True)]  # fmt: skip

    def box(self, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds (n,) of the free entries as arrays (±inf where free),
        the twist bound included as |tw - 2 pi k| <= arccos(c_tw) around the start's
        branch k (equivalent to cos(tw) >= c_tw there; not widened: a start beyond it
        is to be moved onto it)."""
        lo, hi = _widened(self.model, x0, self.free)
        if self.bound > -1.0:
            itw = self.stitch.twist_index
            i = int(np.flatnonzero(self.free == itw)[0])
            tw = float(x0[itw])
            centre = 2.0 * math.pi * round(tw / (2.0 * math.pi))
            half = math.acos(self.bound)
            lo[i], hi[i] = centre - half, centre + half
        return lo, hi


def twist_margin(x: np.ndarray, bound: float, stitch: Stitch) -> float:
    """The twist constraint cos(tw) - c_tw of state ``x`` (>= 0 where it holds; 1 - c_tw
    for a stitch without one)."""
    itw = stitch.twist_index
    return (math.cos(x[itw]) if itw is not None else 1.0) - bound


def twist_gradient(x: np.ndarray, stitch: Stitch) -> np.ndarray:
    """Gradient (n,) of the twist constraint at state ``x``."""
    g = np.zeros(stitch.n_state)
    itw = stitch.twist_index
    if itw is not None:
        g[itw] = -math.sin(x[itw])
    return g


@functools.lru_cache(maxsize=64)
def _state_box(stitch: Stitch, L: float, r: float,
               sampling: str = "parameter") -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """``stitch.bounds(L, r)``, read-only, made once; a pattern's whose contact samples
    sit by arclength (``sampling``) without the speed box of samples by parameter."""
    lo, hi = stitch.bounds(L, r) if sampling == "parameter" else stitch.bounds(L, r, sampling)
    lo.setflags(write=False)
    hi.setflags(write=False)
    return lo, hi


def _widened(model: CellModel, x0: np.ndarray, free: np.ndarray):
    """The free entries' bounds, widened so that they never exclude the start x0."""
    lo, hi = _state_box(model.stitch, model.ip.L, model.ip.r, model.sampling)
    return np.minimum(lo[free], x0[free]), np.maximum(hi[free], x0[free])
