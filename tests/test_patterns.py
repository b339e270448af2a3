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
