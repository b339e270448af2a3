"""The stockinette ansatz inside the free periodic yarn (docs/model.md §11); numpy only.

``to_free(cp, a_x, a_y)`` reads a free state off the control points (8, 6, 3) of any G2
chain in stockinette's path order, e.g. those of a stockinette state (docs/model.md
§2–4): joint j's point, tangent and curvature vector from segment j's start, each end's
speed α = 5|P1 − P0| and offset β = (P2 − P1)·t (β = −(P3 − P4)·t at an end), the
yarn translated so that joint 0 is at the origin. The free geometry of the result
reproduces ``cp`` − cp[0, 0] to round-off, so energies and length are the ansatz's.
"""

from __future__ import annotations

import numpy as np

from . import layout


def _tangent_angles(t: np.ndarray) -> tuple[float, float]:
    return float(np.arccos(np.clip(t[2], -1.0, 1.0))), float(np.arctan2(t[1], t[0]))


def to_free(cp: np.ndarray, a_x: float, a_y: float) -> np.ndarray:
    """The free state (87,) of control points ``cp`` (8, 6, 3), mm, periods in mm; of any
    closed chain (S, 6, 3) the chain's state (``layout.chain_names(S)``: a chart's row)."""
    cp = np.asarray(cp, dtype=float) - cp[0, 0]
    n_seg = cp.shape[0]
    seg0 = layout.chain_seg0(n_seg)
    x = np.empty(seg0 + layout.PER_SEGMENT * n_seg + 2)
    tangents = []
    for j in range(n_seg):
        d1 = cp[j, 1] - cp[j, 0]
        alpha = 5.0 * np.linalg.norm(d1)
        t = d1 / np.linalg.norm(d1)
        arm = cp[j, 2] - cp[j, 1]
        beta = float(arm @ t)
        cv = (arm - beta * t) * 20.0 / alpha**2
        th, ph = _tangent_angles(t)
        e_th = np.array([np.cos(th) * np.cos(ph), np.cos(th) * np.sin(ph), -np.sin(th)])
        e_ph = np.array([-np.sin(ph), np.cos(ph), 0.0])
        s = layout.joint_start(j)
        if j > 0:
            x[s : s + 3] = cp[j, 0]
            s += 3
        x[s : s + 4] = th, ph, cv @ e_th, cv @ e_ph
        b = seg0 + layout.PER_SEGMENT * j
        x[b], x[b + 1] = alpha, beta
        tangents.append(t)
    for s in range(n_seg):
        t_end = tangents[(s + 1) % n_seg]
        b = seg0 + layout.PER_SEGMENT * s
        x[b + 2] = 5.0 * np.linalg.norm(cp[s, 5] - cp[s, 4])
        x[b + 3] = -float((cp[s, 3] - cp[s, 4]) @ t_end)
    x[-2], x[-1] = a_x, a_y
    return x
