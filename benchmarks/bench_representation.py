"""Does a free yarn's verdict depend on how it is parametrised? (prints a table; not a
test; docs/model.md §11, "Resolution").

Per stitch (default garter, rib, seed, stockinette_free) and L (default 10.5, 11.6,
12.2 mm; k = 0.1 mN/mm², Table 1 otherwise, the ``converged`` preset, the first shipped
start): the zero-force state and an x and a y sweep from it as an adaptive study asks
(``energy_gaps``, ``secant_modulus``), once at the preset's resolution (1x: 10 contact
samples per segment, 32 Gauss nodes) and once at twice it (2x: 20 and 64), the 2x zero
force relaxed from the 1x minimum and its sweeps from there. Printed per point:

* E (mJ) and E_c at 1x; E_c of the *same* state at 2x (the discretisation alone) and of
  the 2x minimum, each as a change in % of the 1x E_c;
* the jamming gaps (ΔE_c in x, ΔE_b in y) at 1x and their change at 2x (mJ);
* every state entry within 1e-9 (relative) of its bound at the zero-force state and at
  any converged sweep step, by name (``bounds:`` a count and the names);
* CPU s of the 1x point (zero force + both sweeps) and of the 2x one;
* for a gauged free yarn (samples along the yarn, its end speeds held at L/8,
  docs/model.md §11), what the gauge costs: the 1x zero-force state relaxed again with
  its speeds free, the energy it falls by (mJ; ``nan`` where that relaxation did not
  converge) and its CPU s.

Run: ``python benchmarks/bench_representation.py [--stitches rib,seed] [--L 11.6]
[--sampling parameter] [--samples 15] [--nodes 48]`` (the contact sampling, the 1x samples
and nodes; the bounds checked are those the relaxation uses for that sampling).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from threadpoolctl import threadpool_limits

from knitsweep.analysis.metrics import energy_gaps
from knitsweep.config import Fidelity, StartSettings, StitchParams
from knitsweep.model import CellModel
from knitsweep.presets import Numerics
from knitsweep.relax import Relaxer
from knitsweep.relax.problem import _state_box
from knitsweep.relax.zero_force import zero_force
from knitsweep.strain_sweep import strain_sweep

ON_BOUND_RTOL = 1e-9


def on_bounds(model: CellModel, x: np.ndarray) -> set[str]:
    """Names of the entries of ``x`` that sit on the bounds the model's relaxations use,
    each marked < (on its lower bound) or > (its upper)."""
    st = model.stitch
    lo, hi = _state_box(st, model.ip.L, model.ip.r, model.sampling)
    with np.errstate(invalid="ignore"):
        hit = ((np.isfinite(lo) & (np.abs(x - lo) <= ON_BOUND_RTOL * np.maximum(1.0, np.abs(lo))))
               | (np.isfinite(hi) & (np.abs(x - hi) <= ON_BOUND_RTOL * np.maximum(1.0, np.abs(hi)))))  # fmt: skip
    low = np.isfinite(lo) & (np.abs(x - lo) <= ON_BOUND_RTOL * np.maximum(1.0, np.abs(lo)))
    return {st.state_names[i] + ("<" if low[i] else ">") for i in np.flatnonzero(hit)}


def released(row: dict) -> tuple[float, float]:
    """(energy fall in mJ, CPU s) of the zero-force state of ``row`` relaxed again with
    its gauge released (every end speed free); (0, 0) where the model has no gauge."""
    model = CellModel(row["params"], row["fid"])
    if not model.gauge.size:
        return 0.0, 0.0
    model.gauge = np.empty(0, dtype=np.int64)
    n = Numerics.from_preset("converged")
    t0 = time.process_time()
    r = Relaxer(n.solver).relax(model, row["zero"].x, None)
    cpu = time.process_time() - t0
    fall = row["zero"].total_energy - r.total_energy if r.converged else float("nan")
    return fall, cpu


def point(stitch: str, L: float, k: float, scale: int, base: Fidelity, carried=None) -> dict:
    """Zero force (from the first start, or relaxed from ``carried``) and both sweeps at
    ``scale`` times the samples and quadrature nodes of ``base``."""
    params = StitchParams(stitch=stitch, L_mm=L, k_mN_per_mm2=k)
    n = Numerics.from_preset("converged", observables=("energy_gaps", "secant_modulus"))
    fid = base.model_copy(update={
        "samples_per_segment": scale * base.samples_per_segment,
        "quadrature_nodes": scale * base.quadrature_nodes})  # fmt: skip
    model = CellModel(params, fid)
    t0 = time.process_time()
    if carried is None:
        zero = zero_force(params, fid, n.solver, StartSettings(count=1), 0)
    else:
        zero = zero_force(params, fid, n.solver, StartSettings(count=1), 0,
                          carried=(carried, params))  # fmt: skip
    row = {"zero": zero.best, "gaps": {}, "bounds": set(), "fid": fid, "params": params}
    if zero.best.converged:
        row["bounds"] |= on_bounds(model, zero.best.x)
        for d in ("x", "y"):
            s = strain_sweep(params, zero, d, n.protocol, fid, n.solver)
            g = energy_gaps(s.bending_energy, s.contact_energy)
            row["gaps"][d] = g.delta_E_c if d == "x" else g.delta_E_b
            for x, ok in zip(s.states, s.converged, strict=False):
                if ok:
                    row["bounds"] |= on_bounds(model, x)
    row["cpu"] = time.process_time() - t0
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stitches", default="garter,rib,seed,stockinette_free")
    ap.add_argument("--L", type=float, nargs="+", default=[10.5, 11.6, 12.2])
    ap.add_argument("--k", type=float, default=0.1)
    ap.add_argument(
        "--sampling",
        choices=("auto", "parameter", "arclength", "yarn_arclength"),
        default="auto",
        help="where the contact samples sit (Fidelity.contact_sampling)",
    )
    ap.add_argument(
        "--samples",
        type=int,
        default=0,
        help="contact samples per segment at 1x (default the preset's)",
    )
    ap.add_argument(
        "--nodes", type=int, default=0, help="bending quadrature nodes at 1x (default the preset's)"
    )
    args = ap.parse_args()
    base = Numerics.from_preset("converged").fidelity
    base = base.model_copy(update={
        "contact_sampling": args.sampling,
        "samples_per_segment": args.samples or base.samples_per_segment,
        "quadrature_nodes": args.nodes or base.quadrature_nodes})  # fmt: skip
    print(
        f"sampling {args.sampling}, {base.samples_per_segment} samples and "
        f"{base.quadrature_nodes} nodes per segment at 1x"
    )
    print(f"k = {args.k} mN/mm^2, converged preset, 1 start; E mJ; dEc % of the 1x E_c "
          "(fixed state at 2x, then the 2x minimum); gaps mJ (dE_c x, dE_b y) and their "
          "change at 2x; CPU s of the 1x and 2x points")  # fmt: skip
    print(f"{'stitch':16} {'L':>5} {'status':13} {'E':>9} {'E_c':>9} {'dEc fix%':>8} "
          f"{'dEc 2x%':>8} | {'gap x':>8} {'d gap x':>9} {'gap y':>8} {'d gap y':>9} | "
          f"{'1x s':>6} {'2x s':>6} | {'gauge mJ':>8} {'s':>5} | bounds")  # fmt: skip
    with threadpool_limits(1):
        for stitch in args.stitches.split(","):
            for L in args.L:
                one = point(stitch, L, args.k, 1, base)
                z = one["zero"]
                if not z.converged:
                    print(f"{stitch:16} {L:5.2f} {z.status:13} {z.message[:80]}")
                    continue
                fine = CellModel(one["params"], one["fid"].model_copy(update={
                    "samples_per_segment": 2 * one["fid"].samples_per_segment,
                    "quadrature_nodes": 2 * one["fid"].quadrature_nodes}))  # fmt: skip
                ec_fixed = fine.energies(z.x).contact_energy
                two = point(stitch, L, args.k, 2, base, carried=z.x)
                z2 = two["zero"]
                ec = z.contact_energy
                dfix = 100 * (ec_fixed - ec) / ec
                d2 = 100 * (z2.contact_energy - ec) / ec if z2.converged else float("nan")
                cells = []
                for d in ("x", "y"):
                    g1 = one["gaps"].get(d, float("nan"))
                    g2 = two["gaps"].get(d, float("nan"))
                    cells.append(f"{g1:8.2e} {g2 - g1:+9.1e}")
                b = sorted(one["bounds"] | two["bounds"])
                fall, cpu = released(one)
                print(f"{stitch:16} {L:5.2f} {z.status:13} {z.total_energy:9.6f} {ec:9.3e} "
                      f"{dfix:+8.2f} {d2:+8.2f} | {cells[0]} {cells[1]} | {one['cpu']:6.2f} "
                      f"{two['cpu']:6.2f} | {fall:8.1e} {cpu:5.1f} | {len(b)} {' '.join(b)}",
                      flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
