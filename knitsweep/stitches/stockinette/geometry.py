"""Stockinette state -> the 8 quintic Bézier segments of one stitch cell, with Jacobian.

Implements docs/model.md §2–4: the two crossovers come from ``crossover`` (§3), the
four connectors and the path order from here (§4). The Jacobian is exact: every
step carries the derivative of its output with respect to the inputs it depends
on (forward-mode differentiation written out by hand), so
``d(control point)/d(state)`` is the analytic one, accurate to round-off.

Conventions
-----------
* state ``x``: shape (30,) = (f0, f1, f2, z, phi, S1[6], S2[6], S3[6], tw,
  alpha_c, beta_c, alpha_w, beta_w, a_x, a_y); lengths in mm, angles in rad.
* control points ``cp``: shape (8, 6, 3), segments in path order
  (0 C1.B, 1 cc11, 2 C1.A+t_w, 3 cc12+t_w, 4 C2.A+t_w, 5 cc22, 6 C2.B, 7 cc21).
* Jacobian ``jac``: shape (8, 6, 3, 30), ``jac[s, i, c, k] = d cp[s, i, c] / d x[k]``.

Speed: one call allocates a few scratch arrays, writes the crossover curves
straight into their slots of ``cp``/``jac``, builds the connectors from those
slots, and spells out 3x3 products in scalars (no BLAS calls in the hot path).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ... import kernels  # noqa: F401  (first: it points numba's cache at this version's)
from .crossover import (  # noqa: F401  (re-exported: the public kernel names)
    L_C0,
    L_C1,
    L_G,
    L_PHI,
    L_POS,
    L_TW,
    L_Z,
    N_LOCAL,
    control_points_from_ends,
    control_points_half,
    crossover_curve,
    crossover_curve_into,
    crossover_frame,
)
from .layout import IDX_AX, IDX_AY, IDX_TW, N_STATE, S1, S2, S3

# path slots of the crossover curves and connectors (docs/model.md §4)
_SEG_C1B, _SEG_CC11, _SEG_C1A, _SEG_CC12, _SEG_C2A, _SEG_CC22, _SEG_C2B, _SEG_CC21 = range(8)

# the four connectors, in the order they are built (docs/model.md §4): (from slot, to
# slot, shift of its start, shift of its end, state columns of the speed a and
# offset b, connector's slot); shifts 0 none, 1 t_c, 2 t_w.
# cc12: C1.A end -> C2.A start; cc21: C2.B end -> C1.B start + t_c;
# cc11: C1.B end -> C1.A start + t_w; cc22: C2.A end + t_w -> C2.B start
_CONNECTORS = np.array([
    (_SEG_C1A, _SEG_C2A, 0, 0, 24, 25, _SEG_CC12),
    (_SEG_C2B, _SEG_C1B, 0, 1, 24, 25, _SEG_CC21),
    (_SEG_C1B, _SEG_C1A, 0, 2, 26, 27, _SEG_CC11),
    (_SEG_C2A, _SEG_C2B, 2, 0, 26, 27, _SEG_CC22),
], dtype=np.int64)  # fmt: skip
_i, _TRUE, _FALSE = np.int64, np.bool_(True), np.bool_(False)  # see crossover.py: no literals


@njit(cache=True)
def _scatter(dp_local, sign_x, flip, c0, c1, out):
    """Map a local (6, 3, 19) Jacobian to the 30 state columns of ``out`` (6, 3, 30).

    Local columns map one-to-one to distinct state columns, scaled by exact factors
    (a_x/4 for the centre, the frame flip of C2 for g1 and g2)."""
    fx = 0.25 * sign_x
    for i in range(6):
        for c in range(3):
            src = dp_local[i, c]
            dst = out[i, c]
            dst[:] = 0.0
            dst[IDX_AX] = fx * src[L_POS]
            dst[0] = src[L_G]
            dst[1] = flip * src[L_G + 1]
            dst[2] = flip * src[L_G + 2]
            dst[IDX_TW] = src[L_TW]
            dst[3] = src[L_Z]
            dst[4] = src[L_PHI]
            for j in range(6):
                dst[c0 + j] = src[L_C0 + j]
                dst[c1 + j] = src[L_C1 + j]


@njit(cache=True)
def _end_frame(q, dq, at_end, t, dt, cv, dcv, dr1, dr2):
    """Unit tangent and curvature vector of a Bézier at t = 1 (``at_end``) or 0.

    T = r'/|r'|, cv = (r'' - (r''.T) T)/|r'|^2 (docs/model.md §4), with derivatives
    dT = P dr'/v and dcv = P dr''/v^2 - [T m^T + (r''.T) P + 2 m T^T] dr'/v^3,
    where P = I - T T^T and m = P r''. ``dr1``, ``dr2`` (3, 30) are scratch.
    """
    nl = dq.shape[2]
    # r' = 5 (q[ia] - q[ib]) and r'' = 20 (q[ja] - 2 q[jb] + q[jc]) at this end
    if at_end:
        ia, ib, ja, jb, jc = 5, 4, 5, 4, 3
    else:
        ia, ib, ja, jb, jc = 1, 0, 2, 1, 0
    for i in range(3):
        for k in range(nl):
            dr1[i, k] = 5.0 * (dq[ia, i, k] - dq[ib, i, k])
            dr2[i, k] = 20.0 * (dq[ja, i, k] - 2.0 * dq[jb, i, k] + dq[jc, i, k])
    r10 = 5.0 * (q[ia, 0] - q[ib, 0])
    r11 = 5.0 * (q[ia, 1] - q[ib, 1])
    r12 = 5.0 * (q[ia, 2] - q[ib, 2])
    r20 = 20.0 * (q[ja, 0] - 2.0 * q[jb, 0] + q[jc, 0])
    r21 = 20.0 * (q[ja, 1] - 2.0 * q[jb, 1] + q[jc, 1])
    r22 = 20.0 * (q[ja, 2] - 2.0 * q[jb, 2] + q[jc, 2])
    v = np.sqrt(r10**2 + r11**2 + r12**2)
    ta, tb, tc = r10 / v, r11 / v, r12 / v
    nt = r20 * ta + r21 * tb + r22 * tc
    ma, mb, mc = r20 - nt * ta, r21 - nt * tb, r22 - nt * tc
    v2 = v * v
    t[0], t[1], t[2] = ta, tb, tc
    cv[0], cv[1], cv[2] = ma / v2, mb / v2, mc / v2
    iv, iv2, iv3 = 1.0 / v, 1.0 / (v * v), 1.0 / (v * v * v)
    # P = I - T T^T and B = T m^T + nt P + 2 m T^T, row by row
    tt = (ta, tb, tc)
    mm = (ma, mb, mc)
    for i in range(3):
        ti, mi = tt[i], mm[i]
        p0 = (1.0 if i == 0 else 0.0) - ti * ta
        p1 = (1.0 if i == 1 else 0.0) - ti * tb
        p2 = (1.0 if i == 2 else 0.0) - ti * tc
        b0 = ti * ma + nt * p0 + 2.0 * mi * ta
        b1 = ti * mb + nt * p1 + 2.0 * mi * tb
        b2 = ti * mc + nt * p2 + 2.0 * mi * tc
        for k in range(nl):
            s1 = p0 * dr1[0, k] + p1 * dr1[1, k] + p2 * dr1[2, k]
            s2 = p0 * dr2[0, k] + p1 * dr2[1, k] + p2 * dr2[2, k]
            s3 = b0 * dr1[0, k] + b1 * dr1[1, k] + b2 * dr1[2, k]
            dt[i, k] = s1 * iv
            dcv[i, k] = s2 * iv2 - s3 * iv3


@njit(cache=True)
def _connector(qa, dqa, qb, dqb, shift_a, shift_b, ia, ib, x, p, dp, vec, blk):
    """Connector from the end of curve ``qa`` (+ shift_a) to the start of ``qb``
    (+ shift_b); shifts are 0 none, 1 t_c, 2 t_w (docs/model.md §4).
    Scratch: vec (6, 3), blk (8, 3, 30)."""
    t0, cv0, t1, cv1, q0, q1 = vec[0], vec[1], vec[2], vec[3], vec[4], vec[5]
    dt0, dcv0, dt1, dcv1, dr1, dr2, dq0, dq1 = (blk[0], blk[1], blk[2], blk[3], blk[4], blk[5],
                                                blk[6], blk[7])  # fmt: skip
    _end_frame(qa, dqa, _TRUE, t0, dt0, cv0, dcv0, dr1, dr2)
    _end_frame(qb, dqb, _FALSE, t1, dt1, cv1, dcv1, dr1, dr2)
    # element by element: an array slice assignment would compile numba's
    # shape-mismatch error path (string formatting, ~1.5 s of compile time)
    nl = dp.shape[2]
    for i in range(3):
        q0[i] = qa[5, i]
        q1[i] = qb[0, i]
        for k in range(nl):
            dq0[i, k] = dqa[5, i, k]
            dq1[i, k] = dqb[0, i, k]
    _apply_shift(q0, dq0, shift_a, x)
    _apply_shift(q1, dq1, shift_b, x)
    a, b = x[ia], x[ib]
    dp[:] = 0.0
    z = _i(0)
    control_points_half(q0, dq0, t0, dt0, cv0, dcv0, a, ia, b, ib, _TRUE, z, nl, z, z, p, dp)
    control_points_half(q1, dq1, t1, dt1, cv1, dcv1, a, ia, b, ib, _FALSE, z, nl, z, z, p, dp)


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
    """Fill ``cp`` (8, 6, 3) and ``jac`` (8, 6, 3, 30) from the state ``x`` (30,).

    The crossover curves go straight into their path slots (0, 2, 4, 6), the
    connectors are built from those slots, and the wale shift t_w of slots 2-4 is
    added last, exactly as in docs/model.md §4.
    """
    frame = np.empty((5, 3))
    dframe = np.empty((5, 3, N_LOCAL))
    vec = np.empty((6, 3))  # scratch vectors (tangents, curvature vectors, end points)
    blk19 = np.empty((12, 3, N_LOCAL))  # 6 blocks of scratch + the local Jacobian (6, 3, 19)
    blk30 = np.empty((8, 3, N_STATE))
    p_loc = np.empty((6, 3))
    dp_loc = blk19[6:]
    ax = x[IDX_AX]
    tw, z, phi = x[IDX_TW], x[3], x[4]
    # (crossover, parity, frame flip, x sign); C2 mirrors C1 (docs/model.md §3)
    for ic in range(2):
        parity = 1.0 if ic == 0 else -1.0
        flip = 1.0 if ic == 0 else -1.0
        pos_x = -ax / 4.0 if ic == 0 else ax / 4.0
        crossover_frame(x[0], flip * x[1], flip * x[2], tw, frame, dframe)
        for ab in range(2):
            is_a = ab == 0
            if ic == 0:
                c0, c1 = (S1, S2) if is_a else (S3, S1)
                seg = _SEG_C1A if is_a else _SEG_C1B
            else:
                c0, c1 = (S2, S1) if is_a else (S1, S3)
                seg = _SEG_C2A if is_a else _SEG_C2B
            crossover_curve_into(pos_x, z, phi, parity, is_a, x[c0 : c0 + 6], x[c1 : c1 + 6],
                                 frame, dframe, p_loc, dp_loc, vec, blk19)  # fmt: skip
            for i in range(6):  # element by element, as in _connector
                for d in range(3):
                    cp[seg, i, d] = p_loc[i, d]
            _scatter(dp_loc, -parity, flip, c0, c1, jac[seg])
    # one call site, its integers from a table: one specialisation of _connector
    for j in range(4):
        row = _CONNECTORS[j]
        sa, sb, out = row[0], row[1], row[6]
        _connector(cp[sa], jac[sa], cp[sb], jac[sb], row[2], row[3], row[4], row[5], x,
                   cp[out], jac[out], vec, blk30)  # fmt: skip
    ay = x[IDX_AY]
    for s in (2, 3, 4):
        for i in range(6):
            cp[s, i, 1] += ay
            jac[s, i, 1, IDX_AY] += 1.0
