"""Bending energy and yarn length of the cell, with gradients (docs/model.md §5).

For one quintic r(t) with a = r', b = r'', c = r''' the integrand is

    |r'| (bend kappa^2 + reg |dcv/ds|^2),

and both terms depend on the curve only through the six dot products of a, b, c:
kappa^2 = (a.a b.b - (a.b)^2)/|a|^6 and dcv/ds = alpha_a a + alpha_b b + alpha_c c
with alpha_c = |a|^-3, alpha_b = -3 (a.b)|a|^-5 and
alpha_a = -(a.c + b.b)|a|^-5 + 4 (a.b)^2 |a|^-7. Differentiating those scalar
coefficients gives the exact gradient with respect to a, b, c, and so to the
control points, at the cost of a few dozen flops per quadrature node.
"""

from __future__ import annotations

import numpy as np
from numba import njit

_N_ROWS = 15  # per-node outputs of _nodes


@njit(cache=True, error_model="numpy")
def _nodes(cp, s, tab, gl_w, ws, bend, reg, out):
    """Integrand and gradient factors at every Gauss node q of segment ``s``.

    ``out`` (15, nq): row 0 w_q |r'| (bend kappa^2 + reg |dcv/ds|^2), row 1
    w_q |r'|, row 2 w_q (w_q = ws gl_w[q]), rows 3-5, 6-8, 9-11 the derivatives of
    the integrand with respect to a, b, c (without w_q), rows 12-14 d|r'|/da =
    a/|r'|. Its arithmetic is that of the module docstring, operation for
    operation. error_model="numpy" drops numba's zero check on each of the
    divisions (a branch each); instead the loop reports whether some node has
    r' = 0, the only way they can divide by zero, and the caller raises
    ZeroDivisionError as the checked code did.
    """
    p = cp[s]
    degenerate = False
    for q in range(gl_w.shape[0]):
        a0 = a1 = a2 = 0.0
        b0 = b1 = b2 = 0.0
        c0 = c1 = c2 = 0.0
        for i in range(6):
            t1, t2, t3 = tab[1, q, i], tab[2, q, i], tab[3, q, i]
            a0 += t1 * p[i, 0]
            a1 += t1 * p[i, 1]
            a2 += t1 * p[i, 2]
            b0 += t2 * p[i, 0]
            b1 += t2 * p[i, 1]
            b2 += t2 * p[i, 2]
            c0 += t3 * p[i, 0]
            c1 += t3 * p[i, 1]
            c2 += t3 * p[i, 2]
        u = a0 * a0 + a1 * a1 + a2 * a2
        degenerate |= u == 0.0
        sab = a0 * b0 + a1 * b1 + a2 * b2
        sac = a0 * c0 + a1 * c1 + a2 * c2
        sbb = b0 * b0 + b1 * b1 + b2 * b2
        v = np.sqrt(u)
        iu = 1.0 / u
        u_m25 = iu * iu / v  # u^-2.5
        u_m35 = u_m25 * iu
        kap2 = (sbb - sab * sab * iu) * iu * iu
        al_c = iu / v
        al_b = -3.0 * sab * u_m25
        al_a = -(sac + sbb) * u_m25 + 4.0 * sab * sab * u_m35
        qv0 = al_a * a0 + al_b * b0 + al_c * c0
        qv1 = al_a * a1 + al_b * b1 + al_c * c1
        qv2 = al_a * a2 + al_b * b2 + al_c * c2
        qq = qv0 * qv0 + qv1 * qv1 + qv2 * qv2
        dens = bend * kap2 + reg * qq
        wq = ws * gl_w[q]
        out[0, q] = wq * v * dens
        out[1, q] = wq * v
        out[2, q] = wq
        # d kappa^2 / d(u, sab, sbb)
        k_u = (-2.0 * sbb + 3.0 * sab * sab * iu) * iu * iu * iu
        k_ab = -2.0 * sab * iu * iu * iu
        k_bb = iu * iu
        # d|q|^2 through the alpha coefficients
        qa = qv0 * a0 + qv1 * a1 + qv2 * a2
        qb = qv0 * b0 + qv1 * b1 + qv2 * b2
        qc = qv0 * c0 + qv1 * c1 + qv2 * c2
        g_u = (
            qa * (2.5 * (sac + sbb) * u_m35 - 14.0 * sab * sab * u_m35 * iu)
            + qb * 7.5 * sab * u_m35
            - qc * 1.5 * u_m25
        )
        g_ab = qa * 8.0 * sab * u_m35 - qb * 3.0 * u_m25
        g_ac = -qa * u_m25
        g_bb = -qa * u_m25
        # coefficients of the gradients, as combinations of a, b, c, q
        ca_a = dens / v + v * (bend * 2.0 * k_u + reg * 4.0 * g_u)
        ca_b = v * (bend * k_ab + reg * 2.0 * g_ab)
        ca_c = v * reg * 2.0 * g_ac
        ca_q = v * reg * 2.0 * al_a
        cb_a = v * (bend * k_ab + reg * 2.0 * g_ab)
        cb_b = v * (bend * 2.0 * k_bb + reg * 4.0 * g_bb)
        cb_q = v * reg * 2.0 * al_b
        cc_a = v * reg * 2.0 * g_ac
        cc_q = v * reg * 2.0 * al_c
        out[3, q] = ca_a * a0 + ca_b * b0 + ca_c * c0 + ca_q * qv0
        out[4, q] = ca_a * a1 + ca_b * b1 + ca_c * c1 + ca_q * qv1
        out[5, q] = ca_a * a2 + ca_b * b2 + ca_c * c2 + ca_q * qv2
        out[6, q] = cb_a * a0 + cb_b * b0 + cb_q * qv0
        out[7, q] = cb_a * a1 + cb_b * b1 + cb_q * qv1
        out[8, q] = cb_a * a2 + cb_b * b2 + cb_q * qv2
        out[9, q] = cc_a * a0 + cc_q * qv0
        out[10, q] = cc_a * a1 + cc_q * qv1
        out[11, q] = cc_a * a2 + cc_q * qv2
        out[12, q] = a0 / v
        out[13, q] = a1 / v
        out[14, q] = a2 / v
    return degenerate


