"""Soft-shell / hard-core contact energy of the cell, with gradients (MODEL.md §6).

The yarn is sampled at N midpoints per segment; every ordered pair of samples
(i, j) and periodic image (m, n) closer than 2r contributes
V(R) v_i v_j dt^2. Each physical contact appears twice (the reference's
convention); this kernel visits every unordered pair once and doubles it, which
gives the same sum.

Candidate search: the images (m, n) and segment pairs whose axis-aligned
bounding boxes (of their samples) come within 2r are the only ones visited.
``IMAGES_REFERENCE`` restricts the images to the reference code's fixed box
m in -1..1, n in -3..3; ``IMAGES_CUTOFF`` takes every image that can touch.
"""

from __future__ import annotations

import numpy as np
from numba import njit

IMAGES_REFERENCE = 0
IMAGES_CUTOFF = 1

CORE_EPS = 1e-5  # zeta below which the hard-core penalty takes over
CORE_PENALTY = 100.0  # N mm; stiffness of the hard-core branch
EXCLUSION_FACTOR = 2.1  # neighbours along the yarn closer than 2.1 r in arclength


@njit(cache=True)
def pair_potential(dist, r, rc, k, p):
    """V(R) and dV/dR of one compressed pair (MODEL.md §6), N mm and N.

    Zero for R >= 2r; the caller only asks for R < 2r.
    """
    d = 2.0 * r - 2.0 * rc
    pref = k * d * d / (p * (p - 1.0))
    zeta = (dist - 2.0 * rc) / d
    if zeta >= CORE_EPS:
        zp = zeta ** (1.0 - p)
        v = pref * (zp - 1.0 - (p - 1.0) * (1.0 - zeta))
        dv = pref * (p - 1.0) * (1.0 - zp / zeta) / d
        return v, dv
    ze = CORE_EPS
    v_eps = pref * (ze ** (1.0 - p) - 1.0 - (p - 1.0) * (1.0 - ze))
    r_eps = 2.0 * rc + ze * d
    x = (dist - r_eps) / r_eps
    return v_eps + CORE_PENALTY * x * x, 2.0 * CORE_PENALTY * x / r_eps


@njit(cache=True)
def sample_path(cp, tab, pts, r1, speed):
    """Samples of the 8 segments (path order): positions ``pts`` (8N, 3),
    derivatives ``r1`` (8N, 3) and speeds ``speed`` (8N,); tab: (2, N, 6)."""
    n = tab.shape[1]
    for s in range(cp.shape[0]):
        for j in range(n):
            i = s * n + j
            for d in range(3):
                x = 0.0
                y = 0.0
                for c in range(6):
                    x += tab[0, j, c] * cp[s, c, d]
                    y += tab[1, j, c] * cp[s, c, d]
                pts[i, d] = x
                r1[i, d] = y
            speed[i] = np.sqrt(r1[i, 0] ** 2 + r1[i, 1] ** 2 + r1[i, 2] ** 2)


@njit(cache=True)
def midpoint_arclength(speed, dt, s_mid):
    """Arclength at the samples by the midpoint rule; returns the total."""
    total = 0.0
    for i in range(speed.shape[0]):
        prev = total
        total += speed[i] * dt
        s_mid[i] = 0.5 * (total + prev)
    return total


@njit(cache=True)
def image_list(pts, ax, ay, r, mode):
    """Half of the periodic images that can touch the cell: (n > 0) or
    (n == 0, m > 0); their mirror images are covered by symmetry. Shape (k, 2)."""
    if mode == IMAGES_REFERENCE:
        mmax, nmax = 1, 3
    else:
        ext_x = pts[:, 0].max() - pts[:, 0].min() + 2.0 * r
        ext_y = pts[:, 1].max() - pts[:, 1].min() + 2.0 * r
        mmax = int(np.ceil(ext_x / ax)) - 1 if ax > 0.0 else 0
        nmax = int(np.ceil(ext_y / ay)) - 1 if ay > 0.0 else 0
        mmax = max(mmax, 0)
        nmax = max(nmax, 0)
    out = np.empty(((2 * mmax + 1) * nmax + mmax, 2), dtype=np.int64)
    k = 0
    for m in range(1, mmax + 1):
        out[k, 0] = m
        out[k, 1] = 0
        k += 1
    for n in range(1, nmax + 1):
        for m in range(-mmax, mmax + 1):
            out[k, 0] = m
            out[k, 1] = n
            k += 1
    return out


@njit(cache=True)
def segment_boxes(pts, nseg, n):
    lo = np.empty((nseg, 3))
    hi = np.empty((nseg, 3))
    for s in range(nseg):
        for d in range(3):
            lo[s, d] = pts[s * n : (s + 1) * n, d].min()
            hi[s, d] = pts[s * n : (s + 1) * n, d].max()
    return lo, hi


@njit(cache=True)
def _boxes_close(lo, hi, a, b, ox, oy, cut):
    g = 0.0
    off = (ox, oy, 0.0)
    for d in range(3):
        gap = max(lo[b, d] + off[d] - hi[a, d], lo[a, d] - hi[b, d] - off[d], 0.0)
        g += gap * gap
    return g < cut * cut


@njit(cache=True)
def _grow(a, size):
    out = np.empty((size, *a.shape[1:]), dtype=a.dtype)
    out[: a.shape[0]] = a
    return out


