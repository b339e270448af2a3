"""Reduce a results file to the paper's tables (docs/model.md §9; paper Sections IV–VII).

One pass over a results file (``knitsweep run``; schema in :mod:`knitsweep.store.writer`),
read through :func:`knitsweep.store.read.iter_entries`, so that results still in a
running job's journal count too. Out come plain rows (dicts of str, float, int, bool
or None), ready for CSV, printing and the figures of :mod:`.figures`:

* one row per sweep: Y_sec at ε = 0.02 (N/mm), σ0 (N/mm, fitted to the envelope
  stress) or why there is none, whether the stress curve drops where the winning start
  switches, the gaps ΔE_b and ΔE_c (mJ = N·mm, the paper's "J"), the zero-force
  aspect ratio a_y0/a_x0, extremes of the area and thickness strains, and the contact
  forces by class at zero strain (N) when the file stores them;
* one row per series (fixed k, B, r_core, r, p and direction): (L/r)_trans, its
  bracket, the Table S4 line fit of the linear jammed regime, its zero and ΔL/r
  (paper Fig. 4a);
* one row per point: the zero-force state, its regime (paper Fig. 4c, 5a) and, when
  the job stored contact forces, the paper's pair forces by class and their Fig. 6h
  ratio (computed here from the zero-force state);
* one row per task that failed or was not knittable (listed, never fatal).

Units throughout: L in mm, L/r dimensionless, k in mN/mm², B in mN·mm², r and
r_core in mm, energies in mJ, stresses in N/mm, forces in N.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..analysis import GAP_THRESHOLD, area_strain, regime, sweep_metrics, thickness_strain
from ..analysis.stress_strain import FD_STRESS_SMOOTHING
from ..analysis.transitions import Transition
from ..config import Fidelity
from ..errors import InputError
from ..paths import load_path
from ..quantities import NUMERIC_SERIES_PARAMS, SERIES_PARAMS, registered, sweep_observables
from ..service.spread import POINT_SPREADS, SWEEP_SPREADS
from ..stitches import DEFAULT_STITCH
from ..store.format import POINTS, SWEEPS
from ..store.journal import Entry
from ..store.read import read_files
from ..util.plain_values import plain_value
from .force_columns import (
    PAIR_KEYS,
    contact_classes,
    force_columns,
    job_fidelity,
    pair_force_columns,
)
from .series import (
    add_adaptive_brackets,
    add_reference_shifts,
    mark_failed,
    series_key,
    series_values,
    transition_rows,
)

MIN_THRESHOLD, MAX_THRESHOLD = 1e-12, 1.0
"""The energy-gap thresholds (mJ) a reduction accepts (the paper's: GAP_THRESHOLD)."""
_SWEEP_ARRAYS = ("strain", "stress", "bending_energy", "contact_energy", "a_x", "a_y", "thickness")
_REQUIRED_META = ("status", "L_mm", "L_over_r", *NUMERIC_SERIES_PARAMS)
"""Attributes every task has (``stitch`` is absent for the default stitch)."""


@dataclass(frozen=True)
class SweepCurves:
    """Per-step arrays of one analysed sweep, shape (n,) each, for the figures.

    ``strain`` (dimensionless), ``stress`` (N/mm), ``area_strain`` and
    ``thickness_strain`` (dimensionless), ``bending_energy``/``contact_energy`` (mJ),
    ``packing_fraction`` (dimensionless; None unless the job stored it),
    ``transverse_strain`` a_⊥/a_⊥0 − 1 of the period left free (uniaxial paths; else None).
    """

    task_id: str
    direction: str
    L_mm: float
    L_over_r: float
    series: tuple[Any, ...]
    jammed: bool
    strain: np.ndarray
    stress: np.ndarray
    area_strain: np.ndarray
    thickness_strain: np.ndarray
    bending_energy: np.ndarray
    contact_energy: np.ndarray
    packing_fraction: np.ndarray | None = None
    transverse_strain: np.ndarray | None = None

    @property
    def poisson_ratio(self) -> np.ndarray:
        """ν(ε) = −ε_⊥/ε along a uniaxial pull, secant from the rest (NaN at ε = 0 and
        on other paths); at ε = 0.02 it is the tables' ``poisson_ratio``."""
        if self.transverse_strain is None:
            return np.full_like(self.strain, np.nan)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.strain > 0.0, -self.transverse_strain / self.strain, np.nan)


