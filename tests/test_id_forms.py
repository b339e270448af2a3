"""Unit tier: a job's id is hashed from its id form (``service.id_forms``): every step of
the job format migrates up and down losslessly, every shipped job keeps the ids it had
before the forms were versioned, and an earlier results file still resumes."""

import copy
import shutil

import pytest

from knitsweep.service.id_forms import FORM_VERSION, MIGRATIONS, id_form, migrate_up
from knitsweep.service.jobs import load_job, plan

IDS_BEFORE = [
    ('jobs/adaptive_k0.1.toml', '006c3b907e2aa31a', '3190d5abd8ca4252', '94467af5906a59dd'),
    ('jobs/adaptive_kB.toml', '4c9f1cfe614f6c7c', '69f1e775fb162b88', '1877fde0608f3c36'),
    ('jobs/adaptive_kB_fine.toml', '9dd6ed5c835decd6', '69f1e775fb162b88', '1877fde0608f3c36'),
    ('jobs/demo.toml', 'b9f39d31e58f548d', '0ad5a06cf18daf24', '41829fd6ed0c25cb'),
    ('jobs/paper_Btrans_adaptive.toml', 'c9b417aaf0136306', '69f1e775fb162b88', '1877fde0608f3c36'),
    ('jobs/paper_k0.1_L_sweep.toml', '9770575e25c59283', '3190d5abd8ca4252', '061d2957f1e12c54'),
    ('jobs/paper_linear_regime_L10.7.toml', '0522621bb057b0ae', '0652d24481b5ea8d', '747bd0424ecdecd7'),
    ('jobs/paper_packing_fraction.toml', '267cbe335c2762c4', '3190d5abd8ca4252', '061d2957f1e12c54'),
    ('jobs/paper_phase_kB.toml', '676ddade0d793907', '69f1e775fb162b88', '786d7b47ee03aa01'),
    ('jobs/paper_radius_fixed_ratio.toml', '3835f536782bbb07', '271334bde5ce7919', '8936fd448f20e74e'),
    ('jobs/paper_sigma0_k0.6.toml', 'b71fe8a3dd4f703d', '0158793def7d250e', 'e80791691e261d44'),
    ('jobs/paper_sweeps_B.toml', '500da6a65fd09ba4', '14786a46ffb12304', '22835f36bdafbe53'),
    ('jobs/paper_sweeps_k.toml', 'a6896e49f98332db', 'd449b00b27f452d3', 'f69c53b456bb570f'),
    ('jobs/paper_sweeps_rcore.toml', 'd5f4216031cc534f', '3cb3737ee0f2c46e', 'a1a804521a10d1cf'),
    ('jobs/paper_table_s2_x.toml', 'ebe8782fead40198', 'f971a3bbf81c72bf', 'bf856816e33910e4'),
    ('jobs/paper_table_s2_y.toml', 'fadd626c14284a21', 'a455d093c5eeeffa', '945e03235077e813'),
    ('jobs/paper_table_s2_y_k1.5.toml', '19f4f45e407ad5c6', '7c5e0bed1e4248dd', '8bc8895543c5538c'),
    ('jobs/paper_table_s4.toml', '8660892faedec447', '73ff07d3c7408728', 'bd1339ae1b527be9'),
    ('jobs/paper_table_s4_k0.001.toml', 'c044cd56c4f9426f', '6ee1d48dc9978e59', '6a102351ccc8765a'),
    ('jobs/paper_table_s4_k0.001_paper_preset.toml', 'e7d89996abcae1f6', '9ad49288e24a84fb', '978399acd28f501b'),
    ('jobs/paper_table_s4_more.toml', 'ce0c8ac1485893b8', 'd92cad96b9149817', '19bbb71b63efa920'),
    ('jobs/paper_table_s4_wide.toml', '43170e294bbb15ba', 'c279a8409f717635', 'aa743069203e15b4'),
    ('jobs/paper_z_strain.toml', '3b948ba153365bd3', '3190d5abd8ca4252', '0cf41a08dd79d8e8'),
    ('tests/data/jobs/patterns_k0.1_abb5628.toml', 'f44acfdf395afb3d', 'da017eefb5a084e4', '8de3dc7305e4d9f1'),
    ('jobs/phase_small.toml', 'e554074ab663132d', '3a2600d2625ffe82', 'de0a29b331dbded7'),
    ('tests/data/jobs/tiny.toml', '6cdd72bb5f539776', '43f8c26538190f30', '417c51d15c2f579e'),
    ('tests/data/jobs/tiny_adaptive.toml', 'f89071521ff529b2', '6dc22d11a8f7587f', 'dbfed6b46a829520'),
]  # fmt: skip
"""(job file, job hash, first point's id, first sweep's id) of every shipped job, as the
ids were before the job format's forms were versioned (main at abb5628). The patterns
job has since gained stockinette_free (a new job, new ids): its form of abb5628 is kept
in tests/data/jobs."""


