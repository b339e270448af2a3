"""The results file: one HDF5 file per job, written only by the master.

Crash safety without parallel HDF5 or SWMR:

1. every result that arrives is first written to a journal entry,
   ``<file>.journal/<task id>.pkl``, through a temporary file, fsync and an
   atomic rename: after a kill -9 an entry is either whole or absent;
2. every ``checkpoint_s`` seconds (and at the end) the master copies the HDF5
   file, adds the journalled results to the copy and renames the copy over the
   original (atomic), then deletes the merged entries.

So at any instant the HDF5 file on disk is a complete, readable version, and
no result that arrived is lost; readers (``knitsweep status``, the
post-processor) see the file plus the journal, deduplicated by task id.

Schema (``schema_version`` 2, :data:`RESULTS_SCHEMA_VERSION`; documented in the
README). Files of schema 1 (knitsweep before the record round trip) still read;
they cannot be resumed or merged into.

* root attributes: ``schema_version``, ``knitsweep_version``, ``git_commit``,
  ``job_json`` (effective job spec), ``job_hash``, ``job_name``, library versions
  (``numpy_version`` … ``mpi_library_version``), ``host``, ``slurm_job_id``,
  ``started_at``, ``finished_at``, ``run_status``, ``n_points``, ``n_sweeps``;
* ``/points/<id>``: one grid point's zero-force relaxation over all starts
  (``ZeroForce.to_record``: every field of every start);
* ``/sweeps/<id>``: one strain sweep (``SweepResult.to_record``: arrays over steps,
  step 0 = zero force), with its energy gaps ``delta_E_b``, ``delta_E_c`` and
  ``energy_gap`` (the direction's jamming gap: ΔE_c in x, ΔE_b in y) as attributes;
* ``/series/<id>`` (adaptive jobs): one L series' final transition bracket.
Each task group has attributes ``status`` (done | failed | not_knittable),
``message``, the stitch parameters (``L_mm`` … ``twist_bound``, and ``L_over_r``),
``rank``, ``host``, ``seconds`` and, on failure, ``error_kind``,
``error_message``, ``traceback``. Scalars of a record are attributes, arrays are
datasets.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import pickle
import shutil
import socket
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from ..config import InputError

RESULTS_SCHEMA_VERSION = 2
"""The results-file format this knitsweep writes."""
READABLE_SCHEMAS = (1, 2)
"""Results-file formats this knitsweep reads."""
POINTS, SWEEPS, SERIES = "points", "sweeps", "series"
KINDS = (POINTS, SWEEPS, SERIES)
_STR = None  # h5py string dtype, created lazily


def now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def journal_dir(path: Path) -> Path:
    return path.with_name(path.name + ".journal")


def progress_path(path: Path) -> Path:
    return path.with_name(path.name + ".progress.json")


def lock_path(path: Path) -> Path:
    return path.with_name(path.name + ".lock")


def atomic_write_bytes(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _h5():
    import h5py

    return h5py


def _string_dtype():
    global _STR
    if _STR is None:
        _STR = _h5().string_dtype()
    return _STR


def environment_metadata() -> dict[str, str]:
    """Versions, host, git commit and SLURM job of this run (root attributes)."""
    import platform

    import numba
    import numpy
    import scipy

    h5py = _h5()
    meta = {
        "knitsweep_version": __version__,
        "python_version": platform.python_version(),
        "numpy_version": numpy.__version__,
        "scipy_version": scipy.__version__,
        "numba_version": numba.__version__,
        "h5py_version": h5py.__version__,
        "hdf5_version": h5py.version.hdf5_version,
        "host": socket.gethostname(),
        "slurm_job_id": os.environ.get("SLURM_JOB_ID", ""),
        "git_commit": _git_commit(),
    }
    try:
        import mpi4py

        mpi4py.rc.initialize = False  # asking for versions must not start MPI
        from mpi4py import MPI

        meta["mpi4py_version"] = mpi4py.__version__
        meta["mpi_library_version"] = MPI.Get_library_version().strip().splitlines()[0]
    except Exception as e:
        meta["mpi4py_version"] = f"unavailable ({e})"
        meta["mpi_library_version"] = "unavailable"
    return meta


def _git_commit() -> str:
    import subprocess

    here = Path(__file__).resolve().parent
    try:
        out = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True,
                             text=True, timeout=5)  # fmt: skip
        dirty = subprocess.run(["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5)  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    if out.returncode != 0:
        return "unknown (not a git checkout)"
    return out.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")


# ---- writing ---------------------------------------------------------------------


def split_record(record: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(arrays, scalars) of a task's record: what becomes datasets and what becomes
    attributes of its group."""
    arrays = {k: v for k, v in record.items() if isinstance(v, np.ndarray) and v.ndim > 0}
    return arrays, {k: v for k, v in record.items() if k not in arrays}


