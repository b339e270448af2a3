"""The free yarn's Newton–KKT step (``kernels.kkt_rows.kkt_step_rows``: the reduced Hessian by
an implicit reflection, LAPACK's Cholesky, an indefinite one by its tridiagonal form)
against the dense reference step (``kkt_step``) on real pattern Hessians (docs/model.md
§7, §11)."""

import numpy as np
import pytest

from knitsweep.config import StitchParams
from knitsweep.kernels.kkt import ROWS_FROM, kkt_step, more_sorensen, tangential_step
from knitsweep.kernels.kkt_rows import (
    kkt_step_for,
    kkt_step_rows,
    step_kernels,
    tangential_step_rows,
)
from knitsweep.model import CellModel
from knitsweep.relax.newton import measure_curvature
from knitsweep.relax.problem import Problem
from knitsweep.stitches import get_stitch

TOL = 1e-10


@pytest.fixture(scope="module", params=["garter", "rib", "seed"])
def pattern(request):
    """A pattern's first start at L = 11.6 mm: the point (all entries free) and the
    Lagrangian's Hessian measured there (forward differences, as Newton measures it)."""
    stitch = get_stitch(request.param)
    model = CellModel(StitchParams(stitch=request.param, L_mm=11.6, k_mN_per_mm2=0.1))
    x = stitch.start(1)
    free = np.arange(stitch.n_state)
    prob = Problem(model, x, free)
    pt = prob.evaluate(x.copy())
    curv = measure_curvature(prob, pt)
    return pt, free, curv.lagrangian(pt.multiplier)


def _step(f, b, pt, free, held, radius):
    n = free.size
    p, kappa, neg = np.empty(n), np.empty(n), np.empty(n)
    lam, dec, negative = f(b, free, held, pt.g, pt.a, pt.c, radius, 0.8, 1e-12, p, kappa, neg)
    return lam, dec, negative, p, kappa, neg


def _agree(pt, b, free, held, radius):
    ref = _step(kkt_step, b, pt, free, held, radius)
    new = _step(kkt_step_rows, b, pt, free, held, radius)
    lam, dec, negative, p, kappa, neg = ref
    assert new[2] == negative
    assert new[0] == pytest.approx(lam, rel=TOL)
    assert new[1] == pytest.approx(dec, rel=TOL)
    assert np.max(np.abs(new[3] - p)) <= TOL * np.max(np.abs(p))
    scale = np.max(np.abs(pt.g)) + np.max(np.abs(b)) * np.max(np.abs(p))
    assert np.max(np.abs(new[4] - kappa)) <= TOL * scale
    assert np.all(new[3][held] == 0.0)
    if negative:  # the lowest mode, up to its sign
        assert abs(new[5] @ neg) == pytest.approx(1.0, abs=TOL)
        assert np.all(new[5][held] == 0.0)
    return negative


def test_patterns_take_the_rows_step():
    """Every pattern's 86–88 free entries are past ``ROWS_FROM``, stockinette's 29–30 not
    (its steps stay the dense reference's, bit for bit)."""
    for name in ("garter", "rib", "seed"):
        assert get_stitch(name).n_state - 1 >= ROWS_FROM
    assert get_stitch("stockinette").n_state < ROWS_FROM


@pytest.mark.parametrize("radius", [1e-3, 0.1, 10.0])
def test_rows_step_is_the_dense_step_on_an_indefinite_pattern_hessian(pattern, radius):
    """At a start the reduced Hessian is indefinite: the tridiagonal path (DSYTRD, DSTERF,
    DSTEIN on the low modes, shifted tridiagonal solves) gives the eigendecomposition's
    step, multiplier, decrement and lowest mode to 1e-10, with and without held bounds."""
    pt, free, b = pattern
    held = np.zeros(free.size, dtype=bool)
    assert _agree(pt, b, free, held, radius)
    held[[53, 61, 73]] = True  # offsets of three segment ends held at a bound
    assert _agree(pt, b, free, held, radius)


@pytest.mark.parametrize("radius", [1e-3, 0.1, 1e3])
def test_rows_step_is_the_dense_step_on_a_positive_definite_pattern_hessian(pattern, radius):
    """The same Hessian shifted to positive definite: LAPACK's Cholesky, inside the
    radius (the Newton step) and on it (Moré–Sorensen shifts)."""
    pt, free, b = pattern
    w = np.linalg.eigvalsh(b)
    shifted = b + (max(0.0, -w[0]) + 1e-3 * np.max(np.abs(w))) * np.eye(b.shape[0])
    held = np.zeros(free.size, dtype=bool)
    assert not _agree(pt, shifted, free, held, radius)


@pytest.mark.parametrize("m", [5, 29, 87])
def test_both_steps_run_one_more_sorensen_loop(m):
    """``tangential_step`` (hand-written upper factor) and ``tangential_step_rows``
    (LAPACK's lower factor) are ``more_sorensen`` on their factorisation, bit for bit:
    where the Newton step is too long, a shifted step onto the radius, the two
    factorisations equal to round-off; where hz is not positive definite, no step."""
    rng = np.random.default_rng(m)
    q = rng.standard_normal((m, m))
    hz = q @ q.T + 0.01 * np.eye(m)
    rz = rng.standard_normal(m)
    full = np.linalg.solve(hz, -rz)
    radius = 0.3 * np.linalg.norm(full)
    steps = {}
    for lapack, step in ((False, tangential_step), (True, tangential_step_rows)):
        u, w = np.empty(m), np.empty(m)
        dec, done = more_sorensen(hz, rz, radius, lapack, np.zeros((m, m)), np.empty(m), u, w)
        assert done
        v = np.empty(m)
        assert step(hz, rz, radius, 1e-12, v, np.zeros(m)) == (dec, False)
        assert np.array_equal(u, v)
        steps[lapack] = u, dec
    (u0, d0), (u1, d1) = steps[False], steps[True]
    assert np.linalg.norm(u0) == pytest.approx(radius, rel=1e-12)
    assert np.max(np.abs(u1 - u0)) <= TOL * np.max(np.abs(u0))
    assert d0 == pytest.approx(0.5 * rz @ np.linalg.solve(hz, rz), rel=TOL)
    assert d1 == pytest.approx(d0, rel=TOL)
    hz[0, 0] = -1.0
    for lapack in (False, True):
        got = more_sorensen(hz, rz, radius, lapack, np.zeros((m, m)), np.empty(m), u, w)
        assert got == (0.0, False)


def test_the_step_kernels_by_size():
    """One rule picks the step of a relaxation (``kkt_step_for``) and what compiles and
    counts as cached (``step_kernels``): the dense step below ``ROWS_FROM`` entries."""
    assert kkt_step_for(ROWS_FROM - 1) is kkt_step
    assert kkt_step_for(ROWS_FROM) is kkt_step_rows
    assert step_kernels(30) == (kkt_step,)
    assert step_kernels(88) == (kkt_step, kkt_step_rows)
