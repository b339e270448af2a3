"""Property tier: contact forces and energies by class (kernels.forces) against
finite differences, and the force balance on the cell periods (docs/model.md §9)."""

import numpy as np
import pytest

from knitsweep.config import Fidelity, SolverSettings, StartSettings, StitchParams
from knitsweep.model import CellModel
from knitsweep.relax import relax
from knitsweep.state import CONTACT_CLASSES, IDX_AX, IDX_AY
from knitsweep.zero_force import zero_force

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


@pytest.mark.parametrize("col, index", [(0, IDX_AX), (1, IDX_AY)])
def test_class_forces_are_minus_the_period_derivative_of_class_energies(rest, col, index):
    model = CellModel(PARAMS, FIDELITY)
    forces = model.contact_forces_by_class(rest.x)
    xp, xm = rest.x.copy(), rest.x.copy()
    xp[index] += H
    xm[index] -= H
    fd = -(_class_energies(model, xp) - _class_energies(model, xm)) / (2 * H)
    scale = np.max(np.abs(forces[:, col]))
    np.testing.assert_allclose(forces[:, col], fd, rtol=0, atol=1e-6 * scale)
    # summed over the classes: -dE_c/da of the whole contact energy
    ep, em = model.energies(xp).contact_energy, model.energies(xm).contact_energy
    np.testing.assert_allclose(forces[:, col].sum(), -(ep - em) / (2 * H), rtol=1e-6)


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
