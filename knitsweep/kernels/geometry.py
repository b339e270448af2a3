"""State vector -> the 8 quintic Bézier segments of one stitch cell, with Jacobian.

Implements MODEL.md §2–4. The Jacobian is exact: every step below carries the
derivative of its output with respect to the inputs it depends on (forward-mode
differentiation written out by hand), so ``d(control point)/d(state)`` is the
analytic one, accurate to round-off.

Conventions
-----------
* state ``x``: shape (30,) = (f0, f1, f2, z, phi, S1[6], S2[6], S3[6], tw,
  alpha_c, beta_c, alpha_w, beta_w, a_x, a_y); lengths in mm, angles in rad.
* control points ``cp``: shape (8, 6, 3), segments in path order
  (0 C1.B, 1 cc11, 2 C1.A+t_w, 3 cc12+t_w, 4 C2.A+t_w, 5 cc22, 6 C2.B, 7 cc21).
* Jacobian ``jac``: shape (8, 6, 3, 30), ``jac[s, i, c, k] = d cp[s, i, c] / d x[k]``.

Local Jacobians of one crossover curve use 19 columns:
0 pos_x, 1-3 frame angles (g0, g1, g2), 4 tw, 5 z, 6 phi, 7-12 start
condition, 13-18 end condition.
"""

from __future__ import annotations

import numpy as np
from numba import njit

N_STATE = 30
N_SHAPE = 28
IDX_TW = 23
IDX_AX = 28
IDX_AY = 29
N_SEGMENTS = 8

# local column layout of one crossover curve
_L_POS, _L_G, _L_TW, _L_Z, _L_PHI, _L_C0, _L_C1, _N_LOCAL = 0, 1, 4, 5, 6, 7, 13, 19

# end condition index ranges in the state vector (S1, S2, S3)
S1, S2, S3 = 5, 11, 17


@njit(cache=True)
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(cache=True)
def _rotations(g0, g1, g2):
    """R = R_x(g0) R_y(g1) R_z(g2) and dR/dg_k (MODEL.md §3, R_y transposed)."""
    c0, s0 = np.cos(g0), np.sin(g0)
    c1, s1 = np.cos(g1), np.sin(g1)
    c2, s2 = np.cos(g2), np.sin(g2)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, c0, -s0], [0.0, s0, c0]])
    ry = np.array([[c1, 0.0, -s1], [0.0, 1.0, 0.0], [s1, 0.0, c1]])
    rz = np.array([[c2, -s2, 0.0], [s2, c2, 0.0], [0.0, 0.0, 1.0]])
    drx = np.array([[0.0, 0.0, 0.0], [0.0, -s0, -c0], [0.0, c0, -s0]])
    dry = np.array([[-s1, 0.0, -c1], [0.0, 0.0, 0.0], [c1, 0.0, -s1]])
    drz = np.array([[-s2, -c2, 0.0], [c2, -s2, 0.0], [0.0, 0.0, 0.0]])
    r = rx @ ry @ rz
    dr = np.empty((3, 3, 3))
    dr[0] = drx @ ry @ rz
    dr[1] = rx @ dry @ rz
    dr[2] = rx @ ry @ drz
    return r, dr


@njit(cache=True)
def crossover_frame(g0, g1, g2, tw, frame, dframe):
    """Frame vectors e1, e2, e3, T1, T2 (rows of ``frame``, shape (5, 3)).

    ``dframe`` (5, 3, 19) receives their derivatives in the local columns
    1-3 (frame angles) and 4 (tw).
    """
    r, dr = _rotations(g0, g1, g2)
    ct, st = np.cos(tw), np.sin(tw)
    dframe[:] = 0.0
    for i in range(3):
        # e3 = R(1,0,0), e1 = R(0,1,0), e2 = R(0,0,1)
        frame[2, i] = r[i, 0]
        frame[0, i] = r[i, 1]
        frame[1, i] = r[i, 2]
        for k in range(3):
            dframe[2, i, _L_G + k] = dr[k, i, 0]
            dframe[0, i, _L_G + k] = dr[k, i, 1]
            dframe[1, i, _L_G + k] = dr[k, i, 2]
    for i in range(3):
        frame[3, i] = frame[0, i] * ct + frame[1, i] * st
        frame[4, i] = -frame[0, i] * st + frame[1, i] * ct
        for k in range(3):
            col = _L_G + k
            dframe[3, i, col] = dframe[0, i, col] * ct + dframe[1, i, col] * st
            dframe[4, i, col] = -dframe[0, i, col] * st + dframe[1, i, col] * ct
        dframe[3, i, _L_TW] = frame[4, i]
        dframe[4, i, _L_TW] = -frame[3, i]