@pytest.mark.parametrize(("path", "job_hash", "point_id", "sweep_id"), IDS_BEFORE,
                         ids=[r[0].split("/")[-1] for r in IDS_BEFORE])  # fmt: skip
def test_every_shipped_job_keeps_its_ids(path, job_hash, point_id, sweep_id):
    from pathlib import Path

    job = load_job(Path(__file__).resolve().parents[1] / path)
    points, sweeps = plan(job)
    assert (job.job_hash, points[0].task_id, sweeps[0].task_id) == (job_hash, point_id, sweep_id)
    assert migrate_up(job.canonical()) == job.full_form()


def test_the_forms_are_numbered_in_order():
    assert [m.version for m in MIGRATIONS] == list(range(2, FORM_VERSION + 1))


def _full(tmp_path, extra=""):
    path = tmp_path / "j.toml"
    path.write_text('schema_version = 1\nname = "j"\n[grid]\nL_mm = [11.0, 11.6]\n' + extra)
    return load_job(path).full_form()


@pytest.mark.parametrize("migration", MIGRATIONS, ids=lambda m: f"v{m.version}")
def test_each_step_migrates_down_and_up_losslessly(migration, tmp_path):
    full = _full(tmp_path)
    lower = migration.down(copy.deepcopy(full))
    assert lower is not None and lower != full  # a plain job is of every earlier form
    assert migration.up(lower) == full


@pytest.mark.parametrize(
    ("extra", "kept"),
    [
        ('stitch = "garter"\n', "stitch"),
        ('stitch = ["stockinette", "rib"]\n', "grid.stitch"),
        ('r_mm = [0.7, 0.74]\nr_core_mm = "0.44 * r_mm"\n', "grid.ties"),
        ('k_mN_per_mm2 = [0.1, 0.2]\nzip = [["L_mm", "k_mN_per_mm2"]]\n', "grid.zip"),
        ("[store]\npacking_fraction = true\n", "store.packing_fraction"),
    ],
)
def test_a_job_using_a_later_field_keeps_it_in_its_id(tmp_path, extra, kept):
    full = _full(tmp_path, extra)
    d = id_form(full)
    where = d
    for key in kept.split("."):
        assert key in where, kept
        where = where[key]
    assert migrate_up(d) == full


def test_an_earlier_results_file_resumes_with_nothing_to_compute(data_dir, tmp_path):
    """The schema-2 file of the tiny job (written before the forms were versioned): its
    job hash is the job's; merged into a file of this schema (the way an earlier schema
    resumes) a run finds every task done."""
    import h5py

    from knitsweep import service

    old = tmp_path / "old.h5"
    shutil.copy(data_dir / "schema2_tiny.h5", old)
    with h5py.File(old, "r") as f:
        stored = str(f.attrs["job_hash"])
    tiny = data_dir / "jobs" / "tiny.toml"
    assert load_job(tiny).job_hash == stored
    new = tmp_path / "new.h5"
    service.merge(new, [old])
    summary = service.run(tiny, new, executor="serial", show_progress=False)
    assert summary.skipped == summary.total == 6 and summary.exit_code == 0
