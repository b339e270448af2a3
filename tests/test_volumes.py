"""Unit tier: the contact-volume estimators (knitsweep.analysis.volumes; paper SI
"Contact Volumes") on shapes whose volume is known: a straight tube, a torus and
overlapping parallel tubes; and the two estimators beside each other on a stitch."""

import numpy as np
import pytest
from scipy.integrate import quad

from knitsweep.analysis.volumes import arc_length, qmc_volumes, tube_samples, voxel_volumes
from knitsweep.analysis.volumes.geometry import build_pieces

R_YARN = 0.74


def straight(a_x: float) -> np.ndarray:
    """8 quintic segments on the x axis from 0 to a_x: one period of a straight yarn."""
    cp = np.zeros((8, 6, 3))
    for s in range(8):
        cp[s, :, 0] = np.linspace(s * a_x / 8, (s + 1) * a_x / 8, 6)
    return cp


def circle(radius: float) -> np.ndarray:
    """A closed loop of 8 quintic segments fitted to a circle of ``radius`` in the xy
    plane (least squares on 60 points per 45° arc, ends on the circle)."""
    t = np.linspace(0.0, 1.0, 60)
    from knitsweep.kernels.bezier import basis_tables

    basis = basis_tables(t)[0]
    cp = np.zeros((8, 6, 3))
    for s in range(8):
        ang = (s + t) * np.pi / 4
        target = radius * np.column_stack([np.cos(ang), np.sin(ang)])
        ends = basis[:, [0, 5]] @ target[[0, -1]]
        inner, *_ = np.linalg.lstsq(basis[:, 1:5], target - ends, rcond=None)
        cp[s, 0, :2], cp[s, 5, :2], cp[s, 1:5, :2] = target[0], target[-1], inner
    return cp


def lens_area(a: float, b: float, d: float) -> float:
    """Area (mm²) of the intersection of two disks of radii a, b, centres d apart."""
    if d >= a + b:
        return 0.0
    if d <= abs(a - b):
        return np.pi * min(a, b) ** 2
    return float(a * a * np.arccos((d * d + a * a - b * b) / (2 * d * a))
                 + b * b * np.arccos((d * d + b * b - a * a) / (2 * d * b))
                 - 0.5 * np.sqrt((-d + a + b) * (d + a - b) * (d - a + b) * (d + a + b)))  # fmt: skip


def test_straight_tube_both_estimators():
    # one period of an isolated straight yarn: pi r^2 a_x, whatever the end caps
    a_x, a_y = 4.0, 10.0
    exact = np.pi * R_YARN**2 * a_x
    q = qmc_volumes(straight(a_x), a_x, a_y, R_YARN, samples=1 << 10, scrambles=4)
    assert q.V_total == pytest.approx(exact, rel=1e-12)
    assert q.V_comp == 0.0 and q.V_total_error < 1e-12
    assert q.phi == pytest.approx(exact / (a_x * a_y * 2 * R_YARN), rel=1e-12)
    # voxels: V_uncomp has the two end caps (4/3 pi r^3), V_comp the caps of both
    # stitches at each end, and they cancel; the error falls with the voxel side
    errors = []
    for side in (0.08, 0.04, 0.02):
        v = voxel_volumes(straight(a_x), a_x, a_y, R_YARN, side)
        assert v.V_uncomp == pytest.approx(exact + 4 / 3 * np.pi * R_YARN**3, rel=0.04)
        errors.append(abs(v.V_total - exact) / exact)
    assert errors[2] < errors[0] and errors[2] < 2e-3, errors


def test_torus():
    # a closed loop: Pappus, pi r^2 times the loop's length (2 pi R to 1e-6)
    R = 3.0
    cp = circle(R)
    length = arc_length(cp)
    assert length == pytest.approx(2 * np.pi * R, rel=1e-6)
    exact = np.pi * R_YARN**2 * length
    q = qmc_volumes(cp, 40.0, 40.0, R_YARN, samples=1 << 12, scrambles=4, closed=True)
    assert q.V_total == pytest.approx(exact, rel=1e-12)
    assert q.compressed_by_class["self"] == 0.0
    v = voxel_volumes(cp, 40.0, 40.0, R_YARN, 0.03, closed=True)
    assert v.V_comp == 0.0
    assert v.V_total == pytest.approx(exact, rel=3e-3)


