"""Golden tier: the authors' code's control points, energies and lengths (docs/model.md §10)."""

import numpy as np
import pytest
from conftest import golden_cases, golden_params

from knitsweep.config import Fidelity
from knitsweep.model import CellModel

CASES = golden_cases()
GOLDEN_RTOL = 1e-12
"""The golden values come from the authors' code on another machine. Measured
(benchmarks/cpu_spread.py, 22 cases x 2 image sets): knitsweep's kernels compiled for
this host (AMD EPYC, AVX-512) and for NUMBA_CPU_NAME=generic give identical energies and
lengths, both within 2.3e-14 (relative) of the golden ones; the tolerance is ~40x that."""
IDS = [c["name"] for c in CASES]


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_control_points_match_reference(case):
    model = CellModel(golden_params(case))
    cp = model.control_points(np.array(case["x"]))
    np.testing.assert_allclose(cp, np.array(case["control_points"]), rtol=0, atol=1e-12)


@pytest.mark.parametrize("images", ["cutoff", "reference"])
@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_energies_and_length_match_reference(case, images):
    fid = Fidelity(samples_per_segment=case["params"]["N"], images=images)
    e = CellModel(golden_params(case), fid).energies(np.array(case["x"]))
    for name in ("bending_energy", "contact_energy", "length", "total_energy"):
        assert getattr(e, name) == pytest.approx(case[name], rel=GOLDEN_RTOL, abs=0), name


def test_core_penalty_cases_are_covered():
    """Some golden cases sit deep in the hard-core branch on purpose (zeta < 1e-5)."""
    deep = [c for c in CASES if c["contact_energy"] > 100]
    assert len(deep) >= 2
    for case in deep:
        fid = Fidelity(samples_per_segment=case["params"]["N"])
        assert CellModel(golden_params(case), fid).min_zeta(np.array(case["x"])) < 1e-5


def test_default_quadrature_is_exact_and_coarse_is_not():
    """32 Gauss–Legendre nodes reach 1e-12 on every case; 8 nodes are a measured
    ~1e-3 approximation on the strongly bent public_6 case."""
    case = next(c for c in CASES if c["name"] == "public_6")
    fine = CellModel(golden_params(case)).energies(np.array(case["x"]))
    coarse = CellModel(golden_params(case), Fidelity(quadrature_nodes=8)).energies(
        np.array(case["x"])
    )
    assert fine.bending_energy == pytest.approx(case["bending_energy"], rel=1e-12)
    assert abs(coarse.bending_energy / case["bending_energy"] - 1) > 1e-5
