"""The phase-diagram figures and the stitch renderer: every figure written and
readable, skipped figures say why, partial files are labelled, bad input is refused."""

import json
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from conftest import SHIPPED
from results_factory import write_results

from knitsweep.config import InputError, StitchParams
from knitsweep.formats import shipped_state, write_state
from knitsweep.report import phase_diagram, reduce_results
from knitsweep.report.figures import FIGURES

MIN_BYTES = 20_000


def knitsweep(*args):
    return subprocess.run([sys.executable, "-m", "knitsweep", *args], capture_output=True,
                          text=True, timeout=300)  # fmt: skip


def assert_image(path: Path, min_bytes: int = MIN_BYTES) -> np.ndarray:
    from matplotlib.image import imread

    assert path.is_file(), path
    assert path.stat().st_size > min_bytes, (path, path.stat().st_size)
    image = imread(path)
    assert image.ndim == 3 and image.shape[0] > 200 and image.shape[1] > 200
    assert float(np.std(image[..., :3])) > 0.02  # not a blank canvas
    return image


@pytest.fixture(scope="module")
def tiny(tiny_reference):
    return tiny_reference


@pytest.fixture(scope="module")
def synthetic_report(tmp_path_factory):
    d = tmp_path_factory.mktemp("syn")
    return phase_diagram(write_results(d / "synthetic.h5"), d / "pd")


def test_every_figure_is_written(synthetic_report):
    outcomes = {f.name: f for f in synthetic_report.figures}
    assert set(outcomes) == set(FIGURES)
    for name, f in outcomes.items():
        if name == "figP_patterns.png":  # one stitch here; tests/test_figure_layout.py has two
            assert f.reason == "needs sweeps of two or more stitch patterns"
            continue
        if name == "figI_inplane.png":  # x and y here; tests/test_figure_layout.py has biaxial
            assert f.reason == ("needs sweeps along a biaxial or shear path (directions "
                                "biaxial, strip_x, strip_y, shear, shear_free)")  # fmt: skip
            continue
        assert f.reason is None, (name, f.reason)
        assert_image(f.path)
        assert f.line == f"wrote {f.path}"


def test_figures_drawn_by_forked_helpers_are_the_same_bytes(synthetic_report, monkeypatch):
    from knitsweep.report.figures import render_figures
    from knitsweep.util import forking as processes

    red = synthetic_report.reduction
    alone = [(name, files) for name, _, files in render_figures(red, workers=1)]
    monkeypatch.setattr(processes, "fork_workers", lambda limit=4: 2)  # even on one core
    assert [(name, files) for name, _, files in render_figures(red)] == alone


def test_skipped_figures_say_why(tmp_path):
    path = write_results(tmp_path / "one_k.h5", ks=(0.1,), contact_forces=False)
    out = knitsweep("phase-diagram", str(path), "--out", str(tmp_path / "pd"))
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert ("fig4b_deltaL_vs_k.png skipped: needs ≥ 2 values of k with a transition "
            "(and a jammed-regime fit) in one series") in lines  # fmt: skip
    assert ("fig6h_contact_force_ratio.png skipped: the results file stores no contact forces "
            "(set [store] contact_forces = true in the job)") in lines  # fmt: skip
    assert not (tmp_path / "pd" / "fig4b_deltaL_vs_k.png").exists()
    # with one series, the phase diagram is the regime strip along L/r
    assert_image(tmp_path / "pd" / "fig4c_phase_diagram.png")
    assert (
        sum(line.startswith("wrote ") and line.endswith(".png") for line in lines)
        == len(FIGURES) - 4  # and the patterns figure (one stitch), the in-plane one (x, y)
    )


def test_figures_without_sweeps_are_skipped(tmp_path):
    path = write_results(tmp_path / "p.h5", ks=(0.1,))
    with h5py.File(path, "a") as f:
        del f["sweeps"]
        f.create_group("sweeps")
    report = phase_diagram(path, tmp_path / "pd")
    skipped = {f.name for f in report.figures if f.path is None}
    assert {"fig1b_stress_strain.png", "fig3_energy_gaps.png", "fig4c_phase_diagram.png",
            "fig5b_area_strain_y.png", "fig6g_thickness_strain_x.png"} <= skipped  # fmt: skip
    assert "fig5a_aspect_ratio.png" not in skipped  # points alone suffice
    assert all(f.line.startswith(f"{f.name} skipped: ") for f in report.figures if f.path is None)


