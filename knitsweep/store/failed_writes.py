"""Failed HDF5 writes: one StorageError, and no echoes of it.

HDF5 reports a write that fails (a full disk, a vanished directory) as RuntimeError
from h5py, and the h5py objects freed afterwards report the failed flush again from
their ``__dealloc__``: Cython prints it through ``sys.excepthook`` and
``sys.unraisablehook``, now or whenever the objects are collected, and the library may
fail again when it closes its files at exit. ``hdf5_writes`` turns the failure into one
StorageError naming the cause and silences its echoes; ``hdf5_write_failed`` tells the
CLI to leave without HDF5's exit clean-up.
"""

from __future__ import annotations

import contextlib
import gc
import sys
import traceback
from pathlib import Path

from ..errors import storage_error

_HDF5_WRITE_FAILED = False


def hdf5_write_failed() -> bool:
    """Whether an HDF5 write failed in this process: the library may then fail again
    when it closes its files at exit, so the CLI leaves without that clean-up."""
    return _HDF5_WRITE_FAILED


@contextlib.contextmanager
def hdf5_writes(path: Path):
    """While HDF5 writes ``path`` (or its shadow): a failed write (h5py reports a
    failed flush as RuntimeError) leaves as one StorageError naming the cause. The
    h5py objects freed after a failed flush report it again from ``__dealloc__``,
    through both ``sys.excepthook`` and ``sys.unraisablehook``, now or whenever they
    are collected; those reports are silenced here and, once a write has failed, for
    the rest of the process (the failure itself was raised once)."""
    global _HDF5_WRITE_FAILED
    hooks = _silence_h5py_dealloc()
    failure = None
    try:
        yield
    except (OSError, RuntimeError) as e:
        _HDF5_WRITE_FAILED = True
        failure = storage_error(path, e)
        traceback.clear_frames(e.__traceback__)  # free the h5py objects now, quietly
    finally:
        gc.collect()
        if not _HDF5_WRITE_FAILED:
            sys.excepthook, sys.unraisablehook = hooks
    if failure is not None:
        raise failure


def _silence_h5py_dealloc() -> tuple:
    """Install filters on ``sys.excepthook`` and ``sys.unraisablehook`` that drop an
    h5py object's report of a failed flush; returns the hooks they replaced."""
    excepthook, unraisablehook = sys.excepthook, sys.unraisablehook

    def on_exception(kind, value, tb) -> None:
        if not _from_h5py(value, tb):
            excepthook(kind, value, tb)

    def on_unraisable(unraisable) -> None:
        exc = unraisable.exc_value
        if not (_from_h5py(exc, unraisable.exc_traceback) or (
                isinstance(exc, RuntimeError) and "h5py" in repr(unraisable.object))):  # fmt: skip
            unraisablehook(unraisable)

    sys.excepthook, sys.unraisablehook = on_exception, on_unraisable
    return excepthook, unraisablehook


def _from_h5py(exc: BaseException | None, tb) -> bool:
    """A RuntimeError raised in h5py's own code (its innermost frame is h5py's)."""
    if not isinstance(exc, RuntimeError) or tb is None:
        return False
    while tb.tb_next is not None:
        tb = tb.tb_next
    name = tb.tb_frame.f_code.co_filename.replace("\\", "/")
    return name.startswith("h5py/") or "/h5py/" in name
