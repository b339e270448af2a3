"""A tile of fabric as geometry: what is drawn (``Stitch``: a cell's control points, its
periods and the parity of its mirrored images), which copy of the cell is mirrored,
the yarn of a row through its copies, and the centre-line sampled along a cell with
rotation-minimising frames for its tube (docs/model.md §11 "Drawing a pattern"). Lengths
in mm."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import StitchParams
from ..kernels.bezier import basis_tables
from ..stitches.base import MIRROR, is_mirrored

ROW_COLOURS = ("#c8553d", "#3a7ca5", "#d9a21b", "#6a994e", "#8e5572")
"""Base colour of each row (course) of yarn, cycling: one colour along a row's whole
yarn, through its knit and purl stitches alike (no colour changes at cell boundaries);
the pictures' and the 3D files' (PLY vertex colours)."""


@dataclass(frozen=True)
class Stitch:
    """What is drawn: the cell's control points (S, 6, 3) in drawing order, mm, its
    periods a_x, a_y (mm), the yarn radius r (mm), a one-line description and the
    shift in periods (course, wale) after which the path repeats along its row, and the
    mirror parity (pm, pn) of its images: the copy at lattice offset (m, n) is mirrored
    (z → −z) when pm m + pn n is odd ((0, 0): translations only); ``params``: the
    stitch's parameters (the picture's title, the 3D file's metadata), if known."""

    control_points: np.ndarray
    a_x: float
    a_y: float
    r_mm: float
    label: str
    closing_shift: tuple[int, int] = (1, 0)
    mirror_parity: tuple[int, int] = (0, 0)
    params: StitchParams | None = None

    @property
    def name(self) -> str:
        """The stitch pattern's name ("stitch" when the parameters are unknown)."""
        return self.params.stitch if self.params is not None else "stitch"

    @property
    def repeat(self) -> tuple[int, int]:
        """(copies along a row, rows) after which the fabric repeats itself by a pure
        translation: 2 along a row whose next copy is mirrored (rib, seed), 2 rows
        where the next row is (garter, seed), else 1 (stockinette)."""
        cs = self.closing_shift
        along = (self.mirror_parity[0] * cs[0] + self.mirror_parity[1] * cs[1]) % 2
        return 1 + along, 1 + self.mirror_parity[1] % 2

    @property
    def t_c(self) -> np.ndarray:
        """The vector by which one cell's path repeats along its row, mm."""
        return np.array([self.closing_shift[0] * self.a_x, self.closing_shift[1] * self.a_y, 0.0])

    @property
    def mirrors(self) -> bool:
        """Whether some images are mirrored (a knit/purl pattern, docs/model.md §11)."""
        return any(self.mirror_parity)

    def mirrored(self, m: int, n: int) -> bool:
        """Whether the image at lattice offset (m, n) (m t_c + n t_w) is mirrored."""
        return is_mirrored(self.mirror_parity, m, n)


def copy_mirrored(stitch: Stitch, row: int, column: int) -> bool | None:
    """Whether the copy ``column`` of row ``row`` (lattice offset column·closing_shift +
    (0, row)) is mirrored; None for a stitch of translations alone."""
    if not stitch.mirrors:
        return None
    cs = stitch.closing_shift
    return stitch.mirrored(column * cs[0], column * cs[1] + row)


def unit_cell(stitch: Stitch, cells: int) -> tuple[int, int]:
    """(row, column) of the copy ``--highlight`` saturates: the middle one of the
    ``cells`` × ``cells`` window, or, if that copy is a mirror image, the nearest
    unmirrored copy below or to the left (the cell itself, not its purl image)."""
    mid = cells // 2
    for row, column in ((mid, mid), (mid - 1, mid), (mid, mid - 1), (mid - 1, mid - 1)):
        if not copy_mirrored(stitch, row, column):
            return row, column
    return mid, mid