@njit(cache=True)
def bending_and_length(cp, seg_w, tab, gl_w, bend, reg, grad_e, grad_l):
    """Bending energy E_b (N mm) and yarn length l (mm) of the cell.

    cp: (S, 6, 3) control points; seg_w: (S,) segment weights (the stitch's: a
    segment counted w times, 0 for one that a symmetry already counts); tab:
    (4, nq, 6) Bernstein tables at the Gauss–Legendre nodes; gl_w: (nq,) weights on
    [0, 1]; bend = B/2 (N mm^2); reg (N mm^4). ``grad_e`` and ``grad_l`` (S, 6, 3)
    are overwritten with dE_b/dcp and dl/dcp.

    The node formulas run as one branch-free loop per segment (``_nodes``); the
    sums over nodes then run in node order into local accumulators, the same
    additions in the same order as the one-loop version (identical bits), without
    its read-modify-write of ``grad_e``/``grad_l`` per node.
    """
    grad_e[:] = 0.0
    grad_l[:] = 0.0
    energy = 0.0
    length = 0.0
    nq = gl_w.shape[0]
    work = np.empty((_N_ROWS, nq))
    acc_e = np.empty((3, 6))
    acc_l = np.empty((3, 6))
    for s in range(cp.shape[0]):
        ws = seg_w[s]
        if ws == 0.0:
            continue
        if _nodes(cp, s, tab, gl_w, ws, bend, reg, work):
            raise ZeroDivisionError("division by zero")
        acc_e[:] = 0.0
        acc_l[:] = 0.0
        for q in range(nq):
            energy += work[0, q]
            length += work[1, q]
            wq = work[2, q]
            for d in range(3):
                ga, gb, gc, gl = work[3 + d, q], work[6 + d, q], work[9 + d, q], work[12 + d, q]
                for i in range(6):
                    t1 = tab[1, q, i]
                    acc_e[d, i] += wq * (t1 * ga + tab[2, q, i] * gb + tab[3, q, i] * gc)
                    acc_l[d, i] += wq * t1 * gl
        for i in range(6):
            for d in range(3):
                grad_e[s, i, d] = acc_e[d, i]
                grad_l[s, i, d] = acc_l[d, i]
    return energy, length
