"""Results as tables: every task of a kind one row of ``/points``, ``/sweeps`` or
``/series`` (results schema 3; docs/results-file.md).

A checkpoint appends its results to each kind's columns in one write per column, so
its cost grows with the number of columns, not of results (one HDF5 group per task,
schema 2, cost ~10 ms a result and capped one master near 100 results/s).

Columns of a kind's group (attribute ``layout = "table"``):

* ``task`` (the dimension scale of the rows): task ids; a rerun's result replaces its
  task's row in place;
* ``entry``: per row a JSON object, ``{"attrs": {...}, "arrays": {name: [column,
  shape]}}``: the task's scalars exactly (types kept), and where each array lives
  and its shape;
* ``sha256``: per row, the digest of the task id, ``entry`` and every array's dtype,
  shape and bytes (``row_digest``), verified on every read;
* one column per scalar that is a number or a string (NaN or "" where a row has none),
  named as the scalar: a view of ``entry`` for other readers (xarray, h5py), checked
  against it on every read;
* one column per array, ``(task, <leading dimension>, <trailing dimensions>…)``,
  padded to the longest row (NaN, the smallest integer, -1 for booleans, ""), with
  ``units``, ``long_name`` and named dimension scales, so that
  ``xarray.open_dataset(file, engine="h5netcdf", group="sweeps")`` opens a kind as one
  dataset over (task, step, …). An array whose dtype differs from its column's goes
  to a column of its own (``<name>__2`` …), so every column holds one dtype exactly.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterator
from typing import Any

import numpy as np

from .checksum import Damaged, FileCheck, _update
from .columns import (
    DIGEST,
    ENTRY,
    ROW_CHUNK,
    TASK,
    Columns,
    column_dtype,
    h5,
    scalar_dtype,
)
from .format import attr_value, renamed
from .journal import Entry

LAYOUT = "table"
READ_ROWS = 512  # rows read at a time (bounds a reader's memory)
_DOMAIN = b"knitsweep-row-1\0"


def is_table(group) -> bool:
    return group.attrs.get("layout") == LAYOUT


def create_table(f, kind: str):
    """An empty table for ``kind`` in an open file."""
    h5py = h5()
    g = f.create_group(kind)
    g.attrs["layout"] = LAYOUT
    scale = g.create_dataset(TASK, shape=(0,), maxshape=(None,), chunks=(ROW_CHUNK,),
                             dtype=h5py.string_dtype())  # fmt: skip
    scale.attrs["long_name"] = "task id"
    scale.attrs["units"] = "1"
    scale.make_scale(TASK)
    for name, long_name in ((ENTRY, "the task's scalars and array shapes (JSON)"),
                            (DIGEST, "SHA-256 digest of the row")):  # fmt: skip
        ds = g.create_dataset(name, shape=(0,), maxshape=(None,), chunks=(ROW_CHUNK,),
                              dtype=h5py.string_dtype())  # fmt: skip
        ds.attrs["long_name"] = long_name
        ds.attrs["units"] = "1"
        ds.dims[0].attach_scale(scale)
    return g


# ---- one row ---------------------------------------------------------------------


def _is_array(value: Any) -> bool:
    return isinstance(value, np.ndarray) and value.ndim > 0


def _stored_array(value: np.ndarray) -> np.ndarray:
    """An array as a row holds it: strings as a str object array, the rest as is."""
    if value.dtype.kind in "OUS":
        return np.array([v.decode() if isinstance(v, bytes) else str(v)
                         for v in value.reshape(-1)], dtype=object).reshape(value.shape)  # fmt: skip
    return np.ascontiguousarray(value)


def row_digest(task_id: str, entry_json: str, arrays: dict[str, np.ndarray]) -> str:
    """The digest of one row: its task id, its ``entry`` JSON and its arrays (name,
    shape, dtype and bytes, in name order)."""
    h = hashlib.sha256(_DOMAIN)
    for text in (task_id, entry_json):
        data = text.encode("utf-8", "surrogatepass")
        h.update(b"%d:" % len(data) + data)
    for name in sorted(arrays):  # tagged as a task group's datasets are (store.checksum)
        h.update(b"D" + name.encode() + b"\0")
        _update(h, arrays[name])
    return h.hexdigest()


class _Row:
    """One entry prepared for writing: scalars, arrays, their columns, JSON, digest."""

    def __init__(self, entry: Entry, columns: Columns) -> None:
        values = {**entry.meta, **entry.record}
        self.task_id = entry.task_id
        self.attrs = {}
        self.arrays = {}
        for key, value in values.items():
            if _is_array(value):
                self.arrays[key] = _stored_array(value)
            else:
                v = attr_value(value)
                if v is not None:
                    self.attrs[key] = v
        self.places = {k: columns.array_column(k, a) for k, a in self.arrays.items()}
        listed = {k: [self.places[k], list(a.shape)] for k, a in sorted(self.arrays.items())}
        self.index = -1
        self.json = json.dumps({"attrs": self.attrs, "arrays": listed}, sort_keys=True,
                               separators=(",", ":"))  # fmt: skip
        self.digest = row_digest(self.task_id, self.json, self.arrays)


# ---- the columns of one table ----------------------------------------------------


def _rows_of(task_ids: np.ndarray) -> dict[str, int]:
    return {_text(t): i for i, t in enumerate(task_ids)}


def _text(v: Any) -> str:  # bad bytes (damage) read as U+FFFD: the row fails its checks
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else v


def put_rows(group, kind: str, entries: list[Entry], prepared: dict | None = None) -> None:
    """Write ``entries`` into the table: a task already there replaced in its row (the
    last of several versions of one task in ``entries`` wins), the others appended.
    ``prepared``: rows made by an earlier call, ``id`` of the entry -> (entry, row),
    reused where their columns are this file's (a checkpoint writes each result twice)."""
    if not entries:
        return
    columns = Columns(group, kind)
    rows = []
    for e in {e.task_id: e for e in entries}.values():
        made, r = (None, None) if prepared is None else prepared.get(id(e), (None, None))
        if made is not e or any(columns.array_column(k, a) != r.places[k]
                                for k, a in r.arrays.items()):  # fmt: skip
            r = _Row(e, columns)
            if prepared is not None:
                prepared[id(e)] = (e, r)
        rows.append(r)
    where = _rows_of(group[TASK][()])
    cells: dict[str, list] = {}
    for r in rows:
        r.index = where.setdefault(r.task_id, len(where))
    rows.sort(key=lambda r: r.index)
    for i, r in enumerate(rows):
        for k, v in r.attrs.items():
            col = columns.scalar_column(k, v)
            if col is not None:
                cells.setdefault(col, []).append((i, v))
        for k, a in r.arrays.items():
            cells.setdefault(r.places[k], []).append((i, a))
    columns.grow(TASK, len(where))
    for col, dims in list(columns.dims.items()):  # trailing dimensions long enough
        for axis, dim in enumerate(dims[1:]):
            columns.grow(dim, max((a.shape[axis] for _, a in cells.get(col, ())), default=0))
    sel = _selection(np.array([r.index for r in rows]))
    for name, values in ((TASK, [r.task_id for r in rows]), (ENTRY, [r.json for r in rows]),
                         (DIGEST, [r.digest for r in rows])):  # fmt: skip
        group[name][sel] = np.array(values, dtype=object)
    for col in columns.dims:  # every column: a replaced row's old cells become fill
        ds = group[col]
        h5dtype, fill = column_dtype(columns.dtype[col])
        object_ = columns.dtype[col].kind == "O"
        block = np.full((len(rows), *ds.shape[1:]), fill, dtype=object if object_ else h5dtype)
        if columns.role[col] == "scalar":
            listed = cells.get(col, ())
            if listed:
                at, values = zip(*listed, strict=True)
                block[list(at)] = values
        else:
            for i, a in cells.get(col, ()):
                block[(i, *(slice(0, s) for s in a.shape))] = a
        ds[sel] = block
    columns.save()


