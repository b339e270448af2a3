"""Where a relaxation's and a sweep's cost goes (prints figures; not a pass/fail test).

1. Zero-force relaxation from Init_1 at L = 11.6 mm, k = 0.1 mN/mm^2 (one start) with
   each minimiser, against the authors' code on this machine
   (tests/data/relaxed_reference.json).
2. One point's full x and y sweeps (default L = 11.0 mm, k = 0.1, 4 starts, the
   paper's protocol: h = 0.001 mm, then 0.1/0.05 mm) three ways: SLSQP with every chain
   kept (the code before the Newton solver and merging), SLSQP with merging, and the
   default (Newton, merging). For each: steps, relaxations, chains per step,
   evaluations per step (all chains), per relaxation (median, 90th percentile), CPU
   seconds per sweep, and where they go: the energy kernels (E, ∇E, ∇ℓ, neighbour
   lists, min ζ, thickness), the minimiser's own work around them, and the sweep's.
3. The conditioning of the reduced Hessian of the Lagrangian (∇²E − λ∇²ℓ on the
   tangent space of the length constraint, the twist held where its bound is active)
   at the winning state every few steps of the x sweep: its extreme eigenvalues.

Run: ``python benchmarks/bench_relax.py [--L 11.0] [--repeats N]``. CPU seconds of one
process, single-threaded (BLAS on one thread, as knitsweep's tasks run), so the figures
do not depend on what else the machine runs.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from knitsweep.compilation import compile_kernels
from knitsweep.config import SolverSettings, StartSettings, StitchParams, SweepProtocol
from knitsweep.formats import shipped_state
from knitsweep.kernels.kkt_rows import compile_solver
from knitsweep.model import CellModel
from knitsweep.relax import Relaxer, free_entries, relax
from knitsweep.relax.newton import measure_curvature
from knitsweep.relax.problem import Problem
from knitsweep.relax.zero_force import zero_force
from knitsweep.stitches.stockinette.layout import IDX_TW
from knitsweep.strain_sweep import strain_sweep

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
KERNELS = ("energy_and_gradients", "energies", "min_zeta", "thickness", "_rebuild")


class Clock:
    """CPU seconds spent in the energy kernels and in relaxations (outermost calls)."""

    def __init__(self) -> None:
        self.kernel = self.relax = 0.0
        self._depth = {"kernel": 0, "relax": 0}

    @contextmanager
    def installed(self):
        saved = {name: getattr(CellModel, name) for name in KERNELS}
        saved_relax = Relaxer.relax
        for name in KERNELS:
            setattr(CellModel, name, self._wrap(saved[name], "kernel"))
        Relaxer.relax = self._wrap(saved_relax, "relax")
        try:
            yield self
        finally:
            for name, f in saved.items():
                setattr(CellModel, name, f)
            Relaxer.relax = saved_relax

    def _wrap(self, f, kind):
        def timed(*args, **kwargs):
            self._depth[kind] += 1
            t = time.process_time()
            try:
                return f(*args, **kwargs)
            finally:
                self._depth[kind] -= 1
                if self._depth[kind] == 0:
                    setattr(self, kind, getattr(self, kind) + time.process_time() - t)

        return timed


def zero_force_figures(repeats: int) -> None:
    ref = json.loads((DATA / "relaxed_reference.json").read_text())["cases"][0]
    params = StitchParams(L_mm=11.6, k_mN_per_mm2=0.1)
    model = CellModel(params)
    x0 = shipped_state(1)
    print(f"authors' code: {ref['seconds']:.1f} s, {ref['iterations']} iterations, "
          f"{ref['energy_evaluations']} energy evaluations (finite differences)")  # fmt: skip
    print(f"{'zero-force relaxation from Init_1':<40}{'median [ms]':>12}{'iters':>7}{'evals':>7}"
          f"{'E - E_ref [mJ]':>16}{'speed-up':>11}")  # fmt: skip
    for label, solver in (("SLSQP, ftol 1e-6 (paper)", SolverSettings(method="slsqp", ftol=1e-6)),
                          ("SLSQP, ftol 1e-10", SolverSettings(method="slsqp")),
                          ("Newton, ftol 1e-10 (converged)", SolverSettings())):  # fmt: skip
        relax(model, x0, settings=solver)
        times, r = [], None
        for _ in range(repeats):
            t = time.process_time()
            r = relax(model, x0, settings=solver)
            times.append(time.process_time() - t)
        med = statistics.median(times)
        print(f"  {label:<38}{med * 1e3:12.1f}{r.iterations:7d}{r.evaluations:7d}"
              f"{r.total_energy - ref['total_energy']:16.2e}{ref['seconds'] / med:10.0f}x")  # fmt: skip


def sweep_figures(params: StitchParams) -> dict:
    variants = {
        "SLSQP, all chains": (SolverSettings(method="slsqp"), SweepProtocol(merge_tolerance_mJ=0)),
        "SLSQP, merging": (SolverSettings(method="slsqp"), SweepProtocol()),
        "Newton, merging": (SolverSettings(), SweepProtocol()),
    }
    print(f"\nfull sweeps at L = {params.L_mm} mm, k = {params.k_mN_per_mm2} mN/mm^2, 4 starts, "
          "h = 0.001 mm (CPU seconds)")  # fmt: skip
    head = (f"{'':3}{'':20}{'steps':>6}{'relax.':>7}{'chains':>7}{'ev/step':>8}{'ev/relax':>9}"
            f"{'p90':>5}{'s/sweep':>8}{'kernels':>8}{'solver':>7}{'sweep':>6}")  # fmt: skip
    print(head)
    sweeps = {}
    for label, (solver, protocol) in variants.items():
        zero = zero_force(params, solver=solver, starts=StartSettings(count=4))
        for d in ("x", "y"):
            clock = Clock()
            with clock.installed():
                t = time.process_time()
                s = strain_sweep(params, zero, d, protocol, solver=solver)
                total = time.process_time() - t
            steps = len(s.strain) - 1
            per_relax = s.evaluations[1:]  # the winners'; all relaxations below
            kernel_in_relax = clock.kernel  # kernels outside relaxations are the sweep's
            print(f"{d:3}{label:20}{steps:6d}{s.relaxations:7d}{s.relaxations / steps:7.2f}"
                  f"{s.evaluations_total / steps:8.1f}{np.median(per_relax):9.0f}"
                  f"{np.percentile(per_relax, 90):5.0f}{total:8.2f}"
                  f"{kernel_in_relax / total:7.0%}{(clock.relax - kernel_in_relax) / total:7.0%}"
                  f"{(total - clock.relax) / total:6.0%}")  # fmt: skip
            sweeps[(label, d)] = (zero, s)
    print(
        "kernels: share of the sweep's CPU time in energy kernels; solver: in the minimiser "
        "around them; sweep: the rest (chains, merging, stress, thickness)"
    )
    return sweeps


def conditioning(params: StitchParams, zero, sweep, every: int) -> None:
    """The reduced Hessian's extreme eigenvalues at the winner of every ``every``-th step."""
    model = CellModel(params)
    free = free_entries(model.stitch, "x")
    print("\nreduced Hessian of the Lagrangian along the x sweep (mJ/mm^2; state units)")
    print(f"{'step':>5}{'strain':>9}{'lowest':>11}{'lowest > 0':>12}{'highest':>10}"
          f"{'condition':>11}{'negative':>9}")  # fmt: skip
    for i in range(0, len(sweep.strain), every):
        x = sweep.states[i]
        prob = Problem(model, x, free)
        pt = prob.evaluate(x[free])
        b = measure_curvature(prob, pt).lagrangian(sweep_multiplier(model, x, free))
        b = b[np.ix_(free, free)]
        keep = np.ones(free.size, dtype=bool)
        if np.cos(x[IDX_TW]) - params.twist_bound <= 1e-8:  # the twist bound holds tw
            keep[np.flatnonzero(free == IDX_TW)] = False
        a = pt.a[keep]
        q, _ = np.linalg.qr(np.column_stack([a, np.eye(a.size)[:, : a.size - 1]]))
        z = q[:, 1:]
        w = np.linalg.eigvalsh(z.T @ b[np.ix_(keep, keep)] @ z)
        pos = w[w > 0]
        print(f"{i:5d}{sweep.strain[i]:9.4f}{w[0]:11.2e}{pos.min():12.2e}{w[-1]:10.2e}"
              f"{w[-1] / pos.min():11.1e}{int(np.sum(w < 0)):9d}")  # fmt: skip


def sweep_multiplier(model: CellModel, x: np.ndarray, free: np.ndarray) -> float:
    _, ge, gl = model.energy_and_gradients(x)
    return float(ge[free] @ gl[free] / (gl[free] @ gl[free]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--L", type=float, default=11.0, help="yarn length of the swept point (mm)")
    ap.add_argument("--repeats", type=int, default=5, help="runs per relaxation figure")
    ap.add_argument("--every", type=int, default=15, help="steps between Hessian figures")
    args = ap.parse_args()
    threadpool_limits(1)
    compile_kernels()
    compile_solver()
    print("knitsweep relaxation benchmark (single-threaded, one core, CPU seconds)")
    zero_force_figures(args.repeats)
    params = StitchParams(L_mm=args.L, k_mN_per_mm2=0.1)
    sweeps = sweep_figures(params)
    zero, sweep = sweeps[("Newton, merging", "x")]
    conditioning(params, zero, sweep, args.every)


if __name__ == "__main__":
    main()
