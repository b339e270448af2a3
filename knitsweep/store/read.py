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
from .checksum import DIGEST_ATTRS, Damaged, FileCheck, verify_root
from .format import (
    KINDS,
    POINTS,
    READABLE_SCHEMAS,
    SWEEPS,
    _h5,
    journal_dir,
    progress_path,
    read_task,
)
from .journal import Entry, entry_path, read_entry_file, scan
from .table import TASK, find_row, is_table, table_entries


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
        eof, size = stored_eof(path), path.stat().st_size
        if eof is not None and eof > size:
            why = f"truncated: {size} of its {eof} bytes"
        elif size == 0:
            why = "empty: 0 bytes"
        raise InputError(f"{path}: not a readable HDF5 file ({why}){recover_hint(path)}") from None
    try:
        yield f
    finally:
        f.close()


SIGNATURE = b"\x89HDF\r\n\x1a\n"


def stored_eof(path: Path) -> int | None:
    """The end-of-file address an HDF5 file's superblock records (superblock versions
    0-3 at offset 0), or None if the superblock cannot be read."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(96)
    except OSError:
        return None
    if len(head) < 16 or head[:8] != SIGNATURE:
        return None
    version = head[8]
    if version in (0, 1):
        size = head[13]
        at = 24 + (4 if version == 1 else 0) + 2 * size
    elif version in (2, 3):
        size = head[9]
        at = 12 + 2 * size
    else:
        return None
    if size not in (2, 4, 8) or len(head) < at + size:
        return None
    return int.from_bytes(head[at : at + size], "little")


def recover_hint(path: Path) -> str:
    """'; …knitsweep recover…' for the refusal of a file that looks like a damaged
    results file (an HDF5 signature, or a journal or spare beside it), else ''."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError:
        head = b""
    beside = [p for p in (journal_dir(path), path.with_name(f".{path.name}.spare"),
                          path.with_name(f".{path.name}.shadow")) if p.exists()]  # fmt: skip
    if head == SIGNATURE or beside:
        return (f"; if it is a damaged knitsweep results file, `knitsweep recover {path}` "
                "rebuilds it from its intact tasks, the spare copy and the journal")  # fmt: skip
    if path.exists():  # nothing of a results file in it, nor beside it
        return (f"; if it should be a results file, `knitsweep recover {path} --job JOB.toml` "
                f"starts it anew in place (this file kept as {path.name}.damaged)")  # fmt: skip
    return ""


PARALLEL_FROM = 256
"""Files of at least this many task groups are read by forked helpers in parallel
(each verifies its share; the entries come in the file's order)."""


def file_entries(f, with_data: bool, check: FileCheck | None = None,
                 skip: set | frozenset = frozenset(), salvage: bool = False) -> Iterator[Entry]:  # fmt: skip
    """The verified tasks of an open file (damaged ones recorded in ``check`` and left
    out), but those in ``skip`` ((kind, task id) pairs): a table's rows (schema 3) or
    task groups (schemas 1 and 2); ``salvage``: see ``table.table_entries``."""
    groups = []
    for kind in KINDS:
        table = _table(f, kind, check)
        if table is None:
            groups += [(kind, tid) for tid in _names(f, kind, check) if (kind, tid) not in skip]
            continue
        if table is False:  # its index is damaged: recorded in check
            continue
        for e in table_entries(table, kind, check, skip, salvage):
            if not with_data:
                e.record = {}
            yield e
    yield from _group_entries(f, groups, with_data, check)


def _table(f, kind: str, check: FileCheck | None):
    """The table of ``kind`` in an open file; None where the file has task groups (or
    nothing, or a damaged index, which ``check`` then records)."""
    try:
        group = f.get(kind)
        if group is None or not is_table(group):
            return None
        group[TASK].shape  # noqa: B018  (the index must open)
        return group
    except Exception as e:
        if check is not None:
            check.structure.append(f"the index of /{kind} is unreadable ({type(e).__name__})")
        return False


