"""Rib's starting states from the authors' stockinette ones (docs/model.md §11); numpy only."""

from __future__ import annotations

import numpy as np

from ..stockinette_free.ansatz import to_free


def rib_start(cp: np.ndarray, a_x: float, a_y: float) -> np.ndarray:
    """A rib state (87,) from a stockinette stitch's control points (S, 6, 3): the same
    yarn read into the free layout (``ansatz.to_free``, joint 0 moved to the origin, on
    the mirror plane), which the rib geometry closes through the glide
    (``rib.geometry``: the last segment bends into the mirrored frame of joint 0). No
    further map is needed: on the seven Init files at L = 11 mm this has rib's crossing
    signs (``pattern_crossings``) with the cores apart (min ζ 0.083). (Seed, whose
    stitch must also tilt out of the plane, cuts the yarn elsewhere: ``seed.start``.)"""
    return to_free(cp, a_x, a_y)
