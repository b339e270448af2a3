"""Property tier: contact forces and energies by class (kernels.forces) against
finite differences, and the force balance on the cell periods (docs/model.md §9); the
pair forces against their rule, the virial of the image shifts, and paper Table S3."""

import json

import numpy as np
import pytest

from knitsweep.analysis.paper import TABLE_S3, ratio_crossing, table_s3_crossing_mm
from knitsweep.config import Fidelity, SolverSettings, StartSettings, StitchParams
from knitsweep.kernels.contact import find_contacts, pair_potential
from knitsweep.kernels.forces import contact_class, contact_forces_by_class
from knitsweep.model import CellModel
from knitsweep.relax import relax
from knitsweep.relax.zero_force import zero_force
from knitsweep.report.force_columns import fig6h_forces
from knitsweep.stitches import TRANSLATION_CLASSES as CONTACT_CLASSES
from knitsweep.stitches.stockinette.layout import IDX_AX, IDX_AY

H = 1e-6
PARAMS = StitchParams(L_mm=10.8, k_mN_per_mm2=0.6)  # jammed: every class in contact
FIDELITY = Fidelity()


@pytest.fixture(scope="module")
def rest():
    zf = zero_force(PARAMS, FIDELITY, SolverSettings(), StartSettings(count=1))
    assert zf.best.converged
    return zf.best


@pytest.fixture(scope="module")
def pulled(rest):
    """A strain step: a_x fixed 2 % beyond rest, everything else relaxed."""
    x0 = rest.x.copy()
    x0[IDX_AX] *= 1.02
    r = relax(CellModel(PARAMS, FIDELITY), x0, "x", SolverSettings())
    assert r.converged
    return r


def _class_energies(model, x):
    return model.contacts_by_class(x)[1]


def test_class_energies_add_up_to_the_contact_energy(rest):
    model = CellModel(PARAMS, FIDELITY)
    forces, energies = model.contacts_by_class(rest.x)
    assert forces.shape == (len(CONTACT_CLASSES), 3)
    np.testing.assert_allclose(energies.sum(), model.energies(rest.x).contact_energy, rtol=1e-13)
    # self, same row, NN and NNN same column all touch in a jammed stitch
    assert np.all(energies[:4] > 0.0)


def _assert_minus_derivative(force, energy_at, scale):
    """``force`` (per class) is minus the derivative of ``energy_at(h)`` at h = 0: by
    central differences, or, where the energy steps within H of the state (a pair
    crossing the same-row exclusion boundary, docs/model.md §6; a relaxed state can
    sit at such a step), by the difference on the side without the step, the other
    side's then growing as 1/H."""
    e0, ep, em = energy_at(0.0), energy_at(H), energy_at(-H)
    central = -(ep - em) / (2 * H)
    kink = np.abs(force - central) > 1e-6 * scale
    if not kink.any():
        return
    forward, backward = -(ep - e0) / H, -(e0 - em) / H
    tenth_fwd = -(energy_at(H / 10) - e0) / (H / 10)
    tenth_bwd = -(e0 - energy_at(-H / 10)) / (H / 10)
    for c in np.flatnonzero(kink):
        sides = ((forward[c], tenth_fwd[c]), (backward[c], tenth_bwd[c]))
        smooth = [abs(f - force[c]) <= 3e-5 * scale for f, _ in sides]  # (error H E''/2)
        assert any(smooth), (c, force[c], forward[c], backward[c])
        if not all(smooth):  # the stepped side's error grows as 1/H
            stepped, stepped_tenth = sides[smooth.index(False)]
            assert abs(stepped_tenth - force[c]) > 5 * abs(stepped - force[c]), c


