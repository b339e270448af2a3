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
from .format import attr_value, renamed
from .journal import Entry

LAYOUT = "table"
TASK, ENTRY, DIGEST = "task", "entry", "sha256"
RESERVED = (TASK, ENTRY, DIGEST)
ROW_CHUNK = 256  # rows per chunk of a 1-d column
ARRAY_ROWS = 16  # rows per chunk of an array column
STEP_CHUNK = 32  # steps per chunk (a sweep's length is not known when its column is made)
READ_ROWS = 512  # rows read at a time (bounds a reader's memory)
_DOMAIN = b"knitsweep-row-1\0"
_BOOL_FILL = -1


def _h5():
    import h5py

    return h5py


def is_table(group) -> bool:
    return group.attrs.get("layout") == LAYOUT


def create_table(f, kind: str):
    """An empty table for ``kind`` in an open file."""
    h5py = _h5()
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

    def __init__(self, entry: Entry, columns: _Columns) -> None:
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


def _fill(dtype: np.dtype) -> Any:
    if dtype.kind == "O":
        return ""
    if dtype.kind == "f":
        return np.nan
    if dtype.kind == "c":
        return complex(np.nan, np.nan)
    if dtype.kind == "b":
        return _BOOL_FILL
    if dtype.kind in "iu":
        return np.iinfo(dtype).min if dtype.kind == "i" else np.iinfo(dtype).max
    return 0


def _column_dtype(dtype: np.dtype):
    """(HDF5 dtype, fill) of a column holding arrays or scalars of ``dtype``."""
    if dtype.kind == "O":
        return _h5().string_dtype(), ""
    if dtype.kind == "b":
        return np.dtype(np.int8), _BOOL_FILL
    return dtype, _fill(dtype)


def _scalar_dtype(value: Any) -> np.dtype | None:
    """The column dtype of a scalar (None: it gets no column: only ``entry``)."""
    if isinstance(value, str):
        return np.dtype(object)
    if isinstance(value, (bool, int, float)):
        return np.dtype(float)
    return None