def row_path(stitch: Stitch, one: np.ndarray, row: int, columns: range) -> np.ndarray:
    """The yarn of row ``row`` through the cells ``columns`` (consecutive), shape
    (len(columns)·(k − 1) + 1, 3), mm: the cell's path ``one`` (k, 3) at each copy
    j = column·closing_shift + (0, row), mirrored (z → −z) where the stitch's images
    are (``Stitch.mirrored``), then shifted by column t_c + row t_w; the end point of the
    last copy closes the row. With no mirrored image: the translations alone, computed
    as before mirrors existed (the same floating-point sums, the same pictures)."""
    t_c = stitch.t_c
    t_w = np.array([0.0, stitch.a_y, 0.0])

    def copy(points: np.ndarray, c: int) -> np.ndarray:
        if copy_mirrored(stitch, row, c):
            points = points * MIRROR
        return points + c * t_c + row * t_w

    return np.concatenate([copy(one[:-1], c) for c in columns]
                          + [copy(one[-1:], columns[-1])])  # fmt: skip


def cell_path(control_points: np.ndarray, samples: int = 24) -> np.ndarray:
    """The cell's yarn centre-line, shape (S·samples + 1, 3), mm: each segment sampled
    at ``samples`` + 1 equally spaced t, joins not repeated."""
    cp = np.asarray(control_points, dtype=float)
    if cp.ndim != 3 or cp.shape[1:] != (6, 3):
        raise ValueError(f"control points: expected shape (S, 6, 3), got {cp.shape}")
    basis = basis_tables(np.linspace(0.0, 1.0, samples + 1))[0]  # (samples + 1, 6)
    pts = np.einsum("ti,sik->stk", basis, cp)  # (S, samples + 1, 3)
    return np.concatenate([pts[:, :-1].reshape(-1, 3), pts[-1, -1:]], axis=0)


def frames(path: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit tangents, normals and binormals along ``path`` (n, 3), each (n, 3):
    rotation-minimising frames (double reflection, Wang et al. 2008), so that a
    tube built on them does not twist."""
    p = np.asarray(path, dtype=float)
    t = np.gradient(p, axis=0)
    t /= np.linalg.norm(t, axis=1)[:, None]
    n = len(p)
    normal = np.empty((n, 3))
    seed = np.array([0.0, 0.0, 1.0]) if abs(t[0, 2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    normal[0] = np.cross(t[0], np.cross(seed, t[0]))
    normal[0] /= np.linalg.norm(normal[0])
    v1 = np.diff(p, axis=0)
    c1 = np.einsum("ij,ij->i", v1, v1)
    for i in range(n - 1):
        if c1[i] == 0.0:
            normal[i + 1] = normal[i]
            continue
        rl = normal[i] - (2.0 / c1[i]) * (v1[i] @ normal[i]) * v1[i]
        tl = t[i] - (2.0 / c1[i]) * (v1[i] @ t[i]) * v1[i]
        v2 = t[i + 1] - tl
        c2 = v2 @ v2
        normal[i + 1] = rl - (2.0 / c2) * (v2 @ rl) * v2 if c2 > 0.0 else rl
    return t, normal, np.cross(t, normal)


def dense_cell_samples(control_points: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """The cell's yarn centre-line sampled at most ``spacing`` mm apart (roughly): points
    (k, 3), mm, and their global parameter t in [0, S] (k,); each segment gets enough
    equally spaced t for its control-polygon length (an upper bound on its arc length),
    the same count in every copy, so that a tile's sampling repeats with the cell."""
    cp = np.asarray(control_points, dtype=float)
    parts, ts = [], []
    for s, seg in enumerate(cp):
        polygon = float(np.sum(np.linalg.norm(np.diff(seg, axis=0), axis=1)))
        n = max(8, int(np.ceil(polygon / spacing)))
        t = np.linspace(0.0, 1.0, n + 1)
        parts.append((basis_tables(t)[0] @ seg)[:-1])
        ts.append(s + t[:-1])
    parts.append(cp[-1, -1:])
    ts.append(np.array([float(len(cp))]))
    return np.concatenate(parts), np.concatenate(ts)


def dense_cell_path(control_points: np.ndarray, spacing: float) -> np.ndarray:
    """The points of :func:`dense_cell_samples`, shape (k, 3), mm."""
    return dense_cell_samples(control_points, spacing)[0]