@pytest.mark.parametrize("col, index", [(0, IDX_AX), (1, IDX_AY)])
def test_class_forces_are_minus_the_period_derivative_of_class_energies(rest, col, index):
    model = CellModel(PARAMS, FIDELITY)
    forces = model.contact_forces_by_class(rest.x)

    def moved(h):
        x = rest.x.copy()
        x[index] += h
        return x

    scale = np.max(np.abs(forces[:, col]))
    _assert_minus_derivative(forces[:, col], lambda h: _class_energies(model, moved(h)), scale)
    # summed over the classes: -dE_c/da of the whole contact energy
    _assert_minus_derivative(np.array([forces[:, col].sum()]),
                             lambda h: np.array([model.energies(moved(h)).contact_energy]),
                             abs(forces[:, col].sum()))  # fmt: skip


def test_out_of_plane_push_is_non_negative(rest):
    forces = CellModel(PARAMS, FIDELITY).contact_forces_by_class(rest.x)
    assert np.all(forces[:, 2] >= 0.0) and forces[:, 2].sum() > 0.0


def test_no_contact_no_force(rest):
    thin = StitchParams(L_mm=10.8, r_mm=0.1, r_core_mm=0.05)  # a thread: nothing touches
    forces, energies = CellModel(thin, FIDELITY).contacts_by_class(rest.x)
    assert not forces.any() and not energies.any()


@pytest.mark.parametrize("which", ["rest", "pulled"])
def test_class_forces_plus_bending_balance_the_period_force(request, which):
    """dE*/da (from the length constraint's multiplier) = dE_b/da − ΣF_class − λ dl/da:
    the contact classes and the bending term account for the whole period force."""
    r = request.getfixturevalue(which)
    model = CellModel(PARAMS, FIDELITY)
    forces = model.contact_forces_by_class(r.x)
    for col, index in ((0, IDX_AX), (1, IDX_AY)):
        xp, xm = r.x.copy(), r.x.copy()
        xp[index] += H
        xm[index] -= H
        ep, em = model.energies(xp), model.energies(xm)
        dEb = (ep.bending_energy - em.bending_energy) / (2 * H)
        dl = (ep.length - em.length) / (2 * H)
        balance = dEb - forces[:, col].sum() - r.length_multiplier * dl
        scale = max(abs(dEb), abs(forces[:, col]).sum())
        assert abs(balance - r.period_forces[col]) < 1e-5 * scale, (col, balance, r.period_forces)
    if which == "rest":
        # zero force to SLSQP's stationarity (measured 1.6e-3 of the class forces' scale)
        assert max(map(abs, r.period_forces)) < 5e-3 * scale
    else:
        assert r.period_forces[0] > 1e-3 * scale  # pulled: the cell resists


# ---------------------------------------------------------------- pair forces (Table S3)


def _pair_reference(model, x, weighted):
    """The rule of kernels.forces.contact_pair_forces_by_class, in numpy, on the
    contact kernel's pairs: each contact's force on both samples, positive where it
    pushes two stitches apart (offset axes) or a sample away from its own mid-plane."""
    ip = model.ip
    cp = model.control_points(x)
    tab = model._ctab
    pts, _, speed, idx, sep = find_contacts(cp, tab, x[IDX_AX], x[IDX_AY], ip.r, model._mode)
    dv = np.array([pair_potential(d, ip.r, ip.rc, ip.k, ip.p)[1] for d in sep[:, 3]])
    f = -dv / sep[:, 3]
    if weighted:
        f = f * speed[idx[:, 0]] * speed[idx[:, 1]] / tab.shape[1] ** 2
    force_on_i = f[:, None] * sep[:, :3]
    offset = np.column_stack([idx[:, 2], idx[:, 3], np.zeros(len(idx), dtype=np.int64)])
    apart = -2.0 * np.sign(offset) * force_on_i
    outward = force_on_i * (np.sign(pts[idx[:, 0]]) - np.sign(pts[idx[:, 1]]))
    contribution = np.where(offset != 0, apart, outward)
    out = np.zeros((len(CONTACT_CLASSES), 3))
    classes = [contact_class(m, n) for m, n in idx[:, 2:]]
    np.add.at(out, classes, contribution)
    return out


