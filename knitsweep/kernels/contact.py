"""Soft-shell / hard-core contact energy of the cell, with gradients (docs/model.md §6).

The yarn is sampled at N midpoints per segment; every ordered pair of samples
(i, j) and periodic image (m, n) closer than 2r contributes
V(R) v_i v_j dt^2. Each physical contact appears twice (the reference's
convention); this kernel visits every unordered pair once and doubles it, which
gives the same sum.

Candidate search (``partition``): only images, segment pairs and samples whose
axis-aligned bounding boxes come within 2r are visited. ``IMAGES_REFERENCE``
restricts the images to the reference code's fixed box m in -1..1, n in -3..3;
``IMAGES_CUTOFF`` takes every image that can touch.

Evaluation: found pairs go through a buffer. A branch-free pass computes R, zeta
and V (and dV/dR) for the whole batch, so LLVM vectorises it; zeta^(1-p) comes
from ``elementary.pow_pos`` instead of one libm ``pow`` call per pair (~15 ns, no
vector math library in this llvmlite). A scalar pass then adds energies and
gradients in search order, with running sums, so the result does not depend on
where the buffer was flushed. Pairs in the hard-core branch (zeta < 1e-5) take
``pair_potential`` itself.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .elementary import pow_pos
from .partition import image_reaches, search_pairs, segment_boxes_soa, segment_gaps

IMAGES_REFERENCE = 0
IMAGES_CUTOFF = 1

CORE_EPS = 1e-5  # zeta below which the hard-core penalty takes over
CORE_PENALTY = 100.0  # N mm; stiffness of the hard-core branch
EXCLUSION_FACTOR = 2.1  # neighbours along the yarn closer than 2.1 r in arclength


@njit(cache=True)
def pair_potential(dist, r, rc, k, p):
    """V(R) and dV/dR of one compressed pair (docs/model.md §6), N mm and N.

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
    """Samples of the S segments (path order): positions ``pts`` (SN, 3),
    derivatives ``r1`` (SN, 3) and speeds ``speed`` (SN,); tab: (2, N, 6)."""
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
        # max - min of the x and y columns as numpy's max() and min() give them (a
        # NaN propagates), in one loop that compiles to far less than the reductions
        lo_x = hi_x = pts[0, 0]
        lo_y = hi_y = pts[0, 1]
        for i in range(1, pts.shape[0]):
            vx, vy = pts[i, 0], pts[i, 1]
            lo_x = vx if vx < lo_x or vx != vx else lo_x
            hi_x = vx if vx > hi_x or vx != vx else hi_x
            lo_y = vy if vy < lo_y or vy != vy else lo_y
            hi_y = vy if vy > hi_y or vy != vy else hi_y
        ext_x = hi_x - lo_x + 2.0 * r
        ext_y = hi_y - lo_y + 2.0 * r
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
def sample_cell(cp, tab):
    """Samples of the path: positions (3, 8N) structure-of-arrays, derivatives
    (SN, 3), speeds (SN,), midpoint arclengths (SN,) and the total arclength."""
    nseg = cp.shape[0]
    n = tab.shape[1]
    ns = nseg * n
    pts = np.empty((ns, 3))
    r1 = np.empty((ns, 3))
    speed = np.empty(ns)
    s_mid = np.empty(ns)
    sample_path(cp, tab, pts, r1, speed)
    s_tot = midpoint_arclength(speed, 1.0 / n, s_mid)
    pos = np.empty((3, ns))
    for i in range(ns):
        pos[0, i] = pts[i, 0]
        pos[1, i] = pts[i, 1]
        pos[2, i] = pts[i, 2]
    return pts, pos, r1, speed, s_mid, s_tot


@njit(cache=True)
def _grow(a, size):
    """Copy of a (k, cap) buffer with ``size`` columns. Element by element: an array
    slice assignment would compile numba's shape-mismatch error path (string
    formatting, ~2 s of compile time)."""
    out = np.empty((a.shape[0], size), dtype=a.dtype)
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            out[i, j] = a[i, j]
    return out


