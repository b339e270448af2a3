"""Unit tier: a job's id is hashed from its id form (``service.id_forms``): every step of
the job format migrates up and down losslessly, every shipped job keeps the ids it had
before the forms were versioned, and an earlier results file still resumes. The settings
a task's id hashes (parameters, starts, protocol) have versioned forms of their own: jobs
using the later fields keep the task and series ids they had when those fields were
deleted from every dump instead."""

import copy
import shutil

import pytest

from knitsweep.config import Fidelity, StartSettings, StitchParams, SweepProtocol
from knitsweep.service.adaptive import Refiner
from knitsweep.service.id_forms import (
    ADAPTIVE_FORMS,
    FIDELITY_FORMS,
    FORM_VERSION,
    MIGRATIONS,
    PARAMS_FORMS,
    PROTOCOL_FORMS,
    STARTS_FORMS,
    TASK_FORMS,
    id_form,
    migrate_up,
)
from knitsweep.service.jobs import AdaptiveSettings, fidelity_form, load_job, plan

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
    ('jobs/phase_small.toml', 'e554074ab663132d', '3a2600d2625ffe82', 'de0a29b331dbded7'),
    ('tests/data/jobs/tiny.toml', '6cdd72bb5f539776', '43f8c26538190f30', '417c51d15c2f579e'),
    ('tests/data/jobs/tiny_adaptive.toml', 'f89071521ff529b2', '6dc22d11a8f7587f', 'dbfed6b46a829520'),
]  # fmt: skip
"""(job file, job hash, first point's id, first sweep's id) of every shipped job, as the
ids were before the job format's forms were versioned (main at abb5628). The patterns
job has since gained stockinette_free (a new job, new ids): its form of abb5628 is kept
in tests/data/jobs (``PATTERNS_BEFORE``)."""
PATTERNS_BEFORE = ('tests/data/jobs/patterns_k0.1_abb5628.toml', 'f44acfdf395afb3d',
                   'da017eefb5a084e4', '8de3dc7305e4d9f1')  # fmt: skip
"""The patterns job of abb5628: its free yarns then sampled their contacts by parameter."""


def test_a_job_of_free_yarns_hashes_where_their_samples_sit():
    """Free yarns now sample along the yarn by arclength by default ('auto'), so a job of
    patterns computes something new and gets a new hash; its stockinette (ansatz) tasks,
    which sample by parameter whatever the setting, keep their ids, and the same job
    asking for samples by parameter keeps its old hash."""
    from pathlib import Path

    path, job_hash, point_id, sweep_id = PATTERNS_BEFORE
    job = load_job(Path(__file__).resolve().parents[1] / path)
    points, sweeps = plan(job)
    assert points[0].params.stitch == "stockinette"
    assert (points[0].task_id, sweeps[0].task_id) == (point_id, sweep_id)
    assert job.job_hash != job_hash
    explicit = job.model_copy(update={"fidelity": job.fidelity.model_copy(
        update={"contact_sampling": "yarn_arclength"})})  # fmt: skip
    assert explicit.job_hash == job.job_hash
    by_parameter = job.model_copy(update={"fidelity": job.fidelity.model_copy(
        update={"contact_sampling": "parameter"})})  # fmt: skip
    assert by_parameter.job_hash == job_hash
    garter = next(p for p in points if p.params.stitch == "garter")
    again = next(p for p in plan(by_parameter)[0] if p.params == garter.params)
    assert again.task_id != garter.task_id


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
        ("[starts]\ncarry = true\n", "starts.carry"),
        ("[protocol]\nrest_tolerance_mJ = 1e-5\n", "protocol.rest_tolerance_mJ"),
        ("[starts]\nretries = 0\n", "starts.retries"),
        ("[starts]\nspread = 3\n", "starts.spread"),
        ('[fidelity]\ncontact_sampling = "arclength"\n', "fidelity.contact_sampling"),
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