def _write_group(group, record: dict[str, Any], meta: dict[str, Any]) -> None:
    """A task's record as datasets (arrays) and attributes (scalars) of ``group``;
    every dataset gets ``units`` and ``long_name`` and labelled dimension scales
    (``step`` in a sweep, ``start`` in a point, then e.g. ``state_entry``)."""
    kind = group.name.strip("/").split("/")[0]
    for key, value in {**meta, **record}.items():
        if value is None:
            continue
        if isinstance(value, np.ndarray) and value.ndim > 0:
            if value.dtype == object:
                group.create_dataset(key, data=value.astype(str).astype(object),
                                     dtype=_string_dtype())  # fmt: skip
            else:
                group.create_dataset(
                    key, data=value, compression="gzip" if value.size > 256 else None
                )
            describe_dataset(group, kind, key)
        elif isinstance(value, dict):
            group.attrs[key] = json.dumps(value, sort_keys=True)
        elif isinstance(value, (bool, np.bool_)):
            group.attrs[key] = bool(value)
        elif isinstance(value, (int, np.integer)):
            group.attrs[key] = int(value)
        elif isinstance(value, (float, np.floating)):
            group.attrs[key] = float(value)
        else:
            group.attrs[key] = str(value)


_LEADING_DIM = {POINTS: ("start", "start of the zero-force relaxation"),
                SWEEPS: ("step", "strain step (0: the zero-force state)")}  # fmt: skip


def describe_dataset(group, kind: str, name: str) -> None:
    """``units``, ``long_name`` and dimension scales of dataset ``name`` (xarray and
    netCDF readers then see named dimensions and coordinates)."""
    from ..quantities import AXES, TRAILING_DIMS, dataset_quantity

    ds = group[name]
    q = dataset_quantity(kind, name)
    ds.attrs["units"] = q.units if q else "1"
    ds.attrs["long_name"] = q.long_name if q else name.replace("_", " ")
    trailing = TRAILING_DIMS.get(name, ())
    dims = list(trailing[-(ds.ndim) :]) if ds.ndim <= len(trailing) else list(trailing)
    if ds.ndim > len(trailing) and kind in _LEADING_DIM:
        dims = [_LEADING_DIM[kind][0], *dims]
    if len(dims) != ds.ndim:
        return
    for axis, dim in enumerate(dims):
        scale = group.get(dim)
        if scale is None:
            labels = AXES.get(dim)
            if labels is None:  # the leading dimension: 0 … n-1
                scale = group.create_dataset(dim, data=np.arange(ds.shape[axis]))
                scale.attrs["long_name"] = _LEADING_DIM[kind][1]
            else:
                scale = group.create_dataset(dim, data=np.array(labels, dtype=object),
                                             dtype=_string_dtype())  # fmt: skip
                scale.attrs["long_name"] = dim.replace("_", " ")
            scale.attrs["units"] = "1"
            scale.make_scale(dim)
        if scale.shape[0] == ds.shape[axis]:
            ds.dims[axis].attach_scale(scale)


@dataclass
class Entry:
    """One finished task as journalled: its kind, id, record and metadata."""

    kind: str
    task_id: str
    record: dict[str, Any]
    meta: dict[str, Any]


