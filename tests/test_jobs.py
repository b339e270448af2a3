"""Job specs: validation before any compute, grids, presets, content-addressed ids."""

import subprocess
import sys
from pathlib import Path

import pytest

from knitsweep.config import InputError
from knitsweep.service.grid import Range
from knitsweep.service.jobs import JobSpec, load_job, plan

ROOT = Path(__file__).resolve().parents[1]
MINIMAL = 'schema_version = 1\nname = "t"\n[grid]\nL_mm = [11.6]\n'


def _job(tmp_path, text):
    path = tmp_path / "job.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize("name", sorted(p.stem for p in (ROOT / "jobs").glob("*.toml")))
def test_shipped_jobs_are_valid(name):
    job = load_job(ROOT / "jobs" / f"{name}.toml")
    points, sweeps = plan(job)
    assert len(sweeps) == len(points) * len(job.directions)


def test_paper_series_is_the_papers_grid():
    job = load_job(ROOT / "jobs" / "paper_k0.1_L_sweep.toml")
    L = job.grid.axes()["L_mm"]
    assert L[0] == 10.5 and L[-1] == 12.8 and len(L) == 24
    assert 11.6 in L  # decimal steps: exactly 11.6, not 11.600000000000001
    assert job.grid.axes()["k_mN_per_mm2"] == [0.1]


def test_range_is_inclusive_and_decimal():
    assert Range(start=10.5, stop=10.8, step=0.1).values() == [10.5, 10.6, 10.7, 10.8]


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        (MINIMAL + "colour = 'red'\n", "colour: unknown field"),
        (MINIMAL.replace("[grid]", "[grid]\nL = 3"), "grid.L: unknown field"),
        (MINIMAL + "[protocol]\nstep = 0.1\n", "protocol.step: unknown field"),
        (MINIMAL.replace("[11.6]", "{start = 12, stop = 11, step = 0.1}"), "empty range"),
        (
            MINIMAL.replace("[11.6]", "{start = 11, stop = 12, step = -0.1}"),
            "grid.L_mm = {'start': 11, 'stop': 12, 'step': -0.1}: step = -0.1",
        ),
        (MINIMAL.replace("[11.6]", "[]"), "empty list"),
        (MINIMAL.replace("[grid]", "directions = []\n[grid]"), "directions = []"),
        (MINIMAL.replace("[grid]", "directions = ['x', 'z']\n[grid]"), "directions.1 = 'z'"),
        (MINIMAL.replace("[grid]", "preset = 'ultra'\n[grid]"), "preset = 'ultra'"),
        (MINIMAL.replace("schema_version = 1", "schema_version = 2"), "schema_version = 2"),
        (
            MINIMAL + "k_mN_per_mm2 = [0.1, -1.0]\n",
            "k_mN_per_mm2 = -1.0: must be a finite number in [1e-06, 10000] mN/mm^2",
        ),
        (
            MINIMAL + "r_core_mm = [0.3, 0.8]\n",
            "r_core_mm = 0.8: must satisfy 0 < r_core_mm < r_mm",
        ),
        (MINIMAL + "p = 1.0\n", "p = 1.0: must satisfy 1 < p <= 20"),
        (MINIMAL + "B_mN_mm2 = inf\n", "grid.B_mN_mm2 = inf: must be a finite number"),
        (MINIMAL + "B_mN_mm2 = [90.0, nan]\n", "every value must be a finite number"),
        (MINIMAL + "[starts]\ncount = 0\n", "starts.count = 0"),
        (MINIMAL + "[run]\ntask_timeout_s = 0\n", "run.task_timeout_s = 0"),
        ("name = 'no grid'\nschema_version = 1\n", "grid: Field required"),
        ("this is = not toml [", "not valid TOML"),
    ],
)
def test_bad_job_specs_name_the_field(tmp_path, text, fragment):
    with pytest.raises(InputError) as e:
        load_job(_job(tmp_path, text))
    assert fragment in str(e.value)
    assert "input =" not in str(e.value), "the whole input is noise, not a field"
    assert str(e.value).count(" = ") <= 2, "one problem, one message"