@njit(cache=True)
def _end_direction(ea, dea, eb, deb, e3, de3, sa, sb, cond, lc, t, dt, cv, dcv):
    """Unit tangent and curvature vector at one crossover end (MODEL.md §3).

    ``t = sa|cos psi1| Ea + sb|sin psi1 sin psi2| Eb + |sin psi1 cos psi2| e3`` and
    ``cv = kappa [(Ea x t) cos nu + (t x (Ea x t)) sin nu] / |sin psi1|``;
    ``cond`` = (psi1, psi2, alpha, kappa, nu, beta) sits in local columns lc..lc+5.
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
    for i in range(3):
        t[i] = a * ea[i] + b * eb[i] + c * e3[i]
        for k in range(nl):
            dt[i, k] = a * dea[i, k] + b * deb[i, k] + c * de3[i, k]
        dt[i, lc] += da1 * ea[i] + db1 * eb[i] + dc1 * e3[i]
        dt[i, lc + 1] += db2 * eb[i] + dc2 * e3[i]

    u = np.empty(3)
    w = np.empty(3)
    _cross(ea, t, u)
    _cross(t, u, w)
    h = kappa / abs(s1)
    dh_dpsi1 = -kappa * np.sign(s1) * c1 / (s1 * s1)
    cn, sn = np.cos(nu), np.sin(nu)
    du = np.empty(3)
    dw = np.empty(3)
    tmp = np.empty(3)
    dcol = np.empty(3)
    for k in range(nl):
        # du = dEa x t + Ea x dt ; dw = dt x u + t x du
        _cross(dea[:, k], t, du)
        _cross(ea, dt[:, k], tmp)
        for i in range(3):
            du[i] += tmp[i]
        _cross(dt[:, k], u, dw)
        _cross(t, du, tmp)
        for i in range(3):
            dcol[i] = dw[i] + tmp[i]
            dcv[i, k] = h * (cn * du[i] + sn * dcol[i])
    for i in range(3):
        base = cn * u[i] + sn * w[i]
        cv[i] = h * base
        dcv[i, lc] += dh_dpsi1 * base
        dcv[i, lc + 3] += base / abs(s1)
        dcv[i, lc + 4] += h * (-sn * u[i] + cn * w[i])


@njit(cache=True)
def _end_point(pos_x, z, phi, e3, de3, eb, deb, z1, z2, q, dq):
    """q = pos + z1 z cos(phi) e3 + z2 z sin(phi) Eb, pos = (pos_x, 0, 0)."""
    cp, sp = np.cos(phi), np.sin(phi)
    nl = dq.shape[1]
    for i in range(3):
        q[i] = z1 * z * cp * e3[i] + z2 * z * sp * eb[i]
        for k in range(nl):
            dq[i, k] = z1 * z * cp * de3[i, k] + z2 * z * sp * deb[i, k]
        dq[i, _L_Z] += z1 * cp * e3[i] + z2 * sp * eb[i]
        dq[i, _L_PHI] += -z1 * z * sp * e3[i] + z2 * z * cp * eb[i]
    q[0] += pos_x
    dq[0, _L_POS] += 1.0


@njit(cache=True)
def control_points_from_ends(
    q0, dq0, t0, dt0, cv0, dcv0, a0, ia0, b0, ib0,
    q1, dq1, t1, dt1, cv1, dcv1, a1, ia1, b1, ib1,
    p, dp,
):  # fmt: skip
    """The control-point rule of MODEL.md §3, with its Jacobian.

    P0 = q0, P1 = P0 + a0/5 t0, P2 = P1 + a0^2/20 cv0 + b0 t0, and mirrored at the
    end: P5 = q1, P4 = P5 - a1/5 t1, P3 = P4 + a1^2/20 cv1 - b1 t1. ``ia*``/``ib*``
    are the Jacobian columns of the speeds a and offsets b; ``dp`` is overwritten.
    """
    nl = dp.shape[2]
    for i in range(3):
        p[0, i] = q0[i]
        p[1, i] = q0[i] + a0 / 5.0 * t0[i]
        p[2, i] = p[1, i] + a0 * a0 / 20.0 * cv0[i] + b0 * t0[i]
        p[5, i] = q1[i]
        p[4, i] = q1[i] - a1 / 5.0 * t1[i]
        p[3, i] = p[4, i] + a1 * a1 / 20.0 * cv1[i] - b1 * t1[i]
        for k in range(nl):
            dp[0, i, k] = dq0[i, k]
            dp[1, i, k] = dq0[i, k] + a0 / 5.0 * dt0[i, k]
            dp[2, i, k] = dp[1, i, k] + a0 * a0 / 20.0 * dcv0[i, k] + b0 * dt0[i, k]
            dp[5, i, k] = dq1[i, k]
            dp[4, i, k] = dq1[i, k] - a1 / 5.0 * dt1[i, k]
            dp[3, i, k] = dp[4, i, k] + a1 * a1 / 20.0 * dcv1[i, k] - b1 * dt1[i, k]
        dp[1, i, ia0] += t0[i] / 5.0
        dp[2, i, ia0] += t0[i] / 5.0 + a0 / 10.0 * cv0[i]
        dp[2, i, ib0] += t0[i]
        dp[4, i, ia1] -= t1[i] / 5.0
        dp[3, i, ia1] += -t1[i] / 5.0 + a1 / 10.0 * cv1[i]
        dp[3, i, ib1] -= t1[i]


@njit(cache=True)
def crossover_curve(pos_x, z, phi, parity, is_a, cond0, cond1, frame, dframe, p, dp):
    """Control points (6, 3) and local Jacobian (6, 3, 19) of curve A or B of a
    crossover with centre (pos_x, 0, 0) (MODEL.md §3)."""
    if parity > 0:  # (E10, E20, E11, E21) = (T1, T2, e1, e2)
        i10, i20, i11, i21 = 3, 4, 0, 1
    else:  # (e1, e2, T1, T2)
        i10, i20, i11, i21 = 0, 1, 3, 4
    if is_a:
        sa0, sb0, sa1, sb1, sig = 1.0, parity, -1.0, parity, -1.0
    else:
        sa0, sb0, sa1, sb1, sig = -1.0, -parity, 1.0, -parity, 1.0
    e3, de3 = frame[2], dframe[2]
    t0, cv0, q0 = np.empty(3), np.empty(3), np.empty(3)
    t1, cv1, q1 = np.empty(3), np.empty(3), np.empty(3)
    dt0, dcv0, dq0 = np.empty((3, _N_LOCAL)), np.empty((3, _N_LOCAL)), np.empty((3, _N_LOCAL))
    dt1, dcv1, dq1 = np.empty((3, _N_LOCAL)), np.empty((3, _N_LOCAL)), np.empty((3, _N_LOCAL))
    _end_direction(frame[i10], dframe[i10], frame[i20], dframe[i20], e3, de3,
                   sa0, sb0, cond0, _L_C0, t0, dt0, cv0, dcv0)  # fmt: skip
    _end_direction(frame[i11], dframe[i11], frame[i21], dframe[i21], e3, de3,
                   sa1, sb1, cond1, _L_C1, t1, dt1, cv1, dcv1)  # fmt: skip
    _end_point(pos_x, z, phi, e3, de3, frame[i20], dframe[i20], -1.0, sig * parity, q0, dq0)
    _end_point(pos_x, z, phi, e3, de3, frame[i21], dframe[i21], 1.0, -sig * parity, q1, dq1)
    control_points_from_ends(
        q0, dq0, t0, dt0, cv0, dcv0, cond0[2], _L_C0 + 2, cond0[5], _L_C0 + 5,
        q1, dq1, t1, dt1, cv1, dcv1, cond1[2], _L_C1 + 2, cond1[5], _L_C1 + 5,
        p, dp,
    )  # fmt: skip


@njit(cache=True)
def _scatter(dp_local, cols, factors, out):
    """Map a local (6, 3, 19) Jacobian to the 30 state columns."""
    out[:] = 0.0
    for j in range(_N_LOCAL):
        col, f = cols[j], factors[j]
        for i in range(6):
            for c in range(3):
                out[i, c, col] += f * dp_local[i, c, j]


@njit(cache=True)
def _local_map(sign_x, flip, c0, c1):
    cols = np.empty(_N_LOCAL, dtype=np.int64)
    fac = np.ones(_N_LOCAL)
    cols[_L_POS], fac[_L_POS] = IDX_AX, 0.25 * sign_x
    cols[_L_G], cols[_L_G + 1], cols[_L_G + 2] = 0, 1, 2
    fac[_L_G + 1] = flip
    fac[_L_G + 2] = flip
    cols[_L_TW], cols[_L_Z], cols[_L_PHI] = IDX_TW, 3, 4
    for j in range(6):
        cols[_L_C0 + j] = c0 + j
        cols[_L_C1 + j] = c1 + j
    return cols, fac


@njit(cache=True)
def _end_frame(q, dq, at_end, t, dt, cv, dcv):
    """Unit tangent and curvature vector of a Bézier at t = 1 (``at_end``) or 0.

    T = r'/|r'|, cv = (r'' - (r''.T) T)/|r'|^2 (MODEL.md §4), with derivatives
    dT = P dr'/v and dcv = P dr''/v^2 - [T m^T + (r''.T) P + 2 m T^T] dr'/v^3,
    where P = I - T T^T and m = P r''.
    """
    r1 = np.empty(3)
    r2 = np.empty(3)
    nl = dq.shape[2]
    dr1 = np.empty((3, nl))
    dr2 = np.empty((3, nl))
    if at_end:
        for i in range(3):
            r1[i] = 5.0 * (q[5, i] - q[4, i])
            r2[i] = 20.0 * (q[5, i] - 2.0 * q[4, i] + q[3, i])
            for k in range(nl):
                dr1[i, k] = 5.0 * (dq[5, i, k] - dq[4, i, k])
                dr2[i, k] = 20.0 * (dq[5, i, k] - 2.0 * dq[4, i, k] + dq[3, i, k])
    else:
        for i in range(3):
            r1[i] = 5.0 * (q[1, i] - q[0, i])
            r2[i] = 20.0 * (q[2, i] - 2.0 * q[1, i] + q[0, i])
            for k in range(nl):
                dr1[i, k] = 5.0 * (dq[1, i, k] - dq[0, i, k])
                dr2[i, k] = 20.0 * (dq[2, i, k] - 2.0 * dq[1, i, k] + dq[0, i, k])
    v = np.sqrt(r1[0] ** 2 + r1[1] ** 2 + r1[2] ** 2)
    for i in range(3):
        t[i] = r1[i] / v
    nt = r2[0] * t[0] + r2[1] * t[1] + r2[2] * t[2]
    m = np.empty(3)
    for i in range(3):
        m[i] = r2[i] - nt * t[i]
        cv[i] = m[i] / (v * v)
    proj = np.empty((3, 3))
    big = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            d = 1.0 if i == j else 0.0
            proj[i, j] = d - t[i] * t[j]
            big[i, j] = t[i] * m[j] + nt * proj[i, j] + 2.0 * m[i] * t[j]
    iv, iv2, iv3 = 1.0 / v, 1.0 / (v * v), 1.0 / (v * v * v)
    for i in range(3):
        for k in range(nl):
            s1 = 0.0
            s2 = 0.0
            s3 = 0.0
            for j in range(3):
                s1 += proj[i, j] * dr1[j, k]
                s2 += proj[i, j] * dr2[j, k]
                s3 += big[i, j] * dr1[j, k]
            dt[i, k] = s1 * iv
            dcv[i, k] = s2 * iv2 - s3 * iv3


@njit(cache=True)
def _connector(qa, dqa, qb, dqb, shift_a, shift_b, ia, ib, x, p, dp):
    """Connector from the end of curve ``qa`` (+ shift_a) to the start of ``qb``
    (+ shift_b); shifts are 0 none, 1 t_c, 2 t_w (MODEL.md §4)."""
    t0, cv0, t1, cv1 = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    dt0, dcv0 = np.empty((3, N_STATE)), np.empty((3, N_STATE))
    dt1, dcv1 = np.empty((3, N_STATE)), np.empty((3, N_STATE))
    _end_frame(qa, dqa, True, t0, dt0, cv0, dcv0)
    _end_frame(qb, dqb, False, t1, dt1, cv1, dcv1)
    q0 = qa[5].copy()
    dq0 = dqa[5].copy()
    q1 = qb[0].copy()
    dq1 = dqb[0].copy()
    _apply_shift(q0, dq0, shift_a, x)
    _apply_shift(q1, dq1, shift_b, x)
    a, b = x[ia], x[ib]
    control_points_from_ends(q0, dq0, t0, dt0, cv0, dcv0, a, ia, b, ib,
                             q1, dq1, t1, dt1, cv1, dcv1, a, ia, b, ib, p, dp)  # fmt: skip


@njit(cache=True)
def _apply_shift(q, dq, shift, x):
    if shift == 1:
        q[0] += x[IDX_AX]
        dq[0, IDX_AX] += 1.0
    elif shift == 2:
        q[1] += x[IDX_AY]
        dq[1, IDX_AY] += 1.0


@njit(cache=True)
def state_to_control_points(x, cp, jac):
    """Fill ``cp`` (8, 6, 3) and ``jac`` (8, 6, 3, 30) from the state ``x`` (30,)."""
    frame = np.empty((5, 3))
    dframe = np.empty((5, 3, _N_LOCAL))
    p_loc = np.empty((6, 3))
    dp_loc = np.empty((6, 3, _N_LOCAL))
    curves = np.empty((4, 6, 3))  # C1.A, C1.B, C2.A, C2.B
    dcurves = np.empty((4, 6, 3, N_STATE))
    ax = x[IDX_AX]
    tw, z, phi = x[IDX_TW], x[3], x[4]
    # (crossover, parity, frame flip, x sign); C2 mirrors C1 (MODEL.md §3)
    for ic in range(2):
        parity = 1.0 if ic == 0 else -1.0
        flip = 1.0 if ic == 0 else -1.0
        pos_x = -ax / 4.0 if ic == 0 else ax / 4.0
        crossover_frame(x[0], flip * x[1], flip * x[2], tw, frame, dframe)
        for ab in range(2):
            is_a = ab == 0
            if ic == 0:
                c0, c1 = (S1, S2) if is_a else (S3, S1)
            else:
                c0, c1 = (S2, S1) if is_a else (S1, S3)
            crossover_curve(pos_x, z, phi, parity, is_a, x[c0 : c0 + 6], x[c1 : c1 + 6],
                            frame, dframe, p_loc, dp_loc)  # fmt: skip
            cols, fac = _local_map(-parity, flip, c0, c1)
            k = 2 * ic + ab
            curves[k] = p_loc
            _scatter(dp_loc, cols, fac, dcurves[k])
    c1a, c1b, c2a, c2b = 0, 1, 2, 3
    conn = np.empty((4, 6, 3))
    dconn = np.empty((4, 6, 3, N_STATE))
    # cc12: C1.A end -> C2.A start; cc21: C2.B end -> C1.B start + t_c
    _connector(curves[c1a], dcurves[c1a], curves[c2a], dcurves[c2a], 0, 0, 24, 25, x,
               conn[0], dconn[0])  # fmt: skip
    _connector(curves[c2b], dcurves[c2b], curves[c1b], dcurves[c1b], 0, 1, 24, 25, x,
               conn[1], dconn[1])  # fmt: skip
    # cc11: C1.B end -> C1.A start + t_w; cc22: C2.A end + t_w -> C2.B start
    _connector(curves[c1b], dcurves[c1b], curves[c1a], dcurves[c1a], 0, 2, 26, 27, x,
               conn[2], dconn[2])  # fmt: skip
    _connector(curves[c2a], dcurves[c2a], curves[c2b], dcurves[c2b], 2, 0, 26, 27, x,
               conn[3], dconn[3])  # fmt: skip
    # path order: C1.B, cc11, C1.A+t_w, cc12+t_w, C2.A+t_w, cc22, C2.B, cc21
    cp[0], jac[0] = curves[c1b], dcurves[c1b]
    cp[1], jac[1] = conn[2], dconn[2]
    cp[2], jac[2] = curves[c1a], dcurves[c1a]
    cp[3], jac[3] = conn[0], dconn[0]
    cp[4], jac[4] = curves[c2a], dcurves[c2a]
    cp[5], jac[5] = conn[3], dconn[3]
    cp[6], jac[6] = curves[c2b], dcurves[c2b]
    cp[7], jac[7] = conn[1], dconn[1]
    ay = x[IDX_AY]
    for s in (2, 3, 4):
        for i in range(6):
            cp[s, i, 1] += ay
            jac[s, i, 1, IDX_AY] += 1.0