@dataclass(frozen=True)
class Reduction:
    """Everything the phase-diagram command prints, writes and plots.

    Attributes:
        path: the (first) results file; paths: all of them.
        job_name, run_status: from the file's root attributes.
        partial: True unless the run is 'complete' and every planned task is present.
        partial_reason: why it is partial (None when it is not).
        n_expected: tasks the job plans (points + sweeps); n_found: tasks present.
        threshold: the energy-gap threshold, mJ.
        sweeps, transitions, points, problems: the table rows (see module docstring).
        curves: per-step arrays of every analysed sweep.
        transition_of: {(series values, direction): Transition}; the values are those
            of ``SERIES_PARAMS`` (the stitch's name first), so stitches never share one.
        varying: the series parameters that take more than one value in the file.
        constants: the series parameters that take one value, with it (the stitch
            only if it is not the default one).
        notes: remarks worth printing (e.g. an adaptive bracket that disagrees).
        entries: every task read (with its arrays), for the per-step tables.
        roots: each file's root attributes (with ``file`` and ``n_found``).
    """

    path: Path
    job_name: str
    run_status: str
    partial: bool
    partial_reason: str | None
    n_expected: int
    n_found: int
    threshold: float
    sweeps: list[dict[str, Any]] = field(default_factory=list)
    transitions: list[dict[str, Any]] = field(default_factory=list)
    points: list[dict[str, Any]] = field(default_factory=list)
    problems: list[dict[str, Any]] = field(default_factory=list)
    curves: list[SweepCurves] = field(default_factory=list)
    transition_of: dict[tuple[tuple[Any, ...], str], Transition] = field(default_factory=dict)
    varying: tuple[str, ...] = ()
    constants: dict[str, Any] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    paths: tuple[Path, ...] = ()
    entries: list[Entry] = field(default_factory=list, repr=False)
    roots: list[dict[str, Any]] = field(default_factory=list, repr=False)

    @property
    def status_line(self) -> str:
        """One line: job, run status and counts (with 'PARTIAL' and why, if so)."""
        n_sw = sum(1 for p in self.problems if p["kind"] == "sweep")
        text = (
            f"{' + '.join(p.name for p in self.paths or (self.path,))}: job {self.job_name}, "
            f"run_status {self.run_status}; "
            f"{len(self.points)} points, {len(self.sweeps)} sweeps analysed"
            f"{f', {len(self.problems)} tasks not analysed ({n_sw} sweeps)' if self.problems else ''}"
            f"; gap threshold {self.threshold:g} mJ"
        )
        return f"PARTIAL ({self.partial_reason}) — {text}" if self.partial else text


def _check_meta(path: Path, entry: Entry) -> dict[str, Any]:
    meta = {k: plain_value(v) for k, v in entry.meta.items()}
    need = _REQUIRED_META + (("direction",) if entry.kind == SWEEPS else ())
    missing = [k for k in need if k not in meta]
    if missing:
        raise InputError(
            f"{path}: {entry.kind[:-1]} {entry.task_id} lacks attribute(s) "
            f"{', '.join(missing)}: not a knitsweep results file of this schema"
        )
    for k in _REQUIRED_META[1:]:  # the parameters: numbers (a foreign file may hold text)
        if isinstance(meta[k], bool) or not isinstance(meta[k], (int, float)):
            raise InputError(f"{path}: {entry.kind[:-1]} {entry.task_id}: {k} = {meta[k]!r}: "
                             "must be a number: not a knitsweep results file of this schema")  # fmt: skip
    if not isinstance(meta.get("stitch", DEFAULT_STITCH), str):
        raise InputError(f"{path}: {entry.kind[:-1]} {entry.task_id}: stitch = "
                         f"{meta['stitch']!r}: must be a stitch's name: not a knitsweep results "
                         "file of this schema")  # fmt: skip
    return meta


