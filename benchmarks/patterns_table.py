"""The patterns table of docs/patterns.md (prints markdown) from a results file of
``jobs/patterns_k0.1.toml``: per stitch, (L/r)_trans in x and y (or why there is none),
their shift against the free stockinette yarn (the patterns' own representation), and the
zero-force shape, fabric thickness, energy and Y_sec at one L::

    python benchmarks/patterns_table.py patterns_k0.1.h5 --L 11.7
"""

from __future__ import annotations

import argparse
from pathlib import Path

from knitsweep.report.reduce import reduce_results
from knitsweep.stitches import STITCH_NAMES


def _trans(t: dict | None) -> str:
    if t is None:
        return "–"
    if t["status"] == "transition":
        return f"{t['L_over_r_trans']:.3f}"
    if t["status"] == "unjammed_at_start":
        return f"unjammed from {t['L_over_r_trans']:.2f} (L = {t['L_trans_mm']:g} mm) on"
    return str(t["status"]).replace("_", " ")


def _shift(t: dict | None, field: str) -> str:
    return "–" if t is None or t.get(field) is None else f"{t[field]:+.3f}"


def table(path: Path, L: float) -> list[str]:
    red = reduce_results(path)
    trans = {(t["stitch"], t["direction"]): t for t in red.transitions}
    points = {p["stitch"]: p for p in red.points if p["L_mm"] == L and p["status"] == "done"}
    ysec = {(s["stitch"], s["direction"]): s["Y_sec_N_per_mm"] for s in red.sweeps
            if s["L_mm"] == L}  # fmt: skip
    out = ["| pattern | (L/r)_trans x | (L/r)_trans y | x, y against the free yarn | "
           "x, y against the ansatz | a_x, a_y (mm) | a_y/a_x | thickness (mm) | E (mJ) | "
           "Y_sec x, y (N/mm) |", "|---|---:|---:|---|---|---|---:|---:|---:|---|"]  # fmt: skip
    for stitch in [s for s in STITCH_NAMES if any(k[0] == s for k in trans)]:
        tx, ty = trans.get((stitch, "x")), trans.get((stitch, "y"))
        p = points.get(stitch)
        shape = ("–",) * 4 if p is None else (
            f"{p['a_x0_mm']:.3f}, {p['a_y0_mm']:.3f}", f"{p['aspect_ratio']:.2f}",
            f"{p['thickness0_mm']:.2f}", f"{p['E_b_rest_mJ'] + p['E_c_rest_mJ']:.4f}")  # fmt: skip
        y = ", ".join("–" if ysec.get((stitch, d)) is None else f"{ysec[(stitch, d)]:.3f}"
                      for d in ("x", "y"))  # fmt: skip
        out.append(f"| {stitch} | {_trans(tx)} | {_trans(ty)} | {_shift(tx, 'shift_vs_free')}, "
                   f"{_shift(ty, 'shift_vs_free')} | {_shift(tx, 'shift_vs_ansatz')}, "
                   f"{_shift(ty, 'shift_vs_ansatz')} | {' | '.join(shape)} | {y} |")  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path, help="jobs/patterns_k0.1.toml's results file")
    ap.add_argument("--L", type=float, default=11.7, help="the L (mm) of the shapes and moduli")
    a = ap.parse_args()
    print("\n".join(table(a.results, a.L)))


if __name__ == "__main__":
    main()
