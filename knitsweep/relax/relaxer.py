"""One relaxation, or a chain of them, with either minimiser (docs/model.md §7).

``relax`` minimises E at fixed yarn length from one state. ``Relaxer`` does the same for
relaxations that follow one another (the strain steps of one chain, the stages of a
continuation): it keeps one Verlet neighbour list per model and, for the Newton solver,
the curvature (``newton.Curvature``) from one relaxation to the next.

``SolverSettings.method`` picks the minimiser from ``SOLVERS``: ``newton`` (Newton–KKT
with a trust region, falling back to SLSQP from wherever it stopped if it cannot finish)
or ``slsqp``. Every minimiser has one signature and returns one typed result
(``problem.Minimum``). A relaxation runs its BLAS/LAPACK calls on one thread: with more, OpenBLAS
sums in another order and the same relaxation ends ~1e-13 elsewhere, depending on
what the process did before.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from threadpoolctl import ThreadpoolController

from ..config import SOLVERS as REGISTERED
from ..config import Direction, SolverInfo, SolverSettings
from ..model import CellModel, NeighbourList
from ..paths import load_path
from ..stitches import Stitch
from .newton import Curvature, newton_minimise
from .problem import Minimum, Problem
from .result import Relaxation, assess
from .slsqp import slsqp_minimise

_BLAS: list[ThreadpoolController] = []  # made on first use: inspecting the libraries costs ~1 ms
SUBSTEP_FTOL = 1e-8
"""Energy goal (mJ, ``SolverSettings.ftol``) of the unrecorded sub-steps of a large strain
step."""
_DEPTH = [0]  # how many single_threaded() blocks are open in this process


@contextlib.contextmanager
def single_threaded():
    """BLAS/LAPACK on one thread for the block (re-entrant: a nested block costs nothing,
    so that a sweep can hold it around its thousands of relaxations)."""
    if _DEPTH[0]:
        yield
        return
    if not _BLAS:
        _BLAS.append(ThreadpoolController())
    with _BLAS[0].limit(limits=1):
        _DEPTH[0] += 1
        try:
            yield
        finally:
            _DEPTH[0] -= 1


def free_entries(stitch: Stitch, fixed: Direction | None, gauge: Iterable[int] = ()) -> np.ndarray:
    """Indices of the free entries of a ``stitch`` state: all, or all but the periods the
    load path ``fixed`` controls (``paths.PATHS``), and never the ``gauge`` entries
    (``CellModel.gauge``)."""
    held = set(int(i) for i in gauge) | set(fixed_periods(stitch, fixed))
    return np.array([i for i in range(stitch.n_state) if i not in held])


def fixed_periods(stitch: Stitch, fixed: Direction | None) -> list[int]:
    """The state entries of the periods the load path ``fixed`` holds (none at zero force)."""
    return [] if fixed is None else [stitch.period_index(d) for d in load_path(fixed).controlled]


Minimiser = Callable[[Problem, np.ndarray, SolverSettings, object], Minimum]
"""``minimise(problem, x0, settings, carried) -> Minimum``: from the full start state
``x0`` over ``problem.free``, with what the chain's last relaxation carried."""


@dataclass(frozen=True)
class Solver:
    """A registered minimiser (``config.SOLVERS``: its name, what ``ftol`` means for it,
    whether it walks a large change of the fixed period in sub-steps) bound to its
    implementation."""

    info: SolverInfo
    minimise: Minimiser

    @property
    def name(self) -> str:
        return self.info.name

    @property
    def walks(self) -> bool:
        return self.info.walks


def _slsqp(prob: Problem, x0: np.ndarray, settings: SolverSettings, carried) -> Minimum:
    return slsqp_minimise(prob, x0[prob.free], prob.bounds(x0), settings)


def _newton(prob: Problem, x0: np.ndarray, settings: SolverSettings, carried) -> Minimum:
    lo, hi = prob.box(x0)
    got = newton_minimise(prob, x0[prob.free], lo, hi, settings, carried)
    if got.converged:
        return got
    # the Newton iteration could not finish: SLSQP from the best point it reached
    more = slsqp_minimise(prob, got.z, prob.bounds(x0), settings)
    return Minimum(more.z, more.converged, f"{got.message}; SLSQP from there: {more.message}",
                   got.iterations + more.iterations, None)  # fmt: skip


_IMPLEMENTATIONS: dict[str, Minimiser] = {"newton": _newton, "slsqp": _slsqp}
if set(_IMPLEMENTATIONS) != set(REGISTERED):  # a registered name without a minimiser
    raise ImportError(f"minimisers {sorted(_IMPLEMENTATIONS)} != the registry's "
                      f"{sorted(REGISTERED)} (knitsweep.config.SOLVERS)")  # fmt: skip
