"""How far numbers move from one CPU to another: the tiny test job, the golden energies
and the relaxed reference computed with the kernels compiled for this host and again
for a generic x86-64 (``NUMBA_CPU_NAME=generic``), each in a fresh process with an
empty numba cache, compared value by value.

Run: ``python benchmarks/cpu_spread.py [--cpus host generic] [--keep DIR]``

numba compiles for the host CPU (AVX-512 where there is one, fused multiply-adds,
other vector widths and summation orders); the LAPACK calls pick their kernels at run
time. So a number computed on one machine differs in its last bits from the same number
computed on another, and a test that compares a shipped file with a fresh run can only
compare what the CPU cannot change (tests/test_integrity.py's schema-2 tests: tasks, array
names and kinds, the inputs; the golden energies within 1e-12). This prints, per kind of value, the largest difference
relative to the largest magnitude of that array (``|a - b|_max / |a|_max``: an array
that passes through zero, such as a stress curve, is not inflated by it), between the
CPUs and between each CPU and the shipped ``tests/data/schema2_tiny.h5``.

Not a test: nothing here passes or fails (STYLE.md, "benchmarks kept apart").
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data"
SKIP = {"seconds", "relax_seconds", "wall_seconds", "rank", "host", "started_at"}

CHILD = r"""
import json, sys
import numpy as np
from knitsweep import service
from knitsweep.config import Fidelity, StitchParams
from knitsweep.model import CellModel

out = sys.argv[1]
service.run(sys.argv[2], out + ".h5", executor="serial", show_progress=False)
golden = {}
for case in json.loads(open(sys.argv[3]).read()):
    P = case["params"]
    params = StitchParams.from_internal(P["L"], P["bend"], P["reg"], P["r"], P["rc"], P["k"], P["p"])
    for images in ("cutoff", "reference"):
        e = CellModel(params, Fidelity(samples_per_segment=P["N"], images=images)).energies(
            np.array(case["x"]))
        golden[case["name"] + "/" + images] = [e.bending_energy, e.contact_energy, e.length,
                                               e.total_energy]
json.dump(golden, open(out + ".json", "w"))
"""


def compute(cpu: str, where: Path) -> Path:
    """Run the child with the kernels compiled for ``cpu`` ("host": numba's default) in
    an empty cache; the stem of its outputs."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1",
           "NUMBA_CACHE_DIR": tempfile.mkdtemp(prefix=f"numba-{cpu}-", dir=where)}  # fmt: skip
    env.pop("NUMBA_CPU_NAME", None)
    if cpu != "host":
        env["NUMBA_CPU_NAME"] = cpu
    stem = where / cpu
    subprocess.run([sys.executable, "-c", CHILD, str(stem), str(DATA / "jobs" / "tiny.toml"),
                    str(DATA / "golden_energy.json")], check=True, env=env)  # fmt: skip
    return stem


def arrays(path: Path) -> dict[tuple[str, str, str], np.ndarray]:
    from knitsweep.store.read import iter_entries

    out = {}
    for e in iter_entries(path, with_data=True):
        for name, v in e.record.items():
            a = np.asarray(v)
            if name not in SKIP and a.dtype.kind == "f":
                out[(e.kind, e.task_id, name)] = a
    return out


def spread(a: dict, b: dict) -> dict[str, tuple[float, int, int, int]]:
    """Per array name: (largest scale-relative difference over the rows both have,
    arrays differing, arrays, arrays of different lengths: a sweep that stopped a step
    earlier or later)."""
    worst: dict[str, list] = {}
    for key in sorted(a.keys() & b.keys()):
        x, y = a[key], b[key]
        w = worst.setdefault(key[2], [0.0, 0, 0, 0])
        w[2] += 1
        if x.shape != y.shape:
            w[3] += 1
            n = min(len(x), len(y))
            x, y = x[:n], y[:n]
        ok = np.isfinite(x) & np.isfinite(y)
        if not np.array_equal(x[ok], y[ok]):
            w[1] += 1
            scale = max(np.abs(x[ok]).max(initial=0.0), np.abs(y[ok]).max(initial=0.0))
            w[0] = max(w[0], float(np.abs(x[ok] - y[ok]).max() / scale) if scale else 0.0)
    return {k: tuple(v) for k, v in worst.items()}


def show(title: str, table: dict) -> None:
    print(f"\n{title}")
    print(f"  {'value':<28} {'max rel diff':>13} {'differ':>9} {'lengths differ':>15}")
    for name, (rel, n, total, longer) in sorted(table.items(), key=lambda kv: -kv[1][0]):
        print(f"  {name:<28} {rel:13.2e} {n:>4}/{total:<4} {longer:>15}")
    print(f"  {'largest':<28} {max(v[0] for v in table.values()):13.2e}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cpus", nargs=2, default=["host", "generic"])
    ap.add_argument("--keep", type=Path, help="write the outputs here (default: a temporary dir)")
    args = ap.parse_args()
    where = args.keep or Path(tempfile.mkdtemp(prefix="cpu-spread-"))
    where.mkdir(parents=True, exist_ok=True)
    a, b = (compute(cpu, where) for cpu in args.cpus)
    A, B = arrays(a.with_suffix(".h5")), arrays(b.with_suffix(".h5"))
    shipped = arrays(DATA / "schema2_tiny.h5")
    show(f"tiny job: {args.cpus[0]} vs {args.cpus[1]}", spread(A, B))
    show(f"tiny job: {args.cpus[0]} vs shipped schema2_tiny.h5", spread(A, shipped))
    show(f"tiny job: {args.cpus[1]} vs shipped schema2_tiny.h5", spread(B, shipped))
    ga = json.loads(a.with_suffix(".json").read_text())
    gb = json.loads(b.with_suffix(".json").read_text())
    ref = {c["name"]: [c["bending_energy"], c["contact_energy"], c["length"], c["total_energy"]]
           for c in json.loads((DATA / "golden_energy.json").read_text())}  # fmt: skip
    names = ("bending_energy", "contact_energy", "length", "total_energy")

    def golden_rel(x, y):
        rel = [0.0] * 4
        for key in x:
            for i in range(4):
                u, v = x[key][i], y[key][i]
                rel[i] = max(rel[i], abs(u - v) / max(abs(u), abs(v), 1e-300))
        return rel

    between = golden_rel(ga, gb)
    to_ref = golden_rel(ga, {k: ref[k.split("/")[0]] for k in ga})
    print(f"\ngolden energies ({len(ga)} cases x images): largest relative difference")
    print(
        f"  {'value':<16} {args.cpus[0] + ' vs ' + args.cpus[1]:>18} {args.cpus[0] + ' vs golden':>18}"
    )
    for i, n in enumerate(names):
        print(f"  {n:<16} {between[i]:18.2e} {to_ref[i]:18.2e}")
    print(f"\noutputs in {where}")


if __name__ == "__main__":
    main()