def _base_row(entry: Entry, meta: Mapping[str, Any]) -> dict[str, Any]:
    row = {"task_id": entry.task_id, "status": str(meta["status"])}
    if entry.kind == SWEEPS:
        row |= {"point_id": str(meta.get("point_id", "")), "direction": str(meta["direction"])}
    row |= {"L_mm": float(meta["L_mm"]), "L_over_r": float(meta["L_over_r"])}
    row |= dict(zip(SERIES_PARAMS, series_values(meta), strict=True))
    return row


def _point_row(entry: Entry, meta: Mapping[str, Any], fidelity: Fidelity) -> dict[str, Any]:
    """Zero-force state of one point: periods (mm), aspect ratio, energies (mJ),
    stored generalised and computed pair contact forces (N)."""
    row = _base_row(entry, meta)
    rec = entry.record
    x = rec.get("x")
    winner = int(meta.get("winner", rec.get("winner", 0)) or 0)
    best = None
    if x is not None and np.ndim(x) == 2 and row["status"] == "done":
        best = np.asarray(x[winner], dtype=float)
        a_x0, a_y0 = float(best[-2]), float(best[-1])  # a state ends with its periods
        row |= {
            "a_x0_mm": a_x0,
            "a_y0_mm": a_y0,
            "aspect_ratio": a_y0 / a_x0,
            "E_b_rest_mJ": float(rec["bending_energy"][winner]),
            "E_c_rest_mJ": float(rec["contact_energy"][winner]),
            # a lower minimum a sweep found from this point and started over from
            "rest_found_by": plain_value(meta.get("rest_found_by")),
            "rest_fall_mJ": plain_value(meta.get("rest_fall_mJ")),
        }
        row |= {o.column: plain_value(meta.get(o.name)) for o in registered("point")}
        row |= spread_columns(meta, POINT_SPREADS)
        phi = rec.get("packing_fraction")
        if phi is not None and len(phi) > winner:
            row["packing_fraction"] = plain_value(phi[winner])
            row["packing_fraction_error"] = plain_value(rec["packing_fraction_error"][winner])
    stored = rec.get("contact_forces")
    row |= force_columns(stored, contact_classes(meta))
    row |= pair_force_columns(best if stored is not None else None, meta, fidelity)
    return row


def _fall_below_rest(arrays: Mapping[str, np.ndarray]) -> float:
    """How far (mJ) a sweep's energy fell below its first step's, 0 if never."""
    e = arrays["bending_energy"] + arrays["contact_energy"]
    return float(max(0.0, e[0] - np.min(e)))


