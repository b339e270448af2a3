"""Newton–KKT relaxation: trust-region SQP steps on the exact gradients (docs/model.md §7).

The problem is min E(z) subject to ℓ(z) = L and lo <= z <= hi, z the free entries of
the state (n - 1 in a strain step, all n at zero force; stockinette n = 30); the twist bound cos(tw) >= c_tw is
one of the bounds (``Problem.box``). Each iteration solves the quadratic model

    min_p (∇E)ᵀp + ½ pᵀ B p   subject to   ℓ − L + (∇ℓ)ᵀp = 0,  ‖p‖ <= Δ,  active bounds held,

with B = ∇²E − λ∇²ℓ the Hessian of the Lagrangian: a normal step onto the linearised
constraint (at most 0.8 Δ), then a tangential step in the constraint's null space,
by Cholesky factorisation of the reduced Hessian where it is positive definite and
by its eigenvalues (Moré–Sorensen) where it is not. Steps are accepted on the
augmented Lagrangian E − λc + ½ρc²; Δ grows and shrinks with the agreement of actual
and predicted decrease.

Soft modes. The reduced Hessian's eigenvalues span ~1e-4 … 1e2 mJ/mm² at a
zero-force state, and along the soft modes the energy is far from quadratic: moving
1e-3 mm along one turns its curvature from +7e-5 to −6e-4 mJ/mm² (measured at
L = 11.0 mm, k = 0.1 mN/mm²). A Hessian measured a little away therefore misjudges
exactly the soft modes. What works: ∇²E and ∇²ℓ (``Curvature``, full n × n) from
differences of the exact gradients, measured once per chain and carried from one
relaxation to the next, corrected by a symmetric rank-one update from every accepted
step (the steps that matter point along the soft modes, so these updates repair what
the carried Hessian gets wrong) and from each strain step to the next (which also
corrects the cross terms with the pulled period), and measured again when a
relaxation needs more than ``REMEASURE_AFTER`` iterations. A mode counts as flat only
below 1e-12 of the stiffest, and every step along a flat, soft or negative mode is
bounded by Δ.

The predictor. In a strain step the previous step's solution and the carried Hessian
give the first-order change of the gradients with the pulled period, so the first
Newton step is taken before any evaluation (from the extrapolated KKT conditions):
the first evaluation lands within O(h²) of the new minimum.

Converged when the length residual is below both 1e-3 of ``length_tol_mm`` and
goal/|λ|, the reduced Hessian has no negative mode, the Newton decrement ½ rᵀ H_r⁻¹ r
(the energy the model still expects to gain) is at most the decrement goal
(``SolverSettings.decrement_goal_mJ``, the setting ``ftol``), and, at zero force
(both periods free), so is what the largest component of ∇E − λ∇ℓ (over the entries not
held at a bound) would gain along a mode of curvature 1e-3 mJ/mm²:
|∇L|_max <= sqrt(2 · 1e-3 · goal), which keeps the period forces there below 5e-7 N
(a soft mode can hide a larger gradient from the decrement alone).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import SolverSettings
from ..kernels.kkt import sr1_update
from ..kernels.kkt_rows import kkt_step_for, solve_kkt
from .problem import Minimum, Point, Problem

FD_STEP = 1e-7
"""Forward-difference step of the Hessian columns (state units: mm or rad): the
truncation error ~h·|∇³E| ~ 1e-7 mJ/mm² and the rounding ~1e-16·|∇E|/h ~ 1e-10 stay
far below the softest modes (1e-4); central differences, at twice the cost, measured
no fewer iterations."""
SOFTEST = 1e-3
"""The curvature (mJ/mm²) that scales the zero-force stationarity test."""
FLAT_MODE = 1e-12
"""A reduced-Hessian eigenvalue below this fraction of the largest counts as flat."""
NORMAL_SHARE = 0.8
"""Largest share of the trust radius the normal (constraint) step may use."""
REMEASURE_AFTER = 20
"""Iterations after which a relaxation measures the Hessian again (once)."""
FIRST_RADIUS = 1.0
"""Trust radius (state units) of a chain's first relaxation."""
MAX_RADIUS, MIN_RADIUS = 10.0, 1e-10
"""The trust radius stays within these (state units); below the least, no step can
lower the energy measurably (a kink of the energy, e.g. a contact crossing the
exclusion boundary): the iteration gives up and SLSQP finishes."""
SNAP = 1e-10
"""A start within this relative distance of a bound is put on it (and the bound held)."""
MAX_PROBES = 2
"""Curvature probes along a negative mode at one point: a mode that an update made up is
gone after one; a mode that survives them is real (a state past the fold of its
branch), and the trust region steps down it, growing 4x per good step. Only a mode
that has just appeared, or whose decrement has grown a hundredfold, is probed."""
BLOCKED_CYCLE = 50
"""Iterations in a row that a bound blocks at once (no evaluation between them) after
which the iteration gives up: the active set is cycling. Seen in seed's sweeps: two
sets of bounds held and let go in turn, the multiplier flipping between two values,
the state, the curvature and the radius unchanged, until the iteration limit (~2000
steps of the KKT kernel, 2 CPU s). Leaving then returns the point and the curvature
that the limit returns when the cycle goes on to it, so SLSQP finishes from the same
state; only the iterations and the message differ. Measured over 3833 relaxations of
garter, rib and seed (zero force, 2 starts, and both sweeps at 9.7, 10.9, 12.5 and
13.3 mm): two runs went on to the limit (217 and 1997 iterations long), and the
longest that ended otherwise was 12 iterations long, the next 4."""
MIN_START_RADIUS = 0.01
"""A relaxation starts with at least this radius: one that collapsed on the last
one's final, noise-level steps would cost a dozen doublings."""


