"""Integration tier: results as data (``knitsweep.load``, pandas, xarray), the
self-describing results file, studies that combine, and grids with tied axes."""

import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import TINY, stored
from results_factory import write_results

import knitsweep
import knitsweep.report
from knitsweep.config import InputError
from knitsweep.quantities import COLUMN_QUANTITY, PARAMETERS, dataset_quantity
from knitsweep.service.jobs import JobSpec, load_job
from knitsweep.store.format import POINTS, SWEEPS
from knitsweep.store.read import read_entry
from knitsweep.store.writer import ResultWriter

ROOT = Path(__file__).resolve().parents[1]
PARAMS = list(PARAMETERS)


def test_load_gives_dataframes_named_as_job_files(tiny_reference):
    res = knitsweep.load(tiny_reference)
    assert (len(res.points), len(res.sweeps), len(res.transitions)) == (2, 4, 2)
    for table in (res.points, res.sweeps, res.curves):
        assert set(PARAMS) <= set(table.columns)
    for col in ("Y_sec_N_per_mm", "sigma0_N_per_mm", "delta_E_b_mJ", "delta_E_c_mJ",
                "jamming_gap_mJ", "direction", "status"):  # fmt: skip
        assert col in res.sweeps.columns, col
    for col in ("strain", "stress_N_per_mm", "stress_envelope_N_per_mm", "bending_energy_mJ",
                "contact_energy_mJ", "thickness_mm", "winner", "step", "relax_seconds"):  # fmt: skip
        assert col in res.curves.columns, col
    assert res.transitions["L_over_r_trans"].notna().any()
    # the curves are the stored arrays, step by step
    sid = res.sweeps["task_id"].iloc[0]
    stored = read_entry(tiny_reference, SWEEPS, sid).record
    curve = res.curves[res.curves["task_id"] == sid]
    np.testing.assert_array_equal(curve["stress_N_per_mm"], stored["stress"])
    np.testing.assert_array_equal(curve["step"], np.arange(len(stored["stress"])))
    assert len(res.curves) == res.sweeps["n_steps"].sum()
    assert "4 sweeps" in repr(res)


def test_csv_tables_and_dataframes_share_their_names(tiny_reference, tmp_path):
    import pandas as pd

    report = knitsweep.report.phase_diagram(tiny_reference, tmp_path / "pd", figures=False)
    res = report.results
    for name, frame in (("sweeps", res.sweeps), ("points", res.points),
                        ("transitions", res.transitions)):  # fmt: skip
        csv = pd.read_csv(tmp_path / "pd" / f"{name}.csv")
        assert list(csv.columns) == [*frame.columns, "partial"], name


def test_to_xarray_over_the_grids_own_dimensions(tiny_reference, tmp_path):
    res = knitsweep.load(tiny_reference)
    ds = res.to_xarray()
    assert ds.attrs["Conventions"].startswith("CF-")
    assert dict(ds.sizes) == {"direction": 2, "L_mm": 2, "step": int(res.sweeps["n_steps"].max())}
    assert ds["stress_N_per_mm"].dims == ("direction", "L_mm", "step")
    assert ds["strain"].dims == ("direction", "L_mm", "step") and "strain" in ds.coords
    assert ds["Y_sec_N_per_mm"].dims == ("direction", "L_mm")
    assert ds["a_x0_mm"].dims == ("direction", "L_mm") and ds["point_status"].dims == ("L_mm",)
    assert ds["L_over_r_trans"].dims == ("direction",)  # the transitions, per series
    assert float(ds["k_mN_per_mm2"]) == 0.1  # one value: a scalar coordinate
    for name, var in {**ds.data_vars, **ds.coords}.items():
        assert "units" in var.attrs and "long_name" in var.attrs, name
    assert ds["stress_N_per_mm"].attrs["units"] == "N/mm"
    # integers stay integers, booleans booleans (every cell is present here)
    assert ds["n_steps"].dtype.kind == "i" and ds["jammed"].dtype == bool
    assert ds["winner"].dtype.kind == "i" and ds["winner"].encoding["_FillValue"] == -1
    # the values are the tables' values, cell by cell
    row = res.sweeps.iloc[0]
    cell = ds.sel(direction=row["direction"], L_mm=row["L_mm"])
    assert float(cell["Y_sec_N_per_mm"]) == row["Y_sec_N_per_mm"]
    curve = res.select(direction=row["direction"], L_mm=row["L_mm"]).curves
    np.testing.assert_array_equal(cell["stress_N_per_mm"][: len(curve)], curve["stress_N_per_mm"])
    assert np.isnan(cell["stress_N_per_mm"][len(curve) :]).all()
    assert (cell["winner"][len(curve) :] == -1).all()
    ds.to_netcdf(tmp_path / "r.nc", engine="h5netcdf")  # a valid netCDF-4 file


