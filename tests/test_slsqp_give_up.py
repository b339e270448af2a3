"""A long SLSQP descent (the rough stitches' second opinion) gives up where its hard
cores still overlap after ``OVERLAP_CHECK`` iterations, and only there."""

import numpy as np

from knitsweep.config import NOT_KNITTABLE, SolverSettings, StitchParams
from knitsweep.model import CellModel
from knitsweep.relax import Relaxer
from knitsweep.relax import slsqp as slsqp_module


def _descent(params: StitchParams, x0: np.ndarray, maxiter: int):
    settings = SolverSettings(method="slsqp", maxiter=maxiter)
    return Relaxer(settings).relax(CellModel(params, None), x0, None)


def test_a_descent_into_overlapping_cores_stops_at_the_check(monkeypatch):
    """Seed's start (11.28 mm of yarn) asked for 8.5 mm: SLSQP crushes the cell, its
    cores overlap at the check, and the descent stops there, not at its limit."""
    monkeypatch.setattr(slsqp_module, "OVERLAP_CHECK", 40)
    params = StitchParams(stitch="seed", L_mm=8.5, k_mN_per_mm2=0.1)
    x0 = CellModel(params, None).stitch.start(1)
    r = _descent(params, x0, 400)
    assert "hard cores still overlap after 40 iterations" in r.message
    assert r.status == NOT_KNITTABLE
    assert r.iterations == 40


def test_a_descent_that_keeps_its_cores_apart_is_not_touched(monkeypatch):
    """Stockinette relaxed from its start at 11.0 mm: the same minimum, bit for bit, with
    the check every 40 iterations and with none."""
    params = StitchParams(L_mm=11.0, k_mN_per_mm2=0.1)
    x0 = CellModel(params, None).stitch.start(1)
    ends = []
    for check in (40, 10**9):
        monkeypatch.setattr(slsqp_module, "OVERLAP_CHECK", check)
        r = _descent(params, x0, 400)
        assert r.iterations > 40 and "overlap" not in r.message
        ends.append(r.x)
    assert np.array_equal(ends[0], ends[1])