@njit(cache=True)
def candidate_blocks(pts, box, ax, ay, reach, mode):
    """The candidate search's one loop (``knitsweep.kernels.partition``): every
    (image, segment a, segment b) whose sample boxes come within ``reach``, each
    unordered pair of segments once in the image (0, 0), in search order. Returns
    (k, 3) int64 rows (image, sa, sb) and the images (q, 2) = (m, n) they index;
    image -1 is (0, 0).

    ``pts`` (SN, 3) and ``box`` (6, S) of the samples; images as in ``image_list``
    for half the reach.
    """
    nseg = box.shape[1]
    images = image_list(pts, ax, ay, 0.5 * reach, mode)
    reach2 = reach * reach
    gaps = np.empty(nseg)
    out = np.empty(((images.shape[0] + 1) * nseg * nseg, 3), dtype=np.int64)
    k = 0
    for im in range(-1, images.shape[0]):
        m, nn = (0, 0) if im < 0 else (images[im, 0], images[im, 1])
        ox = m * ax
        oy = nn * ay
        if im >= 0 and not image_reaches(box, ox, oy, reach):
            continue
        for sa in range(nseg):
            segment_gaps(box, sa, ox, oy, gaps)
            for sb in range(sa if im < 0 else 0, nseg):
                if gaps[sb] < reach2:
                    out[k, 0] = im
                    out[k, 1] = sa
                    out[k, 2] = sb
                    k += 1
    return out[:k], images


@njit(cache=True)
def collect_pairs(pts, pos, s_mid, s_tot, n, ax, ay, reach, s_excl, mode):
    """Every sample pair (i, j, m, n) closer than ``reach``, each unordered pair once,
    in (image, segment a, segment b, i, j) order (``candidate_blocks``), leaving out
    same-row pairs within ``s_excl`` along the yarn (none if ``s_excl`` < 0).

    Samples as from ``sample_cell``. Returns ``ib`` (4, cap) int64 = (i, j, m, n),
    ``fb`` (4, cap) = (dx, dy, dz, R^2) with d = p_i - p_j - m t_c - n t_w, and the
    count c of filled columns.
    """
    nseg = pts.shape[0] // n
    box = segment_boxes_soa(pos, nseg, n)
    blocks, images = candidate_blocks(pts, box, ax, ay, reach, mode)
    return search_blocks(pos, s_mid, box, n, blocks, images, ax, ay, 0.0, s_tot, reach * reach,
                         s_excl)  # fmt: skip


@njit(cache=True)
def search_blocks(pos, s_mid, box, n, blocks, images, ax, ay, sx, s_tot, reach2, s_excl):
    """The sample pairs closer than sqrt(``reach2``) of the candidate ``blocks`` (k, 3) =
    (image, segment a, segment b), image indexing ``images`` (q, 2) = (m, n) (-1: (0, 0)),
    in block order (``partition.search_pairs`` on each; the segment b of a block may be a
    column of ``box`` past the samples of one cell: ``kernels.mirrored``'s mirrored copy).
    Returns ``ib`` (4, cap) int64 = (i, j, m, n), ``fb`` (4, cap) = (dx, dy, dz, R^2) and
    the count c of filled columns, as ``collect_pairs``. The image (m, n) sits at
    (m a_x + n s_x, n a_y) (``sx`` the wale vector's skew; 0 for translations)."""
    cap = 4 * box.shape[1] * n * n
    ib = np.empty((4, cap), dtype=np.int64)
    fb = np.empty((4, cap))
    c = np.int64(0)  # not the literal 0: no extra specialisation of the callees
    for q in range(blocks.shape[0]):
        im, sa, sb = blocks[q, 0], blocks[q, 1], blocks[q, 2]
        m, nn = (0, 0) if im < 0 else (images[im, 0], images[im, 1])
        if c + n * n > cap:
            cap *= 2
            ib = _grow(ib, cap)
            fb = _grow(fb, cap)
        c = search_pairs(pos, s_mid, box, n, sa, sb, im < 0, m, nn, m * ax + nn * sx, nn * ay,
                         m * s_tot, reach2, s_excl, ib, fb, c)  # fmt: skip
    return ib, fb, c


