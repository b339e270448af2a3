"""docs/paper.md's section on how far the paper's 30-number ansatz moves the unjamming
transition (issue 34): (L/r)_trans of the ansatz (stitch ``stockinette``) against the free
periodic yarn that contains it (``stockinette_free``, docs/model.md §11) at four k in x and
y, and Y_sec and σ0 of both at three L, from the files of ``jobs/ansatz_vs_free.toml``
(adaptive) and ``jobs/ansatz_vs_free_curves.toml`` (whole curves).

``compare_paper.py --ansatz A.h5 C.h5`` puts the section into the whole document; this
script alone rewrites it (and its two rows of the jobs table) in place::

    python benchmarks/compare_ansatz.py ansatz_vs_free.h5 ansatz_vs_free_curves.h5 \
        --markdown docs/paper.md
"""

from __future__ import annotations

import argparse
from pathlib import Path

import compare_paper_si as si

from knitsweep.report.reduce import Reduction, reduce_results

HEADING = "## The ansatz against the free yarn: how far the 30-number state moves the transition"
JOBS = {
    "ansatz_vs_free": "the ansatz and the free stockinette yarn at k = 0.1, 0.5, 1, 2, x and y, "
    "adaptive: (L/r)_trans",
    "ansatz_vs_free_curves": "the same two at three L, whole curves: Y_sec and σ0",
}
ANSATZ, FREE = "stockinette", "stockinette_free"
NEXT = "## Table S1"  # the section goes before it, after Table S4 and its subsections


def _f(v: float | None, spec: str) -> str:
    return "–" if v is None else format(v, spec)


def _trans(red: Reduction) -> dict[tuple[str, float, str], dict]:
    return {(t["stitch"], t["k_mN_per_mm2"], t["direction"]): t for t in red.transitions}


def _bracket(t: dict | None) -> str:
    if t is None or t["status"] != "transition":
        return "–" if t is None else str(t["status"])
    return f"{t['L_over_r_trans']:.3f} [{t['bracket_lower']:.3f}]"


def transition_table(red: Reduction) -> tuple[list[str], dict[str, list[float]]]:
    """The (L/r)_trans table and each direction's shifts (free − ansatz)."""
    trans = _trans(red)
    ks = sorted({k for _, k, _ in trans})
    out = ["| k (mN/mm²) | pulled | ansatz (L/r)_trans [last jammed] | free yarn | free − ansatz | "
           "± (both brackets) | L_trans ansatz → free (mm) |",
           "|---:|---|---:|---:|---:|---:|---|"]  # fmt: skip
    shifts: dict[str, list[float]] = {"x": [], "y": []}
    for k in ks:
        for d in ("x", "y"):
            a, f = trans.get((ANSATZ, k, d)), trans.get((FREE, k, d))
            both = a is not None and f is not None and "transition" == a["status"] == f["status"]
            shift = f["L_over_r_trans"] - a["L_over_r_trans"] if both else None
            err = (sum(t["L_over_r_trans"] - t["bracket_lower"] for t in (a, f)) if both
                   else None)  # fmt: skip
            if shift is not None:
                shifts[d].append(shift)
            mm = f"{a['L_trans_mm']:.3f} → {f['L_trans_mm']:.3f}" if both else "–"
            out.append(f"| {k:g} | {d} | {_bracket(a)} | {_bracket(f)} | {_f(shift, '+.3f')} | "
                       f"{_f(err, '.3f')} | {mm} |")  # fmt: skip
    return out, shifts


def mechanics_table(red: Reduction) -> tuple[list[str], dict[str, list[float]]]:
    """Y_sec and σ0 of both at each (k, L, direction), and the ratios free/ansatz."""
    rows = {(r["stitch"], r["k_mN_per_mm2"], r["L_mm"], r["direction"]): r for r in red.sweeps}
    keys = sorted({(k, L, d) for _, k, L, d in rows})
    out = ["| k (mN/mm²) | L (mm) | pulled | Y_sec ansatz (N/mm) | Y_sec free | free ÷ ansatz | "
           "σ0 ansatz (N/mm) | σ0 free | jammed over the whole curve (ansatz, free) |",
           "|---:|---:|---|---:|---:|---:|---:|---:|---|"]  # fmt: skip
    ratios: dict[str, list[float]] = {"x": [], "y": []}
    for k, L, d in keys:
        a, f = rows.get((ANSATZ, k, L, d)), rows.get((FREE, k, L, d))
        if a is None or f is None:
            continue
        ya, yf = a["Y_sec_N_per_mm"], f["Y_sec_N_per_mm"]
        ratio = yf / ya if ya and yf is not None else None
        if ratio is not None:
            ratios[d].append(ratio)
        out.append(f"| {k:g} | {L:g} | {d} | {_f(ya, '.4g')} | {_f(yf, '.4g')} | "
                   f"{_f(ratio, '.2f')} | {_f(a['sigma0_N_per_mm'], '.3g')} | "
                   f"{_f(f['sigma0_N_per_mm'], '.3g')} | {a['jammed']}, {f['jammed']} |")  # fmt: skip
    return out, ratios


