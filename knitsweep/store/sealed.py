"""Sealed records: every row of a results file, and its root attributes, once more as
self-checksummed frames that a scan of the file's raw bytes finds without HDF5's
metadata (``knitsweep recover`` of a file cut short; docs/crash-safety.md).

HDF5 keeps a file's structure (its root group, the tables' indexes, the chunk
B-trees) wherever it allocated it, often at the end: a file cut short loses it, and
with it every row, though the rows' bytes lie before the cut. So each checkpoint also
appends to ``/sealed/rows`` (a column of byte strings, which HDF5 stores each in one
piece) one cell holding a frame per row it writes, end to end

    b"KSRW" | u64 length | a journal batch of that one row (``journal.encode_batch``:
    b"KSJB" | sha256 | payload)

holding the row exactly as the table holds it (its scalars as stored, its arrays
unpadded), and to ``/sealed/roots`` a frame of the root attributes whenever they
change (b"KSRT" | u64 length | sha256 of the JSON | JSON). A frame is taken only if
its checksum holds; the frames' column is append-only (a rerun's row adds a frame,
old frames are never freed, so never partly overwritten). A row is therefore
recoverable from any cut that leaves its frame whole. The cost: each row's bytes are
in the file twice (its frame unpadded), and a checkpoint writes them once more.
"""

from __future__ import annotations

import hashlib
import json
import mmap
import os
import struct
from pathlib import Path
from typing import Any

import numpy as np

from .format import _h5, attr_value, renamed
from .journal import Entry, Malformed, decode_batch, encode_batch
from .table import _is_array, _stored_array

GROUP = "sealed"
ROWS, ROOTS = "rows", "roots"
ROW_MAGIC, ROOT_MAGIC = b"KSRW", b"KSRT"
_LENGTH = struct.Struct("<Q")
_HEAD = 4 + _LENGTH.size
_CHUNK = 64
_RUN_ATTRS = ("run_status", "finished_at", "run_seconds")  # change at every close


def row_frame(entry: Entry) -> bytes:
    """The frame of one row: its scalars and arrays as the table stores them."""
    values = {**entry.meta, **entry.record}
    attrs, arrays = {}, {}
    for key, value in values.items():
        if _is_array(value):
            arrays[key] = _stored_array(value)
        elif (v := attr_value(value)) is not None:
            attrs[key] = v
    body = encode_batch([Entry(entry.kind, entry.task_id, arrays, attrs)])
    return ROW_MAGIC + _LENGTH.pack(len(body)) + body


def root_frame(attrs: dict[str, Any], number: int) -> bytes:
    """The frame of a file's root attributes (``number``: its place in ``/sealed/roots``,
    the newest whole one wins)."""
    plain = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in attrs.items()
             if k not in _RUN_ATTRS}  # fmt: skip
    text = json.dumps({"n": number, "attrs": plain}, sort_keys=True, default=str).encode()
    body = hashlib.sha256(text).digest() + text
    return ROOT_MAGIC + _LENGTH.pack(len(body)) + body


def _column(f, name: str):
    h5py = _h5()
    group = f.require_group(GROUP)
    ds = group.get(name)
    if ds is None:
        ds = group.create_dataset(name, shape=(0,), maxshape=(None,), chunks=(_CHUNK,),
                                  dtype=h5py.vlen_dtype(np.uint8))  # fmt: skip
        ds.attrs["long_name"] = f"sealed {name}: self-checksummed frames (docs/crash-safety.md)"
        ds.attrs["units"] = "1"
    return ds


def _append(ds, frames: list[bytes]) -> None:
    """One more cell holding ``frames`` end to end (one object in HDF5's heap: a cell
    per frame would cost a heap insertion per row)."""
    n = len(ds)
    ds.resize((n + 1,))
    ds[n] = np.frombuffer(b"".join(frames), dtype=np.uint8)


def append_rows(f, entries: list[Entry], made: dict[int, tuple] | None = None) -> None:
    """Append the frames of ``entries`` (the last version of each task) to an open
    file; ``made``: frames made by an earlier call, ``id`` of the entry -> (entry,
    frame), reused (a checkpoint writes each result twice)."""
    frames = []
    for e in {(e.kind, e.task_id): e for e in entries}.values():
        got, data = (None, None) if made is None else made.get(id(e), (None, None))
        if got is not e:
            data = row_frame(e)
            if made is not None:
                made[id(e)] = (e, data)
        frames.append(data)
    if frames:
        _append(_column(f, ROWS), frames)


def append_root(f) -> None:
    """Append a frame of the root attributes if they differ from the newest frame's."""
    from .checksum import DIGEST_ATTRS

    ds = _column(f, ROOTS)
    attrs = {k: v for k, v in f.attrs.items() if k not in DIGEST_ATTRS}
    data = root_frame(attrs, len(ds))
    if len(ds):
        last = _root_of(ds[len(ds) - 1].tobytes(), 0)
        if last is not None and last[1] == _root_of(data, 0)[1]:
            return
    _append(ds, [data])


def _root_of(data: bytes | mmap.mmap, at: int) -> tuple[int, dict[str, Any], int] | None:
    """(number, attributes, end) of the root frame at ``at``, None unless whole."""
    (n,) = _LENGTH.unpack_from(data, at + 4)
    start, end = at + _HEAD, at + _HEAD + n
    if n < 32 or end > len(data):
        return None
    digest, text = data[start : start + 32], data[start + 32 : end]
    if hashlib.sha256(text).digest() != digest:
        return None
    try:
        found = json.loads(text)
        return int(found["n"]), dict(found["attrs"]), end
    except (ValueError, KeyError, TypeError):
        return None


def _row_of(data: bytes | mmap.mmap, at: int) -> tuple[Entry, int] | None:
    """(entry, end) of the row frame at ``at``, None unless whole."""
    (n,) = _LENGTH.unpack_from(data, at + 4)
    end = at + _HEAD + n
    if end > len(data):
        return None
    try:
        (entry,) = decode_batch(data[at + _HEAD : end])
    except (Malformed, ValueError):
        return None
    return Entry(entry.kind, entry.task_id, entry.record, renamed(entry.meta)), end


def scan(path: Path) -> tuple[list[tuple[int, int, Entry]], dict[str, Any] | None]:
    """The whole row frames in a file's bytes, ``(start, end, entry)`` in file order,
    and the root attributes of its newest whole root frame (None: none whole)."""
    rows: list[tuple[int, int, Entry]] = []
    roots: list[tuple[int, dict[str, Any]]] = []
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    try:
        size = os.fstat(fd).st_size
        if size < _HEAD:
            return rows, None
        with mmap.mmap(fd, size, access=mmap.ACCESS_READ) as data:
            for magic in (ROW_MAGIC, ROOT_MAGIC):
                at = data.find(magic)
                while 0 <= at <= size - _HEAD:
                    found = _row_of(data, at) if magic == ROW_MAGIC else _root_of(data, at)
                    if found is None:
                        at = data.find(magic, at + 1)
                        continue
                    if magic == ROW_MAGIC:
                        rows.append((at, found[1], found[0]))
                    else:
                        roots.append((found[0], found[1]))
                    at = data.find(magic, found[-1])
    finally:
        os.close(fd)
    return rows, max(roots, key=lambda r: r[0])[1] if roots else None
