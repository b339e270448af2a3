"""How restrictive is the paper's stockinette ansatz? (prints a table; not a test)

At each L (default 10.5, 11.6, 12.2 mm; k = 0.1 mN/mm², Table 1 otherwise) the ansatz's
zero-force state (``zero_force``, 4 starts) is mapped into the free periodic yarn
(``stitches.stockinette_free.ansatz.to_free``, docs/model.md §11), its energy there
checked against the ansatz's, and relaxed again with every control point free (both
periods free, Newton–KKT, then SLSQP if Newton stops short). Printed per L: the ansatz
minimum E_a, the free minimum E_f, the fall E_a − E_f (absolute and relative) and its
split into bending and contact, the periods before and after, the smallest ζ, the
status, whether the ansatz's twist bound was active, whether the crossings in projection are the ansatz's (``stitches.topology``),
and CPU seconds of the free relaxation (median of ``--repeats`` runs).

Run: ``python benchmarks/free_yarn_relax.py [--L 10.5 11.6 12.2] [--repeats 1]``.
"""

from __future__ import annotations

import argparse
import statistics
import time

from threadpoolctl import threadpool_limits

from knitsweep.config import SolverSettings, StitchParams
from knitsweep.model import CellModel
from knitsweep.relax import Relaxer
from knitsweep.relax.zero_force import zero_force
from knitsweep.stitches.stockinette_free.ansatz import to_free
from knitsweep.stitches.topology import crossings, same_topology


def one(L: float, k: float, repeats: int) -> dict:
    pa = StitchParams(L_mm=L, k_mN_per_mm2=k)
    pf = pa.model_copy(update={"stitch": "stockinette_free"})
    zf = zero_force(pa)
    xa = zf.best.x
    ma, mf = CellModel(pa), CellModel(pf)
    xf0 = to_free(ma.control_points(xa), xa[-2], xa[-1])
    ea, ef0 = ma.energies(xa), mf.energies(xf0)
    times, rel = [], None
    for _ in range(repeats):
        t0 = time.process_time()
        rel = Relaxer(SolverSettings()).relax(mf, xf0)
        if not rel.converged:
            rel = Relaxer(SolverSettings(method="slsqp")).relax(mf, rel.x)
        times.append(time.process_time() - t0)
    return {
        "L": L, "Ea": ea.total_energy, "map_err": abs(ef0.total_energy - ea.total_energy),
        "Ef": rel.total_energy, "dEb": ea.bending_energy - rel.bending_energy,
        "dEc": ea.contact_energy - rel.contact_energy, "ax0": xa[-2], "ay0": xa[-1],
        "ax": rel.x[-2], "ay": rel.x[-1], "zeta": rel.min_zeta, "status": rel.status,
        "topology": same_topology(crossings(ma.control_points(xa), xa[-2], xa[-1]),
                                  crossings(mf.control_points(rel.x), rel.x[-2], rel.x[-1]))[0],
        "it": rel.iterations, "cpu": statistics.median(times), "twist": zf.best.twist_active,
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--L", type=float, nargs="+", default=[10.5, 11.6, 12.2])
    ap.add_argument("--k", type=float, default=0.1, help="mN/mm^2")
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args()
    print(f"k = {args.k} mN/mm^2; energies in mJ, lengths in mm")
    print(" L     E_ansatz   |map err|  E_free     fall      fall/E   dE_b      dE_c      "
          "a_x a->f        a_y a->f        min zeta  status     it  cpu s  tw active")  # fmt: skip
    with threadpool_limits(1):
        for L in args.L:
            r = one(L, args.k, args.repeats)
            fall = r["Ea"] - r["Ef"]
            print(f"{r['L']:5.2f} {r['Ea']:.7f}  {r['map_err']:.1e}  {r['Ef']:.7f}  "
                  f"{fall:.2e}  {fall / r['Ea']:7.2%}  {r['dEb']:+.2e}  {r['dEc']:+.2e}  "
                  f"{r['ax0']:.4f}->{r['ax']:.4f}  {r['ay0']:.4f}->{r['ay']:.4f}  "
                  f"{r['zeta']:.3f}  {r['status']:9s} {r['it']:4d}  {r['cpu']:5.1f}  "
                  f"{r['twist']!s:9s}  {r['topology']}")  # fmt: skip


if __name__ == "__main__":
    main()