@njit(cache=True)
def contact_list(ib, fb, c):
    """The first ``c`` buffered pairs as (idx (c, 4) = (i, j, m, n), sep (c, 4) = (dx, dy,
    dz, R))."""
    idx = np.ascontiguousarray(ib[:, :c].T)
    sep = np.empty((c, 4))
    for q in range(c):
        sep[q, 0] = fb[0, q]
        sep[q, 1] = fb[1, q]
        sep[q, 2] = fb[2, q]
        sep[q, 3] = np.sqrt(fb[3, q])
    return idx, sep


@njit(cache=True)
def find_contacts(cp, tab, ax, ay, r, mode):
    """Every counted contact of the cell, each unordered pair once (docs/model.md §6).

    Returns (pts (SN, 3), r1 (SN, 3), speed (SN,), idx (c, 4) = (i, j, m, n),
    sep (c, 4) = (dx, dy, dz, R)), where d = p_i - p_j - m t_c - n t_w and R = |d| < 2r,
    excluding same-row pairs closer than 2.1 r along the yarn. Contacts are listed
    in (image, segment a, segment b, i, j) order (``collect_pairs``).
    """
    n = tab.shape[1]
    pts, pos, r1, speed, s_mid, s_tot = sample_cell(cp, tab)
    ib, fb, c = collect_pairs(pts, pos, s_mid, s_tot, n, ax, ay, 2.0 * r, EXCLUSION_FACTOR * r,
                              mode)  # fmt: skip
    idx, sep = contact_list(ib, fb, c)
    return pts, r1, speed, idx, sep


@njit(cache=True, error_model="numpy", fastmath={"contract"})
def _pow_inplace(x, nb, e):
    """x[:nb] **= e for x in [CORE_EPS, 1], vectorised (``elementary.pow_pos``).

    fastmath "contract" only lets LLVM fuse a * b + c into one correctly rounded
    FMA (no reassociation, no finite-math assumptions): each fused step rounds
    once instead of twice; tests/test_elementary.py bounds the error against
    libm's pow. ~15 % faster than without.
    """
    for c in range(nb):
        x[c] = pow_pos(x[c], e)


@njit(cache=True, error_model="numpy")
def _soft_shell(rr, nb, r, rc, k, p, with_grad, dist, zeta, v, dv):
    """Soft-shell branch of ``pair_potential`` for the first ``nb`` squared
    distances ``rr``: R, zeta, V(R) and, with ``with_grad``, dV/dR, into the 1-D
    arrays ``dist``, ``zeta``, ``v``, ``dv`` (docs/model.md §6).

    The formulas of ``pair_potential``, split into branch-free loops that
    vectorise; zeta^(1-p) comes from ``_pow_inplace``. Pairs with zeta < CORE_EPS
    get meaningless values and are redone by the caller. error_model="numpy": a
    zero zeta (core branch only) then gives inf instead of raising.
    """
    d = 2.0 * r - 2.0 * rc
    if nb > 0 and (d == 0.0 or p * (p - 1.0) == 0.0):
        raise ZeroDivisionError("division by zero")  # as pair_potential would
    two_rc = 2.0 * rc
    pref = k * d * d / (p * (p - 1.0))
    pm1 = p - 1.0
    e = 1.0 - p
    for c in range(nb):
        x = np.sqrt(rr[c])
        z = (x - two_rc) / d
        dist[c] = x
        zeta[c] = z
        v[c] = z if z >= CORE_EPS else CORE_EPS
    # |e log zeta| <= |e| 11.6 for zeta in [CORE_EPS, 1): exp_finite needs <= 708
    if abs(e) * 11.6 <= 700.0:
        _pow_inplace(v, nb, e)
    else:
        for c in range(nb):
            v[c] = v[c] ** e
    if with_grad:
        for c in range(nb):
            dv[c] = pref * pm1 * (1.0 - v[c] / zeta[c]) / d
    for c in range(nb):
        v[c] = pref * (v[c] - 1.0 - pm1 * (1.0 - zeta[c]))


