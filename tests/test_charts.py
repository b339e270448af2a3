"""Knit/purl charts as cells of several stitches (``stitches.chart``, docs/model.md §12):
what a chart may be, where it is refused, and that the four named patterns computed as
charts of one and two stitches are the same fabric (energies, lengths and periods per
stitch), with exact gradients and a two-stitch cell stationary at the one-stitch
minimum."""

import numpy as np
import pytest
from conftest import one_error_line, run_knitsweep

from knitsweep.config import StitchParams
from knitsweep.errors import InputError
from knitsweep.model import CellModel
from knitsweep.stitches import get_stitch, unknown_stitch
from knitsweep.stitches.chart import (
    MAX_CELL_STITCHES,
    chart_stitch_names,
    parse_chart,
    row_and_parity,
    supercell_state,
)


def _model(stitch, L=11.6):
    return CellModel(StitchParams(stitch=stitch, L_mm=L, k_mN_per_mm2=0.1))


@pytest.mark.parametrize(("chart", "rows", "cell"), [
    (["KKPP"], ("KKPP",), ("KKPP", 0)),
    ("kp/pk", ("KP", "PK"), ("KP", 1)),
    ("K-P", ("K", "P"), ("K", 1)),
    (["KP", "KP"], ("KP", "KP"), ("KP", 0)),
    ("KKP, PPK, KKP, PPK", ("KKP", "PPK", "KKP", "PPK"), ("KKP", 1)),
])  # fmt: skip
def test_a_chart_is_rows_bottom_first_and_its_cell_one_row(chart, rows, cell):
    assert parse_chart(chart) == rows
    assert row_and_parity(rows) == cell


@pytest.mark.parametrize(("chart", "fragment"), [
    (["KX"], "chart row 1, column 2 = 'X': a stitch is K (knit) or P (purl)"),
    (["KP", "K"], "chart row 2 = 'K': 1 stitches, row 1 has 2"),
    ([], "an empty chart"),
    ("", "an empty chart"),
    (["KP", ""], "chart row 2: an empty row"),
    (3, "a chart is a list of rows of K and P"),
    (["K" * (MAX_CELL_STITCHES + 1)], f"at most {MAX_CELL_STITCHES} stitches in a row"),
])  # fmt: skip
def test_a_bad_chart_is_refused_naming_row_and_column(chart, fragment):
    with pytest.raises(InputError) as e:
        parse_chart(chart)
    assert fragment in str(e.value)


@pytest.mark.parametrize(("rows", "bad"), [
    (("KP", "KP", "PK", "PK"), "row 2 = 'KP'"),  # moss: two yarns in its cell
    (("K", "P", "K"), "row 3 = 'K'"),  # an odd number of alternating rows
    (("KKPP", "KPKP"), "row 2 = 'KPKP'"),
])  # fmt: skip
def test_a_chart_of_several_yarns_is_refused_naming_the_row(rows, bad):
    with pytest.raises(InputError, match="several yarns") as e:
        row_and_parity(rows)
    assert bad in str(e.value)


def test_a_chart_is_a_stitch_by_name():
    assert unknown_stitch("chart:KKPP") is None
    assert "column 2 = 'Q'" in unknown_stitch("chart:KQ")
    assert get_stitch("chart:kp/pk").name == "chart:KP-PK"
    s = get_stitch("chart:KKPP")
    assert (s.cell_stitches, s.n_segments, s.mirror_parity, s.closing_shift) == (
        4,
        32,
        (0, 0),
        (4, 0),
    )
    assert s.n_state == 4 + 7 * 31 + 4 * 32 + 2 and s.state_names[-2:] == ("a_x", "a_y")
    g = get_stitch("chart:KK-PP")  # rows mirrored: the yarn's height above the plane
    assert g.mirror_parity == (0, 1) and g.state_names[-3:] == ("z0", "a_x", "a_y")
    assert StitchParams(stitch="chart:kkpp").stitch == "chart:KKPP"
    assert chart_stitch_names([["KKPP"], ["KP", "PK"]]) == ["chart:KKPP", "chart:KP-PK"]
    with pytest.raises(InputError, match=r"chart\[1\] row 1, column 2 = 'Q'"):
        chart_stitch_names([["KKPP"], ["KQ"]])


PAIRS = [("stockinette_free", "chart:K", 1), ("garter", "chart:K-P", 1), ("rib", "chart:KP", 1),
         ("seed", "chart:KP-PK", 1), ("stockinette_free", "chart:KK", 2),
         ("rib", "chart:KPKP", 2), ("garter", "chart:KK-PP", 2)]  # fmt: skip


