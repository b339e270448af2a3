"""Contact samples placed by arclength within each segment, with their exact gradient
(docs/model.md §11, "Resolution"; the free yarn's ``Fidelity.contact_sampling =
"arclength"``).

Sample j of a segment sits at the parameter t_j where the segment's arclength fraction
equals f_j = (j + 1/2)/N (the fractions the fixed-parameter samples use as parameters),
so the samples are as far apart as the segment is long, whatever its end speeds. The
arclength is a fixed quadrature rule scaled onto [0, t],

    S(t) = t Σ_K W_K |r'(t X_K)|,       (X_K, W_K) a composite Gauss rule on [0, 1],

smooth in t and in the control points P; t_j is the root of F = S(t) − f_j S(1) by
Newton (to round-off). Each sample carries the segment's length ℓ = S(1) as its
"speed", so §6's weight v_i v_j dt² becomes ℓ_a ℓ_b / N²: the midpoint rule in arclength.
The gradient is exact for these roots (implicit function theorem):

    dt_j/dP = (f_j ∂S(1)/∂P − ∂S(t_j)/∂P) / ∂S(t_j)/∂t,
    dE/dP   = Σ_j B(t_j)ᵀ g_j + Σ_j (g_j · r'(t_j)) dt_j/dP + (Σ_j ∂E/∂ℓ_j) ∂S(1)/∂P,

g_j = dE/dp_j at the samples and ∂S(t)/∂P_c = t Σ_K W_K B_c'(t X_K) r'/|r'| at t X_K.
"""

from __future__ import annotations

import numpy as np
from numba import njit

NEWTON_STEPS = 30
"""Most Newton steps of one sample's parameter (a handful reach round-off)."""


def arclength_rule(panels: int, nodes: int) -> np.ndarray:
    """(2, panels * nodes): the composite Gauss–Legendre rule on [0, 1] (row 0 nodes,
    row 1 weights) that the arclength S(t) is scaled from."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    xs = np.concatenate([(p + 0.5 * (x + 1.0)) / panels for p in range(panels)])
    ws = np.concatenate([0.5 * w / panels for _ in range(panels)])
    return np.ascontiguousarray(np.stack([xs, ws]))


@njit(cache=True, inline="always")
def _basis(t, b, d1):
    """Quintic Bernstein values ``b`` (6,) and first t-derivatives ``d1`` (6,) at t."""
    u = 1.0 - t
    t2, u2 = t * t, u * u
    b[0], b[1], b[2] = u2 * u2 * u, 5 * t * u2 * u2, 10 * t2 * u2 * u
    b[3], b[4], b[5] = 10 * t2 * t * u2, 5 * t2 * t2 * u, t2 * t2 * t
    _derivative_basis(t, d1)


@njit(cache=True, inline="always")
def _derivative_basis(t, d1):
    """The quintic Bernstein basis's t-derivatives ``d1`` (6,) at t."""
    u = 1.0 - t
    t2, u2 = t * t, u * u
    q0, q1, q2, q3, q4 = u2 * u2, 4 * t * u2 * u, 6 * t2 * u2, 4 * t2 * t * u, t2 * t2
    d1[0], d1[1], d1[2] = -5 * q0, 5 * (q0 - q1), 5 * (q1 - q2)
    d1[3], d1[4], d1[5] = 5 * (q2 - q3), 5 * (q3 - q4), 5 * q4


@njit(cache=True)
def derivative_coefficients(cp):
    """(S, 9, 3): each segment's r'(u) = Σ_k C[k] u^k (rows 0–4) and r''(u) = Σ_k C[5 + k]
    u^k (rows 5–8) in the power basis, so that a quadrature node costs a Horner sum."""
    nseg = cp.shape[0]
    co = np.empty((nseg, 9, 3))
    a = np.empty(6)
    for s in range(nseg):
        for d in range(3):
            p0, p1, p2 = cp[s, 0, d], cp[s, 1, d], cp[s, 2, d]
            p3, p4, p5 = cp[s, 3, d], cp[s, 4, d], cp[s, 5, d]
            # r(u) = Σ_k a_k u^k from the Bernstein form
            a[1] = 5.0 * (p1 - p0)
            a[2] = 10.0 * (p2 - 2.0 * p1 + p0)
            a[3] = 10.0 * (p3 - 3.0 * p2 + 3.0 * p1 - p0)
            a[4] = 5.0 * (p4 - 4.0 * p3 + 6.0 * p2 - 4.0 * p1 + p0)
            a[5] = p5 - 5.0 * p4 + 10.0 * p3 - 10.0 * p2 + 5.0 * p1 - p0
            for k in range(5):
                co[s, k, d] = (k + 1) * a[k + 1]
            for k in range(4):
                co[s, 5 + k, d] = (k + 2) * (k + 1) * a[k + 2]
    return co


