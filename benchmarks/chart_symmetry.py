"""Whether a pattern's stitches, given room to differ, relax alike (prints a table; not a
test): the symmetry test of the charts' issue along the course.

Each named pattern (stockinette_free, garter, rib, seed) is relaxed as one stitch at L and
k = 0.1 mN/mm² (``converged``, one start). Its minimum is written as the chart of
``copies`` repeats of its row (``stitches.chart.supercell_state``: 2 and 4 stitches
for stockinette_free and garter, 4 and 8 for rib and seed, whose row repeats every two),
every free shape entry (not the periods, not the gauge's speeds) perturbed by a normal
``--sigma`` (mm, rad, 1/mm), and relaxed again at the same L with ``seeds`` seeds. The
table gives per seed the energy per stitch against the one-stitch minimum, and how far the
relaxed cell is from the one stitch's symmetry: the largest distance from the cell's
centre-line (sampled every ~0.005 mm), moved by that symmetry (one course period, through
the mirror z -> -z where the row alternates), to the nearest sample of the cell and its
images along the course. A cell whose stitches stay alike leaves the sampling's few
10⁻⁵ mm; one whose stitches part (a symmetry broken over several stitches) more.

A row of several stitches only: the rows above repeat it (or mirror it), so a symmetry
broken between rows is not seen here (a cell of several yarns is the next step).
Run: ``python benchmarks/chart_symmetry.py [--L 11.6] [--seeds 3] [--sigma 0.002]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.spatial import cKDTree
from threadpoolctl import threadpool_limits

from knitsweep.config import StartSettings, StitchParams
from knitsweep.model import CellModel
from knitsweep.presets import Numerics
from knitsweep.relax.zero_force import zero_force
from knitsweep.stitches.chart import supercell_state

ROWS = {"stockinette_free": ("K",), "garter": ("K", "P"), "rib": ("KP",), "seed": ("KP", "PK")}
"""Each named pattern's chart."""


def _chart(named: str, copies: int) -> str:
    return "chart:" + "-".join(row * copies for row in ROWS[named])


def _curve(cp: np.ndarray, per_segment: int = 400) -> np.ndarray:
    t = (np.arange(per_segment) + 0.5) / per_segment
    b = np.stack(
        [np.array([1, 5, 10, 10, 5, 1])[i] * t**i * (1 - t) ** (5 - i) for i in range(6)], 1
    )
    return np.concatenate([b @ c for c in cp])


def asymmetry(model: CellModel, x: np.ndarray, mirrored: bool) -> float:
    """Largest distance (mm) from the cell's curve moved by one course period (through
    the mirror z -> 2c - z if ``mirrored``, the plane's height c fitted: a row of
    translations has no plane of its own, and its joint 0, pinned at the origin, slides
    along the yarn) to the cell's curve and its images along the course (sampled 10 times
    as densely: the floor is ~2·10⁻⁴ mm)."""
    cp = model.control_points(x)
    pts = _curve(cp, 400)
    a_x, width = float(x[-2]), model.stitch.cell_periods(x)[0]
    dense = _curve(cp, 4000)
    tree = cKDTree(np.concatenate([dense + np.array([m * width, 0.0, 0.0]) for m in (-1, 0, 1)]))

    def moved(c: float) -> np.ndarray:
        q = pts + np.array([a_x, 0.0, 0.0])
        if mirrored:
            q[:, 2] = 2.0 * c - q[:, 2]
        return q

    if not mirrored:
        return float(tree.query(moved(0.0))[0].max())
    fit = minimize_scalar(lambda c: tree.query(moved(c))[0].mean(), bounds=(-0.5, 0.5),
                          method="bounded", options={"xatol": 1e-7})  # fmt: skip
    return float(tree.query(moved(fit.x))[0].max())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--L", type=float, default=11.6)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--sigma", type=float, default=0.002)
    ap.add_argument("--stitches", nargs="*", default=list(ROWS))
    ap.add_argument("--copies", nargs="*", type=int, default=[2, 4])
    args = ap.parse_args()
    n = Numerics.from_preset("converged")
    print(f"L = {args.L} mm, k = 0.1 mN/mm², sigma = {args.sigma}, converged preset")
    print(
        "| pattern | cell | seed | E per stitch − one stitch's (mJ) | status | asymmetry (mm) | s |"
    )
    print("|---|---|---|---|---|---|---|")
    for named in args.stitches:
        p1 = StitchParams(stitch=named, L_mm=args.L, k_mN_per_mm2=0.1)
        one = zero_force(p1, n.fidelity, n.solver, StartSettings(count=1), 0).best
        m1 = CellModel(p1, n.fidelity)
        mirrored = bool(m1.stitch.mirror_parity[0])
        print(f"| {named} | 1 stitch | – | {one.total_energy:.7f} mJ | {one.status} | – | – |")
        for copies in args.copies:
            chart = _chart(named, copies)
            pc = p1.model_copy(update={"stitch": chart})
            mc = CellModel(pc, n.fidelity)
            x0 = supercell_state(one.x, m1.control_points(one.x), m1.stitch.mirror_parity,
                                 copies, any(mc.stitch.mirror_parity))  # fmt: skip
            free = np.ones(mc.stitch.n_state, bool)
            free[-2:] = False
            free[mc.gauge] = False
            for seed in range(args.seeds):
                x = x0.copy()
                rng = np.random.default_rng(seed)
                x[free] += rng.normal(0.0, args.sigma, int(free.sum()))
                t = time.perf_counter()
                best = zero_force(pc, n.fidelity, n.solver, StartSettings(count=1), 0,
                                  initial=x).best  # fmt: skip
                s = time.perf_counter() - t
                d = best.total_energy - one.total_energy
                print(
                    f"| {named} | {chart} | {seed} | {d:+.2e} | {best.status} | "
                    f"{asymmetry(mc, best.x, mirrored):.2e} | {s:.1f} |",
                    flush=True,
                )


if __name__ == "__main__":
    with threadpool_limits(1):
        main()
