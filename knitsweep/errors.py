"""Bad input, told in one line: ``InputError`` and the messages made from pydantic's
validation errors (the field, the value, what is allowed, and a "did you mean" for
unknown keys). No numba, no scipy; ``config`` and everything above use it.
"""

from __future__ import annotations

import difflib
import errno
from typing import Any

from pydantic import BaseModel, ValidationError


# ---- errors -----------------------------------------------------------------------
class InputError(ValueError):
    """Bad user input, reported as one line naming the field and the allowed range."""


class DamagedResultsWarning(UserWarning):
    """A results file was read without some of its tasks: they are damaged (the
    message names how many, the first ids, and ``knitsweep recover``)."""


class StorageError(OSError):
    """A results file, journal entry or output could not be written (disk full,
    read-only or missing directory, permissions): one line for the user."""


HDF5_DAMAGE = ("B-tree", "signature", "object header", "heap", "checksum", "not aligned",
               "addr overflow")  # fmt: skip
"""Words of HDF5's reports of a write that met damaged metadata (not a disk's fault)."""


def storage_error(what: Any, e: BaseException) -> StorageError:
    """A one-line StorageError for a failed write of ``what``; a symbolic link found in
    place of another file than ``what`` (a shadow or journal swapped for one) is named
    itself, so that the message names the path that is the link."""
    code = getattr(e, "errno", None)
    if code == errno.ELOOP and getattr(e, "filename", None):
        what = e.filename
    text = str(e)
    if code == errno.ENOSPC or "No space left" in text:
        reason = "the disk is full"
    elif code == errno.EROFS or "Read-only file system" in text:
        reason = "the file system is read-only"
    elif code in (errno.EACCES, errno.EPERM) or "Permission denied" in text:
        reason = "permission denied"
    elif code == errno.ENOENT:
        reason = "its directory does not exist"
    elif code == errno.EDQUOT:
        reason = "the disk quota is exceeded"
    elif code == errno.ELOOP:
        reason = "it is a symbolic link (knitsweep never writes through one)"
    elif any(sign in text for sign in HDF5_DAMAGE):
        code, reason = errno.EBADMSG, f"the file is damaged ({text.splitlines()[0]})"
        return StorageError(code, f"cannot write {what}: {reason}", str(what))
    else:
        reason = getattr(e, "strerror", None) or (text.splitlines() or [type(e).__name__])[0]
    return StorageError(code or errno.EIO, f"cannot write {what}: {reason}")


def remedy(e: BaseException) -> str:
    """What to do about a failed write, by its cause (space, permission, or other)."""
    code = getattr(e, "errno", None)
    if code in (errno.ENOSPC, errno.EDQUOT):
        return "make room"
    if code in (errno.EACCES, errno.EPERM, errno.EROFS):
        return "make the directory writable (or move the files to one that is)"
    if code == errno.ELOOP:
        return "remove the symbolic link"
    if code == errno.EBADMSG and getattr(e, "filename", None):
        return f"run `knitsweep recover {e.filename}` (it rebuilds the file from its intact tasks)"
    return "fix the cause"


MAX_SEED = 2**63
"""Seeds are integers in [0, 2**63)."""


def check_seed(seed: Any) -> int:
    """``seed`` if it is an integer in [0, 2**63); InputError otherwise."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < MAX_SEED:
        raise InputError(f"seed = {seed!r}: must be an integer in [0, 2**63)")
    return seed


def did_you_mean(word: str, choices) -> str:
    """' (did you mean 'x'?)' for the closest of ``choices``, else the list of them."""
    choices = sorted(choices)
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    if close:
        return f" (did you mean {close[0]!r}?)"
    return f" (known: {', '.join(choices)})" if choices else ""


def _fields_at(model: type[BaseModel] | None, loc: tuple) -> list[str]:
    """The field names of the model that holds ``loc[-1]``, following ``loc`` down
    from ``model`` through nested models (empty if it cannot be followed)."""
    for part in loc[:-1]:
        field = model.model_fields.get(part) if model is not None else None
        annotation = field.annotation if field is not None else None
        model = (
            annotation
            if isinstance(annotation, type) and issubclass(annotation, BaseModel)
            else None
        )
    return list(model.model_fields) if model is not None else []


def _short(value: Any, limit: int = 60) -> str:
    """repr(value), cut to ``limit`` characters (a 10^5-value list is not a message)."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 4] + " ..."


def describe_validation_error(
    err: ValidationError | InputError, model: type[BaseModel] | None = None
) -> str:
    """One line per problem: ``field = value: what is allowed``; an unknown field gets
    the closest known name of ``model`` (the validated model) as a suggestion."""
    if isinstance(err, InputError):
        return str(err)
    parts = []
    for e in err.errors():
        loc = ".".join(str(x) for x in e["loc"])
        msg = e["msg"].removeprefix("Value error, ")
        if not loc:  # a model-level check: its message names the fields itself
            parts.append(msg)
        elif e["type"] == "extra_forbidden":
            known = _fields_at(model, e["loc"])
            hint = did_you_mean(str(e["loc"][-1]), known) if known else ""
            parts.append(f"{loc}: unknown field{hint}")
        elif "input" in e and e["type"] != "missing":
            parts.append(f"{loc} = {_short(e['input'])}: {msg}")
        else:
            parts.append(f"{loc}: {msg}")
    return "; ".join(parts)
