"""The yarn around one stitch as polylines: the stitch's own piece of centre-line and
the pieces of its neighbouring stitches (docs/model.md §3–4, §9 "Contact volumes").

A stitch's centre-line is S Bézier segments (control points (S, 6, 3), mm); the fabric
repeats it by the periods t_c = (a_x, 0, 0) and t_w = (0, a_y, 0), so image (m, n) is
the stitch m columns along and n rows up, mirrored through the fabric plane (z -> -z)
where a knit/purl pattern's mirror parity says so (``stitches.base.image_points``,
docs/model.md §11). The images m = ±1, ±2, … of row n = 0 continue the same yarn
(mirrored or not: a mirrored cell's yarn runs in the same direction): their arc
coordinate runs on from the own piece's, so that a point's own branch of the tube can be
told from a different part of the yarn by arc length, as the contact energy does
(``kernels.contact.EXCLUSION_FACTOR``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...kernels.bezier import basis_tables, even_tables, gauss_legendre
from ...stitches.base import image_points

CHUNK = 16
"""Segments per chunk of the distance search (one bounding sphere each)."""
BLOCK = 16
"""Chunks per block (a second bounding sphere around them)."""
REACH = 4
"""Images searched: |m|, |n| <= REACH, kept when their box comes within 2r of the stitch's."""


@dataclass(frozen=True)
class Pieces:
    """Polyline segments of the own piece (piece 0) and of every image that can touch
    it, as ``_nearest.nearest_pieces`` takes them.

    Attributes: a, b (M, 3) segment ends (mm); s_mid (M,) arc coordinate of each
    segment's midpoint along its row's yarn (NaN on other rows); piece (M,) int;
    offsets (P, 2) int, image (m, n) of each piece (row 0 is (0, 0)); chunk_lo,
    chunk_hi (C,) int and centre (C, 3), radius (C,) mm: the chunks; chunk_s_lo,
    chunk_s_hi (C,): the arc range of each chunk's midpoints (NaN off row 0); block_lo,
    block_hi, block_centre, block_radius: blocks of BLOCK chunks, likewise; arc_t (K,) and
    arc_s (K,): the own piece's vertices' global parameter t in [0, S] and arc
    coordinate (mm); length (mm): the own piece's arc length (by the polyline);
    closed_length: its length if the own piece is a closed loop, else 0; parity: the
    mirror parity (pm, pn) of the images (image (m, n) mirrored when pm m + pn n is odd;
    (0, 0): translations only).
    """

    a: np.ndarray
    b: np.ndarray
    s_mid: np.ndarray
    piece: np.ndarray
    offsets: np.ndarray
    chunk_lo: np.ndarray
    chunk_hi: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    chunk_s_lo: np.ndarray
    chunk_s_hi: np.ndarray
    block_lo: np.ndarray
    block_hi: np.ndarray
    block_centre: np.ndarray
    block_radius: np.ndarray
    arc_t: np.ndarray
    arc_s: np.ndarray
    length: float
    closed_length: float
    parity: tuple[int, int] = (0, 0)


