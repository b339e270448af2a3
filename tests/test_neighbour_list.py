"""Property tier: the optional Verlet list gives the search's sums, bit for bit.

``kernels.neighbours``: a list built with a skin covers every state whose samples
moved (and whose periods changed) by less than the skin allows; over it,
``contact_energy_listed`` must add exactly what ``contact_energy`` adds, and
outside it must say so and still return the exact energy (docs/model.md §6).
"""

import numpy as np
import pytest
from conftest import golden_cases, golden_params

from knitsweep.kernels.bezier import basis_tables, midpoints
from knitsweep.kernels.contact import IMAGES_CUTOFF, IMAGES_REFERENCE, contact_energy
from knitsweep.kernels.neighbours import build_neighbour_list, contact_energy_listed
from knitsweep.model import CellModel

CASES = golden_cases()
SKIN = 0.2  # mm


def _setup(case):
    p = case["params"]
    tab = np.ascontiguousarray(basis_tables(midpoints(p["N"]))[:2])
    return p, tab, CellModel(golden_params(case))


def _both(cp, tab, x, p, mode, nlist):
    g1, c1, g2, c2 = np.empty((8, 6, 3)), np.empty(2), np.empty((8, 6, 3)), np.empty(2)
    args = (x[28], x[29], p["r"], p["rc"], p["k"], p["p"], mode, True)
    e_search = contact_energy(cp, tab, *args, g1, c1)
    e_list, valid = contact_energy_listed(cp, tab, *args, g2, c2, *nlist)
    return (e_search, g1, c1), (e_list, g2, c2), valid


@pytest.mark.parametrize("mode", [IMAGES_CUTOFF, IMAGES_REFERENCE])
@pytest.mark.parametrize("case", CASES, ids=[c["name"] for c in CASES])
def test_list_sums_are_identical_while_valid(case, mode):
    p, tab, model = _setup(case)
    x0 = np.array(case["x"])
    nlist = build_neighbour_list(model.control_points(x0), tab, x0[28], x0[29], p["r"], mode,
                                 SKIN)  # fmt: skip
    rng = np.random.default_rng(7)
    n_valid = 0
    for scale in [0.0, 1e-5, 1e-4, 1e-3]:
        for _ in range(3):
            x = x0 * (1.0 + scale * rng.standard_normal(30))
            cp = model.control_points(x)
            (e1, g1, c1), (e2, g2, c2), valid = _both(cp, tab, x, p, mode, nlist)
            assert e2 == e1  # exact: the same numbers added in the same order
            np.testing.assert_array_equal(g2, g1)
            np.testing.assert_array_equal(c2, c1)
            n_valid += valid
    assert n_valid >= 6  # the small steps stay inside the skin


def test_list_is_invalidated_by_motion_and_by_the_periods():
    case = CASES[0]
    p, tab, model = _setup(case)
    x0 = np.array(case["x"])
    nlist = build_neighbour_list(model.control_points(x0), tab, x0[28], x0[29], p["r"],
                                 IMAGES_CUTOFF, SKIN)  # fmt: skip
    # shape moved: the list says so and the energy is still the search's
    x = x0.copy()
    x[3] += 0.3
    (e1, g1, _), (e2, g2, _), valid = _both(model.control_points(x), tab, x, p, IMAGES_CUTOFF,
                                            nlist)  # fmt: skip
    assert not valid
    assert e2 == e1
    np.testing.assert_array_equal(g2, g1)
    # a wale period change of 0.2 mm moves the |n| >= 1 images by >= 0.2 mm
    x = x0.copy()
    x[29] += SKIN
    cp = model.control_points(x)
    (e1, _, _), (e2, _, _), valid = _both(cp, tab, x, p, IMAGES_CUTOFF, nlist)
    assert not valid
    assert e2 == e1
    # a rebuilt list is valid again
    nlist = build_neighbour_list(cp, tab, x[28], x[29], p["r"], IMAGES_CUTOFF, SKIN)
    assert _both(cp, tab, x, p, IMAGES_CUTOFF, nlist)[2]


def test_list_holds_every_pair_a_skin_away():
    """Squeeze the cell so that rows four apart touch: those images are in the list."""
    case = CASES[0]
    p, tab, model = _setup(case)
    x = np.array(case["x"])
    x[29] = 0.55
    cp = model.control_points(x)
    nlist = build_neighbour_list(cp, tab, x[28], x[29], p["r"], IMAGES_CUTOFF, SKIN)
    assert np.abs(nlist[0][:, 4]).max() >= 4
    (e1, g1, _), (e2, g2, _), valid = _both(cp, tab, x, p, IMAGES_CUTOFF, nlist)
    assert valid and e2 == e1 > 0
    np.testing.assert_array_equal(g2, g1)


def test_cell_energy_with_a_list_is_cell_energy():
    from knitsweep.kernels.bezier import gauss_legendre
    from knitsweep.kernels.cell import cell_energy, cell_energy_listed
    from knitsweep.stitches.stockinette.layout import SEGMENT_WEIGHTS

    case = CASES[0]
    p, tab, model = _setup(case)
    gx, gw = gauss_legendre(32)
    qtab = basis_tables(gx)
    x0 = np.array(case["x"])
    nlist = build_neighbour_list(model.control_points(x0), tab, x0[28], x0[29], p["r"],
                                 IMAGES_CUTOFF, SKIN)  # fmt: skip
    rng = np.random.default_rng(11)
    for scale in [0.0, 1e-5, 1e-4]:
        x = x0 * (1.0 + scale * rng.standard_normal(30))
        cp, jac = model.control_points_and_jacobian(x)
        args = (cp, jac, x[28], x[29], qtab, gw, tab, SEGMENT_WEIGHTS, p["bend"], p["reg"],
                p["r"], p["rc"], p["k"], p["p"], IMAGES_CUTOFF, True)  # fmt: skip
        ge1, gl1, ge2, gl2 = np.empty(30), np.empty(30), np.empty(30), np.empty(30)
        want = cell_energy(*args, ge1, gl1)
        *got, valid = cell_energy_listed(*args, ge2, gl2, *nlist)
        assert valid
        assert tuple(got) == want
        np.testing.assert_array_equal(ge2, ge1)
        np.testing.assert_array_equal(gl2, gl1)


def test_model_with_a_neighbour_list_gives_the_same_numbers():
    """CellModel's listed path (used by every relaxation) equals the plain one bit for
    bit, and rebuilds its list when the state moves beyond the skin."""
    import numpy as np

    from knitsweep.config import StitchParams
    from knitsweep.formats import shipped_state
    from knitsweep.model import CellModel

    model = CellModel(StitchParams(L_mm=11.6, k_mN_per_mm2=0.1))
    x = shipped_state(1)
    nl = model.neighbour_list(x, skin=0.05)
    rng = np.random.default_rng(5)
    for scale in (1e-4, 1e-3, 3e-2):
        y = x * (1 + scale * rng.standard_normal(30))
        plain = model.energy_and_gradients(y)
        listed = model.energy_and_gradients(y, nl)
        assert plain[0] == listed[0]
        assert np.array_equal(plain[1], listed[1]) and np.array_equal(plain[2], listed[2])
    assert nl.rebuilds >= 2  # the 3 % move went beyond the 0.05 mm skin
