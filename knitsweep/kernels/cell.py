"""Energy, yarn length and their exact gradients for a state vector.

Composes geometry (state -> control points, Jacobian) with the bending and
contact kernels: grad_x E = J^T dE/dcp + (explicit dE_c/d(a_x, a_y)).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .bending import bending_and_length
from .contact import contact_energy
from .geometry import IDX_AX, IDX_AY, N_STATE, state_to_control_points


@njit(cache=True)
def _jt_dot(jac, g, out):
    """out += J^T g for J (8, 6, 3, 30) and g (8, 6, 3)."""
    for s in range(jac.shape[0]):
        for i in range(6):
            for d in range(3):
                gv = g[s, i, d]
                if gv != 0.0:
                    for k in range(N_STATE):
                        out[k] += jac[s, i, d, k] * gv


@njit(cache=True)
def cell_energy(x, qtab, qw, ctab, seg_w, bend, reg, r, rc, k, p, mode, with_grad,
                grad_e, grad_l):  # fmt: skip
    """Bending energy, contact energy (N mm) and yarn length (mm) of state ``x``.

    qtab (4, nq, 6) / qw (nq,): Gauss–Legendre tables; ctab (2, N, 6): contact
    sample tables; seg_w (8,): bending segment weights. With ``with_grad`` the
    gradients of E = E_b + E_c and of the length are written to ``grad_e`` and
    ``grad_l`` (30,). Returns (E_b, E_c, length).
    """
    cp = np.empty((8, 6, 3))
    jac = np.empty((8, 6, 3, N_STATE))
    state_to_control_points(x, cp, jac)
    ge = np.empty((8, 6, 3))
    gl = np.empty((8, 6, 3))
    gc = np.empty((8, 6, 3))
    gcell = np.zeros(2)
    eb, length = bending_and_length(cp, seg_w, qtab, qw, bend, reg, ge, gl)
    ec = contact_energy(cp, ctab, x[IDX_AX], x[IDX_AY], r, rc, k, p, mode, with_grad, gc, gcell)
    if with_grad:
        grad_e[:] = 0.0
        grad_l[:] = 0.0
        ge += gc
        _jt_dot(jac, ge, grad_e)
        _jt_dot(jac, gl, grad_l)
        grad_e[IDX_AX] += gcell[0]
        grad_e[IDX_AY] += gcell[1]
    return eb, ec, length
