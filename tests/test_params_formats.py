"""Unit tier: parameter validation and the authors' file formats."""

import math

import numpy as np
import pytest
from conftest import SHIPPED, golden_cases
from pydantic import ValidationError

from knitsweep.config import Fidelity, InputError, StitchParams
from knitsweep.errors import describe_validation_error
from knitsweep.formats import read_authors_config, read_state, shipped_state, write_state


def _message(**kw):
    with pytest.raises(ValidationError) as e:
        StitchParams(**kw)
    return describe_validation_error(e.value)


def test_the_default_stitch_is_left_out_of_what_ids_hash_and_files_store():
    """Stockinette parameters' id form (what task ids hash and task attributes store) has
    no stitch field, as before stitches were a choice; the dump writes it, and from_flat
    reads either back."""
    from knitsweep.service.jobs import params_form

    p = StitchParams(L_mm=11.0)
    assert "stitch" not in params_form(p) and p.model_dump()["stitch"] == "stockinette"
    assert StitchParams.from_flat(params_form(p)) == StitchParams.from_flat(p.model_dump()) == p
    assert params_form(StitchParams(L_mm=11.0, stitch="garter"))["stitch"] == "garter"


def test_defaults_are_the_papers_table_1():
    ip = StitchParams().internal()
    assert ip.bend == pytest.approx(0.045)  # B/2 with B = 90 mN mm^2
    assert ip.k == pytest.approx(6e-4)  # 0.6 mN/mm^2 in N/mm^2
    assert ip.reg == pytest.approx(0.002)
    assert (ip.p, ip.r, ip.rc, ip.twist_bound) == (2.4, 0.74, 0.325, 0.9)


@pytest.mark.parametrize(
    ("kw", "expected"),
    [
        ({"p": 1.0}, "p = 1.0: must satisfy 1 < p <= 20"),
        ({"r_core_mm": 0.74}, "r_core_mm = 0.74: must satisfy 0 < r_core_mm < r_mm = 0.74"),
        (
            {"k_mN_per_mm2": -0.1},
            "k_mN_per_mm2 = -0.1: must be a finite number in [1e-06, 10000] mN/mm^2",
        ),
        ({"B_mN_mm2": 0.0}, "B_mN_mm2 = 0.0: must be a finite number in [0.001, 1e+06] mN mm^2"),
        ({"L_mm": 1e300}, "L_mm = 1e+300: must be a finite number in (0, 100] mm"),
        ({"L_mm": 1e308}, "L_mm = 1e+308: must be a finite number in (0, 100] mm"),
        (
            {"k_mN_per_mm2": 1e300},
            "k_mN_per_mm2 = 1e+300: must be a finite number in [1e-06, 10000] mN/mm^2",
        ),
        (
            {"B_mN_mm2": 1e300},
            "B_mN_mm2 = 1e+300: must be a finite number in [0.001, 1e+06] mN mm^2",
        ),
        ({"r_mm": 1e300}, "r_mm = 1e+300: must be a finite number in [0.01, 10] mm"),
        (
            {"regularization_mN_mm4": 1e300},
            "regularization_mN_mm4 = 1e+300: must be a finite number in [0, 10000] mN mm^4",
        ),
        ({"p": 1e300}, "p = 1e+300: must satisfy 1 < p <= 20"),
        ({"L_mm": "11.6"}, "L_mm = '11.6': Input should be a valid number"),
        ({"k_mN_per_mm2": True}, "k_mN_per_mm2 = True: Input should be a valid number"),
        ({"L_mm_": 11.6}, "L_mm_: unknown field"),
        ({"L_mm": math.inf}, "L_mm = inf: Input should be a finite number"),
        ({"r_mm": math.nan}, "r_mm = nan: Input should be a finite number"),
        (
            {"regularization_mN_mm4": -1.0},
            "regularization_mN_mm4 = -1.0: must be a finite number in [0, 10000] mN mm^4",
        ),
        ({"twist_bound": 1.0}, "twist_bound = 1.0: must be in [-1, 1)"),
        ({"pattern": 1.0}, "pattern: unknown field"),
        (
            {"stitch": "cable"},
            "stitch = 'cable': must be one of stockinette, stockinette_free, garter, rib, seed, "
            "or a knit/purl chart as chart:KKPP",
        ),
        ({"stitch": 1.0}, "stitch = 1.0: Input should be a valid string"),
    ],
)
def test_validation_names_field_value_and_range(kw, expected):
    assert _message(**kw) == expected


