"""The stockinette ansatz inside the free periodic yarn (docs/model.md §11); numpy and
SciPy.

``to_free(cp, a_x, a_y)`` reads a free state off the control points (8, 6, 3) of any G2
chain in stockinette's path order, e.g. those of a stockinette state (docs/model.md
§2–4): joint j's point, tangent and curvature vector from segment j's start, each end's
speed 5|P1 − P0| and offset β = (P2 − P1)·t (β = −(P3 − P4)·t at an end), the yarn
translated so that joint 0 is at the origin. The free yarn has one speed per joint
(``layout``: the gauge of the joints sliding along the yarn), where a chain has one per
segment end; so the state starts with its joints at equal fractions of the chain's
arclength (``evenly_jointed``) and is then fitted to the chain's curve, point for point
at equal fractions of the arclength (which no choice of joints changes), by least
squares. The free geometry of the result
follows the chain to ~10⁻⁴ mm (docs/model.md §11).
"""

from __future__ import annotations

from math import comb

import numpy as np
from scipy.optimize import least_squares

from . import layout

_FIT_DENSE = 96
"""Curve parameters per segment at which the fit's arclength is measured."""
_FIT_POINTS = 32
"""Points per segment's share of the yarn compared by the fit."""
_FIT_EVEN = 1e-3
"""Weight (mm) of the fit's pull towards an even speed along each segment, |r'(u)| over
its mean minus 1 at the dense parameters: it keeps the fit away from quintics that turn
back on themselves (a speed through zero) where the points alone leave it free, and
moves the points by ~10⁻⁵ mm."""
_FIT_EVALUATIONS = 1500
"""The fit's budget of curve evaluations (~20 Levenberg–Marquardt steps of 77 entries
with a difference Jacobian): the fit is a start's shape, not a result, and seed's
lopsided first segment would otherwise take minutes for the last 10⁻⁵ mm."""


def _tangent_angles(t: np.ndarray) -> tuple[float, float]:
    return float(np.arccos(np.clip(t[2], -1.0, 1.0))), float(np.arctan2(t[1], t[0]))


