"""The one reader of knitsweep's environment variables: every setting is
``KNITSWEEP_<NAME>`` and read through ``setting`` (no other module reads
``os.environ`` for knitsweep's own settings)."""

from __future__ import annotations

import os

PREFIX = "KNITSWEEP_"


def setting(name: str, default: str | None = None) -> str | None:
    """The value of ``KNITSWEEP_<name>``, or ``default`` if unset or empty."""
    return os.environ.get(PREFIX + name) or default
