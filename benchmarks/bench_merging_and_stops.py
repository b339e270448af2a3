"""What merging chains and stopping sweeps early change, on the paper's k = 0.1 series
(prints figures; not a pass/fail test).

For every L of ``jobs/paper_k0.1_L_sweep.toml`` (10.5 … 12.8 mm, 4 starts, the default
preset) and both directions, the same zero-force state is pulled four ways:

* ``all chains``: every start's chain kept to the end (``merge_tolerance_mJ = 0``);
* ``merged``: chains at the same minimum merge (the default);
* ``gaps``: merged, and the sweep stops once the energy gaps are determined;
* ``gaps, adaptive``: the same with adaptive steps.

Printed: per direction, (L/r)_trans and its bracket from each variant's gaps (the one
jamming rule, ``analysis.transition``), the largest change of a gap against ``all
chains`` (relative to max(gap, threshold)) and, for the early stops, against ``merged``
(the same chains pulled to the end: what the stop rule alone changes), the points where
a gap moved by more than 1 %, and each variant's total CPU seconds, relaxations and
evaluations.

Run: ``python benchmarks/bench_merging_and_stops.py [--L 10.5 11.0 …]``; a few minutes.
"""

from __future__ import annotations

import argparse
import time

from threadpoolctl import threadpool_limits

from knitsweep.analysis import transition
from knitsweep.analysis.transitions import GAP_THRESHOLD
from knitsweep.compilation import compile_kernels
from knitsweep.config import StartSettings, StitchParams, SweepProtocol
from knitsweep.kernels.kkt_rows import compile_solver
from knitsweep.relax.zero_force import zero_force
from knitsweep.strain_sweep import strain_sweep

VARIANTS = {
    "all chains": SweepProtocol(merge_tolerance_mJ=0.0),
    "merged": SweepProtocol(),
    "gaps": SweepProtocol(observables=("energy_gaps",)),
    "gaps, adaptive": SweepProtocol(observables=("energy_gaps",), step_control="adaptive"),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--L", type=float, nargs="+", default=[round(10.5 + 0.1 * i, 1)
                                                            for i in range(24)])  # fmt: skip
    ap.add_argument("--r", type=float, default=0.74)
    args = ap.parse_args()
    threadpool_limits(1)
    compile_kernels()
    compile_solver()
    gaps = {(v, d): [] for v in VARIANTS for d in "xy"}
    cost = {v: [0.0, 0, 0] for v in VARIANTS}
    merges = 0
    for L in args.L:
        params = StitchParams(L_mm=L, k_mN_per_mm2=0.1, r_mm=args.r)
        zero = zero_force(params, starts=StartSettings(count=4), seed=2025)
        merges += sum(1 for i in zero.merged_into if i >= 0)
        for d in "xy":
            for name, protocol in VARIANTS.items():
                t = time.process_time()
                s = strain_sweep(params, zero, d, protocol)
                cost[name][0] += time.process_time() - t
                cost[name][1] += s.relaxations
                cost[name][2] += s.evaluations_total
                gaps[(name, d)].append(s.energy_gaps.jamming_gap(d))
    print(f"k = 0.1 mN/mm^2, {len(args.L)} points, 4 starts, default preset; "
          f"{merges} starts merged on their way to zero force")  # fmt: skip
    x = [L / args.r for L in args.L]
    for d in "xy":
        ref = gaps[("all chains", d)]
        print(f"\n{d}: {'variant':<16}{'(L/r)_trans':>12}{'bracket':>22}{'max |d gap|':>13}"
              f"{'vs merged':>11}  gaps moved > 1 % (L mm: relative change)")  # fmt: skip
        for name in VARIANTS:
            g = gaps[(name, d)]
            t = transition(x, g)
            rel = [abs(a - b) / max(b, GAP_THRESHOLD) for a, b in zip(g, ref, strict=True)]
            moved = ", ".join(f"{L}: {r:.1%}" for L, r in zip(args.L, rel, strict=True)
                              if r > 0.01) or "none"  # fmt: skip
            bracket = f"({t.bracket_lower:.4f}, {t.bracket_upper:.4f}]"
            merged = gaps[("merged", d)]
            stop = max(abs(a - b) / max(b, GAP_THRESHOLD) for a, b in zip(g, merged, strict=True))
            print(f"   {name:<16}{t.L_over_r_trans:12.4f}{bracket:>22}{max(rel):13.1e}"
                  f"{stop:11.1e}  {moved}")  # fmt: skip
    print(f"\n{'variant':<16}{'CPU s':>8}{'relaxations':>13}{'evaluations':>13}")
    for name, (sec, n_relax, n_eval) in cost.items():
        print(f"{name:<16}{sec:8.1f}{n_relax:13d}{n_eval:13d}")


if __name__ == "__main__":
    main()
