"""A tile of fabric as a triangle mesh: each row's yarn as one tube around one curve.

Each row (course) of the tile is the cell's centre-line repeated through its copies
(``tile.row_path``: the copy at column c of row n is the cell mirrored where the
stitch's images are, shifted by c t_c + n t_w) and sampled as one curve, so that its
rotation-minimising frames, and with them the tube's rings and normals, run on
through every cell boundary without a seam. The tube of radius ρ around the curve
P(s) is P + ρ (cos φ N + sin φ B); its normal there is cos φ N + sin φ B exactly, so
the mesh carries smooth per-vertex normals. Lengths in mm.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .tile import Stitch, copy_mirrored, dense_cell_samples, frames, row_path


@dataclass(frozen=True)
class TubeMesh:
    """The tubes and centre-lines of a tile of ``rows`` × ``columns`` copies of a cell.

    Centre-lines: ``centre`` (K, 3) mm, every row's curve one after the other (row i is
    ``centre[lines[i, 0]:lines[i, 1]]``); per centre vertex its ``centre_row`` and
    ``centre_column`` (the copy it lies in), ``centre_t`` (the cell's global Bézier
    parameter t in [0, S] there: the point of the cell it is the image of) and
    ``centre_mirrored`` (whether that copy is a mirror image: a purl stitch of a
    knit/purl pattern). Tubes: ``points`` (N, 3) mm, unit outward ``normals`` (N, 3),
    ``triangles`` (T, 3) int (counter-clockwise seen from outside), ``around``
    vertices per ring; vertex i lies on the ring of centre vertex ``ring[i]``.
    """

    centre: np.ndarray
    lines: np.ndarray
    centre_row: np.ndarray
    centre_column: np.ndarray
    centre_t: np.ndarray
    centre_mirrored: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray
    ring: np.ndarray
    around: int
    radius: float


def tube_mesh(stitch: Stitch, copies: Mapping[int, range], radius: float,
              spacing: float = 0.05, around: int = 32) -> TubeMesh:  # fmt: skip
    """The tubes of radius ``radius`` (mm) around the yarn of each row's ``copies``
    (row → consecutive columns); the centre-line sampled about ``spacing`` mm apart,
    ``around`` vertices per ring."""
    if around < 3:
        raise ValueError(f"around = {around}: must be >= 3")
    one, t_one = dense_cell_samples(stitch.control_points, spacing)
    per_cell = len(one) - 1
    phi = 2.0 * np.pi * np.arange(around) / around
    cos_phi, sin_phi = np.cos(phi), np.sin(phi)
    centre, lines, c_row, c_col, c_t, c_mir = [], [], [], [], [], []
    points, normals, triangles, ring = [], [], [], []
    k0 = n0 = 0
    for row, columns in copies.items():
        n_cols = len(columns)
        path = row_path(stitch, one, row, columns)
        k = len(path)
        column = np.minimum(np.arange(k) // per_cell, n_cols - 1)
        t = np.concatenate([np.tile(t_one[:-1], n_cols), t_one[-1:]])
        mirrored = np.array([bool(copy_mirrored(stitch, row, c)) for c in columns])[column]
        _, normal, binormal = frames(path)
        radial = (cos_phi[None, :, None] * normal[:, None, :]
                  + sin_phi[None, :, None] * binormal[:, None, :]).reshape(-1, 3)  # fmt: skip
        points.append(np.repeat(path, around, axis=0) + radius * radial)
        normals.append(radial)
        ring.append(k0 + np.repeat(np.arange(k), around))
        i = np.arange(k - 1)[:, None]
        j = np.arange(around)[None, :]
        a = n0 + i * around + j
        b = n0 + i * around + (j + 1) % around
        c, d = a + around, b + around
        triangles.append(np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                                         np.stack([b, d, c], -1).reshape(-1, 3)]))  # fmt: skip
        centre.append(path)
        lines.append((k0, k0 + k))
        c_row.append(np.full(k, row))
        c_col.append(np.asarray(columns)[column])
        c_t.append(t)
        c_mir.append(mirrored)
        k0 += k
        n0 += k * around
    return TubeMesh(np.concatenate(centre), np.array(lines, dtype=np.int64),
                    np.concatenate(c_row), np.concatenate(c_col), np.concatenate(c_t),
                    np.concatenate(c_mir), np.concatenate(points), np.concatenate(normals),
                    np.concatenate(triangles).astype(np.int64), np.concatenate(ring), around,
                    float(radius))  # fmt: skip
