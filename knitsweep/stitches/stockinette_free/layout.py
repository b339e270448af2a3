"""The free periodic yarn's state layout and bounds (docs/model.md §11); no numba.

The yarn of one stitch cell is 8 quintic Bézier segments in the stockinette path order
(docs/model.md §4), with nothing tied to crossovers: each of the 8 joints (joint j is
where segment j starts; segment 7 ends at joint 0 shifted by t_c) carries its point p,
its unit tangent t(θ, φ) and its curvature vector cv = k1 e_θ + k2 e_φ, normal to t by
construction; each segment end carries its own speed α and offset β. The control-point
rule of §3 then makes every joint G2 whatever the state, and every G2 chain of quintics
with positive end speeds is one state. Joint 0 sits at the origin (the energy does not
change under a translation of the yarn; pinning it removes the three flat modes), so a
state is

    x = (θ0, φ0, k1_0, k2_0,  [p_j (3), θ_j, φ_j, k1_j, k2_j] for j = 1..7,
         [α0_s, β0_s, α1_s, β1_s] for s = 0..7,  a_x, a_y)           shape (87,)

in mm and rad (k in 1/mm). The tangent angles are spherical about z:
t = (sin θ cos φ, sin θ sin φ, cos θ); stockinette's tangents stay within 21° of the
fabric plane (|t_z| <= 0.36 at L = 11.6 mm), far from the poles θ = 0, π.
"""

from __future__ import annotations

import numpy as np

N_JOINTS = 8
"""Joints of the cell's path (joint j starts segment j)."""
N_SEGMENTS = 8
"""Quintic Bézier segments of the cell (stockinette's path order, docs/model.md §4)."""
JOINT0 = 4
"""Entries of joint 0 (its point is pinned at the origin): θ, φ, k1, k2."""
PER_JOINT = 7
"""Entries of joints 1..7: p (3), θ, φ, k1, k2."""
PER_SEGMENT = 4
"""Entries of a segment: α0, β0 (at its start), α1, β1 (at its end)."""
SEG0 = JOINT0 + PER_JOINT * (N_JOINTS - 1)
"""First segment entry (53)."""
N_STATE = SEG0 + PER_SEGMENT * N_SEGMENTS + 2
"""Entries of a state vector (87)."""
IDX_AX = N_STATE - 2
IDX_AY = N_STATE - 1


def joint_start(j: int) -> int:
    """Index of joint j's first entry: θ for joint 0, p_x for joints 1..7 (of any chain:
    the joints come first, ``chain_seg0``)."""
    return 0 if j == 0 else JOINT0 + PER_JOINT * (j - 1)


def chain_seg0(n_segments: int) -> int:
    """First segment entry of a closed chain of ``n_segments`` (its joints' entries before)."""
    return JOINT0 + PER_JOINT * (n_segments - 1)


def chain_names(n_segments: int) -> tuple[str, ...]:
    """Name of every entry of a closed chain of ``n_segments`` quintics (this module's
    layout with as many joints as segments; a chart's row of stitches,
    ``stitches.charts``)."""
    names = ["theta0", "phi0", "k1_0", "k2_0"]
    for j in range(1, n_segments):
        names += [f"px{j}", f"py{j}", f"pz{j}", f"theta{j}", f"phi{j}", f"k1_{j}", f"k2_{j}"]
    for s in range(n_segments):
        names += [f"alpha0_{s}", f"beta0_{s}", f"alpha1_{s}", f"beta1_{s}"]
    return (*names, "a_x", "a_y")


STATE_NAMES = chain_names(N_SEGMENTS)
"""Name of every state entry, in order."""

SEGMENT_WEIGHTS = np.ones(N_SEGMENTS)
"""Every segment counts once: a free yarn has no symmetry that would count one for
another (docs/model.md §11). On a stockinette state mapped in, the weights (2, 2, 2, 1,
0, 0, 0, 1) of §5 give the same sum (the mirrored pieces are equal to round-off)."""
SEGMENT_WEIGHTS.setflags(write=False)

