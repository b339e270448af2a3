"""The free yarn's parametrisation gauge (docs/model.md §11, "The speeds as a gauge"); numpy.

With the contact samples spaced evenly along the whole yarn by arclength
(``Fidelity.contact_sampling = "yarn_arclength"``) the energy depends on the curve
alone, up to how well 8 quintics represent it, and not on how the curve is
parametrised. The end speeds α of the segments then set nearly nothing but the
parametrisation: the reduced Hessian has a dozen modes of curvature 10⁻⁹–10⁻⁶ mJ/mm²
made of speeds and joint slides (rib at L = 11.6 mm, k = 0.1 mN/mm²), on which Newton
crawls (hundreds to thousands of iterations a relaxation). So a gauged free yarn holds
every end speed at L/8, an eighth of the yarn (``SPEED_ENTRIES`` are not free in a
relaxation; the offsets β stay free): its segments are then parametrised at nearly the
speed of an arclength parametrisation and its joints sit near equal fractions of the
yarn, and the rest of the state says where the curve goes.

The joints can still slide along the yarn (a speed held at L/8 at both ends of two
segments of different lengths makes the slide cost a little bending, 10⁻⁶–3·10⁻⁵ mJ/mm²
at stockinette_free's minimum at 10.5 mm, against 10⁻⁴ and up for the physical modes):
the weak penalty JOINT_STIFFNESS Σ_s (ℓ_s − ℓ/8)² on the segments' lengths makes those
slides as stiff as the softest physical mode (summed with the energy by the pattern kernel,
``kernels.arclength.length_spread``). It enters what a relaxation minimises, never a
reported energy (``Energies.gauge_energy``), and at the minima it moves the energy by less
than 10⁻⁶ mJ (measured, docs/model.md §11).

``regauge`` brings any state of the free yarn into the gauge without moving its curve
more than 8 quintics must: the joints are put at equal fractions of the curve's
arclength, each with the curve's own point, tangent and curvature vector there (joint 0,
at the start of the yarn, keeps its frame), every end speed is L/8 and every offset
α/5, which gives each end no tangential acceleration. The result is the G2 quintic
Hermite interpolant of the curve at those joints.
"""

from __future__ import annotations

import itertools

import numpy as np

from . import layout


def speed_entries(n_segments: int) -> tuple[int, ...]:
    """The end speeds α0, α1 of every segment of a closed chain of ``n_segments``."""
    seg0 = layout.chain_seg0(n_segments)
    return tuple(seg0 + layout.PER_SEGMENT * s + e for s in range(n_segments) for e in (0, 2))


SPEED_ENTRIES = speed_entries(layout.N_SEGMENTS)
"""The end speeds α0, α1 of every segment: the gauge's entries (16)."""
OFFSET_ENTRIES = tuple(i + 1 for i in SPEED_ENTRIES)
"""The offsets β0, β1 of every segment."""
JOINT_STIFFNESS = 1e-4
"""mJ/mm²: the weight of the joints' penalty (module docstring)."""
_PIECES, _NODES = 64, 8  # composite Gauss rule of a segment's arclength
_GX, _GW = np.polynomial.legendre.leggauss(_NODES)
_JX, _JW = np.polynomial.legendre.leggauss(16)
JOINT_RULE = np.ascontiguousarray([(_JX + 1.0) / 2, _JW / 2])
"""(2, 16): the penalty's rule for the segments' lengths, 16 Gauss nodes and weights on
[0, 1] (``kernels.arclength.length_spread`` sums it)."""


