"""Whether a job may write into an existing results file: the same job, or one whose
grid, directions or stitches grew (``GROWABLE``); anything else is refused by name."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..errors import InputError
from .format import RESULTS_SCHEMA_VERSION, REWRITABLE_SCHEMAS
from .read import read_root

GROWABLE = ("grid", "directions", "stitch")
"""What a job may change and still run into an existing results file: its tasks are
content-addressed, so a grown grid adds only the new tasks (a shrunk one keeps the
old results in the file). ``stitch``: a job's one stitch (the stitches of several are
``grid.stitch``), so that one stitch can grow into several."""


def check_compatible(path: Path, job, root: dict[str, Any] | None = None) -> str | None:
    """Refuse to write ``job`` into anything that is not a knitsweep results file, or
    into one made by a job with other numerics, protocol, starts or stored
    observables (``root``: the file's ``read_root``, read here if not given). Returns
    None for the same job, or the job hashes the file grew from (comma-separated) when
    only ``GROWABLE`` differ."""
    root = read_root(path) if root is None else root
    version = root["schema_version"]
    if version != RESULTS_SCHEMA_VERSION:
        raise InputError(
            f"{path} has results schema_version {version} (it still reads: status, "
            f"phase-diagram), this knitsweep writes {RESULTS_SCHEMA_VERSION}: write to a new "
            "file (--out), or resume it with the knitsweep version that made it"
            + (
                f"; `knitsweep merge NEW.h5 {path}` copies its results into a new file that "
                "this version resumes"
                if version in REWRITABLE_SCHEMAS
                else ""
            )
        )
    if str(root["job_hash"]) == job.job_hash:
        return None
    from pydantic import ValidationError

    try:  # the job's own class parses the file's spec: the store knows no job schema
        their_job = type(job).model_validate_json(str(root["job_json"]))
    except ValidationError:
        raise InputError(
            f"{path} holds results of a job whose spec this knitsweep cannot read; choose "
            "another --out file, or rerun the job that made it with the knitsweep that made it"
        ) from None
    diff = _differences(their_job.canonical(), job.canonical())
    # settings the file's results do not depend on (``unread_settings``: the contact
    # placement of a job of the ansatz alone) may differ too
    unread = set(their_job.unread_settings())
    fixed = [d for d in diff if d.split(".")[0] not in GROWABLE and d not in unread]
    if fixed or not diff:
        raise InputError(
            f"{path} holds results of a job with other settings (differs in "
            f"{', '.join(fixed) or 'settings'}); only the grid and directions may change "
            "between runs into one file: choose another --out file, or rerun that job"
        )
    return ", ".join(filter(None, [str(root.get("grown_from", "")), str(root["job_hash"])]))


def _differences(a: Any, b: Any, prefix: str = "") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            out += _differences(a.get(k), b.get(k), f"{prefix}{k}.")
        return out
    return [] if a == b else [prefix.rstrip(".")]