def _run_refused(tmp_path, text):
    """``knitsweep run`` of a job file holding ``text``: exit 2, nothing written
    beside the job file; its stderr."""
    path = _job(tmp_path, text)
    proc = subprocess.run([sys.executable, "-m", "knitsweep", "run", str(path), "--out",
                           str(tmp_path / "out.h5")], capture_output=True, text=True,
                          timeout=120)  # fmt: skip
    assert proc.returncode == 2
    assert list(tmp_path.iterdir()) == [path]
    return proc.stderr


def test_bad_job_via_cli_writes_nothing(tmp_path):
    stderr = _run_refused(tmp_path, MINIMAL + "k_mN_per_mm2 = -1\n")
    assert stderr.count("\n") == 1 and "k_mN_per_mm2" in stderr


def test_presets_and_overrides():
    job = JobSpec(schema_version=1, name="t", grid={"L_mm": 11.6}, preset="draft",
                  fidelity={"quadrature_nodes": 24}, protocol={"observables": ["curve"]})  # fmt: skip
    assert job.fidelity.samples_per_segment == 10  # from the preset
    assert job.fidelity.quadrature_nodes == 24  # explicit override
    assert job.solver.ftol == 1e-5 and job.protocol.step_mm == 0.002
    assert job.protocol.step_control == "adaptive" and job.protocol.observables == ("curve",)


def test_task_ids_hash_parameters_not_names_or_order():
    a = JobSpec(schema_version=1, name="a", grid={"L_mm": [11.0, 12.0]})
    b = JobSpec(schema_version=1, name="b", description="other", grid={"L_mm": [12.0, 11.0]})
    c = JobSpec(schema_version=1, name="a", grid={"L_mm": [11.0, 12.1]})
    ids = lambda j: {p.task_id for p in plan(j)[0]}  # noqa: E731
    assert ids(a) == ids(b)
    assert len(ids(a) & ids(c)) == 1
    assert all(len(i) == 16 and "." not in i for i in ids(a))
    assert a.job_hash != c.job_hash


def test_grids_beyond_the_threshold_need_confirmation(tmp_path):
    from knitsweep.service.runs import LARGE_GRID_TASKS, check_grid_size

    values = ", ".join(f"{10 + i * 1e-4:.4f}" for i in range(100_000))
    job = load_job(_job(tmp_path, MINIMAL.replace("[11.6]", f"[{values}]")))
    with pytest.raises(InputError, match=r"300000 tasks \(100000 grid points\), more than 20000"):
        check_grid_size(job, None)
    check_grid_size(job, 300_000)  # confirmed
    assert LARGE_GRID_TASKS == 20_000
    proc = subprocess.run([sys.executable, "-m", "knitsweep", "run", str(tmp_path / "job.toml"),
                           "--out", str(tmp_path / "o.h5")], capture_output=True, text=True,
                          timeout=300)  # fmt: skip
    assert proc.returncode == 2 and "--max-tasks 300000" in proc.stderr
    assert not (tmp_path / "o.h5").exists()


@pytest.mark.parametrize("name", ["../../escape", "a/b", "/abs", ".hidden", "a\\b", "", "x" * 201])
def test_job_names_cannot_leave_the_directory(tmp_path, name):
    with pytest.raises(InputError, match="name = "):
        load_job(_job(tmp_path, MINIMAL.replace('name = "t"', f"name = {name!r}")))


