"""Time of a tile picture and of a 3D export (prints figures, median of several runs).

The shipped start 1 of each pattern at its default window (two repeats each way, at
least 3 × 3), the yarn's radius, ``--pixels`` wide: the mesh, the z-buffer at 2 × 2
samples per pixel, the shading (``render.shade_tile``), then a 2 × 2 tile written as
.vtp (``export3d.write_tile``: the mesh and every vertex's contact class). CPU seconds
of this process (a busy machine stretches the wall time, not these); the first run
compiles the numba kernels and is left out of the median.

Run: ``python benchmarks/bench_render.py [--pixels 1100] [--runs 3]``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from knitsweep.config import StitchParams
from knitsweep.report import render as rd
from knitsweep.report.export3d import write_tile
from knitsweep.stitches import get_stitch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pixels", type=int, default=1100)
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    print(f"{'stitch':12s} {'cells':>6s} {'picture CPU s':>14s} {'.vtp CPU s':>11s}")
    with tempfile.TemporaryDirectory() as tmp:
        for name in ("stockinette", "garter", "rib", "seed"):
            stitch = rd.stitch_from_state(get_stitch(name).start(1), StitchParams(stitch=name))
            cells = rd.default_cells(stitch)
            view = rd._view_matrix(72.0, 0.0, "face")
            box = rd.window(stitch, cells, view)
            pictures, meshes = [], []
            for run in range(args.runs + 1):
                t = time.process_time()
                rd.shade_tile(stitch, cells, stitch.r_mm, view, box, args.pixels)
                pictures.append(time.process_time() - t)
                t = time.process_time()
                write_tile(stitch, Path(tmp) / "tile.vtp", (2, 2), stitch.r_mm)
                meshes.append(time.process_time() - t)
                if run == 0:  # compiles
                    pictures.clear()
                    meshes.clear()
            print(f"{name:12s} {cells[0]:>2d} x {cells[1]:<2d} {statistics.median(pictures):14.2f} "
                  f"{statistics.median(meshes):11.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
