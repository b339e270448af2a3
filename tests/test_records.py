"""Integration tier: records go to the results file and back without loss, and the
`run` and `sweep` paths agree (docs/model.md §8)."""

import dataclasses

import h5py
import numpy as np
import pytest
from conftest import TINY

from knitsweep.config import Fidelity, SolverSettings, StartSettings, StitchParams
from knitsweep.relax.zero_force import ZeroForce, zero_force
from knitsweep.service.jobs import load_job, plan
from knitsweep.store.format import POINTS, SWEEPS, split_record
from knitsweep.store.journal import Entry
from knitsweep.store.read import read_entry
from knitsweep.store.table import create_table, find_row, put_rows
from knitsweep.strain_sweep import SweepResult, strain_sweep, strain_sweep_from_rest

PARAMS = StitchParams(L_mm=11.4, k_mN_per_mm2=0.1)
FIDELITY = Fidelity(samples_per_segment=6, quadrature_nodes=12)
SOLVER = SolverSettings(ftol=1e-8)


def _through_hdf5(tmp_path, record, kind):
    """A record written as a row of a results-file table and read back (scalars and
    arrays, verified)."""
    arrays, scalars = split_record(record)
    with h5py.File(tmp_path / "r.h5", "w") as f:
        create_table(f, kind)
        put_rows(f[kind], kind, [Entry(kind, "t", arrays, scalars)])
    with h5py.File(tmp_path / "r.h5", "r") as f:
        back = find_row(f[kind], kind, "t")
    assert back is not None
    return {**back.record, **back.meta}


def _assert_same(a, b):
    for field in dataclasses.fields(a):
        va, vb = getattr(a, field.name), getattr(b, field.name)
        if isinstance(va, np.ndarray):
            assert va.dtype.kind == np.asarray(vb).dtype.kind, field.name
            np.testing.assert_array_equal(va, vb, err_msg=field.name)
        elif isinstance(va, dict):  # the registered observables, arrays by name
            assert list(va) == list(vb) and va, field.name
            for name in va:
                assert va[name].dtype == vb[name].dtype, name
                np.testing.assert_array_equal(va[name], vb[name], err_msg=name)
        elif isinstance(va, tuple) and va and dataclasses.is_dataclass(va[0]):
            for ra, rb in zip(va, vb, strict=True):
                _assert_same(ra, rb)
        else:
            assert type(va) is type(vb) and va == vb, (field.name, va, vb)


@pytest.fixture(scope="module")
def zero():
    return zero_force(PARAMS, FIDELITY, SOLVER, StartSettings(count=2))


def test_zero_force_round_trips_every_field(zero, tmp_path):
    back = ZeroForce.from_record(_through_hdf5(tmp_path, zero.to_record(), POINTS))
    _assert_same(zero, back)
    assert back.best.period_forces != (0.0, 0.0)  # the real forces, not placeholders


def test_sweep_result_round_trips_every_field(zero, tmp_path):
    from knitsweep.config import SweepProtocol

    protocol = SweepProtocol(step_mm=0.02, switch_strain=0.04, stop_stress_N_per_mm=0.03)
    sweep = strain_sweep(PARAMS, zero, "x", protocol, FIDELITY, SOLVER)
    record = sweep.to_record()
    assert record["delta_E_c"] == sweep.energy_gaps.delta_E_c == record["jamming_gap"]
    back = SweepResult.from_record(_through_hdf5(tmp_path, record, SWEEPS))
    _assert_same(sweep, back)


def test_run_and_sweep_paths_give_the_same_sweep(tiny_reference):
    """The `run` path rebuilds the zero-force state from its stored record; the
    `sweep` path relaxes it in place. Same numbers, stress_envelope[0] included."""
    job = load_job(TINY)
    points, sweeps = plan(job)
    point, task = points[0], next(s for s in sweeps if s.point_id == points[0].task_id)
    stored = read_entry(tiny_reference, SWEEPS, task.task_id)
    entry = read_entry(tiny_reference, POINTS, point.task_id)
    rest = ZeroForce.from_record({**entry.record, **entry.meta})
    zero, sweep = strain_sweep_from_rest(point.params, task.direction, job.protocol, job.fidelity,
                                         job.solver, job.starts, point.seed)  # fmt: skip
    np.testing.assert_array_equal(zero.best.x, rest.best.x)
    assert zero.best.period_forces == rest.best.period_forces
    a_perp0 = rest.best.a_y if task.direction == "x" else rest.best.a_x
    force = rest.best.period_forces[0 if task.direction == "x" else 1]
    assert stored.record["stress_envelope"][0] == sweep.stress_envelope[0] == force / a_perp0
    for name in ("strain", "stress", "stress_envelope", "bending_energy", "contact_energy"):
        np.testing.assert_array_equal(stored.record[name], getattr(sweep, name), err_msg=name)


def test_records_of_earlier_versions_read_under_todays_names(tmp_path):
    """A sweep stored as earlier versions stored it (``energy_gap``, since renamed
    ``jamming_gap``) reads with today's name, from a file and from a journal entry."""
    import h5py

    from knitsweep.store.format import _read_group
    from knitsweep.store.journal import decode, encode

    with h5py.File(tmp_path / "old.h5", "w") as f:
        g = f.create_group("sweeps/abc")
        g.attrs["energy_gap"] = 1.5e-4
        attrs, _ = _read_group(g)
    assert attrs["jamming_gap"] == 1.5e-4 and "energy_gap" not in attrs
    entry = decode(encode(Entry("sweeps", "abc", {"energy_gap": 2e-4}, {"status": "done"})))
    assert entry.record == {"jamming_gap": 2e-4}
