"""The checks run after every relaxation of a pattern (docs/model.md §11), compiled:
the crossings in projection of a yarn's polyline with its images (``stitches.topology``)
and the smallest ζ over the counted contacts of a pattern with mirrored images, and
where (``stitches.patterns.min_zeta_where``).

Each computes what its numpy reference computes, operation for operation in the same
order (no fused multiply-adds: numba's default), so the crossings' positions and
heights and the ζ come out bit for bit; only which pairs are tested differs, and only
by pairs that cannot count. Crossings: pieces are filed in blocks of ``BLOCK``
consecutive pieces, and only pieces of two blocks whose boxes in projection come
within ``BOX_MARGIN`` are tested (two pieces that cross have overlapping boxes). ζ:
an image is culled by the reference's own test, and within a kept image every sample
pair is measured.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit

BLOCK = 8
"""Polyline pieces per block of the crossings' search."""
BOX_MARGIN = 1e-9
"""mm by which two blocks' boxes may miss each other and still be searched."""


@njit(cache=True)
def _block_boxes(p0, p1):
    """(nb, 4) boxes in projection (lo_x, lo_y, hi_x, hi_y) of ``BLOCK`` pieces each."""
    n_p = p0.shape[0]
    nb = (n_p + BLOCK - 1) // BLOCK
    box = np.empty((nb, 4))
    for b in range(nb):
        lox, loy, hix, hiy = np.inf, np.inf, -np.inf, -np.inf
        for i in range(b * BLOCK, min((b + 1) * BLOCK, n_p)):
            for q in (p0, p1):
                lox, hix = min(lox, q[i, 0]), max(hix, q[i, 0])
                loy, hiy = min(loy, q[i, 1]), max(hiy, q[i, 1])
        box[b, 0], box[b, 1], box[b, 2], box[b, 3] = lox, loy, hix, hiy
    return box


@njit(cache=True)
def polyline_crossings(pts, a_x, a_y, s_x, pm, pn, adjacent_only):
    """Every crossing in projection of the polyline ``pts`` (P + 1, 3) with itself and
    its images (m, n), |m| <= 1, |n| <= 2 (|n| = 1 only with ``adjacent_only``), the
    image (m, n) mirrored (z -> -z) when pm m + pn n is odd: rows (m, n, i, j, s, u,
    z of the cell's strand, z of the image's), piece i of the polyline meeting piece j
    of the image at parameters s, u in [0, 1), in the order of
    ``topology.crossings_reference``: images m, then n, ascending, then (i, j). The image
    (m, n) sits at (m a_x + n s_x, n a_y) (``s_x`` the wale vector's skew)."""
    n_p = pts.shape[0] - 1
    p0, p1 = pts[:-1], pts[1:]
    d = p1 - p0
    box = _block_boxes(p0, p1)
    nb = box.shape[0]
    q0, q1 = np.empty_like(p0), np.empty_like(p1)
    e = np.empty_like(d)
    out = np.empty((64, 8))
    k = 0
    wide = int(np.ceil(2.0 * abs(s_x) / a_x))
    for m in range(-1 - wide, 2 + wide):
        for n in range(-2, 3):
            if adjacent_only and abs(n) != 1:
                continue
            sx, sy = m * a_x + n * s_x, n * a_y
            fz = -1.0 if (pm * m + pn * n) % 2 != 0 else 1.0
            for j in range(n_p):  # as numpy's p * (1, 1, ±1) + (sx, sy, 0), then q1 - q0
                q0[j, 0], q0[j, 1], q0[j, 2] = p0[j, 0] + sx, p0[j, 1] + sy, p0[j, 2] * fz + 0.0
                q1[j, 0], q1[j, 1], q1[j, 2] = p1[j, 0] + sx, p1[j, 1] + sy, p1[j, 2] * fz + 0.0
                for c in range(3):
                    e[j, c] = q1[j, c] - q0[j, c]
            first = k
            for bi in range(nb):
                for bj in range(nb):
                    if (box[bj, 0] + sx > box[bi, 2] + BOX_MARGIN
                            or box[bi, 0] > box[bj, 2] + sx + BOX_MARGIN
                            or box[bj, 1] + sy > box[bi, 3] + BOX_MARGIN
                            or box[bi, 1] > box[bj, 3] + sy + BOX_MARGIN):  # fmt: skip
                        continue
                    for i in range(bi * BLOCK, min((bi + 1) * BLOCK, n_p)):
                        for j in range(bj * BLOCK, min((bj + 1) * BLOCK, n_p)):
                            if m == 0 and n == 0 and (j <= i + 1 or (i == 0 and j == n_p - 1)):
                                continue  # each self-crossing once; neighbours never
                            w0, w1 = q0[j, 0] - p0[i, 0], q0[j, 1] - p0[i, 1]
                            den = d[i, 0] * e[j, 1] - d[i, 1] * e[j, 0]
                            if not abs(den) > 1e-14:
                                continue
                            s = (w0 * e[j, 1] - w1 * e[j, 0]) / den
                            u = (w0 * d[i, 1] - w1 * d[i, 0]) / den
                            if not (s >= 0 and s < 1 and u >= 0 and u < 1):
                                continue
                            if k == out.shape[0]:
                                grown = np.empty((2 * k, 8))
                                grown[:k] = out
                                out = grown
                            out[k, 0], out[k, 1], out[k, 2], out[k, 3] = m, n, i, j
                            out[k, 4], out[k, 5] = s, u
                            out[k, 6] = p0[i, 2] + s * d[i, 2]
                            out[k, 7] = q0[j, 2] + u * e[j, 2]
                            k += 1
            if k - first > 1:  # this image's crossings in (i, j) order
                key = out[first:k, 2] * n_p + out[first:k, 3]
                order = np.argsort(key)
                out[first:k] = out[first:k][order]
    return out[:k]


