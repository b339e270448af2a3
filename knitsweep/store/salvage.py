"""Reading what is intact in a damaged results file, or in a copy of an earlier
version of it (the writer's spare and shadow), for ``knitsweep recover``.

A truncated HDF5 file is refused by the library as a whole (its end is short of the
end-of-file address its superblock records); here a copy padded with zeros to that
address is opened instead, so every object that lies before the cut still reads.
Tasks are taken only if they pass their checksums (``store.checksum``; tasks of
files written before checksums are taken unverified and counted as such).
"""

from __future__ import annotations

import contextlib
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .checksum import DIGEST_ATTRS, Damaged, FileCheck, verify_root
from .format import _h5
from .journal import Entry
from .read import file_entries, stored_eof


@dataclass
class Salvage:
    """What one source gave: its root attributes (None: unreadable or failing their
    checksum), its intact tasks and its ``FileCheck``; ``note`` says why it could not
    be read at all."""

    path: Path
    root: dict[str, Any] | None = None
    root_verified: bool = False
    entries: list[Entry] = field(default_factory=list)
    check: FileCheck = field(default_factory=FileCheck)
    note: str = ""


@contextlib.contextmanager
def _readable(path: Path):
    """The HDF5 file at ``path`` opened for reading, or a zero-padded copy of it if it
    was truncated; yields (file or None, note)."""
    h5py = _h5()
    try:
        f = h5py.File(path, "r")
    except Exception as e:
        first = (str(e).splitlines() or [type(e).__name__])[0]
        eof = stored_eof(path)
        size = path.stat().st_size if path.exists() else 0
        if eof is None or eof <= size or eof > 64 * size + (1 << 30):
            yield None, f"unreadable ({first})"
            return
        copy = path.with_name(f".{path.name}.{os.getpid()}.recover.tmp")
        try:
            shutil.copyfile(path, copy)
            with open(copy, "r+b") as fh:
                fh.truncate(eof)  # zeros after the cut: what was before it reads again
            f = h5py.File(copy, "r")
        except Exception as e2:
            copy.unlink(missing_ok=True)
            yield None, f"unreadable, even padded to its recorded size ({type(e2).__name__})"
            return
        try:
            yield f, f"truncated to {size} of {eof} bytes: read up to the cut"
        finally:
            f.close()
            copy.unlink(missing_ok=True)
        return
    try:
        yield f, ""
    finally:
        f.close()


def salvage(path: Path) -> Salvage:
    """Every intact task of one (possibly damaged) results file, with its root."""
    out = Salvage(path)
    if not path.exists():
        out.note = "absent"
        return out
    if path.is_symlink() or not path.is_file():
        out.note = "not a regular file: not read"
        return out
    if path.stat().st_size == 0:
        out.note = "empty (0 bytes)"
        return out
    with _readable(path) as (f, note):
        out.note = note
        if f is None:
            return out
        try:
            out.root_verified = verify_root(f)
            out.root = {k: _plain(v) for k, v in f.attrs.items() if k not in DIGEST_ATTRS}
        except Damaged as e:
            out.note = "; ".join(filter(None, [out.note, str(e)]))
        except Exception as e:
            out.note = "; ".join(filter(None, [out.note, f"root unreadable ({type(e).__name__})"]))
        try:
            out.entries = list(file_entries(f, True, out.check))
        except Exception as e:  # damage past what the readers guard
            out.check.structure.append(f"reading stopped ({type(e).__name__})")
    return out


def _plain(v: Any) -> Any:
    import numpy as np

    return v.item() if isinstance(v, np.generic) else v


def _unused_name(path: Path, suffix: str) -> Path:
    candidate = path.with_name(path.name + suffix)
    n = 1
    while os.path.lexists(candidate):
        candidate = path.with_name(f"{path.name}{suffix}.{n}")
        n += 1
    return candidate


def set_aside(path: Path) -> Path | None:
    """Rename a damaged file to ``<file>.damaged`` (or ``.damaged.N``), never deleting
    it; returns the new name (None if there was no file)."""
    if not os.path.lexists(path):
        return None
    target = _unused_name(path, ".damaged")
    os.rename(path, target)
    return target


__all__ = ["Salvage", "salvage", "set_aside", "stored_eof"]
