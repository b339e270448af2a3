"""The free yarns' parametrisation gauge (stitches/stockinette_free/gauge.py, CellModel.gauge;
docs/model.md §11, "The speeds as a gauge"): with the contact samples along the yarn every
end speed is held at L/8, a state from elsewhere is re-interpolated at equal fractions of its
arclength without moving its curve more than 8 quintics must, and what the gauge withholds
from a minimum is far below the jamming threshold. And a relaxation that stops short with
the hard cores overlapping is too tight to knit."""

import numpy as np
import pytest

from knitsweep.config import NOT_CONVERGED, NOT_KNITTABLE, Fidelity, SolverSettings, StitchParams
from knitsweep.model import CORES_OVERLAP, CellModel
from knitsweep.relax import Relaxer, free_entries
from knitsweep.relax.result import assess
from knitsweep.stitches.stockinette_free.gauge import (
    OFFSET_ENTRIES,
    SPEED_ENTRIES,
    _derivatives,
    regauge,
)

FREE_YARNS = ("stockinette_free", "garter", "rib", "seed")


def _model(stitch, L=11.6, sampling="auto"):
    return CellModel(StitchParams(stitch=stitch, L_mm=L, k_mN_per_mm2=0.1),
                     Fidelity(contact_sampling=sampling))  # fmt: skip


def _dense(cp, n=120):
    """Points along the curve, dense in each segment's parameter (S n, 3)."""
    return np.concatenate([_derivatives(c, np.linspace(0.0, 1.0, n))[0] for c in cp])


def _distance(a, b):
    """Symmetric Hausdorff distance between two point clouds (mm)."""
    d = np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(-1))
    return max(d.min(axis=1).max(), d.min(axis=0).max())


@pytest.mark.parametrize("stitch", FREE_YARNS)
def test_regauge_keeps_the_curve_its_crossings_and_the_cores_apart(stitch):
    """On the first shipped start (speeds from 0.5 to 8 × L/8 for seed): joints at equal
    fractions of the arclength, speeds L/8, offsets L/40; the curve within 0.07 mm of the
    start's (measured: 0.005 stockinette_free to 0.066 seed), the same crossings, the cores
    apart."""
    m0 = _model(stitch)
    x = m0.stitch.start(1)
    length = m0.energies(x).length
    m = _model(stitch, L=round(length, 9))
    y = m.gauged(x)
    assert np.all(y[list(SPEED_ENTRIES)] == m.ip.L / 8)
    assert np.allclose(y[list(OFFSET_ENTRIES)], m.ip.L / 40, rtol=1e-15)
    assert np.array_equal(y[-2:], x[-2:]) and np.array_equal(y[:4], x[:4])  # periods, joint 0
    assert _distance(_dense(m.control_points(x)), _dense(m.control_points(y))) < 0.07
    assert m.topology_change(y) == "" and m.min_zeta(y) > 0.03
    # the new joints sit at equal fractions of the old curve: the new curve's segments are
    # as long to the interpolation's error (measured: at most 4.6 % of L/8, seed's)
    lengths = [np.linalg.norm(np.diff(_dense(m.control_points(y)[s : s + 1], 4000), axis=0),
                              axis=1).sum() for s in range(8)]  # fmt: skip
    assert np.ptp(lengths) < 0.06 * length / 8


def test_gauged_keeps_a_gauged_state_and_its_round_off_copies():
    m = _model("rib")
    y = m.gauged(m.stitch.start(1))
    assert m.gauged(y) is y or np.array_equal(m.gauged(y), y)
    # another length: only the speeds change
    other = _model("rib", L=12.0).gauged(y)
    assert np.all(other[list(SPEED_ENTRIES)] == 12.0 / 8)
    rest = np.setdiff1d(np.arange(y.size), SPEED_ENTRIES)
    assert np.array_equal(other[rest], y[rest])
    # a copy perturbed by round-off (as [starts] spread makes) keeps its perturbation
    rng = np.random.default_rng(1)
    c = y * (1.0 + 1e-15 * rng.standard_normal(y.size))
    g = m.gauged(c)
    assert np.all(g[list(SPEED_ENTRIES)] == 11.6 / 8) and np.array_equal(g[rest], c[rest])


