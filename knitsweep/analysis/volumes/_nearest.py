"""Distances from points to the yarn's centre-line pieces (numba; docs/model.md §9,
"Contact volumes"). Plain arrays in, plain arrays out; no knitsweep imports.

The centre-line is a polyline of segments ``a[q] -> b[q]`` (mm), grouped in chunks of
consecutive segments with a bounding sphere each, so that a query visits only the
chunks that can come within ``r`` of it.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, inline="always")
def _segment_distance(x0, x1, x2, a, b, q):
    """Distance (mm) from point (x0, x1, x2) to segment q of a (M, 3) -> b (M, 3)."""
    d0 = b[q, 0] - a[q, 0]
    d1 = b[q, 1] - a[q, 1]
    d2 = b[q, 2] - a[q, 2]
    w0 = x0 - a[q, 0]
    w1 = x1 - a[q, 1]
    w2 = x2 - a[q, 2]
    dd = d0 * d0 + d1 * d1 + d2 * d2
    t = (w0 * d0 + w1 * d1 + w2 * d2) / dd if dd > 0.0 else 0.0
    t = min(1.0, max(0.0, t))
    e0 = w0 - t * d0
    e1 = w1 - t * d1
    e2 = w2 - t * d2
    return np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)


@njit(cache=True, parallel=False)
def nearest_pieces(x, s0, a, b, s_mid, piece, closed_length, chunk_lo, chunk_hi, centre,
                   radius, chunk_s_lo, chunk_s_hi, block_lo, block_hi, block_centre, block_radius, r, window, d_own,
                   d_other, p_other):  # fmt: skip
    """For each query point, the distance to the stitch's own piece and to the others.

    x (N, 3): query points, mm. s0 (N,): arc coordinate of the query's foot point on
    the own piece (mm), or NaN for no exclusion. a, b (M, 3): segment ends; s_mid (M,):
    arc coordinate of each segment's midpoint along its row's yarn (mm; NaN for pieces
    of other rows); piece (M,): 0 for the own piece, else the index of its image.
    closed_length: arc length of a closed own piece (> 0: arc distances wrap), else 0.
    Chunks c: segments chunk_lo[c] .. chunk_hi[c] - 1 inside the sphere centre[c],
    radius[c]; blocks k: chunks block_lo[k] .. block_hi[k] - 1 inside the sphere
    block_centre[k], block_radius[k] (a second level of culling); chunk_s_lo,
    chunk_s_hi (C,): the arc range of a chunk's segment midpoints (NaN off the own
    row), so that a chunk wholly inside the skipped window is not visited. Segments of the own row whose midpoint lies within ``window`` mm of
    s0 along the yarn are skipped (the query's own branch of the tube).

    Writes d_own (N,): distance to the own piece's centre-line; d_other (N,): to the
    nearest other piece's; p_other (N,): that piece (-1 if none within r). Distances
    beyond r are written as inf.
    """
    n = x.shape[0]
    for i in prange(n):
        x0 = x[i, 0]
        x1 = x[i, 1]
        x2 = x[i, 2]
        excl = not np.isnan(s0[i])
        best_own = np.inf
        best_other = np.inf
        who = -1
        for k in range(block_lo.shape[0]):
            f0 = x0 - block_centre[k, 0]
            f1 = x1 - block_centre[k, 1]
            f2 = x2 - block_centre[k, 2]
            if np.sqrt(f0 * f0 + f1 * f1 + f2 * f2) - block_radius[k] > r:
                continue
            for c in range(block_lo[k], block_hi[k]):
                e0 = x0 - centre[c, 0]
                e1 = x1 - centre[c, 1]
                e2 = x2 - centre[c, 2]
                if np.sqrt(e0 * e0 + e1 * e1 + e2 * e2) - radius[c] > r:
                    continue
                if (excl and closed_length == 0.0 and chunk_s_lo[c] > s0[i] - window
                        and chunk_s_hi[c] < s0[i] + window):  # fmt: skip
                    continue
                for q in range(chunk_lo[c], chunk_hi[c]):
                    if excl and not np.isnan(s_mid[q]):
                        ds = abs(s_mid[q] - s0[i])
                        if closed_length > 0.0 and piece[q] == 0:
                            ds = min(ds, closed_length - ds)
                        if ds < window:
                            continue
                    d = _segment_distance(x0, x1, x2, a, b, q)
                    if d > r:
                        continue
                    if piece[q] == 0:
                        if d < best_own:
                            best_own = d
                    elif d < best_other:
                        best_other = d
                        who = piece[q]
        d_own[i] = best_own
        d_other[i] = best_other
        p_other[i] = who
