"""The seed stitch (docs/model.md §11, "The seed stitch"): its starts have seed's
crossing signs in order with the cores apart, it closes G2 into its mirror image, its
words differ from rib's and garter's, and it relaxes keeping its crossings."""

import numpy as np
import pytest

from knitsweep.config import StitchParams
from knitsweep.errors import InputError
from knitsweep.model import CellModel
from knitsweep.stitches.patterns import PARITIES, check_start, pattern_crossings
from knitsweep.stitches.topology import crossings

P = StitchParams(L_mm=11.0, k_mN_per_mm2=0.1)
IP = P.internal()


@pytest.fixture(scope="module")
def model():
    return CellModel(P)


def _ordered(cp, a_x, a_y, parity):
    """Crossings met along the cell's yarn, in order, as (m, n, sign)."""
    from knitsweep.stitches.topology import crossings as cross

    heights, along = [], []
    cross(cp, a_x, a_y, parity=parity, heights=heights, along=along)
    # ``heights`` and ``along`` are filled in the same order, one entry per crossing
    return [(h[0], a[1], a[2]) for a, h in sorted(zip(along, heights, strict=True))]


def _cyclic_equal(a, b):
    return len(a) == len(b) and any(a[k:] + a[:k] == b for k in range(max(len(a), 1)))


@pytest.mark.parametrize("i", range(1, 8))
def test_seed_start_has_seed_crossings_in_order_and_no_overlap(model, i):
    """The stockinette yarn cut at mid-sinker and tilted (``seed_start``): every crossing
    has the sign that the stitch pulled through it gives in seed (``pattern_crossings``:
    the purl stitches above flip theirs), in stockinette's order along the yarn, and the
    cores are apart; the shipped start is that state to round-off."""
    from knitsweep.stitches.seed.start import recut, seed_start
    from knitsweep.stitches.topology import gauss_word

    x = model.stitch.start(i)
    cp = model.control_points(x)
    seed = CellModel(P.model_copy(update={"stitch": "seed"}))
    xs = seed_start(cp, x[-2], x[-1])
    np.testing.assert_allclose(xs, seed.stitch.start(i), rtol=0, atol=1e-13)
    stock = recut(cp, x[-2])  # the same yarn, from the middle of its sinker loop
    assert gauss_word(stock, x[-2], x[-1]) == gauss_word(cp, x[-2], x[-1])  # the same yarn
    want = pattern_crossings(crossings(stock, x[-2], x[-1]), PARITIES["seed"])
    cs = seed.control_points(xs)
    assert crossings(cs, xs[-2], xs[-1], parity=PARITIES["seed"]) == want
    # the order too (the counts alone cannot tell: seed flips two + and two - above)
    order = _ordered(stock, x[-2], x[-1], (0, 0))
    assert all(m == 0 and abs(n) == 1 for m, n, _ in order)  # each stitch's own column
    flipped = [(m, n, -s if n > 0 else s) for m, n, s in order]  # the purl stitch above
    assert flipped != order
    assert _cyclic_equal(_ordered(cs, xs[-2], xs[-1], PARITIES["seed"]), flipped)
    assert gauss_word(cs, xs[-2], xs[-1], PARITIES["seed"]) != gauss_word(stock, x[-2], x[-1])
    assert check_start(cs, xs[-2], xs[-1], IP.r, IP.rc, PARITIES["seed"]) > 0.1
    assert 15.1 < seed.energies(xs).length < 15.25  # longer than L: walked down (§7)
    assert seed.topology_change(xs) == ""


def test_seed_closes_g2_into_its_mirror_image():
    """Seed uses rib's geometry: joint 0 on the mirror plane, the last segment ending at
    t_c with joint 0's tangent and curvature vector mirrored; G2 at every joint."""
    seed = CellModel(P.model_copy(update={"stitch": "seed"}))
    assert seed.stitch.geometry_module == "knitsweep.stitches.rib.geometry"
    assert seed.stitch.mirror_parity == (1, 1) and seed.stitch.images == "glides"
    x = seed.stitch.start(3)
    cp = seed.control_points(x)
    np.testing.assert_allclose(cp[0, 0], 0.0, atol=0)
    np.testing.assert_allclose(cp[7, 5], [x[-2], 0.0, 0.0], atol=1e-15)
    mirror = np.array([1.0, 1.0, -1.0])

    def frame(seg, end):
        """(tangent, curvature vector) of segment ``seg`` at its start or end."""
        c = cp[seg][::-1] if end else cp[seg]
        d1 = c[1] - c[0]
        t = d1 / np.linalg.norm(d1) * (-1 if end else 1)
        a = 5 * np.linalg.norm(d1)
        k = 20 * (c[2] - 2 * c[1] + c[0]) / a**2
        return t, k - (k @ t) * t

    for s in range(7):  # joints 1..7: the same point, tangent, curvature vector
        np.testing.assert_allclose(cp[s, 5], cp[s + 1, 0], atol=1e-14)
        for a, b in zip(frame(s, True), frame(s + 1, False), strict=True):
            np.testing.assert_allclose(a, b, atol=1e-11)
    for a, b in zip(frame(7, True), frame(0, False), strict=True):  # into the purl stitch
        np.testing.assert_allclose(a, b * mirror, atol=1e-11)