@pytest.mark.parametrize(("named", "chart", "copies"), PAIRS)
def test_the_named_patterns_as_charts_are_the_same_fabric(named, chart, copies):
    """A named pattern's start, written as the chart of its row (its stitch and its
    images along the course, ``supercell_state``): the same energies and length per
    stitch to round-off, and the same periods."""
    ms, mc = _model(named), _model(chart)
    x = ms.gauged(ms.stitch.start(1))
    xc = supercell_state(x, ms.control_points(x), ms.stitch.mirror_parity, copies,
                         any(mc.stitch.mirror_parity))  # fmt: skip
    es, ec = ms.energies(x), mc.energies(xc)
    for f in ("bending_energy", "contact_energy", "length"):
        assert getattr(ec, f) == pytest.approx(getattr(es, f), rel=1e-12, abs=0), f
    assert tuple(xc[-2:]) == tuple(x[-2:])
    assert ec.gauge_energy == pytest.approx(es.gauge_energy, rel=1e-6, abs=1e-15)
    assert mc.min_zeta(xc) == pytest.approx(ms.min_zeta(x), rel=1e-12)
    assert mc.topology_change(xc) == ""


@pytest.mark.parametrize("chart", ["chart:KKP", "chart:KK-PP"])
def test_chart_gradients_match_central_differences(chart):
    """The per-stitch energy's gradient, the periods' included (the cell's course period
    is n a_x) and z0 where the rows are mirrored."""
    m = _model(chart)
    x = m.gauged(m.stitch.start(1))
    _, ge, gl = m.energy_and_gradients(x)
    h = 1e-6
    for k in [*range(0, m.stitch.n_state - 3, 11), *range(m.stitch.n_state - 3, m.stitch.n_state)]:
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        ep, em = m.energies(xp), m.energies(xm)
        fe = (ep.objective - em.objective) / (2 * h)
        fl = (ep.length - em.length) / (2 * h)
        assert abs(fe - ge[k]) <= 1e-6 * max(1.0, abs(ge[k])), (k, m.stitch.state_names[k])
        assert abs(fl - gl[k]) <= 1e-6 * max(1.0, abs(gl[k])), (k, m.stitch.state_names[k])


@pytest.mark.parametrize("chart", ["chart:KKPP", "chart:KKP", "chart:PK", "chart:KK-PP",
                                   "chart:P"])  # fmt: skip
def test_chart_starts_keep_the_cores_apart(chart):
    m = _model(chart)
    for i in (1, 2):
        assert m.check_start(m.gauged(m.stitch.start(i))) > 1e-5


def test_a_chart_whose_start_overlaps_says_where():
    """Seed's tilted stitches side by side (two knits, rows mirrored): their junction
    passes through the row below; refused before any compute, naming the stitch."""
    from knitsweep.relax.zero_force import check_shipped_starts

    with pytest.raises(InputError) as e:
        check_shipped_starts(("chart:KKP-PPK",))
    assert "shipped start seed's Init_1.dat of chart:KKP-PPK = overlapping yarn" in str(e.value)
    assert "segment 7 (stitch 1 of the row, K) of the cell" in str(e.value)
    assert "its image (0, -1)" in str(e.value)


def test_two_rib_stitches_are_stationary_at_ribs_minimum():
    """Rib relaxed at 11.6 mm, written as the chart KP (two free stitches): relaxing that
    cell moves it by less than the relaxation's tolerance, and its stitches stay each
    other's mirror images."""
    from knitsweep.config import StartSettings
    from knitsweep.presets import Numerics
    from knitsweep.relax.zero_force import zero_force

    n = Numerics.from_preset("converged")
    rib = StitchParams(stitch="rib", L_mm=11.6, k_mN_per_mm2=0.1)
    best = zero_force(rib, n.fidelity, n.solver, StartSettings(count=1), 0).best
    assert best.converged
    ms, mc = _model("rib"), _model("chart:KP")
    xc = supercell_state(best.x, ms.control_points(best.x), (1, 0), 1, False)
    chart = rib.model_copy(update={"stitch": "chart:KP"})
    cell = zero_force(chart, n.fidelity, n.solver, StartSettings(count=1), 0, initial=xc).best
    assert cell.converged, cell.message
    assert abs(cell.total_energy - best.total_energy) < 1e-6
    assert cell.a_x == pytest.approx(best.a_x, abs=1e-3)
    cp = mc.control_points(cell.x)
    mirrored = cp[8:] * np.array([1.0, 1.0, -1.0]) - np.array([cell.a_x, 0.0, 0.0])
    assert np.abs(mirrored - cp[:8] + cp[0, 0] - mirrored[0, 0]).max() < 0.02  # mm


