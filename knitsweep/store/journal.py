"""The results file's write-ahead journal: one checksummed entry file per finished task.

An entry is ``<file>.journal/<kind>-<task id>.entry``, written through a temporary
file, fsync and an atomic rename, so after a kill -9 it is whole or absent. Its
bytes are

    b"KSJ1" | sha256(payload) (32 bytes) | payload

and the payload is an uncompressed ``.npz`` archive (read with
``allow_pickle=False``): a JSON header ``__entry__`` (format, kind, task id, the
scalar metadata) and one ``.npy`` member per array. Nothing in an entry can run
code when it is read (the journal used to be pickles: whoever could write into
the journal directory could run code in the master). A damaged, truncated,
foreign or old (pickle) entry is *malformed*: readers skip it and report it
(``knitsweep status``), and the master recomputes its task.

The master journals in *batches* (group commit): ``batch-<sequence>.entry`` holds
the entries that arrived while the previous batch was written, in one file written
and fsynced once (``write_batch``). Its bytes are

    b"KSJB" | sha256(payload) (32 bytes) | payload

with payload ``u32 header length | JSON header | array bytes``: the header lists
each entry (kind, task id, scalars) and, per array, its dtype, shape and offset
into the array bytes (read with ``np.frombuffer``; object dtypes are refused).
A batch is whole or absent after a kill -9; a damaged one is malformed as a whole
and all its tasks are recomputed. Sequence numbers grow, so scanning the journal
in name order meets an entry's newer version after the older one.
"""

from __future__ import annotations

import errno
import hashlib
import io
import json
import os
import re
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import StorageError, storage_error
from ..util.plain_values import plain_value
from ..util.safe_files import replace_file
from .format import renamed

__all__ = ["Entry", "Malformed", "StorageError", "atomic_write_bytes", "decode", "encode",
           "entry_path", "fsync_dir", "read_entry_file", "scan", "storage_error",
           "write_entry"]  # fmt: skip

MAGIC = b"KSJ1"
ENTRY_FORMAT = 1
SUFFIX = ".entry"
_HEADER = "__entry__"
_NAME = re.compile(r"^(points|sweeps|series)-([A-Za-z0-9._-]{1,200})$")
BATCH_MAGIC = b"KSJB"
BATCH_FORMAT = 1
_BATCH = re.compile(r"^batch-([0-9]{12})$")


@dataclass
class Entry:
    """One finished task as journalled: its kind, id, record (arrays) and metadata
    (scalars, strings, JSON-able dicts)."""

    kind: str
    task_id: str
    record: dict[str, Any]
    meta: dict[str, Any]


def fsync_dir(path: Path) -> None:
    """Make a rename or unlink in directory ``path`` durable."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems do not fsync directories; the rename is still atomic
    finally:
        os.close(fd)


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` via a temporary file, fsync and rename: a reader sees
    the old file or the new one, never a part; neither is ever a symbolic link
    followed (``util.safe_files.replace_file``). On failure no temporary file is left and
    ``StorageError`` names the cause."""
    replace_file(path, data, fsync=True)


# ---- encoding -------------------------------------------------------------------


def _plain(value: Any) -> Any:
    """A JSON value for a scalar of a record or its metadata."""
    try:
        return plain_value(value, strict=True)
    except TypeError:
        raise TypeError(f"cannot journal a value of type {type(value).__name__}") from None


def encode(entry: Entry) -> bytes:
    """The bytes of one journal entry (see the module docstring)."""
    arrays: dict[str, np.ndarray] = {}
    layout: dict[str, list[str]] = {"record": [], "meta": [], "object": []}
    scalars: dict[str, dict[str, Any]] = {"record": {}, "meta": {}}
    for part, values in (("record", entry.record), ("meta", entry.meta)):
        for key, value in values.items():
            if isinstance(value, np.ndarray) and value.ndim > 0:
                name = f"{part}/{key}"
                if value.dtype == object:
                    value = value.astype(str)
                    layout["object"].append(name)
                arrays[f"a{len(arrays)}"] = value
                layout[part].append(key)
            else:
                scalars[part][key] = _plain(value)
    header = {"format": ENTRY_FORMAT, "kind": entry.kind, "task_id": entry.task_id,
              "scalars": scalars, "layout": layout}  # fmt: skip
    buffer = io.BytesIO()
    np.savez(buffer, **{_HEADER: np.frombuffer(json.dumps(header).encode(), np.uint8)}, **arrays)
    payload = buffer.getvalue()
    return MAGIC + hashlib.sha256(payload).digest() + payload


class Malformed(ValueError):
    """A journal entry that cannot be trusted (its message says why)."""