SOLVERS = {name: Solver(info, _IMPLEMENTATIONS[name]) for name, info in REGISTERED.items()}
"""The registered minimisers (``config.SOLVERS``, the names ``SolverSettings.method``
takes), each with its implementation."""


class Relaxer:
    """Relaxations in sequence, each warm-started by the caller, sharing a neighbour
    list and (Newton) the measured curvature."""

    def __init__(self, settings: SolverSettings | None = None) -> None:
        self.settings = settings or SolverSettings()
        self.curvature: Curvature | None = None
        self._model: CellModel | None = None
        self._neighbours: NeighbourList | None = None

    def relax(self, model: CellModel, x0: np.ndarray, fixed: Direction | None = None,
              settings: SolverSettings | None = None) -> Relaxation:  # fmt: skip
        """Minimise the energy at fixed yarn length ``model.params.L_mm`` from ``x0``.

        ``fixed=None`` frees both periods (zero-force state); a load path's name
        (``'x'``, ``'y'``, ``'biaxial'``, …) keeps the periods it controls at their values
        in ``x0`` (a strain step, docs/model.md §8).
        """
        settings = settings or self.settings
        t0 = time.perf_counter()
        x0 = model.gauged(np.asarray(x0, dtype=float))
        free = free_entries(model.stitch, fixed, model.gauge)
        with single_threaded():  # the unrecorded sub-steps too
            walked = self._walk(model, x0, fixed, settings)
            if walked is not None:
                x0, iterations, evaluations = walked
            else:
                iterations = evaluations = 0
            prob = self.problem(model, x0, free)
            try:
                got = self._minimise(prob, x0, settings)
                x, success, message, nit = (
                    prob.full(got.z),
                    got.converged,
                    got.message,
                    got.iterations,
                )
            except (ValueError, FloatingPointError, ZeroDivisionError) as e:
                x, success, message, nit = x0.copy(), False, f"minimiser failed: {e}", 0
            last = prob.last_point
            evaluated = (
                prob.last_full if last is not None and np.array_equal(last.z, x[free]) else None
            )
            return assess(model, x0, x, free, success, message, nit + iterations,
                          prob.evaluations + evaluations, settings, time.perf_counter() - t0,
                          evaluated)  # fmt: skip

    def problem(self, model: CellModel, x: np.ndarray, free: np.ndarray) -> Problem:
        """The problem at state ``x`` over ``free``, on this relaxer's neighbour list
        (built at ``x`` for a model it has not seen yet)."""
        if model is not self._model:
            self._model, self._neighbours = model, model.neighbour_list(x)
        return Problem(model, x, free, self._neighbours)

    def _walk(self, model, x0, fixed, settings):
        """For Newton, a change of the fixed period by more than ``substep_mm`` since the
        chain's last solution is walked in equal sub-steps (loosely converged, not
        recorded); returns (the last sub-step's state with x0's fixed period, their
        iterations, evaluations), or None if there is nothing to walk."""
        anchor = self.curvature.anchor if self.curvature is not None else None
        if not SOLVERS[settings.method].walks or fixed is None or anchor is None:
            return None
        i = fixed_periods(model.stitch, fixed)
        if not i:  # no period moves (a shear with the periods relaxed): nothing to walk
            return None
        free = free_entries(model.stitch, fixed, model.gauge)
        change = x0[i] - anchor.x[i]
        n = math.ceil(float(np.max(np.abs(change))) / settings.substep_mm - 1e-9)
        if n <= 1 or not np.array_equal(anchor.x[free], x0[free]):
            return None
        loose = settings.loosened(SUBSTEP_FTOL)
        x, iterations, evaluations = anchor.x.copy(), 0, 0
        for k in range(1, n):
            x[i] = anchor.x[i] + change * k / n
            # the minimiser alone: a sub-step is not recorded, so not assessed either
            prob = self.problem(model, x, free)
            got = self._minimise(prob, x, loose)
            iterations, evaluations = iterations + got.iterations, evaluations + prob.evaluations
            if not (got.converged and np.all(np.isfinite(got.z))):
                break
            x = prob.full(got.z)
        x[i] = x0[i]
        return x, iterations, evaluations

    def _minimise(self, prob: Problem, x0: np.ndarray, settings: SolverSettings) -> Minimum:
        got = SOLVERS[settings.method].minimise(prob, x0, settings, self.curvature)
        self.curvature = got.carried
        return got


def relax(
    model: CellModel,
    x0: np.ndarray,
    fixed: Direction | None = None,
    settings: SolverSettings | None = None,
) -> Relaxation:
    """One relaxation from ``x0`` (see ``Relaxer.relax``)."""
    return Relaxer(settings).relax(model, x0, fixed)
