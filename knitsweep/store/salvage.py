"""Reading what is intact in a damaged results file, or in a copy of an earlier
version of it (the writer's spare and shadow), for ``knitsweep recover``
(docs/crash-safety.md).

Two readers, whose finds are pooled:

* the *sealed frames* (``store.sealed``): a scan of the raw bytes, trusting no HDF5
  metadata, takes every row (and the root attributes) whose frame is whole and
  passes its checksum: from a file cut at any length, every row whose frame lies
  before the cut;
* HDF5 itself, through the file's tables and their checksums (also for files
  written before the frames). A truncated file is shown to the library padded with
  zeros to the end-of-file address its superblock records, through a view of the
  file (nothing is copied, no temporary file exists at any instant); a global heap
  that the cut went through is closed in that view by a free-space record where
  its objects stop, since HDF5 loops for ever on a heap whose rest is zeros. The
  library runs in a forked child that dies with this process: it is abandoned if
  it makes no progress for ``stall_seconds`` (damage that makes HDF5 loop), and
  this process stays free to answer SIGTERM and SIGINT at once.
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import mmap
import os
import signal
import struct
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import sealed
from .checksum import DIGEST_ATTRS, Damaged, FileCheck, verify_root
from .format import _h5
from .journal import Entry
from .read import file_entries, stored_eof

STALL_S = 10.0
"""The HDF5 reader is abandoned after this long without a result, plus 1 s per
50 MB of file (``stall_seconds``)."""
_PR_SET_PDEATHSIG = 1


def stall_seconds(size: int) -> float:
    return STALL_S + size / 50e6


@dataclass
class Salvage:
    """What one source gave: its root attributes (None: unreadable or failing their
    checksum), its intact tasks and its ``FileCheck``; ``note`` says why it could not
    be read whole; ``sealed``: how many tasks came from its sealed frames alone."""

    path: Path
    root: dict[str, Any] | None = None
    root_verified: bool = False
    entries: list[Entry] = field(default_factory=list)
    check: FileCheck = field(default_factory=FileCheck)
    note: str = ""
    sealed: int = 0

    def add_note(self, text: str) -> None:
        self.note = "; ".join(filter(None, [self.note, text]))


# ---- the zero-padded view of a truncated file -------------------------------------


class _Padded(io.RawIOBase):
    """The bytes of a file as HDF5 expects them: the file up to its size, zeros up to
    ``eof``, with ``patches`` ((offset, bytes)) laid over (h5py's file-object driver)."""

    def __init__(self, path: Path, eof: int, patches: list[tuple[int, bytes]]) -> None:
        super().__init__()
        self._fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
        self._eof, self._pos, self._patches = eof, 0, patches

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = 0) -> int:
        self._pos = (0, self._pos, self._eof)[whence] + offset
        return self._pos

    def tell(self) -> int:
        return self._pos

    def readinto(self, b) -> int:
        start = self._pos
        n = max(0, min(len(b), self._eof - start))
        data = os.pread(self._fd, n, start)
        b[: len(data)] = data
        b[len(data) : n] = bytes(n - len(data))
        for at, patch in self._patches:
            lo, hi = max(at, start), min(at + len(patch), start + n)
            if lo < hi:
                b[lo - start : hi - start] = patch[lo - at : hi - at]
        self._pos += n
        return n

    def close(self) -> None:
        if not self.closed:
            os.close(self._fd)
        super().close()


_GCOL = b"GCOL"
_OBJECT = struct.Struct("<HH4xQ")  # a global heap object: index, references, size


def cut_heaps(path: Path, size: int) -> list[tuple[int, bytes]]:
    """Patches that close each global heap collection the cut at ``size`` went
    through: a free-space object where its objects stop being whole (HDF5 1.14
    parses a heap's objects until their sizes add up to the heap's: on zeros, an
    object of size 0, it never gets there)."""
    patches = []
    with open(path, "rb") as fh, mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) as data:
        at = data.find(_GCOL)
        while 0 <= at <= size - 16:
            (extent,) = struct.unpack_from("<Q", data, at + 8)
            end = at + extent
            if data[at + 4] == 1 and end > size and extent >= 32:
                p = at + 16
                while p + 16 <= end:
                    if p + 16 > size:
                        patches.append((p, _OBJECT.pack(0, 0, end - p)))
                        break
                    idx, _, n = _OBJECT.unpack_from(data, p)
                    step = n if idx == 0 else 16 + (n + 7) // 8 * 8
                    if step <= 0:
                        patches.append((p, _OBJECT.pack(0, 0, end - p)))
                        break
                    p += step
            at = data.find(_GCOL, at + 4)
    return patches


# ---- HDF5 in a child that dies with this process ----------------------------------


def _read_hdf5(source, send) -> None:
    """Read the root and every intact task of an open-able HDF5 source; ``send``
    each find as it comes (("root", …), ("entry", …), ("done", check))."""
    h5py = _h5()
    with h5py.File(source, "r") as f:
        try:
            verified = verify_root(f)
            root = {k: _plain(v) for k, v in f.attrs.items() if k not in DIGEST_ATTRS}
            send(("root", root, verified, ""))
        except Damaged as e:
            send(("root", None, False, str(e)))
        except Exception as e:
            send(("root", None, False, f"root unreadable ({type(e).__name__})"))
        check = FileCheck()
        try:
            for e in file_entries(f, True, check, salvage=True):
                send(("entry", e))
        except Exception as e:  # damage past what the readers guard
            check.structure.append(f"reading stopped ({type(e).__name__})")
        send(("done", check))


