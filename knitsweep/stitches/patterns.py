"""Knit/purl patterns on the free yarn: their images, garter's starting shape and the
check that refuses overlapping starts (docs/model.md §11); numpy, the overlap check
compiled (``kernels.checks``).

A pattern repeats one stitch's cell under translations and glide reflections: the image
at (m, n) is mirrored through the fabric plane z = 0 when pm m + pn n is odd
(``PARITIES``). Garter's rows are separate yarns, so its one-stitch cell is a knit
stitch whose odd rows are its mirror images; ``garter_start`` builds such a stitch
from a stockinette one by an affine map (which keeps every joint G2 and the periodicity
along the course), ``garter_crossings`` says which crossing signs the garter fabric
must show, and ``check_start`` refuses a start whose hard cores overlap, naming where.
"""

from __future__ import annotations

from collections import Counter
from math import comb

import numpy as np

from ..errors import InputError
from ..kernels.arclength import arclength_sample_cell, yarn_sample_cell
from ..kernels.checks import pattern_min_zeta
from .base import image_points

PARITIES = {"stockinette": (0, 0), "garter": (0, 1), "rib": (1, 0), "seed": (1, 1)}
"""(pm, pn) per pattern: image (m, n) mirrored when pm m + pn n is odd."""

GARTER_STRETCH, GARTER_LIFT, GARTER_SHEAR = 1.3, 1.0, -0.7
"""The affine map of ``garter_start``: y -> 1.3 y, then z -> z + 1.0 mm - 0.7 y (the
stitch tilted out of the plane, lifted off the mirror plane, rows spread). Chosen on
a grid (stretch 1, 1.15, 1.3, 1.5; lift 0 … 1.6 mm; shear −1.2 … −0.1) among the maps
that give Init_1 garter's crossing signs and no hard-core overlap (min ζ 0.097 over the
rows, docs/model.md §11), the one with the shortest yarn of those checked (14.58 mm)."""

EXCLUSION_FACTOR = 2.1  # as the contact kernel's (docs/model.md §6)
MIN_ZETA = 1e-5  # below it the hard cores overlap (§6)


def garter_start(cp: np.ndarray, a_x: float, a_y: float, stretch: float = GARTER_STRETCH,
                 lift: float = GARTER_LIFT, shear: float = GARTER_SHEAR):  # fmt: skip
    """A garter stitch from a stockinette one: control points (S, 6, 3) mm and periods
    mapped by y -> stretch y, z -> z + lift + shear y (affine, so G2 and the closing
    shift t_c survive). Returns (cp, a_x, a_y)."""
    out = np.array(cp, dtype=float)
    out[..., 1] *= stretch
    out[..., 2] += lift + shear * out[..., 1]
    return out, a_x, a_y * stretch


def pattern_crossings(stockinette: Counter, parity: tuple[int, int]) -> Counter:
    """A pattern's crossing signs (m, n, sign) from stockinette's (``topology.crossings``
    of the same yarn), for mirror parities ``parity`` (``PARITIES``).

    Every crossing of the cell with an image in another row is where a loop is pulled
    through the loop below it: the stitch directly above the lower strand's stitch,
    (m, 0) for an image below (n < 0) and (0, n) for one above. A knit stitch pulls its
    loop through from the back, a purl stitch (mirrored) from the front, so a crossing
    changes sign from stockinette's exactly when that stitch is mirrored. (Seen from the
    partner the same crossing has the same sign when the partner is a mirror image and
    the opposite sign when it is a translate: the rule gives both.)"""
    out: Counter = Counter()
    for (m, n, s), c in stockinette.items():
        puller = (m, 0) if n < 0 else (0, n)
        flip = n != 0 and (parity[0] * puller[0] + parity[1] * puller[1]) % 2 == 1
        out[(m, n, -s if flip else s)] += c
    return out


def garter_crossings(stockinette: Counter) -> Counter:
    """Garter's crossing signs (``pattern_crossings`` with garter's parities): the
    crossings with the purl row above change sign, those with the row below keep
    stockinette's (the cell's own loop is pulled through them, from the back)."""
    return pattern_crossings(stockinette, PARITIES["garter"])


