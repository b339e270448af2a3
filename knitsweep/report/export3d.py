"""A tile's yarn as a 3D file: centre-lines and tube surfaces with data per vertex.

``knitsweep render --out tile.vtp`` (or .vtu, .ply, .obj) writes the ``cells`` (across,
rows) copies of the stitch that a picture shows (``tube_mesh``: each row's yarn one
curve, its tube of radius ρ), in mm:

* ``.vtp``: VTK XML PolyData for ParaView, written here (meshio has no PolyData
  writer): the centre-lines as polylines (one per row) and the tubes as triangles in
  one piece, with every per-vertex array below, the vertex normals, and as field data
  the stitch, the state drawn, its parameters (JSON), the control points and periods,
  and the names of the contact classes.
* ``.vtu``: the same as a VTK unstructured grid (lines and triangles), through meshio.
* ``.ply``: the tube surfaces for Blender, through meshio: normals (nx, ny, nz), the
  rows' colours (red, green, blue, as in the picture) and the per-vertex arrays.
* ``.obj``: the tube surfaces with their normals, through meshio (OBJ holds no other
  per-vertex data).

Per vertex: ``kind`` (0 centre-line, 1 tube surface), ``row`` and ``column`` (the copy),
``purl`` (1 where the copy is a mirror image: a purl stitch of a knit/purl pattern),
``t`` (the cell's Bézier parameter, ``segment`` its integer part), ``contact_class`` (the
index in the field data's ``contact_classes`` of the other yarn touching there, −1 for
none: for a centre-line vertex another centre-line within 2r, the shells overlapping;
for a surface vertex another yarn within r, the surface inside it) and
``clearance_mm`` (distance to that nearest other yarn's centre-line less 2r, resp. r;
negative: compressed; capped at +r). The classes are those of the stitch's contact
energy (docs/model.md §9, §11), by ``analysis.volumes.contact_class``.
"""

from __future__ import annotations

import base64
import json
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from ..util.safe_files import replace_file
from .tile import MIRROR, ROW_COLOURS, Stitch
from .tube_mesh import TubeMesh, tube_mesh

NO_CONTACT = -1
VTK_TYPES = {np.dtype(np.float64): "Float64", np.dtype(np.float32): "Float32",
             np.dtype(np.int64): "Int64", np.dtype(np.int32): "Int32",
             np.dtype(np.uint8): "UInt8"}  # fmt: skip


def tile_mesh(stitch: Stitch, cells: tuple[int, int], radius: float, around: int = 24,
              spacing: float = 0.08) -> TubeMesh:  # fmt: skip
    """The rows 0..cells[1]−1, copies 0..cells[0]−1 of each, as tubes of ``radius``."""
    copies = dict.fromkeys(range(cells[1]), range(cells[0]))
    return tube_mesh(stitch, copies, radius, spacing, around)


def to_cell(
    stitch: Stitch, points: np.ndarray, rows: np.ndarray, columns: np.ndarray
) -> np.ndarray:
    """Points (N, 3) of the copies (rows, columns) mapped back onto the cell: the inverse
    of g p = M^μ p + column t_c + row t_w."""
    t_w = np.array([0.0, stitch.a_y, 0.0])
    local = points - columns[:, None] * stitch.t_c - rows[:, None] * t_w
    (pm, pn), (cm, cn) = stitch.mirror_parity, stitch.closing_shift
    flip = (pm * columns * cm + pn * (columns * cn + rows)) % 2 == 1
    return np.where(flip[:, None], local * MIRROR, local)


