"""The SI comparisons of ``benchmarks/compare_paper.py``: Table S4's fit window, Tables
S2 and S3's RMS columns, contact forces along the L = 10.5 mm sweeps, the packing
fraction, (L/r)_trans against B, Y_sec and σ0 against k, B and r_core, the disappearing
linear regime at L = 10.7 mm and the z strain over the full range of motion. Each
function takes reductions of the shipped jobs' files and returns markdown lines.
"""

from __future__ import annotations

from datetime import datetime

import numpy as np

from knitsweep.analysis import GAP_THRESHOLD, fit_line
from knitsweep.analysis.paper import (
    PHI_END_OF_JAMMING,
    PHI_END_STRAINS_L10_5,
    TABLE_S2,
    TABLE_S3_RMS_N,
    TABLE_S4,
)
from knitsweep.analysis.transitions import linear_jammed_run
from knitsweep.analysis.volumes import voxel_volumes
from knitsweep.config import StitchParams
from knitsweep.model import CellModel
from knitsweep.report.fig_forces import (
    LINEAR_ELASTIC_SIGN,
    pair_forces_along,
    same_row_z_rms,
    sweeps_with_states,
)
from knitsweep.report.fig_volumes import crossing
from knitsweep.report.reduce import Reduction
from knitsweep.stitches import TRANSLATION_CLASSES as CONTACT_CLASSES
from knitsweep.store.read import iter_entries, read_root


def _e(v, spec: str = ".3e") -> str:
    return "–" if v is None else format(v, spec)


def run_seconds(red: Reduction) -> float | None:
    """Wall seconds of the file's last run (its root started_at → finished_at)."""
    root = read_root(red.path)
    try:
        a, b = (datetime.fromisoformat(str(root[k])) for k in ("started_at", "finished_at"))
    except (KeyError, ValueError):
        return None
    return (b - a).total_seconds()


def jobs_table(reds: dict[str, Reduction], what: dict[str, str]) -> list[str]:
    out = ["| job (`jobs/…`) | what it computes | points | sweeps | run time (`mpirun -n 3`, 2 cores) |",
           "|---|---|---:|---:|---:|"]  # fmt: skip
    for name, red in reds.items():
        s = run_seconds(red)
        n_pts, n_sw = len(red.points), len(red.sweeps)
        out.append(f"| `{name}.toml` | {what.get(name, '')} | {n_pts} | {n_sw} | "
                   f"{_e(s and s / 60, '.1f')} min |")  # fmt: skip
    return out


