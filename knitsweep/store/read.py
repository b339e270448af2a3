"""Reading results files: every finished task (HDF5 file plus journal), one task,
the root attributes (schema checked), journal problems and the running master's
progress. Nothing here writes; files still being written read fine.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..config import FAILED
from ..errors import InputError
from .format import (
    KINDS,
    POINTS,
    READABLE_SCHEMAS,
    SWEEPS,
    _h5,
    _read_group,
    journal_dir,
    progress_path,
)
from .journal import Entry, entry_path, read_entry_file, scan


@contextlib.contextmanager
def _open(path: Path):
    """The results file opened for reading; InputError naming what it is otherwise."""
    if path.is_dir():
        raise InputError(f"{path}: a directory, not a results file")
    try:
        f = _h5().File(path, "r")
    except FileNotFoundError:
        raise InputError(f"{path}: no such results file") from None
    except Exception as e:  # h5py raises OSError, sometimes others, for foreign files
        why = str(e).split("(")[0].strip() or type(e).__name__
        raise InputError(f"{path}: not a readable HDF5 file ({why})") from None
    try:
        yield f
    finally:
        f.close()


def _groups(f, kind: str):
    """(task id, group) of one kind in an open file; foreign members are skipped."""
    h5py = _h5()
    parent = f.get(kind)
    if not isinstance(parent, h5py.Group):
        return
    for tid, group in parent.items():
        if isinstance(group, h5py.Group):
            yield tid, group


def iter_entries(path: str | Path, with_data: bool = False,
                 journalled: list[Entry] | None = None) -> Iterator[Entry]:  # fmt: skip
    """Every finished task of a results file, deduplicated: the HDF5 file's
    groups that the journal has no newer version of, then the journal's entries.

    The journal is read first (or given as ``journalled``, read before this call): an
    entry merged and deleted meanwhile is then in the file opened after it. Malformed
    journal entries are skipped (``journal_problems`` lists them)."""
    path = Path(path)
    if journalled is None:
        journalled = scan(journal_dir(path), with_data)[0]
    newer = {(e.kind, e.task_id) for e in journalled}
    if path.exists():
        with _open(path) as f:
            for kind in KINDS:
                for tid, group in _groups(f, kind):
                    if (kind, tid) in newer:
                        continue
                    if with_data:
                        meta, record = _read_group(group)
                    else:
                        meta, record = dict(group.attrs), {}
                    yield Entry(kind, tid, record, meta)
    yield from journalled


def choose_entries(entries: Iterable[Entry]) -> dict[tuple[str, str], Entry]:
    """Each task once, by (kind, task id): a result that is not 'failed' wins over a
    failed one, an earlier entry over a later one (of several files: the first file)."""
    chosen: dict[tuple[str, str], Entry] = {}
    for e in entries:
        old = chosen.get((e.kind, e.task_id))
        if old is None or (old.meta.get("status") == FAILED != e.meta.get("status")):
            chosen[(e.kind, e.task_id)] = e
    return chosen


def read_files(paths: Sequence[str | Path]) -> tuple[list[dict[str, Any]], list[Entry]]:
    """Root attributes of each results file (with ``file`` and ``n_found``, the
    number of its point and sweep tasks), and every finished task of all of them
    (journals included), each task once: a result that is not 'failed' wins over a
    failed one, the first file over later ones. Each entry's meta gets ``file``."""
    roots, entries = [], []
    seen = set()
    for path in map(Path, paths):
        key = path.resolve()
        if key in seen:
            raise InputError(f"{path}: given twice")
        seen.add(key)
        root = read_root(path) | {"file": str(path), "n_found": 0}
        roots.append(root)
        for e in iter_entries(path, with_data=True):
            e.meta["file"] = str(path)
            root["n_found"] += e.kind in (POINTS, SWEEPS)
            entries.append(e)
    return roots, list(choose_entries(entries).values())


def read_entry(path: str | Path, kind: str, task_id: str) -> Entry | None:
    """One finished task with its data, from the journal or the HDF5 file."""
    from .journal import Malformed

    path = Path(path)
    try:
        return read_entry_file(entry_path(journal_dir(path), kind, task_id))
    except (FileNotFoundError, Malformed):
        pass
    for e in reversed(scan(journal_dir(path), with_data=True)[0]):  # batches: newest first
        if (e.kind, e.task_id) == (kind, task_id):
            return e
    if path.exists():
        with _open(path) as f:
            group = f.get(f"{kind}/{task_id}")
            if isinstance(group, _h5().Group):
                meta, record = _read_group(group)
                return Entry(kind, task_id, record, meta)
    return None


def journal_problems(path: str | Path, problems: list | None = None) -> list[str]:
    """One line per malformed journal entry of a results file (their tasks are
    recomputed when the run resumes); ``problems``: the journal's scan, if made."""
    if problems is None:
        problems = scan(journal_dir(Path(path)))[1]
    return [f"{p.name}: {why}" for p, why in problems]


def read_root(path: str | Path) -> dict[str, Any]:
    """Root attributes of a knitsweep results file (schema checked); InputError
    naming the file for anything else (missing, not HDF5, foreign HDF5, other
    schema)."""
    path = Path(path)
    with _open(path) as f:
        attrs = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in f.attrs.items()}
    version = attrs.get("schema_version")
    if version is None:
        raise InputError(f"{path}: an HDF5 file, but not a knitsweep results file (no "
                         "schema_version attribute)")  # fmt: skip
    if not isinstance(version, int) or isinstance(version, bool):
        raise InputError(f"{path}: schema_version {version!r} is not an integer: not a results "
                         "file written by knitsweep")  # fmt: skip
    if version not in READABLE_SCHEMAS:
        raise InputError(
            f"{path}: results schema_version {version}; this knitsweep reads "
            f"{' and '.join(map(str, READABLE_SCHEMAS))}: use the knitsweep version that wrote it"
        )
    missing = [k for k in ("job_json", "job_hash") if k not in attrs] if version >= 2 else []
    if missing:
        raise InputError(f"{path}: schema_version {version} but no {' or '.join(missing)} "
                         "attribute: not a complete knitsweep results file")  # fmt: skip
    return attrs


def read_progress(path: str | Path) -> dict[str, Any] | None:
    p = progress_path(Path(path))
    try:
        data = json.loads(p.read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None
