"""Synthetic results files (schema 1, written with h5py) whose jamming gaps are known
exactly, for the post-processor's tests.

Yarn radius r = 0.5 mm, so L/r = 2 L exactly. Each series has L/r = 20 … 24; the
gap of the pulling direction lies on a straight line through the jammed points:

* k = 0.1, x: ΔE_c = 2e-4 (22.5 − L/r) at 20, 21, 22; 1e-5 at 23; 0 at 24
  → (L/r)_trans = 23, bracket (22, 23), line zero at 22.5, ΔL/r = 0.5;
* k = 0.1, y: ΔE_b = 2e-4 (23.5 − L/r) at 20 … 23; 0 at 24
  → (L/r)_trans = 24, bracket (23, 24), zero at 23.5, ΔL/r = 0.5;
* k = 1.0, x: ΔE_c = 2e-4 (23.8 − L/r) at 20 … 23; 0 at 24
  → (L/r)_trans = 24, bracket (23, 24), zero at 23.8, ΔL/r = 0.2;
* k = 1.0, y: ΔE_b = 1e-3 at every L/r → jammed throughout.

Regimes at k = 0.1: 20–22 jammed_xy, 23 jammed_y_only, 24 unjammed.
"""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import h5py
import numpy as np

from knitsweep.formats import shipped_state

R_MM = 0.5
L_OVER_R = (20.0, 21.0, 22.0, 23.0, 24.0)


def gap(k: float, direction: str, x: float) -> float:
    """The jamming gap (mJ) of the synthetic series at L/r = x."""
    if k == 0.1 and direction == "x":
        return 2e-4 * (22.5 - x) if x <= 22.0 else (1e-5 if x == 23.0 else 0.0)
    if k == 0.1 and direction == "y":
        return 2e-4 * (23.5 - x) if x <= 23.0 else 0.0
    if k == 1.0 and direction == "x":
        return 2e-4 * (23.8 - x) if x <= 23.0 else 0.0
    return 1e-3


def _params(L: float, k: float, stitch: str = "stockinette") -> dict:
    params = {"L_mm": L, "k_mN_per_mm2": k, "B_mN_mm2": 90.0, "r_mm": R_MM, "r_core_mm": 0.22,
              "p": 2.4, "regularization_mN_mm4": 2.0, "twist_bound": 0.9}  # fmt: skip
    return params if stitch == "stockinette" else {**params, "stitch": stitch}  # as stored


def _attrs(group, params: dict, status: str, message: str = "") -> None:
    group.attrs["status"] = status
    group.attrs["message"] = message
    group.attrs["params"] = json.dumps(params, sort_keys=True)
    for key, value in params.items():
        group.attrs[key] = value
    group.attrs["L_over_r"] = params["L_mm"] / params["r_mm"]


def _period_scale(stitch: str) -> float:
    """a_y of ``stitch``'s first start over stockinette's (garter's cell spans two rows):
    its states' a_y are the stockinette ones times this."""
    return float(shipped_state(1, stitch)[-1] / shipped_state(1)[-1])


def _sweep_arrays(
    direction: str, x: float, g: float, contact_forces: bool, stitch: str = "stockinette"
) -> dict:
    n = 31
    strain = np.linspace(0.0, 0.3, n)
    profile = np.r_[1.0, np.linspace(0.6, 0.0, 10), np.linspace(0.05, 0.5, n - 11)]
    gap_b, gap_c = (g, 0.0) if direction == "y" else (0.0, g)
    a0 = (2.5 + 0.01 * x, 1.9 + 0.005 * x)
    stretch = 1.0 + strain
    a_x = a0[0] * (stretch if direction == "x" else 1.0 - 0.2 * strain)
    a_y = a0[1] * (stretch if direction == "y" else 1.0 - 0.3 * strain)
    if direction == "biaxial":
        a_x, a_y = a0[0] * stretch, a0[1] * stretch
    elif direction == "strip_x":
        a_x, a_y = a0[0] * stretch, np.full(n, a0[1])
    elif direction == "ray:1,-0.2":
        a_x, a_y = a0[0] * stretch, a0[1] * (1.0 - 0.2 * strain)
    if direction == "y" and g == 0.0:  # unjammed in y: the area first shrinks (paper Fig. 5b)
        a_x = a0[0] * (1.0 - 1.3 * strain + 2.0 * strain**2)
    out = {
        "strain": strain,
        "stress": 0.02 * strain / (0.01 + strain) + 0.5 * strain**2 * (1.0 + 0.02 * x),
        "bending_energy": 0.3 + gap_b * profile,  # ΔE_b = E_b[0] − min E_b = gap_b
        "contact_energy": 0.01 + gap_c * profile,
        "a_x": a_x,
        "a_y": a_y,
        "a_fixed": a_x if direction == "x" else a_y,
        "thickness": 2.3 * (1.0 - 0.05 * strain + (0.2 + 0.01 * (x - 20)) * strain**2),
        "converged": np.ones(n, dtype=bool),
        "winner": np.zeros(n, dtype=np.int64),
    }
    out["total_energy"] = out["bending_energy"] + out["contact_energy"]
    out["stress_envelope"] = out["stress"].copy()
    across = {"x": 0.0, "y": 0.0, "biaxial": 0.8, "strip_x": 0.4, "ray:1,-0.2": 0.1}[direction]
    main, other = out["stress"], across * out["stress"]
    out["stress_xx"], out["stress_yy"] = (other, main) if direction == "y" else (main, other)
    out["packing_fraction"] = 0.9 - 0.004 * (x - 20.0) - 0.1 * strain  # [store] packing_fraction
    out["packing_fraction_error"] = np.full(n, 1e-3)
    states = np.tile(shipped_state(1, stitch), (n, 1))  # [store] states: a real stitch's
    states[:, -2], states[:, -1] = a_x, a_y * _period_scale(stitch)  # (for the forces)
    out["states"] = states
    if contact_forces:
        out["contact_forces"] = np.tile(_forces(x), (n, 1, 1))
    return out