def _jammed_below(red: Reduction, k: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = next(t for t in red.transitions if t["direction"] == "x" and t["k_mN_per_mm2"] == k)
    rows = sorted((r for r in red.sweeps if r["direction"] == "x" and r["k_mN_per_mm2"] == k
                   and r["jammed"] and (t["L_over_r_trans"] is None
                                        or r["L_over_r"] < t["L_over_r_trans"])),
                  key=lambda r: r["L_mm"])  # fmt: skip
    return (np.array([r["L_mm"] for r in rows]), np.array([r["L_over_r"] for r in rows]),
            np.array([r["delta_E_c"] for r in rows]))  # fmt: skip


TOLERANCES = (2.5e-5, GAP_THRESHOLD, 1e-4, 2e-4)


def _window_cell(L: np.ndarray, g: np.ndarray, sl: slice, paper_slope: float) -> str:
    if sl.stop - sl.start < 2:
        return "–"
    f = fit_line(L[sl], g[sl])
    zero = -f.intercept / f.slope if f.slope else None
    return f"{f.slope / paper_slope:.2f}, {_e(zero, '.2f')} ({sl.stop - sl.start})"


def fit_window(reds: list[Reduction]) -> list[str]:
    """Table S4's slope and zero against the tolerance of the linear run, and for the
    first 4 and 8 jammed points and every jammed point."""
    head = " | ".join(f"tol {t:.1e}: slope ÷ paper, zero (mm)" for t in TOLERANCES)
    out = [
        f"| k | {head} | first 4 points | first 8 | every jammed point |",
        "|---:|" + "---|" * (len(TOLERANCES) + 3),
    ]
    seen = set()
    for red in reds:
        for k in sorted({t["k_mN_per_mm2"] for t in red.transitions if t["direction"] == "x"}):
            if k in seen or k not in TABLE_S4:
                continue
            seen.add(k)
            L, x, g = _jammed_below(red, k)
            if len(L) < 2:
                continue
            slices = [linear_jammed_run(x, g, t) for t in TOLERANCES]
            slices += [slice(0, min(4, len(L))), slice(0, min(8, len(L))), slice(0, len(L))]
            cells = [_window_cell(L, g, sl, TABLE_S4[k].slope_mJ_per_mm) for sl in slices]
            out.append(f"| {k:g} | " + " | ".join(cells) + " |")
    return out


def k0001(red: Reduction, paper_preset: Reduction | None = None) -> list[str]:
    """The k = 0.001 series: both gaps against L, and lines through each, beside the
    paper's Table S4 row (and the series computed with the ``paper`` preset)."""
    rows = sorted((r for r in red.sweeps if r["direction"] == "x"), key=lambda r: r["L_mm"])
    other = {} if paper_preset is None else {round(r["L_mm"], 6): r for r in paper_preset.sweeps
                                             if r["direction"] == "x"}  # fmt: skip
    p = TABLE_S4[0.001]
    out = ["| L (mm) | ΔE_c (mJ) | ΔE_b (mJ) | ΔE_c, `paper` preset | paper's line (mJ) |",
           "|---:|---:|---:|---:|---:|"]  # fmt: skip
    for r in rows:
        o = other.get(round(r["L_mm"], 6))
        out.append(f"| {r['L_mm']:.1f} | {r['delta_E_c']:.3e} | {r['delta_E_b']:.3e} | "
                   f"{_e(o and o['delta_E_c'])} | "
                   f"{max(0.0, p.intercept_mJ + p.slope_mJ_per_mm * r['L_mm']):.3e} |")  # fmt: skip
    zeta = {}
    for e in iter_entries(red.path, with_data=True):
        if e.kind == "points" and e.meta.get("status") == "done":
            zeta[float(e.meta["L_mm"])] = float(e.record["min_zeta"][int(e.meta["winner"])])
    both = [abs(r["delta_E_c"] - other[round(r["L_mm"], 6)]["delta_E_c"]) for r in rows
            if round(r["L_mm"], 6) in other]  # fmt: skip
    if both:
        out.append(f"\nlargest |ΔE_c(converged) − ΔE_c(paper preset)|: {max(both):.1e} mJ")
    if zeta:
        out.append(f"\nsmallest compression ζ of the zero-force states: {min(zeta.values()):.1e}–"
                   f"{max(zeta.values()):.1e} (ζ = 0: the hard cores touch)")  # fmt: skip
    L = np.array([r["L_mm"] for r in rows])
    for name in ("delta_E_c", "delta_E_b"):
        g = np.array([r[name] for r in rows])
        sl = linear_jammed_run(L / 0.74, g, GAP_THRESHOLD)
        if sl.stop - sl.start >= 2:
            f = fit_line(L[sl], g[sl])
            out.append(f"\n{name}: linear run {L[sl][0]:.1f}–{L[sl][-1]:.1f} mm, slope "
                       f"{f.slope:.3e} mJ/mm ({f.slope / p.slope_mJ_per_mm:.2f}× the paper's), "
                       f"zero at {-f.intercept / f.slope:.2f} mm (paper {p.zero_L_mm:.2f})")  # fmt: skip
    return out


def table_s2(reds: list[Reduction]) -> list[str]:
    """RMS (mJ) of a line through E_c(ε) over the first points up to Table S2's ε_final."""
    out = ["| direction | k | L (mm) | step (mm) | ε_final | points | RMS (mJ) | paper RMS | "
           "RMS of a parabola (mJ) |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]  # fmt: skip
    for row in TABLE_S2:
        e = None
        for red in reds:
            for ent in red.entries:
                m = ent.meta
                if (ent.kind == "sweeps" and m.get("direction") == row.direction
                        and abs(m["k_mN_per_mm2"] - row.k_mN_per_mm2) < 1e-12
                        and abs(m["L_mm"] - row.L_mm) < 1e-9):  # fmt: skip
                    e = ent
        if e is None:
            out.append(f"| {row.direction} | {row.k_mN_per_mm2:g} | {row.L_mm:g} | – | – | – | – | "
                       f"{row.rms_mJ:.2e} | – |")  # fmt: skip
            continue
        strain = np.asarray(e.record["strain"], dtype=float)
        ec = np.asarray(e.record["contact_energy"], dtype=float)
        keep = strain <= row.strain_final + 1e-9
        f = fit_line(strain[keep], ec[keep])
        quad = np.polyval(np.polyfit(strain[keep], ec[keep], 2), strain[keep]) - ec[keep]
        out.append(f"| {row.direction} | {row.k_mN_per_mm2:g} | {row.L_mm:g} | {row.step_mm:g} | "
                   f"{strain[keep][-1]:.3f} | {int(keep.sum())} | {np.sqrt(f.mse):.2e} | "
                   f"{row.rms_mJ:.2e} | {np.sqrt(np.mean(quad**2)):.1e} |")  # fmt: skip
    return out


def table_s3_rms(red: Reduction) -> list[str]:
    rms = same_row_z_rms(red)
    out = ["| L (mm) | RMS (N), first 20 steps of the y pull | paper |", "|---:|---:|---:|"]
    for L, v in rms.items():
        out.append(f"| {L:.1f} | {v:.2e} | {_e(TABLE_S3_RMS_N.get(L), '.2e')} |")
    both = [L for L in rms if L in TABLE_S3_RMS_N]
    if both:
        out.append(f"\nmean over Table S3's L values present ({len(both)}): "
                   f"{np.mean([rms[L] for L in both]):.2e} N; the paper's over its rows: "
                   f"{np.mean(list(TABLE_S3_RMS_N.values())):.2e} N (it states 2.24e-05 N)")  # fmt: skip
    return out


def forces_along(red: Reduction, L_mm: float = 10.5) -> list[str]:
    """Pair forces by class (paper sign: + assists linear elasticity) at the first and
    last step of the L = 10.5 mm sweeps."""
    out = ["| pulled | class | F_x at ε = 0 → end (N) | F_y | F_z | end strain |",
           "|---|---|---|---|---|---:|"]  # fmt: skip
    for e in sweeps_with_states(red):
        paper = e.meta.get("stitch", "stockinette") == "stockinette"  # (a pattern's classes differ)
        if abs(float(e.meta["L_mm"]) - L_mm) > 1e-9 or not paper:
            continue
        d = e.meta["direction"]
        strain, f = pair_forces_along(red, e)
        f = f * LINEAR_ELASTIC_SIGN[d][None, None, :]
        for j, cls in enumerate(CONTACT_CLASSES[:4]):
            cells = [f"{f[0, j, a]:+.3f} → {f[-1, j, a]:+.3f}" for a in range(3)]
            out.append(f"| {d} | {cls} | " + " | ".join(cells) + f" | {strain[-1]:.3f} |")
    return out


def packing_fraction(red: Reduction, voxel_at: tuple[float, ...] = (10.5, 11.5, 12.2),
                     voxel_mm: float = 0.04) -> list[str]:  # fmt: skip
    """φ at zero force against L (tube estimator, and voxels at a few L), where it falls
    through 0.85, and where it does along the L = 10.5 mm sweeps."""
    pts = sorted((r for r in red.points if r.get("packing_fraction") is not None),
                 key=lambda r: r["L_mm"])  # fmt: skip
    states = {}
    for e in iter_entries(red.path, with_data=True):
        if e.kind == "points" and round(float(e.meta["L_mm"]), 6) in voxel_at:
            states[round(float(e.meta["L_mm"]), 6)] = (
                np.asarray(e.record["x"][int(e.meta["winner"])], dtype=float),
                e.meta,
            )
    trans = {t["direction"]: t for t in red.transitions}
    out = [f"| L (mm) | L/r | φ (tube QMC) | ± | φ (voxels, l = {voxel_mm:g} mm) | jammed in x | in y |",
           "|---:|---:|---:|---:|---:|---|---|"]  # fmt: skip
    for r in pts:
        vox = "–"
        if round(r["L_mm"], 6) in states:
            x, meta = states[round(r["L_mm"], 6)]
            cp = CellModel(StitchParams.from_flat(meta)).control_points(x)
            vox = f"{voxel_volumes(cp, x[-2], x[-1], meta['r_mm'], voxel_mm).phi:.4f}"
        jam = {d: (trans[d]["L_over_r_trans"] is None or r["L_over_r"] < trans[d]["L_over_r_trans"])
               for d in "xy" if d in trans}  # fmt: skip
        out.append(f"| {r['L_mm']:.1f} | {r['L_over_r']:.2f} | {r['packing_fraction']:.4f} | "
                   f"{r['packing_fraction_error']:.1e} | {vox} | {jam.get('x')} | {jam.get('y')} |")  # fmt: skip
    at = crossing(
        [r["L_mm"] for r in pts], [r["packing_fraction"] for r in pts], PHI_END_OF_JAMMING
    )
    out.append(f"\nφ falls through {PHI_END_OF_JAMMING:g} at L = {_e(at, '.2f')} mm at zero force; "
               + "; ".join(f"(L/r)_trans in {d}: {t['L_over_r_trans']:.2f} (L = {t['L_trans_mm']:.2f} mm)"
                           for d, t in sorted(trans.items()) if t["L_over_r_trans"]))  # fmt: skip
    for c in sorted(red.curves, key=lambda c: (c.direction, c.L_mm)):
        if abs(c.L_mm - 10.5) < 1e-9 and c.packing_fraction is not None:
            eps = crossing(c.strain, c.packing_fraction, PHI_END_OF_JAMMING)
            jumps = np.abs(np.diff(c.packing_fraction))
            out.append(f"\nL = 10.5 mm pulled in {c.direction}: φ = {c.packing_fraction[0]:.4f} at "
                       f"zero strain, {c.packing_fraction[-1]:.4f} at ε = {c.strain[-1]:.3f}; falls "
                       f"through {PHI_END_OF_JAMMING:g} at ε = {_e(eps, '.3f')} (paper "
                       f"{PHI_END_STRAINS_L10_5[c.direction]:g}); largest change between steps "
                       f"{jumps.max():.1e}, median {np.median(jumps):.1e}")  # fmt: skip
    return out


def b_dependence(red: Reduction) -> list[str]:
    """(L/r)_trans against B per k and direction (adaptive brackets)."""
    out = ["| direction | k | " + " | ".join(f"B = {b:g}" for b in (45, 90, 180, 360))
           + " | change 45 → 360 |", "|---|---:|---:|---:|---:|---:|---:|"]  # fmt: skip
    for d in "xy":
        for k in sorted({t["k_mN_per_mm2"] for t in red.transitions}):
            vals = {t["B_mN_mm2"]: t["L_over_r_trans"] for t in red.transitions
                    if t["direction"] == d and t["k_mN_per_mm2"] == k}  # fmt: skip
            cells = [_e(vals.get(b), ".3f") for b in (45.0, 90.0, 180.0, 360.0)]
            ch = (vals[360.0] - vals[45.0]) if vals.get(360.0) and vals.get(45.0) else None
            out.append(f"| {d} | {k:g} | " + " | ".join(cells) + f" | {_e(ch, '+.2f')} |")
    return out


def b_summary(red: Reduction) -> list[str]:
    """One sentence per k: the change of (L/r)_trans from B = 45 to 360 in x and y and the
    gap between the directions at both ends."""
    out = []
    for k in sorted({t["k_mN_per_mm2"] for t in red.transitions}):
        v = {(t["direction"], t["B_mN_mm2"]): t["L_over_r_trans"] for t in red.transitions
             if t["k_mN_per_mm2"] == k}  # fmt: skip
        parts = []
        for b in (45.0, 360.0):
            if v.get(("x", b)) and v.get(("y", b)):
                parts.append(f"y − x = {v['y', b] - v['x', b]:+.2f} at B = {b:g}")
        dx = (v["x", 360.0] - v["x", 45.0]) if v.get(("x", 360.0)) and v.get(("x", 45.0)) else None
        out.append(f"* k = {k:g}: x changes by {_e(dx, '+.2f')} in L/r from B = 45 to 360; "
                   + ("; ".join(parts) or "a direction without a transition in range"))  # fmt: skip
    return [
        "The paper calls (L/r)_trans in x nearly constant in B. knitsweep's falls with B at "
        "every k, and the y transition falls faster, so a stiffer yarn closes the gap "
        "between the directions, as the paper says:",
        "",
        *out,
    ]


def metric_sweep(red: Reduction, param: str, unit: str) -> list[str]:
    """Y_sec and σ0 of x and y pulls against one parameter."""
    out = [f"| {param} ({unit}) | Y_sec x (N/mm) | σ0 x | jammed x | Y_sec y | σ0 y | jammed y |",
           "|---:|---:|---:|---|---:|---:|---|"]  # fmt: skip
    by = {}
    for r in red.sweeps:
        by.setdefault(r[param], {})[r["direction"]] = r
    for v in sorted(by):
        cells = []
        for d in "xy":
            r = by[v].get(d, {})
            cells += [_e(r.get("Y_sec_N_per_mm"), ".4g"), _e(r.get("sigma0_N_per_mm"), ".4g"),
                      str(r.get("jammed", "–"))]  # fmt: skip
        out.append(f"| {v:g} | " + " | ".join(cells) + " |")
    return out


def linear_regime(red: Reduction) -> list[str]:
    out = ["| k | Y_sec (N/mm) | σ0 (N/mm) | softened window (strain) | linear regime | why not |",
           "|---:|---:|---:|---|---|---|"]  # fmt: skip
    for r in sorted(red.sweeps, key=lambda r: r["k_mN_per_mm2"]):
        win = (f"{r['sigma0_window_lo']:.3f}–{r['sigma0_window_hi']:.3f}"
               if r["sigma0_window_lo"] is not None else "–")  # fmt: skip
        out.append(f"| {r['k_mN_per_mm2']:g} | {_e(r['Y_sec_N_per_mm'], '.4g')} | "
                   f"{_e(r['sigma0_N_per_mm'], '.4g')} | {win} | {r['has_linear_regime']} | "
                   f"{r['sigma0_reason'] or '–'} |")  # fmt: skip
    return out


def z_strain(red: Reduction) -> list[str]:
    """Thickness (z) strain over the whole sweep: its largest value past zero strain
    (an expansion if > 0), its smallest, and where it last is ≥ 0."""
    out = ["| pulled | L (mm) | k | jammed | max z strain, ε > 0 (at ε) | min z strain (at ε) | "
           "last ε with z strain ≥ 0 | end ε |", "|---|---:|---:|---|---|---|---:|---:|"]  # fmt: skip
    for c in sorted(red.curves, key=lambda c: (c.direction, c.series[0], c.L_mm)):
        z, e = c.thickness_strain[1:], c.strain[1:]
        i, j = int(np.argmax(z)), int(np.argmin(z))
        up = np.flatnonzero(z >= 0.0)
        last = f"{e[up[-1]]:.3f}" if up.size else "never (shrinks from the first step)"
        out.append(f"| {c.direction} | {c.L_mm:g} | {c.series[0]:g} | {c.jammed} | "
                   f"{z[i]:+.2e} ({e[i]:.3f}) | {z[j]:+.2e} ({e[j]:.3f}) | {last} | {e[-1]:.3f} |")  # fmt: skip
    return out