def _analyse_sweep(
    entry: Entry, meta: Mapping[str, Any], point_forces: Any, threshold: float
) -> tuple[dict[str, Any], SweepCurves]:
    """Metrics row and curves of one done sweep; ValueError if its arrays are unusable.

    σ0 is fitted to the envelope stress where the sweep stores one (schema 1 files
    may not), so that the stress drops of start switches do not hide it."""
    rec = entry.record
    missing = [k for k in _SWEEP_ARRAYS if k not in rec]
    if missing:
        raise ValueError(f"no array(s) {', '.join(missing)}")
    arrays = {k: np.asarray(rec[k], dtype=float) for k in _SWEEP_ARRAYS}
    envelope = rec.get("stress_envelope")
    if envelope is not None and not np.all(np.isfinite(envelope)):
        envelope = None
    direction = str(meta["direction"])
    m = sweep_metrics(direction, **arrays, stress_envelope=envelope, winner=rec.get("winner"),
                      **FD_STRESS_SMOOTHING)  # fmt: skip
    row = _base_row(entry, meta)
    row |= {
        "sweep_status": str(meta.get("sweep_status", "")),
        "rest_restarts": int(meta.get("rest_restarts", 0)),
        "rest_skew": float(meta.get("rest_skew", 0.0)),
        "rest_skew_fall_mJ": float(meta.get("rest_skew_fall_mJ", 0.0)),
        # > 0: the sweep fell below the state it started from (after its restarts): it
        # did not start at its path's minimum, its modulus and gaps are not verdicts
        "fall_below_rest_mJ": _fall_below_rest(arrays),
        "n_steps": m.n_steps,
        "max_strain": m.max_strain,
        "max_stress_N_per_mm": m.max_stress,
        "Y_sec_N_per_mm": m.secant.Y_sec,
        "stress_at_secant_N_per_mm": m.secant.stress_at,
        "sigma0_N_per_mm": m.offset.sigma0,
        "softened_slope_N_per_mm": m.offset.slope,
        "has_linear_regime": m.offset.has_linear_regime,
        "sigma0_source": m.sigma0_source,
        "sigma0_window_lo": m.offset.window[0] if m.offset.window else None,
        "sigma0_window_hi": m.offset.window[1] if m.offset.window else None,
        "sigma0_reason": m.offset.reason,
        "stress_discontinuous": m.drops.discontinuous,
        "n_switching_drops": m.drops.n_switching_drops,
        "first_switching_drop_strain": m.drops.first_drop_strain,
        "delta_E_b": m.gaps.delta_E_b,
        "delta_E_c": m.gaps.delta_E_c,
        "jamming_gap": m.jamming_gap,
        "E_b_rest_mJ": m.gaps.E_b_rest,
        "E_c_rest_mJ": m.gaps.E_c_rest,
        "a_x0_mm": m.a_x0,
        "a_y0_mm": m.a_y0,
        "aspect_ratio": m.aspect_ratio,
        "thickness0_mm": m.thickness0,
        "area_strain_min": m.area_strain_min,
        "area_strain_max": m.area_strain_max,
        "min_area_at_zero_force": m.min_area_at_zero_force,
        "thickness_strain_min": m.thickness_strain_min,
        "thickness_strain_max": m.thickness_strain_max,
        "thickness_strain_at_secant": m.thickness_strain_at,
        "jammed": m.jamming_gap >= threshold,
        **sweep_observables(rec, direction),
        **spread_columns(meta, SWEEP_SPREADS),
    }
    if "spread_delta_E_b" in meta:  # the gap that decides, and its spread over starts
        decides = "delta_E_b" if m.jamming_gap == m.gaps.delta_E_b else "delta_E_c"
        row["within_round_off"] = bool(abs(m.jamming_gap - threshold)
                                       <= float(meta[f"spread_{decides}"]))  # fmt: skip
    stored = rec.get("contact_forces")
    zero_forces = np.asarray(stored)[0] if stored is not None and len(stored) else point_forces
    row |= force_columns(zero_forces, contact_classes(meta))
    curves = SweepCurves(
        task_id=entry.task_id,
        direction=direction,
        L_mm=row["L_mm"],
        L_over_r=row["L_over_r"],
        series=tuple(row[k] for k in SERIES_PARAMS),
        jammed=row["jammed"],
        strain=arrays["strain"],
        stress=arrays["stress"],
        area_strain=area_strain(arrays["a_x"], arrays["a_y"]),
        thickness_strain=thickness_strain(arrays["thickness"]),
        bending_energy=arrays["bending_energy"],
        contact_energy=arrays["contact_energy"],
        packing_fraction=_optional_array(rec.get("packing_fraction")),
        transverse_strain=_transverse_strain(arrays, direction),
    )
    return row, curves


_SPREAD_UNITS = {"E_rest": "mJ", "a_x0": "mm", "a_y0": "mm", "delta_E_b": "mJ", "delta_E_c": "mJ",
                 "Y_sec": "N_per_mm"}  # fmt: skip


def spread_columns(meta: Mapping[str, Any], fields: Mapping[str, str]) -> dict[str, Any]:
    """The ``…_spread`` columns of a task whose job asked for them (``[starts] spread``):
    per field of ``fields`` (record name -> column stem) its spread over starts, and
    ``spread_count``; none for a task without them."""
    if not any(f in meta for f in fields):
        return {}
    out = {f"{stem}_spread_{_SPREAD_UNITS[stem]}": plain_value(meta.get(f))
           for f, stem in fields.items()}  # fmt: skip
    return out | {"spread_count": plain_value(meta.get("spread_count"))}


