"""Packing fraction along one stored sweep by voxels of two sizes and by the tube
estimator (the paper's voxel-size figure, panel b: L = 10.5 mm, k = 0.1, pulled in x,
l = 0.04 and 0.02 mm). Prints the table and draws the figure.

Input: a results file that stores the sweep's states ([store] states = true, e.g.
``jobs/paper_packing_fraction.toml``). Voxels are costly (seconds per state at
l = 0.02 mm), so they are computed at every ``--every``-th step (``--every-fine`` for the
finer voxels); the tube estimate is the stored one, at every step.

Run: ``python benchmarks/bench_volumes_sweep.py paper_packing_fraction.h5 [--L 10.5]
[--direction x] [--out docs/packing_fraction_voxels_L10.5.png]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from knitsweep.analysis.volumes import voxel_volumes
from knitsweep.config import StitchParams
from knitsweep.model import CellModel
from knitsweep.store.read import iter_entries


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path)
    ap.add_argument("--L", type=float, default=10.5)
    ap.add_argument("--direction", default="x")
    ap.add_argument("--every", type=int, default=5)
    ap.add_argument("--every-fine", type=int, default=15)
    ap.add_argument("--out", type=Path, default=Path("docs/packing_fraction_voxels_L10.5.png"))
    a = ap.parse_args()
    e = next(e for e in iter_entries(a.results, with_data=True) if e.kind == "sweeps"
             and e.meta.get("direction") == a.direction and abs(e.meta["L_mm"] - a.L) < 1e-9)  # fmt: skip
    params = StitchParams.from_flat(e.meta)
    model = CellModel(params)
    strain = np.asarray(e.record["strain"], dtype=float)
    states = np.asarray(e.record["states"], dtype=float)
    tube = np.asarray(e.record["packing_fraction"], dtype=float)
    rows = {}
    for side, every in ((0.04, a.every), (0.02, a.every_fine)):
        t = time.perf_counter()
        steps = list(range(0, len(strain), every))
        rows[side] = (steps, [voxel_volumes(model.control_points(states[i]), states[i][-2],
                                            states[i][-1], params.r_mm, side).phi
                              for i in steps])  # fmt: skip
        print(f"voxels l = {side:g} mm: {len(steps)} states in {time.perf_counter() - t:.0f} s")
    print(
        "\n| step | strain | φ tube | φ voxels 0.04 | φ voxels 0.02 |\n|---:|---:|---:|---:|---:|"
    )
    v04 = dict(zip(*rows[0.04], strict=True))
    v02 = dict(zip(*rows[0.02], strict=True))
    for i in sorted(set(v04) | set(v02)):
        f04 = f"{v04[i]:.4f}" if i in v04 else "–"
        f02 = f"{v02[i]:.4f}" if i in v02 else "–"
        print(f"| {i} | {strain[i]:.3f} | {tube[i]:.4f} | {f04} | {f02} |")
    both = sorted(set(v04) & set(v02))
    diff = [v04[i] - v02[i] for i in both]
    off = [v02[i] - tube[i] for i in both]
    print(f"\nvoxels 0.04 − 0.02 mm: {min(diff):+.4f} … {max(diff):+.4f}; voxels 0.02 − tube: "
          f"{min(off):+.4f} … {max(off):+.4f}")  # fmt: skip
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 4.2), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    ax.plot(strain, tube, color="C3", lw=1.5, label="tube quasi-Monte Carlo (stored, every step)")
    ax.plot(
        strain[rows[0.04][0]], rows[0.04][1], "o", color="C0", ms=4, label="voxels, l = 0.04 mm"
    )
    ax.plot(strain[rows[0.02][0]], rows[0.02][1], "s", color="k", ms=4, mfc="none",
            label="voxels, l = 0.02 mm")  # fmt: skip
    ax.set_xlabel(f"strain ε_{a.direction}")
    ax.set_ylabel("packing fraction φ")
    ax.set_title(f"φ along the {a.direction} pull, L = {a.L:g} mm, k = {params.k_mN_per_mm2:g} mN/mm²",
                 fontsize=11)  # fmt: skip
    ax.legend(fontsize=9)
    fig.savefig(a.out, dpi=150)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