@pytest.mark.parametrize(
    ("line", "fragment"),
    [
        (
            "[protocol]\nstep_mm = '0.005'\n",
            "protocol.step_mm = '0.005': Input should be a valid number",
        ),
        ("[protocol]\nstep_mm = true\n", "protocol.step_mm = True: Input should be a valid number"),
        ("[store]\nstates = 'yes'\n", "store.states = 'yes': Input should be a valid boolean"),
        ("[starts]\ncount = true\n", "starts.count = True: Input should be a valid integer"),
        ("[solver]\nftol = '1e-8'\n", "solver.ftol = '1e-8'"),
        ("[run]\ncheckpoint_s = '10'\n", "run.checkpoint_s = '10'"),
        ("[run]\ntask_timeout_s = 1e300\n", "run.task_timeout_s = 1e+300"),
        ("[protocol]\nstep = 0.1\n", "protocol.step: unknown field (did you mean 'step_mm'?)"),
    ],
)
def test_no_coercion_and_suggestions(tmp_path, line, fragment):
    with pytest.raises(InputError) as e:
        load_job(_job(tmp_path, MINIMAL + line))
    assert fragment in str(e.value)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        (MINIMAL.replace("schema_version = 1", "schema_version = '1'"), "schema_version = '1'"),
        (MINIMAL.replace("schema_version = 1", "schema_version = true"), "schema_version = True"),
        (MINIMAL.replace("[grid]", "seed = true\n[grid]"), "seed = True"),
        (MINIMAL.replace("[11.6]", "{start = '11', stop = 12, step = 0.1}"), "start = '11'"),
        (MINIMAL.replace("[11.6]", "1e300"), "L_mm = 1e+300: must be a finite number in (0, 100]"),
        (MINIMAL + "twist_bound = '0.9'\n", "grid.twist_bound = '0.9'"),
    ],
)
def test_top_level_and_grid_types(tmp_path, text, fragment):
    with pytest.raises(InputError) as e:
        load_job(_job(tmp_path, text))
    assert fragment in str(e.value)


def test_observables_enter_sweep_ids_only_as_they_change_results():
    """The same sweep asked for in other words is the same task; other observables give
    other sweeps of the same points."""

    def ids(observables):
        job = JobSpec(schema_version=1, name="t", grid={"L_mm": 11.6},
                      protocol={"observables": observables})  # fmt: skip
        points, sweeps = plan(job)
        return [p.task_id for p in points], [s.task_id for s in sweeps], job.job_hash

    gaps_first = ids(["energy_gaps", "secant_modulus"])
    assert ids(["secant_modulus", "energy_gaps", "secant_modulus"]) == gaps_first
    assert ids(["offset_stress"]) == ids(["curve"]) == ids(["curve", "energy_gaps"])
    curve = ids(["curve"])
    assert curve[0] == gaps_first[0]  # the zero-force tasks are shared
    assert set(curve[1]).isdisjoint(gaps_first[1]) and curve[2] != gaps_first[2]


# ---- the stitch as a grid axis ----------------------------------------------------
TWO = MINIMAL + 'stitch = ["stockinette", "stockinette_free"]\n'


@pytest.mark.parametrize(
    ("name", "job_hash", "first_point", "ids", "job_json"),
    [
        ("jobs/demo.toml", "b9f39d31e58f548d", "0ad5a06cf18daf24", "e08742359b4cabe7",
         "acbcfa15bdddc7e4"),
        ("tests/data/jobs/tiny.toml", "6cdd72bb5f539776", "43f8c26538190f30", "139008e0c88a6345",
         "0870030b6d60d1d6"),
        ("jobs/adaptive_k0.1.toml", "006c3b907e2aa31a", "3190d5abd8ca4252", "c6ac2d67f4ed2d26",
         "1556a9776a1ce864"),
    ],
)  # fmt: skip
def test_stockinette_jobs_keep_their_hash_and_ids(name, job_hash, first_point, ids, job_json):
    """The ids of jobs written before the stitch was a grid axis (computed by the
    knitsweep before it): a stockinette job names no stitch anywhere it is hashed, and
    its job_json is as it was but for the task settings' later fields, written out."""
    import hashlib

    def digest(text):
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    job = load_job(ROOT / name)
    points, _ = plan(job)
    assert job.job_hash == job_hash and points[0].task_id == first_point
    assert digest(" ".join(p.task_id for p in points)) == ids
    # the results file's job_json: as it was but for the later task settings, which
    # dumps now write at their defaults (ids hash their versioned id forms instead)
    later = {
        "starts": {"carry", "retries", "spread"},
        "protocol": {"rest_tolerance_mJ", "shear_rest"},
        "fidelity": {"contact_sampling"},
        "adaptive": {"last_crossing"},
    }
    assert digest(job.model_dump_json(exclude=later)) == job_json
    assert '"carry":false' in job.model_dump_json()
    assert "stitch" not in job.canonical() and "stitch" not in job.canonical()["grid"]
    assert '"stitch":"stockinette"' in job.model_dump_json()  # the job_json as it was
    assert '"grid":{' in job.model_dump_json() and "stitch" not in job.grid.model_dump()


