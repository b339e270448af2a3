"""Timing of one energy evaluation of the stitch cell, stage by stage.

Run: ``python benchmarks/bench_energy.py [--repeats 7] [--min-time 0.2]``

Golden case ``init1_paper`` (tests/data/golden_energy.json, case 0: Init_1 at
L = 11.6 mm, k = 0.1 mN/mm^2) at the paper's fidelity (N = 10 contact samples per
segment, 32 Gauss–Legendre nodes per segment), for both image modes. Each figure
is the median over ``--repeats`` runs of the mean time of one call in a batch of
calls lasting at least ``--min-time`` seconds, after a JIT warm-up. Calls go from
Python to the numba kernels with preallocated outputs, so every figure includes
one dispatch (its cost is printed). The kernels are single-threaded.

The speed-up is against the authors' code: one call of its total_energy at the
same state on this project's 2-core machine (tests/data/relaxed_reference.json,
``energy_eval_seconds``).

Not a test: nothing here passes or fails (STYLE.md, "benchmarks kept apart").
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import numba
import numpy as np
from numba import njit

from knitsweep.config import Fidelity, StitchParams
from knitsweep.kernels.bending import bending_and_length
from knitsweep.kernels.bezier import basis_tables, gauss_legendre, midpoints
from knitsweep.kernels.cell import cell_energy, cell_energy_listed
from knitsweep.kernels.contact import (
    EXCLUSION_FACTOR,
    IMAGES_CUTOFF,
    IMAGES_REFERENCE,
    contact_energy,
    find_contacts,
    midpoint_arclength,
    pair_potential,
    sample_path,
)
from knitsweep.kernels.neighbours import build_neighbour_list, contact_energy_listed
from knitsweep.model import CellModel
from knitsweep.stitches.stockinette.geometry import state_to_control_points
from knitsweep.stitches.stockinette.layout import IDX_AX, IDX_AY, N_STATE, SEGMENT_WEIGHTS

DATA = Path(__file__).resolve().parent.parent / "tests" / "data"
MODES = {"cutoff": IMAGES_CUTOFF, "reference": IMAGES_REFERENCE}  # Fidelity.images -> kernel
SKIN = 0.1  # mm, for the optional neighbour list rows


@njit
def _noop(x):
    return x[0]


@njit(cache=True)
def _brute_contact_energy(cp, tab, ax, ay, r, rc, k, p):
    """E_c without any culling, as the authors' code computes it: every ordered
    sample pair (i, j) in every image of the fixed box m in -1..1, n in -3..3.
    A measurement peer for the culled kernels (same sum, different order);
    returns (E_c, distance tests)."""
    n = tab.shape[1]
    ns = cp.shape[0] * n
    pts, r1, speed, s_mid = np.empty((ns, 3)), np.empty((ns, 3)), np.empty(ns), np.empty(ns)
    sample_path(cp, tab, pts, r1, speed)
    s_tot = midpoint_arclength(speed, 1.0 / n, s_mid)
    cut2 = 4.0 * r * r
    s_excl = EXCLUSION_FACTOR * r
    energy = 0.0
    tests = 0
    for m in range(-1, 2):
        for nn in range(-3, 4):
            for i in range(ns):
                for j in range(ns):
                    tests += 1
                    dx = pts[i, 0] - pts[j, 0] - m * ax
                    dy = pts[i, 1] - pts[j, 1] - nn * ay
                    dz = pts[i, 2] - pts[j, 2]
                    rr = dx * dx + dy * dy + dz * dz
                    if rr >= cut2:
                        continue
                    if nn == 0 and abs(s_mid[i] - s_mid[j] - m * s_tot) <= s_excl:
                        continue
                    v, _ = pair_potential(np.sqrt(rr), r, rc, k, p)
                    energy += v * speed[i] * speed[j] / (n * n)
    return energy, tests


def _time_call(fn, repeats: int, min_time: float) -> list[float]:
    """Seconds per call of ``fn()``: one mean per repeat, each over a batch of
    calls lasting at least ``min_time`` s."""
    fn()  # JIT warm-up (and cache load)
    number = 1
    while True:
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        elapsed = time.perf_counter() - t0
        if elapsed >= min_time:
            break
        number *= 2 if elapsed <= 0 else max(2, int(1.2 * min_time / elapsed))
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        out.append((time.perf_counter() - t0) / number)
    return out


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=7, help="timed repeats per figure (>= 5)")
    ap.add_argument("--min-time", type=float, default=0.1, help="seconds per timed batch")
    args = ap.parse_args()
    repeats = max(5, args.repeats)

    case = json.loads((DATA / "golden_energy.json").read_text())[0]
    ref_seconds = float(json.loads((DATA / "relaxed_reference.json").read_text())[
        "energy_eval_seconds"])  # fmt: skip
    P = case["params"]
    params = StitchParams.from_internal(P["L"], P["bend"], P["reg"], P["r"], P["rc"], P["k"],
                                        P["p"])  # fmt: skip
    ip = params.internal()
    n, nq = P["N"], 32
    x = np.array(case["x"], dtype=float)
    ax, ay = x[IDX_AX], x[IDX_AY]
    gx, gw = gauss_legendre(nq)
    qtab = basis_tables(gx)
    ctab = np.ascontiguousarray(basis_tables(midpoints(n))[:2])
    cp = np.empty((8, 6, 3))
    jac = np.empty((8, 6, 3, N_STATE))
    state_to_control_points(x, cp, jac)
    g1, g2, g3 = np.empty((8, 6, 3)), np.empty((8, 6, 3)), np.empty((8, 6, 3))
    gcell = np.empty(2)
    ge, gl = np.empty(N_STATE), np.empty(N_STATE)

    rows: dict[str, dict[str, float]] = {}

    def record(label: str, mode: str, fn) -> None:
        t = _time_call(fn, repeats, args.min_time)
        rows.setdefault(label, {})[mode] = statistics.median(t)

    energies = {}
    for mode, im in MODES.items():
        fid = Fidelity(samples_per_segment=n, quadrature_nodes=nq, images=mode)
        model = CellModel(params, fid)
        energies[mode] = model.energies(x)

        def cell(with_grad, im=im):  # the stitch's geometry, then the generic composition
            state_to_control_points(x, cp, jac)
            return cell_energy(cp, jac, ax, ay, qtab, gw, ctab, SEGMENT_WEIGHTS, ip.bend, ip.reg,
                               ip.r, ip.rc, ip.k, ip.p, im, with_grad, ge, gl)  # fmt: skip

        record("geometry: control points + Jacobian", mode,
               lambda: state_to_control_points(x, cp, jac))  # fmt: skip
        record("bending + length, with gradients", mode,
               lambda: bending_and_length(cp, SEGMENT_WEIGHTS, qtab, gw, ip.bend, ip.reg, g1, g2))  # fmt: skip
        record("contact: E_c", mode,
               lambda im=im: contact_energy(cp, ctab, ax, ay, ip.r, ip.rc, ip.k, ip.p, im, False,
                                            g3, gcell))  # fmt: skip
        record("contact: E_c + grad", mode,
               lambda im=im: contact_energy(cp, ctab, ax, ay, ip.r, ip.rc, ip.k, ip.p, im, True,
                                            g3, gcell))  # fmt: skip
        record("cell_energy: E (a)", mode, lambda cell=cell: cell(False))
        record("cell_energy: E + grad E + grad l (b)", mode, lambda cell=cell: cell(True))
        record("CellModel.energy_and_gradients (Python API)", mode,
               lambda model=model: model.energy_and_gradients(x))  # fmt: skip
        # optional Verlet list (kernels.neighbours): same sums, no box search
        nlist = build_neighbour_list(cp, ctab, ax, ay, ip.r, im, SKIN)
        record(f"neighbour list: build (skin {SKIN:g} mm)", mode,
               lambda im=im: build_neighbour_list(cp, ctab, ax, ay, ip.r, im, SKIN))  # fmt: skip
        record("neighbour list: contact E_c + grad", mode,
               lambda im=im, nl=nlist: contact_energy_listed(cp, ctab, ax, ay, ip.r, ip.rc, ip.k,
                                                             ip.p, im, True, g3, gcell, *nl))  # fmt: skip
        record("neighbour list: E + grad E + grad l (b)", mode,
               lambda im=im, nl=nlist: (state_to_control_points(x, cp, jac), cell_energy_listed(
                   cp, jac, ax, ay, qtab, gw, ctab, SEGMENT_WEIGHTS, ip.bend, ip.reg, ip.r, ip.rc,
                   ip.k, ip.p, im, True, ge, gl, *nl)))  # fmt: skip
        if mode == "cutoff":
            n_contacts = len(find_contacts(cp, ctab, ax, ay, ip.r, im)[3])
    # the saving of culling, against the authors' fixed image box searched in full
    e_brute, brute_tests = _brute_contact_energy(cp, ctab, ax, ay, ip.r, ip.rc, ip.k, ip.p)
    t_brute = statistics.median(_time_call(
        lambda: _brute_contact_energy(cp, ctab, ax, ay, ip.r, ip.rc, ip.k, ip.p),
        repeats, args.min_time))  # fmt: skip
    dispatch = statistics.median(_time_call(lambda: _noop(x), repeats, args.min_time))

    print("knitsweep energy benchmark (single-threaded: numba kernels, no parallel=True; one core)")
    print(f"  case init1_paper: N = {n} samples/segment, {nq} Gauss-Legendre nodes/segment, "
          f"{n_contacts} counted contacts")  # fmt: skip
    print(f"  {_cpu_name()}, {os.cpu_count()} CPUs; numba {numba.__version__}, "
          f"numpy {np.__version__}, Python {platform.python_version()}")  # fmt: skip
    print(f"  median of {repeats} repeats, each the mean of a batch of >= {args.min_time:g} s; "
          f"Python->numba dispatch ~{dispatch * 1e6:.2f} us/call included")  # fmt: skip
    for mode in MODES:
        e = energies[mode]
        print(f"  E_b = {e.bending_energy:.15g} mJ, E_c = {e.contact_energy:.15g} mJ, "
              f"l = {e.length:.15g} mm ({mode})")  # fmt: skip
    print()
    width = max(len(k) for k in rows) + 2
    print(f"{'stage':<{width}}{'cutoff [us]':>13}{'reference [us]':>16}")
    print("-" * (width + 29))
    for label, by_mode in rows.items():
        print(
            f"{label:<{width}}{by_mode['cutoff'] * 1e6:>13.1f}{by_mode['reference'] * 1e6:>16.1f}"
        )
    print()
    t_cull = rows["contact: E_c"]["cutoff"]
    print(f"culling vs. the authors' fixed box searched in full (E_c alone): brute force "
          f"{t_brute * 1e6:.1f} us, {brute_tests:,} ordered distance tests (E_c = {e_brute:.15g}, "
          f"rel. diff {abs(e_brute / energies['cutoff'].contact_energy - 1):.1e}); culled "
          f"{t_cull * 1e6:.1f} us: x{t_brute / t_cull:.1f}")  # fmt: skip
    print(
        f"authors' code, one E evaluation: {ref_seconds:.3f} s "
        "(relaxed_reference.json energy_eval_seconds)"
    )
    for mode in MODES:
        a = rows["cell_energy: E (a)"][mode]
        b = rows["cell_energy: E + grad E + grad l (b)"][mode]
        print(
            f"speed-up ({mode:>9}): (a) E alone x{ref_seconds / a:,.0f}; "
            f"(b) E + grad E + grad l x{ref_seconds / b:,.0f} against one E of theirs"
        )


if __name__ == "__main__":
    main()
