"""``[starts] retries``: a point none of whose starts converged or was too tight to knit
walks its failed starts again from perturbed copies and takes their verdict
(service/retry.py); the record says so, and the setting is validated and left out of
task ids at its default."""

from dataclasses import replace

import numpy as np
import pytest
from conftest import TINY

from knitsweep.config import CONVERGED, NOT_CONVERGED, NOT_KNITTABLE, StartSettings
from knitsweep.errors import InputError
from knitsweep.relax.zero_force import zero_force
from knitsweep.service import worker
from knitsweep.service.jobs import load_job, plan
from knitsweep.service.retry import needs_retry, retry_failed_starts


def _failed(zf, status=NOT_CONVERGED):
    """``zf`` as a walk that left the stitch would have ended it (its energy kept)."""
    bad = replace(zf.best, status=status, message="topology changed: (as a walk ends)")
    return replace(zf, relaxations=(bad,), status=status, message="no start converged")


@pytest.fixture(scope="module")
def job():
    return load_job(TINY)


@pytest.fixture(scope="module")
def point(job):
    points, _ = plan(job)
    return points[0]


@pytest.fixture(scope="module")
def converged(job, point):
    zf = zero_force(point.params, job.fidelity, job.solver, job.starts, point.seed)
    assert zf.status == CONVERGED
    return zf


def test_only_a_point_with_a_start_neither_converged_nor_too_tight_is_retried(converged):
    assert needs_retry(converged) == []
    assert needs_retry(_failed(converged, NOT_KNITTABLE)) == []
    assert needs_retry(_failed(converged)) == [0]


def test_a_failed_start_takes_its_perturbed_copies_verdict(job, point, converged, monkeypatch):
    monkeypatch.setattr("knitsweep.relax.zero_force.zero_force", lambda *a, **k: _failed(converged))
    record = worker.run_point(job, point)  # without the retry: a failed task
    assert record["status"] == "done" and record["relax_status"] == CONVERGED
    assert list(record["retried"]) == [job.starts.retries] and job.starts.retries == 3
    assert "retried from 3 copies perturbed by 1e-12" in record["message"]
    assert "first walk: topology changed" in str(record["start_message"][0])
    # the copies differ from the start by 1e-12 relative: the same minimum
    assert record["rest_energy"] == pytest.approx(converged.best.total_energy, abs=1e-8)


def test_no_retry_when_told_so_or_nothing_failed(job, point, converged, monkeypatch):
    none = job.starts.model_copy(update={"retries": 0})
    zf, retried, note = retry_failed_starts(_failed(converged), [], point.params, job.fidelity,
                                            job.solver, none, point.seed)  # fmt: skip
    assert zf.status == NOT_CONVERGED and note == "" and not retried.any()
    monkeypatch.setattr("knitsweep.relax.zero_force.zero_force", lambda *a, **k: converged)
    record = worker.run_point(job, point)
    assert "retried" not in record and "retry_message" not in record


def test_retries_are_validated_and_out_of_task_ids_at_their_default(tmp_path):
    from knitsweep.service.id_forms import STARTS_FORMS

    def form(s):
        return STARTS_FORMS.id_form(s.model_dump(mode="json"))

    assert "retries" not in form(StartSettings()) and "retries" in StartSettings().model_dump()
    assert form(StartSettings(retries=5))["retries"] == 5
    bad = tmp_path / "bad.toml"
    bad.write_text(TINY.read_text().replace("[starts]\n", "[starts]\nretries = 17\n"))
    with pytest.raises(InputError, match=r"starts\.retries.*16"):
        load_job(bad)


def test_the_copies_are_seeded(job, point, converged):
    failed = _failed(converged)
    begin = [(np.asarray(converged.best.x), point.params)]
    a = retry_failed_starts(failed, begin, point.params, job.fidelity, job.solver, job.starts, 7)
    b = retry_failed_starts(failed, begin, point.params, job.fidelity, job.solver, job.starts, 7)
    assert np.array_equal(a[0].best.x, b[0].best.x) and a[2] == b[2]
