"""The tile renderer (report/render.py on report/tube_mesh.py and kernels/raster.py) and
the 3D export (report/export3d.py): no seam where cells meet, no speckles, the yarn's
radius, two repeats of the pattern, a title naming the stitch and its parameters, and
3D files that ParaView's reader (VTK) and meshio open back with their data."""

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

from knitsweep.config import StitchParams
from knitsweep.formats import write_state
from knitsweep.report import render as rd
from knitsweep.report.tile import MIRROR
from knitsweep.stitches import get_stitch

PATTERNS = ("stockinette", "garter", "rib", "seed")


def knitsweep(*args):
    return subprocess.run([sys.executable, "-m", "knitsweep", *args], capture_output=True,
                          text=True, timeout=600)  # fmt: skip


def shipped(name: str):
    return rd.stitch_from_state(get_stitch(name).start(1), StitchParams(stitch=name),
                                "shipped start 1")  # fmt: skip


def recut(stitch, k: int):
    """The same fabric with the cell cut at joint ``k`` instead of joint 0: segments
    k..S−1 of the cell, then 0..k−1 of its next copy along the row (mirrored where that
    copy is); its cell boundaries fall elsewhere on the yarn."""
    cp = stitch.control_points
    nxt = (cp[:k] * MIRROR if rd.copy_mirrored(stitch, 0, 1) else cp[:k]) + stitch.t_c
    return dataclasses.replace(stitch, control_points=np.concatenate([cp[k:], nxt]))


def isolated_outliers(image: np.ndarray, jump: float = 0.1, flat: float = 0.06) -> int:
    """Pixels (not on the border) whose luminance differs by more than ``jump`` from the
    median of their 8 neighbours while those agree among themselves within ``flat``:
    single-pixel specks on a smooth surface."""
    lum = image[..., :3] @ np.array([0.3, 0.59, 0.11])
    h, w = lum.shape
    nb = np.stack([lum[1 + dy : h - 1 + dy, 1 + dx : w - 1 + dx]
                   for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)])  # fmt: skip
    centre = lum[1:-1, 1:-1]
    lone = (np.abs(centre - np.median(nb, axis=0)) > jump) & (np.ptp(nb, axis=0) < flat)
    return int(lone.sum())


def test_outlier_count_finds_specks():
    rng = np.random.default_rng(0)
    smooth = np.tile(np.linspace(0.2, 0.8, 80)[None, :, None], (60, 1, 3))
    assert isolated_outliers(smooth) == 0
    specked = smooth.copy()
    ys, xs = rng.integers(2, 58, 12), rng.integers(2, 78, 12)
    specked[ys, xs] = 0.0
    assert isolated_outliers(specked) >= 10


def _views(stitch, width_px):
    view = rd._view_matrix(72.0, 0.0, "face")
    box = rd.window(stitch, 3, view)
    return view, box


@pytest.mark.parametrize("name", PATTERNS)
def test_no_seam_where_cells_meet(name):
    """A tile and the same tile shifted by one repeat of the pattern along the row (one
    cell, or two where the next copy is mirrored) agree on their overlap, and so does
    the fabric cut into cells at another joint: nothing of the picture depends on
    where a cell ends (frames, normals and colours run on through)."""
    stitch = shipped(name)
    view, box = _views(stitch, 300)
    along = stitch.repeat[0]
    width = 3 * 40 * along  # 40 px per cell: a shift of whole pixels
    box = np.array([box[0], box[0] + abs((3 * along * stitch.t_c @ view.T)[0]), box[2], box[3]])
    shift = (along * stitch.t_c) @ view.T
    px = (box[1] - box[0]) / width
    k = round(abs(shift[0]) / px)
    assert abs(abs(shift[0]) / px - k) < 1e-9 and abs(shift[1]) < 1e-12
    a = rd.shade_tile(stitch, 3, stitch.r_mm, view, box, width)
    b = rd.shade_tile(stitch, 3, stitch.r_mm, view, box + np.r_[shift[0], shift[0], 0, 0], width)
    overlap = (a[:, k:], b[:, :-k]) if shift[0] > 0 else (a[:, :-k], b[:, k:])
    diff = np.abs(overlap[0] - overlap[1]).max(axis=-1)
    assert (diff > 0.02).mean() < 0.005 and diff.max() < 0.25, (diff.max(), (diff > 0.02).mean())
    for joint in (3, 5):  # the same yarn cut elsewhere
        c = rd.shade_tile(recut(stitch, joint), 3, stitch.r_mm, view, box, width)
        diff = np.abs(a - c).max(axis=-1)
        assert (diff > 0.02).mean() < 0.005 and diff.max() < 0.25, (joint, diff.max())


