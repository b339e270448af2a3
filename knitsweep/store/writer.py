"""The results file: one HDF5 file per job, written only by the master.

Crash safety without parallel HDF5 or SWMR, with checkpoints whose cost grows with
the new results, not with the file:

1. every result that arrives is first written to the journal (write-ahead log) in
   batches (group commit): ``add`` queues it, ``commit`` writes the queued results
   as one checksummed file ``<file>.journal/batch-<n>.entry`` that cannot run code
   when read (``journal``), through a temporary file, one fsync and an atomic
   rename, so after a kill -9 a batch is whole or absent. A result is durable (and
   the master reports it finished) only once its batch is committed; the master
   commits whenever it would otherwise wait, and at least every ``COMMIT_ENTRIES``
   results;
2. every ``checkpoint_s`` seconds (and at the end) the master appends the new
   results *in place* to a private shadow copy of the file
   (``.<file>.shadow``), fsyncs it and publishes it by an atomic rename over
   the file; the file it replaced, kept under a second name, becomes the next
   shadow and gets the same results (and their ``sealed`` frames) at the next one. Each
   checkpoint writes the new results twice and copies nothing; the shadow is made
   by one copy per launch of the run. Then the merged journal entries are deleted.

So at any instant the HDF5 file on disk is a complete, readable version, never
written in place (the shadow is), and no result that arrived is lost; readers
(``knitsweep status``, the post-processor) see the file plus the journal,
deduplicated by task id, the journal winning (it is never older than the file).
A malformed journal entry is skipped, reported by ``journal_problems`` and its
task recomputed. Disk use during a run: twice the file, plus the journal.

Schema (``schema_version`` 3, :data:`RESULTS_SCHEMA_VERSION`; documented in
docs/results-file.md). Files of schema 1 and 2 (one HDF5 group per task) still read; ``merge`` and
``recover`` rewrite schema 2 into 3; a schema-2 file is not resumed.

* root attributes: ``schema_version``, ``knitsweep_version``, ``git_commit``,
  ``job_json`` (effective job spec), ``job_hash``, ``job_name``, library versions
  (``numpy_version`` … ``mpi_library_version``), ``host``, ``slurm_job_id``,
  ``started_at``, ``finished_at``, ``run_status``, ``n_points``, ``n_sweeps``;
* ``/points``, ``/sweeps`` and ``/series`` (adaptive jobs): one table each
  (``store.table``), one row per task: its ``task`` id, its ``entry`` (the task's
  scalars, exactly, as JSON), a SHA-256 ``sha256`` of the row, a column per scalar and
  a padded column per array (``ZeroForce.to_record`` over the starts, ``SweepResult
  .to_record`` over steps, step 0 = zero force; a series' final transition bracket).
  A row's scalars include ``status`` (done | failed | not_knittable), ``message``,
  the stitch parameters (``L_mm`` … ``twist_bound``, and ``L_over_r``), ``rank``,
  ``host``, ``seconds``, a sweep's energy gaps ``delta_E_b``, ``delta_E_c`` and
  ``jamming_gap`` and, on failure, ``error_kind``, ``error_message``, ``traceback``.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import shutil
import socket
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..util.safe_files import refuse_link
from .checksum import FileCheck, seal_root
from .compatible import check_compatible
from .failed_writes import hdf5_writes
from .format import (
    KINDS,
    RESULTS_SCHEMA_VERSION,
    _h5,
    journal_dir,
    lock_path,
    now,
    progress_path,
)
from .journal import (
    Entry,
    StorageError,
    atomic_write_bytes,
    fsync_dir,
    journal_files,
    next_batch_number,
    scan,
    storage_error,
    write_batch,
)
from .provenance import environment_metadata
from .read import _open, file_entries, read_root
from .sealed import append_root, append_rows
from .table import create_table, put_rows

__all__ = ["ResultWriter", "StorageError", "atomic_write_bytes", "check_compatible",
           "writer_alive"]  # fmt: skip

COMMIT_ENTRIES = 512
"""A batch is committed at the latest when it holds this many results."""
COMMIT_BYTES = 8 * 1024 * 1024
"""… or this many bytes of arrays."""
SPACE_MARGIN_BYTES = 256 * 1024
"""Free space a checkpoint leaves at least, for HDF5's own metadata."""


