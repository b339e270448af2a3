"""The versioned forms of a job's canonical dict, from which its id is hashed, and the
migrations between them (signac's ``contrib/migration`` in spirit: each form step is a
small pair of functions, applied in order, tested on a job of each form).

A job's full form (``JobSpec.full_form``) writes every field that determines its
results. Each ``Migration`` says what one step of the job format added and how a dict of
the form before it becomes one of the form after it (``up``: the field at the value every
earlier job had) and back (``down``: the same dict without the field, or None where the
job uses what the step added, and no earlier form can express it). A job's id is the
digest of its id form: its full form migrated down through every step it allows, newest
first, so that a job that uses none of a step's additions hashes as jobs did before the
step, and earlier results files keep their ids and resume; ``migrate_up`` brings an
earlier form to the full one.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..stitches import DEFAULT_STITCH

Form = dict[str, Any]


@dataclass(frozen=True)
class Migration:
    """One step of the job format: ``version`` is the form it leads to."""

    version: int
    what: str
    up: Callable[[Form], Form]
    down: Callable[[Form], Form | None]


def _field(path: tuple[str, ...], default: Any) -> tuple[Callable, Callable]:
    """``up``/``down`` for a field at ``path`` that earlier forms lack and whose value
    was then ``default``."""

    def up(d: Form) -> Form:
        out = copy.deepcopy(d)
        where = out
        for key in path[:-1]:
            where = where[key]
        where.setdefault(path[-1], copy.deepcopy(default))
        return out

    def down(d: Form) -> Form | None:
        where = d
        for key in path[:-1]:
            where = where[key]
        if where.get(path[-1], default) != default:
            return None
        out = copy.deepcopy(d)
        where = out
        for key in path[:-1]:
            where = where[key]
        where.pop(path[-1], None)
        return out

    return up, down


def _stitch_up(d: Form) -> Form:
    out = copy.deepcopy(d)
    if "stitch" not in out and "stitch" not in out["grid"]:
        out["stitch"] = DEFAULT_STITCH
    return out


def _stitch_down(d: Form) -> Form | None:
    if d.get("stitch", DEFAULT_STITCH) != DEFAULT_STITCH or "stitch" in d["grid"]:
        return None
    out = copy.deepcopy(d)
    out.pop("stitch", None)
    return out


MIGRATIONS: tuple[Migration, ...] = (
    Migration(2, "stitch: the stitch of every point (before: stockinette, the paper's; "
              "several stitches are the grid axis grid.stitch)", _stitch_up, _stitch_down),
    Migration(3, "grid.ties: axes tied to others (before: none)", *_field(("grid", "ties"), {})),
    Migration(4, "grid.zip: axes varied together (before: none)", *_field(("grid", "zip"), [])),
    Migration(5, "store.packing_fraction: the packing fraction stored (before: not)",
              *_field(("store", "packing_fraction"), False)),
)  # fmt: skip
"""Every step of the job format since its first form, oldest first."""
FORM_VERSION = MIGRATIONS[-1].version
"""The form ``JobSpec.full_form`` writes."""


def id_form(full: Form) -> Form:
    """The form a job's id hashes: its full form migrated down through every step it
    allows (the newest first; a step whose addition the job uses stays)."""
    d = full
    for m in reversed(MIGRATIONS):
        lower = m.down(d)
        if lower is not None:
            d = lower
    return d


def migrate_up(d: Form) -> Form:
    """A dict of any earlier form (as ``id_form`` gives, or a job of an earlier format)
    in the full form: every step's ``up``, oldest first."""
    for m in MIGRATIONS:
        d = m.up(d)
    return d
