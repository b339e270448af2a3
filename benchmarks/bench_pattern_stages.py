"""Where a pattern's zero-force state spends its time: every relaxation of the
continuation walk from the first shipped start, in order (prints a table; not a test).

Per stitch and L (k = 0.1 mN/mm², the ``converged`` preset, one start): each relaxation's
stage length L, minimiser (a rough stitch's intermediate stages are SLSQP alone, its last
stage two descents, docs/model.md §7 and §11), tolerance, iterations, evaluations, CPU
seconds, status, energy and the start of its message (which says whether Newton stopped
short and SLSQP finished). A first call compiles and warms up; the second is printed.

Run: ``python benchmarks/bench_pattern_stages.py [--stitches garter,seed] [--L 10.5 11.6]``.
"""

from __future__ import annotations

import argparse
import time

from threadpoolctl import threadpool_limits

from knitsweep.config import StartSettings, StitchParams
from knitsweep.presets import Numerics
from knitsweep.relax import relaxer
from knitsweep.relax.zero_force import zero_force


def stages(stitch: str, L: float, k: float) -> tuple[float, list[tuple]]:
    """CPU seconds of the zero-force state and one row per relaxation it ran."""
    params = StitchParams(stitch=stitch, L_mm=L, k_mN_per_mm2=k)
    n = Numerics.from_preset("converged")
    rows: list[tuple] = []
    plain = relaxer.Relaxer.relax

    def logged(self, model, x0, fixed=None, settings=None):
        t0 = time.process_time()
        r = plain(self, model, x0, fixed, settings)
        s = settings or self.settings
        rows.append((model.params.L_mm, s.method, s.ftol, r.iterations, r.evaluations,
                     time.process_time() - t0, r.status, r.total_energy, r.message))  # fmt: skip
        return r

    relaxer.Relaxer.relax = logged
    try:
        zero_force(params, n.fidelity, n.solver, StartSettings(count=1), 0)  # compile, warm
        rows.clear()
        t0 = time.process_time()
        zero_force(params, n.fidelity, n.solver, StartSettings(count=1), 0)
        return time.process_time() - t0, rows
    finally:
        relaxer.Relaxer.relax = plain


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stitches", default="garter,rib,seed")
    ap.add_argument("--L", type=float, nargs="+", default=[10.5, 11.6])
    ap.add_argument("--k", type=float, default=0.1)
    args = ap.parse_args()
    with threadpool_limits(1):
        for stitch in args.stitches.split(","):
            for L in args.L:
                total, rows = stages(stitch, L, args.k)
                print(f"{stitch} L = {L} mm: zero force {total:.2f} CPU s, {len(rows)} relaxations")
                for Ls, method, ftol, it, ev, cpu, status, e, msg in rows:
                    print(f"  L {Ls:7.3f} {method:6} ftol {ftol:7.1e} it {it:5d} ev {ev:5d} "
                          f"{cpu:6.3f} s {status:13} E {e:.7f}  {msg[:90]}")  # fmt: skip


if __name__ == "__main__":
    main()