def _selection(index: np.ndarray):
    """A slice for contiguous rows, else the sorted row list (h5py's point selection)."""
    if index[-1] - index[0] + 1 == len(index):
        return slice(int(index[0]), int(index[-1]) + 1)
    return list(map(int, index))


# ---- reading ---------------------------------------------------------------------


def _decode(v: Any) -> Any:
    return v.decode("utf-8", "surrogatepass") if isinstance(v, bytes) else v


def table_entries(group, kind: str, check: FileCheck | None = None,
                  skip: set | frozenset = frozenset(), salvage: bool = False) -> Iterator[Entry]:  # fmt: skip
    """The verified entries of a table (with their arrays), but those whose (kind, task
    id) is in ``skip``; a damaged row is left out and recorded in ``check``. A damaged
    column description hides every row (recorded in ``check.structure``), unless
    ``salvage`` (``knitsweep recover``): then the rows are read from the columns
    found, each verified by its digest."""
    try:
        columns = Columns(group, kind)
    except Damaged as e:
        if check is not None:
            check.structure.append(str(e))
        if not salvage:
            return
        columns = Columns(group, kind, described=False)
    tasks = [_text(t) for t in group[TASK][()]]
    for start in range(0, len(tasks), READ_ROWS):
        stop = min(start + READ_ROWS, len(tasks))
        block, unreadable = {}, {}
        for name in (ENTRY, DIGEST, *columns.dims):
            try:
                block[name] = group[name][start:stop]
            except Exception as e:  # HDF5 raises OSError, KeyError, RuntimeError … on damage
                unreadable[name] = f"column {name} unreadable ({type(e).__name__})"
        for why in unreadable.values():  # a column HDF5 cannot read cannot be written either
            if check is not None and f"/{kind}: {why}" not in check.structure:
                check.structure.append(f"/{kind}: {why}")
        for i, tid in enumerate(tasks[start:stop]):
            if not tid or (kind, tid) in skip:
                continue
            try:
                if unreadable:
                    raise Damaged("; ".join(unreadable.values()))
                entry = _row_entry(kind, tid, block, i, columns)
            except Damaged as e:
                if check is not None:
                    check.damaged.append((kind, tid, str(e)))
                continue
            if check is not None:
                check.verified += 1
            yield entry


