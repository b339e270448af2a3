"""Integration tier: the packing fraction as an optional stored observable
([store] packing_fraction = true; paper SI "Contact Volumes"): dataset in the file,
columns in the points and curves tables, and the job hash of jobs without it unchanged."""

import h5py
import numpy as np
import pytest
from conftest import stored

JOB = """schema_version = 1
name = "phi"
seed = 7
directions = ["x"]
preset = "draft"

[grid]
L_mm = 11.4
k_mN_per_mm2 = 0.1

[protocol]
observables = ["curve"]
step_control = "fixed"
step_mm = 0.02
switch_strain = 0.04
stop_stress_N_per_mm = 0.03
max_strain = 0.06

[starts]
count = 1

[store]
packing_fraction = true
"""


@pytest.fixture(scope="module")
def phi_file(tmp_path_factory):
    from knitsweep import service

    d = tmp_path_factory.mktemp("phi")
    job = d / "phi.toml"
    job.write_text(JOB)
    out = d / "phi.h5"
    summary = service.run(job, out, executor="serial", show_progress=False)
    assert summary.counts["done"] == summary.total == 2
    return out


def test_stored_in_the_file(phi_file):
    with h5py.File(phi_file, "r") as f:
        assert f["sweeps/packing_fraction"].attrs["units"] == "1"
    ((sweep,), (point,)) = (
        stored(phi_file, k, with_data=True).values() for k in ("sweeps", "points")
    )
    phi = sweep.record["packing_fraction"]
    assert phi.shape == sweep.record["strain"].shape
    assert np.all((phi > 0.5) & (phi < 1.0))
    assert np.all(sweep.record["packing_fraction_error"] < 5e-3)
    assert point.record["packing_fraction"].shape == (1,)
    # step 0 is the zero-force state: the point's value
    assert phi[0] == pytest.approx(point.record["packing_fraction"][0], abs=1e-12)


def test_columns_in_the_tables(phi_file):
    import knitsweep
    from knitsweep.analysis.volumes import packing_fraction
    from knitsweep.config import StitchParams
    from knitsweep.model import CellModel

    res = knitsweep.load(phi_file)
    assert "packing_fraction" in res.curves.columns
    assert "packing_fraction" in res.points.columns
    c = res.curves
    assert c.packing_fraction.notna().all()
    # recomputed from the stored zero-force state: the same number
    (point,) = stored(phi_file, "points", with_data=True).values()
    x = point.record["x"][0]
    cp = CellModel(StitchParams(L_mm=11.4, k_mN_per_mm2=0.1)).control_points(x)
    phi, _ = packing_fraction(cp, x[-2], x[-1], 0.74)
    assert res.points.packing_fraction.iloc[0] == pytest.approx(phi, abs=1e-12)


def test_job_hash_without_it_unchanged(tmp_path):
    from knitsweep.service.jobs import load_job

    plain = tmp_path / "a.toml"
    plain.write_text(JOB.replace("packing_fraction = true", ""))
    off = tmp_path / "b.toml"
    off.write_text(JOB.replace("packing_fraction = true", "packing_fraction = false"))
    on = tmp_path / "c.toml"
    on.write_text(JOB)
    a, b, c = (load_job(p) for p in (plain, off, on))
    assert a.job_hash == b.job_hash != c.job_hash
    assert "packing_fraction" not in a.canonical()["store"]


def test_a_patterns_stored_value_counts_its_mirrored_images():
    """The worker's packing fraction of a rib start is the estimator's over the rib's
    mirrored images, not over the translated fabric's."""
    from knitsweep.analysis.volumes import packing_fraction
    from knitsweep.config import StitchParams
    from knitsweep.model import CellModel
    from knitsweep.service.worker import _packing_fractions

    model = CellModel(StitchParams(L_mm=11.6, k_mN_per_mm2=0.1, stitch="rib"))
    x = model.stitch.start(1)
    got = _packing_fractions(model, [x, x])
    cp = model.control_points(x)
    mirrored = packing_fraction(cp, x[-2], x[-1], model.params.r_mm, model.stitch.mirror_parity)
    translated = packing_fraction(cp, x[-2], x[-1], model.params.r_mm)
    assert model.stitch.mirror_parity == (1, 0)
    assert np.array_equal(got["packing_fraction"], [mirrored[0]] * 2)
    assert mirrored[0] != translated[0]