def _transverse_strain(arrays: Mapping[str, np.ndarray], direction: str) -> np.ndarray | None:
    """a_⊥/a_⊥0 − 1 of the period a uniaxial path leaves free; None on other paths."""
    path = load_path(direction)
    if not path.uniaxial:
        return None
    across = np.asarray(arrays["a_" + path.transverse], dtype=float)
    return across / across[0] - 1.0


def _optional_array(value: Any) -> np.ndarray | None:
    return None if value is None else np.asarray(value, dtype=float)


def _problem(kind: str, row: Mapping[str, Any], meta: Mapping[str, Any], why: str) -> dict:
    return {
        "kind": kind,
        "task_id": row["task_id"],
        "status": row["status"],
        "direction": row.get("direction", ""),
        "L_mm": row["L_mm"],
        **{k: row[k] for k in SERIES_PARAMS},
        "message": why or str(meta.get("error_message", "")),
    }


def _partial_reasons(root: Mapping[str, Any], n_found: int) -> list[str]:
    run_status = str(root.get("run_status", "unknown"))
    n_expected = int(root.get("n_points", 0)) + int(root.get("n_sweeps", 0))
    reasons = []
    if run_status != "complete":
        reasons.append(f"run_status '{run_status}'")
    if n_found < n_expected:
        reasons.append(f"{n_found} of {n_expected} tasks present")
    check = root.get("check")
    if check is not None and (check.damaged or check.structure):
        reasons.append("; ".join([f"{len(check.damaged)} damaged task(s) not used"]
                                 * bool(check.damaged) + check.structure_lines())
                       + f": `knitsweep recover {root['file']}`, then resume")  # fmt: skip
    return reasons