@pytest.mark.parametrize("name", ["garter", "seed"])
def test_no_speckles(name):
    stitch = shipped(name)
    view, box = _views(stitch, 400)
    image = rd.shade_tile(stitch, 3, stitch.r_mm, view, box, 400)
    assert isolated_outliers(image) == 0
    assert np.isclose(image, rd.BACKGROUND, atol=0.02).all(axis=-1).mean() < 0.2


def test_defaults_two_repeats_yarn_radius_and_title(tmp_path):
    assert [rd.default_cells(shipped(n)) for n in PATTERNS] == [(3, 3), (3, 4), (4, 3), (4, 4)]
    stitch = shipped("rib")
    assert rd.tube_radius(stitch, None, False) == 0.74
    assert rd.tube_radius(stitch, None, True) == stitch.params.r_core_mm == 0.325
    assert rd.tube_radius(stitch, 0.5, True) == 0.5
    title = rd.title(stitch)
    assert title.startswith("rib: shipped start 1\n")
    for part in ("L = 11.6 mm", "k = 0.6 mN/mm²", "B = 90 mN·mm²", "r_core = 0.325 mm"):
        assert part in title, title
    state = tmp_path / "rib_state.dat"
    write_state(state, get_stitch("rib").start(1))
    out = knitsweep("render", "--stitch", "rib", "--state", str(state), "--out",
                    str(tmp_path / "r.png"), "--pixels", "200", "--cells", "2x1", "--core")  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == f"wrote {tmp_path / 'r.png'}: rib, state of rib_state.dat"
    for bad, fragment in ((["--cells", "3y"], "cells = '3y': give N or NxM"),
                          (["--cells", "13"], "cells = 13: must be in 1..12"),
                          (["--preset", "draft"], "--preset and --starts apply to a relaxation")):  # fmt: skip
        out = knitsweep("render", "--state", str(state), "--out", str(tmp_path / "x.png"), *bad)
        assert out.returncode == 2 and out.stderr.startswith("error: ") and fragment in out.stderr, (
            bad, out.stderr)  # fmt: skip


def test_core_tubes_are_thinner():
    stitch = shipped("stockinette")
    view, box = _views(stitch, 200)
    full = rd.shade_tile(stitch, 3, stitch.r_mm, view, box, 200)
    core = rd.shade_tile(stitch, 3, stitch.params.r_core_mm, view, box, 200)
    hole = lambda im: np.isclose(im, rd.BACKGROUND, atol=0.02).all(axis=-1).mean()  # noqa: E731
    assert hole(full) < 0.01 and hole(core) > 0.08


@pytest.mark.slow
def test_render_stitch_relaxes_what_it_draws(tmp_path):
    """``render --stitch NAME --L …`` with neither --state nor --results relaxes the
    stitch at those parameters (once refused: "apply to --state")."""
    out = knitsweep("render", "--stitch", "stockinette", "--L", "11.2", "--k", "0.2",
                    "--preset", "draft", "--out", str(tmp_path / "s.png"), "--pixels", "200")  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith(
        f"wrote {tmp_path / 's.png'}: stockinette, zero-force state, relaxed"
    )
    assert (tmp_path / "s.png").stat().st_size > 10_000


# ---- 3D export --------------------------------------------------------------------


@pytest.fixture(scope="module")
def garter_files(tmp_path_factory):
    from knitsweep.report.export3d import tile_mesh, write_tile

    d = tmp_path_factory.mktemp("mesh")
    stitch = shipped("garter")
    files = {s: write_tile(stitch, d / f"tile.{s}", (2, 2), stitch.r_mm)
             for s in ("vtp", "vtu", "ply", "obj")}  # fmt: skip
    return stitch, tile_mesh(stitch, (2, 2), stitch.r_mm), files


def test_vtp_opens_in_vtk_with_its_data(garter_files):
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    stitch, mesh, files = garter_files
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(files["vtp"]))
    reader.Update()
    poly = reader.GetOutput()
    k = len(mesh.centre)
    assert poly.GetNumberOfPoints() == k + len(mesh.points)
    assert poly.GetNumberOfLines() == 2 and poly.GetNumberOfPolys() == len(mesh.triangles)
    points = vtk_to_numpy(poly.GetPoints().GetData())
    np.testing.assert_array_equal(points[:k], mesh.centre)
    data = poly.GetPointData()
    arrays = {data.GetArrayName(i) for i in range(data.GetNumberOfArrays())}
    assert {"kind", "row", "column", "purl", "t", "segment", "contact_class", "clearance_mm",
            "Normals"} <= arrays  # fmt: skip
    purl = vtk_to_numpy(data.GetArray("purl"))
    rows = vtk_to_numpy(data.GetArray("row"))
    assert np.array_equal(purl, rows % 2)  # garter: the odd rows are the mirrored ones
    field = poly.GetFieldData()
    text = {field.GetAbstractArray(i).GetName(): field.GetAbstractArray(i).GetValue(0)
            for i in range(field.GetNumberOfArrays())
            if field.GetAbstractArray(i).GetClassName() == "vtkStringArray"}  # fmt: skip
    assert text["stitch"] == "garter" and text["state"] == "shipped start 1"
    assert '"L_mm": 11.6' in text["parameters"]
    names = text["contact_classes"].split()
    assert names == ["self", "same_row", "same_column", "mirrored", "other"]
    cp = vtk_to_numpy(field.GetArray("control_points_mm")).reshape(-1, 6, 3)
    np.testing.assert_array_equal(cp, stitch.control_points)
    cls = vtk_to_numpy(data.GetArray("contact_class"))
    assert set(np.unique(cls)) <= {-1, *range(len(names))}
    assert (cls[:k] == names.index("mirrored")).any()  # garter's rows touch their mirrors


