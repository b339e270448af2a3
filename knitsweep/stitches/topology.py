"""The topology of a stitch's fabric as crossing signs in projection (docs/model.md §11).

Yarn cannot pass through yarn, so a relaxation keeps the over/under of every crossing
that the fabric shows seen from above (along −z). ``crossings(cp, a_x, a_y)`` samples
the cell's yarn (control points ``cp`` (S, 6, 3), mm, path order, closing after one
course period) as a polyline, projects the cell and its images m t_c + n t_w
(|m| <= 1, |n| <= 2) onto the fabric plane, and lists every crossing of the cell's
yarn with itself or an image as (m, n, sign): sign +1 where the cell's strand passes
over the image's (larger z). Segment labels are left out on purpose: a crossing slides
along the yarn as the stitch relaxes, from a connector onto a crossover curve, without
any change of topology (seen at L = 10.5 mm in the free yarn, docs/model.md §11).
``same_topology`` compares two such lists as multisets; a difference (a crossing gained,
lost, or with its sign flipped) means the states are not one fabric, or that a pair of
crossings appeared or vanished (a Reidemeister II move in projection), which is flagged
the same way: the check errs on the side of reporting. The search is compiled
(``kernels.checks``); ``crossings_reference`` is the same in numpy.
"""

from __future__ import annotations

import math
from collections import Counter
from math import comb

import numpy as np

from ..kernels.checks import polyline_crossings
from .base import image_points

TOPOLOGY_CHANGED = "topology changed"
"""How every verdict of a relaxed free yarn that left its stitch's crossings begins
(``CellModel.topology_change``)."""

SAMPLES = 48
"""Polyline pieces per segment."""


def _polyline(cp: np.ndarray, samples: int) -> np.ndarray:
    """Points (S*samples + 1, 3) along the yarn, mm."""
    t = np.linspace(0.0, 1.0, samples + 1)[:-1]
    basis = np.stack([comb(5, i) * t**i * (1 - t) ** (5 - i) for i in range(6)], axis=1)
    pts = np.concatenate([basis @ cp[s] for s in range(cp.shape[0])])
    return np.vstack([pts, cp[-1, 5]])


def crossings(cp: np.ndarray, a_x: float, a_y: float, samples: int = SAMPLES,
              parity: tuple[int, int] = (0, 0), heights: list | None = None,
              along: list | None = None, adjacent_only: bool = False,
              skew: float = 0.0) -> Counter:  # fmt: skip
    """Crossings in projection of the cell's yarn with itself and its images, as a
    Counter of (m, n, sign) (see the module docstring).

    ``parity`` (pm, pn): the image (m, n) is mirrored (z -> -z) when pm m + pn n is odd
    (docs/model.md §11: garter (0, 1), rib (1, 0), seed (1, 1)). ``heights``, if given,
    receives (m, n, z of the cell's strand, z of the image's) of every crossing;
    ``along`` receives (position along the cell's yarn in polyline pieces, n, sign)
    (``gauss_word``). ``adjacent_only``: the images in the rows just above and below
    (|n| = 1) alone. Compiled (``kernels.checks.polyline_crossings``): the same
    crossings, positions and heights, in the same order, as ``crossings_reference``
    (which a polyline with non-finite points is left to). ``skew``: the wale vector's
    x component (t_w = (skew, a_y), mm; a sheared cell)."""
    pts = _polyline(np.asarray(cp, dtype=float), samples)
    if not np.all(np.isfinite(pts)):
        return crossings_reference(cp, a_x, a_y, samples, parity, heights, along, adjacent_only,
                                   skew)  # fmt: skip
    out: Counter = Counter()
    rows = polyline_crossings(pts, float(a_x), float(a_y), float(skew), int(parity[0]),
                              int(parity[1]), adjacent_only)  # fmt: skip
    for m_, n_, i_, _, s, _, za, zb in rows:
        m, n, sign = int(m_), int(n_), 1 if za > zb else -1
        out[(m, n, sign)] += 1
        if heights is not None:
            heights.append((m, n, float(za), float(zb)))
        if along is not None:
            along.append((float(int(i_) + s), n, sign))
    return out


