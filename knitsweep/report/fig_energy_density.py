"""The energy density's figure (docs/energy-density.md): W over (ε_xx, ε_yy) (and, with a
shear, over (ε_xx, γ)) with the sampled sweeps, the uniaxial (and shear) sweeps' stresses
against the fit's, and where the fit is not convex."""

from __future__ import annotations

from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..analysis.energy_density import CONVEX_TOLERANCE, DensitySamples, EnergyDensity

LABEL = {"eps_xx": "ε_xx", "eps_yy": "ε_yy", "gamma": "γ"}


def _slice(f: EnergyDensity, axes: tuple[int, int], n: int):
    """A grid over two strains (the third 0), masked outside the sampled region: (gx, gy,
    the full strains (n, n, d), inside)."""
    lo, hi = f.domain.min(0), f.domain.max(0)
    a, b = axes
    gx, gy = np.meshgrid(np.linspace(min(lo[a], 0.0), max(hi[a], 0.0), n),
                         np.linspace(min(lo[b], 0.0), max(hi[b], 0.0), n))  # fmt: skip
    e = np.zeros((n, n, f.dim))
    e[..., a], e[..., b] = gx, gy
    return gx, gy, e, f.in_domain(e)


def _map(fig, ax, f, s, axes, n, title):
    """W over the strains ``axes`` (the other 0) with the samples near that plane."""
    gx, gy, e, inside = _slice(f, axes, n)
    c = ax.contourf(gx, gy, np.where(inside, f.W(e), np.nan), levels=24, cmap="viridis",
                    extend="both")  # fmt: skip
    fig.colorbar(c, ax=ax, label="W (N/mm)")
    other = [k for k in range(f.dim) if k not in axes]
    near = np.ones(len(s.W), dtype=bool)
    for k in other:  # the samples on that plane (their other strain 0)
        near &= np.abs(s.eps[:, k]) < 1e-9
    uni = np.isin(s.direction, ("x", "y", "shear", "shear_free"))
    ax.plot(*s.eps[near & ~uni][:, axes].T, ".", ms=1.2, color="white")
    ax.plot(*s.eps[near & uni][:, axes].T, ".", ms=2.0, color="red")
    if f.dim == 2:
        ax.plot(*np.vstack([f.domain, f.domain[:1]]).T, "k-", lw=0.6)
    ax.set(xlabel=LABEL[f.variables[axes[0]]], ylabel=LABEL[f.variables[axes[1]]], title=title)


