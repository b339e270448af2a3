"""Starts that reach the same minimum merge (docs/model.md §7-8), and the records say so."""

from dataclasses import replace

import numpy as np
import pytest

from knitsweep.config import Fidelity, StartSettings, StitchParams, SweepProtocol
from knitsweep.model import CellModel
from knitsweep.relax import Chain, Relaxer, merge_chains
from knitsweep.relax.chains import soft_distance
from knitsweep.relax.newton import measure_curvature
from knitsweep.relax.problem import Problem
from knitsweep.relax.zero_force import ZeroForce, zero_force
from knitsweep.strain_sweep import SweepResult, strain_sweep

POINT = StitchParams(L_mm=11.0, k_mN_per_mm2=0.1)
FIDELITY = Fidelity(samples_per_segment=6, quadrature_nodes=12)
SHORT = SweepProtocol(step_mm=0.002, max_strain=0.01)
TWINS = StartSettings(count=2, source="perturbed", perturbation=0.0)  # Init_1 twice


@pytest.fixture(scope="module")
def twins():
    return zero_force(POINT, FIDELITY, starts=TWINS)


def test_identical_starts_merge_on_the_way_to_zero_force(twins):
    """Two copies of Init_1 walk the same continuation stages (11.28 -> 11.0 mm: 3) and
    merge after the first; the second's row is the first's result, at no cost."""
    assert twins.stages == (3, 3)
    assert twins.merged_into == (-1, 0) and twins.merged_at == (-1, 1)
    a, b = twins.relaxations
    np.testing.assert_array_equal(a.x, b.x)
    assert b.status == a.status and "merged into start 0 at continuation stage 1/3" in b.message
    assert b.evaluations == 0 and twins.winner == 0 and "1 merged" in twins.message
    back = ZeroForce.from_record(twins.to_record())
    assert back.merged_into == twins.merged_into and back.merged_at == twins.merged_at


def test_no_merging_at_zero_tolerance():
    z = zero_force(POINT, FIDELITY, starts=TWINS.model_copy(update={"merge_tolerance_mJ": 0.0}))
    assert z.merged_into == (-1, -1)
    np.testing.assert_array_equal(z.relaxations[0].x, z.relaxations[1].x)  # same work, twice


def test_a_merged_start_is_not_pulled(twins):
    s = strain_sweep(POINT, twins, "x", SHORT, FIDELITY)
    assert s.carried.tolist() == [True, False]
    assert s.merged_into.tolist() == [-1, 0] and s.merged_at.tolist() == [-1, 0]
    assert s.relaxations == len(s.strain) - 1


@pytest.mark.parametrize("tolerance", [1e-9, 0.0])
def test_chains_at_one_minimum_merge_in_the_sweep(twins, tolerance):
    """Two chains from the same state: merged at step 0 they cost one relaxation per step,
    with the same result as two chains kept apart."""
    one = twins.relaxations[0]
    zero = ZeroForce((one, one), ("a", "b"), (3, 3), 0, one.status, "")
    # (rest check off: at this coarse fidelity the y sweep falls 9.5e-5 mJ below Init_1's
    # zero force and would start over from the lower minimum, its chains then merging the
    # other way; tests/test_rest_branch.py tests that)
    no_rest_check = SHORT.model_copy(update={"rest_tolerance_mJ": 1.0})
    protocol = no_rest_check.model_copy(update={"merge_tolerance_mJ": tolerance})
    s = strain_sweep(POINT, zero, "y", protocol, FIDELITY)
    steps = len(s.strain) - 1
    if tolerance:
        assert s.merged_into.tolist() == [-1, 0] and s.merged_at.tolist() == [-1, 0]
        assert s.relaxations == steps
    else:
        assert s.merged_into.tolist() == [-1, -1] and s.relaxations == 2 * steps
    other = strain_sweep(POINT, replace(zero, relaxations=(one,), labels=("a",), stages=(3,)),
                         "y", no_rest_check, FIDELITY)  # fmt: skip
    np.testing.assert_array_equal(s.total_energy, other.total_energy)
    assert SweepResult.from_record(s.to_record()).merged_at.tolist() == s.merged_at.tolist()


def test_soft_distance_tells_soft_from_stiff_differences(twins):
    """The merge criterion's distance ½δᵀBδ: 5e-11 mJ for 1e-3 along the softest mode,
    orders of magnitude more along the stiffest."""
    model = CellModel(POINT, FIDELITY)
    x = twins.best.x
    free = np.arange(30)
    prob = Problem(model, x, free)
    pt = prob.evaluate(x.copy())
    b = measure_curvature(prob, pt).lagrangian(twins.best.length_multiplier)
    t = pt.a / np.linalg.norm(pt.a)
    p = np.eye(30) - np.outer(t, t)  # the tangent of the length constraint
    w, v = np.linalg.eigh(p @ b @ p + 1e3 * np.outer(t, t))
    keep = Chain(0, x, Relaxer(), twins.best)

    def distance(direction):
        return soft_distance(model, keep, Chain(1, x + 1e-3 * direction, Relaxer(), twins.best),
                             None)  # fmt: skip

    soft, stiff = distance(v[:, 0]), distance(v[:, -2])
    assert soft == pytest.approx(0.5 * 1e-6 * w[0], rel=0.05) and soft < 1e-9
    assert stiff > 1e4 * soft and distance(np.zeros(30)) == 0.0


def test_merge_needs_both_the_energy_and_the_state(twins):
    """Same state but energies 1e-8 mJ apart, or the same energy but a stiff
    displacement: no merge. Same state and energy: merged into the lower start."""
    model = CellModel(POINT, FIDELITY)
    r = twins.best
    higher = replace(r, bending_energy=r.bending_energy + 1e-8)
    moved = r.x.copy()
    moved[3] += 1e-3  # the crossover half-height z: a stiff direction

    def merged(second_x, second_r):
        into, at = np.full(2, -1), np.full(2, -1)
        kept = merge_chains([Chain(0, r.x, Relaxer(), r), Chain(1, second_x, Relaxer(), second_r)],
                            model, None, 1e-9, 5, into, at)  # fmt: skip
        return [c.start for c in kept], into.tolist(), at.tolist()

    assert merged(r.x, higher) == ([0, 1], [-1, -1], [-1, -1])
    assert merged(moved, r) == ([0, 1], [-1, -1], [-1, -1])
    assert merged(r.x.copy(), r) == ([0], [-1, 0], [-1, 5])
