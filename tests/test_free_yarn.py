"""The free periodic yarn (docs/model.md §11): it holds the stockinette ansatz exactly,
its Jacobian is exact, and relaxing in it never raises the ansatz's energy."""

import numpy as np
import pytest

from knitsweep.config import Fidelity, StitchParams
from knitsweep.model import CellModel
from knitsweep.relax import Relaxer
from knitsweep.stitches import get_stitch
from knitsweep.stitches.stockinette_free import layout
from knitsweep.stitches.stockinette_free.ansatz import to_free
from knitsweep.stitches.topology import crossings, same_topology

P = StitchParams(L_mm=11.0, k_mN_per_mm2=0.1)
PF = P.model_copy(update={"stitch": "stockinette_free"})


@pytest.fixture(scope="module")
def models():
    """The ansatz, and the free yarn with its contact samples where the ansatz has them
    (by parameter), so that the map between them is exact."""
    return CellModel(P), CellModel(PF, Fidelity(contact_sampling="parameter"))


@pytest.mark.parametrize("i", range(1, 8))
def test_ansatz_states_have_the_same_energies_in_the_free_yarn(models, i):
    ma, mf = models
    x = ma.stitch.start(i)
    xf = to_free(ma.control_points(x), x[-2], x[-1])
    np.testing.assert_allclose(mf.control_points(xf), ma.control_points(x) - ma.control_points(x)[0, 0],
                               rtol=0, atol=1e-12)  # fmt: skip
    ea, ef = ma.energies(x), mf.energies(xf)
    for a, b in ((ea.bending_energy, ef.bending_energy), (ea.contact_energy, ef.contact_energy),
                 (ea.length, ef.length)):  # fmt: skip
        assert abs(a - b) <= 1e-12 * max(abs(a), 1.0)
    # the shipped free starts are exactly these maps
    np.testing.assert_allclose(mf.stitch.start(i), xf, rtol=1e-15, atol=1e-15)
    # by default (samples along the yarn) the bending energy and length are the same
    ed = CellModel(PF).energies(xf)
    assert abs(ed.bending_energy - ea.bending_energy) <= 1e-12 * ea.bending_energy
    assert abs(ed.length - ea.length) <= 1e-12 * ea.length


def test_free_layout():
    s = get_stitch("stockinette_free")
    assert s.n_state == layout.N_STATE == 87 and s.state_names[-2:] == ("a_x", "a_y")
    assert s.twist_index is None and np.all(s.segment_weights == 1.0)
    lo, hi = s.bounds(11.0, 0.74)
    x = s.start(1)
    assert np.all(lo <= x) and np.all(x <= hi)


def test_free_jacobian_matches_central_differences(models):
    _, mf = models
    rng = np.random.default_rng(3)
    x = mf.stitch.start(2) + rng.normal(0.0, 1e-2, layout.N_STATE)
    _, jac = mf.control_points_and_jacobian(x)
    h = 1e-6
    fd = np.empty_like(jac)
    for k in range(layout.N_STATE):
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        fd[..., k] = (mf.control_points(xp) - mf.control_points(xm)) / (2 * h)
    assert np.abs(jac - fd).max() < 1e-8 * max(1.0, np.abs(jac).max())


def test_free_gradients_match_central_differences(models):
    _, mf = models
    x = mf.stitch.start(1)
    _, ge, gl = mf.energy_and_gradients(x)
    h = 1e-6
    for k in range(0, layout.N_STATE, 3):
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        ep, em = mf.energies(xp), mf.energies(xm)
        fe = (ep.total_energy - em.total_energy) / (2 * h)
        fl = (ep.length - em.length) / (2 * h)
        assert abs(fe - ge[k]) <= 1e-6 * max(1.0, abs(ge[k])), k
        assert abs(fl - gl[k]) <= 1e-6 * max(1.0, abs(gl[k])), k


def test_every_joint_is_g2(models):
    """Tangent and curvature vector agree on both sides of every joint, for any state."""
    _, mf = models
    rng = np.random.default_rng(7)
    x = mf.stitch.start(3) + rng.normal(0.0, 5e-2, layout.N_STATE)
    cp = mf.control_points(x)

    def frame(q, end):
        d1 = 5 * (q[5] - q[4]) if end else 5 * (q[1] - q[0])
        d2 = 20 * (q[5] - 2 * q[4] + q[3]) if end else 20 * (q[2] - 2 * q[1] + q[0])
        t = d1 / np.linalg.norm(d1)
        return t, (d2 - (d2 @ t) * t) / (d1 @ d1)

    for s in range(8):
        t1, c1 = frame(cp[s], True)
        t0, c0 = frame(cp[(s + 1) % 8], False)
        np.testing.assert_allclose(t1, t0, atol=1e-12)
        np.testing.assert_allclose(c1, c0, atol=1e-10)
    np.testing.assert_allclose(cp[7, 5], cp[0, 0] + [x[-2], 0, 0], atol=1e-12)


@pytest.mark.slow
def test_relaxing_the_ansatz_minimum_in_the_free_yarn_lowers_the_energy(models):
    ma, mf = models
    ra = Relaxer().relax(ma, ma.stitch.start(1))
    assert ra.converged
    xf = to_free(ma.control_points(ra.x), ra.x[-2], ra.x[-1])
    rf = Relaxer().relax(mf, xf)
    assert rf.total_energy <= ra.total_energy + 1e-12
    assert abs(rf.length - P.L_mm) < 1e-6 and rf.min_zeta > 1e-5
    before = crossings(ma.control_points(ra.x), ra.x[-2], ra.x[-1])
    assert same_topology(before, crossings(mf.control_points(rf.x), rf.x[-2], rf.x[-1]))[0]


def test_crossing_signs_tell_a_fabric_from_its_mirror_image(models):
    ma, _ = models
    x = ma.stitch.start(1)
    cp = ma.control_points(x)
    ref = crossings(cp, x[-2], x[-1])
    assert sum(ref.values()) == 8  # 4 crossings per stitch, each seen from both stitches
    for i in range(2, 8):
        y = ma.stitch.start(i)
        assert same_topology(ref, crossings(ma.control_points(y), y[-2], y[-1]))[0]
    flipped = cp.copy()
    flipped[..., 2] *= -1.0  # over and under exchanged at every crossing
    same, why = same_topology(ref, crossings(flipped, x[-2], x[-1]))
    assert not same and "lost" in why and "gained" in why


def _key(h):
    return h[:3]


def test_garter_crossings_seen_with_mirrored_rows(models):
    """With the odd rows mirrored (garter's images), stockinette's shape keeps the
    crossing heights and only mirrors the partners: every row-to-row crossing reads
    the partner's z with its sign flipped (docs/model.md §11)."""
    ma, _ = models
    x = ma.stitch.start(1)
    cp = ma.control_points(x)
    plain, mirrored = [], []
    crossings(cp, x[-2], x[-1], heights=plain)
    crossings(cp, x[-2], x[-1], parity=(0, 1), heights=mirrored)
    assert len(plain) == len(mirrored) == 8
    for (m, n, za, zb), (m2, n2, za2, zb2) in zip(
        sorted(plain, key=_key), sorted(mirrored, key=_key), strict=True
    ):
        assert (m, n) == (m2, n2) and za == za2
        assert zb2 == (-zb if n % 2 else zb)