class ResultWriter:
    """The master's handle on a results file (journal + atomic checkpoints)."""

    def __init__(self, path: str | Path, job, extra_meta: dict[str, Any] | None = None) -> None:
        self.path = Path(path)
        self.job = job
        self.journal = journal_dir(self.path)
        self._lock_fd: int | None = None
        self._root_updates: dict[str, Any] = {}
        self.previous_run_seconds = 0.0  # wall time of the earlier runs into this file
        self._acquire_lock()
        try:
            self._open_or_create(extra_meta or {})
        except BaseException:
            self._release_lock()
            raise

    # -- lifecycle
    def _acquire_lock(self) -> None:
        """An exclusive flock on ``<file>.lock`` for the life of this writer; the
        kernel drops it when the process dies, however it dies."""
        lock = lock_path(self.path)
        while True:
            fd = os.open(lock, os.O_CREAT | os.O_RDWR, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                owner = " on host ".join(os.read(fd, 200).decode().split()) or "?"
                os.close(fd)
                raise InputError(
                    f"{self.path} is being written by process {owner}; wait for it to finish"
                ) from None
            try:  # the file we locked may have been unlinked by a finishing writer
                same = os.fstat(fd).st_ino == os.stat(lock).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()} {socket.gethostname()}".encode())
        self._lock_fd = fd

    def _release_lock(self) -> None:
        if self._lock_fd is not None:
            lock_path(self.path).unlink(missing_ok=True)
            os.close(self._lock_fd)
            self._lock_fd = None

    def _open_or_create(self, extra_meta: dict[str, Any]) -> None:
        h5py = _h5()
        self.journal.mkdir(parents=True, exist_ok=True)
        for stale in self.path.parent.glob(f".{self.path.name}.*.tmp"):
            stale.unlink(missing_ok=True)  # a checkpoint interrupted before its rename
        for stale in self.journal.glob(".*.tmp"):
            stale.unlink(missing_ok=True)
        if self.path.exists():
            grown = check_compatible(self.path, self.job)
            with h5py.File(self.path, "r") as f:
                self.previous_run_seconds = float(f.attrs.get("run_seconds", 0.0))
            # the file describes the job now running; applied at the first checkpoint
            self._root_updates = {**extra_meta, "run_status": "running"}
            if grown is not None:
                self._root_updates |= {"job_json": self.job.model_dump_json(),
                                       "job_hash": self.job.job_hash, "job_name": self.job.name,
                                       "grown_from": grown}  # fmt: skip
            return
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        with h5py.File(tmp, "w") as f:
            f.attrs["schema_version"] = RESULTS_SCHEMA_VERSION
            f.attrs["job_json"] = self.job.model_dump_json()
            f.attrs["job_hash"] = self.job.job_hash
            f.attrs["job_name"] = self.job.name
            f.attrs["started_at"] = now()
            f.attrs["finished_at"] = ""
            f.attrs["run_status"] = "running"
            for k, v in {**environment_metadata(), **extra_meta}.items():
                f.attrs[k] = v
            for kind in KINDS:
                f.create_group(kind)
        os.replace(tmp, self.path)

    def add(self, kind: str, task_id: str, record: dict[str, Any], meta: dict[str, Any]) -> None:
        """Journal one finished task durably (atomic, fsynced)."""
        entry = Entry(kind, task_id, record, meta)
        atomic_write_bytes(self.journal / f"{kind}-{task_id}.pkl", pickle.dumps(entry, protocol=5))

    def checkpoint(self, attrs: dict[str, Any] | None = None) -> int:
        """Fold journalled results into the HDF5 file atomically; returns how many."""
        entries = list(_journal_entries(self.journal))
        attrs = {**self._root_updates, **(attrs or {})}
        self._root_updates = {}
        if not entries and not attrs:
            return 0
        h5py = _h5()
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")
        shutil.copyfile(self.path, tmp)
        merged = []
        with h5py.File(tmp, "a") as f:
            for e in entries:
                group_path = f"{e.kind}/{e.task_id}"
                if group_path in f:
                    del f[group_path]  # an earlier failure being replaced by a rerun
                _write_group(f.create_group(group_path), e.record, e.meta)
                merged.append(e)
            for k, v in (attrs or {}).items():
                f.attrs[k] = v
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, self.path)
        for e in merged:
            (self.journal / f"{e.kind}-{e.task_id}.pkl").unlink(missing_ok=True)
        return len(merged)

    def close(self, run_status: str, attrs: dict[str, Any] | None = None) -> None:
        try:
            self.checkpoint({**(attrs or {}), "run_status": run_status, "finished_at": now()})
            with contextlib.suppress(OSError):
                self.journal.rmdir()
        finally:
            self._release_lock()


def writer_alive(lock: Path) -> bool:
    """Whether a live process holds the results file's writer lock."""
    try:
        fd = os.open(lock, os.O_RDONLY)
    except FileNotFoundError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)  # closing also drops the probe's own shared lock
    return False


GROWABLE = ("grid", "directions")
"""What a job may change and still run into an existing results file: its tasks are
content-addressed, so a grown grid adds only the new tasks (a shrunk one keeps the
old results in the file)."""


