"""Contact volumes of one stitch: the paper's voxel method against voxel size, beside
the quasi-Monte-Carlo estimator over the tube (prints figures, draws one).

The paper's SI figure "volume against voxel side" (L = 12.2 mm, k = 0.1 mN/mm², zero
force): V_total = V_uncomp − V_comp/2 by voxels of side l = 0.2 … 0.02 mm, each at
``--phases`` lattice phases (random shifts of the lattice by a fraction of a voxel:
the spread is the voxel method's discretisation error, which the paper's single
lattice does not show), and by scrambled Sobol points over the tube at 2^10 … 2^16
points per scramble, 8 scrambles (mean ± one standard error). Times are medians of
``--repeat`` runs (time.perf_counter, one process).

Run: ``python benchmarks/bench_volumes.py [--L 12.2] [--k 0.1] [--out docs/volume_vs_voxel.png]``
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from knitsweep.analysis.volumes import qmc_volumes, voxel_volumes
from knitsweep.config import StitchParams
from knitsweep.model import CellModel
from knitsweep.relax.zero_force import zero_force

SIDES = (0.2, 0.15, 0.1, 0.08, 0.06, 0.05, 0.04, 0.03, 0.025, 0.02)
SAMPLES = tuple(1 << n for n in range(10, 17, 2))


def _timed(fn, repeat: int):
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return out, statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--L", type=float, default=12.2)
    ap.add_argument("--k", type=float, default=0.1)
    ap.add_argument("--phases", type=int, default=4)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path("docs/volume_vs_voxel.png"))
    a = ap.parse_args()
    params = StitchParams(L_mm=a.L, k_mN_per_mm2=a.k)
    zf = zero_force(params)
    x = zf.best.x
    cp = CellModel(params).control_points(x)
    ax, ay, r = float(x[-2]), float(x[-1]), params.r_mm
    print(
        f"zero-force stitch L = {a.L:g} mm, k = {a.k:g} mN/mm²: a_x = {ax:.4f}, a_y = {ay:.4f} mm\n"
    )
    rng = np.random.default_rng(1)
    print(
        "| voxel side l (mm) | V_total (mm³), lattice phase 0 | spread over phases (min–max) | "
        "V_uncomp | V_comp | φ | s per estimate |"
    )
    print("|---:|---:|---|---:|---:|---:|---:|")
    voxel_rows = []
    for side in SIDES:
        v0, sec = _timed(
            lambda s=side: voxel_volumes(cp, ax, ay, r, s), 1 if side < 0.04 else a.repeat
        )
        others = [voxel_volumes(cp, ax, ay, r, side, offset=tuple(rng.random(3))).V_total
                  for _ in range(a.phases - 1)]  # fmt: skip
        allv = [v0.V_total, *others]
        voxel_rows.append((side, allv, v0))
        print(
            f"| {side:g} | {v0.V_total:.4f} | {min(allv):.4f}–{max(allv):.4f} | {v0.V_uncomp:.4f} | "
            f"{v0.V_comp:.4f} | {v0.phi:.4f} | {sec:.2f} |"
        )
    print(
        "\n| Sobol points per scramble (× 8) | V_total (mm³) | standard error | φ | ± | s per estimate |"
    )
    print("|---:|---:|---:|---:|---:|---:|")
    qmc_rows = []
    for n in SAMPLES:
        q, sec = _timed(lambda n=n: qmc_volumes(cp, ax, ay, r, samples=n), a.repeat)
        qmc_rows.append((n, q))
        print(
            f"| {n} | {q.V_total:.4f} | {q.V_total_error:.1e} | {q.phi:.5f} | {q.phi_error:.1e} | {sec:.2f} |"
        )
    best = qmc_rows[-1][1]
    fine = voxel_rows[-1][2]
    print(
        f"\nvoxels at l = {SIDES[-1]:g} mm minus the tube estimate: V_uncomp {fine.V_uncomp - best.V_uncomp:+.4f}, "
        f"V_comp {fine.V_comp - best.V_comp:+.4f}, V_total {fine.V_total - best.V_total:+.4f} mm³ "
        f"(φ {fine.phi - best.phi:+.4f}): the voxel method's end caps (module docstring)"
    )
    _figure(a, voxel_rows, qmc_rows)
    print(f"wrote {a.out}")


def _figure(a, voxel_rows, qmc_rows) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 4.2), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    for side, allv, v0 in voxel_rows:
        ax.plot([side] * len(allv), allv, "o", color="0.6", ms=4, mfc="none")
        ax.plot(side, v0.V_total, "o", color="C0", ms=5)
    q = qmc_rows[-1][1]
    ax.axhspan(
        q.V_total - 2 * q.V_total_error, q.V_total + 2 * q.V_total_error, color="C3", alpha=0.3
    )
    ax.axhline(q.V_total, color="C3", lw=1, label=f"tube QMC, {int(q.resolution)} × 8 points (±2σ)")
    ax.plot([], [], "o", color="C0", label="voxels, lattice at the box corner (the paper's method)")
    ax.plot([], [], "o", color="0.6", mfc="none", label="voxels, shifted lattices")
    ax.set_xscale("log")
    ax.set_xlabel("voxel side l (mm)")
    ax.set_ylabel("V_total = V_uncomp − V_comp/2 (mm³)")
    ax.set_title(f"stitch volume, zero force, L = {a.L:g} mm, k = {a.k:g} mN/mm²", fontsize=11)
    ax.legend(fontsize=8, loc="center right")
    fine = voxel_rows[-1][2]
    ax.text(
        0.02,
        0.5,
        f"voxels − tube at l = {fine.resolution:g} mm: V_uncomp {fine.V_uncomp - q.V_uncomp:+.3f} "
        f"(4/3 π r³ = {4 / 3 * np.pi * 0.74**3:.3f}: the two end caps),\n"
        f"V_comp {fine.V_comp - q.V_comp:+.3f}, V_total {fine.V_total - q.V_total:+.3f} mm³ "
        f"(φ {fine.phi - q.phi:+.4f})",
        transform=ax.transAxes,
        fontsize=8,
        color="0.3",
    )
    fig.savefig(a.out, dpi=150)


if __name__ == "__main__":
    main()