def _derivatives(c: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Point, first and second parameter derivatives (len(t), 3) of the quintic with
    control points ``c`` (6, 3) at parameters ``t``."""
    t = np.asarray(t, dtype=float)[:, None]
    u = 1.0 - t
    b = np.hstack([u**5, 5 * t * u**4, 10 * t**2 * u**3, 10 * t**3 * u**2, 5 * t**4 * u, t**5])
    d = 5.0 * (c[1:] - c[:-1])
    b4 = np.hstack([u**4, 4 * t * u**3, 6 * t**2 * u**2, 4 * t**3 * u, t**4])
    dd = 4.0 * (d[1:] - d[:-1])
    b3 = np.hstack([u**3, 3 * t * u**2, 3 * t**2 * u, t**3])
    return b @ c, b4 @ d, b3 @ dd


def _arc(c: np.ndarray, a: float, b: float) -> float:
    """Arclength of quintic ``c`` between parameters a and b (Gauss, ``_NODES``)."""
    t = a + 0.5 * (b - a) * (_GX + 1.0)
    return 0.5 * (b - a) * float(_GW @ np.linalg.norm(_derivatives(c, t)[1], axis=1))


def _parameter_at(c: np.ndarray, cum: np.ndarray, s: float) -> float:
    """The parameter where quintic ``c`` has run arclength ``s`` (``cum``: its arclength
    at the ``_PIECES`` + 1 piece boundaries)."""
    k = int(np.clip(np.searchsorted(cum, s) - 1, 0, _PIECES - 1))
    lo = k / _PIECES
    t = lo + (s - cum[k]) / max(cum[k + 1] - cum[k], 1e-300) / _PIECES
    for _ in range(20):  # Newton on the exact arclength (to round-off in a few steps)
        f = cum[k] + _arc(c, lo, t) - s
        speed = float(np.linalg.norm(_derivatives(c, [t])[1][0]))
        dt = f / speed
        t = min(max(t - dt, lo), lo + 1.0 / _PIECES)
        if abs(dt) < 1e-15:
            break
    return t


def regauge(x: np.ndarray, cp: np.ndarray, L: float) -> np.ndarray:
    """The gauged state (a new array) whose curve interpolates that of state ``x`` (with
    control points ``cp`` (8, 6, 3) in path order) at 8 equal fractions of its arclength,
    G2, with every end speed L/8 and every offset L/40 (module docstring). Joint 0's frame,
    the periods and every entry after the shape (garter's z0) are kept. A chain of S
    segments (a chart's row of S/8 stitches, ``L`` the length per stitch) is interpolated
    at S equal fractions, its speeds L/8 as well."""
    x = np.asarray(x, dtype=float)
    out = x.copy()
    cp = np.asarray(cp, dtype=float)
    edges = np.linspace(0.0, 1.0, _PIECES + 1)
    cums = []
    for c in cp:
        pieces = [_arc(c, a, b) for a, b in itertools.pairwise(edges)]
        cums.append(np.concatenate([[0.0], np.cumsum(pieces)]))
    lengths = np.array([cum[-1] for cum in cums])
    starts = np.concatenate([[0.0], np.cumsum(lengths)])
    total = starts[-1]
    n_seg = len(cp)
    for j in range(1, n_seg):
        s = j * total / n_seg
        seg = int(np.clip(np.searchsorted(starts, s, side="right") - 1, 0, len(cp) - 1))
        t = _parameter_at(cp[seg], cums[seg], s - starts[seg])
        r, r1, r2 = (v[0] for v in _derivatives(cp[seg], [t]))
        speed = float(np.linalg.norm(r1))
        tangent = r1 / speed
        cv = (r2 - float(r2 @ tangent) * tangent) / speed**2
        i = layout.joint_start(j)
        theta = float(np.arccos(np.clip(tangent[2], -1.0, 1.0)))
        phi = float(np.arctan2(tangent[1], tangent[0]))
        phi += 2.0 * np.pi * round((x[i + 4] - phi) / (2.0 * np.pi))  # the old branch
        e_th = np.array([np.cos(theta) * np.cos(phi), np.cos(theta) * np.sin(phi), -np.sin(theta)])
        e_ph = np.array([-np.sin(phi), np.cos(phi), 0.0])
        out[i : i + 3] = r - cp[0, 0]
        out[i + 3 : i + 7] = theta, phi, float(cv @ e_th), float(cv @ e_ph)
    speeds = speed_entries(n_seg)
    out[list(speeds)] = L / layout.N_SEGMENTS
    out[[i + 1 for i in speeds]] = L / (5 * layout.N_SEGMENTS)
    return out