def test_unknown_fields_get_a_suggestion():
    with pytest.raises(ValidationError) as e:
        StitchParams(L_mn=11.6)
    assert (
        describe_validation_error(e.value, StitchParams)
        == "L_mn: unknown field (did you mean 'L_mm'?)"
    )


def test_fidelity_validation():
    with pytest.raises(ValidationError) as e:
        Fidelity(samples_per_segment=1)
    assert describe_validation_error(e.value).startswith("samples_per_segment = 1:")
    with pytest.raises(ValidationError):
        Fidelity(images="box")


def test_models_are_frozen():
    with pytest.raises(ValidationError):
        StitchParams().L_mm = 12.0


def test_init_round_trip(tmp_path, init1):
    path = tmp_path / "state.dat"
    write_state(path, init1)
    np.testing.assert_array_equal(read_state(path), init1)
    assert len(path.read_text().splitlines()) == 30


# SHA-256 of the authors' reference/init/Init_*.dat (sabetta/jammed-knits)
AUTHORS_INIT_SHA256 = {
    1: "39d3699e5c6887c44f6adacdc269888202c6be318c38ca30f3da20db74e7742b",
    2: "94abd063791770489e7458f0468b0edbeb623885db2d66635bda55410cf0a78f",
    3: "38b211e760862af81528390982bfb47b56d8e8496bc549765c1caab701baae15",
    4: "5dee4910b794f7345e2a694229bedfe02bffdf34853f93258ad805bd1fdedab8",
    5: "38b211e760862af81528390982bfb47b56d8e8496bc549765c1caab701baae15",
    6: "5dee4910b794f7345e2a694229bedfe02bffdf34853f93258ad805bd1fdedab8",
    7: "39d3699e5c6887c44f6adacdc269888202c6be318c38ca30f3da20db74e7742b",
}


def test_shipped_states_are_the_authors():
    import hashlib

    for i, digest in AUTHORS_INIT_SHA256.items():
        assert hashlib.sha256((SHIPPED / f"Init_{i}.dat").read_bytes()).hexdigest() == digest
    for case, i in (("init1_paper", 1), ("init2_paper", 2), ("init3_paper", 3)):
        x = next(c["x"] for c in golden_cases() if c["name"] == case)
        np.testing.assert_array_equal(shipped_state(i), x)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("1\n2\n", "expected 30 numbers for a stockinette state, found 2"),
        ("1\n" * 29 + "abc\n", "line 30: 'abc' is not a number"),
        ("1\n" * 29 + "nan\n", "line 30: 'nan' is not finite"),
        ("1\n" * 29 + "-2\n", "must be > 0"),
    ],
)
def test_bad_state_files(tmp_path, text, fragment):
    path = tmp_path / "bad.dat"
    path.write_text(text)
    with pytest.raises(InputError, match=fragment):
        read_state(path)


def test_authors_config_units(data_dir):
    cfg = read_authors_config(data_dir / "sampleconfigfile.dat")
    assert cfg.params.L_mm == 11.6  # '*stitch_length 11.6 mm' (trailing unit word)
    assert cfg.params.B_mN_mm2 == pytest.approx(90.0)  # bending_modulus is B/2 in N mm^2
    assert cfg.params.k_mN_per_mm2 == pytest.approx(0.1)  # contact_rigidity is k in N/mm^2
    assert cfg.params.internal().bend == pytest.approx(0.045, rel=1e-15)
    assert cfg.params.internal().k == pytest.approx(1e-4, rel=1e-15)
    assert cfg.samples_per_segment == 10
    assert cfg.sweep_direction == "x"
    assert cfg.step_size_mm == 0.01
    assert cfg.init_file == "1"


def test_authors_config_unknown_key_is_named(tmp_path):
    path = tmp_path / "c.dat"
    path.write_text("comment lines are ignored\n*stitch_length 11\n*stitchlength 12\n")
    with pytest.raises(InputError, match=r"line 3: unknown key '\*stitchlength'"):
        read_authors_config(path)


def test_authors_config_bad_value_is_named(tmp_path):
    path = tmp_path / "c.dat"
    path.write_text("*core_radius 0.9\n")
    with pytest.raises(InputError, match=r"r_core_mm = 0\.9"):
        read_authors_config(path)