def contacts(stitch: Stitch, mesh: TubeMesh) -> tuple[tuple[str, ...], dict[str, np.ndarray]]:
    """(class names, {"contact_class", "clearance_mm"} for the centre-line vertices then
    the tube vertices) (module docstring)."""
    from ..analysis.volumes import build_pieces, contact_class, contact_classes
    from ..analysis.volumes.geometry import distances
    from ..kernels.contact import EXCLUSION_FACTOR

    names = contact_classes(stitch.mirror_parity)
    r = stitch.r_mm
    # every image within 3r of the cell's box (build_pieces keeps those within 2 x its r)
    pieces = build_pieces(stitch.control_points, stitch.a_x, stitch.a_y, 1.5 * r, 0.01,
                          parity=stitch.mirror_parity)  # fmt: skip
    code = np.array([names.index(contact_class(int(m), int(n), stitch.mirror_parity))
                     for m, n in pieces.offsets])  # fmt: skip
    s0 = np.interp(mesh.centre_t, pieces.arc_t, pieces.arc_s)
    out_class, out_gap = [], []
    for pts, rows, cols, s, reach in (
        (mesh.centre, mesh.centre_row, mesh.centre_column, s0, 2.0 * r),
        (mesh.points, mesh.centre_row[mesh.ring], mesh.centre_column[mesh.ring], s0[mesh.ring], r),
    ):
        local = to_cell(stitch, pts, rows, cols)
        d_own, d_other, who = distances(pieces, local, s, reach + r, EXCLUSION_FACTOR * r)
        own = d_own < d_other
        d = np.minimum(d_own, d_other)
        cls = np.where(own, names.index("self"), code[np.maximum(who, 0)])
        cls = np.where(d <= reach, cls, NO_CONTACT)
        out_class.append(cls.astype(np.int32))
        out_gap.append(np.minimum(d - reach, r))
    return names, {"contact_class": np.concatenate(out_class),
                   "clearance_mm": np.concatenate(out_gap)}  # fmt: skip


def vertex_data(stitch: Stitch, mesh: TubeMesh) -> tuple[tuple[str, ...], dict[str, np.ndarray]]:
    """(contact class names, per-vertex arrays for the centre-line vertices then the tube
    vertices, each (K + N,))."""
    ring = mesh.ring
    both = {
        "kind": np.r_[np.zeros(len(mesh.centre)), np.ones(len(mesh.points))].astype(np.int32),
        "row": np.r_[mesh.centre_row, mesh.centre_row[ring]].astype(np.int32),
        "column": np.r_[mesh.centre_column, mesh.centre_column[ring]].astype(np.int32),
        "purl": np.r_[mesh.centre_mirrored, mesh.centre_mirrored[ring]].astype(np.uint8),
        "t": np.r_[mesh.centre_t, mesh.centre_t[ring]],
    }
    segments = len(stitch.control_points)
    both["segment"] = np.minimum(both["t"].astype(np.int32), segments - 1)
    names, contact = contacts(stitch, mesh)
    return names, both | contact


def metadata(stitch: Stitch, names: tuple[str, ...]) -> dict[str, str]:
    """The file's description: the stitch, the state drawn, its parameters, the classes."""
    params = stitch.params.model_dump(mode="json") if stitch.params is not None else {}
    params |= {"stitch": stitch.name}
    return {"stitch": stitch.name, "state": stitch.label,
            "parameters": json.dumps(params, sort_keys=True),
            "contact_classes": " ".join(names), "units": "mm"}  # fmt: skip


def _row_colours(rows: np.ndarray) -> np.ndarray:
    from matplotlib.colors import to_rgb

    palette = np.array([to_rgb(c) for c in ROW_COLOURS])
    return np.rint(255 * palette[np.mod(rows, len(ROW_COLOURS))]).astype(np.uint8)


