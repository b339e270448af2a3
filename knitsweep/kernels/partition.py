"""Candidate search for the contact sum: which sample pairs are closer than 2r.

docs/model.md §6: every ordered pair (i, j) of the 8N samples and periodic image
(m, n) with R = |p_i - p_j - m t_c - n t_w| < 2r counts, except same-row (n = 0)
pairs closer than 2.1 r along the yarn. The search visits each unordered pair
once: the image (0, 0) with j > i, and half of the other images (their mirrors
hold the same pairs with i and j swapped), see ``contact.image_list``.

Culling, coarse to fine, each step exact (it only drops pairs whose boxes are
2r apart): an image whose shifted cell box is 2r away from the cell's box; a
segment pair whose sample boxes are 2r apart; and within a kept segment pair, a
sample i that is 2r away from the other segment's box. On golden case
init1_paper (N = 10) that leaves 92 segment pairs, 616 rows (i, segment) and
5,720 distance tests for 2,296 contacts, against 8,760 tests with segment boxes
alone. (Sub-segment boxes of 5 samples were tried too: fewer tests, but more
time in the bookkeeping at this size.)

Contacts come out in (image, segment a, segment b, i, j) order, i and j
increasing: the order of a plain loop over the box, so sums over them add the
same numbers in the same order whichever images or boxes were culled.

Samples are held structure-of-arrays: ``pos`` (3, 8N) = x, y, z rows.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def segment_boxes_soa(pos, nseg, n):
    """Boxes of each segment's samples: (6, nseg) = (lo_x, lo_y, lo_z, hi_x, hi_y, hi_z)."""
    box = np.empty((6, nseg))
    for s in range(nseg):
        for d in range(3):
            lo = pos[d, s * n]
            hi = lo
            for i in range(s * n + 1, (s + 1) * n):
                v = pos[d, i]
                lo = min(lo, v)
                hi = max(hi, v)
            box[d, s] = lo
            box[3 + d, s] = hi
    return box


@njit(cache=True, inline="always")
def image_reaches(box, ox, oy, cut):
    """True if the cell's segment boxes, all together, come within ``cut`` of
    their copy shifted by (ox, oy, 0)."""
    g = 0.0
    for d in range(3):
        # box[d].min() and box[3 + d].max(), in a loop that compiles to far less
        lo = box[d, 0]
        hi = box[3 + d, 0]
        for s in range(1, box.shape[1]):
            v, w = box[d, s], box[3 + d, s]
            lo = v if v < lo or v != v else lo
            hi = w if w > hi or w != w else hi
        off = ox if d == 0 else (oy if d == 1 else 0.0)
        gap = max(lo + off - hi, lo - hi - off, 0.0)
        g += gap * gap
    return g < cut * cut


@njit(cache=True, inline="always")
def segment_gaps(box, sa, ox, oy, out):
    """Squared gap between the box of segment ``sa`` and every segment box shifted
    by (ox, oy, 0), into ``out`` (nseg,)."""
    for sb in range(box.shape[1]):
        gx = max(box[0, sb] + ox - box[3, sa], box[0, sa] - box[3, sb] - ox, 0.0)
        gy = max(box[1, sb] + oy - box[4, sa], box[1, sa] - box[4, sb] - oy, 0.0)
        gz = max(box[2, sb] - box[5, sa], box[2, sa] - box[5, sb], 0.0)
        out[sb] = gx * gx + gy * gy + gz * gz


@njit(cache=True, inline="always")
def search_pairs(pos, s_mid, box, n, sa, sb, same, m, nn, ox, oy, s_shift, cut2, s_excl,
                 ib, fb, c):  # fmt: skip
    """Append the counted contacts between segments sa and sb + (m t_c + nn t_w).

    ``same``: the image (0, 0), where only j > i is visited. Writes from index
    ``c`` into ``ib`` (4, cap) int64 = (i, j, m, n) and ``fb`` (4, cap) float64 =
    (dx, dy, dz, R^2) with d = p_i - p_j - m t_c - n t_w; the caller guarantees
    cap >= c + n^2. Returns the new count.
    """
    b0 = sb * n
    b1 = b0 + n
    lox, loy, loz = box[0, sb] + ox, box[1, sb] + oy, box[2, sb]
    hix, hiy, hiz = box[3, sb] + ox, box[4, sb] + oy, box[5, sb]
    for i in range(sa * n, sa * n + n):
        xi = pos[0, i]
        yi = pos[1, i]
        zi = pos[2, i]
        # sample i against the shifted box of segment sb
        gx = max(lox - xi, xi - hix, 0.0)
        gy = max(loy - yi, yi - hiy, 0.0)
        gz = max(loz - zi, zi - hiz, 0.0)
        if not gx * gx + gy * gy + gz * gz < cut2:
            continue
        j0 = i + 1 if (same and sa == sb) else b0
        c = search_row(pos, s_mid, i, j0, b1, m, nn, ox, oy, s_shift, cut2, s_excl, ib, fb, c)
    return c


@njit(cache=True, inline="always")
def search_row(pos, s_mid, i, j0, j1, m, nn, ox, oy, s_shift, cut2, s_excl, ib, fb, c):
    """Append the counted contacts (i, j) for j in [j0, j1) in image (m, nn); the
    one place where a pair is tested, shared by the search and the neighbour list
    so that both compute the same bits. Returns the new count."""
    xi = pos[0, i]
    yi = pos[1, i]
    zi = pos[2, i]
    si = s_mid[i]
    row0 = nn == 0
    for j in range(j0, j1):
        dx = xi - pos[0, j] - ox
        dy = yi - pos[1, j] - oy
        dz = zi - pos[2, j]
        rr = dx * dx + dy * dy + dz * dz
        if rr >= cut2:
            continue
        if row0 and abs(si - s_mid[j] - s_shift) <= s_excl:
            continue
        ib[0, c] = i
        ib[1, c] = j
        ib[2, c] = m
        ib[3, c] = nn
        fb[0, c] = dx
        fb[1, c] = dy
        fb[2, c] = dz
        fb[3, c] = rr
        c += 1
    return c
