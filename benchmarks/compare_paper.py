"""knitsweep beside the paper's tables (prints markdown): Table S4, Table S3 with Table 2,
sigma0 coverage and Table S1, and where the zero-strain markers switch.

Inputs are results files of the shipped jobs (run them first, e.g. ``mpirun -n 3
knitsweep run jobs/paper_k0.1_L_sweep.toml``):

* ``--k01``: ``jobs/paper_k0.1_L_sweep.toml`` (k = 0.1, x and y, contact forces stored);
* ``--s4``: ``jobs/paper_table_s4.toml`` (x pulls at k = 0.2 … 2), any number of files;
* ``--k06``: ``jobs/paper_sigma0_k0.6.toml`` (Table 1 values, x and y).

Sections:

1. Table S4: the line through the linear jammed regime of ΔE_c (x) per k, beside the
   paper's row, and the line through every jammed point (the fit before this rule);
2. Table S3: |F_x| (self + same row) and |F_y| (NN + NNN same column) at zero strain
   for three definitions of a contact force, their ratio and where it crosses 1;
   the signs by class beside Table 2;
3. sigma0 coverage: sweeps with an offset stress, fitted to the finite-difference
   stress (before) and to the envelope stress (now), and the discontinuous sweeps;
4. Table S1 at k = 0.6: sigma0 and Y_sec against the paper's fits;
5. markers at k = 0.1: where the area dip of y pulls begins and the z-shrink of x
   pulls ends, for several tolerances, beside the force-ratio crossing, the
   aspect-ratio peak, the end of the linear jammed run and (L/r)_trans.

``--test-data PATH`` also writes the small gap/state dataset the test suite compares
against the paper (tests/data/paper_series.json).

Run: ``python benchmarks/compare_paper.py --k01 paper_k0.1_L_sweep.h5 --s4
paper_table_s4.h5 --k06 paper_sigma0_k0.6.h5``
"""

from __future__ import annotations

import argparse
import json
import sys
from itertools import pairwise
from pathlib import Path

import compare_ansatz
import numpy as np
import paper_doc

from knitsweep.analysis import fit_line, offset_stress
from knitsweep.analysis.paper import (
    TABLE_S1_SIGMA0_L,
    TABLE_S1_YSEC_L,
    TABLE_S3,
    TABLE_S4,
    ratio_crossing,
    table_s3_crossing_mm,
)
from knitsweep.analysis.stress_strain import FD_STRESS_SMOOTHING
from knitsweep.config import StitchParams
from knitsweep.model import CellModel
from knitsweep.report.force_columns import fig6h_forces
from knitsweep.report.reduce import Reduction, reduce_results
from knitsweep.store.read import iter_entries

SIGNS = {  # paper Table 2: direction of each class's force at zero strain
    ("self", "x"): "extend",
    ("same_row", "x"): "extend",
    ("nn_column", "y"): "compress",
    ("nnn_column", "y"): "extend",
}


def _e(v: float | None, spec: str = ".3e") -> str:
    return "–" if v is None else format(v, spec)


def _x_rows(red: Reduction, k: float, d: str = "x") -> list[dict]:
    rows = [r for r in red.sweeps if r["direction"] == d and r["k_mN_per_mm2"] == k]
    return sorted(rows, key=lambda r: r["L_mm"])


