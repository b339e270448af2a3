"""The state vector's layout and its physical bounds (docs/model.md §2); no numba.

A state is x = (q_0 … q_27, a_x, a_y): 28 shape parameters and the two cell periods
(mm). Everything that indexes a state names its entries from here, kernels included.
"""

from __future__ import annotations

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
PERIOD_INDEX = {"x": IDX_AX, "y": IDX_AY}
"""The period a pull in each direction fixes."""

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

CONTACT_CLASSES = ("self", "same_row", "nn_column", "nnn_column", "other")
"""Contact classes by image offset (m, n): self (0, 0), same row (n = 0, m != 0),
nearest and next-nearest same column (m = 0, |n| = 1, 2), other (docs/model.md §9)."""


def state_bounds(L: float, r: float) -> list[tuple[float | None, float | None]]:
    """Generous physical bounds on the 30 state entries for yarn length L and radius r
    (mm); angles are free.

    They exclude only shapes no stitch can have: a negative or longer-than-half-the-
    yarn end speed, a radius of curvature below r/10, control-arm offsets or a
    crossover half-height beyond a quarter or half of the yarn length, periods below
    r/2 or above L. A minimiser that honours bounds at every trial point then cannot
    fling the yarn kilometres away on a poor quasi-Newton step.
    """
    b: list[tuple[float | None, float | None]] = [(None, None)] * N_STATE
    for i in SPEEDS:
        b[i] = (1e-3 * L, 0.5 * L)
    for i in CURVATURES:
        b[i] = (-10.0 / r, 10.0 / r)
    for i in OFFSETS:
        b[i] = (-0.25 * L, 0.25 * L)
    b[IDX_Z] = (-0.5 * L, 0.5 * L)
    b[IDX_AX] = b[IDX_AY] = (0.5 * r, L)
    return b
