"""The master's side of an adaptive job: series bookkeeping around
``adaptive.series_state``.

A series is every parameter of a coarse grid point except L, plus a direction.
Each finished sweep's energy gap (stored with it) is fed in; ``states()`` then
says, per series, which L to evaluate next or how the series ended, and the
runner turns that into tasks and ``/series`` records.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from typing import Any

from ..config import StitchParams
from .adaptive import JAMMED_GAP, SeriesState, series_state
from .jobs import JobSpec, digest
from .worker import DONE


def _params_of(meta: dict[str, Any]) -> StitchParams:
    raw = meta["params"]
    return StitchParams(**(json.loads(raw) if isinstance(raw, str) else raw))


class Refiner:
    def __init__(self, job: JobSpec) -> None:
        self.job = job
        self.settings = job.adaptive
        self.coarse = sorted(job.grid.axes()["L_mm"])
        self.series: dict[str, dict[str, Any]] = {}
        for params in job.points():
            for d in job.directions:
                key = self.key(params, d)
                self.series.setdefault(key, {"base": params, "direction": d, "gaps": {}})

    def key(self, params: StitchParams, direction: str) -> str:
        base = params.model_dump(mode="json", exclude={"L_mm"})
        return digest({"series": base, "direction": direction,
                       "adaptive": self.settings.model_dump(mode="json"),
                       "protocol": self.job.protocol.model_dump(mode="json"),
                       "fidelity": self.job.fidelity.model_dump(mode="json")})  # fmt: skip

    def observe(self, sweep_meta: dict[str, Any]) -> None:
        """Take one finished sweep's gap (done: its gap; not knittable: jammed;
        failed: unknown)."""
        params = _params_of(sweep_meta)
        key = self.key(params, str(sweep_meta["direction"]))
        if key not in self.series:
            return
        status = str(sweep_meta.get("status"))
        if status == DONE:
            gap = float(sweep_meta["energy_gap"])
        elif status == "not_knittable":
            gap = JAMMED_GAP
        else:
            gap = None
        self.series[key]["gaps"][params.L_mm] = gap

    def states(self) -> Iterator[tuple[str, SeriesState]]:
        s = self.settings
        for key, series in self.series.items():
            yield key, series_state(self.coarse, series["gaps"], s.threshold_mJ, s.tolerance_mm,
                                    s.secant_span_mm, s.max_refinements)  # fmt: skip

    def point_params(self, key: str, L: float) -> tuple[StitchParams, str]:
        series = self.series[key]
        return series["base"].model_copy(update={"L_mm": L}), series["direction"]

    def series_meta(self, key: str, state: SeriesState) -> dict[str, Any]:
        """The ``/series/<key>`` record: the final bracket (mm and L/r)."""
        series = self.series[key]
        base: StitchParams = series["base"]
        r = base.r_mm
        flat = base.model_dump(mode="json", exclude={"L_mm"})
        return {
            "status": state.status,
            "message": state.message,
            "direction": series["direction"],
            "params": flat,
            **flat,
            "lo_mm": state.lo,
            "hi_mm": state.hi,
            "L_over_r_trans": None if state.hi is None or state.status != "done" else state.hi / r,
            "bracket_lower": None if state.lo is None else state.lo / r,
            "bracket_upper": None if state.hi is None else state.hi / r,
            "evaluations": state.evaluations,
            "tolerance_mm": self.settings.tolerance_mm,
            "threshold_mJ": self.settings.threshold_mJ,
        }