def write_tile(stitch: Stitch, out: str | Path, cells: tuple[int, int], radius: float) -> Path:
    """Write the tile's yarn to ``out`` (.vtp, .vtu, .ply or .obj; module docstring)."""
    out = Path(out)
    mesh = tile_mesh(stitch, cells, radius)
    names, data = vertex_data(stitch, mesh)
    meta = metadata(stitch, names)
    suffix = out.suffix.lower()
    if suffix == ".vtp":
        return replace_file(out, vtp_bytes(stitch, mesh, data, meta))
    import meshio

    k = len(mesh.centre)
    if suffix == ".vtu":
        points = np.concatenate([mesh.centre, mesh.points])
        lines = np.concatenate([np.column_stack([np.arange(a, b - 1), np.arange(a + 1, b)])
                                for a, b in mesh.lines])  # fmt: skip
        cells_ = [("line", lines), ("triangle", mesh.triangles + k)]
        normals = np.concatenate([np.zeros_like(mesh.centre), mesh.normals])
        m = meshio.Mesh(points, cells_, point_data={**data, "Normals": normals},
                        field_data={})  # fmt: skip
    else:
        surface = {key: v[k:] for key, v in data.items() if key != "kind"}
        if suffix == ".ply":
            rgb = _row_colours(mesh.centre_row[mesh.ring])
            point_data = {"nx": mesh.normals[:, 0], "ny": mesh.normals[:, 1],
                          "nz": mesh.normals[:, 2], "red": rgb[:, 0], "green": rgb[:, 1],
                          "blue": rgb[:, 2], **surface}  # fmt: skip
        else:
            point_data = {"obj:vn": mesh.normals}
        m = meshio.Mesh(mesh.points, [("triangle", mesh.triangles.astype(np.int32))],
                        point_data=point_data)  # fmt: skip
    tmp = out.with_name(f".{out.name}.part")
    try:
        meshio.write(tmp, m, file_format={".vtu": "vtu", ".ply": "ply", ".obj": "obj"}[suffix])
        return replace_file(out, tmp.read_bytes())  # never through a symbolic link
    finally:
        tmp.unlink(missing_ok=True)


def _data_array(name: str, values: np.ndarray, components: int = 1) -> str:
    values = np.ascontiguousarray(values)
    if values.dtype == np.bool_:
        values = values.astype(np.uint8)
    raw = values.astype(values.dtype.newbyteorder("<")).tobytes()
    blob = base64.b64encode(np.uint64(len(raw)).tobytes() + raw).decode()
    return (f'<DataArray type="{VTK_TYPES[values.dtype]}" Name={quoteattr(name)} '
            f'NumberOfComponents="{components}" NumberOfTuples="{values.size // components}" '
            f'format="binary">{blob}</DataArray>')  # fmt: skip


def _string_array(name: str, text: str) -> str:
    raw = text.encode() + b"\0"
    blob = base64.b64encode(np.uint64(len(raw)).tobytes() + raw).decode()
    return (f'<DataArray type="String" Name={quoteattr(name)} NumberOfTuples="1" '
            f'format="binary">{blob}</DataArray>')  # fmt: skip


def vtp_bytes(stitch: Stitch, mesh: TubeMesh, data: dict[str, np.ndarray],
              meta: dict[str, str]) -> bytes:  # fmt: skip
    """The VTK XML PolyData file (version 1.0, inline base64 binary, UInt64 headers)."""
    k = len(mesh.centre)
    points = np.concatenate([mesh.centre, mesh.points])
    normals = np.concatenate([np.zeros_like(mesh.centre), mesh.normals])
    line_conn = np.arange(k, dtype=np.int64)
    line_off = mesh.lines[:, 1].astype(np.int64)
    poly_conn = (mesh.triangles + k).ravel().astype(np.int64)
    poly_off = 3 * np.arange(1, len(mesh.triangles) + 1, dtype=np.int64)
    field = [_string_array(key, value) for key, value in meta.items()]
    field += [_data_array("control_points_mm", stitch.control_points.reshape(-1, 3), 3),
              _data_array("periods_mm", np.array([stitch.a_x, stitch.a_y]))]  # fmt: skip
    point_data = [_data_array(key, v) for key, v in data.items()]
    point_data.append(_data_array("Normals", normals, 3))
    text = "\n".join([
        '<?xml version="1.0"?>',
        '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64">',
        "<PolyData>",
        "<FieldData>", *field, "</FieldData>",
        f'<Piece NumberOfPoints="{len(points)}" NumberOfVerts="0" '
        f'NumberOfLines="{len(mesh.lines)}" NumberOfStrips="0" '
        f'NumberOfPolys="{len(mesh.triangles)}">',
        '<PointData Scalars="contact_class" Normals="Normals">', *point_data, "</PointData>",
        "<Points>", _data_array("Points", points, 3), "</Points>",
        "<Lines>", _data_array("connectivity", line_conn), _data_array("offsets", line_off),
        "</Lines>",
        "<Polys>", _data_array("connectivity", poly_conn), _data_array("offsets", poly_off),
        "</Polys>",
        "</Piece>", "</PolyData>", "</VTKFile>", "",
    ])  # fmt: skip
    return text.encode()
