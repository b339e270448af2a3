"""The Newton–KKT relaxation (docs/model.md §7): its step, its Hessian, and its minima
against SLSQP's."""

import numpy as np
import pytest

from knitsweep.config import CONVERGED, SolverSettings, StartSettings, StitchParams
from knitsweep.kernels.kkt import kkt_step, sr1_update
from knitsweep.model import CellModel
from knitsweep.relax import Relaxer, relax
from knitsweep.relax.newton import FD_STEP, measure_curvature
from knitsweep.relax.problem import Problem
from knitsweep.relax.zero_force import zero_force
from knitsweep.stitches.stockinette.layout import IDX_AX, IDX_TW

POINT = StitchParams(L_mm=11.0, k_mN_per_mm2=0.1)
SLSQP = SolverSettings(method="slsqp")


@pytest.fixture(scope="module")
def rest():
    """The zero-force state at L = 11.0 mm, k = 0.1 (one start, SLSQP, as the old code)."""
    return zero_force(POINT, solver=SLSQP, starts=StartSettings(count=1)).best


def _quadratic_step(h, g, a, c, radius=1e9):
    n = g.size
    b = np.zeros((30, 30))
    b[:n, :n] = h
    p, kappa, neg = np.empty(n), np.empty(n), np.empty(n)
    lam, dec, negative = kkt_step(b, np.arange(n), np.zeros(n, dtype=np.bool_), g, a, c, radius,
                                  0.8, 1e-12, p, kappa, neg)  # fmt: skip
    return p, lam, dec, negative, neg


def test_kkt_step_solves_the_equality_constrained_quadratic():
    """Inside the radius the step is the exact KKT solution of min gᵀp + ½pᵀHp s.t.
    aᵀp = -c, with its multiplier and the decrement ½ rᵀH_r⁻¹r of the reduced model."""
    rng = np.random.default_rng(1)
    m = rng.standard_normal((8, 8))
    h = m @ m.T + 0.1 * np.eye(8)
    g, a, c = rng.standard_normal(8), rng.standard_normal(8), 0.3
    p, lam, dec, negative, _ = _quadratic_step(h, g, a, c)
    k = np.block([[h, a[:, None]], [a[None, :], np.zeros((1, 1))]])
    sol = np.linalg.solve(k, np.r_[-g, -c])
    np.testing.assert_allclose(p, sol[:8], rtol=1e-10, atol=1e-12)
    assert lam == pytest.approx(-sol[8], rel=1e-10)
    assert not negative
    # the decrement is what the tangential step gains from the constraint's foot point
    pn = -c * a / (a @ a)
    q = lambda s: g @ s + 0.5 * s @ h @ s  # noqa: E731
    assert dec == pytest.approx(q(pn) - q(p), rel=1e-9)


def test_kkt_step_respects_the_radius_and_finds_negative_modes():
    rng = np.random.default_rng(2)
    m = rng.standard_normal((6, 6))
    h = m @ m.T + 0.1 * np.eye(6)
    g, a = rng.standard_normal(6), rng.standard_normal(6)
    p, *_ = _quadratic_step(h, g, a, 0.0, radius=1e-3)
    assert np.linalg.norm(p) == pytest.approx(1e-3, rel=0.02)
    assert abs(a @ p) < 1e-12  # still on the constraint
    indefinite = h - 20.0 * np.eye(6)
    p, _, _, negative, mode = _quadratic_step(indefinite, g, a, 0.0, radius=0.1)
    assert negative and abs(a @ mode) < 1e-10
    assert mode @ indefinite @ mode < 0 and np.linalg.norm(p) == pytest.approx(0.1, rel=0.02)


def test_sr1_update_fits_the_secant():
    rng = np.random.default_rng(3)
    h = np.eye(5)
    s, y = rng.standard_normal(5), rng.standard_normal(5)
    assert sr1_update(h, s, y, 1e-8)
    np.testing.assert_allclose(h @ s, y, rtol=1e-12)
    np.testing.assert_allclose(h, h.T)


def test_measured_hessian_matches_second_differences(rest):
    """Forward differences of the exact gradients give ∇²E along any direction to ~1e-6."""
    model = CellModel(POINT)
    free = np.arange(30)
    prob = Problem(model, rest.x, free)
    curv = measure_curvature(prob, prob.evaluate(rest.x.copy()))
    d = np.random.default_rng(0).standard_normal(30)
    d /= np.linalg.norm(d)
    eps = 1e-4
    _, gp, _ = model.energy_and_gradients(rest.x + eps * d)
    _, gm, _ = model.energy_and_gradients(rest.x - eps * d)
    hv = (gp - gm) / (2 * eps)
    assert np.linalg.norm(curv.energy @ d - hv) <= 1e-5 * np.linalg.norm(hv)
    assert FD_STEP < 1e-5


