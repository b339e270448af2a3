"""The stockinette state vector's layout and its physical bounds (docs/model.md §2);
no numba.

A stockinette state is x = (q_0 … q_27, a_x, a_y): the paper's 28 shape parameters
of one stitch (two crossovers built around one shared construction, four connectors)
and the two cell periods (mm). Everything that indexes a stockinette state names its
entries from here, its geometry kernel included.
"""

from __future__ import annotations

import numpy as np

N_STATE = 30
"""Entries of a state vector."""
N_SHAPE = 28
"""Shape parameters (every entry but the periods)."""
N_SEGMENTS = 8
"""Quintic Bézier segments of the yarn path in one cell (docs/model.md §4)."""

IDX_Z = 3  # crossover half-height z (mm)
IDX_TW = 23  # twist between the two ends of a crossover (rad)
IDX_AX = 28  # cell period along the course, a_x (mm)
IDX_AY = 29  # cell period along the wale, a_y (mm)

# the three end conditions S1, S2, S3 start at these indices (psi1, psi2, alpha, kappa, nu, beta)
S1, S2, S3 = 5, 11, 17

# entries by kind: end speeds alpha (and the connectors' alpha_c, alpha_w), curvature
# magnitudes kappa, control-arm offsets beta (and beta_c, beta_w)
SPEEDS = (S1 + 2, S2 + 2, S3 + 2, 24, 26)
CURVATURES = (S1 + 3, S2 + 3, S3 + 3)
OFFSETS = (S1 + 5, S2 + 5, S3 + 5, 25, 27)

_END = ("psi1", "psi2", "alpha", "kappa", "nu", "beta")
STATE_NAMES = (
    "f0", "f1", "f2", "z", "phi",
    *(f"S1_{n}" for n in _END), *(f"S2_{n}" for n in _END), *(f"S3_{n}" for n in _END),
    "tw", "alpha_c", "beta_c", "alpha_w", "beta_w", "a_x", "a_y",
)  # fmt: skip
"""Name of every state entry, in order (docs/model.md §2)."""

SEGMENT_WEIGHTS = np.array([2.0, 2.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0])
"""Weights of the segments (path order 0 C1.B, 1 cc11, 2 C1.A, 3 cc12, 4 C2.A, 5 cc22,
6 C2.B, 7 cc21) in the cell's bending sum (docs/model.md §5): E_b = 2E(C1.A) +
2E(C1.B) + 2E(cc11) + E(cc12) + E(cc21); C2 and cc22 enter through the mirror symmetry
of the cell, exactly as in the reference code."""
SEGMENT_WEIGHTS.setflags(write=False)

STARTS = tuple(f"Init_{i}.dat" for i in range(1, 8))
"""The authors' starting states, shipped in ``data/`` beside this module."""


def state_bounds(L: float, r: float) -> tuple[np.ndarray, np.ndarray]:
    """Generous physical bounds (lower, upper), each (30,), on the state entries for
    yarn length L and radius r (mm); ±inf where free (angles).

    They exclude only shapes no stitch can have: a negative or longer-than-half-the-
    yarn end speed, a radius of curvature below r/10, control-arm offsets or a
    crossover half-height beyond a quarter or half of the yarn length, periods below
    r/2 or above L. A minimiser that honours bounds at every trial point then cannot
    fling the yarn kilometres away on a poor quasi-Newton step.
    """
    lo = np.full(N_STATE, -np.inf)
    hi = np.full(N_STATE, np.inf)
    for i in SPEEDS:
        lo[i], hi[i] = 1e-3 * L, 0.5 * L
    for i in CURVATURES:
        lo[i], hi[i] = -10.0 / r, 10.0 / r
    for i in OFFSETS:
        lo[i], hi[i] = -0.25 * L, 0.25 * L
    lo[IDX_Z], hi[IDX_Z] = -0.5 * L, 0.5 * L
    lo[IDX_AX] = lo[IDX_AY] = 0.5 * r
    hi[IDX_AX] = hi[IDX_AY] = L
    return lo, hi