def energy_density_figure(f: EnergyDensity, s: DensitySamples, out: Path | BinaryIO,
                          n: int = 161, dpi: int = 130) -> Path | BinaryIO:  # fmt: skip
    """A PNG written to ``out`` (a path, or a binary file such as the report's buffer):
    (a) W (N/mm) over (ε_xx, ε_yy) in the sampled region, the states on that plane
    drawn (rays white; the uniaxial and shear sweeps red); with a shear (b) W over
    (ε_xx, γ) at ε_yy = 0; then σ_xx of the x sweep, σ_yy of the y sweep (and σ_xy of the
    shear sweep), sampled (dots) and fitted (lines); last the tangent's smallest eigenvalue
    over (ε_xx, ε_yy) (γ = 0), negative where W is not convex."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = 3 if f.dim == 2 else 4
    fig, ax = plt.subplots(1, panels, figsize=(4.0 * panels, 4.2), layout="constrained")
    pt = f.point
    fig.suptitle(f"{pt['stitch']}, L = {pt['L_mm']:g} mm, k = {pt['k_mN_per_mm2']:g} mN/mm²: "
                 f"energy density W({', '.join(LABEL[v] for v in f.variables)}) from "
                 f"{len(s.W)} relaxed states", fontsize=10)  # fmt: skip
    _map(fig, ax[0], f, s, (0, 1), n, "(a) W" + (" at γ = 0" if f.dim == 3 else ""))
    if f.dim == 3:
        _map(fig, ax[1], f, s, (0, 2), n, "(b) W at ε_yy = 0")
    curves = ax[panels - 2]
    for d, i, colour in (("x", 0, "C0"), ("y", 1, "C3"), ("shear", 2, "C1")):
        m = s.direction == d
        if not m.any() or i >= f.dim:
            continue
        e = s.eps[m]
        order = np.argsort(e[:, i])
        name = LABEL[f.variables[i]].replace("ε_", "").replace("γ", "xy")
        curves.plot(e[order, i], s.stress[m][order, i], ".", ms=3, color=colour,
                    label=f"{d} sweep: σ_{name} sampled")  # fmt: skip
        err = f.fit.get("stress_error", {}).get(d, float("nan"))
        curves.plot(e[order, i], f.stress(e[order])[:, i], "-", color=colour, lw=1,
                    label=f"fit (error {100 * err:.2g} % of peak)")  # fmt: skip
    curves.set(xlabel="strain of the sweep", ylabel="stress (N/mm)",
               title=f"({'bc'[f.dim - 2]}) uniaxial{' and shear' if f.dim == 3 else ''} "
               "sweeps")  # fmt: skip
    curves.legend(fontsize=7)
    gx, gy, e, inside = _slice(f, (0, 1), n)
    eig = np.full(gx.shape, np.nan)
    eig[inside] = np.linalg.eigvalsh(f.tangent(e[inside]))[:, 0]
    last = ax[panels - 1]
    top = float(np.nanmax(np.abs(eig))) if np.isfinite(eig).any() else 1.0
    c = last.pcolormesh(gx, gy, eig, cmap="RdBu", vmin=-top, vmax=top, shading="auto")
    fig.colorbar(c, ax=last, label="smallest eigenvalue of ∂²W/∂ε² (N/mm)")
    bad = inside & (eig < -CONVEX_TOLERANCE * np.nanmax(eig))
    last.contour(gx, gy, bad.astype(float), levels=[0.5], colors="k", linewidths=0.6)
    share = 100 * f.fit.get("convexity", {}).get("fraction", float("nan"))
    last.set(xlabel="ε_xx", ylabel="ε_yy",
             title=f"({'cd'[f.dim - 2]}) not convex (outlined): {share:.0f} %"
             + (" of the region" if f.dim == 3 else ""))  # fmt: skip
    fig.savefig(out, format="png", dpi=dpi)
    plt.close(fig)
    return out


def density_summary(fit: EnergyDensity) -> str:
    """The fit's measured errors in a few lines (``knitsweep energy-density`` prints
    them; the report shows them under the figure)."""
    f, pt = fit.fit, fit.point
    err = f["stress_error"]
    worst = max(err, key=err.get)
    lines = [
        f"{pt['stitch']} L = {pt['L_mm']:g} mm: W({', '.join(fit.variables)}) from "
        f"{f['samples']} states of {len(f['sweeps'])} sweeps, knots "
        + "x".join(str(k) for k in f["knots"]),
        "stress error (% of each sweep's peak): "
        + ", ".join(f"{d} {100 * err[d]:.2f}" for d in ("x", "y") if d in err)
        + f"; largest {100 * err[worst]:.2f} ({worst}); energy {100 * f['energy_error']:.2f}",
    ]
    if f.get("held_out_error"):
        h = np.array(list(f["held_out_error"].values()))
        lines.append(
            f"between rays (each left out): median {100 * np.median(h):.1f} %, "
            f"largest {100 * h.max():.1f} % of the ray's peak stress"
        )
    c = f["convexity"]
    lines.append(
        f"not convex on {100 * c['fraction']:.0f} % of the sampled region "
        f"(smallest eigenvalue {c['min_eigenvalue_N_per_mm']:.3g} N/mm, largest "
        f"{c['max_eigenvalue_N_per_mm']:.3g})"
    )
    if "mirror_asymmetry" in f:
        m = f["mirror_asymmetry"]
        lines.append(f"mirror W(gamma) = W(-gamma) at {m['samples']} samples: energy within "
                     f"{100 * m['energy']:.2g} % of the largest W, shear stress within "
                     f"{100 * m['shear_stress']:.2g} % of the largest")  # fmt: skip
    if f["left_out"]:
        lines.append("left out: " + "; ".join(f"{d}: {w}" for d, w in f["left_out"].items()))
    return "\n".join(lines)