def centre_line(cp: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (K, 3), mm, of the centre-line sampled at most ``spacing`` mm apart
    (each segment by its control-polygon length, an upper bound on its arc length),
    and their global parameter t in [0, S] (K,), joins not repeated."""
    cp = np.asarray(cp, dtype=float)
    pts, ts = [], []
    for s, seg in enumerate(cp):
        polygon = float(np.sum(np.linalg.norm(np.diff(seg, axis=0), axis=1)))
        n = max(4, int(np.ceil(polygon / spacing)))
        t = np.linspace(0.0, 1.0, n + 1)[:-1]
        pts.append(basis_tables(t)[0] @ seg)
        ts.append(s + t)
    pts.append(cp[-1, -1:])
    ts.append(np.array([float(len(cp))]))
    return np.concatenate(pts), np.concatenate(ts)


def arc_length(cp: np.ndarray, nodes: int = 32) -> float:
    """Arc length (mm) of the centre-line, Gauss–Legendre on each segment."""
    x, w = gauss_legendre(nodes)
    d1 = basis_tables(x)[1]  # (nodes, 6)
    speed = np.linalg.norm(np.einsum("ti,sik->stk", d1, np.asarray(cp, dtype=float)), axis=2)
    return float(np.sum(speed @ w))


def fabric_depth(cp: np.ndarray, r: float, parity: tuple[int, int] = (0, 0),
                 samples: int = 64) -> float:  # fmt: skip
    """The fabric's thickness Δz = z_max − z_min + 2r of the centre-line over the cell
    and all its images (paper SI S4 and "Contact Volumes"; docs/model.md §9, §11), from
    ``samples`` evenly spaced points of each segment, mm.

    A translated image keeps the cell's z, so for a fabric of translations alone
    (stockinette, ``parity`` (0, 0)) this is the cell's own z-range; where some images
    are mirrored through the fabric plane (z -> -z, ``image_points``: garter, rib, seed)
    the fabric spans the cell's z-range and its mirror image's."""
    z = np.einsum("ti,si->st", even_tables(samples)[0], np.asarray(cp, dtype=float)[:, :, 2])
    hi, lo = z.max(), z.min()
    if any(parity):  # some image (m, n) has pm m + pn n odd: a mirrored copy of the cell
        hi, lo = max(hi, -lo), min(lo, -hi)
    return float(hi - lo + 2.0 * r)


def build_pieces(cp: np.ndarray, a_x: float, a_y: float, r: float, spacing: float = 0.01,
                 closed: bool = False, parity: tuple[int, int] = (0, 0)) -> Pieces:  # fmt: skip
    """The own piece and every image (m, n) whose bounding box comes within 2r of the
    own piece's (|m|, |n| <= REACH), as polylines of at most ``spacing`` mm per segment,
    each image mirrored where ``parity`` says (``image_points``). ``closed``: the own
    piece is a closed loop (test shapes), so that arc distances along it wrap."""
    verts, ts = centre_line(cp, spacing)
    chord = np.linalg.norm(np.diff(verts, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(chord)])
    length = float(arc[-1])
    box = np.stack([verts.min(axis=0), verts.max(axis=0)])
    lo, hi = box[0] - 2.0 * r, box[1] + 2.0 * r
    offsets = [(0, 0)]
    for m in range(-REACH, REACH + 1):
        for n in range(-REACH, REACH + 1):
            if (m, n) == (0, 0):
                continue
            corners = image_points(box, m, n, a_x, a_y, parity)  # mirrored: z swaps ends
            if np.all(corners.max(axis=0) >= lo) and np.all(corners.min(axis=0) <= hi):
                offsets.append((m, n))
    a, b, s_mid, piece, chunks = [], [], [], [], []
    mid = 0.5 * (arc[1:] + arc[:-1])
    start = 0
    for p, (m, n) in enumerate(offsets):
        image = image_points(verts, m, n, a_x, a_y, parity)
        a.append(image[:-1])
        b.append(image[1:])
        s_mid.append(mid + m * length if n == 0 else np.full(len(mid), np.nan))
        piece.append(np.full(len(mid), p))
        for c in range(0, len(mid), CHUNK):
            chunks.append((start + c, start + min(c + CHUNK, len(mid))))
        start += len(mid)
    a, b = np.concatenate(a), np.concatenate(b)
    lo_hi = np.array(chunks, dtype=np.int64)
    # chunk boxes (segment starts plus the last end), spheres around them
    last = b[lo_hi[:, 1] - 1]
    c_lo = np.minimum(np.minimum.reduceat(a, lo_hi[:, 0], axis=0), last)
    c_hi = np.maximum(np.maximum.reduceat(a, lo_hi[:, 0], axis=0), last)
    centre = 0.5 * (c_lo + c_hi)
    radius = 0.5 * np.linalg.norm(c_hi - c_lo, axis=1)
    starts = np.arange(0, len(chunks), BLOCK)
    b_lo = np.minimum.reduceat(centre - radius[:, None], starts, axis=0)
    b_hi = np.maximum.reduceat(centre + radius[:, None], starts, axis=0)
    b_centre = 0.5 * (b_lo + b_hi)
    b_radius = 0.5 * np.linalg.norm(b_hi - b_lo, axis=1)
    bl = np.column_stack([starts, np.minimum(starts + BLOCK, len(chunks))])
    s_all = np.concatenate(s_mid)
    s_lo = np.minimum.reduceat(s_all, lo_hi[:, 0])
    s_hi = np.maximum.reduceat(s_all, lo_hi[:, 0])
    return Pieces(a, b, s_all, np.concatenate(piece).astype(np.int64),
                  np.array(offsets, dtype=np.int64), np.ascontiguousarray(lo_hi[:, 0]),
                  np.ascontiguousarray(lo_hi[:, 1]), centre, radius, s_lo, s_hi,
                  np.ascontiguousarray(bl[:, 0]), np.ascontiguousarray(bl[:, 1]), b_centre,
                  b_radius, ts, arc, length, length if closed else 0.0,
                  tuple(parity))  # fmt: skip


def distances(pieces: Pieces, x: np.ndarray, s0: np.ndarray | None, r: float,
              window: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """(d_own (N,), d_other (N,), piece of the nearest other (N,), -1 if none) for
    query points x (N, 3), mm; inf beyond r. With ``s0`` (N,), the arc coordinates of
    the queries' foot points, the yarn within ``window`` mm of s0 is skipped."""
    from ._nearest import nearest_pieces  # numba, compiled on first use

    x = np.ascontiguousarray(x, dtype=float)
    n = len(x)
    s0 = np.full(n, np.nan) if s0 is None else np.ascontiguousarray(s0, dtype=float)
    d_own, d_other = np.empty(n), np.empty(n)
    who = np.empty(n, dtype=np.int64)
    nearest_pieces(x, s0, pieces.a, pieces.b, pieces.s_mid, pieces.piece, pieces.closed_length,
                   pieces.chunk_lo, pieces.chunk_hi, pieces.centre, pieces.radius,
                   pieces.chunk_s_lo, pieces.chunk_s_hi, pieces.block_lo, pieces.block_hi, pieces.block_centre, pieces.block_radius,
                   float(r), float(window), d_own, d_other, who)  # fmt: skip
    return d_own, d_other, who
