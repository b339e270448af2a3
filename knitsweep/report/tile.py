"""A tile of fabric as geometry: what is drawn (``Stitch``: a cell's control points, its
periods and the parity of its mirrored images), which copy of the cell is mirrored,
the yarn of a row through its copies, and the centre-line sampled along a cell with
rotation-minimising frames for its tube (docs/model.md §11 "Drawing a pattern"). Lengths
in mm."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..kernels.bezier import basis_tables
from ..stitches.base import MIRROR, is_mirrored


@dataclass(frozen=True)
class Stitch:
    """What is drawn: the cell's control points (S, 6, 3) in drawing order, mm, its
    periods a_x, a_y (mm), the yarn radius r (mm), a one-line description and the
    shift in periods (course, wale) after which the path repeats along its row, and the
    mirror parity (pm, pn) of its images: the copy at lattice offset (m, n) is mirrored
    (z → −z) when pm m + pn n is odd ((0, 0): translations only)."""

    control_points: np.ndarray
    a_x: float
    a_y: float
    r_mm: float
    label: str
    closing_shift: tuple[int, int] = (1, 0)
    mirror_parity: tuple[int, int] = (0, 0)

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


def dense_cell_path(control_points: np.ndarray, spacing: float) -> np.ndarray:
    """The cell's yarn centre-line sampled at most ``spacing`` mm apart (roughly), shape
    (k, 3): each segment gets enough equally spaced t for its control-polygon length
    (an upper bound on its arc length)."""
    cp = np.asarray(control_points, dtype=float)
    parts = []
    for seg in cp:
        polygon = float(np.sum(np.linalg.norm(np.diff(seg, axis=0), axis=1)))
        n = max(8, int(np.ceil(polygon / spacing)))
        basis = basis_tables(np.linspace(0.0, 1.0, n + 1))[0]
        parts.append((basis @ seg)[:-1])
    parts.append(cp[-1, -1:])
    return np.concatenate(parts)
