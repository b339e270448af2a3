"""``knitsweep recover F.h5``: rebuild the most complete results file that the
damaged ``F.h5``, the previous checkpoint's copies beside it (``.F.h5.spare``,
``.F.h5.shadow``: see ``store.writer``) and its journal still hold.

Every source is read with its checksums (``store.salvage``); a task is taken from
the journal first (never older than the file), then from the file, then from the
earlier copies, and only if intact. The damaged file is kept as ``F.h5.damaged``
(nothing is deleted); the rebuilt ``F.h5`` has ``run_status`` 'recovered', so running
the job again resumes it and computes only what is missing.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..errors import InputError
from ..store.format import (
    POINTS,
    RESULTS_SCHEMA_VERSION,
    REWRITABLE_SCHEMAS,
    SERIES,
    SWEEPS,
    journal_dir,
    lock_path,
)
from ..store.journal import scan
from ..store.read import choose_entries
from ..store.salvage import salvage, set_aside
from ..store.writer import ResultWriter, check_no_links, writer_alive
from .jobs import JobSpec, load_job

_RUN_ATTRS = ("run_status", "finished_at")  # set by the rebuild itself


def _hidden(path: Path, what: str) -> Path:
    return path.with_name(f".{path.name}.{what}")


def recover(path: str | Path, job_path: str | Path | None = None) -> dict[str, Any]:
    """Rebuild ``path`` from what is intact (see the module docstring); returns what
    was recovered from where, what must be recomputed, and where the damaged file is
    kept. ``job_path``: the job file, needed only if no source holds an intact job spec.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path}: a directory, not a results file")
    check_no_links(path)  # nothing is read, renamed or written through a link
    if writer_alive(lock_path(path)):
        raise InputError(f"{path} is being written by a running knitsweep; stop it first")
    sources = [salvage(path), salvage(_hidden(path, "shadow")), salvage(_hidden(path, "spare"))]
    journalled, malformed = scan(journal_dir(path), with_data=True)
    if not (any(s.entries or s.root for s in sources) or journalled or job_path):
        raise InputError(f"{path}: nothing to recover (no readable file, spare copy or "
                         "journal entry)")  # fmt: skip
    main = sources[0]
    intact = (main.root_verified and not main.check.damaged and not main.check.structure
              and not main.note)  # fmt: skip
    if intact:
        return {"file": str(path), "intact": True, "verified": main.check.verified,
                "unverified": main.check.unverified, "journal": len(journalled)}  # fmt: skip
    root = _root(path, sources, job_path)
    if root.get("schema_version", RESULTS_SCHEMA_VERSION) not in REWRITABLE_SCHEMAS:
        raise InputError(f"{path}: results schema_version {root.get('schema_version')}: "
                         "recover it with the knitsweep version that wrote it")  # fmt: skip
    job = JobSpec.model_validate_json(str(root["job_json"]))
    from_where: dict[tuple[str, str], str] = {}
    ordered = [(e, "journal") for e in journalled]
    ordered += [(e, label) for s, label in zip(sources, ("file", "shadow", "spare"), strict=True)
                for e in s.entries]  # fmt: skip
    chosen = choose_entries(e for e, _ in ordered)
    for e, label in ordered:
        if chosen.get((e.kind, e.task_id)) is e:
            from_where[(e.kind, e.task_id)] = label
    kept = set_aside(path)
    meta = {k: v for k, v in root.items() if k not in _RUN_ATTRS}
    writer = ResultWriter(path, job, meta | {"recovered_from": str(kept or "")})
    try:
        for key, e in chosen.items():
            if from_where[key] != "journal":  # the journal's entries are the writer's already
                writer.add(e.kind, e.task_id, e.record, e.meta)
    finally:
        writer.close("recovered")
    planned = int(root.get("n_points", 0)) + int(root.get("n_sweeps", 0))
    tasks = sum(kind in (POINTS, SWEEPS) for kind, _ in chosen)
    lost = sorted({(k, t) for s in sources for k, t, _ in s.check.damaged} - set(chosen))
    return {
        "file": str(path),
        "intact": False,
        "kept": str(kept) if kept else None,
        "job": job.name,
        "recovered": tasks,
        "series": sum(kind == SERIES for kind, _ in chosen),
        "from": {
            label: sum(v == label for v in from_where.values())
            for label in ("file", "shadow", "spare", "journal")
        },
        "planned": planned,
        "recompute": max(planned - tasks, 0),
        "damaged_lost": [f"{k[:-1]} {t}" for k, t in lost],
        "sources": {str(s.path): s.note or "read" for s in sources if s.note != "absent"},
        "malformed_journal": [f"{p.name}: {why}" for p, why in malformed],
    }


def _root(path: Path, sources, job_path) -> dict[str, Any]:
    """The root attributes to rebuild with: the first source whose root passes its
    checksum (the file, then the earlier copies), else one written before checksums
    that reads, else a fresh root from the job file."""
    for want_verified in (True, False):
        for s in sources:
            if s.root and (s.root_verified or not want_verified) and "job_json" in s.root:
                return dict(s.root)
    if job_path is None:
        raise InputError(f"{path}: no intact copy of the job spec (the file's root is damaged "
                         "and no spare holds one): give the job file, "
                         f"knitsweep recover {path} --job JOB.toml")  # fmt: skip
    job = load_job(job_path)
    from .jobs import plan

    points, sweeps = plan(job)
    return {"job_json": job.model_dump_json(), "job_hash": job.job_hash, "job_name": job.name,
            "n_points": len(points), "n_sweeps": len(sweeps)}  # fmt: skip