def test_partial_file_is_labelled_in_figures(tmp_path):
    from knitsweep.report.fig_energy import fig3_energy_gaps
    from knitsweep.report.plotting import style

    path = write_results(tmp_path / "run.h5", ks=(0.1,), run_status="running")
    red = reduce_results(path)
    with style():
        fig = fig3_energy_gaps(red, [])
    assert fig.get_suptitle().startswith("PARTIAL RESULTS (run_status 'running'")
    report = phase_diagram(path, tmp_path / "pd")
    assert report.lines()[0].startswith("PARTIAL")
    assert all(f.path is not None for f in report.figures if f.name.startswith("fig3"))


def test_tiny_job_figures_via_cli(tiny, tmp_path):
    out = knitsweep("phase-diagram", str(tiny), "--out", str(tmp_path / "pd"))
    assert out.returncode == 0, out.stderr
    written = [Path(line.removeprefix("wrote ")) for line in out.stdout.splitlines()
               if line.startswith("wrote ") and line.endswith(".png")]  # fmt: skip
    assert len(written) >= 10
    for path in written:
        assert_image(path, 10_000)


def test_figures_use_agg_without_pyplot(synthetic_report):
    code = ("import sys; from knitsweep.report import phase_diagram; "
            f"phase_diagram({str(synthetic_report.reduction.path)!r}, "
            f"{str(synthetic_report.reduction.path.parent / 'again')!r}); "
            "print('matplotlib.pyplot' in sys.modules)")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300, env={"MPLBACKEND": "TkAgg", "PATH": ""})  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


# ---- knitsweep render ----------------------------------------------------------------


def test_render_point_and_sweep(tiny, tmp_path):
    from knitsweep.store.read import iter_entries

    entries = list(iter_entries(tiny))
    point = next(e.task_id for e in entries if e.kind == "points")
    sweep = next(e.task_id for e in entries if e.kind == "sweeps")
    out = knitsweep("render", "--results", str(tiny), "--task", point[:6], "--out",
                    str(tmp_path / "p.png"), "--pixels", "320")  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == f"wrote {tmp_path / 'p.png'}: stockinette, zero-force state"
    assert_image(tmp_path / "p.png", 10_000)
    out = knitsweep("render", "--results", str(tiny), "--task", sweep, "--out",
                    str(tmp_path / "s.png"), "--pixels", "320", "--radius", "0.5")  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert_image(tmp_path / "s.png", 10_000)
    out = knitsweep("render", "--results", str(tiny), "--task", sweep, "--strain-step", "3",
                    "--out", str(tmp_path / "s3.png"))  # fmt: skip
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == [
        f"error: sweep {sweep} stores no states or control points; only step 0 can be drawn "
        "(set [store] states = true or geometry = true in the job to keep every step)"
    ]


def test_render_stored_states_and_control_points(tmp_path):
    from knitsweep.model import CellModel
    from knitsweep.report.render import render

    path = write_results(tmp_path / "st.h5", ks=(0.1,), not_knittable_L=None)
    x = shipped_state(1)
    params = StitchParams(r_mm=0.5, r_core_mm=0.22)
    with h5py.File(path, "a") as f:
        g = f["sweeps/s0.1_22_x"]
        n = len(g["strain"])
        g["states"][...] = np.tile(x, (n, 1))  # (the factory stores states)
        g["a_x"][...] = x[28]
        g["a_y"][...] = x[29]
        h = f["sweeps/s0.1_22_y"]
        h["control_points"] = np.tile(CellModel(params).control_points(x), (n, 1, 1, 1))
        h["a_x"][...] = x[28]
        h["a_y"][...] = x[29]
    for task in ("s0.1_22_x", "s0.1_22_y"):
        out, stitch = render(tmp_path / f"{task}.png", results=path, task=task, step=5,
                             width_px=300)  # fmt: skip
        assert "step 5" in stitch.label and stitch.r_mm == 0.5
        assert stitch.control_points.shape == (8, 6, 3)
        assert_image(out, 8_000)