def test_only_a_free_yarn_sampled_along_itself_has_a_gauge():
    assert _model("rib").gauge.size == 16 and _model("stockinette_free").gauge.size == 16
    assert _model("rib", sampling="parameter").gauge.size == 0
    assert _model("rib", sampling="arclength").gauge.size == 0
    ansatz = _model("stockinette")
    x = ansatz.stitch.start(1)
    assert ansatz.gauge.size == 0 and ansatz.gauged(x) is x
    free = free_entries(ansatz.stitch, "x", ansatz.gauge)
    assert free.size == 29


def test_regauge_is_the_stitchs():
    m = _model("garter")
    x = m.stitch.start(1)
    assert np.array_equal(m.gauged(x), regauge(x, m.control_points(x), m.ip.L))


@pytest.mark.slow
def test_a_relaxation_holds_the_gauge_and_releasing_it_gains_nothing_that_matters():
    """Rib's zero-force state at 11.6 mm from its first start: every speed L/8 at the end;
    relaxed again with the speeds free, the energy falls by far less than the jamming
    threshold (5e-5 mJ; measured 3.9e-7 mJ)."""
    from knitsweep.config import StartSettings
    from knitsweep.presets import Numerics
    from knitsweep.relax.zero_force import zero_force

    n = Numerics.from_preset("converged")
    m = _model("rib")
    zero = zero_force(m.params, n.fidelity, n.solver, StartSettings(count=1), 0)
    x = zero.best.x
    assert zero.best.converged and np.all(x[list(SPEED_ENTRIES)] == 11.6 / 8)
    m.gauge = np.empty(0, dtype=np.int64)  # released
    r = Relaxer(n.solver).relax(m, x, None)
    assert r.converged
    assert 0.0 <= zero.best.total_energy - r.total_energy < 5e-6


def test_a_relaxation_stopped_with_overlapping_cores_is_not_knittable():
    """A minimiser that stopped short (not converged, not stationary) where the cores
    overlap has not been able to get them apart: not knittable, saying so; where they are
    apart the same stop is not converged."""
    m = _model("seed")
    x = m.gauged(m.stitch.start(1))
    squeezed = x.copy()
    squeezed[-2:] *= 0.6
    assert m.min_zeta(squeezed) < 0.0
    free = free_entries(m.stitch, None, m.gauge)
    settings = SolverSettings()
    r = assess(m, x, squeezed, free, False, "Iteration limit reached", 10, 10, settings, 0.0)
    assert r.status == NOT_KNITTABLE and r.message.startswith(CORES_OVERLAP)
    assert "where the minimiser stopped" in r.message and "Iteration limit" in r.message
    apart = assess(m, x, x, free, False, "Iteration limit reached", 10, 10, settings, 0.0)
    assert apart.status == NOT_CONVERGED


def test_the_joints_penalty_and_its_gradient():
    """The joints' penalty JOINT_STIFFNESS Σ (ℓ_s − ℓ/8)², summed by the pattern kernel: its
    gradient exact (central differences of the penalty alone: the gradient with the gauge
    less the gradient with it released), part of what the model's gradient holds but never
    of a reported energy."""
    from knitsweep.stitches.stockinette_free.gauge import JOINT_STIFFNESS

    m = _model("stockinette_free")
    x = m.gauged(m.stitch.start(2))
    energies, g, _ = m.energy_and_gradients(x)
    e = energies.gauge_energy
    assert 0.0 < e < JOINT_STIFFNESS * 8 * (0.1 * x[m.gauge[0]]) ** 2
    entries = m.gauge
    m.gauge = np.empty(0, dtype=np.int64)  # released: no penalty
    released, g0, _ = m.energy_and_gradients(x)
    assert released.gauge_energy == 0.0
    assert released.total_energy == energies.total_energy
    m.gauge = entries
    h = 1e-6
    for k in range(0, x.size, 5):
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        fd = (m.energies(xp).gauge_energy - m.energies(xm).gauge_energy) / (2 * h)
        assert g[k] - g0[k] == pytest.approx(fd, rel=1e-6, abs=1e-12)
    assert energies.total_energy == energies.bending_energy + energies.contact_energy
    plain = _model("stockinette_free", sampling="parameter")
    assert plain.energies(x).gauge_energy == 0.0