@njit(cache=True)
def accumulate_pairs(ib, fb, nb, speed, dt2, r, rc, k, p, with_grad, work, g, energy, gax,
                     gay):  # fmt: skip
    """Add the first ``nb`` buffered pairs, in buffer order, to the running sums
    ``energy``, ``gax``, ``gay`` (E and the explicit dE/da_x, dE/da_y through the
    image offsets; returned) and, with ``with_grad``, to the gradient ``g``
    (SN, 4): columns 0-2 dE/dp_i, column 3 dE/dv_i. Each unordered pair stands for
    two ordered ones: weight w = 2 v_i v_j dt^2. ``work`` (4, cap) is scratch.
    Running sums make the result independent of where the buffer was flushed.
    """
    dist, zeta, v, dv = work[0], work[1], work[2], work[3]
    _soft_shell(fb[3], nb, r, rc, k, p, with_grad, dist, zeta, v, dv)
    for c in range(nb):
        i, j = ib[0, c], ib[1, c]
        vc = v[c]
        dvc = dv[c] if with_grad else 0.0
        if not zeta[c] >= CORE_EPS:  # hard-core branch: the scalar formulas
            vc, dvc = pair_potential(dist[c], r, rc, k, p)
        si = speed[i]
        sj = speed[j]
        w = 2.0 * si * sj * dt2
        energy += vc * w
        if with_grad:
            f = w * dvc / dist[c]
            dx, dy, dz = fb[0, c], fb[1, c], fb[2, c]
            fx, fy, fz = f * dx, f * dy, f * dz
            g[i, 0] += fx
            g[i, 1] += fy
            g[i, 2] += fz
            g[i, 3] += 2.0 * vc * sj * dt2
            g[j, 0] -= fx
            g[j, 1] -= fy
            g[j, 2] -= fz
            g[j, 3] += 2.0 * vc * si * dt2
            gax -= ib[2, c] * f * dx
            gay -= ib[3, c] * f * dy
    return energy, gax, gay


@njit(cache=True)
def contact_energy(cp, tab, ax, ay, r, rc, k, p, mode, with_grad, grad_cp, grad_cell):
    """Contact energy E_c (N mm) of the cell and, if ``with_grad``, its gradient.

    cp: (S, 6, 3) control points; tab: (2, N, 6) Bernstein values and first
    derivatives at the N sample parameters. ``grad_cp`` (S, 6, 3) receives
    dE_c/dcp at fixed periods and ``grad_cell`` (2,) the explicit dE_c/d(a_x, a_y)
    through the image offsets.

    The pairs found by the search (``candidate_blocks``) go through a buffer: a
    vectorised pass evaluates the potential of a batch, a scalar pass adds it up in
    search order. This is ``collect_pairs`` with a buffer of fixed size that is
    flushed instead of grown: collecting every pair first (one growing buffer, then
    one sum) measured ~10 % slower here and ~70 % slower on the neighbour-list path,
    from allocating and copying the larger buffers.
    """
    nseg = cp.shape[0]
    n = tab.shape[1]
    pts, pos, r1, speed, s_mid, s_tot = sample_cell(cp, tab)
    dt2, cut, s_excl, ib, fb, work, g = pair_sum_start(n, speed.shape[0], r)
    box = segment_boxes_soa(pos, nseg, n)
    blocks, images = candidate_blocks(pts, box, ax, ay, cut, mode)
    energy = 0.0
    gax = 0.0
    gay = 0.0
    c = np.int64(0)  # not the literal 0: no extra specialisation of the callees
    for q in range(blocks.shape[0]):
        im, sa, sb = blocks[q, 0], blocks[q, 1], blocks[q, 2]
        m, nn = (0, 0) if im < 0 else (images[im, 0], images[im, 1])
        if c + n * n > ib.shape[1]:
            energy, gax, gay = accumulate_pairs(ib, fb, c, speed, dt2, r, rc, k, p, with_grad,
                                                work, g, energy, gax, gay)  # fmt: skip
            c = np.int64(0)
        c = search_pairs(pos, s_mid, box, n, sa, sb, im < 0, m, nn, m * ax, nn * ay, m * s_tot,
                         cut * cut, s_excl, ib, fb, c)  # fmt: skip
    return finish_pairs(ib, fb, c, speed, r1, tab, dt2, r, rc, k, p, with_grad, work, g, energy,
                        gax, gay, grad_cp, grad_cell)  # fmt: skip