def test_render_state_file(tmp_path):
    state = tmp_path / "s.dat"
    write_state(state, shipped_state(1))
    out = knitsweep("render", "--state", str(state), "--L", "11.6", "--out",
                    str(tmp_path / "st.pdf"), "--cells", "2", "--side", "back",
                    "--pixels", "400")  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "st.pdf").stat().st_size > 10_000


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--state", "S", "--results", "R"], "give either"),
        (["--state", "S", "--starts", "2"], "--preset and --starts apply to a relaxation"),
        (["--preset", "nosuch"], "preset"),
        (["--results", "R"], "--results needs --task"),
        (["--state", "S", "--strain-step", "2"], "--strain-step applies to a sweep"),
        (["--results", "R", "--task", "p", "--L", "11"], "a results file holds its own parameters"),
        (["--state", "S", "--radius", "0"], "radius = 0.0: must be > 0"),
        (["--state", "S", "--side", "left"], "side = 'left'"),
        (["--state", "S", "--k", "-1"], "k_mN_per_mm2 = -1.0"),
        (["--results", "R", "--task", "nosuchid"], "task = 'nosuchid': no point or sweep"),
    ],
)
def test_render_bad_input(tmp_path, args, fragment):
    state = tmp_path / "s.dat"
    write_state(state, shipped_state(1))
    results = write_results(tmp_path / "r.h5", ks=(0.1,))
    args = [str(state) if a == "S" else str(results) if a == "R" else a for a in args]
    out = knitsweep("render", "--out", str(tmp_path / "x.png"), *args)
    assert out.returncode == 2, out.stdout
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and fragment in lines[0], lines


def test_render_bad_suffix_and_cells(tmp_path):
    from knitsweep.report.render import render

    with pytest.raises(InputError, match="must end in"):
        render(tmp_path / "x.jpg", state=tmp_path / "s.dat")
    with pytest.raises(InputError, match="cells = 0"):
        render(tmp_path / "x.png", state=tmp_path / "s.dat", cells=0)


# ---- publication options: formats, journal widths, titles, style ---------------------


def test_formats_and_journal_widths(tmp_path):
    """png, pdf and svg of every figure; at column width 3.4 in, fonts of 7-8 pt."""
    from PIL import Image

    from knitsweep.report.figures import write_figures
    from knitsweep.report.plotting import JOURNAL_RC, FigureOptions

    red = reduce_results(write_results(tmp_path / "r.h5"))
    opts = FigureOptions(formats=("png", "pdf", "svg"), width="column")
    outcomes = write_figures(red, tmp_path / "fig", opts)
    written = [o for o in outcomes if o.path is not None]
    assert len(written) >= 10
    for o in written:
        stem = o.path.stem
        for fmt in ("png", "pdf", "svg"):
            assert (tmp_path / "fig" / f"{stem}.{fmt}").stat().st_size > 1000, (stem, fmt)
        # 3.4 in at 300 dpi; x and y side by side (3, 4a), 6h and S11 (six panels) are too
        # dense: the page's 7 in
        page = stem.startswith(("fig6h", "fig3", "fig4a", "figS11"))
        with Image.open(o.path) as im:
            assert im.size[0] == round((7.0 if page else 3.4) * 300), stem
    assert (tmp_path / "fig" / "fig3_energy_gaps.pdf").read_bytes().startswith(b"%PDF")
    assert min(v for k, v in JOURNAL_RC.items() if "size" in k and "marker" not in k) >= 7


def test_no_title_and_style(tmp_path):
    import matplotlib

    from knitsweep.report.fig_energy import fig3_energy_gaps
    from knitsweep.report.plotting import FigureOptions, style

    red = reduce_results(write_results(tmp_path / "r.h5"))
    with style(FigureOptions(title=False)):
        assert fig3_energy_gaps(red, []).get_suptitle() == ""
    with style(FigureOptions()):
        assert "Energy gaps" in fig3_energy_gaps(red, []).get_suptitle()
    # the user's matplotlib style is kept unless --style asks for another
    with matplotlib.rc_context({"axes.facecolor": "#123456"}):
        with style(FigureOptions()):
            fig = fig3_energy_gaps(red, [])
            assert matplotlib.colors.to_hex(fig.axes[0].get_facecolor()) == "#123456"
        with style(FigureOptions(style="knitsweep")):
            fig = fig3_energy_gaps(red, [])
            assert matplotlib.colors.to_hex(fig.axes[0].get_facecolor()) == "#ffffff"