def _child(conn, path: Path, eof: int | None, patches) -> None:
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent's to handle (it kills us)
    with contextlib.suppress(Exception):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    _read_source(conn.send, path, eof, patches)


def _read_source(send, path: Path, eof: int | None, patches) -> None:
    """``_read_hdf5`` of ``path`` (through the padded view if ``eof``)."""
    source = _Padded(path, eof, patches) if eof else str(path)
    try:
        _read_hdf5(source, send)
    except Exception as e:
        send(("failed", f"{type(e).__name__}: {(str(e).splitlines() or [''])[0]}"))
    finally:
        if isinstance(source, _Padded):
            source.close()


def _hdf5(path: Path, out: Salvage, eof: int | None, patches) -> None:
    """Pool into ``out`` what HDF5 reads of ``path`` (in a forked child if forking is
    safe here, else in this process)."""
    from multiprocessing.connection import Connection

    from ..util.forking import fork_workers

    if fork_workers() <= 1:  # threads or no fork: read here, unguarded
        collect = _Collect(out)
        try:
            _read_source(collect, path, eof, patches)
        finally:
            collect.finish()
        return
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns into the caller's code
        code = 0
        try:
            os.close(r)
            _child(Connection(w, readable=False), path, eof, patches)
        except BaseException:
            code = 1
        finally:
            os._exit(code)
    os.close(w)
    conn, collect = Connection(r, writable=False), _Collect(out)
    limit, last = stall_seconds(path.stat().st_size), time.monotonic()
    try:
        while not collect.finished:
            if conn.poll(0.1):
                try:
                    collect(conn.recv())
                except EOFError:
                    out.check.structure.append("reading stopped (the HDF5 library crashed)")
                    break
                last = time.monotonic()
            elif time.monotonic() - last > limit:
                out.check.structure.append(
                    f"reading stopped: HDF5 made no progress for {limit:.0f} s (its metadata is "
                    "damaged); the sealed frames were read"
                )
                break
    finally:
        conn.close()
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        collect.finish()


class _Collect:
    """Takes the HDF5 reader's messages into a ``Salvage``."""

    def __init__(self, out: Salvage) -> None:
        self.out, self.finished, self.check = out, False, FileCheck()

    def __call__(self, message) -> None:
        kind, *rest = message
        if kind == "root":
            self.out.root, self.out.root_verified = rest[0], rest[1]
            self.out.add_note(rest[2])
        elif kind == "entry":
            self.out.entries.append(rest[0])
        elif kind == "done":
            self.check, self.finished = rest[0], True
        else:  # failed: the file does not open
            self.out.add_note(f"unreadable by HDF5 ({rest[0]})")
            self.finished = True

    def finish(self) -> None:
        self.out.check.merge(self.check)
        self.check = FileCheck()


# ---- one source -------------------------------------------------------------------


def salvage(path: Path) -> Salvage:
    """Every intact task of one (possibly damaged) results file, with its root."""
    out = Salvage(path)
    if not path.exists():
        out.note = "absent"
        return out
    if path.is_symlink() or not path.is_file():
        out.note = "not a regular file: not read"
        return out
    size = path.stat().st_size
    if size == 0:
        out.note = "empty (0 bytes)"
        return out
    eof = stored_eof(path)
    if eof is None:
        out.note = f"not an HDF5 file ({size} bytes, no HDF5 signature at its start)"
    elif eof > size:
        if eof > 64 * size + (1 << 30):
            out.note = f"unreadable (its superblock records an end of {eof} bytes)"
        else:
            out.note = f"truncated to {size} of {eof} bytes: read up to the cut"
            _hdf5(path, out, eof, cut_heaps(path, size))
    else:
        _hdf5(path, out, None, [])
    _pool_frames(path, out)
    return out


def _pool_frames(path: Path, out: Salvage) -> None:
    """Add the rows of the sealed frames that HDF5 did not give intact (and their
    root, if HDF5 gave none)."""
    try:
        rows, root = sealed.scan(path)
    except (OSError, ValueError) as e:
        out.check.structure.append(f"its sealed frames unreadable ({type(e).__name__})")
        return
    have = {(e.kind, e.task_id) for e in out.entries}
    for _, _, e in rows:
        if (e.kind, e.task_id) not in have:
            have.add((e.kind, e.task_id))
            out.entries.append(e)
            out.sealed += 1
    if out.root is None and root is not None:
        out.root, out.root_verified = root, True  # checksummed as a frame
        out.add_note("root attributes from its sealed frame")
    if out.sealed:
        out.add_note(f"{out.sealed} task(s) from its sealed frames")


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


def aside_name(path: Path) -> Path:
    """Where ``set_aside`` would keep ``path``: ``<file>.damaged`` (or ``.damaged.N``)."""
    return _unused_name(path, ".damaged")


def set_aside(path: Path, target: Path | None = None) -> Path | None:
    """Rename a damaged file to ``target`` (default ``aside_name``), never deleting
    it; returns the new name (None if there was no file)."""
    if not os.path.lexists(path):
        return None
    target = target or aside_name(path)
    os.rename(path, target)
    return target


__all__ = ["Salvage", "aside_name", "salvage", "set_aside", "stored_eof"]