def crossings_reference(cp: np.ndarray, a_x: float, a_y: float, samples: int = SAMPLES,
                        parity: tuple[int, int] = (0, 0), heights: list | None = None,
                        along: list | None = None, adjacent_only: bool = False,
                        skew: float = 0.0) -> Counter:  # fmt: skip
    """``crossings`` in numpy: the reference the compiled search is tested against."""
    pts = _polyline(np.asarray(cp, dtype=float), samples)
    p0, p1 = pts[:-1], pts[1:]
    out: Counter = Counter()
    n_p = len(p0)
    d = p1 - p0
    wide = math.ceil(2.0 * abs(skew) / a_x)
    for m in range(-1 - wide, 2 + wide):
        for n in (-1, 1) if adjacent_only else (-2, -1, 0, 1, 2):
            q0, e, i_idx, j_idx, s, u, _, hit = _image_crossings(p0, p1, d, m, n, a_x, a_y,
                                                                 parity, skew)  # fmt: skip
            if m == 0 and n == 0:  # each self-crossing once; neighbouring pieces never
                hit &= (j_idx > i_idx + 1) & ~((i_idx == 0) & (j_idx == n_p - 1))
            for i, j, sij, uij in zip(i_idx[hit], j_idx[hit], s[hit], u[hit], strict=True):
                za = p0[i, 2] + sij * d[i, 2]
                zb = q0[j, 2] + uij * e[j, 2]
                out[(m, n, 1 if za > zb else -1)] += 1
                if heights is not None:
                    heights.append((m, n, float(za), float(zb)))
                if along is not None:
                    along.append((float(i + sij), n, 1 if za > zb else -1))
    return out


def _image_crossings(p0, p1, d, m, n, a_x, a_y, parity, skew) -> tuple:
    """The pieces of the cell's polyline (p0[i] → p1[i], directions ``d``) that may cross
    the pieces of its image (m, n) in projection (``_near_pieces``), and where: (q0 and e,
    the image's piece starts and directions; i, j, the candidate pairs; s, u, their
    parameters along each piece; den, d_i × e_j in the plane; hit, the pairs that cross
    within both pieces), each array over the candidate pairs."""
    q0 = image_points(p0, m, n, a_x, a_y, parity, skew)
    q1 = image_points(p1, m, n, a_x, a_y, parity, skew)
    e = q1 - q0
    i_idx, j_idx = _near_pieces(p0, p1, q0, q1)
    w = q0[j_idx, :2] - p0[i_idx, :2]
    di, ej = d[i_idx], e[j_idx]
    den = di[:, 0] * ej[:, 1] - di[:, 1] * ej[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (w[:, 0] * ej[:, 1] - w[:, 1] * ej[:, 0]) / den
        u = (w[:, 0] * di[:, 1] - w[:, 1] * di[:, 0]) / den
    hit = (np.abs(den) > 1e-14) & (s >= 0) & (s < 1) & (u >= 0) & (u < 1)
    return q0, e, i_idx, j_idx, s, u, den, hit


def _near_pieces(p0, p1, q0, q1) -> tuple[np.ndarray, np.ndarray]:
    """Every pair (i, j) of polyline pieces p0[i]→p1[i], q0[j]→q1[j] whose boxes in
    projection may overlap, as index arrays sorted by i, then j (the order of
    ``np.nonzero`` over the full i × j table, which they replace: the same crossings,
    found in the same order, from ~1 % of the pairs). Each piece is filed under the
    cell of a square grid, as wide as the widest piece, that holds its box's lower
    corner; two boxes that overlap are then filed at most one cell apart."""
    pmin, qmin = np.minimum(p0, p1)[:, :2], np.minimum(q0, q1)[:, :2]
    # an image's pieces are the cell's, shifted (and mirrored in z): as wide in x and y
    h = float(np.max(np.abs(p1 - p0)[:, :2])) * (1.0 + 1e-9) + 1e-12
    origin = np.minimum(pmin.min(axis=0), qmin.min(axis=0)) - h

    def cell(corner: np.ndarray) -> np.ndarray:
        return np.floor((corner - origin) / h).astype(np.int64)

    cp_, cq = cell(pmin), cell(qmin)
    width = int(max(cp_[:, 1].max(), cq[:, 1].max())) + 3
    key_q = cq[:, 0] * width + cq[:, 1]
    order = np.argsort(key_q, kind="stable")
    sorted_q = key_q[order]
    rows, cols = [], []
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            target = (cp_[:, 0] + dx) * width + (cp_[:, 1] + dy)
            lo = np.searchsorted(sorted_q, target, side="left")
            count = np.searchsorted(sorted_q, target, side="right") - lo
            total = int(count.sum())
            if not total:
                continue
            first = np.repeat(lo - np.cumsum(count) + count, count)
            rows.append(np.repeat(np.arange(len(pmin)), count))
            cols.append(order[first + np.arange(total)])
    if not rows:
        return np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64)
    i_idx, j_idx = np.concatenate(rows), np.concatenate(cols)
    keep = np.lexsort((j_idx, i_idx))
    return i_idx[keep], j_idx[keep]


