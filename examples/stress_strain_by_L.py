"""Plot one stress–strain curve per yarn length L from a results file.

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
    fig, axes = plt.subplots(1, len(directions), figsize=(3.4 * len(directions), 2.8),
                             squeeze=False, layout="constrained")  # fmt: skip
    for ax, direction in zip(axes[0], directions, strict=True):
        # one stress-strain curve per L, in one line (other parameters: their first value)
        stress = ds.stress_N_per_mm.sel(direction=direction)
        stress = stress.isel({d: 0 for d in stress.dims if d not in ("L_mm", "step")})
        stress.plot.line(x="strain", hue="L_mm", ax=ax, add_legend=len(ds.L_mm) <= 8)
        ax.set_xlabel(f"strain in {direction}")
        ax.set_ylabel("stress (N/mm)")
        ax.set_title(f"pulled in {direction}", fontsize=9)
    fig.savefig(args.out, dpi=200)

    # the sweep metrics, one row per sweep
    print(res.sweeps[["direction", "L_mm", "Y_sec_N_per_mm", "delta_E_c_mJ", "delta_E_b_mJ"]])
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