def test_to_xarray_keeps_types_with_fill_values_where_cells_are_missing(tiny_reference):
    ds = knitsweep.load(tiny_reference).select(direction="x", L_mm=11.4).to_xarray()
    full = knitsweep.load(tiny_reference).to_xarray()
    assert ds.sizes["L_mm"] == 1 and full.sizes["L_mm"] == 2
    res = knitsweep.load(tiny_reference)
    three = list(res.sweeps["task_id"][:3])  # one (direction, L) cell without a sweep
    part = res.select(task_id=three).to_xarray()
    assert part.sizes == {"direction": 2, "L_mm": 2, "step": part.sizes["step"]}
    assert part["jammed"].dtype == np.int8 and part["jammed"].attrs["flag_meanings"] == "false true"
    assert (part["jammed"] == -1).sum() == 1 and part["n_steps"].dtype.kind == "i"


def test_one_stress_strain_curve_per_L_in_one_line(tiny_reference, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    ds = knitsweep.load(tiny_reference).to_xarray()
    lines = ds.stress_N_per_mm.sel(direction="x").plot.line(x="strain", hue="L_mm")
    assert len(lines) == 2
    assert np.array_equal(lines[0].get_xdata()[:3], ds.strain.sel(direction="x")[0, :3])


def test_select_and_tables_sorted_by_direction_parameters_step(tiny_reference):
    res = knitsweep.load(tiny_reference)
    for table in (res.sweeps, res.curves):
        order = table[["direction", "L_mm", *(["step"] if "step" in table else [])]]
        assert order.equals(order.sort_values(list(order.columns)).reset_index(drop=True))
    x = res.select(direction="x")
    assert set(x.sweeps["direction"]) == {"x"} and len(x.points) == 2
    one = res.select(L_mm=11.4, direction="x")
    assert len(one.sweeps) == 1 and set(one.curves["L_mm"]) == {11.4}
    assert len(res.select(L_mm=[11.4, 12.0]).sweeps) == 4
    with pytest.raises(KeyError, match="no column colour"):
        res.select(colour="red")
    assert set(res.transitions["file"]) == {str(tiny_reference)}
    assert {"L_mm", "k_mN_per_mm2", "file"} <= set(res.problems.columns)


def test_every_dataset_of_a_run_is_self_describing(tiny_reference):
    """units, long_name and a named dimension on every dataset; no phony dimensions;
    each kind opens in xarray as one dataset over its tasks, equal to what knitsweep
    reads (padding aside)."""
    import xarray as xr

    with h5py.File(tiny_reference) as f:
        for kind in (POINTS, SWEEPS):
            for name, ds in f[kind].items():
                assert "units" in ds.attrs and "long_name" in ds.attrs, (kind, name)
                if ds.is_scale:
                    continue
                assert all(len(d) for d in ds.dims), (kind, name)
                if ds.ndim > 1:
                    assert dataset_quantity(kind, name), f"{kind}/{name}: not in quantities"
    for kind in (POINTS, SWEEPS):
        opened = xr.open_dataset(tiny_reference, engine="h5netcdf", group=kind)
        assert not [d for d in opened.dims if d.startswith("phony")], opened.dims
        assert ("step" if kind == SWEEPS else "start") in opened.dims
        assert opened["seconds"].attrs["units"] == "s"  # the task's wall time
        for tid, e in stored(tiny_reference, kind, with_data=True).items():
            row = opened.sel(task=tid)
            assert float(row["L_mm"]) == e.meta["L_mm"] and str(row["status"].values) == "done"
            for name, value in e.record.items():
                if value.dtype.kind == "f":
                    got = row[name].values[tuple(slice(0, n) for n in value.shape)]
                    assert np.array_equal(got, value, equal_nan=True), (kind, name)


def test_checkpoints_keep_the_dimension_scales(tiny_reference, tmp_path):
    """A result written at one checkpoint is written again into the next shadow copy:
    its dimensions must still resolve in the published file after both."""
    import xarray as xr

    job = load_job(TINY)
    out = tmp_path / "two.h5"
    writer = ResultWriter(out, job, {"n_points": 2, "n_sweeps": 4})
    sids = sorted(stored(tiny_reference, SWEEPS))[:3]
    for sid in sids:
        entry = read_entry(tiny_reference, SWEEPS, sid)
        writer.add(SWEEPS, sid, entry.record, entry.meta)
        writer.checkpoint()
    writer.close("partial")
    ds = xr.open_dataset(out, engine="h5netcdf", group="sweeps")
    assert ds["stress"].dims == ("task", "step") and ds.sizes["step"] > 2
    assert sorted(ds["task"].values) == sids


def test_several_files_combine_and_old_schema_reads(tmp_path):
    """Two files of different jobs (k = 0.1 and k = 1.0; results schema 1)."""
    a = write_results(tmp_path / "a.h5", ks=(0.1,), not_knittable_L=None)
    b = write_results(tmp_path / "b.h5", ks=(1.0,), not_knittable_L=None)
    both = knitsweep.load(a, b)
    assert sorted(both.transitions["k_mN_per_mm2"].unique()) == [0.1, 1.0]
    assert len(both.sweeps) == len(knitsweep.load(a).sweeps) + len(knitsweep.load(b).sweeps)
    assert set(both.points["file"]) == {str(a), str(b)}
    with pytest.raises(InputError, match="given twice"):
        knitsweep.load(a, a)
    out = subprocess.run([sys.executable, "-m", "knitsweep", "phase-diagram", str(a), str(b),
                          "--out", str(tmp_path / "pd"), "--no-figures"],
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "pd" / "transitions.csv").read_text().count("\n") == 1 + 4


def test_load_reads_a_file_being_written(tiny_reference, tmp_path):
    """A result still in the journal (not yet checkpointed) is read."""
    job = load_job(TINY)
    out = tmp_path / "live.h5"
    writer = ResultWriter(out, job, {"n_points": 2, "n_sweeps": 4})
    try:
        res = knitsweep.load(out)
        assert len(res.points) == 0
        pid = next(iter(stored(tiny_reference, POINTS)))
        entry = read_entry(tiny_reference, POINTS, pid)
        writer.add(POINTS, pid, entry.record, entry.meta)
        assert len(knitsweep.load(out).points) == 0  # queued, not yet durable
        writer.commit()  # its journal batch: durable, and read
        res = knitsweep.load(out)
        assert list(res.points["task_id"]) == [pid] and res.partial
    finally:
        writer.close("partial")


def test_example_script_runs(tiny_reference, tmp_path):
    png = tmp_path / "ss.png"
    out = subprocess.run([sys.executable, str(ROOT / "examples" / "stress_strain_by_L.py"),
                          str(tiny_reference), "--out", str(png)],
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert png.stat().st_size > 10_000 and "Y_sec_N_per_mm" in out.stdout


def test_column_quantities_know_their_units():
    assert COLUMN_QUANTITY["stress_N_per_mm"].units == "N/mm"
    assert COLUMN_QUANTITY["delta_E_c_mJ"].units == "mJ"
    assert COLUMN_QUANTITY["L_mm"].units == "mm"


# ---- grids with ties and zipped axes -----------------------------------------------


def _job(**grid):
    return JobSpec(schema_version=1, name="t", grid=grid)


def test_tied_core_radius_follows_the_yarn_radius():
    job = _job(L_mm=12.0, r_mm=[0.66, 0.7, 0.74], r_core_mm="0.45 * r_mm")
    assert [(p.r_mm, p.r_core_mm) for p in job.points()] == [(0.66, 0.297), (0.7, 0.315),
                                                             (0.74, 0.333)]  # fmt: skip
    again = JobSpec.model_validate_json(job.model_dump_json())
    assert again.job_hash == job.job_hash and again.points() == job.points()
    assert job.job_hash != _job(L_mm=12.0, r_mm=[0.66, 0.7, 0.74]).job_hash


def test_zipped_axes_vary_together():
    job = _job(L_mm=[11.0, 12.0], r_mm=[0.7, 0.75], k_mN_per_mm2=[0.1, 1.0],
               zip=[["L_mm", "r_mm"]])  # fmt: skip
    assert [(p.k_mN_per_mm2, p.L_mm, p.r_mm) for p in job.points()] == [
        (0.1, 11.0, 0.7), (0.1, 12.0, 0.75), (1.0, 11.0, 0.7), (1.0, 12.0, 0.75)]  # fmt: skip


def test_plain_grids_keep_their_hashes():
    """Ties and zips enter the job hash only when used: older files still resume."""
    assert "ties" not in _job(L_mm=11.0).canonical()["grid"]
    assert "zip" not in _job(L_mm=11.0).canonical()["grid"]


@pytest.mark.parametrize(
    ("grid", "message"),
    [
        ({"L_mm": 12.0, "r_core_mm": "0.45 * r_core_mm"}, "cannot follow itself"),
        ({"L_mm": 12.0, "r_core_mm": "0.45 * q"}, "'q' is not one of"),
        ({"L_mm": 12.0, "r_core_mm": "0.45 * r_mm", "r_mm": "L_mm"}, "is itself tied"),
        ({"L_mm": 12.0, "r_core_mm": "half of r"}, "a tie is '<number> \\* <parameter>'"),
        ({"L_mm": 12.0, "r_core_mm": "-0.4 * r_mm"}, "factor must be a finite number > 0"),
        ({"L_mm": [1.0, 2.0], "r_mm": [0.7], "zip": [["L_mm", "r_mm"]]}, "same number"),
        ({"L_mm": [10.0, 11.0], "r_mm": [0.7, 0.8], "zip": [["L_mm", "L_mm"]]}, "different"),
        ({"L_mm": 12.0, "r_core_mm": "1.2 * r_mm"}, "r_core_mm < r_mm"),
    ],
)
def test_bad_ties_and_zips_are_refused(tmp_path, grid, message):
    path = tmp_path / "j.toml"
    lines = ["schema_version = 1", 'name = "t"', "[grid]"]
    lines += [f"{k} = {json.dumps(v)}" for k, v in grid.items()]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=message):
        load_job(path)


def test_shipped_fixed_ratio_radius_job():
    job = load_job(ROOT / "jobs" / "paper_radius_fixed_ratio.toml")
    points = job.points()
    assert len({p.r_mm for p in points}) == len(points) > 5
    assert all(abs(p.r_core_mm / p.r_mm - 0.45) < 1e-9 and p.L_mm == 12.0 for p in points)
