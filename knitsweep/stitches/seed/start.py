"""Seed's starting states from the authors' stockinette ones (docs/model.md §11); numpy only.

In seed the course runs knit -> purl -> knit, so, as in rib, the cell closes through the
glide and joint 0 lies on the mirror plane. Each loop is pulled through a loop of the
other kind (the purl stitches below and above it), so, as in garter, the stitch must be
tilted out of the plane: its bottom behind the purl loop below, its legs in front of
that loop's head. The purl stitch beside it is the mirror image, tilted the other way,
so the yarn between them has to pass through the fabric plane: ``seed_start`` moves the
junction to the middle of the sinker loop (the stockinette yarn cut there, ``recut``)
and tilts the stitch by an amount that vanishes at the junction (``SEED_MAP``).
"""

from __future__ import annotations

from math import comb

import numpy as np

from ..stockinette_free.ansatz import to_free

SEED_MAP = {"kappa": 3.65, "lift": 1.48, "tilt": -0.77, "stretch_y": 0.95,
            "stretch_x": 1.47, "flatten": 0.25, "waist": 0.71}  # fmt: skip
"""The map of ``seed_start``, applied to the control points of the stockinette yarn cut
at mid-sinker (x from 0 to a_x, the stitch centred at a_x/2, y up the wale from the
sinker): x -> a_x/2 + (a_x/2)(w u + (1 - w) u³) with u = (x - a_x/2)/(a_x/2) and
w = ``waist`` (the loop narrowed, the sinker loops lengthened; the ends stay), then
x -> ``stretch_x`` x, y -> ``stretch_y`` y, and z -> ``flatten`` z + φ(x)(``lift`` +
``tilt`` y) with φ(x) = tanh(κ sin(π x / a_x)) / tanh κ (a_x the stretched period): the
stitch lifted behind the plane at its bottom and tilted forward up the wale, by the
full amount across the stitch and by nothing at the junction, where φ changes sign
(φ(x + a_x) = −φ(x): the purl stitch beside it is tilted the other way). Chosen by a
Nelder–Mead search on Init_1 (the shortest yarn with min ζ >= 0.11 over the pattern),
rounded to two decimals (docs/model.md §11)."""

_FIT = 24  # samples of the two pieces that become segment 0 (least squares)


def _split(c: np.ndarray, t: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """A quintic's control points (6, 3) split at t (de Casteljau): two quintics."""
    left, right, cur = [c[0]], [c[-1]], np.array(c, dtype=float)
    while len(cur) > 1:
        cur = (1 - t) * cur[:-1] + t * cur[1:]
        left.append(cur[0])
        right.append(cur[-1])
    return np.array(left), np.array(right[::-1])


def recut(cp: np.ndarray, a_x: float) -> np.ndarray:
    """The stockinette yarn (S, 6, 3) cut at the middle of its sinker loop (the last
    segment, split in two): 9 pieces from that point to the next, closing by t_c =
    (a_x, 0, 0), the cut at the origin. The same yarn as ``cp``, so ``crossings`` of it
    are stockinette's (only the partner columns m change with the cell's ends)."""
    cp = np.asarray(cp, dtype=float)
    first, second = _split(cp[-1])
    chain = np.array([second - [a_x, 0.0, 0.0], *cp[:-1], first])
    return chain - chain[0, 0]


def seed_map(p: np.ndarray, a_x: float, kappa: float, lift: float, tilt: float,
             stretch_y: float, stretch_x: float, flatten: float, waist: float):  # fmt: skip
    """``SEED_MAP`` applied to points ``p`` (..., 3) of the recut yarn (a new array)."""
    q = np.array(p, dtype=float)
    h = a_x / 2
    u = (q[..., 0] - h) / h
    q[..., 0] = stretch_x * (h + h * (waist * u + (1 - waist) * u**3))
    q[..., 1] *= stretch_y
    phi = np.tanh(kappa * np.sin(np.pi * q[..., 0] / (stretch_x * a_x))) / np.tanh(kappa)
    q[..., 2] = flatten * q[..., 2] + phi * (lift + tilt * q[..., 1])
    return q


def _bernstein(t: np.ndarray) -> np.ndarray:
    return np.stack([comb(5, i) * t**i * (1 - t) ** (5 - i) for i in range(6)], axis=1)


def seed_start(cp: np.ndarray, a_x: float, a_y: float, **change: float) -> np.ndarray:
    """A seed state (87,) from a stockinette stitch's control points (8, 6, 3), mm.

    The yarn is cut at mid-sinker (``recut``: 9 pieces), its control points mapped
    (``SEED_MAP``, or the entries given in ``change``); pieces 2..8 become segments 1..7
    and the first two pieces (the half sinker and the first segment) segment 0, a
    quintic fitted to them by least squares with its ends held. The free state is read
    off these segments (``ansatz.to_free``: each joint's frame from the segment leaving
    it, so every joint is G2), and the rib geometry closes it through the glide. On the
    seven Init files at L = 11 mm this has seed's crossing signs and order with min ζ
    >= 0.1 and a yarn length of 15.15–15.19 mm (tests)."""
    par = {**SEED_MAP, **change}
    chain = recut(cp, a_x)
    mapped = seed_map(chain, a_x, **par)
    out = np.empty((8, 6, 3))
    out[1:] = mapped[2:]
    t = (np.arange(_FIT) + 0.5) / _FIT
    b = _bernstein(t)
    pieces = np.concatenate([_bernstein(2 * t[t < 0.5]) @ chain[0],
                             _bernstein(2 * t[t >= 0.5] - 1) @ chain[1]])  # fmt: skip
    target = seed_map(pieces, a_x, **par)
    out[0, 0], out[0, 5] = mapped[0, 0], mapped[2, 0]
    rhs = target - np.outer(b[:, 0], out[0, 0]) - np.outer(b[:, 5], out[0, 5])
    out[0, 1:5] = np.linalg.lstsq(b[:, 1:5], rhs, rcond=None)[0]
    return to_free(out, par["stretch_x"] * a_x, par["stretch_y"] * a_y)
