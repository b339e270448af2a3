"""One crossover: frame, end directions, end points and control points (docs/model.md §3).

Forward-mode derivatives written out by hand: every function returns its value
and its Jacobian with respect to the crossover's 19 local inputs, columns
0 pos_x, 1-3 frame angles (g0, g1, g2), 4 tw, 5 z, 6 phi, 7-12 start condition,
13-18 end condition; ``geometry`` maps them to the 30 state entries.

Speed (this runs 4 times per energy evaluation): 3x3 products and cross products
are spelled out in scalars (no BLAS calls, no temporaries), and the Jacobian loops
visit only the columns that can be non-zero. A skipped column is one whose
inputs are exactly zero, so the result is the same as the full loop's.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ... import kernels  # noqa: F401  (first: it points numba's cache at this version's)

# local column layout of one crossover curve
L_POS, L_G, L_TW, L_Z, L_PHI, L_C0, L_C1, N_LOCAL = 0, 1, 4, 5, 6, 7, 13, 19

# Compile time: numba compiles a kernel once per distinct *literal* int or bool
# argument (a constant 0 and a constant 1 are two specialisations). Constant
# arguments of kernel calls therefore go in as plain int64 / bool_ values: one
# specialisation per kernel, the same machine arithmetic (benchmarks/bench_compile.py).
_i = np.int64
_TRUE = np.bool_(True)
_FALSE = np.bool_(False)


@njit(cache=True)
def _rxryrz(c0, s0, o0, c1, s1, o1, c2, s2, o2):
    """R_x R_y R_z (docs/model.md §3) as 9 scalars, row-major, where R_x(c, s, o) =
    [[o,0,0],[0,c,-s],[0,s,c]], R_y(c, s, o) = [[c,0,-s],[0,o,0],[s,0,c]] (the
    transpose of the usual one, as in docs/model.md) and R_z(c, s, o) =
    [[c,-s,0],[s,c,0],[0,0,o]]; (c, s, o) = (cos t, sin t, 1) gives the rotation,
    (-sin t, cos t, 0) its derivative. Terms with structural zeros are left out,
    which for finite inputs changes no bit of the plain triple-loop product."""
    m00, m02 = o0 * c1, -o0 * s1
    m10, m11, m12 = -s0 * s1, c0 * o1, -s0 * c1
    m20, m21, m22 = c0 * s1, s0 * o1, c0 * c1
    return (
        m00 * c2, m00 * -s2, m02 * o2,
        m10 * c2 + m11 * s2, m10 * -s2 + m11 * c2, m12 * o2,
        m20 * c2 + m21 * s2, m20 * -s2 + m21 * c2, m22 * o2,
    )  # fmt: skip


@njit(cache=True, inline="always")
def _put_column(r, d0, d1, d2, col, e, de):
    """Column ``col`` of R (9-tuples, row-major) and of dR/dg_k into e (3,), de (3, 19)."""
    for i in range(3):
        e[i] = r[3 * i + col]
        de[i, L_G] = d0[3 * i + col]
        de[i, L_G + 1] = d1[3 * i + col]
        de[i, L_G + 2] = d2[3 * i + col]


@njit(cache=True)
def crossover_frame(g0, g1, g2, tw, frame, dframe):
    """Frame vectors e1, e2, e3, T1, T2 (rows of ``frame``, shape (5, 3)).

    ``dframe`` (5, 3, 19) receives their derivatives in the local columns
    1-3 (frame angles) and 4 (tw); all other columns are zeroed.
    """
    c0, s0 = np.cos(g0), np.sin(g0)
    c1, s1 = np.cos(g1), np.sin(g1)
    c2, s2 = np.cos(g2), np.sin(g2)
    r = _rxryrz(c0, s0, 1.0, c1, s1, 1.0, c2, s2, 1.0)
    d0 = _rxryrz(-s0, c0, 0.0, c1, s1, 1.0, c2, s2, 1.0)
    d1 = _rxryrz(c0, s0, 1.0, -s1, c1, 0.0, c2, s2, 1.0)
    d2 = _rxryrz(c0, s0, 1.0, c1, s1, 1.0, -s2, c2, 0.0)
    ct, st = np.cos(tw), np.sin(tw)
    dframe[:] = 0.0
    # e3 = R(1,0,0), e1 = R(0,1,0), e2 = R(0,0,1): rows 2, 0, 1 take columns 0, 1, 2
    _put_column(r, d0, d1, d2, 0, frame[2], dframe[2])
    _put_column(r, d0, d1, d2, 1, frame[0], dframe[0])
    _put_column(r, d0, d1, d2, 2, frame[1], dframe[1])
    for i in range(3):
        frame[3, i] = frame[0, i] * ct + frame[1, i] * st
        frame[4, i] = -frame[0, i] * st + frame[1, i] * ct
        for k in range(3):
            col = L_G + k
            dframe[3, i, col] = dframe[0, i, col] * ct + dframe[1, i, col] * st
            dframe[4, i, col] = -dframe[0, i, col] * st + dframe[1, i, col] * ct
        dframe[3, i, L_TW] = frame[4, i]
        dframe[4, i, L_TW] = -frame[3, i]


@njit(cache=True)
def _end_direction(ea, dea, eb, deb, e3, de3, sa, sb, cond, lc, t, dt, cv, dcv):
    """Unit tangent and curvature vector at one crossover end (docs/model.md §3).

    ``t = sa|cos psi1| Ea + sb|sin psi1 sin psi2| Eb + |sin psi1 cos psi2| e3`` and
    ``cv = kappa [(Ea x t) cos nu + (t x (Ea x t)) sin nu] / |sin psi1|``;
    ``cond`` = (psi1, psi2, alpha, kappa, nu, beta) sits in local columns lc..lc+5.
    Only the frame columns (1-4) and lc..lc+4 can be non-zero; the loops visit
    those and zero the rest.
    """
    psi1, psi2, kappa, nu = cond[0], cond[1], cond[3], cond[4]
    c1, s1, c2, s2 = np.cos(psi1), np.sin(psi1), np.cos(psi2), np.sin(psi2)
    a = sa * abs(c1)
    b = sb * abs(s1 * s2)
    c = abs(s1 * c2)
    da1 = -sa * np.sign(c1) * s1
    sgb = sb * np.sign(s1 * s2)
    db1, db2 = sgb * c1 * s2, sgb * s1 * c2
    sgc = np.sign(s1 * c2)
    dc1, dc2 = sgc * c1 * c2, -sgc * s1 * s2
    nl = dt.shape[1]
    dt[:] = 0.0
    dcv[:] = 0.0
    for i in range(3):
        t[i] = a * ea[i] + b * eb[i] + c * e3[i]
        for k in range(L_G, L_TW + 1):
            dt[i, k] = a * dea[i, k] + b * deb[i, k] + c * de3[i, k]
        dt[i, lc] += da1 * ea[i] + db1 * eb[i] + dc1 * e3[i]
        dt[i, lc + 1] += db2 * eb[i] + dc2 * e3[i]
    t0, t1, t2 = t[0], t[1], t[2]
    e0, e1, e2 = ea[0], ea[1], ea[2]
    # u = Ea x t, w = t x u
    u0, u1, u2 = e1 * t2 - e2 * t1, e2 * t0 - e0 * t2, e0 * t1 - e1 * t0
    w0, w1, w2 = t1 * u2 - t2 * u1, t2 * u0 - t0 * u2, t0 * u1 - t1 * u0
    h = kappa / abs(s1)
    dh_dpsi1 = -kappa * np.sign(s1) * c1 / (s1 * s1)
    cn, sn = np.cos(nu), np.sin(nu)
    for k in range(L_G, nl):
        if k > L_TW and (k < lc or k > lc + 1):
            continue  # dEa and dt vanish in this column, so du = dw = 0
        # du = dEa x t + Ea x dt ; dw = dt x u + t x du
        f0, f1, f2 = dea[0, k], dea[1, k], dea[2, k]
        g0, g1, g2 = dt[0, k], dt[1, k], dt[2, k]
        du0 = (f1 * t2 - f2 * t1) + (e1 * g2 - e2 * g1)
        du1 = (f2 * t0 - f0 * t2) + (e2 * g0 - e0 * g2)
        du2 = (f0 * t1 - f1 * t0) + (e0 * g1 - e1 * g0)
        dw0 = (g1 * u2 - g2 * u1) + (t1 * du2 - t2 * du1)
        dw1 = (g2 * u0 - g0 * u2) + (t2 * du0 - t0 * du2)
        dw2 = (g0 * u1 - g1 * u0) + (t0 * du1 - t1 * du0)
        dcv[0, k] = h * (cn * du0 + sn * dw0)
        dcv[1, k] = h * (cn * du1 + sn * dw1)
        dcv[2, k] = h * (cn * du2 + sn * dw2)
    _curvature_row(0, u0, w0, h, dh_dpsi1, cn, sn, s1, lc, cv, dcv)
    _curvature_row(1, u1, w1, h, dh_dpsi1, cn, sn, s1, lc, cv, dcv)
    _curvature_row(2, u2, w2, h, dh_dpsi1, cn, sn, s1, lc, cv, dcv)


@njit(cache=True, inline="always")
def _curvature_row(i, ui, wi, h, dh_dpsi1, cn, sn, s1, lc, cv, dcv):
    base = cn * ui + sn * wi
    cv[i] = h * base
    dcv[i, lc] += dh_dpsi1 * base
    dcv[i, lc + 3] += base / abs(s1)
    dcv[i, lc + 4] += h * (-sn * ui + cn * wi)


@njit(cache=True)
def _end_point(pos_x, z, phi, e3, de3, eb, deb, z1, z2, q, dq):
    """q = pos + z1 z cos(phi) e3 + z2 z sin(phi) Eb, pos = (pos_x, 0, 0).

    de3/deb vanish outside the frame columns 1-4, so only those, z, phi and
    pos_x get non-zero entries; the rest of ``dq`` (3, 19) is zeroed."""
    cp, sp = np.cos(phi), np.sin(phi)
    dq[:] = 0.0
    for i in range(3):
        q[i] = z1 * z * cp * e3[i] + z2 * z * sp * eb[i]
        for k in range(L_G, L_TW + 1):
            dq[i, k] = z1 * z * cp * de3[i, k] + z2 * z * sp * deb[i, k]
        dq[i, L_Z] += z1 * cp * e3[i] + z2 * sp * eb[i]
        dq[i, L_PHI] += -z1 * z * sp * e3[i] + z2 * z * cp * eb[i]
    q[0] += pos_x
    dq[0, L_POS] += 1.0


@njit(cache=True)
def control_points_half(q, dq, t, dt, cv, dcv, a, ia, b, ib, at_start, k0, k1, k2, k3, p, dp):
    """Three control points at one end, with their Jacobian (docs/model.md §3).

    ``at_start``: P0 = q, P1 = P0 + a/5 t, P2 = P1 + a^2/20 cv + b t (rows 0-2);
    else P5 = q, P4 = P5 - a/5 t, P3 = P4 + a^2/20 cv - b t (rows 5, 4, 3).
    ``ia``/``ib`` are the Jacobian columns of a and b. Only the columns in
    [k0, k1) and [k2, k3) are written (the caller has zeroed ``dp`` and guarantees
    that dq, dt, dcv vanish elsewhere); a's and b's columns get their extra terms
    last.
    """
    fa = a / 5.0
    ga = a * a / 20.0
    if at_start:
        for i in range(3):
            p[0, i] = q[i]
            p[1, i] = q[i] + fa * t[i]
            p[2, i] = p[1, i] + ga * cv[i] + b * t[i]
            for lo, hi in ((k0, k1), (k2, k3)):
                for k in range(lo, hi):
                    d1 = dq[i, k] + fa * dt[i, k]
                    dp[0, i, k] = dq[i, k]
                    dp[1, i, k] = d1
                    dp[2, i, k] = d1 + ga * dcv[i, k] + b * dt[i, k]
            dp[1, i, ia] += t[i] / 5.0
            dp[2, i, ia] += t[i] / 5.0 + a / 10.0 * cv[i]
            dp[2, i, ib] += t[i]
    else:
        for i in range(3):
            p[5, i] = q[i]
            p[4, i] = q[i] - fa * t[i]
            p[3, i] = p[4, i] + ga * cv[i] - b * t[i]
            for lo, hi in ((k0, k1), (k2, k3)):
                for k in range(lo, hi):
                    d4 = dq[i, k] - fa * dt[i, k]
                    dp[5, i, k] = dq[i, k]
                    dp[4, i, k] = d4
                    dp[3, i, k] = d4 + ga * dcv[i, k] - b * dt[i, k]
            dp[4, i, ia] -= t[i] / 5.0
            dp[3, i, ia] += -t[i] / 5.0 + a / 10.0 * cv[i]
            dp[3, i, ib] -= t[i]


@njit(cache=True)
def control_points_from_ends(
    q0, dq0, t0, dt0, cv0, dcv0, a0, ia0, b0, ib0,
    q1, dq1, t1, dt1, cv1, dcv1, a1, ia1, b1, ib1,
    p, dp,
):  # fmt: skip
    """The control-point rule of docs/model.md §3, with its Jacobian, on all columns.

    P0 = q0, P1 = P0 + a0/5 t0, P2 = P1 + a0^2/20 cv0 + b0 t0, and mirrored at the
    end: P5 = q1, P4 = P5 - a1/5 t1, P3 = P4 + a1^2/20 cv1 - b1 t1. ``ia*``/``ib*``
    are the Jacobian columns of the speeds a and offsets b; ``dp`` is overwritten.
    """
    nl = dp.shape[2]
    dp[:] = 0.0
    z = _i(0)
    control_points_half(q0, dq0, t0, dt0, cv0, dcv0, a0, _i(ia0), b0, _i(ib0), _TRUE, z, nl, z, z,
                        p, dp)  # fmt: skip
    control_points_half(q1, dq1, t1, dt1, cv1, dcv1, a1, _i(ia1), b1, _i(ib1), _FALSE, z, nl, z,
                        z, p, dp)  # fmt: skip


@njit(cache=True)
def crossover_curve_into(pos_x, z, phi, parity, is_a, cond0, cond1, frame, dframe, p, dp,
                         vec, blk):  # fmt: skip
    """``crossover_curve`` with caller-provided scratch: vec (6, 3), blk (6, 3, 19)."""
    if parity > 0:  # (E10, E20, E11, E21) = (T1, T2, e1, e2)
        i10, i20, i11, i21 = 3, 4, 0, 1
    else:  # (e1, e2, T1, T2)
        i10, i20, i11, i21 = 0, 1, 3, 4
    if is_a:
        sa0, sb0, sa1, sb1, sig = 1.0, parity, -1.0, parity, -1.0
    else:
        sa0, sb0, sa1, sb1, sig = -1.0, -parity, 1.0, -parity, 1.0
    e3, de3 = frame[2], dframe[2]
    t0, cv0, q0, t1, cv1, q1 = vec[0], vec[1], vec[2], vec[3], vec[4], vec[5]
    dt0, dcv0, dq0, dt1, dcv1, dq1 = blk[0], blk[1], blk[2], blk[3], blk[4], blk[5]
    _end_direction(frame[i10], dframe[i10], frame[i20], dframe[i20], e3, de3,
                   sa0, sb0, cond0, _i(L_C0), t0, dt0, cv0, dcv0)  # fmt: skip
    _end_direction(frame[i11], dframe[i11], frame[i21], dframe[i21], e3, de3,
                   sa1, sb1, cond1, _i(L_C1), t1, dt1, cv1, dcv1)  # fmt: skip
    _end_point(pos_x, z, phi, e3, de3, frame[i20], dframe[i20], -1.0, sig * parity, q0, dq0)
    _end_point(pos_x, z, phi, e3, de3, frame[i21], dframe[i21], 1.0, -sig * parity, q1, dq1)
    # a start can depend on columns 0-12 (pos, frame, tw, z, phi, start condition),
    # an end on 0-6 and 13-18 (the same with the end condition)
    dp[:] = 0.0
    control_points_half(q0, dq0, t0, dt0, cv0, dcv0, cond0[2], _i(L_C0 + 2), cond0[5],
                        _i(L_C0 + 5), _TRUE, _i(0), _i(L_C1), _i(0), _i(0), p, dp)  # fmt: skip
    control_points_half(q1, dq1, t1, dt1, cv1, dcv1, cond1[2], _i(L_C1 + 2), cond1[5],
                        _i(L_C1 + 5), _FALSE, _i(0), _i(L_C0), _i(L_C1), _i(N_LOCAL), p, dp)  # fmt: skip


@njit(cache=True)
def crossover_curve(pos_x, z, phi, parity, is_a, cond0, cond1, frame, dframe, p, dp):
    """Control points (6, 3) and local Jacobian (6, 3, 19) of curve A or B of a
    crossover with centre (pos_x, 0, 0) (docs/model.md §3)."""
    crossover_curve_into(pos_x, z, phi, parity, is_a, cond0, cond1, frame, dframe, p, dp,
                         np.empty((6, 3)), np.empty((6, 3, N_LOCAL)))  # fmt: skip
