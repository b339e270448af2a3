"""Energy, yarn length and their exact gradients for a stitch's control points.

Composes the bending and contact kernels with the Jacobian of the stitch's geometry
(``knitsweep.stitches``: state -> control points cp (S, 6, 3) and J = dcp/dx
(S, 6, 3, n)): grad_x E = J^T dE/dcp + (explicit dE_c/d(a_x, a_y)), the periods
being the state's last two entries. ``cell_energy_listed`` is the same with the
optional neighbour list of ``neighbours`` (docs/model.md §6) for callers that
evaluate many nearby states.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .bending import bending_and_length
from .neighbours import NO_LIST, contact_energy_listed


@njit(cache=True)
def _jt_dot2(jac, g1, g2, out1, out2):
    """out1 += J^T g1 and out2 += J^T g2 for J (S, 6, 3, n), g (S, 6, 3), in one
    pass over J, row by row (each out[k] adds the same terms in the same order as
    two separate passes). The trip count is read from the array, so that LLVM
    vectorises the k loops instead of unrolling them into scalar code (measured
    2.9 -> 1.5 us)."""
    nk = jac.shape[3]
    for s in range(jac.shape[0]):
        for i in range(6):
            for d in range(3):
                a = g1[s, i, d]
                b = g2[s, i, d]
                row = jac[s, i, d]
                if a != 0.0:
                    for k in range(nk):
                        out1[k] += row[k] * a
                if b != 0.0:
                    for k in range(nk):
                        out2[k] += row[k] * b


def cell_energy(cp, jac, ax, ay, qtab, qw, ctab, seg_w, bend, reg, r, rc, k, p, mode,
                with_grad, grad_e, grad_l):  # fmt: skip
    """Bending energy, contact energy (N mm) and yarn length (mm) of the cell whose
    control points are ``cp`` (S, 6, 3), periods ``ax``, ``ay`` (mm).

    qtab (4, nq, 6) / qw (nq,): Gauss–Legendre tables; ctab (2, N, 6): contact
    sample tables; seg_w (S,): bending segment weights. With ``with_grad`` the
    gradients of E = E_b + E_c and of the length with respect to the state are
    written to ``grad_e`` and ``grad_l`` (n,), through ``jac`` (S, 6, 3, n).
    Returns (E_b, E_c, length).

    Not a kernel of its own: ``cell_energy_listed`` with no list (``neighbours.NO_LIST``),
    which sums over the full search (``contact.contact_energy``) at once, the same
    numbers. A separate kernel would compile the bending, contact and gradient kernels
    into one more entry point (~1.2 s of compile time).
    """
    return cell_energy_listed(cp, jac, ax, ay, qtab, qw, ctab, seg_w, bend, reg, r, rc, k, p,
                              mode, with_grad, grad_e, grad_l, *NO_LIST)[:3]  # fmt: skip


@njit(cache=True)
def cell_energy_listed(cp, jac, ax, ay, qtab, qw, ctab, seg_w, bend, reg, r, rc, k, p, mode,
                       with_grad, grad_e, grad_l, rows, ref_pos, meta):  # fmt: skip
    """``cell_energy`` with the contact sum over a neighbour list
    (``neighbours.build_neighbour_list``, built from these control points or nearby
    ones). Returns (E_b, E_c, length, valid): the same numbers as ``cell_energy``, bit
    for bit; ``valid`` False means the list no longer covered the state (the contact
    sum then came from the full search) and should be rebuilt.
    """
    ge, gl, gc, gcell = _scratch(cp)
    eb, length = bending_and_length(cp, seg_w, qtab, qw, bend, reg, ge, gl)
    ec, valid = contact_energy_listed(cp, ctab, ax, ay, r, rc, k, p, mode, with_grad, gc,
                                      gcell, rows, ref_pos, meta)  # fmt: skip
    if with_grad:
        _state_gradients(jac, ge, gl, gc, gcell, grad_e, grad_l)
    return eb, ec, length, valid


@njit(cache=True)
def _scratch(cp):
    """dE_b/dcp, dl/dcp, dE_c/dcp (each shaped like ``cp``) and dE_c/d(a_x, a_y) (2,)."""
    return np.empty_like(cp), np.empty_like(cp), np.empty_like(cp), np.zeros(2)


@njit(cache=True)
def _state_gradients(jac, ge, gl, gc, gcell, grad_e, grad_l):
    """grad_x E = J^T (dE_b/dcp + dE_c/dcp) + explicit dE_c/d(a_x, a_y), and
    grad_x l = J^T dl/dcp, into ``grad_e``, ``grad_l`` (n,); the periods are the
    state's last two entries."""
    grad_e[:] = 0.0
    grad_l[:] = 0.0
    for s in range(ge.shape[0]):  # ge += gc, element by element (numpy's in-place
        for i in range(6):  # add compiles its broadcasting machinery: ~0.4 s)
            for d in range(3):
                ge[s, i, d] += gc[s, i, d]
    _jt_dot2(jac, ge, gl, grad_e, grad_l)
    n = grad_e.shape[0]
    grad_e[n - 2] += gcell[0]
    grad_e[n - 1] += gcell[1]