def _bernstein(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quintic Bernstein basis (len(u), 6) and its derivative at parameters ``u``."""
    b = np.stack([comb(5, i) * u**i * (1 - u) ** (5 - i) for i in range(6)], axis=1)
    d = np.stack([5 * ((comb(4, i - 1) * u ** (i - 1) * (1 - u) ** (5 - i)) if i > 0 else 0 * u)
                  - 5 * ((comb(4, i) * u**i * (1 - u) ** (4 - i)) if i < 5 else 0 * u)
                  for i in range(6)], axis=1)  # fmt: skip
    return b, d


_U = np.linspace(0.0, 1.0, _FIT_DENSE + 1)
_B, _D = _bernstein(_U)


def _uneven(cp: np.ndarray) -> np.ndarray:
    """|r'(u)| over its segment's mean, minus 1, at the dense parameters (S (n + 1),)."""
    v = np.stack([np.linalg.norm(_D @ seg, axis=1) for seg in cp])
    return (v / v.mean(axis=1, keepdims=True) - 1.0).ravel()


def by_arclength(cp: np.ndarray, points: int = _FIT_POINTS) -> np.ndarray:
    """The chain ``cp`` (S, 6, 3) at S·points equal fractions of its arclength (from its
    start, the last excluded), shape (S·points, 3): a curve's points that do not depend
    on where its joints are. The arclength is the trapezoid rule on ``_FIT_DENSE``
    parameters per segment, the points linear between them."""
    pos = np.concatenate([_B[:-1] @ seg for seg in cp] + [_B[-1:] @ cp[-1]])
    arc = _arclength_grid(cp)[0]
    target = arc[-1] * np.arange(cp.shape[0] * points) / (cp.shape[0] * points)
    return np.stack([np.interp(target, arc, pos[:, c]) for c in range(3)], axis=1)


def _arclength_grid(cp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Arclength from the chain's start (trapezoid rule) at the dense parameters, and
    the global parameter (segment + u) there, each (S n + 1,)."""
    n = _FIT_DENSE
    ds = []
    for seg in cp:
        v = np.linalg.norm(_D @ seg, axis=1)
        ds.append(0.5 * (v[1:] + v[:-1]) / n)
    arc = np.concatenate([[0.0], np.cumsum(np.concatenate(ds))])
    glob = np.concatenate([s + _U[:-1] for s in range(cp.shape[0])] + [[cp.shape[0]]])
    return arc, glob


def evenly_jointed(cp: np.ndarray, a_x: float, a_y: float) -> np.ndarray:
    """A free state (79,) of the chain ``cp`` (8, 6, 3) (joint 0 at the origin) with its
    joints at equal fractions of the arclength: each joint's point, tangent and curvature
    vector the chain's there, its speed α the segments' share of the length, the offsets
    α/5 (r''(0) = 20 (β0 − α/5) t + α² cv: a segment parametrised by arclength has r''
    normal to r'). The start of
    ``to_free``'s fit: it does not depend on where the chain's own joints are."""
    arc, glob = _arclength_grid(cp)
    x = np.zeros(layout.N_STATE)
    share = arc[-1] / layout.N_JOINTS
    for j in range(layout.N_JOINTS):
        g = float(np.interp(j * share, arc, glob))
        s, u = min(int(g), cp.shape[0] - 1), g - min(int(g), cp.shape[0] - 1)
        b, d = _bernstein(np.array([u]))
        seg = cp[s]
        p = (b @ seg)[0]
        r1 = (d @ seg)[0]
        r2 = 20.0 * sum(comb(3, i) * u**i * (1 - u) ** (3 - i) * (seg[i + 2] - 2 * seg[i + 1]
                                                                    + seg[i])
                        for i in range(4))  # fmt: skip
        t = r1 / np.linalg.norm(r1)
        cv = (r2 - (r2 @ t) * t) / (r1 @ r1)
        th, ph = _tangent_angles(t)
        e_th = np.array([np.cos(th) * np.cos(ph), np.cos(th) * np.sin(ph), -np.sin(th)])
        e_ph = np.array([-np.sin(ph), np.cos(ph), 0.0])
        k = layout.joint_start(j)
        if j > 0:
            x[k : k + 3] = p
            k += 3
        x[k : k + 5] = th, ph, cv @ e_th, cv @ e_ph, share
    x[layout.SEG0 : layout.IDX_AX] = share / 5.0
    x[layout.IDX_AX], x[layout.IDX_AY] = a_x, a_y
    return x


def close_through_glide(cp: np.ndarray, a_x: float) -> np.ndarray:
    """The chain ``cp`` (8, 6, 3) (joint 0 at the origin) with its last segment's end
    rebuilt into joint 0's frame mirrored (z -> -z) at t_c = (a_x, 0, 0), with the end's
    own speed and offset: the closing of rib and seed (``geometry.closed_control_points``
    with ``mirrored``), G2 into the purl stitch beside."""
    out = np.array(cp, dtype=float)
    m = np.array([1.0, 1.0, -1.0])
    d1 = cp[0, 1] - cp[0, 0]
    alpha0 = 5.0 * np.linalg.norm(d1)
    t0 = d1 / np.linalg.norm(d1)
    arm = cp[0, 2] - cp[0, 1]
    cv0 = (arm - (arm @ t0) * t0) * 20.0 / alpha0**2
    t_end = (cp[-1, 5] - cp[-1, 4]) / np.linalg.norm(cp[-1, 5] - cp[-1, 4])
    a1 = 5.0 * np.linalg.norm(cp[-1, 5] - cp[-1, 4])
    b1 = -float((cp[-1, 3] - cp[-1, 4]) @ t_end)
    end = np.array([a_x, 0.0, 0.0])
    out[-1, 5] = end
    out[-1, 4] = end - (a1 / 5.0) * m * t0
    out[-1, 3] = end - (a1 / 5.0 + b1) * m * t0 + (a1 * a1 / 20.0) * m * cv0
    return out


def to_free(cp: np.ndarray, a_x: float, a_y: float, glide: bool = False,
            fit: bool = True) -> np.ndarray:  # fmt: skip
    """The free state (79,) whose curve follows the chain ``cp`` (8, 6, 3), mm, periods
    in mm (module docstring); ``glide``: the course closes through a glide (rib, seed:
    ``geometry.closed_control_points``; the chain's last segment end is first rebuilt
    so, ``close_through_glide``), else by a translation. ``fit`` False: the evenly
    jointed state alone (``evenly_jointed``), for a chain whose parametrisation is so
    lopsided (seed's first segment, ``seed.start``) that the fit turns a segment back on
    itself."""
    from .geometry import closed_control_points

    cp = np.asarray(cp, dtype=float) - cp[0, 0]
    if glide:
        cp = close_through_glide(cp, a_x)
    x = evenly_jointed(cp, a_x, a_y)
    if not fit:
        return x
    want = by_arclength(cp).ravel()
    shape = np.arange(layout.N_STATE - 2)
    buf, jac = np.empty((8, 6, 3)), np.empty((8, 6, 3, layout.N_STATE))

    def residual(z):
        xx = x.copy()
        xx[shape] = z
        closed_control_points(xx, buf, jac, glide)
        return np.concatenate([by_arclength(buf).ravel() - want, _FIT_EVEN * _uneven(buf)])

    fit = least_squares(residual, x[shape], method="lm", xtol=1e-10, ftol=1e-10,
                        max_nfev=_FIT_EVALUATIONS)
    x[shape] = fit.x
    return x