def test_zero_force_from_init_is_at_least_as_low_as_slsqp(init1):
    """Newton from Init_1 at L = 11.6 mm reaches SLSQP's converged minimum or below it
    (SLSQP at ftol 1e-10 stops ~1e-8 mJ short along the soft modes), and is stationary."""
    params = StitchParams(L_mm=11.6, k_mN_per_mm2=0.1)
    model = CellModel(params)
    a = relax(model, init1, settings=SLSQP)
    b = relax(model, init1)
    assert a.converged and b.converged and b.message.startswith("Newton converged")
    assert b.total_energy <= a.total_energy + 1e-9
    # the decrement bounds the energy still to gain; along a soft mode (curvature 1e-4)
    # a decrement of 1e-10 mJ leaves a gradient of ~1e-7
    assert abs(b.length_residual) <= 1e-9 and b.kkt_residual <= 1e-6
    assert abs(b.period_forces[0]) < 1e-6 and abs(b.period_forces[1]) < 1e-6


def test_strain_steps_reach_slsqp_minima_with_a_few_evaluations(rest):
    """30 steps of 0.001 mm in x from the same zero-force state: every Newton energy is
    within 1e-9 mJ of SLSQP's (converged preset) or below it; the carried Hessian and the
    predictor make a step cost a handful of evaluations, not SLSQP's ~40."""
    model = CellModel(POINT)
    chains = {"newton": Relaxer(SolverSettings()), "slsqp": Relaxer(SLSQP)}
    x = {k: rest.x.copy() for k in chains}
    energies = {k: [] for k in chains}
    evaluations = {k: [] for k in chains}
    for i in range(1, 31):
        for k, relaxer in chains.items():
            x0 = x[k].copy()
            x0[IDX_AX] = rest.x[IDX_AX] + 0.001 * i
            r = relaxer.relax(model, x0, "x")
            assert r.status == CONVERGED, (k, i, r.message)
            x[k] = r.x
            energies[k].append(r.total_energy)
            evaluations[k].append(r.evaluations)
    diff = np.array(energies["newton"]) - np.array(energies["slsqp"])
    assert diff.max() <= 1e-9
    assert np.median(evaluations["newton"][1:]) <= 6 < np.median(evaluations["slsqp"])


def test_a_large_step_is_walked_along_its_branch(rest):
    """A 0.05 mm step is walked in sub-steps of ``substep_mm``: the same state as relaxing
    at the intermediate periods oneself (to the sub-steps' tolerance)."""
    model = CellModel(POINT)
    first = Relaxer()
    r0 = first.relax(model, rest.x, "x")
    walked = first.relax(model, _at(r0.x, r0.x[IDX_AX] + 0.05), "x")
    by_hand = Relaxer()
    r = by_hand.relax(model, rest.x, "x")
    for k in range(1, 6):
        r = by_hand.relax(model, _at(r.x, r0.x[IDX_AX] + 0.01 * k), "x")
    assert walked.converged and walked.evaluations > r.evaluations
    assert walked.total_energy == pytest.approx(r.total_energy, abs=1e-9)
    assert np.max(np.abs(walked.x - r.x)) < 1e-3


def test_a_start_beyond_the_twist_bound_ends_on_it(rest):
    """The twist bound is a bound on tw: a start outside is moved onto it, and the
    result meets cos(tw) >= c_tw."""
    model = CellModel(POINT)
    x = rest.x.copy()
    x[IDX_TW] = np.arccos(0.9) + 0.05
    r = relax(model, x)
    assert r.converged and r.twist_margin >= -1e-8
    assert r.total_energy == pytest.approx(rest.total_energy, abs=1e-7)


def _at(x, a_x):
    x = x.copy()
    x[IDX_AX] = a_x
    return x


def test_a_cycling_active_set_ends_as_the_iteration_limit_would(rest, monkeypatch):
    """Bounds held and let go in turn without an evaluation (seen in seed's sweeps, each
    to the iteration limit) end the iteration after ``BLOCKED_CYCLE`` such steps with
    the point and the curvature that the limit returns: SLSQP then finishes from the
    same state."""
    from knitsweep.relax import newton

    def blocked_step(b_full, pt, free, active, radius):  # every step leaves z_0's bound
        p = np.zeros(free.size)
        p[0] = 1.0
        return newton._Step(p, 0.0, 1.0, None, np.zeros(free.size))

    monkeypatch.setattr(newton, "_kkt_step", blocked_step)
    model = CellModel(POINT)
    free = np.arange(30)
    lo, hi = np.full(30, -np.inf), np.full(30, np.inf)
    hi[0] = rest.x[0]
    ends, limit_of_cycles = [], newton.BLOCKED_CYCLE
    for cycle in (limit_of_cycles, 10**9):
        monkeypatch.setattr(newton, "BLOCKED_CYCLE", cycle)
        prob = Problem(model, rest.x, free)
        got = newton.newton_minimise(prob, rest.x.copy(), lo, hi, SolverSettings(maxiter=300))
        ends.append((got, prob.evaluations))
    (cut, n_cut), (limit, n_limit) = ends
    assert not cut.converged and cut.iterations == limit_of_cycles
    assert "let go in turn" in cut.message
    assert not limit.converged and limit.iterations == 300 and "limit" in limit.message
    assert np.array_equal(cut.z, limit.z) and n_cut == n_limit
    for a, b in ((cut.carried.energy, limit.carried.energy),
                 (cut.carried.length, limit.carried.length)):  # fmt: skip
        assert np.array_equal(a, b)
    assert cut.carried.radius == limit.carried.radius
