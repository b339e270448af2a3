"""Progress of a run as text: the line the master prints and ``knitsweep status``
shows (from the master's progress counts)."""

from __future__ import annotations

import math
from typing import Any


def duration(s: float) -> str:
    """'4m05s', '1h02m', or '--' for an unknown (infinite) duration."""
    if not math.isfinite(s):
        return "--"
    s = int(s)
    return f"{s // 3600}h{s % 3600 // 60:02d}m" if s >= 3600 else f"{s // 60}m{s % 60:02d}s"


def progress_line(c: dict[str, Any]) -> str:
    """One status line from progress counts (shared by the bar and ``status``)."""
    finished = c["done"] + c["failed"] + c["not_knittable"]
    width = 24
    filled = int(width * finished / max(c["total"], 1))
    rate = c.get("rate_per_s") or 0.0
    eta = (c["running"] + c["pending"]) / rate if rate > 0 else math.inf
    return (f"[{'#' * filled}{'.' * (width - filled)}] {finished}/{c['total']}  "
            f"done {c['done']}  failed {c['failed']}  not_knittable {c['not_knittable']}  "
            f"running {c['running']}  pending {c['pending']}  {rate * 60:.1f}/min  "
            f"ETA {duration(eta)}")  # fmt: skip