def _forces(x: float) -> np.ndarray:
    f = np.zeros((5, 3))
    f[0] = (0.02, 0.01, 0.005)
    f[1] = (0.03 - 0.001 * (x - 20), 0.002, 0.01)
    f[2] = (0.005, 0.02 + 0.004 * (x - 20), 0.01)
    f[3] = (0.001, 0.01, 0.002)
    return f


def write_results(
    path: Path,
    *,
    ks: tuple[float, ...] = (0.1, 1.0),
    run_status: str = "complete",
    contact_forces: bool = True,
    not_knittable_L: float | None = 9.5,
    stitches: tuple[str, ...] = ("stockinette",),
    failed_L: float | None = None,
    directions: tuple[str, ...] = ("x", "y"),
) -> Path:
    """A results file with series at every k of ``ks``, every load path of ``directions``
    (the biaxial ones with x's gaps), plus (if
    ``not_knittable_L``) one not-knittable point whose sweeps carry no arrays and (if
    ``failed_L``) one failed point whose sweeps failed with it; each series once per
    stitch of ``stitches`` (the same data, another pattern's name)."""
    n_points = 0
    with h5py.File(path, "w") as f:
        f.attrs["schema_version"] = 1
        f.attrs["job_name"] = "synthetic"
        f.attrs["job_json"] = json.dumps({"name": "synthetic"})
        f.attrs["run_status"] = run_status
        points, sweeps = f.create_group("points"), f.create_group("sweeps")
        for stitch, k in itertools.product(stitches, ks):
            tag = "" if stitch == "stockinette" else f"{stitch}_"
            for x in L_OVER_R:
                L = x * R_MM
                pid = f"{tag}p{k:g}_{x:g}"
                pg = points.create_group(pid)
                _attrs(pg, _params(L, k, stitch), "done", "lowest of 1 starts")
                state = shipped_state(1, stitch)[None, :].copy()  # real, for the pair forces
                a_y = (1.9 + 0.005 * x - 0.002 * (x - 22.0) ** 2) * _period_scale(stitch)
                state[0, -2:] = (2.5 + 0.01 * x, a_y)
                pg["x"] = state
                pg["bending_energy"] = np.array([0.3])
                pg["contact_energy"] = np.array([0.01])
                pg.attrs["winner"] = 0
                pg.attrs["thickness"] = 2.3
                pg["packing_fraction"] = np.array([0.9 - 0.004 * (x - 20.0)])
                pg["packing_fraction_error"] = np.array([1e-3])
                if contact_forces:
                    pg["contact_forces"] = _forces(x)
                n_points += 1
                for d in directions:
                    sg = sweeps.create_group(f"{tag}s{k:g}_{x:g}_{d}")
                    _attrs(sg, _params(L, k, stitch), "done", "stress 0.3 N/mm > 0.2")
                    sg.attrs["point_id"] = pid
                    sg.attrs["direction"] = d
                    sg.attrs["sweep_status"] = "done"
                    g = gap(k, "y" if d == "y" else "x", x)
                    arrays = _sweep_arrays(d, x, g, contact_forces, stitch)
                    for name, value in arrays.items():
                        sg[name] = value
            if not_knittable_L is not None:
                pg = points.create_group(f"{tag}p{k:g}_nk")
                _attrs(pg, _params(not_knittable_L, k, stitch), "not_knittable", "cores overlap")
                n_points += 1
                for d in directions:
                    sg = sweeps.create_group(f"{tag}s{k:g}_nk_{d}")
                    _attrs(sg, _params(not_knittable_L, k, stitch), "not_knittable",
                           "zero-force state: cores overlap")  # fmt: skip
                    sg.attrs["point_id"] = f"{tag}p{k:g}_nk"
                    sg.attrs["direction"] = d
            if failed_L is not None:
                why = "no start converged; best (Init_1): length constraint missed by 1.79 mm"
                pg = points.create_group(f"{tag}p{k:g}_failed")
                _attrs(pg, _params(failed_L, k, stitch), "failed", why)
                n_points += 1
                for d in directions:
                    sg = sweeps.create_group(f"{tag}s{k:g}_failed_{d}")
                    _attrs(sg, _params(failed_L, k, stitch), "failed", f"zero-force state: {why}")
                    sg.attrs["point_id"] = f"{tag}p{k:g}_failed"
                    sg.attrs["direction"] = d
        f.attrs["n_points"] = n_points
        f.attrs["n_sweeps"] = len(directions) * n_points
    return path