def test_unknown_stitches_are_refused_listing_seed():
    from knitsweep.stitches import STITCH_NAMES, check_stitch_name, get_stitch

    assert "seed" in STITCH_NAMES and get_stitch("seed").name == "seed"
    with pytest.raises(InputError, match=r"must be one of .*rib, seed"):
        check_stitch_name("moss")


def test_seed_words_differ_from_rib_and_garter():
    """Over a row period (two stitches) seed's crossing order is neither rib's nor
    garter's (whose row period is its one stitch twice). One seed stitch alone meets its
    crossings in garter's order (each is a knit stitch pulled through the purl one below,
    with a purl one pulled through it above); what differs is the purl stitch beside it.
    The rows' interlocking runs (n, sorted signs), which a relaxation of seed or rib must
    keep, are rib's: the order within the runs tells the two apart."""
    from knitsweep.stitches.topology import fabric_word, gauss_word, interlocking, least_rotation

    def cell(name):
        m = CellModel(P.model_copy(update={"stitch": name}))
        x = m.stitch.start(1)
        return m.control_points(x), x[-2], x[-1], PARITIES[name]

    seed, rib, (cg, gx, gy, gp) = cell("seed"), cell("rib"), cell("garter")
    two = np.concatenate([cg, cg + np.array([gx, 0.0, 0.0])])  # garter's row, two stitches
    garter_row = least_rotation([c for c in gauss_word(two, 2 * gx, gy, gp) if c[0] != 0])
    assert len(fabric_word(*seed)) == len(garter_row) == len(fabric_word(*rib)) == 16
    assert fabric_word(*seed) != fabric_word(*rib)
    assert fabric_word(*seed) != garter_row
    assert gauss_word(*seed) == gauss_word(cg, gx, gy, gp)  # one stitch: garter's order
    assert gauss_word(*seed) != gauss_word(*rib)
    assert interlocking(*seed) == interlocking(*rib)  # the runs' signs sorted: the same
    assert [n for n, _ in interlocking(*seed)] in ([-1, 1, -1, 1], [1, -1, 1, -1])


def test_a_relaxed_seed_keeps_its_crossings(data_dir):
    """Seed relaxed at L = 11.6 mm, k = 0.1 (``knitsweep relax --stitch seed``, one
    start): the yarn keeps every crossing of the start in its order (even the full
    Gauss word), the cores apart; rows pulled apart are named."""
    from knitsweep.stitches.topology import fabric_word, gauss_word

    seed = CellModel(StitchParams(stitch="seed", L_mm=11.6, k_mN_per_mm2=0.1))
    x = np.loadtxt(data_dir / "seed_relaxed_L11.6_k0.1.dat")
    x0 = seed.stitch.start(1)
    c, c0 = seed.control_points(x), seed.control_points(x0)
    assert seed.topology_change(x) == ""
    for word in (gauss_word, fabric_word):
        assert word(c, x[-2], x[-1], (1, 1)) == word(c0, x0[-2], x0[-1], (1, 1))
    assert seed.min_zeta(x) > 0.0
    assert seed.energies(x).length == pytest.approx(11.6, abs=1e-8)
    flat = x.copy()
    flat[-1] *= 2.0
    why = seed.topology_change(flat)
    assert why.startswith("topology changed:") and "seed stitch has 16 crossings" in why


@pytest.mark.slow
def test_seed_relaxes_with_its_topology():
    """The zero-force state of seed from its first start (measured: 40 CPU s,
    E = 0.35812 mJ, a_x = 2.7217, a_y = 1.6587 mm): converged, topology kept, shorter
    along the wale than stockinette (a_y 2.1941 mm) and about as wide (a_x 2.8493 mm)."""
    from knitsweep.config import SolverSettings, StartSettings
    from knitsweep.relax.zero_force import zero_force

    p = StitchParams(stitch="seed", L_mm=11.6, k_mN_per_mm2=0.1)
    zf = zero_force(p, None, SolverSettings(), StartSettings(count=1))
    best = zf.best
    assert best.converged, best.message
    assert 2.5 < best.x[-2] < 2.9 and 1.5 < best.x[-1] < 1.8
    assert best.min_zeta > 0.0
    assert CellModel(p).topology_change(best.x) == ""
