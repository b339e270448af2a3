"""The energy density's figure (docs/energy-density.md): W over (ε_xx, ε_yy) with the
sampled sweeps, the uniaxial sweeps' stresses against the fit's, and where the fit is
not convex."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..analysis.energy_density import CONVEX_TOLERANCE, DensitySamples, EnergyDensity


def energy_density_figure(f: EnergyDensity, s: DensitySamples, out: Path, n: int = 161) -> Path:
    """Three panels: (a) W (N/mm) in the sampled region, each sweep's states drawn;
    (b) σ_xx of the x sweep and σ_yy of the y sweep, sampled (dots) and fitted (lines);
    (c) the tangent's smallest eigenvalue, negative where W is not convex."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lo, hi = f.domain.min(0), f.domain.max(0)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
    inside = f.in_domain(gx, gy)
    W = np.where(inside, f.W(gx, gy), np.nan)
    eig = np.full(gx.shape, np.nan)
    eig[inside] = np.linalg.eigvalsh(f.tangent(gx[inside], gy[inside]))[:, 0]
    fig, ax = plt.subplots(1, 3, figsize=(12.0, 4.2), layout="constrained")
    pt = f.point
    fig.suptitle(f"{pt['stitch']}, L = {pt['L_mm']:g} mm, k = {pt['k_mN_per_mm2']:g} mN/mm²: "
                 f"energy density from {len(s.W)} relaxed states", fontsize=10)  # fmt: skip
    c = ax[0].contourf(gx, gy, W, levels=24, cmap="viridis", extend="both")
    fig.colorbar(c, ax=ax[0], label="W (N/mm)")
    for d in s.ends:
        m = s.direction == d
        ax[0].plot(*s.eps[m].T, ".", ms=1.2, color="white" if d not in ("x", "y") else "red")
    ax[0].plot(*np.vstack([f.domain, f.domain[:1]]).T, "k-", lw=0.6)
    ax[0].set(xlabel="ε_xx", ylabel="ε_yy", title="(a) W; states (rays white, x and y red)")
    for d, i, colour in (("x", 0, "C0"), ("y", 1, "C3")):
        m = s.direction == d
        if not m.any():
            continue
        e = s.eps[m]
        order = np.argsort(e[:, i])
        ax[1].plot(e[order, i], s.stress[m][order, i], ".", ms=3, color=colour,
                   label=f"{d} sweep: σ_{d}{d} sampled")  # fmt: skip
        fit = f.stress(e[order, 0], e[order, 1])[:, i]
        err = f.fit.get("stress_error", {}).get(d, float("nan"))
        ax[1].plot(e[order, i], fit, "-", color=colour, lw=1,
                   label=f"fit (error {100 * err:.2g} % of peak)")  # fmt: skip
    ax[1].set(xlabel="strain of the pulled period", ylabel="stress (N/mm)",
              title="(b) uniaxial sweeps: samples and fit")  # fmt: skip
    ax[1].legend(fontsize=7)
    top = float(np.nanmax(np.abs(eig))) if np.isfinite(eig).any() else 1.0
    c = ax[2].pcolormesh(gx, gy, eig, cmap="RdBu", vmin=-top, vmax=top, shading="auto")
    fig.colorbar(c, ax=ax[2], label="smallest eigenvalue of ∂²W/∂ε² (N/mm)")
    bad = inside & (eig < -CONVEX_TOLERANCE * np.nanmax(eig))
    ax[2].contour(gx, gy, bad.astype(float), levels=[0.5], colors="k", linewidths=0.6)
    ax[2].set(xlabel="ε_xx", ylabel="ε_yy",
              title=f"(c) not convex: {100 * f.fit['convexity']['fraction']:.0f} % (outlined)")  # fmt: skip
    fig.savefig(out, dpi=130)
    plt.close(fig)
    return out
