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

The settings a task's id hashes have forms of their own, versioned the same way
(``FormHistory``): ``PARAMS_FORMS`` (a point's ``StitchParams``), ``STARTS_FORMS``
(``StartSettings``) and ``PROTOCOL_FORMS`` (``SweepProtocol``). Their dumps write every
field; a task's id hashes each one's id form, so that a task using nothing a later field
changed keeps the id it had before the field existed.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..config import REST_TOLERANCE_MJ, RETRIES
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


@dataclass(frozen=True)
class FormHistory:
    """The versioned forms of one dict a hash is taken of: its ``migrations``, oldest
    first (the first form is version 1, each step leads to the next)."""

    what: str
    migrations: tuple[Migration, ...]

    @property
    def version(self) -> int:
        """The newest form: the one a full dump writes."""
        return self.migrations[-1].version if self.migrations else 1

    def id_form(self, full: Form) -> Form:
        """The form an id hashes: ``full`` migrated down through every step it allows
        (the newest first; a step whose addition the dict uses stays)."""
        d = full
        for m in reversed(self.migrations):
            lower = m.down(d)
            if lower is not None:
                d = lower
        return d

    def migrate_up(self, d: Form) -> Form:
        """A dict of any earlier form (as ``id_form`` gives) in the full form: every
        step's ``up``, oldest first."""
        for m in self.migrations:
            d = m.up(d)
        return d


def _shears(d: Form) -> bool:
    from ..paths import load_path

    return any(load_path(x).shears for x in d.get("directions", ()))


def _shear_rest_up(d: Form) -> Form:
    """A job's ``protocol.shear_rest`` up: 'held' (upright) where a direction shears, as
    every job before it held it; else the default 'relaxed' (the same results)."""
    out = copy.deepcopy(d)
    out["protocol"].setdefault("shear_rest", "held" if _shears(d) else "relaxed")
    return out


def _shear_rest_down(d: Form) -> Form | None:
    """The inverse of ``_shear_rest_up`` (None where the job's value is not the one it
    restores)."""
    if d["protocol"].get("shear_rest") != ("held" if _shears(d) else "relaxed"):
        return None
    out = copy.deepcopy(d)
    out["protocol"].pop("shear_rest", None)
    return out


JOB_FORMS = FormHistory("a job (JobSpec.full_form)", (
    Migration(2, "stitch: the stitch of every point (before: stockinette, the paper's; "
              "several stitches are the grid axis grid.stitch)", _stitch_up, _stitch_down),
    Migration(3, "grid.ties: axes tied to others (before: none)", *_field(("grid", "ties"), {})),
    Migration(4, "grid.zip: axes varied together (before: none)", *_field(("grid", "zip"), [])),
    Migration(5, "store.packing_fraction: the packing fraction stored (before: not)",
              *_field(("store", "packing_fraction"), False)),
    Migration(6, "starts.carry: each point of a series starts from its neighbour's "
              "zero-force state (before: not)", *_field(("starts", "carry"), False)),
    Migration(7, "protocol.rest_tolerance_mJ: a sweep falling this far below its zero-force "
              "energy relaxes again at rest (before: the default, 5e-6 mJ, was the only one)",
              *_field(("protocol", "rest_tolerance_mJ"), REST_TOLERANCE_MJ)),
    Migration(8, "starts.retries: a point no start of which converged walks again from "
              "perturbed copies (the default, 3, hashes as the jobs before it)",
              *_field(("starts", "retries"), RETRIES)),
    Migration(9, "starts.spread: each point and sweep also relaxed from perturbed copies "
              "(before: off)", *_field(("starts", "spread"), 1)),
    Migration(10, "fidelity.contact_sampling: how the contact sum samples the yarn (before: "
              "'parameter')", *_field(("fidelity", "contact_sampling"), "parameter")),
    Migration(11, "protocol.shear_rest: a shear starts from the zero-force state with its skew "
              "relaxed (before: 'held', upright)",
              _shear_rest_up, _shear_rest_down),
    Migration(12, "adaptive.last_crossing: a re-entrant series' last crossing refined too "
              "(before: not)", *_field(("adaptive", "last_crossing"), False)),
))  # fmt: skip
"""Every step of the job format since its first form."""
MIGRATIONS = JOB_FORMS.migrations
FORM_VERSION = JOB_FORMS.version
"""The form ``JobSpec.full_form`` writes."""
id_form = JOB_FORMS.id_form
migrate_up = JOB_FORMS.migrate_up

PARAMS_FORMS = FormHistory("a point's parameters (StitchParams)", (
    Migration(2, "stitch: the stitch pattern (before: stockinette, the paper's)",
              *_field(("stitch",), DEFAULT_STITCH)),
))  # fmt: skip
STARTS_FORMS = FormHistory("the starts (StartSettings)", (
    Migration(2, "carry: each point of a series starts from its neighbour's zero-force "
              "state (before: not)", *_field(("carry",), False)),
    Migration(3, "retries: a point no start of which converged walks again from perturbed "
              "copies (the default, 3, hashes as the settings before it)",
              *_field(("retries",), RETRIES)),
    Migration(4, "spread: each point and sweep also relaxed from perturbed copies (before: "
              "off)", *_field(("spread",), 1)),
))  # fmt: skip
PROTOCOL_FORMS = FormHistory("a sweep's protocol (SweepProtocol)", (
    Migration(2, "rest_tolerance_mJ: a sweep falling this far below its zero-force energy "
              "relaxes again at rest (before: the default was the only one)",
              *_field(("rest_tolerance_mJ",), REST_TOLERANCE_MJ)),
    Migration(3, "shear_rest: a shear starts from the zero-force state with its skew relaxed "
              "(before: 'held'; a sweep that does not shear hashes it as 'held')",
              *_field(("shear_rest",), "held")),
))  # fmt: skip
FIDELITY_FORMS = FormHistory("the fidelity (Fidelity)", (
    Migration(2, "contact_sampling: how the contact sum samples the yarn (before: "
              "'parameter')", *_field(("contact_sampling",), "parameter")),
))  # fmt: skip


def protocol_id_form(protocol: Form, direction: str) -> Form:
    """The id form of a sweep's protocol (``SweepProtocol`` dumped) along ``direction``:
    where the path does not shear, ``shear_rest`` changes nothing and hashes as 'held'."""
    from ..paths import load_path

    if not load_path(direction).shears:
        protocol = {**protocol, "shear_rest": "held"}
    return PROTOCOL_FORMS.id_form(protocol)


ADAPTIVE_FORMS = FormHistory("the adaptive search (AdaptiveSettings)", (
    Migration(2, "last_crossing: a re-entrant series' last crossing refined too (before: not)",
              *_field(("last_crossing",), False)),
))  # fmt: skip
"""The forms of the adaptive settings a series' key hashes."""

TASK_FORMS = (PARAMS_FORMS, STARTS_FORMS, PROTOCOL_FORMS, FIDELITY_FORMS)
"""The settings a task's id hashes, each with its forms."""