IDS_OF_LATER_FIELDS = [
    ('', '', '7bc409199448f0aa', ('154183f3e9a4fc68', '763ec966b47d1865'), 'b7b99bdf35c022c9', '61cbd8f586cc22b0', ('05f6bf1b38adfad3', '3a725d400f3d6963')),
    ('stitch = "garter"\n[fidelity]\ncontact_sampling = "parameter"\n', '', 'e218b85a9beee6ea', ('b6610298a421d455', '8960e816bf915787'), '85253b2e297e827f', 'b17ee7b977358fd9', ('3f06f1eb030bf66a', 'e369dd0f4430090e')),
    ('[fidelity]\ncontact_sampling = "parameter"\n', "stitch = ['stockinette', 'rib']\n", 'a907d4e5beeb9e72', ('154183f3e9a4fc68', '763ec966b47d1865', '3f36eb1520cb3420', '8da9655bcc1d547a'), 'b7b99bdf35c022c9', '603adb6fb46292bd', ('05f6bf1b38adfad3', '3a725d400f3d6963', '9dbe336bdd721f5e', 'b7152b2aa83fe78e')),
    ('[starts]\ncount = 2\ncarry = true\n', '', 'a9e1ed2971a90c18', ('0dafa9b5a282fbe6', 'e8d617231db9a2eb'), '5ae9cee48d69f56b', 'd340765edd6c12f0', ('05f6bf1b38adfad3', '3a725d400f3d6963')),
    ('[protocol]\nrest_tolerance_mJ = 1e-5\n', '', '80866a62fe65aa3b', ('154183f3e9a4fc68', '763ec966b47d1865'), 'a77ae0b8f6771581', 'cd1f65de5a84d944', ('4d534d8cc4697d57', 'a061f7cefcda941b')),
    ('mode = "adaptive"\n', '', '0997b2919014a1a5', ('154183f3e9a4fc68', '763ec966b47d1865'), 'b7b99bdf35c022c9', '61cbd8f586cc22b0', ('05f6bf1b38adfad3', '3a725d400f3d6963')),
    ('mode = "adaptive"\nstitch = "garter"\n[fidelity]\ncontact_sampling = "parameter"\n[protocol]\nrest_tolerance_mJ = 1e-5\n', '', '15ae294abd820f4a', ('b6610298a421d455', '8960e816bf915787'), '9ae430e4d121039b', 'd5f5d7b26fbf47c3', ('ab9fc7ff96a3a5b7', 'bf337bb2a19979cb')),
    ('mode = "adaptive"\n[starts]\ncarry = true\n', '', '973c20c67fa7ac33', ('724de50c81d8716f', 'fc74bf68b4b00f88'), '6f1cf2d8863fe28f', '95c4f151e0baece8', ('05f6bf1b38adfad3', '3a725d400f3d6963')),
    ('[starts]\nretries = 0\n', '', '7e3c08c8efc3500c', ('dc5e8ad8c49fee35', '9d396206c11ba81b'), 'cdc366748982508d', '0e39ecddc9ed937c', ('05f6bf1b38adfad3', '3a725d400f3d6963')),
    ('[starts]\nspread = 3\n', '', '3ffc949dc8b16c92', ('e2d867a59bd68ed2', '96244a0dda331a62'), '79abda858af69b38', 'f45eb09441ae9b7d', ('05f6bf1b38adfad3', '3a725d400f3d6963')),
    ('[fidelity]\ncontact_sampling = "arclength"\n', '', 'f7ad0370d60a5489', ('d18f1241a907a40d', '4d1798f65f2ffa88'), 'c7e1ab83da785a1e', '484e9a6d42464867', ('1090b1f9d8215e7c', '605a7a023bf295b2')),
]  # fmt: skip
"""(top of the job file, [grid] lines, job hash, point ids, first and last sweep ids,
adaptive series keys) of small jobs using each later-added field of the task settings,
as main computed them when those fields were deleted from every dump (c6819a9; retries,
spread and contact_sampling, added since: 1112e92). The jobs of free yarns (garter, rib) ask
for contact samples by parameter, as every job then had them: the default ('auto') now
places a free yarn's along the yarn, which computes something else and hashes so."""


@pytest.mark.parametrize(("top", "grid", "job_hash", "point_ids", "first", "last", "series"),
                         IDS_OF_LATER_FIELDS, ids=lambda v: None)  # fmt: skip
def test_task_and_series_ids_of_every_later_field_are_kept(tmp_path, top, grid, job_hash,
                                                           point_ids, first, last, series):  # fmt: skip
    path = tmp_path / "j.toml"
    path.write_text(f'schema_version = 1\nname = "j"\n{top}[grid]\nL_mm = [11.0, 11.6]\n{grid}')
    job = load_job(path)
    points, sweeps = plan(job)
    assert job.job_hash == job_hash
    assert tuple(p.task_id for p in points) == point_ids
    assert (sweeps[0].task_id, sweeps[-1].task_id) == (first, last)
    assert tuple(sorted(Refiner(job).series)) == series


def test_the_task_forms_are_numbered_in_order():
    for forms in TASK_FORMS:
        assert [m.version for m in forms.migrations] == list(range(2, forms.version + 1))


TASK_DUMPS = [(PARAMS_FORMS, StitchParams()), (STARTS_FORMS, StartSettings()),
              (PROTOCOL_FORMS, SweepProtocol(shear_rest="held")),
              (FIDELITY_FORMS, Fidelity(contact_sampling="parameter")),
              (ADAPTIVE_FORMS, AdaptiveSettings())]  # fmt: skip
"""Each form's settings as the earliest form had them (the fidelity's 'auto' sampling is
resolved per stitch before it is hashed, ``jobs.fidelity_form``: 'parameter' for the
ansatz; a shear started upright, and a sweep that does not shear hashes its protocol so,
``id_forms.protocol_id_form``)."""


@pytest.mark.parametrize(("forms", "settings"), TASK_DUMPS, ids=lambda v: getattr(v, "what", ""))
def test_each_task_form_step_migrates_down_and_up_losslessly(forms, settings):
    """A dump writes every field (nothing is deleted any more); each step's down form of
    the defaults lacks its field and its up form is the dump again."""
    full = settings.model_dump(mode="json")
    assert set(full) == set(type(settings).model_fields)
    for m in forms.migrations:
        lower = m.down(copy.deepcopy(full))
        assert lower is not None and lower != full
        assert m.up(lower) == full
    assert forms.migrate_up(forms.id_form(full)) == full


