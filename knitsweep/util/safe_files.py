"""Safe file I/O for every command: bounded reads of input files and writes that never
go through a symbolic link and never leave a half-written file.

* ``read_text``: the UTF-8 text of an input file of at most a given size (InputError
  naming the file otherwise);
* ``replace_file``: write through a new temporary file and an atomic rename (the
  store's journal and every output file);
* ``refuse_link``, ``check_writable``, ``check_output_dir``, ``make_output_dir``: refuse,
  before any compute, an output that is a link or cannot be written.
"""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path

from ..errors import InputError, StorageError, storage_error


def read_text(path: str | Path, what: str, max_bytes: int, hint: str = "") -> str:
    """The UTF-8 text of an input file of at most ``max_bytes``; InputError naming the
    file for a missing, unreadable, binary, non-UTF-8 (e.g. UTF-16) or oversized one
    (``hint`` is added to the non-UTF-8 message)."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            raw = f.read(max_bytes + 1)
    except OSError as e:
        raise InputError(f"{what} {path}: {e.strerror or e}") from None
    if len(raw) > max_bytes:
        raise InputError(f"{what} {path}: larger than {max_bytes} bytes, not a {what}")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise InputError(f"{what} {path}: not UTF-8 text (byte {e.start}){hint}") from None
    if "\x00" in text:
        raise InputError(f"{what} {path}: a binary file, not a {what}")
    return text


def refuse_link(path: str | Path, what: str) -> None:
    """InputError if ``path`` is a symbolic link: knitsweep never writes, replaces or
    deletes a file through one (it could point anywhere)."""
    if os.path.islink(path):
        raise InputError(f"{what} {path}: is a symbolic link (to {os.readlink(path)}); "
                         "knitsweep does not write through links: remove it or give the "
                         "real path")  # fmt: skip


def replace_file(path: str | Path, data: bytes, fsync: bool = False) -> Path:
    """Write ``data`` to ``path`` through a new temporary file (created exclusively,
    never following a link) and an atomic rename: a reader sees the old file or the
    new one. A symbolic link at ``path`` is refused (StorageError, ELOOP); on failure
    no temporary file is left and StorageError names the cause."""
    path = Path(path)
    if os.path.islink(path):
        raise storage_error(path, OSError(errno.ELOOP, "symbolic link"))
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        if os.path.lexists(tmp):
            os.unlink(tmp)  # this process's own leftover (a name with our pid)
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o644)
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            if fsync:
                os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except StorageError:
        raise
    except OSError as e:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise storage_error(path, e) from None
    return path


def check_writable(path: str | Path, what: str) -> Path:
    """Refuse, before any compute, an output ``path`` that cannot be written: a missing
    or read-only directory, a directory or a symbolic link in its place (an existing
    file is replaced). Probes the directory by creating and removing a hidden file.
    Every command checks its outputs with this (``--out`` rules are the same in all)."""
    path = Path(path)
    parent = path.parent
    refuse_link(path, what)
    if not parent.is_dir():
        raise InputError(f"{what} {path}: directory {parent} does not exist")
    if path.is_dir():
        raise InputError(f"{what} {path}: is a directory")
    try:
        fd, probe = tempfile.mkstemp(prefix=".knitsweep-probe-", dir=parent)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise InputError(f"{what} {path}: directory {parent} is not writable "
                         f"({e.strerror or e})") from None  # fmt: skip
    return path


def check_output_dir(path: str | Path, what: str) -> Path:
    """Refuse an output directory that is a symbolic link, whose place holds a file,
    whose parent does not exist (as for every output file: no directories are made
    but this one), or that cannot be written (checked before any compute)."""
    path = Path(path)
    refuse_link(path, what)
    if path.exists() and not path.is_dir():
        raise InputError(f"{what} {path}: exists and is not a directory")
    if path.is_dir():
        check_writable(path / "probe", what)
        return path
    check_writable(path, what)
    return path


def make_output_dir(path: str | Path, what: str = "--out") -> Path:
    """The output directory ``path``, made if missing (its parent must exist), after
    ``check_output_dir``; never a symbolic link."""
    path = check_output_dir(path, what)
    try:
        path.mkdir(exist_ok=True)
    except OSError as e:
        raise storage_error(path, e) from None
    refuse_link(path, what)
    return path