def test_bad_figure_options_are_refused(tiny, tmp_path):
    for args, fragment in ((["--format", "gif"], "png, pdf, svg"),
                           (["--width", "poster"], "auto, column or page"),
                           (["--style", "no-such-style"], "not a matplotlib style")):  # fmt: skip
        out = knitsweep("phase-diagram", str(tiny), "--out", str(tmp_path / "x"), *args)
        assert out.returncode == 2 and fragment in out.stderr, (args, out.stderr)


def test_render_defaults_show_the_stitches(tmp_path):
    """The default tube is the yarn's radius r, holes in shadow, not white."""
    from PIL import Image

    from knitsweep.report.render import BACKGROUND, render

    path, stitch = render(tmp_path / "s.png", state=SHIPPED / "Init_1.dat", cells=2,
                          width_px=500, radius=0.5)  # fmt: skip
    assert stitch.r_mm == 0.74
    pixels = np.asarray(Image.open(path).convert("RGB"), dtype=float) / 255.0
    white = np.all(pixels > 0.98, axis=-1)
    rows = np.flatnonzero((~white).mean(axis=1) > 0.5)  # the picture's rows, not the texts'
    inner = white[rows[0] + 5 : rows[-1] - 5, 60:-60]  # inside the picture frame: no white
    assert not inner.any(), int(inner.sum())
    assert np.isclose(pixels, BACKGROUND, atol=0.02).all(axis=-1).any()  # the holes


@pytest.mark.parametrize("param, value", [("regularization_mN_mm4", 3.0), ("twist_bound", 0.8)])
def test_phase_diagram_along_any_series_parameter(tmp_path, param, value):
    """Two files that differ only in ``param``: the phase diagram is drawn against it
    (every series parameter has a symbol)."""
    a = write_results(tmp_path / "a.h5", ks=(0.1,), contact_forces=False)
    b = write_results(tmp_path / "b.h5", ks=(0.1,), contact_forces=False)
    with h5py.File(b, "a") as f:
        for kind in ("points", "sweeps"):
            for tid in list(f[kind]):  # other parameters, other task ids
                f.move(f"{kind}/{tid}", f"{kind}/{tid}_b")
                group = f[f"{kind}/{tid}_b"]
                params = json.loads(group.attrs["params"]) | {param: value}
                group.attrs["params"] = json.dumps(params, sort_keys=True)
                group.attrs[param] = value
                if "point_id" in group.attrs:
                    group.attrs["point_id"] = f"{group.attrs['point_id']}_b"
    report = phase_diagram([a, b], tmp_path / "pd")
    assert param in reduce_results([a, b]).varying
    assert_image(tmp_path / "pd" / "fig4c_phase_diagram.png")
    assert all(f.path is not None or "skipped" in f.line for f in report.figures)


# ---- render: a pattern's images (docs/model.md §11) ---------------------------------


def _garter_stitch():
    from knitsweep.report.render import stitch_from_state
    from knitsweep.stitches import get_stitch

    x = get_stitch("garter").start(1)
    return stitch_from_state(x, StitchParams(stitch="garter"))


def test_render_tile_mirrors_garter_rows():
    """Garter's tile: row n is row 0 mirrored (z -> -z) when n is odd, plus n t_w; the
    copies along a row are the cell's path repeated by t_c, as stockinette's."""
    from knitsweep.report.tile import cell_path, copy_mirrored, row_path, unit_cell

    stitch = _garter_stitch()
    assert stitch.mirror_parity == (0, 1) and stitch.mirrors
    one = cell_path(stitch.control_points, 12)
    columns = range(-1, 4)
    base = row_path(stitch, one, 0, columns)
    t_w = np.array([0.0, stitch.a_y, 0.0])
    expect_row0 = np.concatenate([one[:-1] + m * stitch.t_c for m in columns]
                                 + [one[-1:] + columns[-1] * stitch.t_c])  # fmt: skip
    np.testing.assert_allclose(base, expect_row0, rtol=0, atol=1e-12)
    assert np.abs(base[:, 2]).max() > 1.0  # far off the mirror plane: a mirror shows
    for n in (-1, 1, 2, 3):
        mirrored = n % 2 == 1
        expect = base * np.array([1.0, 1.0, -1.0 if mirrored else 1.0]) + n * t_w
        np.testing.assert_allclose(row_path(stitch, one, n, columns), expect, rtol=0, atol=1e-12)
        assert all(copy_mirrored(stitch, n, m) is mirrored for m in columns)
    # the mirrored rows are not the translated ones
    assert not np.allclose(row_path(stitch, one, 1, columns), base + t_w, atol=0.1)
    # --highlight saturates the cell itself, not a purl image of it
    assert unit_cell(stitch, 3) == (0, 1) and unit_cell(stitch, 4) == (2, 2)


