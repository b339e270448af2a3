"""Each stitch pattern through what a study computes per point, side by side with
stockinette (prints a table; not a test).

Per stitch (default: every pattern knitsweep knows) and L (default 10.5, 11.6, 12.2 mm;
k = 0.1 mN/mm², Table 1 otherwise, the ``converged`` preset): the zero-force state from
the first shipped start alone (``zero_force``, one start, walked from the start's own
length by continuation), then an x and a y sweep from it with the observables an
adaptive study asks for (``energy_gaps`` and ``secant_modulus``: each sweep stops once
it knows Y_sec and both energy gaps). Printed: CPU seconds of each (median of
``--repeats`` runs, BLAS on one thread, one process), the zero-force state (status,
E, a_x, a_y, a_y/a_x, min ζ), and per direction the steps, Y_sec and the jamming gap
(ΔE_c in x, ΔE_b in y); then the cost per point (zero force + both sweeps) of each
pattern over stockinette's at the same L. a_x and a_y are per-stitch spacings for every
pattern, and the strain is the fabric's, so the rows compare directly.

Run: ``python benchmarks/bench_pattern_pipeline.py [--stitches stockinette,rib]
[--L 11.6] [--repeats 1] [--sampling parameter]`` (``--sampling``: where a free yarn's
contact samples sit, ``Fidelity.contact_sampling``, by default along the yarn with the
speeds as a gauge; stockinette's are its own).
"""

from __future__ import annotations

import argparse
import statistics
import time

from threadpoolctl import threadpool_limits

from knitsweep.analysis.metrics import energy_gaps
from knitsweep.analysis.stress_strain import secant_modulus
from knitsweep.config import StartSettings, StitchParams
from knitsweep.presets import Numerics
from knitsweep.relax.zero_force import zero_force
from knitsweep.stitches import STITCH_NAMES
from knitsweep.strain_sweep import strain_sweep


def one(stitch: str, L: float, k: float, sampling: str = "auto") -> dict:
    params = StitchParams(stitch=stitch, L_mm=L, k_mN_per_mm2=k)
    n = Numerics.from_preset("converged", observables=("energy_gaps", "secant_modulus"))
    n = n.model_copy(update={"fidelity": n.fidelity.model_copy(
        update={"contact_sampling": sampling})})  # fmt: skip
    t0 = time.process_time()
    zero = zero_force(params, n.fidelity, n.solver, StartSettings(count=1), 0)
    row = {"zero_cpu": time.process_time() - t0, "zero": zero.best}
    for d in ("x", "y"):
        if not zero.best.converged:
            row[d] = None
            continue
        t0 = time.process_time()
        s = strain_sweep(params, zero, d, n.protocol, n.fidelity, n.solver)
        cpu = time.process_time() - t0
        gaps = energy_gaps(s.bending_energy, s.contact_energy)
        ysec = secant_modulus(s.strain, s.stress).Y_sec
        gap = gaps.delta_E_c if d == "x" else gaps.delta_E_b
        row[d] = {"cpu": cpu, "steps": len(s.strain), "Y_sec": ysec, "gap": gap,
                  "status": s.status}  # fmt: skip
    return row


def _f(v, fmt: str) -> str:
    return "—" if v is None else format(v, fmt)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stitches", default=",".join(STITCH_NAMES))
    ap.add_argument("--L", type=float, nargs="+", default=[10.5, 11.6, 12.2])
    ap.add_argument("--k", type=float, default=0.1)
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--sampling", choices=("auto", "parameter", "arclength", "yarn_arclength"),
                    default="auto",
                    help="a free yarn's contact samples (Fidelity.contact_sampling)")  # fmt: skip
    args = ap.parse_args()
    stitches = args.stitches.split(",")
    print(f"k = {args.k} mN/mm^2, converged preset, 1 start; CPU s (median of {args.repeats}); "
          "E mJ, lengths mm, Y_sec N/mm, gap mJ (ΔE_c in x, ΔE_b in y)")  # fmt: skip
    print(f"{'stitch':12} {'L':>5} {'zero s':>7} {'status':14} {'E':>9} {'a_x':>6} {'a_y':>6} "
          f"{'ay/ax':>5} {'min ζ':>6} | {'x s':>6} {'st':>3} {'Y_sec,x':>7} {'gap x':>8} | "
          f"{'y s':>6} {'st':>3} {'Y_sec,y':>7} {'gap y':>8} | {'point s':>7} {'÷ stock.':>8}")  # fmt: skip
    per_point: dict[tuple[str, float], float] = {}
    with threadpool_limits(1):
        for L in args.L:
            for stitch in stitches:
                rows = [one(stitch, L, args.k, args.sampling) for _ in range(args.repeats)]
                row = rows[-1]
                z = row["zero"]
                zcpu = statistics.median(r["zero_cpu"] for r in rows)
                cells = []
                total = zcpu
                for d in ("x", "y"):
                    if row[d] is None:
                        cells.append(f"{'—':>6} {'—':>3} {'—':>7} {'—':>8}")
                        continue
                    cpu = statistics.median(r[d]["cpu"] for r in rows)
                    total += cpu
                    s = row[d]
                    cells.append(f"{cpu:6.2f} {s['steps']:3d} {_f(s['Y_sec'], '7.4f')} "
                                 f"{s['gap']:8.2e}")  # fmt: skip
                per_point[(stitch, L)] = total
                base = per_point.get(("stockinette", L))
                ratio = f"{total / base:8.1f}" if base else f"{'—':>8}"
                print(f"{stitch:12} {L:5.2f} {zcpu:7.2f} {z.status:14} {z.total_energy:9.6f} "
                      f"{z.a_x:6.3f} {z.a_y:6.3f} {z.a_y / z.a_x:5.2f} {z.min_zeta:6.3f} | "
                      f"{cells[0]} | {cells[1]} | {total:7.2f} {ratio}")  # fmt: skip


if __name__ == "__main__":
    main()
