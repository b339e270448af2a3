"""Energy, yarn length and exact gradients of a pattern's cell whose images include
glide reflections (docs/model.md §11): ``cell.cell_energy`` with the contact sum of
``mirrored`` in place of the translations' culled one."""

from __future__ import annotations

import numpy as np
from numba import njit

from .arclength import length_spread
from .bending import bending_and_length
from .cell import _state_gradients
from .mirrored import N_MIRROR_CLASSES, mirrored_contact_energy


@njit(cache=True)
def pattern_cell_energy(cp, jac, ax, ay, sx, cx, qtab, qw, ctab, aq, seg_w, bend, reg, r, rc, k, p,
                        pm, pn, gauge_rule, gauge_stiffness, with_grad, grad_e, grad_l):  # fmt: skip
    """(E_b, E_c, length, gauge penalty) of the cell ``cp`` (S, 6, 3) with Jacobian ``jac``
    (S, 6, 3, n) over images mirrored by parities (pm, pn), the wale vector skewed by
    ``sx`` (t_w = (s_x, a_y), mm; a prescribed shear, not a state entry); ``ax`` the
    cell's course period, ``cx`` times the state's (a chart's row of ``cx`` stitches,
    ``stitches.charts``; 1 for one stitch); with ``with_grad`` the
    gradients of E_b + E_c + the penalty and of the length with respect to the state into
    ``grad_e``, ``grad_l`` (n,). Arguments as ``cell.cell_energy``'s; ``aq`` the
    arclength rule of samples placed by arclength, empty for samples at ``ctab``'s
    parameters (``mirrored.mirrored_contact_energy``); the penalty is a free yarn's gauge
    on its joints' slides (``arclength.length_spread`` by the rule ``gauge_rule``), 0 where
    ``gauge_stiffness`` is."""
    ge, gl, gc = np.empty_like(cp), np.empty_like(cp), np.empty_like(cp)
    gcell = np.zeros(2)
    eb, length = bending_and_length(cp, seg_w, qtab, qw, bend, reg, ge, gl)
    ce = np.zeros(N_MIRROR_CLASSES)
    ec = mirrored_contact_energy(cp, ctab, aq, ax, ay, sx, r, rc, k, p, pm, pn, -1, with_grad, gc,
                                 gcell, ce)  # fmt: skip
    penalty = 0.0
    if gauge_stiffness > 0.0:
        penalty = length_spread(cp, gauge_rule, gauge_stiffness, with_grad, ge)
    if with_grad:
        gcell[0] *= cx  # d a_cell / d a_x
        _state_gradients(jac, ge, gl, gc, gcell, grad_e, grad_l)
    return eb, ec, length, penalty
