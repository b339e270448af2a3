"""A failed zero-force point's starts walked again from perturbed copies (``[starts] retries``).

A free yarn's zero-force walk can end, from the same start, converged, too tight to knit,
or out of its stitch ("topology changed"), as the last bits of its arithmetic decide: the
same job gave seed at L = 9.3 mm not knittable with the kernels compiled for an AVX-512
host and failed with them compiled for a generic x86-64 (docs/patterns.md,
"Reproducibility"). A start that ended neither converged nor not knittable has then told
nothing about the stitch; it is walked again from ``retries`` copies of itself, its shape
perturbed by ``RETRY_PERTURBATION`` relative (seeded from the point's seed), side by side,
and takes their verdict: their lowest converged relaxation, or not knittable if every
copy ended so. Copies that fail too leave the start as it was. No tolerance is loosened:
each copy is relaxed and checked as every start is.

The point's message and its record say so: ``retried`` (per start: how many copies it was
walked again from, 0 if none) and ``retry_message`` (what each retry gave).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..config import (
    CONVERGED,
    NOT_KNITTABLE,
    RETRY_PERTURBATION,
    Fidelity,
    SolverSettings,
    StartSettings,
    StitchParams,
)
from ..relax import single_threaded, walk_starts
from ..relax.zero_force import ZeroForce, pick_lowest


def needs_retry(zf: ZeroForce) -> list[int]:
    """The starts of ``zf`` to walk again: none if a start converged or every start is too
    tight to knit; else its own (unmerged) starts that ended neither."""
    own = [i for i in range(len(zf.relaxations))
           if not zf.merged_into or zf.merged_into[i] < 0]  # fmt: skip
    if zf.status in (CONVERGED, NOT_KNITTABLE):
        return []
    return [i for i in own if zf.relaxations[i].status not in (CONVERGED, NOT_KNITTABLE)]


def retry_failed_starts(
    zf: ZeroForce,
    begin: list[tuple[np.ndarray, StitchParams]],
    params: StitchParams,
    fidelity: Fidelity,
    solver: SolverSettings,
    starts: StartSettings,
    seed: int,
) -> tuple[ZeroForce, np.ndarray, str]:
    """``zf`` with its failed starts (``needs_retry``) walked again from ``starts.retries``
    perturbed copies each; ``begin``: every start's state and the parameters it was relaxed
    at, as ``zero_force`` walked them. Returns the new zero-force state, the copies each
    start was walked again from, and a message (empty if nothing was retried)."""
    retried = np.zeros(len(zf.relaxations), dtype=np.int64)
    which = needs_retry(zf) if starts.retries else []
    if not which:
        return zf, retried, ""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x7E7]))
    relaxations, stages, labels = list(zf.relaxations), list(zf.stages), list(zf.labels)
    notes = []
    for i in which:
        x0, source = begin[i]
        copies = []
        for _ in range(starts.retries):
            x = np.array(x0, dtype=float)
            x[:-2] *= 1.0 + RETRY_PERTURBATION * rng.standard_normal(len(x) - 2)
            copies.append((x, source))
        with single_threaded():
            walked, _, _ = walk_starts(params, fidelity, copies, solver,
                                               starts.merge_tolerance_mJ)  # fmt: skip
        results = [r for r, _ in walked]
        retried[i] = len(copies)
        k, status = pick_lowest(results)
        counts = ", ".join(f"{sum(r.status == s for r in results)} {s}"
                           for s in sorted({r.status for r in results}))  # fmt: skip
        if status in (CONVERGED, NOT_KNITTABLE):
            notes.append(f"{labels[i]} retried from {len(copies)} copies perturbed by "
                         f"{RETRY_PERTURBATION:g}: {counts}; took copy {k}'s {status}")  # fmt: skip
            relaxations[i] = replace(results[k], message=f"{results[k].message} [retry {k} of "
                                     f"{labels[i]}; first walk: {zf.relaxations[i].message}]")  # fmt: skip
            stages[i] = walked[k][1]
        else:
            notes.append(f"{labels[i]} retried from {len(copies)} copies perturbed by "
                         f"{RETRY_PERTURBATION:g}: {counts}; kept as it was")  # fmt: skip
    own = [i for i in range(len(relaxations))
           if not zf.merged_into or zf.merged_into[i] < 0]  # fmt: skip
    w, status = pick_lowest([relaxations[i] for i in own])
    winner = own[w]
    if status == CONVERGED:
        message = f"lowest of {len(relaxations)} starts: {labels[winner]}"
    elif status == NOT_KNITTABLE:
        message = f"no start converged; best ({labels[winner]}): {relaxations[winner].message}"
    else:
        message = zf.message
    note = "; ".join(notes)
    out = replace(zf, relaxations=tuple(relaxations), stages=tuple(stages), winner=winner,
                  status=status, message=f"{message} ({note})")  # fmt: skip
    return out, retried, note