def decode(data: bytes, with_data: bool = True) -> Entry:
    """The entry in ``data``; ``Malformed`` if it is not an intact knitsweep entry."""
    if data[:2] == b"\x80\x04" or data[:2] == b"\x80\x05":
        raise Malformed("an old pickle entry, not read (pickle could run code)")
    if len(data) < 36 or data[:4] != MAGIC:
        raise Malformed("not a knitsweep journal entry")
    payload = data[36:]
    if hashlib.sha256(payload).digest() != data[4:36]:
        raise Malformed("checksum mismatch (damaged or truncated)")
    try:
        with np.load(io.BytesIO(payload), allow_pickle=False) as npz:
            header = json.loads(npz[_HEADER].tobytes())
            if header.get("format") != ENTRY_FORMAT:
                raise Malformed(f"entry format {header.get('format')!r}, expected {ENTRY_FORMAT}")
            kind, task_id = header["kind"], header["task_id"]
            record = dict(header["scalars"]["record"])
            meta = dict(header["scalars"]["meta"])
            objects = set(header["layout"]["object"])
            index = 0
            for part, target in (("record", record), ("meta", meta)):
                for key in header["layout"][part]:
                    value = npz[f"a{index}"]  # read even if not kept: a reader that
                    if f"{part}/{key}" in objects:  # skips it must not count it intact
                        value = np.array(value.tolist(), dtype=object)
                    if with_data or part == "meta":
                        target[key] = value
                    index += 1
    except Malformed:
        raise
    except Exception as e:  # whatever a checksummed but foreign payload raises
        raise Malformed(f"unreadable ({type(e).__name__})") from None
    if not (isinstance(kind, str) and isinstance(task_id, str)):
        raise Malformed("kind or task id is not a string")
    return Entry(kind, task_id, renamed(record), renamed(meta))


# ---- the journal directory ------------------------------------------------------


def entry_path(journal: Path, kind: str, task_id: str) -> Path:
    return journal / f"{kind}-{task_id}{SUFFIX}"


def write_entry(journal: Path, entry: Entry) -> Path:
    """Journal one entry durably (atomic, fsynced); returns its path."""
    path = entry_path(journal, entry.kind, entry.task_id)
    atomic_write_bytes(path, encode(entry))
    return path


def read_entry_file(path: Path, with_data: bool = True) -> Entry:
    """One entry file, checked against its name; ``Malformed`` or FileNotFoundError."""
    match = _NAME.match(path.name.removesuffix(SUFFIX))
    if match is None:
        raise Malformed("not a journal entry name")
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    except FileNotFoundError:
        raise
    except OSError as e:
        why = "a symbolic link, not read" if e.errno == errno.ELOOP else e.strerror or e
        raise Malformed(f"unreadable ({why})") from None
    with os.fdopen(fd, "rb") as fh:
        data = fh.read()
    entry = decode(data, with_data)
    if (entry.kind, entry.task_id) != match.groups():
        raise Malformed(f"holds {entry.kind}/{entry.task_id}, not what its name says")
    return entry


def scan(journal: Path, with_data: bool = False) -> tuple[list[Entry], list[tuple[Path, str]]]:
    """The journal's intact entries and its malformed files ``(path, why)``.

    Single entry files come first, then the batches in sequence order (a task's
    later entry follows its earlier one). Entries merged into the HDF5 file (and
    deleted) while this reads are skipped; old pickle entries (``*.pkl``) are
    listed as malformed, never unpickled."""
    entries: list[Entry] = []
    problems: list[tuple[Path, str]] = []
    if journal.is_symlink():  # it could point anywhere: never read, written or cleaned
        return entries, [(journal, "the journal directory is a symbolic link, not read")]
    if journal.is_dir():
        for path in sorted(journal.iterdir()):
            if path.is_symlink() and not path.name.startswith("."):
                problems.append((path, "a symbolic link, not read (and never deleted through)"))
    for path in journal_files(journal):
        if path.suffix == ".pkl":
            problems.append((path, "an old pickle entry, not read (pickle could run code)"))
            continue
        try:
            if _BATCH.match(path.name.removesuffix(SUFFIX)):
                entries.extend(read_batch_file(path, with_data))
            else:
                entries.append(read_entry_file(path, with_data))
        except FileNotFoundError:
            continue
        except Malformed as e:
            problems.append((path, str(e)))
    return entries, problems


def journal_files(journal: Path) -> list[Path]:
    """The journal's files in reading order: entry files, then batches by sequence
    (temporary files of writes under way and symbolic links are not listed: nothing
    is read, written or deleted through a link)."""
    if not journal.is_dir():
        return []
    if journal.is_symlink():
        return []
    paths = [p for p in journal.iterdir()
             if not p.name.startswith(".") and not p.is_symlink() and p.is_file()]  # fmt: skip
    return sorted(paths, key=lambda p: (p.name.startswith("batch-"), p.name))


