"""Property tier: the culled contact search finds exactly the pairs of a plain loop.

``find_contacts``/``contact_energy`` skip images, segment pairs and samples by
bounding boxes (``kernels.partition``); a brute-force numpy enumeration of every
sample pair in the same images must give the same contacts, in the same order,
and the same energy (docs/model.md §6).
"""

import numpy as np
import pytest
from conftest import golden_cases, golden_params

from knitsweep.kernels.bending import bending_and_length
from knitsweep.kernels.bezier import basis_tables, gauss_legendre, midpoints
from knitsweep.kernels.contact import (
    EXCLUSION_FACTOR,
    IMAGES_CUTOFF,
    IMAGES_REFERENCE,
    contact_energy,
    find_contacts,
    image_list,
    midpoint_arclength,
    pair_potential,
    sample_path,
)
from knitsweep.model import CellModel
from knitsweep.stitches.stockinette.layout import SEGMENT_WEIGHTS

CASES = golden_cases()


def _brute_force(cp, tab, ax, ay, r, mode):
    """Every counted contact as (i, j, m, n) rows, in (image, i, j) order."""
    nseg, n = cp.shape[0], tab.shape[1]
    ns = nseg * n
    pts, r1, speed, s = np.empty((ns, 3)), np.empty((ns, 3)), np.empty(ns), np.empty(ns)
    sample_path(cp, tab, pts, r1, speed)
    s_tot = midpoint_arclength(speed, 1.0 / n, s)
    rows = []
    images = [(0, 0)] + [tuple(mn) for mn in image_list(pts, ax, ay, r, mode)]
    for m, nn in images:
        d = pts[:, None, :] - pts[None, :, :] - np.array([m * ax, nn * ay, 0.0])
        rr = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2]
        ok = rr < (2.0 * r) ** 2
        if nn == 0:
            ok &= ~(np.abs(s[:, None] - s[None, :] - m * s_tot) <= EXCLUSION_FACTOR * r)
        if (m, nn) == (0, 0):
            ok &= np.arange(ns)[:, None] < np.arange(ns)[None, :]
        for i, j in zip(*np.nonzero(ok), strict=True):
            rows.append((i, j, m, nn))
    return np.array(rows, dtype=np.int64).reshape(-1, 4), speed, pts


def _states():
    """Golden states, and Init_1's squeezed and stretched so that other images touch."""
    for case in CASES:
        yield case, np.array(case["x"])
    x = np.array(CASES[0]["x"])
    for fx, fy in [(1.0, 0.35), (0.7, 1.0), (0.8, 0.6), (1.5, 1.5)]:
        y = x.copy()
        y[28] *= fx
        y[29] *= fy
        yield CASES[0], y


@pytest.mark.parametrize("mode", [IMAGES_CUTOFF, IMAGES_REFERENCE])
def test_culled_search_equals_brute_force(mode):
    for case, x in _states():
        p = case["params"]
        tab = np.ascontiguousarray(basis_tables(midpoints(p["N"]))[:2])
        cp = CellModel(golden_params(case)).control_points(x)
        ax, ay = x[28], x[29]
        want, speed, pts = _brute_force(cp, tab, ax, ay, p["r"], mode)
        _, _, _, idx, sep = find_contacts(cp, tab, ax, ay, p["r"], mode)
        # same set; and within each image the same (segment pair, i, j) order
        assert {tuple(row) for row in idx} == {tuple(row) for row in want}
        assert len(idx) == len(want)
        d = (
            pts[idx[:, 0]]
            - pts[idx[:, 1]]
            - np.column_stack([idx[:, 2] * ax, idx[:, 3] * ay, np.zeros(len(idx))])
        )
        np.testing.assert_array_equal(sep[:, :3], d)
        rr = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
        np.testing.assert_array_equal(sep[:, 3], np.sqrt(rr))
        # the energy is the brute-force sum over the same pairs
        n = p["N"]
        e = 0.0
        for (i, j, _, _), dist in zip(want, np.linalg.norm(
            pts[want[:, 0]] - pts[want[:, 1]]
            - np.column_stack([want[:, 2] * ax, want[:, 3] * ay, np.zeros(len(want))]),
            axis=1,
        ), strict=True):  # fmt: skip
            v, _ = pair_potential(dist, p["r"], p["rc"], p["k"], p["p"])
            e += 2.0 * v * speed[i] * speed[j] / n**2
        g, gc = np.empty((8, 6, 3)), np.empty(2)
        got = contact_energy(cp, tab, ax, ay, p["r"], p["rc"], p["k"], p["p"], mode, False, g, gc)
        assert got == pytest.approx(e, rel=1e-12, abs=0)


def test_contacts_come_out_in_loop_order():
    """(image, segment a, segment b, i, j): i non-decreasing within a segment pair."""
    case = CASES[0]
    x = np.array(case["x"])
    tab = np.ascontiguousarray(basis_tables(midpoints(10))[:2])
    cp = CellModel(golden_params(case)).control_points(x)
    _, _, _, idx, _ = find_contacts(cp, tab, x[28], x[29], 0.74, IMAGES_REFERENCE)
    images = [(0, 0)] + [tuple(mn) for mn in image_list(cp.reshape(-1, 3), x[28], x[29], 0.74,
                                                          IMAGES_REFERENCE)]  # fmt: skip
    rank = {mn: k for k, mn in enumerate(images)}
    key = [(rank[(m, n)], i // 10, j // 10, i, j) for i, j, m, n in idx]
    assert key == sorted(key)


def test_degenerate_segment_still_raises():
    """A segment with r' = 0 at a node raises ZeroDivisionError, as the scalar
    kernel did, instead of returning nan."""
    gx, gw = gauss_legendre(32)
    g1, g2 = np.empty((8, 6, 3)), np.empty((8, 6, 3))
    with pytest.raises(ZeroDivisionError):
        bending_and_length(np.zeros((8, 6, 3)), SEGMENT_WEIGHTS, basis_tables(gx), gw, 0.045,
                           0.002, g1, g2)  # fmt: skip
