"""Stability at the edges of parameter space (issue 7): every run ends with finite
numbers and a truthful status; no NaN is stored; no exception escapes a task."""

import math

import numpy as np
import pytest

from knitsweep.kernels.contact import CORE_EPS
from knitsweep.service.jobs import JobSpec, plan
from knitsweep.service.worker import execute

BASE = {"L_mm": 11.6, "k_mN_per_mm2": 0.1}
EXTREMES = {
    "k=1e-3 (soft limit)": {"k_mN_per_mm2": 1e-3},
    "k=10 (stiff limit)": {"k_mN_per_mm2": 10.0},
    "p=1.2": {"p": 1.2},
    "p=4": {"p": 4.0},
    "r_core/r=0.05": {"r_core_mm": 0.037},
    "r_core/r=0.95": {"r_core_mm": 0.703},
    "B=9 (B/10)": {"B_mN_mm2": 9.0},
    "B=900 (10 B)": {"B_mN_mm2": 900.0},
    "L=10": {"L_mm": 10.0},
    "L=8 (too short)": {"L_mm": 8.0},
    "L=16 (loose)": {"L_mm": 16.0},
}
PROTOCOLS = {
    "tiny steps": {"step_mm": 1e-5, "max_steps": 6},
    "huge steps": {"step_mm": 1.0, "switch_strain": 0.0, "max_steps": 6},
}


def _job(grid, protocol=None):
    return JobSpec(
        schema_version=1, name="extreme", preset="draft", directions=["x", "y"],
        grid={**BASE, **grid}, starts={"count": 1},
        protocol={"max_steps": 8, **(protocol or {})},
    )  # fmt: skip


def _finite(record):
    for key, value in record.items():
        if isinstance(value, np.ndarray) and value.dtype.kind in "fc":
            assert np.all(np.isfinite(value)), key
        elif isinstance(value, float):
            assert math.isfinite(value), key


UNREACHABLE = {"L=8 (too short)"}
"""Points whose walk from the start may also end short of L (a failed task, never done):
at 8 mm the continuation from Init_1 (12.6 mm) meets overlapping cores on the way, and
whether it then ends at L with the cores overlapping (not knittable) or stops with the
length missed (failed) depends on the build's last bits (both seen, on two machines'
builds of the same commit)."""


def _check_point(job, point, unreachable=False):
    reply = execute(job, point, None, rank=0)
    assert reply.error is None, reply.error and reply.error["traceback"]
    rec = reply.record
    _finite(rec)
    assert rec["status"] in ("done", "not_knittable", *(("failed",) if unreachable else ()))
    w = rec["winner"]
    if rec["status"] == "done":
        assert abs(rec["length"][w] - point.params.L_mm) <= job.solver.length_tol_mm
        assert rec["min_zeta"][w] >= CORE_EPS
    elif rec["status"] == "not_knittable":
        assert rec["min_zeta"][w] < CORE_EPS and "overlap" in rec["message"]
    else:  # failed, and says why: the length it could not reach
        assert "length constraint missed" in rec["message"]
        assert abs(rec["length"][w] - point.params.L_mm) > job.solver.length_tol_mm
    return rec


def _check_sweeps(job, point, rec):
    _, sweeps = plan(job)
    for s in sweeps:
        reply = execute(job, s, {**rec, "params": point.params}, rank=0)
        assert reply.error is None, reply.error and reply.error["traceback"]
        _finite(reply.record)
        assert reply.record["status"] in ("done", "not_knittable")
        assert len(reply.record["strain"]) >= 2


@pytest.mark.parametrize("name", list(EXTREMES))
def test_parameter_extremes(name):
    job = _job(EXTREMES[name])
    (point,), _ = plan(job)
    rec = _check_point(job, point, name in UNREACHABLE)
    if rec["status"] == "done":
        _check_sweeps(job, point, rec)


def test_expected_verdicts():
    """Cores of 95 % of the yarn radius, or 8 mm of yarn per stitch at r = 0.74 mm,
    cannot be stitched without the cores overlapping; 16 mm is a loose stitch."""
    for name, verdict in (("r_core/r=0.95", ("not_knittable",)),
                          ("L=8 (too short)", ("not_knittable", "failed")),
                          ("L=16 (loose)", ("done",))):  # fmt: skip
        job = _job(EXTREMES[name])
        assert _check_point(job, plan(job)[0][0], name in UNREACHABLE)["status"] in verdict, name


@pytest.mark.parametrize("name", list(PROTOCOLS))
def test_strain_step_extremes(name):
    job = _job({}, PROTOCOLS[name])
    (point,), _ = plan(job)
    _check_sweeps(job, point, _check_point(job, point))
