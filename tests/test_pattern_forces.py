"""Property tier: pair forces by class over a pattern's mirrored images (garter, rib,
seed; kernels.mirrored.mirrored_pair_forces_by_class, docs/model.md §9, §11) against
their rule on pairs found by brute force over images built from the pattern's
definition, and, weighted, against central differences of the class energies with the
images moving and the yarn held (the virial of the image shifts), as tests/test_forces.py
checks stockinette's."""

import numpy as np
import pytest

from knitsweep.config import Fidelity, StitchParams
from knitsweep.kernels.arclength import yarn_sample_cell
from knitsweep.kernels.contact import EXCLUSION_FACTOR, pair_potential, sample_cell
from knitsweep.kernels.mirrored import MIRROR_CLASSES, N_MIRROR_CLASSES, mirrored_contact_energy
from knitsweep.model import CellModel

H = 1e-6
PATTERNS = ("garter", "rib", "seed")


@pytest.fixture(
    scope="module",
    params=[(p, s) for p in PATTERNS for s in ("auto", "parameter")],
    ids=lambda v: f"{v[0]}-{v[1]}",
)
def pattern(request):
    """A pattern's model, with its contact samples along the yarn (the default) or by
    parameter, and its first start (in the model's gauge)."""
    stitch, sampling = request.param
    model = CellModel(StitchParams(stitch=stitch, L_mm=11.6, k_mN_per_mm2=0.1),
                      Fidelity(contact_sampling=sampling))  # fmt: skip
    return model, model.gauged(model.stitch.start(1))


def _contacts(model, x, weighted):
    """Every counted contact by brute force, each unordered pair once: the cell's samples
    against those of each image (m, n) of half the lattice (n > 0, or n = 0 and m >= 0),
    mirrored (z -> -z) when pm m + pn n is odd. Returns (class (c,), offsets (c, 2), each
    contact's share of the pair forces (c, 3): along an offset axis 2 f (-d_a)
    sign(offset), else F_a (sign(a_i) - sign(a_j')), a_j' the partner's coordinate in its
    own (mirrored) cell)."""
    ip, tab = model.ip, model._ctab
    if model.sampling == "yarn_arclength":  # evenly along the yarn (kernels.arclength)
        pts, _, _, speed, s_mid, s_tot, _ = yarn_sample_cell(
            model.control_points(x), tab.shape[1], model._aq
        )
    else:
        pts, _, _, speed, s_mid, s_tot = sample_cell(model.control_points(x), tab)
    pm, pn = model.stitch.mirror_parity
    ns, dt2 = len(pts), 1.0 / tab.shape[1] ** 2
    classes, offsets, shares = [], [], []
    for m in range(-3, 4):
        for n in range(4):
            if n == 0 and m < 0:
                continue
            mirrored = (pm * m + pn * n) % 2 == 1
            own = pts * [1.0, 1.0, -1.0 if mirrored else 1.0]  # the partners in their cell
            d = pts[:, None] - own[None] - [m * x[-2], n * x[-1], 0.0]
            dist = np.linalg.norm(d, axis=2)
            hit = dist < 2.0 * ip.r
            if (m, n) == (0, 0):
                hit &= np.triu(np.ones((ns, ns), dtype=bool), 1)
            if n == 0:
                hit &= np.abs(s_mid[:, None] - s_mid[None] - m * s_tot) > EXCLUSION_FACTOR * ip.r
            i, j = np.nonzero(hit)
            dv = np.array([pair_potential(v, ip.r, ip.rc, ip.k, ip.p)[1] for v in dist[i, j]])
            f = -dv / dist[i, j]
            if weighted:
                f = f * speed[i] * speed[j] * dt2
            force = f[:, None] * d[i, j]
            offset = np.array([m, n, 0])
            apart = -2.0 * np.sign(offset) * force
            outward = force * (np.sign(pts[i]) - np.sign(own[j]))
            shares.append(np.where(offset != 0, apart, outward))
            cls = 0 if (m, n) == (0, 0) else 3 if mirrored else 1 if n == 0 else 2 if m == 0 else 4
            classes.append(np.full(len(i), cls))
            offsets.append(np.tile([m, n], (len(i), 1)))
    return np.concatenate(classes), np.concatenate(offsets), np.concatenate(shares)