def _hidden(path: Path, what: str) -> Path:
    return path.with_name(f".{path.name}.{what}")


# ---- writing ---------------------------------------------------------------------


def _put(f, entries: list[Entry], prepared: dict | None = None,
         framed: dict | None = None) -> None:  # fmt: skip
    """Write entries into their kinds' tables of an open file, each replacing an
    earlier version of its task (a failure being replaced by a rerun, or a duplicate
    after a crash), and their sealed frames (``store.sealed``); ``prepared``:
    ``table.put_rows``'s, ``framed``: ``sealed.append_rows``'s."""
    for kind in KINDS:
        put_rows(f[kind], kind, [e for e in entries if e.kind == kind], prepared)
    append_rows(f, entries, framed)


def check_no_links(path: Path) -> None:
    """InputError if the results file or any file the writer makes beside it (lock,
    journal directory, shadow, spare, progress file) is a symbolic link: the writer
    never writes, replaces or deletes through one."""
    for p, what in ((path, "results file"), (lock_path(path), "lock file"),
                    (journal_dir(path), "journal directory"),
                    (_hidden(path, "shadow"), "shadow copy"), (_hidden(path, "spare"), "spare copy"),
                    (progress_path(path), "progress file")):  # fmt: skip
        refuse_link(p, what)


def hold_lock(path: Path) -> int:
    """An exclusive flock on ``<file>.lock`` (its descriptor), held by a writer or a
    ``recover`` for as long as it works on ``path``; the kernel drops it when the
    process dies, however it dies. InputError if another process holds it."""
    lock = lock_path(path)
    if not path.parent.is_dir():
        raise StorageError(2, f"cannot write {path}: directory {path.parent} does not exist")
    check_no_links(path)
    while True:
        try:
            fd = os.open(lock, os.O_CREAT | os.O_RDWR | os.O_NOFOLLOW, 0o644)
        except OSError as e:
            if e.errno == errno.ELOOP:  # made a link since check_no_links looked
                check_no_links(path)
            raise storage_error(lock, e) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            owner = " on host ".join(os.read(fd, 200).decode(errors="replace").split())
            os.close(fd)
            raise InputError(
                f"{path} is being written by process {owner or '?'}; wait for it to finish"
            ) from None
        try:  # the file we locked may have been unlinked by a finishing writer
            same = os.fstat(fd).st_ino == os.stat(lock).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()} {socket.gethostname()}".encode())
    except OSError as e:
        os.close(fd)
        raise storage_error(path, e) from None
    return fd


def release_lock(path: Path, fd: int) -> None:
    with contextlib.suppress(OSError):  # e.g. the directory became read-only:
        lock_path(path).unlink(missing_ok=True)  # a stale lock is harmless
    os.close(fd)


def remove_stale(path: Path) -> None:
    """Delete what an interrupted checkpoint or ``recover`` left beside ``path``: the
    shadow and spare, temporary files of this writer's name, and a killed
    ``recover``'s rebuild (``.<file>.<pid>.recover.tmp`` with its journal, lock and
    copies). Only under ``path``'s lock: no process that made them is alive."""
    name = path.name
    for stale in (_hidden(path, "shadow"), _hidden(path, "spare"),
                  *path.parent.glob(f".{name}.*.tmp"), *path.parent.glob(f".{name}.*.recover.tmp*"),
                  *path.parent.glob(f"..{name}.*.recover.tmp.*")):  # fmt: skip
        with contextlib.suppress(OSError):
            if stale.is_dir() and not stale.is_symlink():
                shutil.rmtree(stale)
            else:
                stale.unlink(missing_ok=True)