def find_row(group, kind: str, task_id: str) -> Entry | None:
    """One task's verified entry (None: absent or damaged)."""
    where = _rows_of(group[TASK][()]).get(task_id)
    if where is None:
        return None
    try:
        columns = Columns(group, kind)
        block = {name: group[name][where : where + 1] for name in (ENTRY, DIGEST, *columns.dims)}
        return _row_entry(kind, task_id, block, 0, columns)
    except Exception:
        return None


def _row_entry(kind: str, task_id: str, block: dict, i: int, columns: Columns) -> Entry:
    """The verified entry of row ``i`` of ``block`` (the columns' rows read); ``Damaged``."""
    try:  # a flipped byte may leave a string that is no UTF-8
        entry_json, digest = _decode(block[ENTRY][i]), _decode(block[DIGEST][i])
        listed = json.loads(entry_json)
        attrs, placed = listed["attrs"], listed["arrays"]
        arrays = {}
        for name, (col, shape) in placed.items():
            a = block[col][(i, *(slice(0, s) for s in shape))]
            dtype = columns.dtype[col]
            if dtype.kind == "O":
                a = np.array([_decode(s) for s in a.reshape(-1)], dtype=object).reshape(shape)
            else:
                a = np.ascontiguousarray(a.astype(dtype))
            arrays[name] = a
    except Exception as e:
        raise Damaged(f"unreadable ({type(e).__name__})") from None
    if row_digest(task_id, entry_json, arrays) != digest and not (
            not columns.described and _as_bool(task_id, entry_json, arrays, placed, digest,
                                               columns)):  # fmt: skip
        raise Damaged("checksum mismatch (the stored data changed after it was written)")
    for col, name in columns.name_of.items():  # the scalar columns say what entry says
        if columns.role[col] != "scalar" or not columns.described:
            continue
        v = attrs.get(name)
        want = v if v is not None and scalar_dtype(v) == columns.dtype[col] else None
        got = block[col][i]
        if columns.dtype[col].kind == "O":
            ok = _text(got) == (want if want is not None else "")
        else:
            w = np.nan if want is None else float(want)
            ok = bool(got == w or (np.isnan(got) and np.isnan(w)))
        if not ok:
            raise Damaged(f"its {col} column disagrees with its entry")
    return Entry(kind, task_id, arrays, renamed(dict(attrs)))


def _as_bool(task_id, entry_json, arrays, placed, digest, columns) -> bool:
    """Whether the row matches its digest with its int8 columns read as booleans (what
    a damaged description no longer says); if so, ``arrays`` holds them so."""
    flags = {name: arrays[name].astype(bool) for name, (col, _) in placed.items()
             if columns.dtype[col] == np.int8}  # fmt: skip
    if not flags or row_digest(task_id, entry_json, {**arrays, **flags}) != digest:
        return False
    arrays.update(flags)
    return True