def _group_entries(f, names, with_data: bool, check: FileCheck | None) -> Iterator[Entry]:
    """The verified task groups ``names`` of a file of schema 1 or 2; files of at least
    ``PARALLEL_FROM`` groups are read by forked helpers."""
    from ..util.forking import fork_workers, forked_map

    workers = fork_workers() if with_data and len(names) >= PARALLEL_FROM else 1
    if workers <= 1:
        yield from _read_named(f, names, with_data, check)
        return
    global _SHARE
    size = -(-len(names) // (4 * workers))  # a few shares a helper: they finish together
    shares = [names[i : i + size] for i in range(0, len(names), size)]
    _SHARE = (f.filename, with_data)
    try:
        for entries, found in forked_map(workers, _read_share, shares):
            if check is not None:
                check.merge(found)
            yield from entries
    finally:
        _SHARE = None


_SHARE: tuple[str, bool] | None = None  # (file, with data) for the helpers of file_entries


def _read_share(names: list[tuple[str, str]]) -> tuple[list[Entry], FileCheck]:
    """In a helper: the entries of ``names`` from the file, read and verified here."""
    path, with_data = _SHARE
    check = FileCheck()
    with _h5().File(path, "r") as f:
        return list(_read_named(f, names, with_data, check)), check


def _names(f, kind: str, check: FileCheck | None) -> list[str]:
    """The task ids of one kind in an open file (none if its index is unreadable,
    which ``check`` then records)."""
    h5py = _h5()
    try:
        parent = f.get(kind)
        return list(parent.keys()) if isinstance(parent, h5py.Group) else []
    except Exception as e:  # the group's index is damaged: its tasks cannot be named
        if check is not None:
            check.structure.append(f"the index of /{kind} is unreadable ({type(e).__name__})")
        return []


def _read_named(f, names, with_data: bool, check: FileCheck | None) -> Iterator[Entry]:
    """The verified entries of the task groups ``names`` ((kind, task id) pairs) of an
    open file; foreign members are skipped, damaged ones recorded in ``check``."""
    h5py = _h5()
    for kind, tid in names:
        try:
            group = f[kind][tid]
        except Exception as e:
            if check is not None:
                check.damaged.append((kind, tid, f"unreadable ({type(e).__name__})"))
            continue
        if isinstance(group, h5py.Group):
            task = read_task(group, with_data, check)
            if task is not None:
                yield Entry(kind, tid, task[1], task[0])


def iter_entries(path: str | Path, with_data: bool = False,
                 journalled: list[Entry] | None = None,
                 check: FileCheck | None = None) -> Iterator[Entry]:  # fmt: skip
    """Every finished task of a results file, deduplicated: the HDF5 file's
    groups that the journal has no newer version of, then the journal's entries.

    The journal is read first (or given as ``journalled``, read before this call): an
    entry merged and deleted meanwhile is then in the file opened after it. Malformed
    journal entries are skipped (``journal_problems`` lists them). Every group is
    verified against its checksum (``store.checksum``): damaged ones are left out and
    recorded in ``check``, with the count of verified and unverified ones."""
    path = Path(path)
    if journalled is None:
        journalled = scan(journal_dir(path), with_data)[0]
    newer = {(e.kind, e.task_id) for e in journalled}
    if path.exists():
        with _open(path) as f:
            yield from file_entries(f, with_data, check, newer)
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
    """Root attributes of each results file (with ``file``, ``n_found``, the
    number of its point and sweep tasks, and ``check``, its ``FileCheck``), and every
    finished, intact task of all of them (journals included), each task once: a result
    that is not 'failed' wins over a failed one, the first file over later ones. Each
    entry's meta gets ``file``."""
    roots, entries = [], []
    seen = set()
    for path in map(Path, paths):
        key = path.resolve()
        if key in seen:
            raise InputError(f"{path}: given twice")
        seen.add(key)
        check = FileCheck()
        root = read_root(path) | {"file": str(path), "n_found": 0, "check": check}
        roots.append(root)
        for e in iter_entries(path, with_data=True, check=check):
            e.meta["file"] = str(path)
            root["n_found"] += e.kind in (POINTS, SWEEPS)
            entries.append(e)
    return roots, list(choose_entries(entries).values())


def read_entry(path: str | Path, kind: str, task_id: str) -> Entry | None:
    """One finished task with its data, from the journal or the HDF5 file (None if
    absent or damaged)."""
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
            try:
                table = f.get(kind)
                if table is not None and is_table(table):
                    return find_row(table, kind, task_id)
                group = f.get(f"{kind}/{task_id}")
            except Exception:  # a damaged index
                return None
            task = read_task(group, True) if isinstance(group, _h5().Group) else None
            if task is not None:
                return Entry(kind, task_id, task[1], task[0])
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
        try:
            verify_root(f)
            attrs = {k: (v.item() if isinstance(v, np.generic) else v)
                     for k, v in f.attrs.items() if k not in DIGEST_ATTRS}  # fmt: skip
        except Damaged as e:
            raise InputError(f"{path}: {e}{recover_hint(path)}") from None
        except Exception as e:  # an unreadable attribute (damage or a foreign writer)
            raise InputError(f"{path}: root attributes unreadable ({type(e).__name__})"
                             f"{recover_hint(path)}") from None  # fmt: skip
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
    if version >= 2:  # the same test in every command: a spec that is no JSON object is foreign
        try:
            spec = json.loads(str(attrs["job_json"]))
        except ValueError:
            spec = None
        if not isinstance(spec, dict) or not isinstance(attrs["job_hash"], str):
            raise InputError(f"{path}: its job_json attribute is not a job spec: not a results "
                             "file written by knitsweep")  # fmt: skip
    return attrs


def read_progress(path: str | Path) -> dict[str, Any] | None:
    p = progress_path(Path(path))
    try:
        data = json.loads(p.read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None