def same_topology(before: Counter, after: Counter) -> tuple[bool, str]:
    """(True, "") if the two crossing lists agree; else (False, what differs)."""
    if before == after:
        return True, ""
    gained = after - before
    lost = before - after
    parts = []
    if lost:
        parts.append("lost " + ", ".join(f"{k}x{v}" for k, v in sorted(lost.items())[:4]))
    if gained:
        parts.append("gained " + ", ".join(f"{k}x{v}" for k, v in sorted(gained.items())[:4]))
    return False, "crossings in projection changed (m, n, sign): " + "; ".join(parts)


def gauss_word(cp: np.ndarray, a_x: float, a_y: float, parity: tuple[int, int] = (0, 0),
               samples: int = SAMPLES, adjacent_only: bool = False, skew: float = 0.0
               ) -> tuple[tuple[int, int], ...]:  # fmt: skip
    """The crossings met along the cell's yarn, in order, as (row offset n, sign), in the
    rotation that sorts first (a cyclic word: a crossing sliding across the cell's end
    rotates it). Unlike ``crossings`` it does not name the partner's column m, which a
    crossing changes when it slides across the partner cell's end (seen in garter), and
    it does tell stockinette from garter, whose (n, sign) counts agree. With
    ``adjacent_only``, the crossings with the rows just above and below alone (the word
    ``adjacent_rows`` keeps, at less cost)."""
    along: list = []
    crossings(cp, a_x, a_y, samples, parity, along=along, adjacent_only=adjacent_only, skew=skew)
    return least_rotation([(n, s) for _, n, s in sorted(along)])


def least_rotation(word: list) -> tuple:
    """The rotation of the cyclic ``word`` that sorts first (() for an empty word)."""
    return min((tuple(word[k:] + word[:k]) for k in range(len(word))), default=())


def row_period(cp: np.ndarray, a_x: float, parity: tuple[int, int] = (0, 0)):
    """(control points, course period, parities) of one whole period of a row's yarn.

    Where the course closes through a glide (rib, seed: pm = 1) a row repeats only every
    two stitches: the cell's yarn followed by its mirror image one course period on.
    That yarn closes by a translation of 2 a_x, and its images (2m, n) are mirrored
    when pn n is odd. Elsewhere the cell's yarn is the row's period."""
    if not parity[0]:
        return np.asarray(cp, dtype=float), a_x, parity
    cp = np.asarray(cp, dtype=float)
    image = image_points(cp, 1, 0, a_x, 0.0, parity)  # (1, 0): mirrored, pm = 1
    return np.concatenate([cp, image]), 2.0 * a_x, (0, parity[1])


