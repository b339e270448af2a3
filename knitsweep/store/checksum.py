"""Checksums of a results file: the root attributes' digest, written with the data and
verified on every read (docs/results-file.md), and the verification of the task
groups of schema-2 files. (A schema-3 row's digest is ``store.table.row_digest``, which
shares this module's ``_update`` for arrays.)

A schema-2 task group's digest (attribute ``sha256`` of the group) covers, in name
order, every attribute of the group and every dataset in it (its name, dtype, shape and
bytes, and its attributes but the dimension-scale references, which hold file
addresses), as read back from the file. The root's digest (root attribute
``root_sha256``) covers the root attributes. A digest that does not match, or a group
HDF5 cannot read, makes the task *damaged*: readers skip it and say so by id, and a
resumed run recomputes it. Files written before checksums (no ``sha256`` attributes)
still read, as *unverified*.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np

GROUP_DIGEST = "sha256"
"""Attribute of a task group holding the SHA-256 digest of its contents (hex)."""
ROOT_DIGEST = "root_sha256"
"""Root attribute holding the SHA-256 digest of the other root attributes (hex)."""
DIGEST_ATTRS = (GROUP_DIGEST, ROOT_DIGEST)
_REFERENCES = ("DIMENSION_LIST", "REFERENCE_LIST")  # file addresses, rewritten per copy
_DOMAIN = b"knitsweep-digest-1\0"


class Damaged(Exception):
    """A task group or the root whose contents cannot be trusted (why: the message)."""


@dataclass
class FileCheck:
    """What reading a results file found: damaged tasks ``(kind, task id, why)``, how
    many tasks were verified and how many carry no checksum (older files), and damage
    to the file's structure that hides tasks whose ids cannot be read."""

    damaged: list[tuple[str, str, str]] = field(default_factory=list)
    verified: int = 0
    unverified: int = 0
    structure: list[str] = field(default_factory=list)

    def merge(self, other: FileCheck) -> None:
        """Add what ``other`` found (a share of the same file, read elsewhere)."""
        self.damaged += other.damaged
        self.verified += other.verified
        self.unverified += other.unverified
        self.structure += other.structure

    def structure_lines(self) -> list[str]:
        """One line per structure problem ("damaged /sweeps: column description
        unreadable" for one that names the table, "damaged: …" for the others)."""
        return [f"damaged {why}" if why.startswith("/") else f"damaged: {why}"
                for why in self.structure]  # fmt: skip

    def lines(self, path: Any) -> list[str]:
        """One line per damaged task or structure problem, and one for the unverified."""
        out = [f"damaged {kind[:-1]} {tid}: {why}: not used, recomputed on resume"
               for kind, tid, why in self.damaged]  # fmt: skip
        out += self.structure_lines()
        if self.damaged or self.structure:
            out.append(f"`knitsweep recover {path}` rebuilds the file from what is intact")
        if self.unverified:
            out.append(f"{self.unverified} task(s) written without checksums (a knitsweep "
                       "before checksums): read unverified")  # fmt: skip
        return out


def _update(h, value: Any) -> None:
    """Feed one attribute or dataset value, tagged with its type and shape."""
    import h5py

    if isinstance(value, str):
        data = value.encode("utf-8", "surrogatepass")
        h.update(b"s%d:" % len(data) + data)
    elif isinstance(value, bytes):
        h.update(b"b%d:" % len(value) + value)
    elif isinstance(value, h5py.Empty):
        h.update(b"e" + np.dtype(value.dtype).str.encode())
    else:
        a = np.asarray(value)
        h.update(b"n" + repr(a.shape).encode())
        if a.dtype.kind == "O":
            for item in a.reshape(-1):
                _update(h, item)
        else:
            a = np.ascontiguousarray(a)
            h.update(a.dtype.str.encode() + b":" + a.tobytes())


def group_digest(group) -> str:
    """The hex SHA-256 digest of a task group as stored (see the module docstring)."""
    return read_sealed(group)[0]


def read_sealed(group) -> tuple[str, dict[str, Any], dict[str, Any]]:
    """(digest, attributes, datasets) of a task group, each object read once: the
    digest as ``group_digest`` defines it, the group's attributes (the digest
    attributes left out) and the values of its datasets but the dimension scales
    (``is_scale``: coordinates, not data)."""
    import h5py

    h = hashlib.sha256(_DOMAIN)
    attrs = {
        name: group.attrs[name] for name in sorted(group.attrs.keys()) if name not in DIGEST_ATTRS
    }
    _feed(h, attrs)
    data = {}
    for name in sorted(group.keys()):
        obj = group[name]
        if not isinstance(obj, h5py.Dataset):
            h.update(b"G" + name.encode() + b"\0")  # no subgroups are written
            continue
        h.update(b"D" + name.encode() + b"\0")
        value = obj[()]
        _update(h, value)
        ds_attrs = {a: obj.attrs[a] for a in sorted(obj.attrs.keys()) if a not in _REFERENCES}
        _feed(h, ds_attrs)
        if _stored(ds_attrs, "CLASS") != "DIMENSION_SCALE":
            data[name] = value
    return h.hexdigest(), attrs, data


def _feed(h, attrs: dict[str, Any]) -> None:
    """Feed attributes already read and sorted by name."""
    for name, value in attrs.items():
        h.update(b"A" + name.encode() + b"\0")
        _update(h, value)


def root_digest(f) -> str:
    """The hex SHA-256 digest of a file's root attributes (the digest itself excluded)."""
    h = hashlib.sha256(_DOMAIN + b"root\0")
    _feed(h, {name: f.attrs[name] for name in sorted(f.attrs.keys()) if name not in DIGEST_ATTRS})
    return h.hexdigest()


def seal_root(f) -> None:
    """Write the digest of the root attributes just written."""
    f.attrs[ROOT_DIGEST] = root_digest(f)


def _stored(attrs, name: str) -> str | None:
    if name not in attrs:
        return None
    value = attrs[name]
    return value.decode(errors="replace") if isinstance(value, bytes) else str(value)


def read_verified(group) -> tuple[bool, dict[str, Any], dict[str, Any]]:
    """(verified, attributes, datasets) of a task group, read once (``read_sealed``):
    verified True if the group matches its digest, False if it has none (written before
    checksums); ``Damaged`` if it does not match or cannot be read."""
    try:
        stored = _stored(group.attrs, GROUP_DIGEST)
        actual, attrs, data = read_sealed(group)
    except Exception as e:  # HDF5 raises OSError, KeyError, RuntimeError … on damage
        raise Damaged(f"unreadable ({_why(e)})") from None
    if stored is not None and actual != stored:
        raise Damaged("checksum mismatch (the stored data changed after it was written)")
    return stored is not None, attrs, data


def verify_root(f) -> bool:
    """Like ``read_verified``'s verdict, for the root attributes."""
    try:
        stored = _stored(f.attrs, ROOT_DIGEST)
        if stored is None:
            return False
        actual = root_digest(f)
    except Exception as e:
        raise Damaged(f"root attributes unreadable ({_why(e)})") from None
    if actual != stored:
        raise Damaged("root attributes fail their checksum")
    return True


def _why(e: BaseException) -> str:
    text = str(e).split("(")[0].strip()
    return f"{type(e).__name__}: {text}" if text else type(e).__name__