def _samples(cp: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Midpoint samples (S n, 3), their midpoint arclengths (S n,) and the total (§6)."""
    t = (np.arange(n) + 0.5) / n
    b0 = np.stack([comb(5, i) * t**i * (1 - t) ** (5 - i) for i in range(6)], axis=1)
    b1 = 5 * np.stack([(comb(4, i - 1) * t ** (i - 1) * (1 - t) ** (5 - i) if i > 0 else 0 * t)
                       - (comb(4, i) * t**i * (1 - t) ** (4 - i) if i < 5 else 0 * t)
                       for i in range(6)], axis=1)  # fmt: skip
    pts = np.concatenate([b0 @ cp[s] for s in range(cp.shape[0])])
    speed = np.concatenate([np.linalg.norm(b1 @ cp[s], axis=1) for s in range(cp.shape[0])])
    total = np.cumsum(speed) / n
    return pts, total - 0.5 * speed / n, float(total[-1])


def min_zeta_where(cp, a_x, a_y, r, r_core, parity=(0, 0), samples=10, arc_rule=None, skew=0.0):
    """Smallest ζ over the counted contacts of the pattern (images mirrored by
    ``parity``; same-row neighbours along the yarn excluded as in §6) and where:
    (ζ, (m, n), segment of the cell, segment of the image); ζ = 1 if nothing touches.
    Compiled (``kernels.checks.pattern_min_zeta``): bit for bit what
    ``min_zeta_where_reference`` finds (which samples that are not finite are left to).
    With a non-empty ``arc_rule`` (2, K) the samples sit at arclength fractions of each
    segment, or with a third row evenly along the whole yarn (``kernels.arclength``), as
    the contact sum's then do. ``skew``: the wale vector's x component (a sheared cell)."""
    if arc_rule is not None and arc_rule.shape[1] > 0:
        place = yarn_sample_cell if arc_rule.shape[0] == 3 else arclength_sample_cell
        pts, _, _, _, s_mid, s_tot, _ = place(np.asarray(cp, dtype=float), samples, arc_rule)
        if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(s_mid))):
            return (-np.inf, None, None, None)
    else:
        pts, s_mid, s_tot = _samples(np.asarray(cp, dtype=float), samples)
    if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(s_mid))):
        return min_zeta_where_reference(cp, a_x, a_y, r, r_core, parity, samples, skew)
    z, m, n, i, j = pattern_min_zeta(pts, s_mid, s_tot, float(a_x), float(a_y), float(skew),
                                     float(r), float(r_core), int(parity[0]), int(parity[1]),
                                     EXCLUSION_FACTOR * r)  # fmt: skip
    if i < 0:
        return (1.0, None, None, None)
    return (float(z), (int(m), int(n)), int(i // samples), int(j // samples))


def min_zeta_where_reference(cp, a_x, a_y, r, r_core, parity=(0, 0), samples=10, skew=0.0):
    """``min_zeta_where`` in numpy: the reference the compiled one is tested against."""
    pts, s_mid, s_tot = _samples(np.asarray(cp, dtype=float), samples)
    d = 2 * r - 2 * r_core
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    images, copies = [], []
    wide = int(np.ceil(3.0 * abs(skew) / a_x))
    for m in range(-2 - wide, 3 + wide):
        for n in range(-3, 4):
            q = image_points(pts, m, n, a_x, a_y, parity, skew)
            if np.any(q.min(axis=0) - hi >= 2 * r) or np.any(lo - q.max(axis=0) >= 2 * r):
                continue  # every sample of the image 2r away or more: no contact counted
            images.append((m, n))
            copies.append(q)
    if not images:
        return (1.0, None, None, None)
    diff = pts[None, :, None] - np.stack(copies)[:, None]  # (images, cell sample, image sample)
    dist = np.sqrt(diff[..., 0] ** 2 + diff[..., 1] ** 2 + diff[..., 2] ** 2)  # as norm sums
    for k, (m, n) in enumerate(images):
        if n == 0:  # the same row: neighbours along the yarn are no contact (§6)
            near = np.abs(s_mid[:, None] - s_mid[None] - m * s_tot) <= EXCLUSION_FACTOR * r
            dist[k][near] = np.inf
    flat = dist.reshape(len(images), -1)
    where = np.argmin(flat, axis=1)  # each image's first smallest distance, row by row
    best = (1.0, None, None, None)
    for k, image in enumerate(images):  # in the images' order: the first of equal ζ wins
        i, j = divmod(int(where[k]), dist.shape[2])
        z = (flat[k, where[k]] - 2 * r_core) / d
        if flat[k, where[k]] < 2 * r and z < best[0]:
            best = (float(z), image, int(i // samples), int(j // samples))
    return best


def check_start(
    cp,
    a_x,
    a_y,
    r,
    r_core,
    parity=(0, 0),
    label="start",
    samples=10,
    compiled=True,
    arc_rule=None,
    segment_names=None,
) -> float:
    """min ζ of a starting state; InputError naming where if the hard cores overlap.
    ``compiled=False``: by ``min_zeta_where_reference`` (the same ζ, bit for bit, without
    compiling the check's kernel: what a command checking one start before it compiles
    anything uses), unless the samples sit by arclength (a non-empty ``arc_rule``, as in
    ``min_zeta_where``), which only the compiled check places. ``segment_names``: what
    the message calls each segment (``Stitch.segment_names``)."""
    if arc_rule is not None and arc_rule.shape[1] > 0:
        z, image, sa, sb = min_zeta_where(cp, a_x, a_y, r, r_core, parity, samples, arc_rule)
    else:
        where = min_zeta_where if compiled else min_zeta_where_reference
        z, image, sa, sb = where(cp, a_x, a_y, r, r_core, parity, samples)
    if not z > MIN_ZETA:
        a, b = (f"segment {sa}", f"segment {sb}") if segment_names is None else (
            segment_names[sa], segment_names[sb])  # fmt: skip
        raise InputError(f"{label} = overlapping yarn: min zeta {z:.3g} <= {MIN_ZETA:g} between "
                         f"{a} of the cell and {b} of its image {image}: "
                         f"a start must keep the hard cores apart")  # fmt: skip
    return z


def _turning(cp: np.ndarray, nodes: int) -> np.ndarray:
    """∫ t × dt along the quintic segments ``cp`` (S, 6, 3): Σ_s ∫₀¹ (r′ × r″)/|r′|² du,
    Gauss–Legendre with ``nodes`` nodes per segment (radians, a vector)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    u, w = 0.5 * (x + 1.0), 0.5 * w
    d1 = np.stack([5 * comb(4, i) * u**i * (1 - u) ** (4 - i) for i in range(5)], axis=1)
    d2 = np.stack([20 * comb(3, i) * u**i * (1 - u) ** (3 - i) for i in range(4)], axis=1)
    total = np.zeros(3)
    for seg in np.asarray(cp, dtype=float):
        v = d1 @ np.diff(seg, axis=0)  # r′(u), (nodes, 3)
        a = d2 @ np.diff(seg, n=2, axis=0)  # r″(u)
        total += (w[:, None] * np.cross(v, a) / np.sum(v * v, axis=1)[:, None]).sum(axis=0)
    return total


def net_bending_moment(cp: np.ndarray, parity: tuple[int, int], B: float,
                       nodes: int = 32) -> np.ndarray:  # fmt: skip
    """The yarn's bending moment summed over one repeat of the fabric, per stitch:
    B ∫ t × dt (an elastica's moment is B t × dt/ds), N·mm² with B in N·mm², shape (3,).

    Its in-plane components are a moment that the fabric carries at every cut and that a
    free edge releases by curling (docs/model.md §11, "Curl"). Over a pattern with
    mirrored images the repeat holds the stitch and its mirror image (z -> -z), whose
    moment is the cell's with its x and y components reversed (a moment is an axial
    vector): a pattern with purl stitches carries none in the plane, whatever its shape;
    stockinette, which mirrors nothing, can."""
    m = B * _turning(cp, nodes)
    if not any(parity):
        return m
    mirrored = B * _turning(np.asarray(cp, dtype=float) * np.array([1.0, 1.0, -1.0]), nodes)
    return 0.5 * (m + mirrored)