def fabric_word(cp: np.ndarray, a_x: float, a_y: float, parity: tuple[int, int] = (0, 0),
                samples: int = SAMPLES, skew: float = 0.0) -> tuple[tuple[int, int], ...]:  # fmt: skip
    """How a row interlocks with the other rows: the cyclic ``gauss_word`` of one whole
    row period (``row_period``) with its crossings with the rows beside it (|n| = 1)
    only (``adjacent_rows``).

    A row crossing itself in projection (n = 0: the cell with itself or the stitches
    beside it) changes by Reidemeister moves without any change in how the rows hold
    each other: knit and purl columns of a rib slide behind one another as the fabric
    draws in. Over a whole row period a crossing sliding across the cell's end rotates
    the word; over the cell alone, where the course closes through a glide, it would
    come back mirrored (its sign flipped)."""
    cp2, a_x2, parity2 = row_period(cp, a_x, parity)
    return adjacent_rows(gauss_word(cp2, a_x2, a_y, parity2, samples, adjacent_only=True,
                                    skew=skew))  # fmt: skip


def adjacent_rows(word) -> tuple[tuple[int, int], ...]:
    """A cyclic word of crossings (n, sign) with those of rows other than the ones just
    above and below (|n| = 1) left out, in its least rotation. A loop is pulled through
    the loop below it and holds the one above: only those rows interlock with it. The
    row itself (n = 0) crosses itself as columns slide behind one another (a drawn-in
    rib), and rows two apart (|n| = 2) cross it in projection where a tight fabric's
    rows overlap (garter at L = 8.5 and 9.3 mm, k = 0.1 mN/mm²: 8 such crossings beside
    the 8 with the rows beside, whose order stayed garter's): neither is a change of how
    the rows hold each other."""
    return least_rotation([c for c in word if abs(c[0]) == 1])


def interlocking(cp: np.ndarray, a_x: float, a_y: float, parity: tuple[int, int] = (0, 0),
                 samples: int = SAMPLES, skew: float = 0.0
                 ) -> tuple[tuple[int, tuple[int, ...]], ...]:  # fmt: skip
    """What a relaxation must keep (``CellModel.topology_change``): along one row period,
    the runs of consecutive crossings with the same other row, as (n, the run's signs
    sorted), cyclic (``fabric_word`` grouped).

    Within a run the order may change: the cell's strand sweeping across a crossing of
    two strands of that row (a Reidemeister III move; in a drawn-in rib, where the row's
    knit and purl columns overlap) swaps two of its crossings without any change in
    how the rows hold each other. A sign that flips (yarn through yarn), a crossing
    gained or lost, or a run that moves does change the word. Unlike ``gauss_word`` it
    does not tell garter from stockinette, whose runs differ only in their order."""
    word = fabric_word(cp, a_x, a_y, parity, samples, skew)
    if not word:
        return ()
    k = next((i for i in range(len(word)) if word[i][0] != word[i - 1][0]), 0)
    word = word[k:] + word[:k]  # start at a run's first crossing
    runs: list[tuple[int, tuple[int, ...]]] = []
    for n, s in word:
        if runs and runs[-1][0] == n:
            runs[-1] = (n, (*runs[-1][1], s))
        else:
            runs.append((n, (s,)))
    return least_rotation([(n, tuple(sorted(signs))) for n, signs in runs])


