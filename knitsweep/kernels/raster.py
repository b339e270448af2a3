"""A depth-buffered triangle rasteriser (a z-buffer), for pictures drawn without OpenGL.

Every pixel whose centre lies inside a front-facing triangle is a candidate; the one
nearest the viewer wins, so surfaces that pass through each other meet along their
true intersection, and each pixel is either covered or not (no splat holes, no
specks). Pixel (i, j) has its centre at (x, y) = (j + 0.5, i + 0.5), x to the right,
y downwards; with y downwards a triangle counter-clockwise as the viewer sees it has
a negative signed area, and the others (back faces) are skipped. A centre on an edge
shared by two triangles belongs to both (the tolerance ``EDGE``), so no crack opens.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

EDGE = 1e-9
"""Barycentric tolerance: a pixel centre this far outside a triangle still counts."""


@njit(cache=True)
def rasterize_triangles(xy: np.ndarray, depth: np.ndarray, triangles: np.ndarray,
                        zbuf: np.ndarray, owner: np.ndarray,
                        weights: np.ndarray) -> None:  # fmt: skip
    """Draw ``triangles`` (T, 3) of vertices ``xy`` (N, 2) pixels, ``depth`` (N,)
    (larger is nearer the viewer) into the buffers of an (H, W) image: ``zbuf``
    (H, W) the nearest depth so far (start at -inf), ``owner`` (H, W) its triangle
    (start at -1) and ``weights`` (H, W, 3) its barycentric coordinates at the pixel
    centre; each updated where a triangle is nearer."""
    h, w = zbuf.shape
    for t in range(triangles.shape[0]):
        a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        x0, y0 = xy[a, 0], xy[a, 1]
        x1, y1 = xy[b, 0], xy[b, 1]
        x2, y2 = xy[c, 0], xy[c, 1]
        area = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
        if not area < 0.0:
            continue
        lo_x = max(math.ceil(min(x0, x1, x2) - 0.5), 0)
        hi_x = min(math.floor(max(x0, x1, x2) - 0.5), w - 1)
        lo_y = max(math.ceil(min(y0, y1, y2) - 0.5), 0)
        hi_y = min(math.floor(max(y0, y1, y2) - 0.5), h - 1)
        z0, z1, z2 = depth[a], depth[b], depth[c]
        inv = 1.0 / area
        for i in range(lo_y, hi_y + 1):
            py = i + 0.5
            for j in range(lo_x, hi_x + 1):
                px = j + 0.5
                w0 = ((x2 - x1) * (py - y1) - (y2 - y1) * (px - x1)) * inv
                w1 = ((x0 - x2) * (py - y2) - (y0 - y2) * (px - x2)) * inv
                w2 = ((x1 - x0) * (py - y0) - (y1 - y0) * (px - x0)) * inv
                if w0 < -EDGE or w1 < -EDGE or w2 < -EDGE:
                    continue
                z = w0 * z0 + w1 * z1 + w2 * z2
                if z > zbuf[i, j]:
                    zbuf[i, j] = z
                    owner[i, j] = t
                    weights[i, j, 0] = w0
                    weights[i, j, 1] = w1
                    weights[i, j, 2] = w2


@njit(cache=True)
def interpolate_pixels(owner: np.ndarray, weights: np.ndarray, triangles: np.ndarray,
                       values: np.ndarray, out: np.ndarray) -> None:  # fmt: skip
    """Per-vertex ``values`` (N, C) at every covered pixel of ``owner`` (H, W) (its
    triangle, -1: none) by the barycentric ``weights`` (H, W, 3), into ``out``
    (H, W, C); uncovered pixels are left as they are."""
    h, w = owner.shape
    for i in range(h):
        for j in range(w):
            t = owner[i, j]
            if t < 0:
                continue
            a, b, c = triangles[t, 0], triangles[t, 1], triangles[t, 2]
            w0, w1, w2 = weights[i, j, 0], weights[i, j, 1], weights[i, j, 2]
            for k in range(values.shape[1]):
                out[i, j, k] = w0 * values[a, k] + w1 * values[b, k] + w2 * values[c, k]