def _restarts(red: Reduction) -> list[str]:
    """Points whose zero-force state a sweep replaced by a lower minimum (docs/model.md §8)."""
    return [f"{p['stitch']} at L = {p['L_mm']:g} mm, k = {p['k_mN_per_mm2']:g} "
            f"({p['rest_found_by']}, {p['rest_fall_mJ']:.2g} mJ lower)"
            for p in red.points if p.get("rest_found_by")]  # fmt: skip


def _span(v: list[float], spec: str) -> str:
    return f"{format(min(v), spec)} to {format(max(v), spec)}" if v else "–"


def section(adaptive: Reduction, curves: Reduction) -> list[str]:
    """The markdown lines of the section (its heading first)."""
    ttab, shifts = transition_table(adaptive)
    mtab, ratios = mechanics_table(curves)
    found = _restarts(adaptive) + _restarts(curves)
    d = [
        HEADING,
        "",
        "The paper's state is an ansatz: 30 numbers build both strands of a crossover around one "
        "frame and make the two crossovers mirror images. knitsweep's free periodic yarn "
        "(`stockinette_free`, docs/model.md §11) frees every control point of the same 8 "
        "quintic segments, with G2 at every joint, and contains the ansatz exactly; the "
        "patterns are built on it. Both with the same protocol (`converged`, 2 starts carried "
        "along each series, sweeps that stop once they know Y_sec and both gaps; "
        "`jobs/ansatz_vs_free.toml`, adaptive to 0.02 mm):",
        "",
        *ttab,
        "",
        f"Freeing the yarn moves (L/r)_trans by {_span(shifts['x'], '+.2f')} in x and "
        f"{_span(shifts['y'], '+.2f')} in y over these k (the brackets: the last column but "
        "one). Beside Table S4 this is the representation's share of a transition: the paper's "
        "(L/r)_trans are the ansatz's.",
        "",
        "Y_sec and σ0 over whole curves (`jobs/ansatz_vs_free_curves.toml`, the same starts):",
        "",
        *mtab,
        "",
        f"The free yarn's Y_sec is {_span(ratios['x'], '.2f')}× the ansatz's in x and "
        f"{_span(ratios['y'], '.2f')}× in y at these points.",
        "",
    ]
    if found:
        d += ["Zero-force states that a sweep replaced by a lower minimum it found (a sweep that "
              "falls below its zero-force energy by more than 5·10⁻⁶ mJ relaxes again from "
              "there and starts over): " + "; ".join(found) + ".", ""]  # fmt: skip
    return d


def _jobs_rows(reds: dict[str, Reduction]) -> list[str]:
    return si.jobs_table(reds, JOBS)[2:]  # without its header


def write_in_place(path: Path, lines: list[str], job_rows: list[str]) -> None:
    """Replace the section (or insert it before ``NEXT``) and the jobs' rows of the jobs
    table (after its last row) in the markdown file ``path``."""
    text = path.read_text().split("\n")
    text = [t for t in text if not any(t.startswith(f"| `{n}.toml`") for n in JOBS)]
    last_job = max(i for i, t in enumerate(text) if t.startswith("| `paper_"))
    text[last_job + 1 : last_job + 1] = job_rows
    if HEADING in text:
        start = text.index(HEADING)
        end = next(i for i in range(start + 1, len(text)) if text[i].startswith("## "))
    else:
        start = end = next(i for i, t in enumerate(text) if t.startswith(NEXT))
    text[start:end] = lines
    path.write_text("\n".join(text))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("adaptive", type=Path, help="jobs/ansatz_vs_free.toml's file")
    ap.add_argument("curves", type=Path, help="jobs/ansatz_vs_free_curves.toml's file")
    ap.add_argument(
        "--markdown", type=Path, help="rewrite the section in this file (docs/paper.md)"
    )
    a = ap.parse_args()
    adaptive, curves = reduce_results(a.adaptive), reduce_results(a.curves)
    lines = section(adaptive, curves)
    print("\n".join(lines))
    if a.markdown:
        write_in_place(a.markdown, lines, _jobs_rows({"ansatz_vs_free": adaptive,
                                                      "ansatz_vs_free_curves": curves}))  # fmt: skip
        print(f"\nwrote {a.markdown}")


if __name__ == "__main__":
    main()