@njit(cache=True)
def pattern_min_zeta(pts, s_mid, s_tot, a_x, a_y, s_x, r, r_core, pm, pn, s_excl):
    """Smallest ζ over the counted contacts of the samples ``pts`` (N, 3) (midpoint
    arclengths ``s_mid``, total ``s_tot``) with the images (m, n), |m| <= 2, |n| <= 3,
    mirrored when pm m + pn n is odd, same-row pairs within ``s_excl`` along the yarn
    left out; and where: (ζ, m, n, i, j) with the samples i of the cell and j of the
    image (ζ = 1, i = -1 if nothing touches), as ``patterns.min_zeta_where`` finds it
    (each image's first nearest pair, images in order, the first of equal ζ kept). The
    image (m, n) sits at (m a_x + n s_x, n a_y); a skew widens the range of m to reach
    as far."""
    ns = pts.shape[0]
    d = 2 * r - 2 * r_core
    lo = np.empty(3)
    hi = np.empty(3)
    for c in range(3):
        lo[c], hi[c] = pts[:, c].min(), pts[:, c].max()
    q = np.empty_like(pts)
    best, bm, bn, bi, bj = 1.0, 0, 0, -1, -1
    wide = int(np.ceil(3.0 * abs(s_x) / a_x))
    for m in range(-2 - wide, 3 + wide):
        for n in range(-3, 4):
            fz = -1.0 if (pm * m + pn * n) % 2 != 0 else 1.0
            for j in range(ns):  # as numpy's copy, z *= -1, += (m a_x, n a_y, 0.0)
                q[j, 0] = pts[j, 0] + (m * a_x + n * s_x)
                q[j, 1] = pts[j, 1] + n * a_y
                q[j, 2] = pts[j, 2] * fz + 0.0
            far = False
            for c in range(3):
                if q[:, c].min() - hi[c] >= 2 * r or lo[c] - q[:, c].max() >= 2 * r:
                    far = True
            if far:
                continue  # every sample of the image 2r away or more: no contact counted
            # a pair 2r apart or more cannot count (the bound a little beyond (2r)², for
            # the roundings), nor be nearer than the nearest so far (the square root is
            # monotone: rr below the nearest's rr is necessary)
            dmin, rmin, wi, wj = np.inf, 4 * r * r * (1.0 + 1e-9), 0, 0
            for i in range(ns):
                for j in range(ns):
                    dx = pts[i, 0] - q[j, 0]
                    dy = pts[i, 1] - q[j, 1]
                    dz = pts[i, 2] - q[j, 2]
                    rr = dx * dx + dy * dy + dz * dz
                    if not rr < rmin:
                        continue
                    if n == 0 and abs(s_mid[i] - s_mid[j] - m * s_tot) <= s_excl:
                        continue  # the same row: neighbours along the yarn (§6)
                    dist = math.sqrt(rr)
                    if dist < dmin:
                        dmin, rmin, wi, wj = dist, rr, i, j
            z = (dmin - 2 * r_core) / d
            if dmin < 2 * r and z < best:
                best, bm, bn, bi, bj = z, m, n, wi, wj
    return best, bm, bn, bi, bj


def compile_checks() -> None:
    """Compile (or load from numba's cache) both kernels for the argument types their
    callers pass, without running them (``compilation.compile_group``)."""
    f, i = numba.float64, numba.int64
    pts = numba.float64[:, ::1]
    polyline_crossings.compile((pts, f, f, f, i, i, numba.boolean))
    pattern_min_zeta.compile((pts, numba.float64[::1], f, f, f, f, f, f, i, i, f))
