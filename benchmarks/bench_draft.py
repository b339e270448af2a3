"""What a study point costs per preset, and which lever makes ``draft`` cheap.

Run: ``python benchmarks/bench_draft.py [--L 11.3 11.4 11.5 11.6] [--k 0.1] [--starts 4]
[--repeats 3] [--variant SPEC ...]``

A point of a study is one task for its zero-force state (``zero_force`` from
``--starts`` shipped starts) and one task per sweep direction (x and y), as a job runs
them (``service.worker``). For each setting (``studies.accuracy.setting`` specs:
``draft``, ``draft:ftol=1e-5`` …; a ``@N`` suffix sets the number of starts, e.g.
``draft@2``; a ``+carry`` suffix carries starts along the series as ``[starts] carry``
does: the largest L from the shipped starts, every other point from the zero-force
state of the next larger L, e.g. ``draft@4+carry``) this prints, per point of the series (k = 0.1 mN/mm^2 around the
transition by default), the CPU seconds of the zero-force task and of both sweeps
(medians over ``--repeats``), and the relative errors of Y_sec and of the jamming gap
against the first setting (``converged`` unless told otherwise): the gap's error
relative to max(|gap|, 5e-5 mJ), the jamming threshold, as the issue asks.

Not a test: nothing here passes or fails (STYLE.md, "benchmarks kept apart").
"""

from __future__ import annotations

import argparse
import statistics
import time

from knitsweep.analysis.stress_strain import secant_modulus
from knitsweep.compilation import compile_kernels
from knitsweep.config import StartSettings, StitchParams
from knitsweep.relax.zero_force import zero_force
from knitsweep.strain_sweep import strain_sweep
from knitsweep.studies.accuracy import setting

THRESHOLD = 5e-5  # mJ: the jamming threshold of the energy gaps


def point(L: float, k: float, spec: str, starts: int, repeats: int, carried=None) -> dict:
    s = setting(spec)
    params = StitchParams(L_mm=L, k_mN_per_mm2=k)
    zf_t, sw_t = [], []
    for _ in range(repeats):
        t = time.process_time()
        zf = zero_force(params, s.fidelity, s.solver, StartSettings(count=starts), 0,
                        carried=carried)  # fmt: skip
        zf_t.append(time.process_time() - t)
        t = time.process_time()
        sweeps = {d: strain_sweep(params, zf, d, s.protocol, s.fidelity, s.solver) for d in "xy"}
        sw_t.append(time.process_time() - t)
    out = {"zf": statistics.median(zf_t), "sweeps": statistics.median(sw_t),
           "E0": zf.best.total_energy, "state": (zf.best.x, params)}  # fmt: skip
    for d, sw in sweeps.items():
        out[f"Y_{d}"] = secant_modulus(sw.strain, sw.stress).Y_sec
        out[f"gap_{d}"] = sw.energy_gaps.jamming_gap(d)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--L", type=float, nargs="+", default=[11.3, 11.4, 11.5, 11.6])
    ap.add_argument("--k", type=float, default=0.1)
    ap.add_argument("--starts", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--variant", nargs="+", default=["converged", "draft"])
    ap.add_argument("--detail", action="store_true", help="also each point's Y_sec and gaps")
    args = ap.parse_args()
    compile_kernels()
    rows = {}
    for spec in args.variant:
        base, _, carry = spec.partition("+")
        name, _, n = base.partition("@")
        starts = int(n) if n else args.starts
        compile_kernels(setting(name).fidelity)
        if carry != "carry":
            rows[spec] = [point(L, args.k, name, starts, args.repeats) for L in args.L]
            continue
        done, carried = {}, None
        for L in sorted(args.L, reverse=True):
            done[L] = point(L, args.k, name, starts, args.repeats, carried)
            carried = done[L]["state"]
        rows[spec] = [done[L] for L in args.L]
    ref = rows[args.variant[0]]
    print(f"k = {args.k} mN/mm^2, L = {args.L} mm, CPU s per task (median of {args.repeats}); "
          f"errors against {args.variant[0]}")  # fmt: skip
    print(f"{'setting':34s} {'zf s/pt':>8s} {'sweeps':>8s} {'s/pt':>7s} {'ratio':>6s} "
          f"{'dE0 mJ':>8s} {'Y_sec':>8s} {'gap':>8s}")  # fmt: skip
    ref_cost = sum(r["zf"] + r["sweeps"] for r in ref) / len(ref)
    for spec, pts in rows.items():
        zf = sum(r["zf"] for r in pts) / len(pts)
        sw = sum(r["sweeps"] for r in pts) / len(pts)
        y_err = max(abs(p[f"Y_{d}"] / r[f"Y_{d}"] - 1) for p, r in zip(pts, ref, strict=True)
                    for d in "xy")  # fmt: skip
        g_err = max(abs(p[f"gap_{d}"] - r[f"gap_{d}"]) / max(abs(r[f"gap_{d}"]), THRESHOLD)
                    for p, r in zip(pts, ref, strict=True) for d in "xy")  # fmt: skip
        de0 = max(abs(p["E0"] - r["E0"]) for p, r in zip(pts, ref, strict=True))
        print(f"{spec:34s} {zf:8.3f} {sw:8.3f} {zf + sw:7.3f} {ref_cost / (zf + sw):6.1f} "
              f"{de0:8.1e} {y_err:8.1e} {g_err:8.1e}")  # fmt: skip
        if args.detail:
            for L, p in zip(args.L, pts, strict=True):
                print(f"    L {L:5.2f}: Y_sec x {p['Y_x']:.5g} y {p['Y_y']:.5g} N/mm, gap x "
                      f"{p['gap_x']:.4g} y {p['gap_y']:.4g} mJ, E0 {p['E0']:.10g}")  # fmt: skip


if __name__ == "__main__":
    main()
