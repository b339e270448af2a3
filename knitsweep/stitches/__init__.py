"""Stitch geometries behind one interface (``base.Stitch``), chosen by name.

``get_stitch("stockinette")`` returns the bundle of layout, geometry kernel, bending
weights, images, contact classes, starting states and drawing order that the kernels
and every layer above consume; nothing above this package knows which stitch it
computes. docs/adding-a-stitch.md says what a new stitch writes.
"""

from __future__ import annotations

import importlib

from ..errors import InputError
from .base import TRANSLATION_CLASSES, Stitch

STITCH_NAMES = ("stockinette", "stockinette_free", "garter", "rib", "seed")
"""Every stitch knitsweep knows, by name (each a subpackage with a ``STITCH``)."""
DEFAULT_STITCH = "stockinette"

__all__ = ["DEFAULT_STITCH", "STITCH_NAMES", "TRANSLATION_CLASSES", "Stitch",
           "check_stitch_name", "get_stitch"]  # fmt: skip


def check_stitch_name(name: object) -> str:
    """``name`` if it names a stitch; InputError listing the known ones otherwise."""
    if not isinstance(name, str) or name not in STITCH_NAMES:
        raise InputError(f"stitch = {name!r}: must be one of {', '.join(STITCH_NAMES)}")
    return name


def get_stitch(name: str = DEFAULT_STITCH) -> Stitch:
    """The stitch called ``name`` (its layout only: the geometry kernel loads on first
    use)."""
    return importlib.import_module(f"{__name__}.{check_stitch_name(name)}").STITCH