@njit(cache=True)
def pair_sum_start(n, ns, r):
    """What every contact sum starts from (the full search, the neighbour list, the
    mirrored images): with N = ``n`` samples per segment, ``ns`` samples in all and
    yarn radius ``r``, the quadrature weight dt² = 1/N², the cut-off 2r, the exclusion
    along the yarn ``EXCLUSION_FACTOR`` r and the pair buffers (``pair_buffers``)."""
    ib, fb, work, g = pair_buffers(n, ns)
    return 1.0 / (n * n), 2.0 * r, EXCLUSION_FACTOR * r, ib, fb, work, g


@njit(cache=True)
def pair_buffers(n, ns):
    """The pair buffers of a contact sum with N = ``n`` samples per segment and ``ns``
    samples in all: ``ib`` (4, cap) int64, ``fb`` and ``work`` (4, cap), and the
    sample gradient ``g`` (ns, 4), zeroed."""
    cap = max(2048, 2 * n * n)
    ib = np.empty((4, cap), dtype=np.int64)
    fb = np.empty((4, cap))
    work = np.empty((4, cap))
    return ib, fb, work, np.zeros((ns, 4))


@njit(cache=True)
def finish_pairs(ib, fb, c, speed, r1, tab, dt2, r, rc, k, p, with_grad, work, g, energy, gax,
                 gay, grad_cp, grad_cell):  # fmt: skip
    """The end of every contact sum: add the last ``c`` buffered pairs, then project
    the sample gradient onto the control points (``grad_cp``) and store the explicit
    period derivatives (``grad_cell``). Returns E_c."""
    energy, gax, gay = accumulate_pairs(ib, fb, c, speed, dt2, r, rc, k, p, with_grad, work, g,
                                        energy, gax, gay)  # fmt: skip
    if with_grad:
        project_gradient(g, speed, r1, tab, grad_cp)
        grad_cell[0] = gax
        grad_cell[1] = gay
    return energy


@njit(cache=True)
def project_gradient(g, speed, r1, tab, grad_cp):
    """dE/dcp (S, 6, 3) from dE/dp_i and dE/dv_i (``g`` (SN, 4)) at the samples:
    p_i = sum_c B_c(t_j) P_c and v_i = |r'(t_j)|, so dv_i/dr' = r'/v_i."""
    nseg = grad_cp.shape[0]
    n = tab.shape[1]
    grad_cp[:] = 0.0
    for s in range(nseg):
        for jj in range(n):
            i = s * n + jj
            inv = g[i, 3] / speed[i]
            for d in range(3):
                gd = g[i, d]
                gv = inv * r1[i, d]
                for cc in range(6):
                    grad_cp[s, cc, d] += tab[0, jj, cc] * gd + tab[1, jj, cc] * gv


def min_zeta(cp, tab, ax, ay, r, rc, mode):
    """Smallest zeta = (R - 2 r_core)/(2r - 2 r_core) over the counted contacts;
    1.0 when nothing touches.

    Plain numpy on ``find_contacts``'s separations (the same operations as a compiled
    loop, and the same minimum): a kernel of its own would compile the whole contact
    search once more (~0.8 s) for a call made once per relaxation."""
    sep = find_contacts(cp, tab, ax, ay, r, mode)[4]
    z = (sep[:, 3] - 2.0 * rc) / (2.0 * r - 2.0 * rc)
    z = z[z < 1.0]
    return float(z.min()) if z.size else 1.0
