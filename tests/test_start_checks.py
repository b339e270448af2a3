"""A start whose hard cores overlap is refused before any compute by every command that
takes a state, for every stitch (the knit/purl patterns too): one ``error:`` line naming
the segment of the cell and the image where the cores overlap, exit code 2 (README
"Bad input"; ``CellModel.check_start``)."""

import pytest
from conftest import TINY, run_knitsweep

from knitsweep.config import StitchParams
from knitsweep.errors import InputError
from knitsweep.formats import write_state
from knitsweep.model import CellModel

STITCHES = ["stockinette", "stockinette_free", "garter", "rib", "seed"]


def one_error_line(proc, fragment):
    """Exit 2 and one ``error:`` line holding ``fragment``, no traceback; beside it at most
    the notice that the kernels compile first (a cold cache: the check needs the stitch's
    geometry kernel)."""
    lines = [line for line in proc.stderr.strip().splitlines()
             if not line.startswith("compiling numerical kernels")]  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert fragment in lines[0] and "Traceback" not in proc.stderr, proc.stderr


def squeezed(stitch: str, tmp_path):
    """The stitch's first shipped start with both periods at 60 %: its cores overlap
    (min zeta -0.5 ... -0.8)."""
    model = CellModel(StitchParams(stitch=stitch))
    x = model.stitch.start(1).copy()
    x[-2:] *= 0.6
    assert model.min_zeta(x) < -0.3
    path = tmp_path / f"{stitch}_overlapping.dat"
    write_state(path, x)
    return path


@pytest.mark.parametrize("stitch", STITCHES)
def test_check_start_names_segment_and_image_for_every_stitch(stitch, tmp_path):
    model = CellModel(StitchParams(stitch=stitch))
    x = model.stitch.start(1)
    assert model.check_start(x) == pytest.approx(model.min_zeta(x), rel=1e-12)
    bad = x.copy()
    bad[-2:] *= 0.6
    with pytest.raises(InputError, match=r"segment \d+ of the cell and segment \d+ of its image "
                                         r"\(-?\d, -?\d\)") as info:  # fmt: skip
        model.check_start(bad, "state file s.dat")
    assert str(info.value).startswith("state file s.dat = overlapping yarn: min zeta -")
    assert f"{model.min_zeta(bad):.3g}" in str(info.value)


@pytest.mark.parametrize("stitch", STITCHES)
def test_energy_refuses_an_overlapping_state(stitch, tmp_path):
    state = squeezed(stitch, tmp_path)
    out = run_knitsweep("energy", "--stitch", stitch, "--state", state, "--json")
    one_error_line(out, "overlapping yarn")
    assert str(state) in out.stderr and "of its image (" in out.stderr and out.stdout == ""


@pytest.mark.parametrize("stitch", ["stockinette", "garter"])
def test_relax_refuses_an_overlapping_state_before_relaxing(stitch, tmp_path):
    state = squeezed(stitch, tmp_path)
    out = run_knitsweep("relax", "--stitch", stitch, "--state", state, "--preset", "draft",
                        "--out", tmp_path / "relaxed.dat", timeout=120)  # fmt: skip
    one_error_line(out, "overlapping yarn")
    assert "segment" in out.stderr and not (tmp_path / "relaxed.dat").exists()


@pytest.mark.parametrize("volumes", [False, True])
def test_render_refuses_an_overlapping_state(tmp_path, volumes):
    state = squeezed("rib", tmp_path)
    png = tmp_path / "rib.png"
    args = ["render", "--stitch", "rib", "--state", state, "--out", png]
    out = run_knitsweep(*args, *(["--contact-volumes", "--volume-points", "1024"] * volumes))
    one_error_line(out, "overlapping yarn")
    assert not png.exists()


def test_shipped_starts_pass_the_check():
    for stitch in STITCHES:
        model = CellModel(StitchParams(stitch=stitch))
        for i in range(model.stitch.n_starts):
            assert model.check_start(model.stitch.start(i + 1)) > 0.05, (stitch, i)


@pytest.fixture
def damaged_garter_start(monkeypatch):
    """Garter's shipped Init_3 with both periods at 60 %, as a damaged install would ship it."""
    from knitsweep.stitches.base import Stitch

    start = Stitch.start

    def damaged(self, index=1):
        x = start(self, index)
        if self.name == "garter" and index == 3:
            x = x.copy()
            x[-2:] *= 0.6
        return x

    monkeypatch.setattr(Stitch, "start", damaged)


def test_run_refuses_a_shipped_start_that_overlaps_before_compute(damaged_garter_start, tmp_path):
    """``run`` checks every stitch's shipped starts (here garter's Init_3, squeezed by a
    damaged install) before any compute: nothing is written."""
    from knitsweep import service

    job = tmp_path / "garter.toml"
    job.write_text(TINY.read_text().replace("[grid]", '[grid]\nstitch = "garter"'))
    out = tmp_path / "g.h5"
    with pytest.raises(InputError, match=r"shipped start Init_3(\.dat)? of garter = overlapping "
                                         r"yarn: .* segment \d+ of its image"):  # fmt: skip
        service.run(job, out, executor="serial", show_progress=False)
    assert not out.exists()


def test_a_stitch_added_on_resume_has_its_starts_checked(
    damaged_garter_start, monkeypatch, tmp_path, tiny_reference
):
    """A job grown by a stitch runs into its old file; the new stitch's shipped starts are
    checked before compute (here garter's Init_3, squeezed), the file left as it was; the
    stitches already in the file are not checked again."""
    import shutil

    from knitsweep import service
    from knitsweep.service import runs
    from knitsweep.service.jobs import load_job

    out = tmp_path / "t.h5"
    shutil.copy(tiny_reference, out)
    before = out.read_bytes()
    assert runs.stitches_in_file(out) == ("stockinette",)
    grown = tmp_path / "grown.toml"
    grown.write_text(
        TINY.read_text().replace("[grid]", '[grid]\nstitch = ["stockinette", "garter"]')
    )
    with pytest.raises(InputError, match=r"shipped start Init_3(\.dat)? of garter = overlapping"):
        service.run(grown, out, executor="serial", show_progress=False)
    assert out.read_bytes() == before
    checked = []
    monkeypatch.setattr("knitsweep.relax.zero_force.check_shipped_starts",
                        lambda stitches, fidelity=None: checked.append(stitches))  # fmt: skip
    runs.check_job_starts(load_job(grown), already=runs.stitches_in_file(out))
    assert checked == [("garter",)]
