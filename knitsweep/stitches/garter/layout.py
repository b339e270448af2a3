"""Garter's state: the free yarn of one knit stitch (docs/model.md §11) plus the height of
its joint 0 above the mirror plane; no numba.

x = (the free yarn's 85 shape entries, z0, a_x, a_y), shape (88,): the free yarn pins
joint 0 at the origin, but in garter the mirror plane z = 0 that makes the purl rows is
physical, so the yarn's height above it, z0 (mm), is an entry. Odd rows are the mirror
images (z -> -z) of the even ones.
"""

from __future__ import annotations

import numpy as np

from ..stockinette_free import layout as free

N_FREE_SHAPE = free.N_STATE - 2
"""Shape entries taken over from the free yarn (85)."""
IDX_Z0 = N_FREE_SHAPE
"""The height of joint 0 above the mirror plane (mm)."""
N_STATE = free.N_STATE + 1
N_SEGMENTS = free.N_SEGMENTS
STATE_NAMES = (*free.STATE_NAMES[:N_FREE_SHAPE], "z0", "a_x", "a_y")
SEGMENT_WEIGHTS = free.SEGMENT_WEIGHTS
STARTS = tuple(f"Init_{i}.dat" for i in range(1, 8))
"""The authors' seven starts made garter stitches (``patterns.garter_start``)."""


def state_bounds(L: float, r: float, sampling: str = "parameter") -> tuple[np.ndarray, np.ndarray]:
    """The free yarn's bounds (``stockinette_free.layout.state_bounds``, for the contact
    ``sampling``) and |z0| <= L."""
    flo, fhi = free.state_bounds(L, r, sampling)
    lo = np.concatenate([flo[:N_FREE_SHAPE], [-L], flo[N_FREE_SHAPE:]])
    hi = np.concatenate([fhi[:N_FREE_SHAPE], [L], fhi[N_FREE_SHAPE:]])
    return lo, hi


def from_free(x_free: np.ndarray, z0: float) -> np.ndarray:
    """A garter state (88,) from a free yarn state (87,) and the height z0 (mm)."""
    return np.concatenate([x_free[:N_FREE_SHAPE], [z0], x_free[N_FREE_SHAPE:]])