@pytest.mark.parametrize("weighted", [False, True])
def test_pattern_pair_forces_follow_their_rule(pattern, weighted):
    model, x = pattern
    got = model.contact_pair_forces_by_class(x, weighted=weighted)
    classes, _, shares = _contacts(model, x, weighted)
    want = np.zeros((N_MIRROR_CLASSES, 3))
    np.add.at(want, classes, shares)
    assert want[MIRROR_CLASSES.index("mirrored")].any()  # the mirrored images touch
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-13 * np.abs(want).max())
    # summed over the classes: every contact's share once
    np.testing.assert_allclose(got.sum(axis=0), shares.sum(axis=0), rtol=1e-12,
                               atol=1e-13 * np.abs(want).max())  # fmt: skip


def test_weighted_pattern_pair_forces_are_the_image_shift_derivative(pattern):
    """Weighted by ds ds', the pair forces along an offset axis are the virial of the
    image shifts: a contact with the image (m, n) adds -∂E/∂a_x / |m| (and -∂E/∂a_y / |n|)
    with the yarn held and only the images moving. So for each class and axis the offset
    contacts' shares times their |offset| add up to -∂E_c(class)/∂a by central
    differences; where every offset contact of a class sits at one |offset| (and no
    other contact of the class adds along that axis) that is the kernel's pair force
    itself times |offset|; and summed over the classes, -∂E_c/∂a of the whole contact
    energy."""
    model, x = pattern
    ip, tab = model.ip, model._ctab
    cp = model.control_points(x)
    pm, pn = model.stitch.mirror_parity
    got = model.contact_pair_forces_by_class(x, weighted=True)
    classes, offsets, shares = _contacts(model, x, True)

    def energies(ax, ay):
        ce = np.zeros(N_MIRROR_CLASSES)
        e = mirrored_contact_energy(cp, tab, model._aq, ax, ay, 0.0, ip.r, ip.rc, ip.k, ip.p, pm, pn, -1, False,
                                    np.zeros_like(cp), np.zeros(2), ce)  # fmt: skip
        return np.append(ce, e)  # the five classes and E_c

    direct = 0
    for col, step in ((0, (H, 0.0)), (1, (0.0, H))):
        fd = -(energies(x[-2] + step[0], x[-1] + step[1])
               - energies(x[-2] - step[0], x[-1] - step[1])) / (2 * H)  # fmt: skip
        offset = np.abs(offsets[:, col])
        virial = np.zeros(N_MIRROR_CLASSES)
        np.add.at(virial, classes, np.where(offset > 0, shares[:, col] * offset, 0.0))
        scale = np.abs(fd).max()
        assert scale > 0.0
        np.testing.assert_allclose(virial, fd[:-1], rtol=1e-6, atol=1e-7 * scale)
        # the class sums are E_c's to round-off, which the differences amplify by 1/H
        assert fd[:-1].sum() == pytest.approx(fd[-1], rel=1e-9, abs=1e-8 * scale)
        for c in range(N_MIRROR_CLASSES):
            mine = classes == c
            ks = set(offset[mine])
            if len(ks) == 1 and 0 not in ks:  # one |offset|, nothing along the mid-plane
                k = ks.pop()
                assert got[c, col] * k == pytest.approx(fd[c], rel=1e-6), (c, col)
                direct += 1
    assert direct > 0


def test_a_patterns_table_columns_are_its_pair_forces_by_class(pattern):
    """The post-processor's ``pair_F_<class>_<axis>_N`` of a pattern's point are its pair
    forces by its own classes (mirrored images included); Fig. 6h's sums, defined on the
    paper's classes, stay empty."""
    from knitsweep.report.force_columns import FIG6H_KEYS, pair_force_columns, pair_keys

    model, x = pattern
    meta = model.params.model_dump()
    row = pair_force_columns(x, meta, model.fidelity)
    assert tuple(row) == pair_keys(MIRROR_CLASSES)
    f = model.contact_pair_forces_by_class(x)
    got = np.array([[row[f"pair_F_{c}_{a}_N"] for a in "xyz"] for c in MIRROR_CLASSES])
    assert np.array_equal(got, f)
    assert np.any(got[MIRROR_CLASSES.index("mirrored")] != 0.0)
    assert all(row[k] is None for k in FIG6H_KEYS)
    assert all(v is None for v in pair_force_columns(None, meta, model.fidelity).values())