def test_overlapping_parallel_tubes():
    # rows a_y < 2r apart: each stitch shares a lens of area A with the row above and
    # the one below, V_total = (pi r^2 - A) a_x
    a_x, a_y = 4.0, 1.2
    lens = lens_area(R_YARN, R_YARN, a_y)
    exact_comp = 2 * lens * a_x
    exact = (np.pi * R_YARN**2 - lens) * a_x
    q = qmc_volumes(straight(a_x), a_x, a_y, R_YARN, samples=1 << 13, scrambles=8, seed=3)
    assert q.V_total_error > 0.0
    assert abs(q.V_total - exact) < 5 * q.V_total_error
    assert q.V_total_error < 1e-3 * exact
    assert q.V_comp == pytest.approx(exact_comp, rel=2e-3)
    assert q.compressed_by_class["nn_column"] == pytest.approx(exact_comp, rel=2e-3)
    assert q.phi == pytest.approx(exact / (a_x * a_y * 2 * R_YARN), rel=1e-3)
    # the voxel method as the paper defines it measures distances to the stitch's own
    # piece of centre-line: its end caps also overlap the rows above and below, which
    # the set V_comp counts once, so it converges to the true volume plus the volume
    # of a ball of radius r (at the end) inside the neighbouring row's tube
    ball_in_row, _ = quad(lambda x: lens_area(np.sqrt(max(R_YARN**2 - x * x, 0.0)), R_YARN, a_y),
                          -R_YARN, R_YARN, limit=200)  # fmt: skip
    v = voxel_volumes(straight(a_x), a_x, a_y, R_YARN, 0.02)
    assert v.V_total == pytest.approx(exact + ball_in_row, rel=2e-3)


def test_tube_samples_cover_the_tube():
    # the weights add up to pi r^2 times the arc length for any state
    cp = circle(2.0)
    pieces = build_pieces(cp, 40.0, 40.0, R_YARN, closed=True)
    u = np.random.default_rng(0).random((4096, 3))
    ts = tube_samples(cp, pieces, R_YARN, u)
    dist = np.hypot(np.hypot(ts.x[:, 0], ts.x[:, 1]) - 2.0, ts.x[:, 2])
    assert np.all(dist <= R_YARN + 1e-6)
    assert ts.weight.sum() == pytest.approx(np.pi * R_YARN**2 * arc_length(cp), rel=0.03)
    assert not ts.self_overlap.any() and np.all(ts.other == -1)


def test_estimators_on_a_stitch_and_a_fixed_seed():
    from knitsweep.config import StitchParams
    from knitsweep.formats import shipped_state
    from knitsweep.model import CellModel

    x = shipped_state(1)
    model = CellModel(StitchParams(L_mm=11.6, k_mN_per_mm2=0.1))
    cp = model.control_points(x)
    a = qmc_volumes(cp, x[-2], x[-1], R_YARN, samples=1 << 12, scrambles=4)
    b = qmc_volumes(cp, x[-2], x[-1], R_YARN, samples=1 << 12, scrambles=4)
    assert a == b  # the same seed, the same points: deterministic
    assert a.V_cell == pytest.approx(x[-2] * x[-1] * model.thickness(x), rel=1e-12)
    assert 0.5 < a.phi < 1.0 and a.phi_error < 2e-3
    assert a.V_total == pytest.approx(a.V_uncomp - a.V_comp / 2, rel=1e-12)
    v = voxel_volumes(cp, x[-2], x[-1], R_YARN, 0.08)
    # the voxels' end caps at the joins with the same-row neighbours add volume
    assert v.V_uncomp > a.V_uncomp and v.phi > a.phi


def test_render_contact_volumes(tmp_path):
    from typer.testing import CliRunner

    from knitsweep.cli import app
    from knitsweep.config import StitchParams
    from knitsweep.formats import shipped_state
    from knitsweep.report.contact_volumes import contact_volume_points
    from knitsweep.report.render import stitch_from_state

    stitch = stitch_from_state(shipped_state(1), StitchParams(L_mm=11.6, k_mN_per_mm2=0.1))
    clouds = contact_volume_points(stitch, 1 << 12)
    # every class of Fig. 6a-d is there in a relaxed stitch
    assert all(len(clouds[k]) > 0 for k in ("self", "same_row", "nn_above", "nn_below",
                                            "nnn_column"))  # fmt: skip
    out = tmp_path / "cv.png"
    state = tmp_path / "s.dat"
    state.write_text("\n".join(repr(float(v)) for v in shipped_state(1)) + "\n")
    res = CliRunner().invoke(app, ["render", "--state", str(state), "--L", "11.6", "--k", "0.1",
                                   "--contact-volumes", "--volume-points", "2048", "--out", str(out)])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert out.stat().st_size > 10_000
    bad = CliRunner().invoke(app, ["render", "--state", str(state), "--contact-volumes",
                                   "--volume-points", "1000", "--out", str(out)])  # fmt: skip
    assert bad.exit_code == 2 and "samples = 1000" in bad.output