def table_s4(reds: list[Reduction]) -> list[str]:
    out = ["| k (mN/mm²) | fitted L (mm) | slope (mJ/mm) | paper | intercept (mJ) | paper | "
           "zero L (mm) | paper | max \\|res\\| (mJ) | paper | mean \\|res\\| | paper | MSE (mJ²) | "
           "paper | (L/r)_trans | ΔL/r | all-jammed slope (÷ paper) |",
           "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]  # fmt: skip
    seen = set()
    pairs = sorted(((t["k_mN_per_mm2"], i, t) for i, red in enumerate(reds) for t in red.transitions),
                   key=lambda v: (v[0], v[1]))  # fmt: skip
    for k, i, t in pairs:
        red = reds[i]
        if t["direction"] != "x" or k in seen or t["fit_n_points"] is None:
            continue
        seen.add(k)
        p = TABLE_S4.get(k)
        rows = [r for r in _x_rows(red, k) if r["jammed"] and (
            t["L_over_r_trans"] is None or r["L_over_r"] < t["L_over_r_trans"])]  # fmt: skip
        every = fit_line(np.array([r["L_mm"] for r in rows]),
                         np.array([r["delta_E_c"] for r in rows]))  # fmt: skip
        ratio = f"{every.slope / p.slope_mJ_per_mm:.2f}" if p else "–"
        out.append(
            f"| {k:g} | {t['fit_L_lo_mm']:.1f}–{t['fit_L_hi_mm']:.1f} ({t['fit_n_points']}) | "
            f"{t['fit_slope_mJ_per_mm']:.3e} | {_e(p and p.slope_mJ_per_mm)} | "
            f"{t['fit_intercept_mJ']:.4f} | {_e(p and p.intercept_mJ, '.4f')} | "
            f"{_e(t['fit_zero_L_mm'], '.3f')} | {_e(p and p.zero_L_mm, '.3f')} | "
            f"{t['fit_max_abs_residual_mJ']:.2e} | {_e(p and p.max_abs_residual_mJ, '.2e')} | "
            f"{t['fit_mean_abs_residual_mJ']:.2e} | {_e(p and p.mean_abs_residual_mJ, '.2e')} | "
            f"{t['fit_mse_mJ2']:.2e} | {_e(p and p.mse_mJ2, '.2e')} | "
            f"{_e(t['L_over_r_trans'], '.2f')} | {_e(t['delta_L_over_r'], '.3f')} | "
            f"{every.slope:.3e} ({ratio}) |"
        )
    return out


def _forces_by_definition(red: Reduction) -> dict[float, dict[str, np.ndarray]]:
    """L → {definition: (5, 3) forces} at zero strain of every done point."""
    out = {}
    for e in iter_entries(red.path, with_data=True):
        if e.kind != "points" or e.meta.get("status") != "done":
            continue
        x = np.asarray(e.record["x"][int(e.meta.get("winner", 0))], dtype=float)
        params = StitchParams.from_flat(e.meta)
        model = CellModel(params)
        out[round(float(e.meta["L_mm"]), 6)] = {
            "pair": model.contact_pair_forces_by_class(x),
            "pair, ds ds′-weighted": model.contact_pair_forces_by_class(x, weighted=True),
            "generalised −∂E_c/∂a": model.contact_forces_by_class(x),
        }
    return out


def _fx_fy(f: np.ndarray) -> tuple[float, float]:
    fx, fy, _ = fig6h_forces(f)
    return abs(fx), abs(fy)


def table_s3(red: Reduction) -> list[str]:
    forces = _forces_by_definition(red)
    names = list(next(iter(forces.values())))
    out = ["| L (mm) | paper \\|F_x\\| | \\|F_y\\| | ratio | "
           + " | ".join(f"{n}: \\|F_x\\| | \\|F_y\\| | ratio" for n in names) + " |",
           "|---:|" + "---:|" * (3 + 3 * len(names))]  # fmt: skip
    for L, (px, py) in sorted(TABLE_S3.items()):
        if L not in forces:
            continue
        cells = [f"{L:.1f}", f"{px:.3f}", f"{py:.3f}", f"{px / py:.3f}"]
        for n in names:
            fx, fy = _fx_fy(forces[L][n])
            cells += [f"{fx:.3g}", f"{fy:.3g}", f"{fx / fy:.3f}"]
        out.append("| " + " | ".join(cells) + " |")
    Ls = sorted(forces)
    cross = [f"paper {table_s3_crossing_mm():.2f} mm"]
    for n in names:
        c = ratio_crossing(Ls, [np.divide(*_fx_fy(forces[L][n])) for L in Ls])
        cross.append(f"{n} {_e(c, '.2f')} mm")
    out += ["", "ratio crosses 1 at: " + "; ".join(cross)]
    L0 = min(forces)
    f = forces[L0]["pair"]
    signs = []
    for (cls, a), want in SIGNS.items():
        v = f[["self", "same_row", "nn_column", "nnn_column"].index(cls), "xyz".index(a)]
        signs.append(
            f"{cls} {a}: {v:+.3f} N ({'extend' if v > 0 else 'compress'}; Table 2: {want})"
        )
    flips = [L for L0_, L in pairwise(Ls)
             if np.sign(forces[L0_]["pair"][2, 1]) != np.sign(forces[L]["pair"][2, 1])]  # fmt: skip
    out += ["", f"pair forces by class at L = {L0:g} mm: " + "; ".join(signs),
            f"NN same-column y force changes sign at L = {flips} mm"]  # fmt: skip
    return out


def sigma0_coverage(reds: list[Reduction]) -> list[str]:
    out = ["| file | sweeps | σ0 on FD stress (before) | σ0 on envelope (now) | "
           "discontinuous (switching drops) | without σ0 now (direction, L mm: no linear regime) |", "|---|---:|---:|---:|---:|---|"]  # fmt: skip
    for red in reds:
        before = 0
        for e in iter_entries(red.path, with_data=True):
            if e.kind == "sweeps" and e.meta.get("status") == "done":
                o = offset_stress(e.record["strain"], e.record["stress"], **FD_STRESS_SMOOTHING)
                before += o.sigma0 is not None
        now = [r for r in red.sweeps if r["sigma0_N_per_mm"] is not None]
        missing = [f"{r['direction']} {r['L_mm']:g}" for r in red.sweeps
                   if r["sigma0_N_per_mm"] is None]  # fmt: skip
        disc = sum(bool(r["stress_discontinuous"]) for r in red.sweeps)
        out.append(f"| {red.path.name} | {len(red.sweeps)} | {before} | {len(now)} | {disc} | "
                   f"{'; '.join(missing) or '–'} |")  # fmt: skip
    return out


def table_s1(red: Reduction) -> list[str]:
    out = ["| direction | L (mm) | L/r | jammed | σ0 (N/mm) | Table S1 | ratio | Y_sec (N/mm) | "
           "Table S1 | ratio |", "|---|---:|---:|---|---:|---:|---:|---:|---:|---:|"]  # fmt: skip
    for d in "xy":
        (a0, b0), (a1, b1) = TABLE_S1_SIGMA0_L[d], TABLE_S1_YSEC_L[d]
        for r in _x_rows(red, 0.6, d):
            s0, ys = a0 * np.exp(b0 * r["L_over_r"]), a1 * np.exp(b1 * r["L_over_r"])
            mine = r["sigma0_N_per_mm"]
            out.append(f"| {d} | {r['L_mm']:g} | {r['L_over_r']:.2f} | {r['jammed']} | {_e(mine, '.4g')} | "
                       f"{s0:.4g} | {_e(mine and mine / s0, '.2f')} | {r['Y_sec_N_per_mm']:.4g} | "
                       f"{ys:.4g} | {r['Y_sec_N_per_mm'] / ys:.2f} |")  # fmt: skip
    return out


def _first(Ls: list[float], flags: list[bool]) -> float | None:
    return next((L for L, f in zip(Ls, flags, strict=True) if f), None)


def markers(red: Reduction) -> list[str]:
    k = 0.1
    curves = {(c.direction, c.L_mm): c for c in red.curves if c.series[0] == k}
    Ls = sorted(L for d, L in curves if d == "y")
    dip = [-float(np.min(curves["y", L].area_strain)) for L in Ls]
    # thickness strain of x pulls at small strain (the jammed regime): its minimum there
    shrink = []
    for L in Ls:
        c = curves["x", L]
        small = c.strain <= 0.02
        shrink.append(-float(np.min(c.thickness_strain[small])))
    out = ["| tolerance | area dip of y pulls deeper than it, from L (mm) | "
           "z-shrink of x pulls (ε ≤ 0.02) deeper than it, up to L (mm) |", "|---:|---:|---:|"]  # fmt: skip
    for tol in (1e-6, 1e-4, 1e-3, 2e-3, 3e-3):  # 1e-6: above the relaxations' noise
        last = [L for L, s in zip(Ls, shrink, strict=True) if s > tol]
        out.append(f"| {tol:g} | {_e(_first(Ls, [v > tol for v in dip]), 'g')} | "
                   f"{_e(max(last) if last else None, 'g')} |")  # fmt: skip
    pts = sorted((r for r in red.points if r["k_mN_per_mm2"] == k), key=lambda r: r["L_mm"])
    ratio = ratio_crossing([r["L_mm"] for r in pts], [r["force_ratio_xy"] for r in pts])
    gen = ratio_crossing([r["L_mm"] for r in pts], [r["generalised_force_ratio_xy"] for r in pts])
    peak = max(pts, key=lambda r: r["aspect_ratio"])["L_mm"]
    trans = {t["direction"]: t for t in red.transitions if t["k_mN_per_mm2"] == k}
    out += [
        "",
        "area dip depth by L: " + ", ".join(f"{L:g}: {v if v > 0 else 0.0:.1e}"
                                            for L, v in zip(Ls, dip, strict=True)),
        "z-shrink depth by L: " + ", ".join(f"{L:g}: {v if v > 0 else 0.0:.1e}"
                                            for L, v in zip(Ls, shrink, strict=True)),
        f"force ratio crosses 1: pair forces {_e(ratio, '.2f')} mm, generalised {_e(gen, '.2f')} mm; "
        f"aspect ratio a_y0/a_x0 peaks at L = {peak:g} mm",
        "; ".join(f"{d}: (L/r)_trans {t['L_over_r_trans']:.2f} (L = {t['L_trans_mm']:.2f} mm), linear "
                  f"jammed run {t['fit_L_lo_mm']:.1f}–{t['fit_L_hi_mm']:.1f} mm, gap at 11.1 mm "
                  f"{next(r['jamming_gap'] for r in _x_rows(red, k, d) if abs(r['L_mm'] - 11.1) < 1e-9):.2e} mJ"
                  for d, t in sorted(trans.items())),
    ]  # fmt: skip
    return out


def write_test_data(k01: Reduction, s4: list[Reduction], path: Path) -> None:
    """Gaps of every x series (and y at k = 0.1) and the k = 0.1 zero-force states at
    Table S3's L values: what tests/test_transitions.py and test_forces.py compare."""
    series = {}
    for red in [k01, *s4]:
        for t in red.transitions:
            d, k = t["direction"], t["k_mN_per_mm2"]
            if d == "x" or k == 0.1:
                rows = _x_rows(red, k, d)
                series[f"{d} {k:g}"] = {"direction": d, "k_mN_per_mm2": k,
                                        "L_mm": [r["L_mm"] for r in rows],
                                        "gap_mJ": [r["jamming_gap"] for r in rows]}  # fmt: skip
    states = {}
    for e in iter_entries(k01.path, with_data=True):
        L = round(float(e.meta["L_mm"]), 6)
        if e.kind == "points" and (L in TABLE_S3 or L == 10.5):
            states[f"{L:g}"] = [float(v) for v in e.record["x"][int(e.meta.get("winner", 0))]]
    data = {"about": "knitsweep results (converged preset, 4 starts) of jobs/paper_k0.1_L_sweep.toml "
            "and jobs/paper_table_s4.toml, written by benchmarks/compare_paper.py",
            "r_mm": 0.74, "series": series,
            "zero_force_states_k0.1": dict(sorted(states.items(), key=lambda kv: float(kv[0])))}  # fmt: skip
    path.write_text(json.dumps(data, indent=1) + "\n")


JOBS = {  # job name -> what it computes, in the order docs/paper.md lists them
    "paper_k0.1_L_sweep": "k = 0.1, x and y: Figs. 1b, 2, 3, 5, 6g-h, Table S3",
    "paper_table_s4": "x pulls at k = 0.2 … 2 (7 k): Table S4, Fig. 4a-b",
    "paper_table_s4_more": "x pulls at k = 0.8 … 1.7 (6 k): Table S4",
    "paper_table_s4_wide": "x pulls at k = 3, 4 to L = 16 mm: Table S4",
    "paper_table_s4_k0.001": "x pulls at k = 0.001 from L = 9.5 mm: Table S4's first row",
    "paper_table_s4_k0.001_paper_preset": "the same with the `paper` preset (SLSQP)",
    "paper_sigma0_k0.6": "Table 1 values, x and y: Table S1",
    "paper_table_s2_x": "Table S2's x rows, step 0.01 mm",
    "paper_table_s2_y": "Table S2's y rows with step 0.002 mm",
    "paper_table_s2_y_k1.5": "Table S2's y row with step 0.01 mm",
    "paper_packing_fraction": "k = 0.1, x and y, φ and states stored: SI Contact Volumes, "
                              "Figs. 6a-f, S11, Table S3 RMS",
    "paper_Btrans_adaptive": "(L/r)_trans against B at four k, adaptive: Fig. S6 (Fig. 4c)",
    "paper_sweeps_k": "Y_sec, σ0 against k at L = 12.2 mm: Fig. S5a-b",
    "paper_sweeps_B": "Y_sec, σ0 against B: Fig. S5c-d",
    "paper_sweeps_rcore": "Y_sec, σ0 against r_core: Fig. S5e-f",
    "paper_linear_regime_L10.7": "stress-strain at L = 10.7 mm over k: Disappearing Linear Elasticity",
    "paper_z_strain": "z strain to σ = 0.5 N/mm: Fig. S12",
    **compare_ansatz.JOBS,
}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--k01", type=Path, required=True)
    ap.add_argument("--s4", type=Path, nargs="*", default=[])
    ap.add_argument("--k06", type=Path)
    ap.add_argument("--s2", type=Path, nargs="*", default=[], help="the Table S2 jobs' files")
    ap.add_argument("--pf", type=Path, help="jobs/paper_packing_fraction.toml's file")
    ap.add_argument("--btrans", type=Path, help="jobs/paper_Btrans_adaptive.toml's file")
    ap.add_argument("--sweeps", type=Path, nargs="*", default=[],
                    help="the k, B and r_core sweeps' files (paper_sweeps_*.h5)")  # fmt: skip
    ap.add_argument("--linear", type=Path, help="jobs/paper_linear_regime_L10.7.toml's file")
    ap.add_argument("--zstrain", type=Path, help="jobs/paper_z_strain.toml's file")
    ap.add_argument(
        "--k0001-paper", type=Path, help="jobs/paper_table_s4_k0.001_paper_preset.toml's file"
    )
    ap.add_argument("--ansatz", type=Path, nargs=2, default=[],
                    help="jobs/ansatz_vs_free.toml's and jobs/ansatz_vs_free_curves.toml's files")  # fmt: skip
    ap.add_argument("--markdown", type=Path, help="also write the whole comparison here")
    ap.add_argument("--test-data", type=Path)
    a = ap.parse_args()
    red = {p: reduce_results(p) for p in [a.k01, *a.s4, a.k06, *a.s2, a.pf, a.btrans, *a.sweeps,
                                          a.linear, a.zstrain, a.k0001_paper, *a.ansatz]
           if p is not None}  # fmt: skip
    k01, s4 = red[a.k01], [red[p] for p in a.s4]
    doc = paper_doc.document(a, red, JOBS, sys.modules[__name__])
    print("\n".join(doc))
    if a.markdown:
        a.markdown.write_text("\n".join(doc) + "\n")
        print(f"\nwrote {a.markdown}")
    if a.test_data:
        write_test_data(k01, s4, a.test_data)
        print(f"\nwrote {a.test_data}")


if __name__ == "__main__":
    main()