def reduce_results(
    paths: str | Path | Sequence[str | Path], threshold: float = GAP_THRESHOLD
) -> Reduction:
    """Reduce one or several results files (complete, partial, or still being
    written) to tables; several files combine as one study (tasks are
    content-addressed: a task in two files counts once).

    Args:
        paths: HDF5 results file(s) of ``knitsweep run`` (results schema 1 or 2).
        threshold: energy-gap threshold, mJ (paper: ``GAP_THRESHOLD``): a sweep with jamming gap
            (ΔE_c for x, ΔE_b for y) below it is unjammed.

    Returns:
        The :class:`Reduction`; tasks that failed, were not knittable, or whose
        arrays cannot be analysed are in ``problems``, not raised.

    Raises:
        InputError: a missing or unreadable file, a wrong schema version, or task
            groups without the attributes this schema guarantees; a threshold outside
            [MIN_THRESHOLD, MAX_THRESHOLD].
    """
    paths = [Path(paths)] if isinstance(paths, (str, Path)) else [Path(p) for p in paths]
    if not paths:
        raise InputError("give at least one results file")
    if not (np.isfinite(threshold) and MIN_THRESHOLD <= threshold <= MAX_THRESHOLD):
        raise InputError(f"threshold = {threshold!r}: must be in [{MIN_THRESHOLD:g}, "
                         f"{MAX_THRESHOLD:g}] mJ")  # fmt: skip
    roots, entries = read_files(paths)
    tasks = {POINTS: [], SWEEPS: []}
    for e in entries:
        if e.kind in tasks:  # other kinds (an adaptive job's /series) are read below
            tasks[e.kind].append((e, _check_meta(Path(e.meta["file"]), e)))
    point_of = {e.task_id: e for e, _ in tasks[POINTS]}
    fidelity_of = {r["file"]: job_fidelity(r) for r in roots}  # each file's own job
    points, sweeps, problems, curves = [], [], [], []
    pair_of: dict[str, dict[str, Any]] = {}
    for e, meta in sorted(tasks[POINTS], key=lambda em: (series_values(em[1]), em[1]["L_mm"])):
        row = _point_row(e, meta, fidelity_of[meta["file"]])
        points.append(row)
        pair_of[e.task_id] = {k: v for k, v in row.items() if k.startswith("pair_F_")} | {
            "force_ratio_xy": row["force_ratio_xy"]
        }
        if row["status"] != "done":
            problems.append(_problem("point", row, meta, str(meta.get("message", ""))))
    for e, meta in sorted(
        tasks[SWEEPS], key=lambda em: (em[1]["direction"], series_values(em[1]), em[1]["L_mm"])
    ):
        base = _base_row(e, meta)
        if base["status"] != "done":
            problems.append(_problem("sweep", base, meta, str(meta.get("message", ""))))
            continue
        point = point_of.get(base["point_id"])
        point_forces = point.record.get("contact_forces") if point is not None else None
        try:
            row, c = _analyse_sweep(e, meta, point_forces, threshold)
        except ValueError as err:
            problems.append(_problem("sweep", base, meta, f"not analysable: {err}"))
            continue
        sweeps.append(row | pair_of.get(base["point_id"], dict.fromkeys(PAIR_KEYS)))
        curves.append(c)

    transition_of, transitions = transition_rows(sweeps, problems, threshold)
    notes: list[str] = []
    for r in roots:  # damaged tasks are never used: listed, and the file is partial
        check = r["check"]
        problems += [{"kind": kind[:-1], "task_id": tid, "status": "damaged", "direction": "",
                      "message": why, "file": r["file"]} for kind, tid, why in check.damaged]  # fmt: skip
        if check.unverified:
            notes.append(f"{Path(r['file']).name}: {check.unverified} task(s) written without "
                         "checksums (a knitsweep before checksums): read unverified")  # fmt: skip
    add_adaptive_brackets([e for e in entries if e.kind not in tasks], transitions, notes)
    mark_failed(transition_of, transitions, problems)
    add_reference_shifts(transitions)
    for row in (*points, *sweeps):
        row["regime"] = _regime(row, transition_of) if row["status"] == "done" else None
    n_found = len(tasks[POINTS]) + len(tasks[SWEEPS])
    reasons = [f"{Path(r['file']).name}: {why}" if len(roots) > 1 else why
               for r in roots
               for why in _partial_reasons(r, r["n_found"])]  # fmt: skip
    values = {k: sorted({row[k] for row in points + sweeps}) for k in SERIES_PARAMS}
    return Reduction(
        path=paths[0],
        job_name=" + ".join(str(r.get("job_name", "")) or _job_name(r) for r in roots),
        run_status=" + ".join(sorted({str(r.get("run_status", "unknown")) for r in roots})),
        partial=bool(reasons),
        partial_reason=", ".join(reasons) or None,
        n_expected=sum(int(r.get("n_points", 0)) + int(r.get("n_sweeps", 0)) for r in roots),
        n_found=n_found,
        threshold=float(threshold),
        sweeps=sweeps,
        transitions=transitions,
        points=points,
        problems=problems,
        curves=curves,
        transition_of=transition_of,
        varying=tuple(k for k, v in values.items() if len(v) > 1),
        constants={
            k: v[0]
            for k, v in values.items()  # (the default stitch goes unsaid)
            if len(v) == 1 and (k != "stitch" or v[0] != DEFAULT_STITCH)
        },
        notes=notes,
        paths=tuple(paths),
        roots=roots,
        entries=entries,
    )


def _job_name(root: Mapping[str, Any]) -> str:
    try:
        return str(json.loads(str(root.get("job_json", "{}"))).get("name", ""))
    except json.JSONDecodeError:
        return ""


def _regime(row: Mapping[str, Any], transition_of: Mapping) -> str | None:
    """Regime of a point from its series' transitions in x and y (None if one is absent)."""
    key = series_key(row)
    tx, ty = transition_of.get((key, "x")), transition_of.get((key, "y"))
    if tx is None or ty is None or "failed" in (tx.status, ty.status):
        return None
    return regime(row["L_over_r"], tx, ty)
