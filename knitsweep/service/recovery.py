"""``knitsweep recover F.h5``: rebuild the most complete results file that the
damaged ``F.h5``, the previous checkpoint's copies beside it (``.F.h5.spare``,
``.F.h5.shadow``: see ``store.writer``) and its journal still hold
(docs/crash-safety.md).

Every source is read with its checksums (``store.salvage``: the tables through HDF5,
and the sealed frames from the raw bytes); a task is taken from the journal first
(never older than the file), then from the file, then from the earlier copies, and
only if intact. The new file is built beside the old one under a temporary name
(``.F.h5.<pid>.recover.tmp``, which the next ``run`` or ``recover`` deletes if a
kill left it) and only then takes ``F.h5``'s place: a signal at any instant leaves
``F.h5`` as it was. The damaged file is kept as ``F.h5.damaged`` (nothing is
deleted); the rebuilt ``F.h5`` has ``run_status`` 'recovered', so running the job
again resumes it and computes only what is missing. A file that holds no results at
all (0 bytes, or not HDF5) is rebuilt only with the job file (``--job``), and kept
aside like any other.
"""

from __future__ import annotations

import contextlib
import os
import shutil
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
from ..store.journal import fsync_dir, journal_files, scan
from ..store.read import choose_entries
from ..store.salvage import aside_name, salvage
from ..store.writer import ResultWriter, check_no_links, hold_lock, release_lock, remove_stale
from . import signals
from .jobs import JobSpec, load_job

_RUN_ATTRS = ("run_status", "finished_at")  # set by the rebuild itself
_NO_RESULTS = ("empty", "not an HDF5 file")  # notes of a file that holds nothing


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
    lock = hold_lock(path)  # no run starts on it meanwhile (a running one: refused)
    try:
        remove_stale_builds(path)
        return _recover(path, job_path)
    finally:
        release_lock(path, lock)


def remove_stale_builds(path: Path) -> None:
    """What a killed ``recover`` left beside ``path`` (under ``path``'s lock)."""
    for stale in path.parent.glob(f".{path.name}.*.recover.tmp"):
        _remove_build(stale)
    for stale in (
        *path.parent.glob(f".{path.name}.*.recover.tmp.*"),
        *path.parent.glob(f"..{path.name}.*.recover.tmp.*"),
    ):  # (killed as it began)
        with contextlib.suppress(OSError):
            if stale.is_dir() and not stale.is_symlink():
                shutil.rmtree(stale)
            else:
                stale.unlink()


def _remove_build(build: Path) -> None:
    """A rebuild that did not take its file's place, with its journal, lock and copies."""
    remove_stale(build)
    for p in (build, journal_dir(build), lock_path(build)):
        with contextlib.suppress(OSError):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p)
            else:
                p.unlink(missing_ok=True)


def _recover(path: Path, job_path) -> dict[str, Any]:
    sources = [salvage(path), salvage(_hidden(path, "shadow")), salvage(_hidden(path, "spare"))]
    journal = journal_dir(path)
    read_files = journal_files(journal)
    journalled, malformed = scan(journal, with_data=True)
    main = sources[0]
    holds_nothing = main.note.startswith(_NO_RESULTS)
    if holds_nothing and job_path is None and not any(s.root for s in sources):
        raise InputError(
            f"{path}: {main.note}: it holds no results"
            + (f" (its journal holds {len(journalled)}, kept)" if journalled else "")
            + f"; if it is a results file to start over, `knitsweep recover {path} --job "
            f"JOB.toml` starts it anew in place (this file kept as {aside_name(path).name}), "
            f"then `knitsweep run JOB.toml --out {path}` computes the tasks"
        )
    if not (any(s.entries or s.root for s in sources) or journalled or job_path):
        raise InputError(f"{path}: nothing to recover (no readable file, spare copy or "
                         "journal entry)")  # fmt: skip
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
    kept = aside_name(path) if os.path.lexists(path) else None
    _rebuild(path, job, {k: v for k, v in root.items() if k not in _RUN_ATTRS}
             | {"recovered_from": str(kept or "")}, chosen.values(), kept)  # fmt: skip
    unread = {p for p, _ in malformed}
    for p in [*read_files, _hidden(path, "shadow"), _hidden(path, "spare")]:
        if p not in unread:  # what they held is in the new file
            with contextlib.suppress(OSError):
                p.unlink(missing_ok=True)
    with contextlib.suppress(OSError):
        journal.rmdir()
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


def _rebuild(path: Path, job: JobSpec, meta: dict[str, Any], entries, kept: Path | None) -> None:
    """Write ``entries`` into a new file beside ``path`` and put it in ``path``'s place,
    the old file kept as ``kept``; a signal or an error before the swap leaves
    ``path`` untouched and no temporary file."""
    build = path.with_name(f".{path.name}.{os.getpid()}.recover.tmp")
    done = False
    try:
        writer = ResultWriter(build, job, meta)
        try:
            for e in entries:
                writer.add(e.kind, e.task_id, e.record, e.meta)
        finally:
            writer.close("recovered")
        with signals.deferred():  # two renames: never cut between them by a signal
            if kept is not None:
                try:  # F.h5 stays a complete file at every instant (old, then new)
                    os.link(path, kept)
                except OSError:
                    os.rename(path, kept)
            os.replace(build, path)
            done = True
        fsync_dir(path.parent)
    finally:
        if not done:
            _remove_build(build)


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