class _Columns:
    """The columns of one kind's table, as its ``columns`` attribute lists them
    (column -> [name, role, the values' dtype, dimensions]), created as needed."""

    def __init__(self, group, kind: str, described: bool = True) -> None:
        self.g = group
        self.kind = kind
        self.scales: dict[str, Any] = {}
        self.dims: dict[str, tuple[str, ...]] = {}
        self.dtype: dict[str, np.dtype] = {}  # the values' dtype (bool for an int8 column)
        self.role: dict[str, str] = {}
        self.name_of: dict[str, str] = {}
        self._found: dict[tuple, str] = {}  # (role, name, dtype, rank) -> column
        self.changed = False
        self.described = described  # False: the columns as found (the description damaged)
        if not described:
            self._from_datasets()
            return
        try:
            listed = json.loads(group.attrs.get("columns", "{}"))
            for col, (name, role, dtype, dims) in listed.items():
                if not (isinstance(name, str) and role in ("array", "scalar")):
                    raise ValueError(col)
                col.encode(), name.encode()  # a flipped byte may leave no UTF-8 (\udcxx)
                self._register(col, name, role, np.dtype(dtype), tuple(map(str, dims)))
        except Exception as e:  # a JSON that no longer parses, or not a description
            raise Damaged(f"/{kind}: column description unreadable ({type(e).__name__})") from None

    def _from_datasets(self) -> None:
        """The columns as the group's datasets show them (for ``recover`` when the
        ``columns`` attribute is damaged): a row's ``entry`` says which of them it
        uses; its digest decides what an int8 column held (bool or int8)."""
        h5py = _h5()
        for col, ds in self.g.items():
            if col in RESERVED or not isinstance(ds, h5py.Dataset) or ds.is_scale:
                continue
            dtype = np.dtype(object) if ds.dtype.kind in "OSU" else ds.dtype
            role = "scalar" if ds.ndim == 1 else "array"
            self._register(col, col, role, dtype, (TASK, *(f"axis{i}" for i in range(1, ds.ndim))))

    def _register(self, col, name, role, dtype, dims) -> None:
        self.dims[col], self.dtype[col], self.role[col] = dims, dtype, role
        self.name_of[col] = name
        self._found.setdefault((role, name, dtype, len(dims) - 1), col)

    def save(self) -> None:
        """Write the ``columns`` attribute if a column was made."""
        if self.changed:
            listed = {c: [self.name_of[c], self.role[c], self.dtype[c].str, list(self.dims[c])]
                      for c in self.dims}  # fmt: skip
            self.g.attrs["columns"] = json.dumps(listed, sort_keys=True)

    def _free_name(self, name: str) -> str:
        if name not in self.g and name not in RESERVED:
            return name
        i = 2
        while f"{name}__{i}" in self.g:
            i += 1
        return f"{name}__{i}"

    def array_column(self, name: str, value: np.ndarray) -> str:
        """The column of array ``name`` with ``value``'s dtype and rank (made if new)."""
        col = self._found.get(("array", name, value.dtype, value.ndim))
        return col if col is not None else self._create("array", name, value.dtype, value.shape)

    def scalar_column(self, name: str, value: Any) -> str | None:
        """The column of scalar ``name`` (None: a value that only ``entry`` holds)."""
        dtype = _scalar_dtype(value)
        if dtype is None:
            return None
        col = self._found.get(("scalar", name, dtype, 0))
        return col if col is not None else self._create("scalar", name, dtype, ())

    def _dims_of(self, name: str, shape: tuple[int, ...], col: str) -> tuple[str, ...]:
        from ..quantities import TRAILING_DIMS, leading_dimension

        if not shape:
            return (TASK,)
        trailing = TRAILING_DIMS.get(name, ())
        dims = (leading_dimension(self.kind, name), *trailing)
        if len(dims) != len(shape):
            dims = tuple(f"{col}_axis{i}" for i in range(len(shape)))
        return (TASK, *dims)

    def _scale(self, dim: str):
        """The dimension scale of ``dim`` (made if new): the labels of a dimension that
        every stitch labels alike (``quantities.AXES``), else 0 … n-1."""
        from ..quantities import AXES

        scale = self.scales.get(dim)
        if scale is None:
            scale = self.scales[dim] = self.g.get(dim)
        if scale is None:
            labels = AXES.get(dim) if dim != "contact_class" else None  # that one: per stitch
            if labels is None:
                scale = self.g.create_dataset(dim, shape=(0,), maxshape=(None,), chunks=(256,),
                                              dtype=np.int64)  # fmt: skip
            else:
                scale = self.g.create_dataset(dim, data=np.array(labels, dtype=object),
                                              dtype=_h5().string_dtype())  # fmt: skip
            scale.attrs["long_name"] = dim.replace("_", " ")
            scale.attrs["units"] = "1"
            scale.make_scale(dim)
            self.scales[dim] = scale
        return scale

    def _create(self, role: str, name: str, dtype: np.dtype, shape: tuple[int, ...]) -> str:
        from ..quantities import SCALARS, dataset_quantity

        col = self._free_name(name)
        dims = self._dims_of(name, shape, col)
        h5dtype, fill = _column_dtype(dtype)
        sizes = [len(self.g[TASK])] + [len(self._scale(d)) for d in dims[1:]]
        inner = [STEP_CHUNK if d == "step" else min(128, max(1, n, m))
                 for d, n, m in zip(dims[1:], sizes[1:], shape, strict=True)]  # fmt: skip
        rows = ARRAY_ROWS if inner else ROW_CHUNK
        ds = self.g.create_dataset(
            col,
            shape=tuple(sizes),
            maxshape=(None,) * len(sizes),
            chunks=(rows, *inner),
            dtype=h5dtype,
            fillvalue=None if dtype.kind == "O" else fill,
        )  # fmt: skip  (uncompressed: a damaged byte spoils its row, not its chunk)
        q = dataset_quantity(self.kind, name) if role == "array" else SCALARS.get(name)
        ds.attrs["units"] = q.units if q else "1"
        ds.attrs["long_name"] = q.long_name if q else name.replace("_", " ")
        if dtype.kind != "O":
            ds.attrs["_FillValue"] = np.array(fill, dtype=h5dtype)
        for axis, dim in enumerate(dims):
            ds.dims[axis].attach_scale(self.g[TASK] if dim == TASK else self._scale(dim))
        self._register(col, name, role, dtype, dims)
        self.changed = True
        return col

    def grow(self, dim: str, size: int) -> None:
        """Dimension ``dim`` (and every column along it) at least ``size`` long."""
        scale = self.g[TASK] if dim == TASK else self._scale(dim)
        old = len(scale)
        if size <= old:
            return
        scale.resize((size,))
        if dim != TASK:
            scale[old:] = np.arange(old, size)
        for col, dims in self.dims.items():
            if dim in dims:
                ds = self.g[col]
                shape = list(ds.shape)
                for axis, d in enumerate(dims):
                    if d == dim:
                        shape[axis] = size
                ds.resize(tuple(shape))
        if dim == TASK:
            for name in (ENTRY, DIGEST):
                self.g[name].resize((size,))


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
    columns = _Columns(group, kind)
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
        h5dtype, fill = _column_dtype(columns.dtype[col])
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
        columns = _Columns(group, kind)
    except Damaged as e:
        if check is not None:
            check.structure.append(str(e))
        if not salvage:
            return
        columns = _Columns(group, kind, described=False)
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
        columns = _Columns(group, kind)
        block = {name: group[name][where : where + 1] for name in (ENTRY, DIGEST, *columns.dims)}
        return _row_entry(kind, task_id, block, 0, columns)
    except Exception:
        return None


def _row_entry(kind: str, task_id: str, block: dict, i: int, columns: _Columns) -> Entry:
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
        want = v if v is not None and _scalar_dtype(v) == columns.dtype[col] else None
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