def test_chart_on_the_command_line_is_refused_before_any_compute():
    one_error_line(run_knitsweep("relax", "--chart", "KQ"), "--chart row 1, column 2 = 'Q'")
    one_error_line(run_knitsweep("relax", "--chart", "KP", "--stitch", "rib"), "give one of them")
    one_error_line(
        run_knitsweep("sweep", "--direction", "x", "--chart", "KP,KP,PK"), "several yarns"
    )


def test_chart_in_a_job_file(tmp_path):
    from knitsweep.service.jobs import load_job

    base = 'schema_version = 1\nname = "c"\n'
    one = tmp_path / "one.toml"
    one.write_text(base + 'chart = ["kkpp"]\n[grid]\nL_mm = 11.6\n')
    assert load_job(one).stitches == ("chart:KKPP",)
    grid = tmp_path / "grid.toml"
    grid.write_text(
        base + '[grid]\nL_mm = 11.6\nstitch = "rib"\nchart = [["KKPP"], ["KP", "PK"]]\n'
    )
    assert load_job(grid).stitches == ("rib", "chart:KKPP", "chart:KP-PK")
    bad = tmp_path / "bad.toml"
    bad.write_text(base + '[grid]\nL_mm = 11.6\nchart = [["KKPP"], ["KQ"]]\n')
    with pytest.raises(InputError, match=r"grid.chart\[1\] row 1, column 2 = 'Q'"):
        load_job(bad)
    both = tmp_path / "both.toml"
    both.write_text(base + 'chart = ["KP"]\nstitch = "rib"\n[grid]\nL_mm = 11.6\n')
    with pytest.raises(InputError, match="give the stitch in one place"):
        load_job(both)
    same = tmp_path / "same.toml"
    same.write_text(base + '[grid]\nL_mm = 11.6\nstitch = "chart:KP"\nchart = [["kp"]]\n')
    with pytest.raises(InputError, match="repeated"):
        load_job(same)


def test_two_by_two_rib_rearranges_its_crossings_but_keeps_the_rows_linking(data_dir):
    """2x2 rib relaxed at 11.6 mm (k = 0.1; stored): its knit ribs fold over its purl
    ribs, the crossings with the rows beside it rearranged (the interlocking word of its
    start is not kept: pairs of crossings appear), but every row's linking with the cell's
    is its start's; lifting one segment through the yarn it passes under changes it."""
    from knitsweep.formats import read_state
    from knitsweep.stitches.topology import crossings, linking_sums, stitch_topology, topology_word

    m = _model("chart:KKPP")
    x = read_state(data_dir / "chart_KKPP_L11.6_k0.1.dat", "chart:KKPP")
    x1 = m.stitch.start(1)
    assert m.stitch.keeps_linking and not _model("chart:KPKP").stitch.keeps_linking
    cp, cp1 = m.control_points(x), m.control_points(x1)
    periods, periods1 = m.stitch.cell_periods(x), m.stitch.cell_periods(x1)
    word = topology_word(cp, *periods, interlock=True)
    assert word != topology_word(cp1, *periods1, interlock=True)
    assert stitch_topology(m.stitch, cp, x) == stitch_topology(m.stitch, cp1, x1)
    assert m.topology_change(x) == ""
    heights, along = [], []
    crossings(cp, *periods, heights=heights, along=along)
    # a segment under a strand of the row above once, lifted 5 mm over everything
    under = [(int(a // 48), n) for (a, n, _), (_, _, za, zb) in zip(along, heights, strict=True)
             if n == 1 and za < zb]  # fmt: skip
    seg = next(s for s, _ in under if sum(1 for t, _ in under if t == s) == 1)
    lifted = cp.copy()
    lifted[seg, :, 2] += 5.0
    before, after = dict(linking_sums(cp, *periods)), dict(linking_sums(lifted, *periods))
    assert abs(after.get(1, 0) - before.get(1, 0)) == 2


@pytest.mark.parametrize("chart", ["chart:KKP", "chart:KK-PP"])
def test_chart_contact_forces_are_the_per_stitch_energys_derivatives(chart):
    """Summed over the classes, the contact forces on the periods are −dE_c/da per stitch
    at fixed shape (central differences of the per-stitch E_c), and the classes' energies
    add up to E_c per stitch."""
    m = _model(chart)
    x = m.gauged(m.stitch.start(1))
    forces, energies = m.contacts_by_class(x)
    assert energies.sum() == pytest.approx(m.energies(x).contact_energy, rel=1e-10)
    h = 1e-6
    for k, col in ((-2, 0), (-1, 1)):
        xp, xm = x.copy(), x.copy()
        xp[k] += h
        xm[k] -= h
        fd = -(m.energies(xp).contact_energy - m.energies(xm).contact_energy) / (2 * h)
        assert forces[:, col].sum() == pytest.approx(fd, rel=1e-5, abs=1e-9), col
