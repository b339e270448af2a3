"""Whether a stitch's zero-force state keeps the stitch's left–right mirror (prints a
table; not a test).

The candidate reduction of issue 34: every pattern's stitch looks the same in a mirror
x -> -x held across the course, so a relaxation could keep half of the yarn and mirror the
rest. That is exact only if the minimum the relaxation finds without it has that symmetry.
This measures it: the relaxed cell's centre-line sampled every ``--spacing`` mm (``report.
tile.dense_cell_path``), mirrored as x -> 2c - x, y -> y + d, z -> ±z, against the fabric
(the cell and its images within 3 periods, ``stitches.base.image_points``); c, d and the
sign are fitted (a grid, then Nelder–Mead on the mean distance), and the table gives the
largest and the root-mean-square distance from a mirrored sample to the fabric's
centre-line (the polyline through its samples: its chords stray from the curve by about
spacing² κ / 8, 2·10⁻⁶ mm at 0.0025 mm). A symmetric state leaves that; an asymmetric one
more.

Per stitch (default: every one knitsweep knows) and L (default 10.5, 11.6 and 12.2 mm),
k = 0.1 mN/mm², the ``converged`` preset, the zero-force state from the first shipped start
(``zero_force``, one start). Run: ``python benchmarks/mirror_symmetry.py [--stitches rib]
[--L 11.6] [--spacing 0.0025]``.
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np
from scipy.optimize import minimize
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from knitsweep.config import StartSettings, StitchParams
from knitsweep.model import CellModel
from knitsweep.presets import Numerics
from knitsweep.relax.zero_force import zero_force
from knitsweep.report.tile import dense_cell_path
from knitsweep.stitches import STITCH_NAMES
from knitsweep.stitches.base import image_points

REACH = 3
"""Images within this many periods of the cell make up the fabric a mirrored cell is
compared with."""


def mirror_distances(model: CellModel, x: np.ndarray, spacing: float) -> dict:
    """The fitted mirror of the cell onto the fabric (module docstring): its c, d (mm), z
    sign, and the largest and RMS distances (mm) of the mirrored samples to the fabric."""
    cp = model.control_points(x)
    cell = dense_cell_path(cp, spacing)
    ax, ay = float(x[-2]), float(x[-1])
    parity = model.image_group.parity
    fabric = np.concatenate([image_points(cell, m, n, ax, ay, parity)
                             for m, n in itertools.product(range(-REACH, REACH + 1), repeat=2)])  # fmt: skip
    tree = cKDTree(fabric)
    k = cell.shape[0]

    def to_line(q: np.ndarray) -> np.ndarray:
        """Distances of points ``q`` (j, 3) to the fabric's polyline: to the two chords
        at the nearest sample (within its copy)."""
        _, i = tree.query(q)
        best = np.full(len(q), np.inf)
        for lo in (i - 1, i):
            ok = (lo // k == (lo + 1) // k) & (lo >= 0) & (lo + 1 < fabric.shape[0])
            a, b = fabric[np.where(ok, lo, 0)], fabric[np.where(ok, lo + 1, 0)]
            ab = b - a
            t = np.clip(((q - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-300), 0, 1)
            d = np.linalg.norm(a + t[:, None] * ab - q, axis=1)
            best = np.where(ok, np.minimum(best, d), best)
        return best

    def mirrored(c: float, d: float, sz: float) -> np.ndarray:
        return cell * np.array([-1.0, 1.0, sz]) + np.array([2.0 * c, d, 0.0])

    def mean_distance(v: np.ndarray, sz: float) -> float:
        return float(to_line(mirrored(v[0], v[1], sz)).mean())

    best = (np.inf, 0.0, 0.0, 1.0)
    for sz in (1.0, -1.0):
        for c in np.linspace(0.0, ax, 61)[:-1]:
            for d in np.linspace(0.0, ay, 41)[:-1]:
                m = mean_distance(np.array([c, d]), sz)
                if m < best[0]:
                    best = (m, c, d, sz)
    _, c0, d0, sz = best
    fit = minimize(mean_distance, np.array([c0, d0]), args=(sz,), method="Nelder-Mead",
                   options={"xatol": 1e-7, "fatol": 1e-10, "maxiter": 4000})  # fmt: skip
    dist = to_line(mirrored(fit.x[0], fit.x[1], sz))
    return {"c": fit.x[0], "d": fit.x[1], "sz": sz, "max": float(dist.max()),
            "rms": float(np.sqrt(np.mean(dist**2)))}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stitches", default=",".join(STITCH_NAMES))
    ap.add_argument("--L", type=float, nargs="+", default=[10.5, 11.6, 12.2])
    ap.add_argument("--k", type=float, default=0.1)
    ap.add_argument("--spacing", type=float, default=0.0025, help="sampling, mm")
    args = ap.parse_args()
    n = Numerics.from_preset("converged")
    print(f"k = {args.k} mN/mm^2, converged preset, 1 start; samples {args.spacing} mm apart; "
          "distances of the mirrored cell to the fabric, mm")  # fmt: skip
    print(f"{'stitch':17} {'L':>5} {'status':10} {'a_x':>6} {'c/a_x':>6} {'d/a_y':>6} "
          f"{'z':>2} {'max':>9} {'rms':>9}")  # fmt: skip
    with threadpool_limits(1):
        for stitch in args.stitches.split(","):
            for L in args.L:
                params = StitchParams(stitch=stitch, L_mm=L, k_mN_per_mm2=args.k)
                zero = zero_force(params, n.fidelity, n.solver, StartSettings(count=1), 0)
                x = zero.best.x
                r = mirror_distances(CellModel(params, n.fidelity), x, args.spacing)
                print(f"{stitch:17} {L:5.2f} {zero.best.status:10} {x[-2]:6.3f} "
                      f"{r['c'] / x[-2]:6.3f} {r['d'] / x[-1]:6.3f} {int(r['sz']):+2d} "
                      f"{r['max']:9.2e} {r['rms']:9.2e}")  # fmt: skip


if __name__ == "__main__":
    main()