@njit(cache=True, inline="always")
def _velocity(co, s, u):
    """r'(u) of segment s (Horner on ``derivative_coefficients``)."""
    x = (((co[s, 4, 0] * u + co[s, 3, 0]) * u + co[s, 2, 0]) * u + co[s, 1, 0]) * u + co[s, 0, 0]
    y = (((co[s, 4, 1] * u + co[s, 3, 1]) * u + co[s, 2, 1]) * u + co[s, 1, 1]) * u + co[s, 0, 1]
    z = (((co[s, 4, 2] * u + co[s, 3, 2]) * u + co[s, 2, 2]) * u + co[s, 1, 2]) * u + co[s, 0, 2]
    return x, y, z


@njit(cache=True, inline="always")
def _acceleration(co, s, u):
    """r''(u) of segment s (Horner on ``derivative_coefficients``)."""
    x = ((co[s, 8, 0] * u + co[s, 7, 0]) * u + co[s, 6, 0]) * u + co[s, 5, 0]
    y = ((co[s, 8, 1] * u + co[s, 7, 1]) * u + co[s, 6, 1]) * u + co[s, 5, 1]
    z = ((co[s, 8, 2] * u + co[s, 7, 2]) * u + co[s, 6, 2]) * u + co[s, 5, 2]
    return x, y, z


@njit(cache=True)
def _put_sample(cp, co, s, t, i, b, d1, pts, pos, r1):
    """Sample ``i``: segment ``s``'s point and first derivative at parameter ``t`` into
    ``pts[i]``, ``pos[:, i]`` and ``r1[i]`` (``b``, ``d1``: basis buffers)."""
    _basis(t, b, d1)
    for d in range(3):
        x = 0.0
        for c in range(6):
            x += b[c] * cp[s, c, d]
        pts[i, d] = x
        pos[d, i] = x
    r1[i, 0], r1[i, 1], r1[i, 2] = _velocity(co, s, t)


@njit(cache=True)
def _arc(co, s, t, aq, want_dt):
    """(S(t), ∂S/∂t) of segment s (``want_dt`` False: ∂S/∂t = 0); ``co`` the segments'
    ``derivative_coefficients``."""
    val, der = 0.0, 0.0
    for q in range(aq.shape[1]):
        u = t * aq[0, q]
        r1x, r1y, r1z = _velocity(co, s, u)
        v = np.sqrt(r1x * r1x + r1y * r1y + r1z * r1z)
        val += aq[1, q] * v
        if want_dt:
            r2x, r2y, r2z = _acceleration(co, s, u)
            der += aq[1, q] * (v + u * (r1x * r2x + r1y * r2y + r1z * r2z) / v)
    return t * val, der


@njit(cache=True)
def _root(co, s, goal, tj, aq):
    """(t, ∂S/∂t near t): the parameter t of segment s where S(t) = ``goal``, by Newton
    from ``tj``, and the derivative its last step used (for the next root's guess)."""
    der = 1.0
    for _ in range(NEWTON_STEPS):
        val, der = _arc(co, s, tj, aq, True)
        step = (val - goal) / der
        tn = tj - step
        # stay inside (0, 1): S is increasing, so the root lies between
        if tn <= 0.0:
            tn = 0.5 * tj
        elif tn >= 1.0:
            tn = 0.5 * (tj + 1.0)
        tj = tn
        if abs(step) < 1e-11:  # quadratic convergence: the root to round-off
            break
    return tj, der


@njit(cache=True)
def arclength_params(cp, n, aq):
    """(t (S, n): each sample's parameter, seglen (S,): each segment's length S(1)) of
    the samples at arclength fractions (j + 1/2)/n of every segment."""
    return _arclength_params(derivative_coefficients(cp), n, aq)


@njit(cache=True)
def _arclength_params(co, n, aq):
    nseg = co.shape[0]
    t = np.empty((nseg, n))
    seglen = np.empty(nseg)
    for s in range(nseg):
        ell = _arc(co, s, 1.0, aq, False)[0]
        seglen[s] = ell
        tj = 0.5 / n  # then each sample's Newton starts from the previous root
        for j in range(n):
            tj = _root(co, s, (j + 0.5) / n * ell, tj, aq)[0]
            t[s, j] = tj
    return t, seglen


