"""Free periodic yarn state -> the 8 quintic Bézier segments of the cell, with Jacobian.

Implements docs/model.md §11 with the control-point rule of §3: segment s runs from
joint s to joint s + 1 (segment 7 to joint 0 + t_c). At a joint with point p, unit
tangent t and curvature vector cv, the segment that leaves it has

    P0 = p,   P1 = p + (α0/5) t,   P2 = p + (α0/5 + β0) t + (α0²/20) cv

and the segment that reaches it, with σ = −1 in place of +1,

    P5 = p,   P4 = p − (α1/5) t,   P3 = p − (α1/5 + β1) t + (α1²/20) cv,

so both leave or reach p with tangent t and curvature vector cv: G2 by construction.
t = (sin θ cos φ, sin θ sin φ, cos θ), cv = k1 e_θ + k2 e_φ with e_θ = ∂t/∂θ,
e_φ = (−sin φ, cos φ, 0); their derivatives (∂e_θ/∂θ = −t, ∂e_θ/∂φ = cos θ e_φ,
∂e_φ/∂φ = −sin θ t − cos θ e_θ) are written out, so the Jacobian is exact.

Conventions: state ``x`` (87,) as in ``layout``; ``cp`` (8, 6, 3) mm in path order;
``jac`` (8, 6, 3, 87), ``jac[s, i, c, k] = d cp[s, i, c] / d x[k]``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ... import kernels  # noqa: F401  (first: it points numba's cache at this version's)
from .layout import JOINT0, PER_JOINT, PER_SEGMENT


@njit(cache=True)
def _joint_frame(x, j, fr):
    """Joint j's frame into ``fr`` (8, 3): rows p, t, cv, dt/dθ, dt/dφ, dcv/dθ,
    dcv/dφ, e_φ (e_θ = dt/dθ is row 3); returns the column of its first angle θ and
    the column of its point (−1 for joint 0, pinned at the origin)."""
    if j == 0:
        ip, ia = -1, 0
        fr[0, :] = 0.0
    else:
        ip = JOINT0 + PER_JOINT * (j - 1)
        ia = ip + 3
        for c in range(3):
            fr[0, c] = x[ip + c]
    th, ph, k1, k2 = x[ia], x[ia + 1], x[ia + 2], x[ia + 3]
    st, ct, sp, cph = np.sin(th), np.cos(th), np.sin(ph), np.cos(ph)
    t = (st * cph, st * sp, ct)
    eth = (ct * cph, ct * sp, -st)
    eph = (-sp, cph, 0.0)
    for c in range(3):
        fr[1, c] = t[c]
        fr[2, c] = k1 * eth[c] + k2 * eph[c]
        fr[3, c] = eth[c]
        fr[4, c] = st * eph[c]
        fr[5, c] = -k1 * t[c]
        fr[6, c] = k1 * ct * eph[c] - k2 * (st * t[c] + ct * eth[c])
        fr[7, c] = eph[c]
    return ia, ip


@njit(cache=True)
def _half(x, fr, ia, ip, ib, sigma, slots, cp, jac):
    """Control points ``slots`` (3,) = (on the joint, first, second) of one segment end,
    from the joint frame ``fr`` (``_joint_frame``) and the end's (α, β) at columns
    ``ib``, ``ib + 1``; ``sigma`` +1 where the segment leaves the joint, −1 where it
    reaches it. Writes cp[slot] (3,) and jac[slot] (3, n) (columns of this end only:
    the caller zeroes jac first)."""
    a, b = x[ib], x[ib + 1]
    c1 = sigma * a / 5.0  # P1 - p = c1 t
    c2 = sigma * (a / 5.0 + b)  # P2 - p = c2 t + q cv
    q = a * a / 20.0
    s0, s1, s2 = slots[0], slots[1], slots[2]
    for c in range(3):
        p, t, cv = fr[0, c], fr[1, c], fr[2, c]
        cp[s0, c] = p
        cp[s1, c] = p + c1 * t
        cp[s2, c] = p + c2 * t + q * cv
        if ip >= 0:
            for s in (s0, s1, s2):
                jac[s, c, ip + c] = 1.0
        # angles θ, φ and curvature components k1, k2
        jac[s1, c, ia] = c1 * fr[3, c]
        jac[s1, c, ia + 1] = c1 * fr[4, c]
        jac[s2, c, ia] = c2 * fr[3, c] + q * fr[5, c]
        jac[s2, c, ia + 1] = c2 * fr[4, c] + q * fr[6, c]
        jac[s2, c, ia + 2] = q * fr[3, c]
        jac[s2, c, ia + 3] = q * fr[7, c]
        # this end's speed and offset
        jac[s1, c, ib] = sigma * t / 5.0
        jac[s2, c, ib] = sigma * t / 5.0 + (a / 10.0) * cv
        jac[s2, c, ib + 1] = sigma * t


@njit(cache=True)
def state_to_control_points(x, cp, jac):
    """Fill ``cp`` (8, 6, 3) and ``jac`` (8, 6, 3, 87) from the free state ``x`` (87,)
    (docs/model.md §11); segment 7 ends at joint 0 shifted by t_c = (a_x, 0, 0)."""
    closed_control_points(x, cp, jac, False)


@njit(cache=True)
def closed_control_points(x, cp, jac, mirrored):
    """``state_to_control_points``, the course closing by a translation (``mirrored``
    False) or through a glide (True: segment 7 ends at M joint 0 + t_c with joint 0's
    frame mirrored, M = diag(1, 1, -1), as in rib; joint 0 is at the origin, so
    M joint 0 = joint 0)."""
    chain_control_points(x, cp, jac, mirrored, 1.0)


@njit(cache=True)
def chain_control_points(x, cp, jac, mirrored, cx):
    """``closed_control_points`` of a closed chain of S = ``cp.shape[0]`` segments (S
    joints, ``layout.chain_names(S)``), its last segment ending at joint 0 shifted by
    (cx a_x, 0, 0): a chart's row of cx stitches of period a_x each
    (``stitches.charts``); cx = 1 and S = 8 is the stitch of ``closed_control_points``."""
    n_seg = cp.shape[0]
    seg0 = JOINT0 + PER_JOINT * (n_seg - 1)
    fr = np.empty((8, 3))
    start_slots = np.array([0, 1, 2])
    end_slots = np.array([5, 4, 3])
    jac[:] = 0.0
    for j in range(n_seg):
        ia, ip = _joint_frame(x, j, fr)
        s_out = j  # the segment leaving joint j
        s_in = (j - 1) % n_seg  # the segment reaching it
        b_out = seg0 + PER_SEGMENT * s_out
        b_in = seg0 + PER_SEGMENT * s_in + 2
        _half(x, fr, ia, ip, b_out, 1.0, start_slots, cp[s_out], jac[s_out])
        if j == 0 and mirrored:  # the mirrored frame: M t, M cv and their derivatives
            for row in range(1, 8):
                fr[row, 2] = -fr[row, 2]
        _half(x, fr, ia, ip, b_in, -1.0, end_slots, cp[s_in], jac[s_in])
    last = n_seg - 1
    iax = seg0 + PER_SEGMENT * n_seg
    for i in (3, 4, 5):
        cp[last, i, 0] += cx * x[iax]
        jac[last, i, 0, iax] += cx


@njit(cache=True)
def lifted_control_points(x, cp, jac, cx):
    """``chain_control_points`` (closing by a translation) of a state whose shape entries
    are followed by z0, the height of joint 0 above the mirror plane, then the periods:
    the chain lifted by z0 (garter's state, ``garter.layout``; a chart whose rows are
    mirrored, ``stitches.charts``)."""
    nf = x.shape[0] - 3  # shape entries
    xf = np.empty(nf + 2)
    xf[:nf] = x[:nf]
    xf[nf] = x[nf + 1]
    xf[nf + 1] = x[nf + 2]
    jf = np.empty((cp.shape[0], 6, 3, nf + 2))
    chain_control_points(xf, cp, jf, False, cx)
    for s in range(cp.shape[0]):
        for i in range(6):
            cp[s, i, 2] += x[nf]
            for c in range(3):
                for k in range(nf):
                    jac[s, i, c, k] = jf[s, i, c, k]
                jac[s, i, c, nf] = 1.0 if c == 2 else 0.0
                jac[s, i, c, nf + 1] = jf[s, i, c, nf]
                jac[s, i, c, nf + 2] = jf[s, i, c, nf + 1]