@dataclass(frozen=True)
class Anchor:
    """A chain's last converged point: the full state (n,), ∇E, ∇ℓ (n,), ℓ − L (mm)."""

    x: np.ndarray
    ge: np.ndarray
    gl: np.ndarray
    c: float
    energy: float


@dataclass
class Curvature:
    """∇²E (mJ) and ∇²ℓ (mm) per state unit squared, shape (n, n), at a recent point
    of a chain, the trust radius Δ that last worked, and the chain's last converged
    point. ``known[i]``: column i was measured (a strain step never measures its fixed
    period's column; its row comes with the others' columns)."""

    energy: np.ndarray
    length: np.ndarray
    known: np.ndarray
    radius: float = FIRST_RADIUS
    anchor: Anchor | None = None

    def lagrangian(self, lam: float) -> np.ndarray:
        """B = ∇²E − λ∇²ℓ, (n, n)."""
        return self.energy - lam * self.length

    def update(self, s: np.ndarray, y_e: np.ndarray, y_l: np.ndarray, lam: float,
               probe: bool = False) -> None:  # fmt: skip
        """A symmetric rank-one update of the Lagrangian's Hessian B = ∇²E − λ∇²ℓ from a
        step s (n,) of the full state and the changes y_e, y_l (n,) of ∇E and ∇ℓ, so
        that B s = y_e − λ y_l afterwards (∇²ℓ is updated by its own secant first, ∇²E
        then carries the rest). Skipped when ill-defined and, unless ``probe`` (a step
        taken to measure the curvature), when the secant curvature sᵀ(y_e − λ y_l) is
        not positive: near a minimum that is the third-order change along a soft mode,
        and taken for curvature it would make up a negative mode the state does not have."""
        y = y_e - lam * y_l
        if not probe and not float(s @ y) > 0.0:
            return
        sr1_update(self.length, s, y_l, 1e-8)
        sr1_update(self.energy, s, y + lam * (self.length @ s), 1e-8)


def measure_curvature(prob: Problem, pt: Point, radius: float = FIRST_RADIUS) -> Curvature:
    """∇²E and ∇²ℓ at ``pt`` by forward differences of the exact gradients (n
    evaluations). Column j holds the derivatives of all n gradient entries, so a fixed
    period's row is filled too, and its column by symmetry."""
    free = prob.free
    n_state = prob.x.size
    he = np.zeros((n_state, n_state))
    hl = np.zeros((n_state, n_state))
    for j, col in enumerate(free):
        zj = pt.z.copy()
        zj[j] += FD_STEP
        q = prob.evaluate(zj)
        he[:, col] = (q.ge - pt.ge) / FD_STEP
        hl[:, col] = (q.gl - pt.gl) / FD_STEP
    known = np.zeros(n_state, dtype=bool)
    known[free] = True
    ff, fixed = np.ix_(free, free), ~known
    for h in (he, hl):
        h[ff] = 0.5 * (h[ff] + h[ff].T)
        h[np.ix_(free, fixed)] = h[np.ix_(fixed, free)].T
    return Curvature(he, hl, known, radius)


@dataclass(frozen=True)
class _Step:
    p: np.ndarray  # the step (n,), zero on held bounds
    lam: float  # the model's length multiplier (mJ/mm)
    decrement: float  # energy the full Newton step would still gain (mJ)
    negative: np.ndarray | None  # the reduced Hessian's negative mode (n,), if it has one
    kappa: np.ndarray  # ∂L/∂z (n,) after the step: the multipliers of the held bounds