@njit(cache=True)
def arclength_sample_cell(cp, n, aq):
    """``contact.sample_cell``'s arrays for samples at arclength fractions: positions
    (S n, 3) and (3, S n), derivatives r'(t_j) (S n, 3), "speeds" (S n,) = the segment's
    length ℓ (so the pair weight is ℓ_a ℓ_b / n²), the arclengths along the yarn (S n,)
    and the total; then the parameters t (S, n)."""
    nseg = cp.shape[0]
    ns = nseg * n
    co = derivative_coefficients(cp)
    t, seglen = _arclength_params(co, n, aq)
    pts = np.empty((ns, 3))
    r1 = np.empty((ns, 3))
    speed = np.empty(ns)
    s_mid = np.empty(ns)
    pos = np.empty((3, ns))
    b, d1 = np.empty(6), np.empty(6)
    before = 0.0
    for s in range(nseg):
        for j in range(n):
            i = s * n + j
            _put_sample(cp, co, s, t[s, j], i, b, d1, pts, pos, r1)
            speed[i] = seglen[s]
            s_mid[i] = before + (j + 0.5) / n * seglen[s]
        before += seglen[s]
    return pts, pos, r1, speed, s_mid, before, t


@njit(cache=True)
def _arc_gradient(co, s, t, aq, d1, out):
    """∂S(t)/∂P of segment s into ``out`` (6, 3); returns ∂S/∂t (``_arc``'s)."""
    out[:] = 0.0
    der = 0.0
    for q in range(aq.shape[1]):
        u = t * aq[0, q]
        _derivative_basis(u, d1)
        r1x, r1y, r1z = _velocity(co, s, u)
        v = np.sqrt(r1x * r1x + r1y * r1y + r1z * r1z)
        r2x, r2y, r2z = _acceleration(co, s, u)
        der += aq[1, q] * (v + u * (r1x * r2x + r1y * r2y + r1z * r2z) / v)
        f = t * aq[1, q] / v
        for c in range(6):
            out[c, 0] += f * d1[c] * r1x
            out[c, 1] += f * d1[c] * r1y
            out[c, 2] += f * d1[c] * r1z
    return der


@njit(cache=True)
def project_arclength_gradient(g, cp, r1, t, aq, grad_cp):
    """dE/dcp (S, 6, 3) from dE/dp_j and dE/dℓ_j (``g`` (S n, 4)) at arclength samples
    (module docstring); ``r1`` (S n, 3) the derivatives and ``t`` (S, n) the parameters
    of ``arclength_sample_cell``."""
    nseg, n = t.shape
    co = derivative_coefficients(cp)
    grad_cp[:] = 0.0
    b, d1 = np.empty(6), np.empty(6)
    dl = np.empty((6, 3))
    ds = np.empty((6, 3))
    for s in range(nseg):
        _arc_gradient(co, s, 1.0, aq, d1, dl)
        gl = 0.0
        for j in range(n):
            i = s * n + j
            tj = t[s, j]
            gl += g[i, 3]
            gr = g[i, 0] * r1[i, 0] + g[i, 1] * r1[i, 1] + g[i, 2] * r1[i, 2]
            if gr != 0.0:
                st = _arc_gradient(co, s, tj, aq, d1, ds)
                f = (j + 0.5) / n
                w = gr / st
                for c in range(6):
                    for d in range(3):
                        grad_cp[s, c, d] += w * (f * dl[c, d] - ds[c, d])
            _basis(tj, b, d1)
            for c in range(6):
                for d in range(3):
                    grad_cp[s, c, d] += b[c] * g[i, d]
        for c in range(6):
            for d in range(3):
                grad_cp[s, c, d] += gl * dl[c, d]


# ---- samples evenly spaced along the whole yarn --------------------------------------
# With a rule ``aq`` of three rows (the third is not read) the S N samples sit at the
# fractions (i + 1/2)/(S N) of the whole yarn's arclength, each in the segment that holds
# it, so that neither the speeds nor where the joints sit along the yarn move them. Each
# carries ℓ_tot / S as its "speed" (the pair weight (ℓ_tot / (S N))²), and with
# F_i = S_{s_i}(t_i) − (f_i ℓ_tot − Σ_{s < s_i} ℓ_s):
#     dt_i/dP_s = ([f_i − (s < s_i)] ∂ℓ_s/∂P − (s = s_i) ∂S_s(t_i)/∂P) / ∂S(t_i)/∂t.