@pytest.mark.parametrize(
    ("forms", "settings", "kept"),
    [
        (PARAMS_FORMS, StitchParams(stitch="garter"), "stitch"),
        (STARTS_FORMS, StartSettings(carry=True), "carry"),
        (STARTS_FORMS, StartSettings(retries=0), "retries"),
        (STARTS_FORMS, StartSettings(spread=3), "spread"),
        (FIDELITY_FORMS, Fidelity(contact_sampling="arclength"), "contact_sampling"),
        (PROTOCOL_FORMS, SweepProtocol(rest_tolerance_mJ=1e-5), "rest_tolerance_mJ"),
        (PROTOCOL_FORMS, SweepProtocol(), "shear_rest"),
        (ADAPTIVE_FORMS, AdaptiveSettings(last_crossing=True), "last_crossing"),
    ],
)
def test_settings_using_a_later_field_keep_it_in_their_id_form(forms, settings, kept):
    full = settings.model_dump(mode="json")
    assert kept in forms.id_form(full)
    assert forms.migrate_up(forms.id_form(full)) == full
    default = dict(TASK_DUMPS)[forms]
    assert kept not in forms.id_form(default.model_dump(mode="json"))


def test_the_fidelity_of_a_task_hashes_its_stitchs_sampling():
    """'auto' is 'parameter' for the ansatz (ids as before the setting) and
    'yarn_arclength' for a free yarn (as if asked for)."""
    auto = Fidelity()
    assert fidelity_form(auto, "stockinette") == FIDELITY_FORMS.id_form(
        Fidelity(contact_sampling="parameter").model_dump(mode="json")
    )
    for stitch in ("stockinette_free", "garter", "rib", "seed"):
        assert fidelity_form(auto, stitch) == FIDELITY_FORMS.id_form(
            Fidelity(contact_sampling="yarn_arclength").model_dump(mode="json")
        )


def _stored_ids(path):
    from conftest import stored_meta

    return {kind: set(stored_meta(path, kind)) for kind in ("points", "sweeps")}


def test_the_schema2_file_holds_the_task_ids_of_today(data_dir):
    points, sweeps = plan(load_job(data_dir / "jobs" / "tiny.toml"))
    assert _stored_ids(data_dir / "schema2_tiny.h5") == {
        "points": {p.task_id for p in points},
        "sweeps": {s.task_id for s in sweeps},
    }


def test_a_schema3_file_from_before_the_task_forms_resumes_with_nothing_to_compute(
    data_dir, tmp_path
):
    """The tiny job's file as main c6819a9 wrote it (results schema 3, the task settings'
    later fields then deleted from every dump): it holds the task ids of today and a run
    into it finds every task done."""
    import h5py

    from knitsweep import service

    old = tmp_path / "old.h5"
    shutil.copy(data_dir / "schema3_tiny_c6819a9.h5", old)
    with h5py.File(old, "r") as f:
        assert int(f.attrs["schema_version"]) == 3
        stored = str(f.attrs["job_hash"])
    tiny = data_dir / "jobs" / "tiny.toml"
    points, sweeps = plan(load_job(tiny))
    assert load_job(tiny).job_hash == stored
    assert _stored_ids(old) == {"points": {p.task_id for p in points},
                                "sweeps": {s.task_id for s in sweeps}}  # fmt: skip
    summary = service.run(tiny, old, executor="serial", show_progress=False)
    assert summary.skipped == summary.total == 6 and summary.exit_code == 0


def test_a_shear_started_from_its_relaxed_skew_is_a_new_task_and_nothing_else_is(tmp_path):
    """protocol.shear_rest: the shear sweeps of a job at the default ('relaxed') hash anew
    (they compute something else than before), its x sweeps, points and a job without a
    shear keep their ids; 'held' is the shear as before."""

    def planned(top: str, directions: str):
        path = tmp_path / "j.toml"
        path.write_text(
            f'schema_version = 1\nname = "j"\nstitch = "garter"\n'
            f"directions = {directions}\n{top}[grid]\nL_mm = [11.0, 11.6]\n"
        )
        job = load_job(path)
        points, sweeps = plan(job)
        return job, [p.task_id for p in points], {(s.point_id, s.direction): s.task_id
                                                  for s in sweeps}  # fmt: skip

    both = '["x", "shear"]'
    relaxed, held = planned("", both), planned('[protocol]\nshear_rest = "held"\n', both)
    assert relaxed[0].protocol.shear_rest == "relaxed" and relaxed[0].job_hash != held[0].job_hash
    assert relaxed[1] == held[1]
    for key, sid in relaxed[2].items():
        assert (sid == held[2][key]) == (key[1] == "x")
    x_only = planned("", '["x"]'), planned('[protocol]\nshear_rest = "relaxed"\n', '["x"]')
    assert x_only[0][0].job_hash == x_only[1][0].job_hash
    assert migrate_up(id_form(held[0].full_form())) == held[0].full_form()
    assert migrate_up(id_form(relaxed[0].full_form())) == relaxed[0].full_form()