def next_batch_number(journal: Path) -> int:
    """One more than the highest batch sequence number in ``journal``."""
    numbers = [int(m.group(1)) for p in journal_files(journal)
               if (m := _BATCH.match(p.name.removesuffix(SUFFIX)))]  # fmt: skip
    return max(numbers, default=0) + 1


# ---- batches (group commit) -----------------------------------------------------


def batch_path(journal: Path, number: int) -> Path:
    return journal / f"batch-{number:012d}{SUFFIX}"


_JSON_TYPES = (str, float, int, bool, type(None))


def encode_batch(entries: list[Entry]) -> bytes:
    """The bytes of one batch file (see the module docstring)."""
    blobs: list[bytes] = []
    offset = 0
    listed = []
    for entry in entries:
        arrays = []
        scalars: dict[str, dict[str, Any]] = {"record": {}, "meta": {}}
        for part, values in (("record", entry.record), ("meta", entry.meta)):
            for key, value in values.items():
                if isinstance(value, np.ndarray) and value.ndim > 0:
                    is_object = value.dtype == object
                    if is_object:
                        value = value.astype(str)
                    data = np.ascontiguousarray(value).tobytes()
                    arrays.append([part, key, value.dtype.str, list(value.shape), offset,
                                   len(data), is_object])  # fmt: skip
                    blobs.append(data)
                    offset += len(data)
                elif type(value) in _JSON_TYPES:
                    scalars[part][key] = value
                else:
                    scalars[part][key] = _plain(value)
        listed.append({"kind": entry.kind, "task_id": entry.task_id, "scalars": scalars,
                       "arrays": arrays})  # fmt: skip
    header = json.dumps({"format": BATCH_FORMAT, "entries": listed}, separators=(",", ":"),
                        check_circular=False).encode()  # fmt: skip
    payload = b"".join([struct.pack("<I", len(header)), header, *blobs])
    return BATCH_MAGIC + hashlib.sha256(payload).digest() + payload


def decode_batch(data: bytes, with_data: bool = True) -> list[Entry]:
    """The entries of one batch file; ``Malformed`` if it is not an intact batch."""
    if len(data) < 40 or data[:4] != BATCH_MAGIC:
        raise Malformed("not a knitsweep journal batch")
    payload = memoryview(data)[36:]
    if hashlib.sha256(payload).digest() != data[4:36]:
        raise Malformed("checksum mismatch (damaged or truncated)")
    try:
        (n,) = struct.unpack_from("<I", payload, 0)
        header = json.loads(bytes(payload[4 : 4 + n]))
        if header.get("format") != BATCH_FORMAT:
            raise Malformed(f"batch format {header.get('format')!r}, expected {BATCH_FORMAT}")
        blob = payload[4 + n :]
        out = []
        for item in header["entries"]:
            record = dict(item["scalars"]["record"])
            meta = dict(item["scalars"]["meta"])
            for part, key, dtype, shape, offset, size, is_object in item["arrays"]:
                if not with_data and part == "record":
                    continue
                dt = np.dtype(dtype)
                if dt.hasobject or offset < 0 or offset + size > len(blob):
                    raise Malformed("an array outside the batch or of object dtype")
                value = np.frombuffer(blob[offset : offset + size], dtype=dt).reshape(shape)
                value = np.array(value.tolist(), dtype=object) if is_object else value.copy()
                (record if part == "record" else meta)[key] = value
            kind, task_id = item["kind"], item["task_id"]
            if not (isinstance(kind, str) and isinstance(task_id, str)):
                raise Malformed("kind or task id is not a string")
            out.append(Entry(kind, task_id, record, meta))
    except Malformed:
        raise
    except Exception as e:  # whatever a checksummed but foreign payload raises
        raise Malformed(f"unreadable ({type(e).__name__})") from None
    return out


def write_batch(journal: Path, number: int, entries: list[Entry]) -> Path:
    """Journal several entries durably in one file: one write, one fsync of it and
    one of the directory (the group commit); returns its path."""
    path = batch_path(journal, number)
    atomic_write_bytes(path, encode_batch(entries))
    fsync_dir(journal)
    return path


def read_batch_file(path: Path, with_data: bool = True) -> list[Entry]:
    """The entries of one batch file; ``Malformed`` or FileNotFoundError."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise
    except OSError as e:
        raise Malformed(f"unreadable ({e.strerror or e})") from None
    return decode_batch(data, with_data)
