"""Garter and rib against stockinette: one energy evaluation and one zero-force relaxation.

Run: ``python benchmarks/bench_patterns.py [--repeats 3] [--eval-repeats 7]
[--min-time 0.2] [--kernels culled,exhaustive] [--skip-relax]``

Every stitch at L = 11.6 mm, k = 0.1 mN/mm^2 (Table 1 otherwise), the paper's fidelity.

1. One call of ``CellModel.energy_and_gradients`` (E, ∇E, ∇ℓ) at the first shipped
   start: the median over ``--eval-repeats`` runs of the mean time of a call in a batch
   lasting at least ``--min-time`` s, after a JIT warm-up. Stockinette's call has no
   neighbour list (as the patterns'), so all pay their full contact search.
2. ``zero_force`` from Init_1 alone (one start, walked from the start's own length in
   continuation stages, docs/model.md §7): median CPU seconds over ``--repeats`` runs,
   with the last stage's iterations and evaluations, the stages, all stages' kernel
   calls, and where the CPU time went: the energy kernels (``energy_and_gradients``),
   the Newton step's compiled linear algebra (``kkt_step``) and SLSQP.

Garter's contact sum is taken with each kernel of ``--kernels``, alternating run by run:
``culled`` (``mirrored_contact_energy``, the package's) and ``exhaustive`` (every sample
pair of every reachable image, ``mirrored_contact_energy_exhaustive``, the kernel before
the culls), so that the two are measured under the same load; rib's with the culled
kernel. Ratios are the pattern over stockinette. CPU seconds of one process, BLAS on one thread.

Not a test: nothing here passes or fails.
"""

from __future__ import annotations

import argparse
import statistics
import time
from contextlib import contextmanager

import numpy as np
from numba import njit

import knitsweep.stitches.images as images_module
from knitsweep.config import StartSettings, StitchParams
from knitsweep.kernels.arclength import length_spread
from knitsweep.kernels.bending import bending_and_length
from knitsweep.kernels.cell import _state_gradients
from knitsweep.kernels.mirrored import N_MIRROR_CLASSES, mirrored_contact_energy_exhaustive
from knitsweep.kernels.pattern_cell import pattern_cell_energy
from knitsweep.model import CellModel
from knitsweep.relax import newton, relaxer
from knitsweep.relax.relaxer import single_threaded
from knitsweep.relax.zero_force import zero_force

PARAMS = StitchParams(L_mm=11.6, k_mN_per_mm2=0.1)


@njit(cache=True)
def _pattern_cell_energy_exhaustive(cp, jac, ax, ay, sx, cx, qtab, qw, ctab, aq, seg_w, bend, reg, r,
                                    rc, k, p, pm, pn, gauge_rule, gauge_stiffness, with_grad,
                                    grad_e, grad_l):  # fmt: skip
    """``pattern_cell.pattern_cell_energy`` with the exhaustive contact kernel."""
    ge, gl, gc = np.empty_like(cp), np.empty_like(cp), np.empty_like(cp)
    gcell = np.zeros(2)
    eb, length = bending_and_length(cp, seg_w, qtab, qw, bend, reg, ge, gl)
    ce = np.zeros(N_MIRROR_CLASSES)
    ec = mirrored_contact_energy_exhaustive(cp, ctab, aq, ax, ay, sx, r, rc, k, p, pm, pn, -1,
                                            with_grad, gc, gcell, ce)  # fmt: skip
    penalty = 0.0
    if gauge_stiffness > 0.0:
        penalty = length_spread(cp, gauge_rule, gauge_stiffness, with_grad, ge)
    if with_grad:
        gcell[0] *= cx
        _state_gradients(jac, ge, gl, gc, gcell, grad_e, grad_l)
    return eb, ec, length, penalty


KERNELS = {"culled": pattern_cell_energy, "exhaustive": _pattern_cell_energy_exhaustive}


@contextmanager
def garter_kernel(name: str):
    """CellModel's pattern kernel replaced by ``KERNELS[name]`` for the block."""
    saved = images_module.pattern_cell_energy
    images_module.pattern_cell_energy = KERNELS[name]
    try:
        yield
    finally:
        images_module.pattern_cell_energy = saved


class Clock:
    """CPU seconds and calls of the energy kernels, the Newton step and SLSQP."""

    NAMES = ("kernel", "kkt", "slsqp")

    def __init__(self) -> None:
        self.seconds = dict.fromkeys(self.NAMES, 0.0)
        self.calls = dict.fromkeys(self.NAMES, 0)

    @contextmanager
    def installed(self):
        saved = (CellModel.energy_and_gradients, newton._kkt_step, relaxer.slsqp_minimise)
        CellModel.energy_and_gradients = self._wrap(saved[0], "kernel")
        newton._kkt_step = self._wrap(saved[1], "kkt")
        relaxer.slsqp_minimise = self._wrap(saved[2], "slsqp")
        try:
            yield self
        finally:
            CellModel.energy_and_gradients, newton._kkt_step, relaxer.slsqp_minimise = saved

    def _wrap(self, f, kind):
        def timed(*args, **kwargs):
            t = time.process_time()
            try:
                return f(*args, **kwargs)
            finally:
                self.seconds[kind] += time.process_time() - t
                self.calls[kind] += 1

        return timed


