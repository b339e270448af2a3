"""The accuracy study: structure, errors against the finest setting, report files."""

import csv
import math

import pytest

from knitsweep.config import StitchParams
from knitsweep.studies.accuracy import METRICS, accuracy_study, setting, table, write_report

CHEAP = "draft:step_mm=0.02+stop_stress_N_per_mm=0.05+max_strain=0.2"


def test_setting_parsing():
    s = setting("converged:samples_per_segment=6+ftol=1e-8+step_mm=0.002")
    assert s.fidelity.samples_per_segment == 6 and s.solver.ftol == 1e-8
    assert s.protocol.step_mm == 0.002 and s.fidelity.quadrature_nodes == 32
    with pytest.raises(ValueError):
        setting("converged:samples_per_segment=1")


def test_study_measures_errors_against_the_finest(tmp_path):
    point = StitchParams(L_mm=11.0, k_mN_per_mm2=0.1)
    results = accuracy_study(point, [CHEAP, CHEAP + "+samples_per_segment=12"], [11.3, 11.5, 11.7])
    coarse, fine = results
    assert all(fine.errors[m] == 0 for m in METRICS if fine.values[m] is not None)
    assert coarse.errors["E0"] > 0 and coarse.seconds_sweep > 0
    assert all(math.isfinite(v) for v in coarse.values.values() if v is not None)
    assert 11.3 / 0.74 < fine.values["L_over_r_trans_x"] < 11.7 / 0.74
    csv_path, png = write_report(results, tmp_path)
    with open(csv_path) as f:
        rows = list(csv.DictReader(f))
    assert [r["setting"] for r in rows] == [coarse.name, fine.name]
    assert png.stat().st_size > 10_000
    assert "E0" in table(results)
