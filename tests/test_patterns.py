"""Knit/purl patterns on the free yarn (docs/model.md §11): garter's start has garter's
crossing signs and keeps the cores apart; a mirrored stockinette stitch is refused,
naming where it overlaps; the overlap search agrees with the contact kernel's."""

import numpy as np
import pytest

from knitsweep.config import StitchParams
from knitsweep.errors import InputError
from knitsweep.model import CellModel
from knitsweep.stitches.patterns import (
    check_start,
    garter_crossings,
    garter_start,
    min_zeta_where,
)
from knitsweep.stitches.topology import crossings

P = StitchParams(L_mm=11.0, k_mN_per_mm2=0.1)
IP = P.internal()


@pytest.fixture(scope="module")
def model():
    return CellModel(P)


@pytest.mark.parametrize("i", [1, 2, 5])
def test_min_zeta_search_is_the_kernels(model, i):
    x = model.stitch.start(i)
    z, *_ = min_zeta_where(model.control_points(x), x[-2], x[-1], IP.r, IP.rc)
    assert z == pytest.approx(model.min_zeta(x), rel=1e-12)


@pytest.mark.parametrize("i", range(1, 8))
def test_garter_start_has_garter_crossings_and_no_overlap(model, i):
    x = model.stitch.start(i)
    cp = model.control_points(x)
    want = garter_crossings(crossings(cp, x[-2], x[-1]))
    assert want != crossings(cp, x[-2], x[-1])  # garter is not stockinette
    g, ax, ay = garter_start(cp, x[-2], x[-1])
    assert crossings(g, ax, ay, parity=(0, 1)) == want
    assert check_start(g, ax, ay, IP.r, IP.rc, (0, 1)) > 0.05


def test_a_mirrored_stockinette_stitch_is_refused_naming_where(model):
    x = model.stitch.start(1)
    with pytest.raises(InputError, match=r"garter start = overlapping yarn: .* image \(0, 1\)"):
        check_start(model.control_points(x), x[-2], x[-1], IP.r, IP.rc, (0, 1), "garter start")


def test_garter_start_is_still_g2(model):
    x = model.stitch.start(3)
    g, _, _ = garter_start(model.control_points(x), x[-2], x[-1])
    for s in range(8):
        a, b = g[s], g[(s + 1) % 8]
        t1 = (a[5] - a[4]) / np.linalg.norm(a[5] - a[4])
        t0 = (b[1] - b[0]) / np.linalg.norm(b[1] - b[0])
        np.testing.assert_allclose(t1, t0, atol=1e-12)


def test_garter_stitch_shipped_starts_and_exact_gradients():
    from knitsweep.stitches.garter.layout import from_free
    from knitsweep.stitches.stockinette_free.ansatz import to_free

    ma = CellModel(P)
    mg = CellModel(P.model_copy(update={"stitch": "garter"}))
    assert mg.stitch.n_state == 88 and mg.stitch.images == "glides"
    x = ma.stitch.start(2)
    g, ax, ay = garter_start(ma.control_points(x), x[-2], x[-1])
    xg = from_free(to_free(g, ax, ay), g[0, 0, 2])
    np.testing.assert_allclose(mg.stitch.start(2), xg, rtol=1e-15, atol=1e-15)
    # the yarn as built, translated in the fabric plane only (the mirror plane stays)
    np.testing.assert_allclose(mg.control_points(xg), g - [g[0, 0, 0], g[0, 0, 1], 0.0],
                               atol=1e-12)  # fmt: skip
    assert mg.min_zeta(xg) == pytest.approx(check_start(g, ax, ay, IP.r, IP.rc, (0, 1)), rel=1e-12)
    e, ge, gl = mg.energy_and_gradients(xg)
    h = 1e-6
    for k in (*range(0, 88, 7), 85, 86, 87):
        xp, xm = xg.copy(), xg.copy()
        xp[k] += h
        xm[k] -= h
        ep, em = mg.energies(xp), mg.energies(xm)
        fe = (ep.total_energy - em.total_energy) / (2 * h)
        fl = (ep.length - em.length) / (2 * h)
        assert fe == pytest.approx(ge[k], rel=1e-5, abs=1e-8), k
        assert fl == pytest.approx(gl[k], rel=1e-5, abs=1e-8), k
    # the mirrored rows carry contact: garter's energy is not stockinette's
    assert e.contact_energy > 0.0


def test_gauss_words_tell_garter_from_stockinette(model):
    from knitsweep.stitches.topology import gauss_word

    words, garter = set(), set()
    for i in range(1, 8):
        x = model.stitch.start(i)
        cp = model.control_points(x)
        words.add(gauss_word(cp, x[-2], x[-1]))
        garter.add(gauss_word(*garter_start(cp, x[-2], x[-1]), parity=(0, 1)))
    assert len(words) == 1 and len(garter) == 1 and words != garter
    (w,), (g,) = words, garter
    assert len(w) == len(g) == 8
    # the same counts of (n, sign): only the order along the yarn tells them apart
    assert sorted(w) == sorted(g)


def test_a_changed_topology_is_named():
    from knitsweep.stitches.garter.layout import from_free
    from knitsweep.stitches.stockinette_free.ansatz import to_free

    ma = CellModel(P)
    mg = CellModel(P.model_copy(update={"stitch": "garter"}))
    for i in (1, 4):
        assert mg.topology_change(mg.stitch.start(i)) == ""
    x = ma.stitch.start(1)
    cp = ma.control_points(x)
    # the stockinette stitch far above its mirror images: its rows no longer interlock
    xs = from_free(to_free(cp, x[-2], x[-1]), 3.0)
    why = mg.topology_change(xs)
    assert why.startswith("topology changed:") and "garter stitch has 8 crossings" in why
    assert ma.topology_change(x) == ""  # translations alone: not checked