def test_render_tile_of_seed_is_a_checkerboard():
    """Seed's tile: the copy at (row, column) is mirrored when row + column is odd, and
    each row's yarn runs on through the mirrored copies without a gap (the course closes
    through the glide, joint 0 on the mirror plane)."""
    from knitsweep.report.render import stitch_from_state
    from knitsweep.report.tile import cell_path, copy_mirrored, row_path
    from knitsweep.stitches import get_stitch

    stitch = stitch_from_state(get_stitch("seed").start(1), StitchParams(stitch="seed"))
    assert stitch.mirror_parity == (1, 1) and stitch.mirrors
    for row in range(-1, 3):
        for column in range(-1, 3):
            assert copy_mirrored(stitch, row, column) is ((row + column) % 2 == 1)
    one = cell_path(stitch.control_points, 12)
    for row in (0, 1):
        for c in (-1, 0, 1):  # each copy ends where the next one (mirrored or not) starts
            end = row_path(stitch, one, row, range(c, c + 1))[-1]
            start = row_path(stitch, one, row, range(c + 1, c + 2))[0]
            np.testing.assert_allclose(end, start, rtol=0, atol=1e-12)
        assert np.abs(row_path(stitch, one, row, range(-1, 3))[:, 2]).max() > 1.0


def test_render_stockinette_tile_is_translations_alone():
    """Stockinette mirrors nothing: every row is the old sum, bit for bit (its pictures
    are unchanged), and its colours are the rows' cycle."""
    from knitsweep.report import render as rd

    stitch = rd.stitch_from_state(shipped_state(1), StitchParams())
    assert stitch.mirror_parity == (0, 0) and not stitch.mirrors
    one = rd.cell_path(stitch.control_points, 12)
    t_w = np.array([0.0, stitch.a_y, 0.0])
    cells = 3
    for row in range(-1, cells + 1):
        old = np.concatenate([one[:-1] + m * stitch.t_c + row * t_w for m in range(-1, cells + 1)]
                             + [one[-1:] + cells * stitch.t_c + row * t_w])  # fmt: skip
        assert np.array_equal(rd.row_path(stitch, one, row, range(-1, cells + 1)), old)
        assert rd.copy_mirrored(stitch, row, 0) is None
    assert rd.unit_cell(stitch, 3) == (1, 1)


def test_render_garter_draws_its_mirrored_rows(tmp_path):
    """``render --stitch garter`` draws the purl rows: the picture is not the one of the
    cell translated."""
    import dataclasses

    from knitsweep.report.render import _view_matrix, shade_tile, window
    from knitsweep.stitches import get_stitch

    state = tmp_path / "g.dat"
    write_state(state, get_stitch("garter").start(1))
    out = knitsweep("render", "--stitch", "garter", "--state", str(state), "--out",
                    str(tmp_path / "g.png"), "--pixels", "300")  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert_image(tmp_path / "g.png", 10_000)
    stitch = _garter_stitch()
    view = _view_matrix(72.0, 0.0, "face")
    box = window(stitch, 2, view)
    image = shade_tile(stitch, 2, 0.5, view, box, 160)
    flat = shade_tile(dataclasses.replace(stitch, mirror_parity=(0, 0)), 2, 0.5, view, box, 160)
    assert np.abs(image - flat).max() > 0.3


@pytest.mark.parametrize("name", ["rib", "garter", "seed"])
def test_render_contact_volumes_of_a_pattern(tmp_path, name):
    """``render --stitch rib --contact-volumes`` (and garter, seed) draws the pattern's
    contact volumes over its mirrored images, once refused (tests/test_volumes.py checks
    where the points lie)."""
    from knitsweep.stitches import get_stitch

    state = tmp_path / "s.dat"
    write_state(state, get_stitch(name).start(1))
    out = knitsweep("render", "--stitch", name, "--state", str(state), "--contact-volumes",
                    "--volume-points", "4096", "--out", str(tmp_path / "cv.png"))  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert_image(tmp_path / "cv.png")
    assert "wrote" in out.stdout and "cv.png" in out.stdout
