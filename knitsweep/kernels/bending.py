"""Bending energy and yarn length of the cell, with gradients (MODEL.md §5).

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

# weights of the segments (path order) in the cell sums of MODEL.md §5:
# E_b = 2E(C1.A) + 2E(C1.B) + 2E(cc11) + E(cc12) + E(cc21); C2 and cc22 enter
# through the symmetry of the cell, exactly as in the reference code.
SEGMENT_WEIGHTS = np.array([2.0, 2.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0])


@njit(cache=True)
def bending_and_length(cp, seg_w, tab, gl_w, bend, reg, grad_e, grad_l):
    """Bending energy E_b (N mm) and yarn length l (mm) of the cell.

    cp: (8, 6, 3) control points; seg_w: (8,) segment weights; tab: (4, nq, 6)
    Bernstein tables at the Gauss–Legendre nodes; gl_w: (nq,) weights on [0, 1];
    bend = B/2 (N mm^2); reg (N mm^4). ``grad_e`` and ``grad_l`` (8, 6, 3) are
    overwritten with dE_b/dcp and dl/dcp.
    """
    grad_e[:] = 0.0
    grad_l[:] = 0.0
    energy = 0.0
    length = 0.0
    nq = gl_w.shape[0]
    a = np.empty(3)
    b = np.empty(3)
    c = np.empty(3)
    for s in range(cp.shape[0]):
        ws = seg_w[s]
        if ws == 0.0:
            continue
        for q in range(nq):
            for d in range(3):
                a[d] = 0.0
                b[d] = 0.0
                c[d] = 0.0
                for i in range(6):
                    a[d] += tab[1, q, i] * cp[s, i, d]
                    b[d] += tab[2, q, i] * cp[s, i, d]
                    c[d] += tab[3, q, i] * cp[s, i, d]
            u = a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
            sab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
            sac = a[0] * c[0] + a[1] * c[1] + a[2] * c[2]
            sbb = b[0] * b[0] + b[1] * b[1] + b[2] * b[2]
            v = np.sqrt(u)
            iu = 1.0 / u
            u_m25 = iu * iu / v  # u^-2.5
            u_m35 = u_m25 * iu
            kap2 = (sbb - sab * sab * iu) * iu * iu
            al_c = iu / v
            al_b = -3.0 * sab * u_m25
            al_a = -(sac + sbb) * u_m25 + 4.0 * sab * sab * u_m35
            qv0 = al_a * a[0] + al_b * b[0] + al_c * c[0]
            qv1 = al_a * a[1] + al_b * b[1] + al_c * c[1]
            qv2 = al_a * a[2] + al_b * b[2] + al_c * c[2]
            qq = qv0 * qv0 + qv1 * qv1 + qv2 * qv2
            dens = bend * kap2 + reg * qq
            wq = ws * gl_w[q]
            energy += wq * v * dens
            length += wq * v
            # d kappa^2 / d(u, sab, sbb)
            k_u = (-2.0 * sbb + 3.0 * sab * sab * iu) * iu * iu * iu
            k_ab = -2.0 * sab * iu * iu * iu
            k_bb = iu * iu
            # d|q|^2 through the alpha coefficients
            qa = qv0 * a[0] + qv1 * a[1] + qv2 * a[2]
            qb = qv0 * b[0] + qv1 * b[1] + qv2 * b[2]
            qc = qv0 * c[0] + qv1 * c[1] + qv2 * c[2]
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
            qvec = (qv0, qv1, qv2)
            for d in range(3):
                ga = ca_a * a[d] + ca_b * b[d] + ca_c * c[d] + ca_q * qvec[d]
                gb = cb_a * a[d] + cb_b * b[d] + cb_q * qvec[d]
                gc = cc_a * a[d] + cc_q * qvec[d]
                gl = a[d] / v
                for i in range(6):
                    grad_e[s, i, d] += wq * (
                        tab[1, q, i] * ga + tab[2, q, i] * gb + tab[3, q, i] * gc
                    )
                    grad_l[s, i, d] += wq * tab[1, q, i] * gl
    return energy, length
