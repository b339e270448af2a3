"""Triangles to pixels with a depth buffer, no OpenGL (runs headless): the z-buffer of
``kernels.raster``, and deferred shading's one step, the winners' barycentric
coordinates interpolating whatever per-vertex data the caller shades with.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Fragments:
    """What the rasteriser saw at each pixel of an (H, W) image: ``triangle`` (H, W) the
    index of the nearest covering triangle (-1: none), ``weights`` (H, W, 3) its
    barycentric coordinates at the pixel centre (0 where none), ``depth`` (H, W)
    towards the viewer (-inf where none)."""

    triangle: np.ndarray
    weights: np.ndarray
    depth: np.ndarray

    @property
    def covered(self) -> np.ndarray:
        return self.triangle >= 0

    def interpolate(self, values: np.ndarray, triangles: np.ndarray,
                    empty: float = 0.0) -> np.ndarray:  # fmt: skip
        """Per-vertex ``values`` (N, C) at every pixel (H, W, C) by the winners'
        barycentric weights; ``empty`` where no triangle covers the pixel."""
        from ..kernels.raster import interpolate_pixels

        out = np.full((*self.triangle.shape, values.shape[1]), empty)
        interpolate_pixels(self.triangle, self.weights, np.ascontiguousarray(triangles),
                           np.ascontiguousarray(values, dtype=float), out)  # fmt: skip
        return out


def rasterize(xy: np.ndarray, depth: np.ndarray, triangles: np.ndarray,
              shape: tuple[int, int]) -> Fragments:  # fmt: skip
    """The nearest front-facing triangle at every pixel centre (``kernels.raster``).

    Args:
        xy: vertex positions (N, 2) in pixels, x to the right, y downwards; pixel
            (i, j) has its centre at (j + 0.5, i + 0.5).
        depth: vertex depth (N,) towards the viewer (larger is nearer).
        triangles: (T, 3) vertex indices, counter-clockwise as seen by the viewer
            (front faces); clockwise ones (back faces) are skipped.
        shape: (H, W) of the image.
    """
    from ..kernels.raster import rasterize_triangles  # numba, compiled on first use

    zbuf = np.full(shape, -np.inf)
    owner = np.full(shape, -1, dtype=np.int64)
    weights = np.zeros((*shape, 3))
    rasterize_triangles(np.ascontiguousarray(xy, dtype=float),
                        np.ascontiguousarray(depth, dtype=float),
                        np.ascontiguousarray(triangles, dtype=np.int64), zbuf, owner, weights)  # fmt: skip
    return Fragments(owner, weights, zbuf)