def _lockable(path: Path, mode: int) -> bool | None:
    """Whether ``path`` could be flocked with ``mode`` right now (the probe's own lock
    is dropped at once): False if another holder blocks it, None if the file cannot be
    opened or locked at all."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    except OSError:
        return None
    try:
        fcntl.flock(fd, mode | fcntl.LOCK_NB)
        return True
    except BlockingIOError:
        return False
    except OSError:
        return None
    finally:
        os.close(fd)  # closing also drops the probe's lock


def _unused(path: Path) -> bool:
    """Whether no HDF5 reader holds ``path`` open (HDF5 readers hold a shared
    flock for as long as the file is open)."""
    return bool(_lockable(path, fcntl.LOCK_EX))


class ResultWriter:
    """The master's handle on a results file (journal + in-place shadow checkpoints).

    ``malformed`` lists the journal files found damaged when the writer opened
    (removed: their tasks count as unfinished and are recomputed)."""

    def __init__(self, path: str | Path, job, extra_meta: dict[str, Any] | None = None) -> None:
        self.path = Path(path)
        self.job = job
        self.journal = journal_dir(self.path)
        self._shadow, self._spare = _hidden(self.path, "shadow"), _hidden(self.path, "spare")
        self._pending: dict[tuple[str, str], Entry] = {}  # journalled, not yet in the file
        self._batch: list[Entry] = []  # added, not yet journalled (the next group commit)
        self._batch_bytes = 0
        self._batch_no = 1
        self._files: list[Path] = []  # the journal files holding the pending entries
        self._lag: list[Entry] = []  # in the file, not yet in the shadow
        self._lag_attrs: dict[str, Any] = {}
        self._prepared: dict[int, tuple] = {}  # the lag's rows, made when first written
        self._framed: dict[int, tuple] = {}  # … and their sealed frames
        self._shadow_ready = False
        self.malformed: list[tuple[Path, str]] = []
        self.check = FileCheck()  # damaged and unverified tasks found in the file
        self.stored: list[Entry] = []
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
        self._lock_fd = hold_lock(self.path)

    def _release_lock(self) -> None:
        if self._lock_fd is not None:
            release_lock(self.path, self._lock_fd)
            self._lock_fd = None

    @property
    def journalled(self) -> list[Entry]:
        """The journal's entries not yet merged into the HDF5 file."""
        return list(self._pending.values())

    def _open_or_create(self, extra_meta: dict[str, Any]) -> None:
        h5py = _h5()
        if self.path.exists():
            root = read_root(self.path)
            grown = check_compatible(self.path, self.job, root)
            self._read_stored()
            self.previous_run_seconds = float(root.get("run_seconds", 0.0))
            # the file describes the job now running; applied at the first checkpoint
            self._root_updates = {**extra_meta, "run_status": "running"}
            if grown is not None:
                self._root_updates |= {"job_json": self.job.model_dump_json(),
                                       "job_hash": self.job.job_hash, "job_name": self.job.name,
                                       "grown_from": grown}  # fmt: skip
            elif str(root.get("job_json", "")) != self.job.model_dump_json():
                # same results, new label or run settings (the caller allowed a relabel)
                self._root_updates |= {"job_json": self.job.model_dump_json(),
                                       "job_name": self.job.name}  # fmt: skip
        remove_stale(self.path)  # only now: a damaged file was refused with its spare kept
        try:
            self.journal.mkdir(exist_ok=True)
            for stale in self.journal.glob(".*.tmp"):
                stale.unlink(missing_ok=True)
        except OSError as e:
            raise storage_error(self.journal, e) from None
        entries, self.malformed = scan(self.journal, with_data=True)
        for path, _ in self.malformed:
            if path.is_symlink():
                continue  # reported; not ours to remove
            with contextlib.suppress(OSError):
                path.unlink(missing_ok=True)  # reported by the caller; the task is redone
        self._pending = {(e.kind, e.task_id): e for e in entries}
        self._files = journal_files(self.journal)
        self._batch_no = next_batch_number(self.journal)
        if self.path.exists():
            return
        tmp = _hidden(self.path, f"{os.getpid()}.tmp")
        try:
            with hdf5_writes(self.path), h5py.File(tmp, "w") as f:
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
                    create_table(f, kind)
                seal_root(f)
                append_root(f)
            _fsync_file(tmp)
            os.replace(tmp, self.path)
        except StorageError:
            tmp.unlink(missing_ok=True)
            raise
        except OSError as e:
            tmp.unlink(missing_ok=True)
            raise storage_error(self.path, e) from None
        fsync_dir(self.path.parent)

    def _read_stored(self) -> None:
        """The file's intact tasks (metadata) and its ``FileCheck``; InputError, with
        the way to recover, if damage hides tasks whose ids cannot be read."""
        with _open(self.path) as f:
            self.stored = list(file_entries(f, False, self.check))
        if self.check.structure:
            raise InputError(f"{self.path}: {'; '.join(self.check.structure_lines())}: "
                             f"`knitsweep recover {self.path}` rebuilds it from its intact "
                             "tasks, the spare copy and the journal")  # fmt: skip

    def entries(self) -> list[Entry]:
        """Every finished, intact task: the file's (but those the journal has a newer
        version of) and the journal's (metadata only for the file's)."""
        newer = set(self._pending)
        return [e for e in self.stored if (e.kind, e.task_id) not in newer] + self.journalled

    def add(self, kind: str, task_id: str, record: dict[str, Any], meta: dict[str, Any]) -> int:
        """Queue one finished task for the journal's next batch, committing the batch
        when it is full; returns how many results that commit made durable (0: none
        yet). StorageError if the disk refuses it (its tasks then count as
        unfinished)."""
        self._batch.append(Entry(kind, task_id, record, meta))
        self._batch_bytes += sum(getattr(v, "nbytes", 0) for v in record.values())
        if len(self._batch) >= COMMIT_ENTRIES or self._batch_bytes >= COMMIT_BYTES:
            return self.commit()
        return 0

    @property
    def uncommitted(self) -> int:
        """Results added but not yet durable."""
        return len(self._batch)

    def commit(self) -> int:
        """Journal the queued results durably in one batch file (one write, one
        fsync of it and of the directory); returns how many."""
        if not self._batch:
            return 0
        entries, self._batch, self._batch_bytes = self._batch, [], 0
        try:
            path = write_batch(self.journal, self._batch_no, entries)
        except StorageError:
            self._batch = entries + self._batch  # still not durable: kept for a retry
            raise
        self._batch_no += 1
        self._files.append(path)
        for e in entries:
            self._pending[(e.kind, e.task_id)] = e
        return len(entries)

    def entry(self, kind: str, task_id: str) -> Entry | None:
        """One finished task with its data: queued, journalled or in the file."""
        for e in reversed(self._batch):
            if (e.kind, e.task_id) == (kind, task_id):
                return e
        found = self._pending.get((kind, task_id))
        if found is not None:
            return found
        from .read import read_entry

        return read_entry(self.path, kind, task_id)

    def checkpoint(self, attrs: dict[str, Any] | None = None) -> int:
        """Fold the journalled results into the HDF5 file atomically, appending in
        place to the shadow copy and renaming it over the file; returns how many.
        On a write error the file is unchanged, the journal kept, no temporary file
        is left and StorageError names the cause."""
        self.commit()  # the journal first: a checkpoint that fails must lose nothing
        entries = list(self._pending.values())
        attrs = {**self._root_updates, **(attrs or {})}
        if not entries and not attrs:
            return 0
        self._check_space(entries)
        try:
            with hdf5_writes(self.path):
                spare = self._fold(entries, attrs)
        except StorageError:
            for p in (self._shadow, self._spare):
                with contextlib.suppress(OSError):  # (a read-only directory keeps them)
                    p.unlink(missing_ok=True)
            raise
        fsync_dir(self.path.parent)
        for path in self._files:  # every pending entry is in the file now
            with contextlib.suppress(OSError):
                path.unlink(missing_ok=True)
        self._files = []
        self._pending = {}
        self._root_updates = {}
        if spare is not None:
            with contextlib.suppress(OSError):
                os.replace(spare, self._shadow)
                self._shadow_ready = True
                self._lag = entries
                self._lag_attrs = dict(attrs or {})
        self._prepared = {id(e): self._prepared[id(e)] for e in self._lag
                          if id(e) in self._prepared}  # fmt: skip
        self._framed = {id(e): self._framed[id(e)] for e in self._lag if id(e) in self._framed}
        return len(entries)

    def _check_space(self, entries: list[Entry]) -> None:
        """StorageError before HDF5 writes a byte if the disk cannot hold this
        checkpoint (HDF5 copes badly with a disk that fills under it)."""
        new = sum(v.nbytes for e in entries for v in e.record.values() if hasattr(v, "nbytes"))
        need = 2 * new + SPACE_MARGIN_BYTES  # written twice (this and the next shadow)
        if not (self._shadow_ready and self._shadow.exists()):
            need += self.path.stat().st_size  # the shadow is made first
        try:
            st = os.statvfs(self.path.parent)
        except OSError:
            return
        if st.f_bavail * st.f_frsize < need:
            raise StorageError(28, f"cannot write {self.path}: the disk is full (a checkpoint "
                               f"needs ~{need // 1024} KiB, {st.f_bavail * st.f_frsize // 1024} "
                               "KiB are free)")  # fmt: skip

    def _fold(self, entries: list[Entry], attrs: dict[str, Any] | None) -> Path | None:
        """Append to the shadow, fsync it and rename it over the file; returns the
        spare name of the version replaced (None: no hard links here)."""
        if not (self._shadow_ready and _unused(self._shadow)):
            # once per launch (or after a reader held the retired file open: unlink
            # that name first, copying onto it would rewrite the reader's file)
            self._shadow.unlink(missing_ok=True)
            _copy_new(self.path, self._shadow)
            self._lag, self._lag_attrs = [], {}
        self._shadow_ready = False  # until it is published whole
        with _h5().File(self._shadow, "a") as f:
            # last checkpoint's results, written again: a group copied from the other
            # file (H5Ocopy) would keep references into that file, and its dimension
            # scales would point at nothing
            _put(f, self._lag + entries, self._prepared, self._framed)
            for k, v in {**self._lag_attrs, **(attrs or {})}.items():
                f.attrs[k] = v
            seal_root(f)
            append_root(f)
        _fsync_file(self._shadow)
        if os.path.islink(self._shadow):  # swapped for a link since: never renamed into place
            raise OSError(errno.ELOOP, "symbolic link", str(self._shadow))
        try:  # keep the version being replaced: it becomes the next shadow
            os.link(self.path, self._spare)
            spare = self._spare
        except OSError:
            spare = None  # no hard links here: the next checkpoint copies
        os.replace(self._shadow, self.path)
        return spare

    def close(self, run_status: str, attrs: dict[str, Any] | None = None) -> None:
        """The last checkpoint with the run's status; the shadow and lock are removed
        even when it fails (the journal then keeps what arrived)."""
        try:
            self.checkpoint({**(attrs or {}), "run_status": run_status, "finished_at": now()})
            with contextlib.suppress(OSError):
                self.journal.rmdir()
        finally:
            for p in (self._shadow, self._spare):
                with contextlib.suppress(OSError):
                    p.unlink(missing_ok=True)
            self._release_lock()


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _copy_new(src: Path, dst: Path) -> None:
    """Copy ``src`` to a new file ``dst``, created exclusively (never through a link)."""
    fd = os.open(dst, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
    with open(src, "rb") as fin, os.fdopen(fd, "wb") as fout:
        shutil.copyfileobj(fin, fout, 1 << 20)


def writer_alive(lock: Path) -> bool:
    """Whether a live process holds the results file's writer lock."""
    return _lockable(lock, fcntl.LOCK_SH) is False