@pytest.mark.parametrize(("name", "mirrored_kinds"), [
    ("garter", ("mirrored_above", "mirrored_below")),
    ("rib", ("mirrored_beside", "mirrored_above", "mirrored_below")),
    ("seed", ("mirrored_above", "mirrored_below")),
])  # fmt: skip
def test_contact_volumes_of_a_pattern_touch_their_images(name, mirrored_kinds):
    """A pattern's contact volumes (docs/model.md §11) over its mirrored images: each
    point of a kind lies within r of the centre-line of an image of that kind, the
    images built here as the pattern defines them (z -> -z where pm m + pn n is odd);
    the mirrored neighbours touch the shipped start."""
    from scipy.spatial import cKDTree

    from knitsweep.config import StitchParams
    from knitsweep.report.contact_volumes import KINDS, contact_volume_points, volume_kind
    from knitsweep.report.render import stitch_from_state
    from knitsweep.report.tile import cell_path
    from knitsweep.stitches import get_stitch

    stitch = get_stitch(name)
    x = stitch.start(1)
    drawn = stitch_from_state(x, StitchParams(stitch=name))
    clouds = contact_volume_points(drawn, 1 << 12)
    assert tuple(clouds) == KINDS[True]
    assert all(len(clouds[k]) > 0 for k in ("self", *mirrored_kinds)), {
        k: len(v) for k, v in clouds.items()
    }
    path = cell_path(drawn.control_points, 200)  # chords below 0.02 mm
    pm, pn = stitch.mirror_parity
    near: dict[str, list] = {}
    for m in range(-3, 4):
        for n in range(-3, 4):
            flip = -1.0 if (pm * m + pn * n) % 2 else 1.0
            image = path * [1.0, 1.0, flip] + [m * x[-2], n * x[-1], 0.0]
            near.setdefault(volume_kind(m, n, (pm, pn)), []).append(image)
    r = drawn.r_mm
    for kind, pts in clouds.items():
        if kind == "self" or not len(pts):
            continue
        d = cKDTree(np.concatenate(near[kind])).query(pts)[0]
        assert d.max() <= r + 0.02, (kind, d.max(), r)


@pytest.mark.parametrize("stitch", ["stockinette", "stockinette_free", "garter", "rib", "seed"])
def test_thickness_is_the_fabrics_over_every_image(stitch):
    """Δz spans the cell and every image that touches the plane's z-range: for
    translations alone the cell's own z-range (stockinette: the same bits as that
    formula), with mirrored images the union of the cell and its mirror image."""
    from knitsweep.analysis.volumes import fabric_depth
    from knitsweep.config import StitchParams
    from knitsweep.kernels.bezier import basis_tables
    from knitsweep.model import CellModel
    from knitsweep.stitches.base import image_points

    model = CellModel(StitchParams(stitch=stitch, k_mN_per_mm2=0.1))
    x = model.stitch.start(1)
    cp = model.control_points(x)
    own = np.einsum("ti,si->st", basis_tables(np.linspace(0.0, 1.0, 64))[0], cp[:, :, 2])
    dz_cell = float(own.max() - own.min() + 2.0 * R_YARN)
    # the images built point by point, as the contact kernel and the renderer see them
    pts = np.einsum("ti,sik->stk", basis_tables(np.linspace(0.0, 1.0, 64))[0], cp).reshape(-1, 3)
    z = np.concatenate([image_points(pts, m, n, x[-2], x[-1], model.stitch.mirror_parity)[:, 2]
                        for m in (-1, 0, 1) for n in (-1, 0, 1)])  # fmt: skip
    dz_fabric = float(z.max() - z.min() + 2.0 * R_YARN)
    assert model.thickness(x) == fabric_depth(cp, R_YARN, model.stitch.mirror_parity)
    if model.stitch.mirror_parity == (0, 0):
        assert model.thickness(x) == dz_cell  # bit for bit the cell's own z-range
    else:
        assert model.thickness(x) == pytest.approx(dz_fabric, abs=1e-14)
        assert model.thickness(x) > dz_cell + 0.1  # the purl images stand out of the cell
