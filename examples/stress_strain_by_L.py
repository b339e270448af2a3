"""Plot one stress–strain curve per yarn length L from a results file.

    python examples/stress_strain_by_L.py demo.h5 --out stress_strain.png

The results file comes from ``knitsweep run jobs/demo.toml`` (README, set-up); any
results file works. Everything here goes through ``knitsweep.load``: pandas
DataFrames whose columns carry their units (``stress_N_per_mm``, ``L_mm``).
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
    curves = res.curves
    directions = sorted(curves["direction"].unique())
    fig, axes = plt.subplots(1, len(directions), figsize=(3.4 * len(directions), 2.8),
                             squeeze=False, layout="constrained")  # fmt: skip
    for ax, direction in zip(axes[0], directions, strict=True):
        for L, curve in curves[curves["direction"] == direction].groupby("L_mm"):
            ax.plot(curve["strain"], curve["stress_N_per_mm"], label=f"L = {L:g} mm")
        ax.set_xlabel(f"strain in {direction}")
        ax.set_ylabel("stress (N/mm)")
        ax.legend(fontsize=7, frameon=False)
    fig.savefig(args.out, dpi=200)

    # the sweep metrics, one row per sweep
    print(res.sweeps[["direction", "L_mm", "Y_sec_N_per_mm", "delta_E_c_mJ", "delta_E_b_mJ"]])
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