def check_compatible(path: Path, job) -> str | None:
    """Refuse to write ``job`` into a file made by a job with other numerics,
    protocol, starts or stored observables. Returns None for the same job, or the
    job hashes the file grew from (comma-separated) when only ``GROWABLE`` differ."""
    h5py = _h5()
    try:
        with h5py.File(path, "r") as f:
            version = int(f.attrs.get("schema_version", -1))
            their_hash = str(f.attrs.get("job_hash", ""))
            their_json = str(f.attrs.get("job_json", "{}"))
            history = str(f.attrs.get("grown_from", ""))
    except OSError as e:
        raise InputError(
            f"{path} exists but is not a readable HDF5 file ({e}); move it away"
        ) from None
    if version != RESULTS_SCHEMA_VERSION:
        readable = " (it still reads: status, phase-diagram)" if version in READABLE_SCHEMAS else ""
        raise InputError(
            f"{path} has results schema_version {version}{readable}, this knitsweep writes "
            f"{RESULTS_SCHEMA_VERSION}: write to a new file (--out), or resume it with the "
            "knitsweep version that made it"
        )
    if their_hash == job.job_hash:
        return None
    from .jobs import JobSpec

    diff = _differences(JobSpec.model_validate_json(their_json).canonical(), job.canonical())
    fixed = [d for d in diff if d.split(".")[0] not in GROWABLE]
    if fixed or not diff:
        raise InputError(
            f"{path} holds results of a job with other settings (differs in "
            f"{', '.join(fixed) or 'settings'}); only the grid and directions may change "
            "between runs into one file: choose another --out file, or rerun that job"
        )
    return ", ".join(filter(None, [history, their_hash]))


def _differences(a: Any, b: Any, prefix: str = "") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            out += _differences(a.get(k), b.get(k), f"{prefix}{k}.")
        return out
    return [] if a == b else [prefix.rstrip(".")]


# ---- reading ---------------------------------------------------------------------


def _journal_entries(journal: Path) -> Iterator[Entry]:
    if not journal.is_dir():
        return
    for p in sorted(journal.glob("*.pkl")):
        try:
            yield pickle.loads(p.read_bytes())
        except (FileNotFoundError, EOFError, pickle.UnpicklingError):
            continue  # merged and deleted meanwhile, or never completed


def _read_group(group) -> tuple[dict[str, Any], dict[str, Any]]:
    attrs = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in group.attrs.items()}
    data = {}
    for k, ds in group.items():
        if ds.is_scale:  # a dimension's coordinates, not a field of the record
            continue
        v = ds[()]
        if ds.dtype.kind == "O":
            v = np.array([s.decode() if isinstance(s, bytes) else s for s in v], dtype=object)
        data[k] = v
    return attrs, data


def iter_entries(path: str | Path, with_data: bool = False) -> Iterator[Entry]:
    """Every finished task of a results file, deduplicated: the HDF5 file's
    groups first, then journal entries not yet merged into it."""
    path = Path(path)
    seen: set[tuple[str, str]] = set()
    if path.exists():
        with _h5().File(path, "r") as f:
            for kind in KINDS:
                for tid, group in f.get(kind, {}).items():
                    if with_data:
                        meta, record = _read_group(group)
                    else:
                        meta, record = dict(group.attrs), {}
                    seen.add((kind, tid))
                    yield Entry(kind, tid, record, meta)
    for e in _journal_entries(journal_dir(path)):
        if (e.kind, e.task_id) not in seen:
            seen.add((e.kind, e.task_id))
            yield e


def read_entry(path: str | Path, kind: str, task_id: str) -> Entry | None:
    """One finished task with its data, from the HDF5 file or the journal."""
    path = Path(path)
    if path.exists():
        with _h5().File(path, "r") as f:
            group = f.get(f"{kind}/{task_id}")
            if group is not None:
                meta, record = _read_group(group)
                return Entry(kind, task_id, record, meta)
    try:
        return pickle.loads((journal_dir(path) / f"{kind}-{task_id}.pkl").read_bytes())
    except (FileNotFoundError, EOFError, pickle.UnpicklingError):
        return None


def read_root(path: str | Path) -> dict[str, Any]:
    """Root attributes of a results file (schema checked)."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such results file")
    try:
        with _h5().File(path, "r") as f:
            attrs = {k: (v.item() if isinstance(v, np.generic) else v) for k, v in f.attrs.items()}
    except OSError as e:
        raise InputError(f"{path}: not a readable HDF5 file ({e})") from None
    if attrs.get("schema_version") not in READABLE_SCHEMAS:
        raise InputError(
            f"{path}: results schema_version {attrs.get('schema_version')!r}; this knitsweep "
            f"reads {' and '.join(map(str, READABLE_SCHEMAS))}: use the knitsweep version that "
            "wrote it"
        )
    return attrs


def read_progress(path: str | Path) -> dict[str, Any] | None:
    p = progress_path(Path(path))
    try:
        return json.loads(p.read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None
