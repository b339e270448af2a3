"""Contact samples placed by arclength within each segment (kernels/arclength.py,
``Fidelity.contact_sampling = "arclength"``; docs/model.md §11, "Resolution")."""

from __future__ import annotations

import numpy as np
import pytest
from pydantic import ValidationError

from knitsweep.config import Fidelity, StitchParams
from knitsweep.kernels.arclength import (
    arclength_params,
    arclength_rule,
    derivative_coefficients,
)
from knitsweep.kernels.mirrored import (
    N_MIRROR_CLASSES,
    mirrored_contact_energy,
    mirrored_contact_energy_exhaustive,
)
from knitsweep.model import CellModel
from knitsweep.relax.problem import _state_box
from knitsweep.stitches.stockinette_free.layout import SEG0

ARC = Fidelity(contact_sampling="arclength")
YARN = Fidelity(contact_sampling="yarn_arclength")
PARAM = Fidelity(contact_sampling="parameter")
PATTERNS = ("garter", "rib", "seed")
SAMPLINGS = [(name, f) for name in PATTERNS for f in (ARC, YARN)]


def _model(name, fidelity=ARC, L=11.0):
    return CellModel(StitchParams(L_mm=L, k_mN_per_mm2=0.1, stitch=name), fidelity)


def test_power_basis_derivatives_are_the_bernstein_ones():
    """``derivative_coefficients``: r' and r'' of every segment of a pattern's start, as
    the power basis's Horner sums, equal the Bernstein form's derivatives (the
    differences of the control points on the degree-4 and degree-3 bases) to round-off."""
    from math import comb

    m = _model("seed")
    cp = m.control_points(m.stitch.start(1))
    co = derivative_coefficients(cp)
    u = np.linspace(0.0, 1.0, 11)
    d1 = 5.0 * np.diff(cp, axis=1)  # (S, 5, 3)
    d2 = 4.0 * np.diff(d1, axis=1)  # (S, 4, 3)
    b4 = np.stack([comb(4, i) * u**i * (1 - u) ** (4 - i) for i in range(5)], axis=1)
    b3 = np.stack([comb(3, i) * u**i * (1 - u) ** (3 - i) for i in range(4)], axis=1)
    powers = np.stack([u**k for k in range(5)], axis=1)
    scale = np.abs(cp).max()
    np.testing.assert_allclose(np.einsum("uk,skd->sud", powers, co[:, :5]),
                               np.einsum("ui,sid->sud", b4, d1), atol=1e-12 * scale)  # fmt: skip
    np.testing.assert_allclose(np.einsum("uk,skd->sud", powers[:, :4], co[:, 5:]),
                               np.einsum("ui,sid->sud", b3, d2), atol=1e-11 * scale)  # fmt: skip


def _arclength(cp_s, t, nodes=200):
    """∫_0^t |r'| of one segment by a fine Gauss rule of its own."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    u = 0.5 * t * (x + 1.0)
    k = np.arange(5)
    from math import comb

    b4 = np.array([[comb(4, i) * v**i * (1 - v) ** (4 - i) for i in k] for v in u])
    d = 5.0 * (cp_s[1:] - cp_s[:-1])
    return 0.5 * t * np.sum(w * np.linalg.norm(b4 @ d, axis=1))


def test_samples_sit_at_equal_arclength_fractions():
    m = _model("rib")
    cp = m.control_points(m.stitch.start(1))
    # a segment with very unequal end speeds: the fixed-parameter samples bunch up
    cp[3, 1] = cp[3, 0] + 0.02 * (cp[3, 1] - cp[3, 0])
    n = 10
    t, seglen = arclength_params(cp, n, arclength_rule(2, 8))
    for s in range(cp.shape[0]):
        # the 16-node rule: ~1e-9 on the start's segments, ~1e-6 on segment 3
        tol = 1e-5 if s == 3 else 1e-8
        ell = _arclength(cp[s], 1.0)
        assert seglen[s] == pytest.approx(ell, rel=tol)
        for j in range(n):
            assert _arclength(cp[s], t[s, j]) / ell == pytest.approx((j + 0.5) / n, abs=tol)
    assert np.all(np.diff(t, axis=1) > 0.0)
    # segment 3's parameters are far from the midpoints (j + 1/2)/n
    assert np.max(np.abs(t[3] - (np.arange(n) + 0.5) / n)) > 0.05


@pytest.mark.parametrize(("name", "fid"), SAMPLINGS)
def test_gradient_matches_central_differences(name, fid):
    m = _model(name, fid)
    x = m.stitch.start(2)
    e, g, _ = m.energy_and_gradients(x)
    assert e.contact_energy > 0.0
    h = 1e-6
    fd = np.empty_like(g)
    for i in range(x.size):
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        # the gradient is that of what a relaxation minimises: E plus the gauge's penalty
        fd[i] = (m.energies(xp).objective - m.energies(xm).objective) / (2 * h)
    np.testing.assert_allclose(g, fd, rtol=0, atol=1e-7 * np.max(np.abs(g)))


@pytest.mark.parametrize(("name", "fid"), SAMPLINGS)
def test_class_forces_are_minus_the_period_derivatives(name, fid):
    """Each class's force on a period is -dE_c(class)/da at fixed shape (through the
    samples' parameters too), by central differences of the class energies."""
    m = _model(name, fid)
    x = m.stitch.start(1)
    forces, _ = m.contacts_by_class(x)
    h = 1e-6
    for col in (0, 1):
        xp, xm = x.copy(), x.copy()
        xp[-2 + col] += h
        xm[-2 + col] -= h
        fd = -(m.contacts_by_class(xp)[1] - m.contacts_by_class(xm)[1]) / (2 * h)
        np.testing.assert_allclose(forces[:, col], fd, rtol=1e-6, atol=1e-11)