@njit(cache=True)
def yarn_sample_cell(cp, n, aq):
    """``arclength_sample_cell``'s arrays for samples evenly spaced along the whole yarn
    (above); the parameters are returned as (S N, 2): segment, t."""
    nseg = cp.shape[0]
    ns = nseg * n
    co = derivative_coefficients(cp)
    b, d1 = np.empty(6), np.empty(6)
    seglen = np.empty(nseg)
    for s in range(nseg):
        seglen[s] = _arc(co, s, 1.0, aq, False)[0]
    total = seglen.sum()
    pts, r1, pos = np.empty((ns, 3)), np.empty((ns, 3)), np.empty((3, ns))
    speed, s_mid, st = np.empty(ns), np.empty(ns), np.empty((ns, 2))
    s, before, tj, der, last = 0, 0.0, 0.0, 1.0, -1.0
    for i in range(ns):
        goal = (i + 0.5) / ns * total
        while s < nseg - 1 and goal - before > seglen[s]:
            before += seglen[s]
            s += 1
            last = -1.0
        local = goal - before
        # Newton from the tangent line at the segment's previous root (S' there), or
        # from the segment's mean speed for its first
        guess = tj + (local - last) / der if last >= 0.0 else local / seglen[s]
        tj, der = _root(co, s, local, min(max(guess, 1e-12), 1.0 - 1e-12), aq)
        last = local
        st[i, 0], st[i, 1] = s, tj
        _put_sample(cp, co, s, tj, i, b, d1, pts, pos, r1)
        speed[i] = total / nseg
        s_mid[i] = goal
    return pts, pos, r1, speed, s_mid, total, st


@njit(cache=True)
def project_yarn_gradient(g, cp, r1, st, aq, grad_cp):
    """dE/dcp (S, 6, 3) from dE/dp_i and dE/dv_i (``g`` (S N, 4)) at the samples of
    ``yarn_sample_cell`` (``st`` their segments and parameters)."""
    nseg = cp.shape[0]
    ns = st.shape[0]
    co = derivative_coefficients(cp)
    grad_cp[:] = 0.0
    b, d1 = np.empty(6), np.empty(6)
    ds = np.empty((6, 3))
    coef = np.zeros(nseg)  # the coefficient of ∂ℓ_s/∂P
    after = np.zeros(nseg)  # Σ A_i over the samples in segments after s
    gv = 0.0
    for i in range(ns):
        s = int(st[i, 0])
        tj = st[i, 1]
        gv += g[i, 3]
        gr = g[i, 0] * r1[i, 0] + g[i, 1] * r1[i, 1] + g[i, 2] * r1[i, 2]
        if gr != 0.0:
            a = gr / _arc_gradient(co, s, tj, aq, d1, ds)
            f = (i + 0.5) / ns
            for q in range(nseg):
                coef[q] += a * f
            for q in range(s):
                after[q] += a
            for c in range(6):
                for d in range(3):
                    grad_cp[s, c, d] -= a * ds[c, d]
        _basis(tj, b, d1)
        for c in range(6):
            for d in range(3):
                grad_cp[s, c, d] += b[c] * g[i, d]
    for s in range(nseg):
        _arc_gradient(co, s, 1.0, aq, d1, ds)
        w = coef[s] - after[s] + gv / nseg
        for c in range(6):
            for d in range(3):
                grad_cp[s, c, d] += w * ds[c, d]


@njit(cache=True)
def length_spread(cp, aq, stiffness, with_grad, grad_cp):
    """stiffness Σ_s (ℓ_s − ℓ̄)² of control points ``cp`` (S, 6, 3), ℓ_s the segments'
    lengths by the rule ``aq`` (``arclength_rule``), ℓ̄ their mean; with ``with_grad`` its
    gradient added into ``grad_cp`` (S, 6, 3) (Σ_s (ℓ_s − ℓ̄) = 0 drops the mean's share).
    A free yarn's gauge penalty on its joints' slides (``stitches.base.Gauge``)."""
    nseg = cp.shape[0]
    co = derivative_coefficients(cp)
    ell = np.empty(nseg)
    for s in range(nseg):
        ell[s] = _arc(co, s, 1.0, aq, False)[0]
    dev = ell - ell.mean()
    if with_grad:
        d1, ds = np.empty(6), np.empty((6, 3))
        for s in range(nseg):
            _arc_gradient(co, s, 1.0, aq, d1, ds)
            w = 2.0 * stiffness * dev[s]
            for c in range(6):
                for d in range(3):
                    grad_cp[s, c, d] += w * ds[c, d]
    return stiffness * (dev @ dev)
