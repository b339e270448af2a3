"""What a cell of n stitches costs against one stitch (prints a table; not a test).

For the free stockinette (chart ``K`` × n) and rib (chart ``KP`` × n/2) at L = 11.6 mm,
k = 0.1 mN/mm² (``converged``): the one stitch's minimum written as the chart of n
stitches (``stitches.chart.supercell_state``), its free shape entries perturbed by a
normal 0.002 (seed 0), and relaxed at the same L (one start). Per n: the CPU seconds of
one energy with its gradient (median of ``--calls``), of the relaxation and its
iterations, each also as a ratio to n = 1 (rib: to its one-stitch cell). The issue's
target: a cell of 4 stitches at most 5× one stitch per relaxation, of 16 at most 25×.
Run: ``python benchmarks/chart_cost.py [--n 1 2 4 8 16] [--calls 30]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from threadpoolctl import threadpool_limits

from knitsweep.config import StartSettings, StitchParams
from knitsweep.model import CellModel
from knitsweep.presets import Numerics
from knitsweep.relax.zero_force import zero_force
from knitsweep.stitches.chart import supercell_state


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", nargs="*", type=int, default=[1, 2, 4, 8, 16])
    ap.add_argument("--calls", type=int, default=30)
    ap.add_argument("--L", type=float, default=11.6)
    args = ap.parse_args()
    num = Numerics.from_preset("converged")
    print(f"L = {args.L} mm, k = 0.1 mN/mm², converged preset, one process, CPU s")
    print("| stitch | n | energy + gradient (ms) | × n=1 | relaxation (s) | iterations | × n=1 |")
    print("|---|---|---|---|---|---|---|")
    for named, row in (("stockinette_free", "K"), ("rib", "KP")):
        p1 = StitchParams(stitch=named, L_mm=args.L, k_mN_per_mm2=0.1)
        one = zero_force(p1, num.fidelity, num.solver, StartSettings(count=1), 0).best
        m1 = CellModel(p1, num.fidelity)
        base = None
        for n in args.n:
            if n % len(row):
                continue
            chart = "chart:" + row * (n // len(row))
            pc = p1.model_copy(update={"stitch": chart})
            mc = CellModel(pc, num.fidelity)
            x = supercell_state(one.x, m1.control_points(one.x), m1.stitch.mirror_parity,
                                n // len(row), False)  # fmt: skip
            free = np.ones(mc.stitch.n_state, bool)
            free[-2:] = False
            free[mc.gauge] = False
            x[free] += np.random.default_rng(0).normal(0.0, 0.002, int(free.sum()))
            mc.energy_and_gradients(x)  # compiled
            calls = []
            for _ in range(args.calls):
                t = time.process_time()
                mc.energy_and_gradients(x)
                calls.append(time.process_time() - t)
            energy = float(np.median(calls))
            t = time.process_time()
            r = zero_force(pc, num.fidelity, num.solver, StartSettings(count=1), 0, initial=x).best
            relax = time.process_time() - t
            if base is None:
                base = (energy, relax)
            print(
                f"| {named} | {n} | {1e3 * energy:.2f} | {energy / base[0]:.1f} | {relax:.2f} "
                f"({r.status}) | {r.iterations} | {relax / base[1]:.1f} |",
                flush=True,
            )


if __name__ == "__main__":
    with threadpool_limits(1):
        main()