@pytest.mark.parametrize(("name", "fid"), SAMPLINGS)
def test_culled_sum_is_the_exhaustive_one(name, fid):
    m = _model(name, fid)
    x = m.stitch.start(1)
    cp = m.control_points(x)
    ip = m.ip
    out = []
    for kernel in (mirrored_contact_energy, mirrored_contact_energy_exhaustive):
        g, gc, ce = np.zeros_like(cp), np.zeros(2), np.zeros(N_MIRROR_CLASSES)
        e = kernel(cp, m._ctab, m._aq, x[-2], x[-1], 0.0, ip.r, ip.rc, ip.k, ip.p,
                   *m.stitch.mirror_parity, -1, True, g, gc, ce)  # fmt: skip
        out.append((e, g, gc, ce))
    for a, b in zip(*out, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-13, atol=1e-18)


def test_a_free_yarn_samples_along_itself_by_default_and_the_ansatz_by_parameter():
    """'auto' (the default) is 'yarn_arclength' for every free yarn, with its end speeds as
    the gauge; the ansatz samples by parameter whatever the setting, with no gauge."""
    assert Fidelity().contact_sampling == "auto"
    for name in ("stockinette_free", *PATTERNS):
        m = _model(name, Fidelity())
        assert m.sampling == "yarn_arclength" and m._aq.shape == (3, 16)
        assert m.gauge.size == 16
        assert _model(name, PARAM).sampling == "parameter" and _model(name, PARAM).gauge.size == 0
    for fidelity in (Fidelity(), YARN, ARC):
        ansatz = _model("stockinette", fidelity)
        assert ansatz.sampling == "parameter" and ansatz.gauge.size == 0
    with pytest.raises(ValidationError, match="contact_sampling"):
        Fidelity(contact_sampling="even")


def test_samples_by_arclength_drop_the_speed_box():
    p = _model("garter")
    q = _model("garter", PARAM)
    lo, hi = _state_box(p.stitch, p.ip.L, p.ip.r, p.sampling)
    qlo, qhi = _state_box(q.stitch, q.ip.L, q.ip.r, q.sampling)
    speeds = [SEG0 + 4 * s + e for s in range(8) for e in (0, 2)]
    assert np.all(lo[speeds] < qlo[speeds]) and np.all(hi[speeds] > qhi[speeds])
    assert hi[speeds[0]] == pytest.approx(p.ip.L)


def test_min_zeta_uses_the_same_samples():
    """The knittability check (min ζ) samples where the contact sum does: by arclength
    its ζ is not the fixed parameters' one."""
    m = _model("seed")
    x = m.stitch.start(1)
    z_arc, z_par = m.min_zeta(x), _model("seed", PARAM).min_zeta(x)
    assert 0.0 < z_arc < 1.0 and z_arc != z_par


def test_yarn_samples_are_evenly_spaced_along_the_yarn():
    """With "yarn_arclength" the samples sit at (i + 1/2)/(S N) of the whole yarn: their
    arclengths along it are exact multiples, however unequal the segments."""
    from knitsweep.kernels.arclength import yarn_sample_cell

    m = _model("garter", YARN)
    cp = m.control_points(m.stitch.start(1))
    _, _, _, speed, _, total, st = yarn_sample_cell(cp, 10, m._aq)
    ell = np.array([_arclength(cp[s], 1.0) for s in range(8)])
    assert total == pytest.approx(ell.sum(), rel=1e-8)
    before = np.concatenate([[0.0], np.cumsum(ell)])
    for i in range(80):
        s, t = int(st[i, 0]), st[i, 1]
        assert before[s] + _arclength(cp[s], t) == pytest.approx((i + 0.5) / 80 * total, rel=1e-8)
    assert np.all(speed == total / 8)
    assert len(set(st[:, 0].astype(int))) == 8


def test_along_the_yarn_the_under_resolved_rib_shows_its_overlap(data_dir):
    """The rib state whose cores pass between the default's samples (test_patterns)
    overlaps at the model's own 10 samples when they sit along the yarn, and its contact
    sum is refused; the relaxed rib state's E_c holds at 20 and 40 samples."""
    from knitsweep.model import CORES_OVERLAP

    m = _model("rib", YARN, L=11.6)
    x = np.loadtxt(data_dir / "rib_under_resolved_L11.6_k0.1.dat")
    assert m.min_zeta(x) < 0.0 < _model("rib", PARAM, L=11.6).min_zeta(x)
    assert m.resolution_change(x).startswith(CORES_OVERLAP)
    y = np.loadtxt(data_dir / "rib_relaxed_L11.6_k0.1.dat")
    assert m.resolution_change(y) == ""
    ec = [_model("rib", YARN.model_copy(update={"samples_per_segment": n}), L=11.6)
          .energies(y).contact_energy for n in (10, 20, 40)]  # fmt: skip
    assert max(ec) - min(ec) < 0.015 * ec[0]  # measured 1.0 %