def test_contact_class_marks_where_other_yarn_is_near(garter_files):
    """A centre-line vertex is classed in contact exactly where another piece of yarn's
    centre-line comes within 2r (checked by brute force over the tile's own rows, for
    the vertices of the copy in the middle whose neighbours the tile holds)."""
    from knitsweep.report.export3d import contacts, tile_mesh

    stitch = shipped("garter")
    mesh = tile_mesh(stitch, (3, 3), stitch.r_mm)
    _, data = contacts(stitch, mesh)
    k = len(mesh.centre)
    cls, gap = data["contact_class"][:k], data["clearance_mm"][:k]
    mid = (mesh.centre_row == 1) & (mesh.centre_column == 1)
    other_row = mesh.centre_row[None, :] != mesh.centre_row[mid][:, None]
    d = np.linalg.norm(mesh.centre[mid][:, None, :] - mesh.centre[None, :, :], axis=-1)
    nearest_other_row = np.where(other_row, d, np.inf).min(axis=1)
    r = stitch.r_mm
    close = nearest_other_row < 2 * r - 0.02
    assert close.any()
    assert (cls[mid][close] != -1).all()
    assert (gap[mid][close] < 0).all()
    assert np.all(gap <= r + 1e-12)


def test_ply_obj_vtu_open_in_meshio(garter_files):
    import meshio

    _, mesh, files = garter_files
    for suffix in ("ply", "obj", "vtu"):
        m = meshio.read(files[suffix])
        tris = next(c.data for c in m.cells if c.type == "triangle")
        assert len(tris) == len(mesh.triangles), suffix
        if suffix == "vtu":
            assert sum(len(c.data) for c in m.cells if c.type == "line") == len(mesh.centre) - 2
            assert {"contact_class", "purl", "row", "Normals"} <= set(m.point_data)
        else:
            np.testing.assert_allclose(m.points, mesh.points, rtol=0, atol=1e-12)
    ply = meshio.read(files["ply"])
    assert {"nx", "ny", "nz", "red", "green", "blue", "contact_class", "purl"} <= set(
        ply.point_data
    )
    obj = meshio.read(files["obj"])
    np.testing.assert_allclose(obj.point_data["obj:vn"], mesh.normals, atol=1e-12)


def test_render_out_mesh_from_the_cli(tmp_path):
    state = tmp_path / "s.dat"
    write_state(state, get_stitch("seed").start(1))
    out = knitsweep("render", "--stitch", "seed", "--state", str(state), "--cells", "2",
                    "--out", str(tmp_path / "tile.vtp"))  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert (
        (tmp_path / "tile.vtp")
        .read_bytes()
        .startswith(b'<?xml version="1.0"?>\n<VTKFile type="PolyData"')
    )
    out = knitsweep("render", "--state", str(state), "--out", str(tmp_path / "x.stl"))
    assert out.returncode == 2
    assert out.stderr.strip() == (f"error: out = '{tmp_path / 'x.stl'}': must end in .png, .pdf, "
                                  ".svg, .vtp, .vtu, .ply, .obj")  # fmt: skip


@pytest.mark.parametrize("note", ["3 × 4 stitches, face side", "state of a.dat\n3 × 3 stitches"])
def test_picture_texts_fit(note):
    """The title's two lines and the note fit in the figure (none clipped, none over
    another) for a wide and a tall picture."""
    from test_figure_layout import layout_problems

    stitch = shipped("seed")
    for shape in ((40, 100, 3), (110, 100, 3)):
        fig = rd.stitch_figure(np.zeros(shape), np.array([0.0, 10.0, 0.0, 10.0 * shape[0] / 100]),
                               rd.title(stitch), note)  # fmt: skip
        assert not layout_problems(fig), layout_problems(fig)