def _kkt_step(b_full: np.ndarray, pt: Point, free: np.ndarray, active: np.ndarray,
              radius: float) -> _Step:  # fmt: skip
    """The trust-region SQP step at ``pt`` with the bounds in ``active`` held;
    ``b_full`` (n, n) is the Lagrangian's Hessian, ``free`` the free entries
    (compiled: ``kernels.kkt.kkt_step``, ``kernels.kkt_rows.kkt_step_rows`` from
    ``ROWS_FROM`` entries)."""
    return _Step(*solve_kkt(kkt_step_for(free.size), b_full, free, active, pt.g, pt.a, pt.c,
                            radius, NORMAL_SHARE, FLAT_MODE))  # fmt: skip


def _snap(z: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """z with entries within ``SNAP`` (relative) of a finite bound moved onto it."""
    near_lo = np.isfinite(lo) & (z - lo <= SNAP * (1.0 + np.abs(lo)))
    near_hi = np.isfinite(hi) & (hi - z <= SNAP * (1.0 + np.abs(hi)))
    return np.where(near_lo, lo, np.where(near_hi, hi, z))


def _predicted_start(curv: Curvature, prob: Problem, z0: np.ndarray, lo: np.ndarray,
                     hi: np.ndarray) -> np.ndarray:  # fmt: skip
    """z0 moved by the Newton step of the KKT conditions extrapolated from the chain's
    last converged point to the new fixed entries (no evaluation), or z0 itself if the
    free entries differ from that point's or nothing changed."""
    anchor = curv.anchor
    if anchor is None:
        return z0
    d = prob.x - anchor.x
    d[prob.free] = 0.0
    if not np.any(d) or not np.array_equal(anchor.x[prob.free], z0):
        return z0
    ge = anchor.ge + curv.energy @ d
    gl = anchor.gl + curv.length @ d
    free = prob.free
    virtual = Point(z0, anchor.energy + float(anchor.ge @ d), ge[free], anchor.c + float(
        anchor.gl @ d), gl[free], ge, gl)  # fmt: skip
    lam = virtual.multiplier
    active = (z0 <= lo) | (z0 >= hi)
    step = _kkt_step(curv.lagrangian(lam), virtual, free, active, curv.radius)
    return np.clip(z0 + step.p, lo, hi)


def newton_minimise(
    prob: Problem,
    z0: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    settings: SolverSettings,
    curvature: Curvature | None = None,
) -> Minimum:
    """Minimise from z0 within [lo, hi], warm-started by ``curvature`` (carried on in
    the result). z is the best point reached, also on failure."""
    free = prob.free
    z0 = np.clip(z0, lo, hi)  # only the twist can lie outside its bound: onto it
    usable = curvature is not None and bool(np.all(curvature.known[free]))
    if usable:
        z0 = _predicted_start(curvature, prob, z0, lo, hi)
    pt = prob.evaluate(_snap(z0, lo, hi))
    if not pt.finite:
        return Minimum(pt.z, False, "non-finite energy at the start", 0, curvature)
    if usable and curvature.anchor is not None:  # the secant from the last solution
        anchor = curvature.anchor
        curvature.update(
            prob.full(pt.z) - anchor.x,
            pt.ge - anchor.ge,
            pt.gl - anchor.gl,
            pt.multiplier,
        )
    measured = not usable
    if measured:
        curvature = measure_curvature(prob, pt, curvature.radius if curvature else FIRST_RADIUS)
    assert curvature is not None
    radius, rho = max(curvature.radius, MIN_START_RADIUS), 1.0
    active = (pt.z <= lo) | (pt.z >= hi)
    lam = pt.multiplier
    probes, previous, blocked = 0, None, 0
    for it in range(1, settings.maxiter + 1):
        b_full = curvature.lagrangian(lam)
        step = _kkt_step(b_full, pt, free, active, radius)
        # a held bound whose multiplier has the wrong sign (∂L/∂z_i must be >= 0 at a
        # lower bound, <= 0 at an upper one) is let go if the step without it leaves
        # the bound inwards
        at_lo, at_hi = pt.z <= lo, pt.z >= hi
        release = active & ((at_lo & (step.kappa < 0)) | (at_hi & (step.kappa > 0)))
        if release.any():
            loose = _kkt_step(b_full, pt, free, active & ~release, radius)
            inwards = (at_lo & (loose.p > 0)) | (at_hi & (loose.p < 0))
            if np.all(inwards[release]):
                active, step = active & ~release, loose
        suspect = (
            previous is None
            or previous.negative is None
            or (step.decrement > 100.0 * previous.decrement)
        )
        if step.negative is not None and suspect and probes < MAX_PROBES:
            # a negative mode that has just appeared (or grown a hundredfold) may be a
            # rank-one update's artefact: measure the curvature along it (one
            # evaluation) and let the update correct the model there
            probes, blocked = probes + 1, 0
            q = prob.evaluate(pt.z + FD_STEP * step.negative)
            s_full = np.zeros(prob.x.size)
            s_full[free] = q.z - pt.z
            curvature.update(s_full, q.ge - pt.ge, q.gl - pt.gl, lam, probe=True)
            continue
        previous = step
        lam = step.lam
        goal = settings.decrement_goal_mJ
        c_tol = min(1e-3 * settings.length_tol_mm, goal / max(abs(lam), 1e-300))
        # at zero force, the stationarity a soft mode hides from the decrement (there the
        # period components of ∇L are the period forces, an output): ∇L along a mode of
        # curvature SOFTEST leaves at most the decrement goal to gain
        g_tol = math.sqrt(2.0 * SOFTEST * goal)
        stationary = prob.free.size < prob.x.size or g_tol >= float(
            np.max(np.abs(np.where(active, 0.0, pt.g - lam * pt.a)))
        )
        if (abs(pt.c) <= c_tol and step.decrement <= goal and step.negative is None
                and stationary):  # fmt: skip
            curvature.radius = radius
            curvature.anchor = Anchor(prob.full(pt.z), pt.ge, pt.gl, pt.c, pt.energy)
            message = f"Newton converged (decrement {step.decrement:.2g} mJ)"
            return Minimum(pt.z, True, message, it, curvature)
        p = step.p
        # stay inside the box: shorten the step to the first bound it meets
        with np.errstate(divide="ignore", invalid="ignore"):
            room = np.where(p > 0, (hi - pt.z) / p, np.where(p < 0, (lo - pt.z) / p, np.inf))
        alpha = min(1.0, float(np.min(room)))
        hit = room <= alpha
        if alpha <= 0.0:  # blocked at once: hold the bound and try again
            active = active | hit
            blocked += 1
            if blocked >= BLOCKED_CYCLE:
                message = f"Newton: bounds held and let go in turn for {blocked} iterations"
                return Minimum(pt.z, False, message, it, curvature)
            continue
        blocked = 0
        trial = prob.evaluate(np.clip(pt.z + alpha * p, lo, hi) if alpha < 1.0 else pt.z + p)
        s = trial.z - pt.z
        # the augmented Lagrangian merit and the decrease the model predicts for it
        s_full = np.zeros(prob.x.size)
        s_full[free] = s
        c_new = pt.c + float(pt.a @ s)
        model = float((pt.g - lam * pt.a) @ s) + 0.5 * float(s_full @ b_full @ s_full)
        feas = 0.5 * (pt.c * pt.c - c_new * c_new)
        if feas > 0.0:
            rho = max(rho, 2.0 * model / feas + 1.0)
        pred = -model + rho * feas
        ared = (pt.energy - lam * pt.c + 0.5 * rho * pt.c**2) - (
            trial.energy - lam * trial.c + 0.5 * rho * trial.c**2
        )
        noise = 1e-14 * max(1.0, abs(pt.energy))
        norm = float(np.linalg.norm(s))
        if trial.finite and (ared >= 1e-4 * pred or (pred <= noise and ared >= -noise)):
            curvature.update(s_full, trial.ge - pt.ge, trial.gl - pt.gl, lam)
            pt, probes = trial, 0
            ratio = ared / pred if pred > 0 else 1.0
            if alpha < 1.0:  # cut short by a bound, which the model did not know of
                active = active | hit
            elif ratio > 0.75 and norm >= 0.99 * radius:
                radius = min((2.0 if step.negative is None else 4.0) * radius, MAX_RADIUS)
            elif ratio < 0.25:
                radius = 0.25 * norm
        else:
            radius = 0.25 * (norm if alpha == 1.0 else radius)
        if radius < MIN_RADIUS:
            return Minimum(pt.z, False, "Newton: trust region collapsed", it, curvature)
        if it >= REMEASURE_AFTER and not measured:
            curvature = measure_curvature(prob, pt, radius)
            measured = True
    return Minimum(pt.z, False, "Newton: iteration limit reached", settings.maxiter, curvature)