def topology_word(cp: np.ndarray, a_x: float, a_y: float, parity: tuple[int, int] = (0, 0),
                  samples: int = SAMPLES, skew: float = 0.0, interlock: bool = False
                  ) -> tuple[tuple[int, tuple[int, ...]], ...]:  # fmt: skip
    """The word a relaxation of a pattern must keep (``CellModel.topology_change``), as
    runs (n, signs), with the rows beside it only (``adjacent_rows``). Where the course
    closes by a translation (garter): the cell's ``gauss_word``, every crossing in its
    order (runs of one), which tells garter from stockinette. Where it closes through a
    glide (rib), or a row of the cell holds knit and purl stitches (``interlock``, a
    chart's row, ``Stitch.mixes_row``): ``interlocking``, since there the knit and purl
    columns slide behind one another as the fabric draws in."""
    if parity[0] or interlock:
        return interlocking(cp, a_x, a_y, parity, samples, skew)
    word = adjacent_rows(gauss_word(cp, a_x, a_y, parity, samples, adjacent_only=True, skew=skew))
    return tuple((n, (s,)) for n, s in word)


def linking_sums(cp: np.ndarray, a_x: float, a_y: float, parity: tuple[int, int] = (0, 0),
                 samples: int = SAMPLES, skew: float = 0.0
                 ) -> tuple[tuple[int, int], ...]:  # fmt: skip
    """Per other row n (n != 0, every row the cell's yarn can reach in projection): the
    sum over the cell's crossings in projection with that row's yarn (its images (m, n),
    every m) of their oriented signs, over/under (+1 where the cell's strand is on top)
    times the handedness of the strands' directions in the plane (the z component of
    d_cell × d_image), as ((n, sum), ...) for the rows with a crossing.

    Two rows are two yarns, and this is their linking in projection: a pair of crossings
    that appears or vanishes as strands slide over one another (a Reidemeister II move:
    one strand on top at both, the directions crossing opposite ways) or a crossing that
    slides past another (III) leaves it as it was; a strand passing through another flips
    one crossing and changes the sum by 2. So it is what a relaxation must keep where the
    crossings themselves may rearrange: a chart's knit ribs folding over its purl ribs
    (``Stitch.keeps_linking``). The cell's crossings with its own row (one yarn) are left
    out: a loop forming in projection (I) changes their sum."""
    pts = _polyline(np.asarray(cp, dtype=float), samples)
    p0, p1 = pts[:-1], pts[1:]
    d = p1 - p0
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    reach_y = math.ceil((hi[1] - lo[1]) / a_y)
    out: Counter = Counter()
    for n in range(-reach_y, reach_y + 1):
        if n == 0:
            continue
        reach_x = math.ceil((hi[0] - lo[0] + abs(n * skew)) / a_x) + 1
        for m in range(-reach_x, reach_x + 1):
            q0, e, i_idx, j_idx, s, u, den, hit = _image_crossings(p0, p1, d, m, n, a_x, a_y,
                                                                   parity, skew)  # fmt: skip
            za = p0[i_idx, 2] + s * d[i_idx, 2]
            zb = q0[j_idx, 2] + u * e[j_idx, 2]
            sign = np.where(za > zb, 1, -1) * np.where(den > 0, 1, -1)
            out[n] += int(sign[hit].sum())
    return tuple(sorted((n, v) for n, v in out.items() if v))


def stitch_topology(stitch, cp: np.ndarray, x: np.ndarray, skew: float = 0.0) -> tuple:
    """What a relaxation of ``stitch`` (a ``Stitch``) at state ``x`` (control points
    ``cp``) must keep: ``linking_sums`` where its knit ribs may fold over its purl ribs
    (``Stitch.keeps_linking``: a chart's row with knit and purl stitches and two of a
    kind side by side), else ``topology_word``."""
    a_x, a_y = stitch.cell_periods(x)
    if stitch.keeps_linking:
        return linking_sums(cp, a_x, a_y, stitch.mirror_parity, skew=skew)
    return topology_word(cp, a_x, a_y, stitch.mirror_parity, skew=skew,
                         interlock=stitch.mixes_row)  # fmt: skip
