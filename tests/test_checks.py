"""The compiled checks after a pattern's relaxation (``kernels.checks``) find what their
numpy references find, bit for bit: the crossings in projection (with their positions
along the yarn and their heights, in the same order), the topology words built on them,
and the smallest ζ and where, on the shipped starts and relaxed states of every
pattern, perturbed, for every mirror parity, and on states whose topology changed."""

import warnings

import numpy as np
import pytest

from knitsweep.config import StitchParams
from knitsweep.model import CellModel
from knitsweep.stitches import topology as T
from knitsweep.stitches.patterns import PARITIES, min_zeta_where, min_zeta_where_reference

STITCHES = ("garter", "rib", "seed", "stockinette_free")
RELAXED = ("rib_relaxed_L11.6_k0.1.dat", "seed_relaxed_L11.6_k0.1.dat",
           "rib_under_resolved_L11.6_k0.1.dat")  # fmt: skip


def _states(name, data_dir):
    """(model, state) pairs: shipped starts 1, 4, 7, relaxed states, each as it is and
    perturbed (shape and periods), and with its rows pulled apart."""
    model = CellModel(StitchParams(stitch=name, L_mm=11.6, k_mN_per_mm2=0.1))
    base = [model.stitch.start(i) for i in (1, 4, 7)]
    if name in ("rib", "seed"):
        base += [np.loadtxt(data_dir / f) for f in RELAXED if f.startswith(name)]
    rng = np.random.default_rng(len(name))
    out = []
    for x in base:
        out.append(x)
        for scale in (0.01, 0.05):
            y = x.copy()
            y[:-2] += rng.normal(scale=scale, size=y.size - 2)
            y[-2:] *= 1.0 + rng.normal(scale=scale, size=2)
            out.append(y)
        apart = x.copy()
        apart[-1] *= 2.0
        out.append(apart)
    return model, out


def _gauss_word_reference(cp, a_x, a_y, parity):
    along: list = []
    T.crossings_reference(cp, a_x, a_y, parity=parity, along=along)
    return T.least_rotation([(n, s) for _, n, s in sorted(along)])


@pytest.mark.parametrize("name", STITCHES)
def test_compiled_crossings_are_the_numpy_ones(name, data_dir):
    model, states = _states(name, data_dir)
    found = 0
    for x in states:
        cp = model.control_points(x)
        for parity in PARITIES.values():
            for cp_, a_x, par in (
                (cp, x[-2], parity),
                T.row_period(cp, x[-2], parity),
            ):  # the cell, and a row's whole period as the words take it
                for adjacent in (False, True):
                    got, want = ([], []), ([], [])
                    c = T.crossings(cp_, a_x, x[-1], parity=par, heights=got[0], along=got[1],
                                    adjacent_only=adjacent)  # fmt: skip
                    r = T.crossings_reference(cp_, a_x, x[-1], parity=par, heights=want[0],
                                              along=want[1], adjacent_only=adjacent)  # fmt: skip
                    assert c == r and got == want
                    found += sum(c.values())
                    if adjacent:
                        full = T.crossings_reference(cp_, a_x, x[-1], parity=par)
                        assert c == {k: v for k, v in full.items() if abs(k[1]) == 1}
    assert found > 100 * len(states)


@pytest.mark.parametrize("name", STITCHES)
def test_topology_words_are_the_reference_ones(name, data_dir):
    """The words of the check, from the crossings with the rows beside alone, equal
    those from every crossing by the numpy search; a changed topology is still named."""
    model, states = _states(name, data_dir)
    changed = 0
    for x in states:
        cp = model.control_points(x)
        for parity in PARITIES.values():
            cp2, a_x2, par2 = T.row_period(cp, x[-2], parity)
            want = T.adjacent_rows(_gauss_word_reference(cp2, a_x2, x[-1], par2))
            assert T.fabric_word(cp, x[-2], x[-1], parity) == want
            cell = T.adjacent_rows(_gauss_word_reference(cp, x[-2], x[-1], parity))
            assert T.gauss_word(cp, x[-2], x[-1], parity, adjacent_only=True) == cell
            word = T.topology_word(cp, x[-2], x[-1], parity)
            assert word == (T.interlocking(cp, x[-2], x[-1], parity) if parity[0] else
                            tuple((n, (s,)) for n, s in cell))  # fmt: skip
        changed += model.topology_change(x) != ""
    if model.stitch.images == "glides":  # a pattern's relaxations are checked
        assert changed >= len(states) // 4  # at least the rows pulled apart


@pytest.mark.parametrize("name", STITCHES)
def test_compiled_min_zeta_is_the_numpy_one(name, data_dir):
    model, states = _states(name, data_dir)
    ip = model.ip
    overlapping = 0
    for x in states:
        cp = model.control_points(x)
        for parity in PARITIES.values():
            for r, rc, samples in ((ip.r, ip.rc, 10), (ip.r, ip.rc, 20), (1.3 * ip.r, ip.rc, 10)):
                got = min_zeta_where(cp, x[-2], x[-1], r, rc, parity, samples)
                assert got == min_zeta_where_reference(cp, x[-2], x[-1], r, rc, parity, samples)
                overlapping += got[0] < 1e-5
    assert overlapping > 0  # the mirrored stockinette stitches overlap


def test_non_finite_states_are_left_to_the_references():
    model = CellModel(StitchParams(stitch="rib"))
    x = model.stitch.start(1)
    cp = model.control_points(x)
    cp[2, 3, 0] = np.nan
    with warnings.catch_warnings():  # numpy warns of the NaN's cast to a grid cell
        warnings.simplefilter("ignore", RuntimeWarning)
        assert T.crossings(cp, x[-2], x[-1]) == T.crossings_reference(cp, x[-2], x[-1])
        got = min_zeta_where(cp, x[-2], x[-1], 0.5, 0.4)
        assert got == min_zeta_where_reference(cp, x[-2], x[-1], 0.5, 0.4)
