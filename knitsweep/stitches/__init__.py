"""Stitch geometries behind one interface (``base.Stitch``), chosen by name.

``get_stitch("stockinette")`` returns the bundle of layout, geometry kernel, bending
weights, images, contact classes, starting states and drawing order that the kernels
and every layer above consume; nothing above this package knows which stitch it
computes. docs/adding-a-stitch.md says what a new stitch writes.
"""

from __future__ import annotations

import importlib

from ..errors import InputError
from . import chart
from .base import TRANSLATION_CLASSES, Stitch

STITCH_NAMES = ("stockinette", "stockinette_free", "garter", "rib", "seed")
"""The stitch registry: every stitch knitsweep knows, by name (each a subpackage with a
``STITCH``). Registering a stitch is adding its name here: the settings' validation,
the CLI's help, the error messages and the contract test (tests/test_stitch_contract.py)
are built from this tuple."""
DEFAULT_STITCH = "stockinette"
STITCH_CHOICES = ", ".join(STITCH_NAMES)
"""The registered names as the help texts and error messages list them."""

__all__ = ["DEFAULT_STITCH", "STITCH_CHOICES", "STITCH_NAMES", "TRANSLATION_CLASSES", "Stitch",
           "check_stitch_name", "get_stitch", "unknown_stitch"]  # fmt: skip


def unknown_stitch(name: object) -> str | None:
    """None if ``name`` is a registered stitch or a chart (``chart:KKPP``,
    ``stitches.chart``), else why not (the text every check of a stitch name gives: the
    settings', the grid's, the CLI's)."""
    if isinstance(name, str) and name in STITCH_NAMES:
        return None
    if chart.is_chart_name(name):
        try:
            chart.check_chart_name(name, "chart")  # type: ignore[arg-type]
        except InputError as e:
            return str(e)
        return None
    return f"must be one of {STITCH_CHOICES}, or a knit/purl chart as chart:KKPP"


def check_stitch_name(name: object, field: str = "stitch") -> str:
    """``name`` if it names a stitch (a chart's in its canonical spelling,
    ``chart.chart_name``); InputError naming ``field`` and listing the registered ones
    otherwise."""
    if chart.is_chart_name(name):  # parsed once: its refusal is ``unknown_stitch``'s
        try:
            return chart.check_chart_name(name, "chart")  # type: ignore[arg-type]
        except InputError as e:
            raise InputError(f"{field} = {name!r}: {e}") from None
    why = unknown_stitch(name)
    if why is not None:
        raise InputError(f"{field} = {name!r}: {why}")
    return name  # type: ignore[return-value]


def get_stitch(name: str = DEFAULT_STITCH) -> Stitch:
    """The stitch called ``name`` (its layout only: the geometry kernel loads on first
    use); a chart's (``chart:`` and its rows) built once."""
    name = check_stitch_name(name)
    if chart.is_chart_name(name):
        return chart.chart_stitch(name)
    return importlib.import_module(f"{__name__}.{name}").STITCH