@njit(cache=True)
def find_contacts(cp, tab, ax, ay, r, mode):
    """Every counted contact of the cell, each unordered pair once (MODEL.md §6).

    Returns (pts (8N, 3), r1 (8N, 3), speed (8N,), idx (c, 4) = (i, j, m, n),
    sep (c, 4) = (dx, dy, dz, R)), where d = p_i - p_j - m t_c - n t_w and R = |d| < 2r,
    excluding same-row pairs closer than 2.1 r along the yarn.
    """
    nseg = cp.shape[0]
    n = tab.shape[1]
    ns = nseg * n
    pts = np.empty((ns, 3))
    r1 = np.empty((ns, 3))
    speed = np.empty(ns)
    s_mid = np.empty(ns)
    sample_path(cp, tab, pts, r1, speed)
    s_tot = midpoint_arclength(speed, 1.0 / n, s_mid)
    lo, hi = segment_boxes(pts, nseg, n)
    images = image_list(pts, ax, ay, r, mode)
    cut = 2.0 * r
    cut2 = cut * cut
    s_excl = EXCLUSION_FACTOR * r
    cap = 4 * ns * n
    idx = np.empty((cap, 4), dtype=np.int64)
    sep = np.empty((cap, 4))
    c = 0
    for im in range(-1, images.shape[0]):
        if im < 0:
            m, nn = 0, 0
        else:
            m, nn = images[im, 0], images[im, 1]
        ox = m * ax
        oy = nn * ay
        s_shift = m * s_tot
        for sa in range(nseg):
            for sb in range(sa if im < 0 else 0, nseg):
                if not _boxes_close(lo, hi, sa, sb, ox, oy, cut):
                    continue
                for i in range(sa * n, (sa + 1) * n):
                    j0 = i + 1 if (im < 0 and sa == sb) else sb * n
                    for j in range(j0, (sb + 1) * n):
                        dx = pts[i, 0] - pts[j, 0] - ox
                        dy = pts[i, 1] - pts[j, 1] - oy
                        dz = pts[i, 2] - pts[j, 2]
                        rr = dx * dx + dy * dy + dz * dz
                        if rr >= cut2:
                            continue
                        if nn == 0 and abs(s_mid[i] - s_mid[j] - s_shift) <= s_excl:
                            continue
                        if c == idx.shape[0]:
                            idx = _grow(idx, 2 * c)
                            sep = _grow(sep, 2 * c)
                        idx[c, 0] = i
                        idx[c, 1] = j
                        idx[c, 2] = m
                        idx[c, 3] = nn
                        sep[c, 0] = dx
                        sep[c, 1] = dy
                        sep[c, 2] = dz
                        sep[c, 3] = np.sqrt(rr)
                        c += 1
    return pts, r1, speed, idx[:c], sep[:c]


@njit(cache=True)
def contact_energy(cp, tab, ax, ay, r, rc, k, p, mode, with_grad, grad_cp, grad_cell):
    """Contact energy E_c (N mm) of the cell and, if ``with_grad``, its gradient.

    cp: (8, 6, 3) control points; tab: (2, N, 6) Bernstein values and first
    derivatives at the N sample parameters. ``grad_cp`` (8, 6, 3) receives
    dE_c/dcp at fixed periods and ``grad_cell`` (2,) the explicit dE_c/d(a_x, a_y)
    through the image offsets.
    """
    n = tab.shape[1]
    dt2 = 1.0 / (n * n)
    _, r1, speed, idx, sep = find_contacts(cp, tab, ax, ay, r, mode)
    ns = speed.shape[0]
    g_pts = np.zeros((ns, 3))
    g_speed = np.zeros(ns)
    gax = 0.0
    gay = 0.0
    energy = 0.0
    for c in range(idx.shape[0]):
        i, j = idx[c, 0], idx[c, 1]
        dist = sep[c, 3]
        v, dv = pair_potential(dist, r, rc, k, p)
        # factor 2: every unordered pair stands for two ordered ones
        w = 2.0 * speed[i] * speed[j] * dt2
        energy += v * w
        if with_grad:
            f = w * dv / dist
            for d in range(3):
                g_pts[i, d] += f * sep[c, d]
                g_pts[j, d] -= f * sep[c, d]
            gax -= idx[c, 2] * f * sep[c, 0]
            gay -= idx[c, 3] * f * sep[c, 1]
            g_speed[i] += 2.0 * v * speed[j] * dt2
            g_speed[j] += 2.0 * v * speed[i] * dt2
    if with_grad:
        grad_cp[:] = 0.0
        for s in range(cp.shape[0]):
            for jj in range(n):
                i = s * n + jj
                inv = g_speed[i] / speed[i]
                for d in range(3):
                    gd = g_pts[i, d]
                    gv = inv * r1[i, d]
                    for cc in range(6):
                        grad_cp[s, cc, d] += tab[0, jj, cc] * gd + tab[1, jj, cc] * gv
        grad_cell[0] = gax
        grad_cell[1] = gay
    return energy


@njit(cache=True)
def min_zeta(cp, tab, ax, ay, r, rc, mode):
    """Smallest zeta = (R - 2 r_core)/(2r - 2 r_core) over the counted contacts;
    1.0 when nothing touches."""
    _, _, _, idx, sep = find_contacts(cp, tab, ax, ay, r, mode)
    zmin = 1.0
    for c in range(idx.shape[0]):
        z = (sep[c, 3] - 2.0 * rc) / (2.0 * r - 2.0 * rc)
        if z < zmin:
            zmin = z
    return zmin