def eval_seconds(stitch: str, repeats: int, min_time: float) -> float:
    """Median CPU seconds of one energy_and_gradients call at the first start."""
    model = CellModel(PARAMS.model_copy(update={"stitch": stitch}))
    x = model.stitch.start(1)
    model.energy_and_gradients(x)
    batch = 1
    while True:
        t = time.process_time()
        for _ in range(batch):
            model.energy_and_gradients(x)
        if time.process_time() - t >= min_time:
            break
        batch *= 2
    times = []
    for _ in range(repeats):
        t = time.process_time()
        for _ in range(batch):
            model.energy_and_gradients(x)
        times.append((time.process_time() - t) / batch)
    return statistics.median(times)


def relax_once(stitch: str) -> tuple[float, object, Clock]:
    """CPU seconds of zero_force from Init_1, its result and the clock of its parts."""
    clock = Clock()
    with clock.installed(), single_threaded():
        t = time.process_time()
        z = zero_force(PARAMS.model_copy(update={"stitch": stitch}),
                       starts=StartSettings(count=1))  # fmt: skip
        seconds = time.process_time() - t
    return seconds, z, clock


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3, help="zero-force runs per variant")
    ap.add_argument("--eval-repeats", type=int, default=7)
    ap.add_argument("--min-time", type=float, default=0.2)
    ap.add_argument("--kernels", default="culled,exhaustive",
                    help="garter contact kernels, comma-separated: culled, exhaustive")  # fmt: skip
    ap.add_argument("--skip-relax", action="store_true")
    args = ap.parse_args()
    kernels = [k.strip() for k in args.kernels.split(",") if k.strip()]
    for k in kernels:
        if k not in KERNELS:
            ap.error(f"--kernels: {k!r} is not one of {', '.join(KERNELS)}")
    variants = [("stockinette", "culled")] + [("garter", k) for k in kernels] + [("rib", "culled")]

    def context(stitch, kernel):
        return garter_kernel(kernel) if stitch == "garter" else garter_kernel("culled")

    print(f"L = {PARAMS.L_mm} mm, k = {PARAMS.k_mN_per_mm2} mN/mm^2; CPU seconds, medians")
    # warm-up (JIT, caches) of every variant
    for stitch, kernel in variants:
        with context(stitch, kernel):
            eval_seconds(stitch, 1, 0.0)
    evals: dict[tuple[str, str], list[float]] = {v: [] for v in variants}
    for _ in range(args.eval_repeats):  # alternate the variants run by run
        for v in variants:
            with context(*v):
                evals[v].append(eval_seconds(v[0], 1, args.min_time))
    ev = {v: statistics.median(t) for v, t in evals.items()}
    base = ev[variants[0]]
    print(f"\none energy_and_gradients call (median of {args.eval_repeats})")
    print(f"  {'stitch':<12}{'contact kernel':<16}{'us':>10}{'/ stockinette':>15}")
    for v in variants:
        print(f"  {v[0]:<12}{v[1]:<16}{ev[v] * 1e6:10.1f}{ev[v] / base:14.1f}x")
    if args.skip_relax:
        return
    relax_once("stockinette")  # warm-up of the solver's kernels
    runs: dict[tuple[str, str], list[tuple[float, object, Clock]]] = {v: [] for v in variants}
    for _ in range(args.repeats):
        for v in variants:
            with context(*v):
                runs[v].append(relax_once(v[0]))
    print(f"\nzero-force relaxation from Init_1, one start (median of {args.repeats})")
    print(f"  {'stitch':<12}{'kernel':<12}{'CPU s':>8}{'/ stock.':>9}{'stages':>7}"
          f"{'last it':>8}{'last ev':>8}{'evals':>7}{'E kern s':>9}{'kkt s':>7}{'kkt n':>7}"
          f"{'SLSQP s':>8}{'E [mJ]':>12}  status")  # fmt: skip
    rel = {v: statistics.median(s for s, _, _ in r) for v, r in runs.items()}
    for v in variants:
        _, z, clock = sorted(runs[v], key=lambda t: t[0])[len(runs[v]) // 2]
        b = z.best
        print(f"  {v[0]:<12}{v[1]:<12}{rel[v]:8.2f}{rel[v] / rel[variants[0]]:8.0f}x"
              f"{z.stages[z.winner]:7d}{b.iterations:8d}{b.evaluations:8d}"
              f"{clock.calls['kernel']:7d}{clock.seconds['kernel']:9.2f}{clock.seconds['kkt']:7.2f}"
              f"{clock.calls['kkt']:7d}{clock.seconds['slsqp']:8.2f}{b.total_energy:12.7f}  "
              f"{z.status}")  # fmt: skip
    print("  (last it/ev: the last stage's iterations and evaluations; evals: kernel calls of "
          "all stages; SLSQP s includes its kernel calls)")  # fmt: skip


if __name__ == "__main__":
    main()
