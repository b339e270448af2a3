"""Plot one stress–strain curve per yarn length L from a results file, a row of panels per
stitch (a patterns file holds several) and one per direction.

    python examples/stress_strain_by_L.py demo.h5 --out stress_strain.png

The results file comes from ``knitsweep run jobs/demo.toml`` (README, set-up); any
results file works. Everything here goes through ``knitsweep.load``: an xarray Dataset over
the grid's dimensions (``ds.stress_N_per_mm.plot.line(x="strain", hue="L_mm")``) and
pandas DataFrames whose columns carry their units (``stress_N_per_mm``, ``L_mm``).
"""

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

import knitsweep


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", nargs="*", default=["demo.h5"], help="results file(s) [demo.h5]")
    ap.add_argument("--out", default="stress_strain.png", help="figure to write")
    args = ap.parse_args()

    res = knitsweep.load(*args.results)
    ds = res.to_xarray()  # over (direction, L_mm, …, step); strain is a coordinate
    directions = list(ds.direction.values)
    # one row of panels per stitch (a patterns file holds several), one per direction
    stitches = list(ds.stitch.values) if "stitch" in ds.dims else [str(ds.stitch.values)]
    fig, axes = plt.subplots(len(stitches), len(directions), squeeze=False,
                             figsize=(3.4 * len(directions), 2.8 * len(stitches)),
                             layout="constrained")  # fmt: skip
    for row, stitch in zip(axes, stitches, strict=True):
        for ax, direction in zip(row, directions, strict=True):
            stress = ds.stress_N_per_mm.sel(direction=direction)
            if "stitch" in stress.dims:
                stress = stress.sel(stitch=stitch)
            # one curve per L; any other parameter that varies: its first value, said so
            others = [d for d in stress.dims if d not in ("L_mm", "step")]
            fixed = ", ".join(f"{d} = {stress[d].values[0]:g}" for d in others)
            stress = stress.isel({d: 0 for d in others})
            stress = stress.dropna("L_mm", how="all")  # the L values of this stitch
            stress.plot.line(x="strain", hue="L_mm", ax=ax, add_legend=len(stress.L_mm) <= 8)
            ax.set_xlabel(f"strain in {direction}")
            ax.set_ylabel("stress (N/mm)")
            ax.set_title(f"{stitch}, pulled in {direction}" + (f"\n({fixed})" if fixed else ""),
                         fontsize=9)  # fmt: skip
    fig.savefig(args.out, dpi=200)

    # the sweep metrics, one row per sweep
    print(res.sweeps[["stitch", "direction", "L_mm", "Y_sec_N_per_mm", "delta_E_c_mJ",
                      "delta_E_b_mJ"]])  # fmt: skip
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
