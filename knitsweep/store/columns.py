"""The columns of one kind's table (``store.table``; docs/results-file.md): which
column holds which scalar or array, with what dtype, fill and named dimensions, as the
table's ``columns`` attribute describes them, and the columns made and grown as rows
arrive. A damaged description is named (``Damaged``); ``described=False`` reads the
columns as the group's datasets show them, for ``recover``."""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from .checksum import Damaged

TASK, ENTRY, DIGEST = "task", "entry", "sha256"
RESERVED = (TASK, ENTRY, DIGEST)
ROW_CHUNK = 256  # rows per chunk of a 1-d column
ARRAY_ROWS = 16  # rows per chunk of an array column
STEP_CHUNK = 32  # steps per chunk (a sweep's length is not known when its column is made)
BOOL_FILL = -1


def h5():
    import h5py

    return h5py


def _fill(dtype: np.dtype) -> Any:
    if dtype.kind == "O":
        return ""
    if dtype.kind == "f":
        return np.nan
    if dtype.kind == "c":
        return complex(np.nan, np.nan)
    if dtype.kind == "b":
        return BOOL_FILL
    if dtype.kind in "iu":
        return np.iinfo(dtype).min if dtype.kind == "i" else np.iinfo(dtype).max
    return 0


def column_dtype(dtype: np.dtype):
    """(HDF5 dtype, fill) of a column holding arrays or scalars of ``dtype``."""
    if dtype.kind == "O":
        return h5().string_dtype(), ""
    if dtype.kind == "b":
        return np.dtype(np.int8), BOOL_FILL
    return dtype, _fill(dtype)


def scalar_dtype(value: Any) -> np.dtype | None:
    """The column dtype of a scalar (None: it gets no column: only ``entry``)."""
    if isinstance(value, str):
        return np.dtype(object)
    if isinstance(value, (bool, int, float)):
        return np.dtype(float)
    return None


class Columns:
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
        h5py = h5()
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
        dtype = scalar_dtype(value)
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
                                              dtype=h5().string_dtype())  # fmt: skip
            scale.attrs["long_name"] = dim.replace("_", " ")
            scale.attrs["units"] = "1"
            scale.make_scale(dim)
            self.scales[dim] = scale
        return scale

    def _create(self, role: str, name: str, dtype: np.dtype, shape: tuple[int, ...]) -> str:
        from ..quantities import SCALARS, dataset_quantity

        col = self._free_name(name)
        dims = self._dims_of(name, shape, col)
        h5dtype, fill = column_dtype(dtype)
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