STARTS = tuple(f"Init_{i}.dat" for i in range(1, 8))
"""The authors' seven starting states mapped into the free yarn (``ansatz.to_free``)."""


SPEED_BOUNDS = (0.05, 0.3)
"""End speeds α of a segment, in units of the yarn length L (an eighth of the yarn per
segment is 0.125 L). The contact samples sit at fixed curve parameters (docs/model.md
§6), so a segment's samples are as far apart as its speed makes them: with speeds down to
10⁻³ L a relaxation shortens some segments to ~0.02 mm and stretches others, and the
sparse samples let hard cores pass between them (docs/model.md §11, "Resolution")."""
OFFSET_BOUND = 0.125
"""|β| <= 0.125 L: the second control point's offset along the tangent, within an eighth
of the yarn (as far as one segment's share)."""


ARCLENGTH_SPEED_BOUNDS = (0.01, 1.0)
"""End speeds α in units of L when the contact samples sit by arclength
(``Fidelity.contact_sampling = "arclength"``): the samples no longer depend on the speeds,
so these only keep a segment's end regular (α > 0) and far from anything a yarn of length
L reaches (docs/model.md §11, "Resolution"). Along the whole yarn (``"yarn_arclength"``,
the default) the speeds are not free at all: they are held at L/8 (``gauge``)."""
ARCLENGTH_OFFSET_BOUND = 0.5
"""|β| <= L/2 with samples by arclength."""


def state_bounds(L: float, r: float, sampling: str = "parameter") -> tuple[np.ndarray, np.ndarray]:
    """Bounds (lower, upper), each (87,), for yarn length L and radius r (mm); ±inf where
    free (angles): curvature components within 10/r, joint points within L of joint 0,
    periods in [r/2, L]; speeds in ``SPEED_BOUNDS`` L and offsets within ``OFFSET_BOUND`` L
    (the box that keeps samples at fixed parameters resolved), or with samples placed by
    arclength (``sampling`` "arclength" or "yarn_arclength") in ``ARCLENGTH_SPEED_BOUNDS`` L and within ``ARCLENGTH_OFFSET_BOUND`` L."""
    return chain_bounds(N_SEGMENTS, 1, L, r, sampling)


def chain_bounds(n_segments: int, stitches: int, L: float, r: float,
                 sampling: str = "parameter") -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """``state_bounds`` of a closed chain of ``n_segments`` through ``stitches`` stitches of
    yarn length L each (a chart's row, ``stitches.charts``): joint points within the row's
    yarn (stitches × L) of joint 0, speeds and offsets in units of L and periods (per
    stitch) as ``state_bounds``'s."""
    speeds, offset = SPEED_BOUNDS, OFFSET_BOUND
    if sampling != "parameter":  # "arclength" or "yarn_arclength"
        speeds, offset = ARCLENGTH_SPEED_BOUNDS, ARCLENGTH_OFFSET_BOUND
    n = chain_seg0(n_segments) + PER_SEGMENT * n_segments + 2
    reach = stitches * L
    lo = np.full(n, -np.inf)
    hi = np.full(n, np.inf)
    for j in range(n_segments):
        s = joint_start(j)
        if j > 0:
            lo[s : s + 3], hi[s : s + 3] = -reach, reach
            s += 3
        lo[s + 2 : s + 4], hi[s + 2 : s + 4] = -10.0 / r, 10.0 / r
    seg0 = chain_seg0(n_segments)
    for s in range(n_segments):
        b = seg0 + PER_SEGMENT * s
        for i in (b, b + 2):
            lo[i], hi[i] = speeds[0] * L, speeds[1] * L
        for i in (b + 1, b + 3):
            lo[i], hi[i] = -offset * L, offset * L
    lo[n - 2] = lo[n - 1] = 0.5 * r
    hi[n - 2] = hi[n - 1] = L
    return lo, hi