@pytest.mark.parametrize("weighted", [False, True])
def test_pair_forces_follow_their_rule(rest, pulled, weighted):
    model = CellModel(PARAMS, FIDELITY)
    for x in (rest.x, pulled.x):
        got = model.contact_pair_forces_by_class(x, weighted=weighted)
        np.testing.assert_allclose(got, _pair_reference(model, x, weighted), rtol=1e-12,
                                   atol=1e-14 * np.abs(got).max())  # fmt: skip


@pytest.mark.parametrize("col, index, cls, per_offset", [
    (0, IDX_AX, "same_row", 1.0), (1, IDX_AY, "nn_column", 1.0), (1, IDX_AY, "nnn_column", 2.0),
])  # fmt: skip
def test_weighted_pair_forces_are_the_image_shift_derivative(rest, col, index, cls, per_offset):
    """Weighted by ds ds′, a class's pair force along its offset axis is −∂E_c(class)/∂a
    with the yarn held where it is and only the images moving (the virial of those
    contacts), divided by the offset |m| or |n| of the class."""
    model = CellModel(PARAMS, FIDELITY)
    ip, x = model.ip, rest.x
    cp = model.control_points(x)
    dcp = np.zeros((*cp.shape, 2))

    def class_energies(a):
        periods = [x[IDX_AX], x[IDX_AY]]
        periods[col] = a
        forces, energies = np.empty((5, 3)), np.empty(5)
        contact_forces_by_class(cp, dcp, model._ctab, *periods, ip.r, ip.rc, ip.k, ip.p,
                                model._mode, forces, energies)  # fmt: skip
        return energies

    row = CONTACT_CLASSES.index(cls)
    fd = -(class_energies(x[index] + H)[row] - class_energies(x[index] - H)[row]) / (2 * H)
    got = model.contact_pair_forces_by_class(x, weighted=True)[row, col]
    assert got != 0.0
    assert got * per_offset == pytest.approx(fd, rel=1e-6)


def test_no_contact_no_pair_force(rest):
    thin = StitchParams(L_mm=10.8, r_mm=0.1, r_core_mm=0.05)
    assert not CellModel(thin, FIDELITY).contact_pair_forces_by_class(rest.x).any()


def test_pair_forces_reproduce_table_s3(data_dir):
    """On knitsweep's own zero-force states of the k = 0.1 series (tests/data/
    paper_series.json), the unweighted pair forces give Table S3's |F_x| (self + same
    row) within 5 % at every L (measured: -4 … +2 %), its |F_y| (NN + NNN same
    column) within 30 % (measured: -28 … +20 %), a ratio crossing 1 within 0.1 mm of
    Table S3's 11.46 mm, and Table 2's directions at L = 10.5 mm."""
    states = json.loads((data_dir / "paper_series.json").read_text())["zero_force_states_k0.1"]
    ratio = {}
    for text, x in states.items():
        L = float(text)
        f = CellModel(
            StitchParams(L_mm=L, k_mN_per_mm2=0.1), FIDELITY
        ).contact_pair_forces_by_class(np.array(x))
        fx, fy = (abs(v) for v in fig6h_forces(f)[:2])
        ratio[L] = fx / fy
        if L in TABLE_S3:
            assert fx == pytest.approx(TABLE_S3[L][0], rel=0.05), L
            assert fy == pytest.approx(TABLE_S3[L][1], rel=0.30), L
        if L == 10.5:  # paper Table 2 (and Fig. S11, drawn at L = 10.5 mm)
            i = {c: CONTACT_CLASSES.index(c) for c in CONTACT_CLASSES}
            assert f[i["self"], 0] > 0 and f[i["same_row"], 0] > 0  # extend in x
            assert f[i["nn_column"], 1] < 0 < f[i["nnn_column"], 1]  # compress / extend in y
            assert f[i["nn_column"], 2] == f[:, 2].max() > 0  # NN pushes out of plane most
    Ls = sorted(ratio)
    crossing = ratio_crossing(Ls, [ratio[L] for L in Ls])
    assert crossing is not None and crossing == pytest.approx(table_s3_crossing_mm(), abs=0.1)