def test_stitch_axis_computes_every_point_for_every_stitch(tmp_path):
    one = load_job(_job(tmp_path, MINIMAL.replace("[11.6]", "[11.0, 11.6]")))
    two = load_job(_job(tmp_path, TWO.replace("[11.6]", "[11.0, 11.6]")))
    assert two.stitches == ("stockinette", "stockinette_free") and two.grid.size() == 4
    points, sweeps = plan(two)
    assert [p.params.stitch for p in points] == ["stockinette"] * 2 + ["stockinette_free"] * 2
    assert len(sweeps) == 8 and len({p.task_id for p in points}) == 4
    # the stockinette points are the stockinette job's tasks: files of both combine
    assert [p.task_id for p in points[:2]] == [p.task_id for p in plan(one)[0]]
    assert two.job_hash != one.job_hash
    assert two.canonical()["grid"]["stitch"] == ["stockinette", "stockinette_free"]
    again = JobSpec.model_validate_json(two.model_dump_json())  # the results file's job_json
    assert again.job_hash == two.job_hash and again.stitches == two.stitches


def test_one_stitch_is_the_same_job_wherever_it_is_written(tmp_path):
    top = load_job(_job(tmp_path, MINIMAL.replace("[grid]", 'stitch = "garter"\n[grid]')))
    axis = load_job(_job(tmp_path, MINIMAL + 'stitch = "garter"\n'))
    listed = load_job(_job(tmp_path, MINIMAL + 'stitch = ["garter"]\n'))
    assert top.job_hash == axis.job_hash == listed.job_hash
    assert plan(top)[0] == plan(axis)[0] == plan(listed)[0]
    plain = load_job(_job(tmp_path, MINIMAL))
    stockinette = load_job(_job(tmp_path, MINIMAL + 'stitch = ["stockinette"]\n'))
    assert plain.job_hash == stockinette.job_hash and plan(plain)[0] == plan(stockinette)[0]


KNOWN = "must be one of stockinette, stockinette_free, garter, rib, seed"


@pytest.mark.parametrize(
    ("line", "fragment"),
    [
        ('stitch = ["stockinette", "purl"]\n', f"grid.stitch = ['stockinette', 'purl']: 'purl' "
                                               f"is not a stitch: {KNOWN}"),
        ('stitch = "purl"\n', f"grid.stitch = 'purl': 'purl' is not a stitch: {KNOWN}"),
        ('stitch = ["garter", 3]\n', f"3 is not a stitch: {KNOWN}"),
        ('stitch = ["garter", "garter"]\n', "grid.stitch = ['garter', 'garter']: repeated values"),
        ("stitch = []\n", "grid.stitch = []: expected a stitch name or a non-empty list"),
    ],
)  # fmt: skip
def test_bad_stitch_axes_name_the_field_and_the_stitches(tmp_path, line, fragment):
    with pytest.raises(InputError) as e:
        load_job(_job(tmp_path, MINIMAL + line))
    assert fragment in str(e.value) and str(e.value).count("\n") == 0


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        (MINIMAL.replace("[grid]", 'stitch = "purl"\n[grid]'), f"stitch = 'purl': {KNOWN}"),
        (MINIMAL.replace("[grid]", 'stitch = ["garter"]\n[grid]'),
         "several stitches are a grid axis: [grid] stitch = [...]"),
        (MINIMAL.replace("[grid]", 'stitch = "garter"\n[grid]') + 'stitch = ["garter"]\n',
         "give the stitch in one place"),
    ],
)  # fmt: skip
def test_the_one_stitch_field_takes_one_name(tmp_path, text, fragment):
    with pytest.raises(InputError) as e:
        load_job(_job(tmp_path, text))
    assert fragment in str(e.value)


def test_unknown_stitch_via_cli_exits_2_before_any_compute(tmp_path):
    stderr = _run_refused(tmp_path, MINIMAL + 'stitch = ["stockinette", "purl"]\n')
    assert stderr.count("\n") == 1 and "grid.stitch" in stderr and KNOWN in stderr
