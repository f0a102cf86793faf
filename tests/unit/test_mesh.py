"""Tests for retarget.mesh: loading each format, the refusals, save/load round trips.

Every file is built in code, by hand (text, a GLB's chunks, a glTF's JSON) or by trimesh,
and written into tmp_path or passed as bytes; no external data.
"""

import base64
import io
import json
import struct
import sys

import numpy as np
import pytest
import trimesh
from trimesh.visual.material import SimpleMaterial

from retarget.errors import RetargetError
from retarget.mesh import Mesh, load_mesh, mesh_from_arrays, save_mesh

# a unit square split in two triangles, then an apex above it
SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float64)
SQUARE_FACES = np.array([[0, 1, 2], [0, 2, 3]])
PYRAMID = np.vstack([SQUARE, [[0.5, 0.5, 1.0]]])
PYRAMID_FACES = np.array(
    [[0, 1, 2], [0, 2, 3], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]
)


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


def obj_text(vertices, faces_lines, extra=""):
    v = "".join(f"v {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in vertices)
    return v + extra + "".join(f"f {line}\n" for line in faces_lines)


def area(vertices, faces):
    """Total area of the triangles, a check that a polygon was covered."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()


def trimesh_of(vertices, faces, uv=None, normals=None):
    visual = None
    if uv is not None:
        visual = trimesh.visual.TextureVisuals(uv=uv, material=SimpleMaterial())
    return trimesh.Trimesh(
        vertices, faces, vertex_normals=normals, visual=visual, process=False
    )


# ---------------------------------------------------------------- OBJ


def test_obj_keeps_vertex_count_and_order(tmp_path):
    # unsorted positions, vertex 2 unused in the middle and vertex 5 unused at the end
    vertices = np.array(
        [[3.5, -1, 2], [0.25, 7, -3], [9, 9, 9], [-2, 0.5, 1], [1, 1, 1], [8, 8, 8]]
    )
    path = write(tmp_path, "head.obj", obj_text(vertices, ["5 2 1", "4 5 1"]))
    mesh = load_mesh(path)
    assert isinstance(mesh, Mesh)
    assert type(mesh.vertices) is np.ndarray and type(mesh.faces) is np.ndarray
    assert mesh.vertices.dtype == np.float64 and mesh.faces.dtype == np.int64
    np.testing.assert_array_equal(mesh.vertices, vertices)
    np.testing.assert_array_equal(mesh.faces, [[4, 1, 0], [3, 4, 0]])
    assert (mesh.n_vertices, mesh.n_faces) == (6, 2)
    assert mesh.uv is None and mesh.normals is None
    assert mesh.name == "head"


def test_obj_units_are_not_rescaled_or_centred(tmp_path):
    vertices = PYRAMID * 1000.0 + [120.0, -40.0, 7.5]  # millimetres, off-centre
    path = write(tmp_path, "mm.obj", obj_text(vertices, ["1 2 3", "1 3 4", "1 2 5"]))
    np.testing.assert_array_equal(load_mesh(path).vertices, vertices)


def test_obj_quad_and_ngon_are_triangulated_with_the_same_vertices(tmp_path):
    pentagon = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 2, 0], [0, 1, 0]], float)
    vertices = np.vstack([SQUARE, pentagon])
    path = write(tmp_path, "poly.obj", obj_text(vertices, ["1 2 3 4", "5 6 7 8 9"]))
    mesh = load_mesh(path)
    assert mesh.n_vertices == 9
    assert mesh.faces.shape == (2 + 3, 3)
    quad = mesh.faces[np.all(mesh.faces < 4, axis=1)]
    penta = mesh.faces[np.all(mesh.faces >= 4, axis=1)]
    assert len(quad) == 2 and len(penta) == 3
    assert area(mesh.vertices, quad) == pytest.approx(1.0)
    assert area(mesh.vertices, penta) == pytest.approx(3.0)


def test_obj_with_vt_and_vn(tmp_path):
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    normals = np.array([[0, 0, 1], [0, 0.6, 0.8], [0.6, 0, 0.8], [0, 0, 1]], float)
    extra = "".join(f"vt {u} {v}\n" for u, v in uv)
    extra += "".join(f"vn {x} {y} {z}\n" for x, y, z in normals)
    faces = ["1/1/1 2/2/2 3/3/3", "1/1/1 3/3/3 4/4/4"]
    path = write(tmp_path, "uv.obj", obj_text(SQUARE, faces, extra))
    mesh = load_mesh(path)
    np.testing.assert_array_equal(mesh.vertices, SQUARE)
    np.testing.assert_array_equal(mesh.faces, SQUARE_FACES)
    np.testing.assert_allclose(mesh.uv, uv)
    np.testing.assert_allclose(mesh.normals, normals)


def test_obj_uv_seam_keeps_the_vertex_count(tmp_path):
    # vertex 1 is used with vt 1 in one face and vt 5 in the other: a seam
    extra = "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 0.5\n"
    faces = ["1/1 2/2 3/3", "1/5 3/3 4/4"]
    path = write(tmp_path, "seam.obj", obj_text(SQUARE, faces, extra))
    mesh = load_mesh(path)
    assert mesh.n_vertices == 4
    np.testing.assert_array_equal(mesh.vertices, SQUARE)
    np.testing.assert_array_equal(mesh.faces, SQUARE_FACES)
    assert mesh.uv.shape == (4, 2)
    assert mesh.uv[0].tolist() in ([0.0, 0.0], [0.5, 0.5])
    np.testing.assert_allclose(mesh.uv[1:], [[1, 0], [1, 1], [0, 1]])


def test_obj_materials_do_not_split_or_duplicate_vertices(tmp_path):
    extra = "mtllib missing.mtl\n"
    faces = ["1 2 3", "usemtl skin", "1 3 4", "usemtl eyes", "1 2 5"]
    text = obj_text(PYRAMID, [], extra) + "".join(
        f"{line}\n" if line.startswith("usemtl") else f"f {line}\n" for line in faces
    )
    mesh = load_mesh(write(tmp_path, "mtl.obj", text))
    np.testing.assert_array_equal(mesh.vertices, PYRAMID)
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4]])


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # trimesh's nanmedian
def test_obj_uv_is_none_when_a_vertex_has_no_vt(tmp_path):
    # vertex 2 is used by no face, so it has no texture coordinate
    vertices = PYRAMID[[0, 1, 4, 2, 3]]
    extra = "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
    faces = ["1/1 2/2 4/3", "1/1 4/3 5/4"]
    path = write(tmp_path, "gap.obj", obj_text(vertices, faces, extra))
    mesh = load_mesh(path)
    np.testing.assert_array_equal(mesh.vertices, vertices)
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 3], [0, 3, 4]])
    assert mesh.uv is None


def test_obj_relative_indices_without_vt(tmp_path):
    path = write(tmp_path, "rel.obj", obj_text(SQUARE, ["-4 -3 -2", "-4 -2 -1"]))
    np.testing.assert_array_equal(load_mesh(path).faces, SQUARE_FACES)


def test_obj_unused_tail_vertices_with_vt_are_refused(tmp_path):
    extra = "vt 0 0\nvt 1 0\nvt 1 1\n"
    faces = ["1/1 2/2 3/3", "1/1 3/3 4/2"]
    path = write(tmp_path, "tail.obj", obj_text(PYRAMID, faces, extra))
    with pytest.raises(RetargetError, match=r"declares 5 vertices .* only the first 4"):
        load_mesh(path)


# ---------------------------------------------------------------- PLY, STL, OFF


PLY_HEADER = """ply
format ascii 1.0
element vertex {n}
property double x
property double y
property double z
{extra}element face {f}
property list uchar int vertex_indices
end_header
"""


def ply_text(vertices, faces, columns=None, names=""):
    rows = vertices if columns is None else np.hstack([vertices, columns])
    header = PLY_HEADER.format(n=len(rows), f=len(faces), extra=names)
    body = "".join(" ".join(repr(float(x)) for x in row) + "\n" for row in rows)
    return header + body + "".join(f"{len(f)} {' '.join(map(str, f))}\n" for f in faces)


def test_ply_with_normals_and_uv(tmp_path):
    normals = np.tile([0.0, 0.0, 1.0], (4, 1))
    uv = SQUARE[:, :2] * 0.5
    names = "".join(f"property double {n}\n" for n in ("nx", "ny", "nz", "s", "t"))
    text = ply_text(SQUARE, SQUARE_FACES.tolist(), np.hstack([normals, uv]), names)
    mesh = load_mesh(write(tmp_path, "face.ply", text))
    np.testing.assert_array_equal(mesh.vertices, SQUARE)
    np.testing.assert_array_equal(mesh.faces, SQUARE_FACES)
    np.testing.assert_allclose(mesh.normals, normals)
    np.testing.assert_allclose(mesh.uv, uv)


def test_ply_mixed_polygons_keep_vertices_not_face_order(tmp_path):
    text = ply_text(PYRAMID, [[0, 1, 2, 3], [0, 1, 4]])
    mesh = load_mesh(write(tmp_path, "mixed.ply", text))
    np.testing.assert_array_equal(mesh.vertices, PYRAMID)
    assert mesh.n_faces == 3
    assert sorted(map(sorted, mesh.faces.tolist())) == [[0, 1, 2], [0, 1, 4], [0, 2, 3]]
    assert mesh.uv is None and mesh.normals is None


def test_stl_gives_three_unshared_vertices_per_face(tmp_path):
    path = tmp_path / "soup.stl"
    trimesh_of(PYRAMID, PYRAMID_FACES).export(path)
    mesh = load_mesh(path)
    assert mesh.n_vertices == 3 * len(PYRAMID_FACES)
    np.testing.assert_array_equal(mesh.faces, np.arange(18).reshape(6, 3))
    np.testing.assert_allclose(mesh.vertices[mesh.faces], PYRAMID[PYRAMID_FACES])
    assert mesh.normals is None


def test_off_with_a_quad(tmp_path):
    text = "OFF\n5 2 0\n" + "".join(f"{x} {y} {z}\n" for x, y, z in PYRAMID)
    text += "4 0 1 2 3\n3 0 1 4\n"
    mesh = load_mesh(write(tmp_path, "pyr.off", text))
    np.testing.assert_array_equal(mesh.vertices, PYRAMID)
    assert mesh.n_faces == 3
    quad = mesh.faces[np.all(mesh.faces < 4, axis=1)]
    assert len(quad) == 2 and area(mesh.vertices, quad) == pytest.approx(1.0)


# ---------------------------------------------------------------- glTF / GLB


def test_glb_single_geometry(tmp_path):
    normals = np.tile([0.0, 0.0, 1.0], (4, 1))
    path = tmp_path / "one.glb"
    trimesh_of(SQUARE * 0.1, SQUARE_FACES, normals=normals).export(path)
    mesh = load_mesh(path)
    assert mesh.n_vertices == 4
    np.testing.assert_allclose(mesh.vertices, SQUARE * 0.1, atol=1e-7)
    np.testing.assert_array_equal(mesh.faces, SQUARE_FACES)
    np.testing.assert_allclose(mesh.normals, normals, atol=1e-7)


def test_glb_scene_applies_transforms_and_concatenates(tmp_path):
    turn = trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0])
    turn[:3, 3] = [0, 0, 5]
    mirror = np.diag([-1.0, 1.0, 1.0, 1.0])
    normals = np.tile([0.0, 0.0, 1.0], (5, 1))
    scene = trimesh.Scene()
    pyramid = trimesh_of(PYRAMID, PYRAMID_FACES, normals=normals)
    square = trimesh_of(SQUARE, SQUARE_FACES, normals=normals[:4])
    scene.add_geometry(pyramid, node_name="first", transform=turn)
    scene.add_geometry(square, node_name="second", transform=mirror)
    path = write(tmp_path, "scene.glb", scene.export(file_type="glb"))

    mesh = load_mesh(path)
    assert (mesh.n_vertices, mesh.n_faces) == (4 + 5, 2 + 6)
    # root nodes come last to first: "second" (mirrored square), then "first"
    np.testing.assert_allclose(mesh.vertices[:4], SQUARE * [-1, 1, 1], atol=1e-6)
    np.testing.assert_allclose(
        mesh.vertices[4:], trimesh.transform_points(PYRAMID, turn), atol=1e-6
    )
    # the mirror reverses each triangle so it still faces the same way (+z)
    np.testing.assert_array_equal(mesh.faces[:2], SQUARE_FACES[:, ::-1])
    np.testing.assert_array_equal(mesh.faces[2:], PYRAMID_FACES + 4)
    np.testing.assert_allclose(mesh.normals[:4], normals[:4], atol=1e-6)
    np.testing.assert_allclose(mesh.normals[4:], [[0, -1, 0]] * 5, atol=1e-6)
    # same file, same arrays
    again = load_mesh(path)
    np.testing.assert_array_equal(again.vertices, mesh.vertices)
    np.testing.assert_array_equal(again.faces, mesh.faces)


def test_gltf_with_external_buffers_needs_a_path(tmp_path):
    path = tmp_path / "split.gltf"
    trimesh_of(PYRAMID, PYRAMID_FACES).export(path)  # writes .bin files beside it
    assert any(p.suffix == ".bin" for p in tmp_path.iterdir())
    mesh = load_mesh(path)
    np.testing.assert_allclose(mesh.vertices, PYRAMID, atol=1e-6)
    np.testing.assert_array_equal(mesh.faces, PYRAMID_FACES)
    with pytest.raises(RetargetError, match=r"could not read the given bytes as GLTF"):
        load_mesh(path.read_bytes(), "gltf")


# ---------------------------------------------------------------- sources


def test_bytes_and_file_object_sources_match_the_path(tmp_path):
    path = write(tmp_path, "src.obj", obj_text(PYRAMID, ["1 2 3", "1 3 4", "1 2 5"]))
    data = path.read_bytes()
    with open(path, "rb") as handle:
        from_handle = load_mesh(handle, "obj")
    from_bytes = load_mesh(data, "OBJ")
    for mesh in (from_bytes, load_mesh(io.BytesIO(data), ".obj"), from_handle):
        np.testing.assert_array_equal(mesh.vertices, PYRAMID)
        np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4]])
    assert from_handle.name == "src"
    assert from_bytes.name == ""


def test_file_type_overrides_the_suffix(tmp_path):
    path = write(tmp_path, "mesh.txt", obj_text(SQUARE, ["1 2 3"]))
    assert load_mesh(path, "obj").n_vertices == 4


# ---------------------------------------------------------------- refusals


@pytest.mark.parametrize(
    ("source", "file_type", "message"),
    [
        (b"v 0 0 0", "fbx", r"unsupported file type 'fbx'; supported: obj, ply, stl"),
        (b"v 0 0 0", None, r"cannot tell the file type of the given bytes"),
        (42, "obj", r"source must be a path, bytes or a binary file object, got int"),
        (io.StringIO("v 0"), "obj", r"must be opened in binary mode: read\(\) gave str"),
    ],
)
def test_bad_source_or_type_is_refused(source, file_type, message):
    with pytest.raises(RetargetError, match=message):
        load_mesh(source, file_type)


def test_unknown_suffix_is_refused(tmp_path):
    path = write(tmp_path, "points.xyz", "1 2 3\n")
    with pytest.raises(RetargetError, match=r"unsupported file type '\.xyz'"):
        load_mesh(path)


def test_missing_file_is_refused(tmp_path):
    with pytest.raises(RetargetError, match=r"could not read '.*nope\.obj': .*No such"):
        load_mesh(tmp_path / "nope.obj")


@pytest.mark.parametrize(
    ("data", "file_type", "message"),
    [
        (b"ply\nformat nonsense\n", "ply", r"could not read the given bytes as PLY: \w+Error"),
        (b"OFF\nhello\n", "off", r"could not read the given bytes as OFF: \w+Error"),
        (b"glTF garbage", "glb", r"could not read the given bytes as GLB: \w+Error"),
        (b'{"asset": 1}', "gltf", r"could not read the given bytes as GLTF: \w+Error"),
        (b"v a b c\nf 1 2 3\n", "obj", r"could not read the given bytes as OBJ: ValueError"),
        (b"v 0 0 0\nv 1 0 0\nf 1 2 9\n", "obj", r"as OBJ: IndexError: index 8 is out"),
        (b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "obj", r"no triangle mesh as OBJ \(found PointCloud\)"),
        (b"hello world", "obj", r"holds no triangle mesh as OBJ \(nothing was read\)"),
        (b"", "stl", r"holds no triangle mesh as STL \(nothing was read\)"),
        (b"\x00\xff\xfe\x80 binary", "obj", r"holds no triangle mesh as OBJ"),
    ],
)
def test_files_that_are_not_meshes_are_refused(data, file_type, message):
    with pytest.raises(RetargetError, match=message):
        load_mesh(data, file_type)


def test_any_trimesh_exception_is_wrapped(monkeypatch):
    def broken(*args, **kwargs):
        raise KeyError("accessors")

    monkeypatch.setattr(trimesh, "load_scene", broken)
    message = r"could not read the given bytes as PLY: KeyError: 'accessors'"
    with pytest.raises(RetargetError, match=message):
        load_mesh(b"ply", "ply")


def test_pointcloud_ply_is_refused(tmp_path):
    path = write(tmp_path, "cloud.ply", ply_text(PYRAMID, []))
    with pytest.raises(RetargetError, match=r"'.*cloud\.ply' holds no triangle mesh"):
        load_mesh(path)


def test_nan_and_inf_coordinates_are_refused(tmp_path):
    text = "v 0 0 0\nv nan 0 0\nv 1 inf 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n"
    message = r"2 vertices have NaN or infinite coordinates \(first: vertex 1\)"
    with pytest.raises(RetargetError, match=message):
        load_mesh(write(tmp_path, "nan.obj", text))


def test_faces_past_the_last_vertex_are_refused(tmp_path):
    path = write(tmp_path, "oob.ply", ply_text(SQUARE, [[0, 1, 2], [0, 2, 9]]))
    message = r"faces index vertex 9 but there are only 4 vertices \(valid indices 0\.\.3\)"
    with pytest.raises(RetargetError, match=message):
        load_mesh(path)


def test_negative_face_indices_are_refused(tmp_path):
    path = write(tmp_path, "neg.ply", ply_text(SQUARE, [[0, 1, 2], [0, -1, 3]]))
    message = r"1 faces hold negative vertex indices \(first: face \d, \[0, -1, 3\]\)"
    with pytest.raises(RetargetError, match=message):
        load_mesh(path)


def test_vertex_and_face_caps(tmp_path):
    path = write(tmp_path, "pyr.obj", obj_text(PYRAMID, ["1 2 3", "1 3 4", "1 2 5"]))
    with pytest.raises(RetargetError, match=r"has 5 vertices, above max_vertices=4"):
        load_mesh(path, max_vertices=4)
    with pytest.raises(RetargetError, match=r"has 3 faces, above max_faces=2"):
        load_mesh(path, max_faces=2)
    assert load_mesh(path, max_vertices=5, max_faces=3).n_faces == 3


def test_max_bytes(tmp_path):
    text = obj_text(SQUARE, ["1 2 3"])
    path = write(tmp_path, "small.obj", text)
    size = len(text)
    message = rf"is {size} bytes long, above max_bytes={size - 1}"
    with pytest.raises(RetargetError, match=rf"'.*small\.obj' {message}"):
        load_mesh(path, max_bytes=size - 1)
    with pytest.raises(RetargetError, match=rf"the given bytes {message}"):
        load_mesh(text.encode(), "obj", max_bytes=size - 1)
    with pytest.raises(RetargetError, match=rf"is over max_bytes={size - 1} bytes"):
        load_mesh(io.BytesIO(text.encode()), "obj", max_bytes=size - 1)
    assert load_mesh(path, max_bytes=size).n_vertices == 4


# ---------------------------------------------------------------- mesh_from_arrays


def test_mesh_from_arrays_copies_casts_and_freezes():
    vertices = SQUARE.astype(np.float32)
    faces = SQUARE_FACES.astype(np.int32)
    uv, normals = SQUARE[:, :2], SQUARE
    mesh = mesh_from_arrays(vertices, faces, uv=uv, normals=normals, name="sq")
    assert mesh.vertices.dtype == np.float64 and mesh.faces.dtype == np.int64
    assert mesh.uv.shape == (4, 2) and mesh.normals.shape == (4, 3)
    assert mesh.name == "sq"
    vertices[0, 0] = 99.0
    assert mesh.vertices[0, 0] == 0.0
    for array in (mesh.vertices, mesh.faces, mesh.uv, mesh.normals):
        with pytest.raises(ValueError, match="read-only"):
            array[0, 0] = 1


NAN_NORMALS = [[0, 0, 1], [0, 0, 1], [0, np.nan, 1], [0, 0, 1]]


@pytest.mark.parametrize(
    ("vertices", "faces", "kwargs", "message"),
    [
        (np.zeros((0, 3)), [[0, 1, 2]], {}, r"mesh is an empty mesh: vertices has shape"),
        (SQUARE, np.zeros((0, 3), int), {}, r"mesh is an empty mesh: faces has shape"),
        (SQUARE, [], {}, r"empty mesh: faces has shape \(0,\)"),
        (SQUARE[:, :2], SQUARE_FACES, {}, r"vertices must have shape \(V, 3\), got"),
        (SQUARE, [[0, 1, 2, 3]], {}, r"faces must be triangles, shape \(F, 3\), got"),
        (SQUARE, [[0.0, 1, 2]], {}, r"must hold integer vertex indices, got dtype float64"),
        ([["a", "b", "c"]], [[0, 0, 0]], {}, r"vertices must be a numeric \(V, 3\) array"),
        (SQUARE, [[0, 1, 2], [0, 2]], {}, r"faces must be an integer \(F, 3\) array"),
        (SQUARE, [[0, 1, 4]], {}, r"faces index vertex 4 but there are only 4 vertices"),
        (SQUARE, [[0, 1, 2], [-4, 2, 3]], {}, r"1 faces hold negative .* \(first: face 1"),
        (SQUARE, SQUARE_FACES, {"max_vertices": 3}, r"has 4 vertices, above max_vertices=3"),
        (SQUARE, SQUARE_FACES, {"max_faces": 1}, r"mesh has 2 faces, above max_faces=1"),
        (SQUARE, SQUARE_FACES, {"uv": [[0, 0]] * 3}, r"uv must have shape \(4, 2\), one row"),
        (SQUARE, SQUARE_FACES, {"normals": SQUARE[:, :2]}, r"normals must have shape \(4, 3"),
        (SQUARE, SQUARE_FACES, {"normals": NAN_NORMALS}, r"normals of 1 vertices are NaN"),
    ],
)
def test_mesh_from_arrays_refusals(vertices, faces, kwargs, message):
    with pytest.raises(RetargetError, match=message):
        mesh_from_arrays(vertices, faces, **kwargs)


def test_refusals_are_value_errors():
    with pytest.raises(ValueError):
        mesh_from_arrays(SQUARE, [[0, 1, 7]])


# ---------------------------------------------------------------- save_mesh round trips


@pytest.mark.parametrize("file_type", ["obj", "ply", "off", "glb", "gltf"])
def test_save_then_load_round_trip(tmp_path, file_type):
    normals = np.tile([0.0, 0.6, 0.8], (5, 1))
    uv = PYRAMID[:, :2] * 0.5 + 0.25
    vertices = PYRAMID * 0.123 - 0.5
    mesh = mesh_from_arrays(vertices, PYRAMID_FACES, uv=uv, normals=normals)
    path = tmp_path / f"out.{file_type}"
    save_mesh(mesh, path)
    loaded = load_mesh(path)
    np.testing.assert_allclose(loaded.vertices, mesh.vertices, atol=1e-6)
    np.testing.assert_array_equal(loaded.faces, mesh.faces)
    if file_type == "off":  # OFF holds neither
        assert loaded.uv is None and loaded.normals is None
    else:
        np.testing.assert_allclose(loaded.uv, uv, atol=1e-6)
        np.testing.assert_allclose(loaded.normals, normals, atol=1e-6)
    # one file, plus the material an OBJ with uv names; a .gltf embeds its buffers
    written = {"obj": ["out.mtl", "out.obj"]}.get(file_type, [path.name])
    assert sorted(p.name for p in tmp_path.iterdir()) == written


def test_save_obj_without_uv_writes_no_material(tmp_path):
    save_mesh(mesh_from_arrays(SQUARE, SQUARE_FACES), tmp_path / "plain.obj")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["plain.obj"]
    assert "mtllib" not in (tmp_path / "plain.obj").read_text()


def test_save_stl_round_trip_keeps_the_triangles(tmp_path):
    mesh = mesh_from_arrays(PYRAMID, PYRAMID_FACES)
    save_mesh(mesh, tmp_path / "out.stl")
    loaded = load_mesh(tmp_path / "out.stl")
    triangles = loaded.vertices[loaded.faces]
    np.testing.assert_allclose(triangles, PYRAMID[PYRAMID_FACES], atol=1e-6)


def test_save_unsupported_or_missing_suffix_is_refused(tmp_path):
    mesh = mesh_from_arrays(SQUARE, SQUARE_FACES)
    with pytest.raises(RetargetError, match=r"unsupported file type '\.fbx'"):
        save_mesh(mesh, tmp_path / "out.fbx")
    with pytest.raises(RetargetError, match=r"cannot tell the file type of '.*out'"):
        save_mesh(mesh, tmp_path / "out")
    assert not list(tmp_path.iterdir())



# ---------------------------------------------------------------- hostile inputs
#
# Each builds the malformed file in code. `not_parsed` replaces trimesh's loader so a
# test shows that the refusal came at the door, before any parsing.


@pytest.fixture
def not_parsed(monkeypatch):
    def fail(*args, **kwargs):
        raise AssertionError("trimesh was asked to parse a file the door should refuse")

    monkeypatch.setattr(trimesh, "load_scene", fail)


@pytest.fixture
def no_charset_normalizer(monkeypatch):
    """Text that is not UTF-8 must be decoded here, not guessed by charset_normalizer
    (an optional dependency of trimesh, imported only when UTF-8 decoding fails)."""
    monkeypatch.setitem(sys.modules, "charset_normalizer", None)


def binary_stl(triangles):
    """A binary STL of (F, 3, 3) float triangles: 80-byte header, count, 50 B each."""
    triangles = np.asarray(triangles, dtype="<f4").reshape(-1, 3, 3)
    rows = b"".join(
        struct.pack("<3f", 0, 0, 0) + t.tobytes() + b"\0\0" for t in triangles
    )
    return b"binary header".ljust(80, b"\0") + struct.pack("<I", len(triangles)) + rows


ASCII_STL = """solid {name}
 facet normal 0 0 1
  outer loop
   vertex 0 0 0
   vertex 1 0 0
   vertex 0 1 0
  endloop
 endfacet
endsolid {name}
"""


def test_binary_stl_whose_size_disagrees_with_its_header_is_refused(no_charset_normalizer):
    data = binary_stl(np.tile(PYRAMID[PYRAMID_FACES[:1]], (40, 1, 1)))
    data = data[:80] + struct.pack("<I", 1000) + data[84:]  # 40 triangles follow
    message = (
        r"binary STL header says 1,000 triangles \(50,084 bytes\) but the file is "
        r"2,084 bytes: truncated or not an STL"
    )
    with pytest.raises(RetargetError, match=message):
        load_mesh(data, "stl")
    with pytest.raises(RetargetError, match=r"header says 40 triangles .* is 2,085 bytes"):
        load_mesh(binary_stl(PYRAMID[np.tile(PYRAMID_FACES[:1], (40, 1))]) + b"\0", "stl")


def test_stl_too_short_for_a_header_is_refused():
    with pytest.raises(RetargetError, match=r"is 11 bytes long, shorter than the 84-byte"):
        load_mesh(b"not a mesh!", "stl")


@pytest.mark.parametrize("header", [b"solid exported by a CAD tool", b"COLOR=\xff\xfe\x80"])
def test_binary_stl_whose_header_starts_with_solid_or_is_not_text_loads(
        no_charset_normalizer, header):
    data = binary_stl(PYRAMID[PYRAMID_FACES])
    data = header.ljust(80, b" ") + data[80:]
    mesh = load_mesh(data, "stl")
    np.testing.assert_allclose(mesh.vertices[mesh.faces], PYRAMID[PYRAMID_FACES])


def test_ascii_stl_that_is_not_utf8_loads(no_charset_normalizer):
    data = ASCII_STL.format(name="caf\xe9").encode("latin-1")
    mesh = load_mesh(data, "stl")
    np.testing.assert_array_equal(mesh.vertices, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])


def test_ascii_stl_without_facets_is_refused():
    with pytest.raises(RetargetError, match=r"ASCII STL .* holds no 'facet'"):
        load_mesh(b"solid empty\nendsolid empty\n", "stl")


def test_stl_caps_are_checked_from_the_header(not_parsed):
    data = binary_stl(PYRAMID[PYRAMID_FACES])
    with pytest.raises(RetargetError, match=r"has 6 faces, above max_faces=5"):
        load_mesh(data, "stl", max_faces=5)
    with pytest.raises(RetargetError, match=r"has 18 vertices, above max_vertices=17"):
        load_mesh(data, "stl", max_vertices=17)
    with pytest.raises(RetargetError, match=r"has 3 vertices, above max_vertices=2"):
        load_mesh(ASCII_STL.format(name="x").encode(), "stl", max_vertices=2)


# glTF files are built from their JSON: a pyramid of float32 positions and uint32
# indices in one buffer, embedded (.gltf, data: URI) or as the GLB binary chunk.


def gltf_parts(vertices=PYRAMID, faces=PYRAMID_FACES):
    """(glTF JSON as a dict, its one buffer's bytes): one node placing one mesh."""
    positions = np.asarray(vertices, dtype="<f4")
    indices = np.asarray(faces, dtype="<u4")
    blob = positions.tobytes() + indices.tobytes()
    document = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "buffers": [{"byteLength": len(blob)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": positions.nbytes},
            {"buffer": 0, "byteOffset": positions.nbytes, "byteLength": indices.nbytes},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": len(positions),
             "type": "VEC3", "min": positions.min(0).tolist(),
             "max": positions.max(0).tolist()},
            {"bufferView": 1, "componentType": 5125, "count": indices.size,
             "type": "SCALAR"},
        ],
    }
    return document, blob


def gltf_bytes(document, blob):
    """A .gltf with the buffer embedded as a base64 data: URI."""
    document = json.loads(json.dumps(document))
    uri = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
    document["buffers"][0]["uri"] = uri
    return json.dumps(document).encode()


def glb_bytes(document, blob):
    """A GLB: header, JSON chunk, binary chunk (each padded to 4 bytes)."""
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = struct.pack("<I4s", len(text), b"JSON") + text
    body += struct.pack("<I4s", len(blob), b"BIN\0") + blob
    return struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body


def test_hand_built_gltf_and_glb_load():
    document, blob = gltf_parts()
    for data, kind in ((gltf_bytes(document, blob), "gltf"), (glb_bytes(document, blob), "glb")):
        mesh = load_mesh(data, kind)
        np.testing.assert_allclose(mesh.vertices, PYRAMID)
        np.testing.assert_array_equal(mesh.faces, PYRAMID_FACES)


def test_gltf_bytes_with_an_external_buffer_are_refused_by_name(not_parsed):
    document, blob = gltf_parts()
    document["buffers"][0]["uri"] = "mesh.bin"
    message = (
        r"glTF buffer 0 refers to the external file 'mesh.bin'; upload a \.glb or a "
        r"\.gltf with embedded \(data: URI\) buffers"
    )
    with pytest.raises(RetargetError, match=message):
        load_mesh(json.dumps(document).encode(), "gltf")
    with pytest.raises(RetargetError, match=message):
        load_mesh(glb_bytes(document, b""), "glb")


def test_gltf_path_still_reads_a_buffer_beside_it(tmp_path):
    document, blob = gltf_parts()
    document["buffers"][0]["uri"] = "mesh.bin"
    (tmp_path / "mesh.bin").write_bytes(blob)
    path = write(tmp_path, "split.gltf", json.dumps(document))
    np.testing.assert_allclose(load_mesh(path).vertices, PYRAMID)
    (tmp_path / "mesh.bin").write_bytes(blob[:40])
    with pytest.raises(RetargetError, match=r"buffer 0 declares 132 bytes but holds 40"):
        load_mesh(path)


def broken(change):
    """The pyramid glTF with `change(document)` applied."""
    document, blob = gltf_parts()
    change(document)
    return document, blob


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            lambda d: d["bufferViews"][1].update(byteLength=1000),
            r"glTF bufferView 1 spans bytes 60\.\.1,060 of buffer 0, which holds 132 "
            r"bytes",
        ),
        (
            lambda d: d["accessors"][0].update(count=50),
            r"glTF accessor 0 \(50 VEC3 values of 12 bytes, from byte 0 of bufferView "
            r"0\) needs bytes 0\.\.600 of the bufferView, which is 60 bytes long",
        ),
        (
            lambda d: d["accessors"][1].update(byteOffset=8),
            r"glTF accessor 1 \(18 SCALAR values of 4 bytes, from byte 8 of bufferView "
            r"1\) needs bytes 8\.\.80 of the bufferView, which is 72 bytes long",
        ),
        (
            lambda d: d["bufferViews"][0].update(byteStride=16),
            r"glTF accessor 0 .* needs bytes 0\.\.76 of the bufferView, which is 60",
        ),
        (
            lambda d: d["bufferViews"][0].update(byteStride=8),
            r"glTF bufferView 0 has byteStride 8, less than accessor 0's 12-byte values",
        ),
        (
            lambda d: d["bufferViews"][0].update(buffer=3),
            r"glTF bufferView 0 refers to buffer 3, which does not exist",
        ),
        (
            lambda d: d["accessors"][0].update(bufferView=7),
            r"glTF accessor 0 refers to bufferView 7, which does not exist",
        ),
        (
            lambda d: d["accessors"][1].update(componentType=5124),
            r"glTF accessor 1 has componentType 5124, not one of 5120, 5121",
        ),
        (
            lambda d: d["accessors"][1].update(count=0),
            r"glTF accessor 1 has count 0; it must be a whole number of at least 1",
        ),
        (
            lambda d: d["meshes"][0]["primitives"][0].update(indices=9),
            r"glTF mesh 0 primitive 0: its indices refer to accessor 9, which does not",
        ),
        (
            lambda d: d["meshes"][0]["primitives"][0]["attributes"].update(NORMAL=1),
            r"glTF mesh 0 primitive 0: NORMAL \(accessor 1\) must be VEC3, got SCALAR",
        ),
        (
            lambda d: d["meshes"][0]["primitives"][0]["attributes"].pop("POSITION"),
            r"glTF mesh 0 primitive 0 has no POSITION attribute",
        ),
        (
            lambda d: d["accessors"][1].update(count=17),
            r"glTF mesh 0 primitive 0: its indices \(accessor 1\) hold 17 values, not a "
            r"multiple of 3",
        ),
        (
            lambda d: d["nodes"][0].update(mesh=4),
            r"glTF node 0 refers to mesh 4, which does not exist",
        ),
        (
            lambda d: d.update(scene=2),
            r"glTF scene 2 does not exist \(the file has 1 scene\)",
        ),
    ],
)
def test_gltf_layout_is_checked_against_its_buffers(not_parsed, change, message):
    document, blob = broken(change)
    for data, kind in ((gltf_bytes(document, blob), "GLTF"), (glb_bytes(document, blob), "GLB")):
        prefix = rf"could not read the given bytes as {kind}: "
        with pytest.raises(RetargetError, match=prefix + message):
            load_mesh(data, kind)


def test_truncated_glb_is_refused(not_parsed):
    data = glb_bytes(*gltf_parts())
    with pytest.raises(RetargetError, match=r"GLB binary chunk says 132 bytes but 100 follow"):
        load_mesh(data[:-32], "glb")


def test_non_utf8_gltf_json_is_refused(not_parsed):
    data = gltf_bytes(*gltf_parts()).replace(b'"2.0"', b'"2.0\xff"')
    with pytest.raises(RetargetError, match=r"its glTF JSON is not UTF-8 text \(byte \d+\)"):
        load_mesh(data, "gltf")


def instanced_gltf(n_nodes, vertices=PYRAMID, faces=PYRAMID_FACES):
    """One mesh placed by `n_nodes` root nodes, each moved along x."""
    document, blob = gltf_parts(vertices, faces)
    document["nodes"] = [{"mesh": 0, "translation": [i, 0, 0]} for i in range(n_nodes)]
    document["scenes"] = [{"nodes": list(range(n_nodes))}]
    return document, blob


def test_gltf_instancing_is_counted_before_loading(not_parsed):
    # 5,000 nodes placing one 5-vertex mesh: a 200 kB file, 25,000 vertices
    data = gltf_bytes(*instanced_gltf(5000))
    message = (
        r"the given bytes has 25,000 vertices, above max_vertices=10000: its glTF "
        r"scene places 5,000 mesh instances \(mesh 0, of 5 vertices, at 5,000 nodes\)"
    )
    with pytest.raises(RetargetError, match=message):
        load_mesh(data, "gltf", max_vertices=10_000)
    with pytest.raises(RetargetError, match=r"has 30,000 faces, above max_faces=29999"):
        load_mesh(data, "gltf", max_faces=29_999)


def test_gltf_instances_within_the_caps_load():
    mesh = load_mesh(gltf_bytes(*instanced_gltf(3)), "gltf")
    assert (mesh.n_vertices, mesh.n_faces) == (15, 18)


def test_gltf_strip_and_point_primitives_are_counted_as_loaded(not_parsed):
    # a triangle strip of 5 vertices is 3 triangles; points add no triangles
    document, blob = gltf_parts()
    strip = {"attributes": {"POSITION": 0}, "mode": 5}
    points = {"attributes": {"POSITION": 0}, "mode": 0}
    document["meshes"][0]["primitives"] = [strip, points]
    with pytest.raises(RetargetError, match=r"has 3 faces, above max_faces=2"):
        load_mesh(gltf_bytes(document, blob), "gltf", max_faces=2)
    with pytest.raises(RetargetError, match=r"has 5 vertices, above max_vertices=4"):
        load_mesh(gltf_bytes(document, blob), "gltf", max_vertices=4)


@pytest.mark.parametrize(
    ("nodes", "roots", "message"),
    [
        ([{"mesh": 0, "children": [0]}], [0],
         r"glTF node 0 is reached twice from scene 0's roots \(a cycle, or a node with "
         r"two parents\); glTF nodes must form trees"),
        ([{"children": [1, 1]}, {"mesh": 0}], [0], r"glTF node 1 is reached twice"),
        ([{"mesh": 0}], [0, 0], r"glTF node 0 is reached twice"),
        ([{"children": [i + 1]} for i in range(200)] + [{"mesh": 0}], [0],
         r"glTF node 128 is 129 levels deep; at most 128 are read"),
        ([{"children": [5]}], [0], r"glTF node 0 refers to child node 5, which does not"),
        ([{"mesh": 0}], [3], r"glTF scene 0 refers to node 3, which does not exist"),
    ],
)
def test_gltf_node_trees_are_checked(not_parsed, nodes, roots, message):
    document, blob = gltf_parts()
    document["nodes"], document["scenes"] = nodes, [{"nodes": roots}]
    with pytest.raises(RetargetError, match=message):
        load_mesh(glb_bytes(document, blob), "glb")


def test_gltf_node_count_is_capped(not_parsed):
    document, blob = gltf_parts()
    document["nodes"] = [{}] * 10_001
    document["scenes"] = [{"nodes": list(range(10_001))}]
    with pytest.raises(RetargetError, match=r"glTF scene 0 places more than 10,000 nodes"):
        load_mesh(glb_bytes(document, blob), "glb")


def test_gltf_that_would_unpack_far_beyond_its_size_is_refused(not_parsed):
    # an accessor with no bufferView is read as zeros: 10 M MAT4 values from nothing
    document, blob = gltf_parts()
    document["accessors"].append(
        {"componentType": 5126, "count": 10_000_000, "type": "MAT4"}
    )
    message = (
        r"its accessors and bufferViews would unpack 132 bytes of buffers into "
        r"640,000,264 bytes of arrays, above 4 times the buffers plus 64 MiB "
        r"\(bufferViews 132 bytes, accessors 640,000,132; the largest, accessor 2, with "
        r"no bufferView, 640,000,000 bytes\)"
    )
    with pytest.raises(RetargetError, match=message):
        load_mesh(glb_bytes(document, blob), "glb")


def test_gltf_without_a_scene_names_why_nothing_was_read():
    document, blob = gltf_parts()
    del document["scene"], document["scenes"]
    with pytest.raises(RetargetError, match=r"holds no triangle mesh as GLB: it has no scene"):
        load_mesh(glb_bytes(document, blob), "glb")


def test_gltf_node_scale_beyond_the_coordinate_bound_is_refused():
    document, blob = gltf_parts()
    document["nodes"][0]["scale"] = [1e308, 1e308, 1e308]
    message = (
        r"vertex 1 has coordinate x = 1e\+308, beyond the supported ±1e\+09 units; "
        r"rescale the mesh"
    )
    with pytest.raises(RetargetError, match=message):
        load_mesh(glb_bytes(document, blob), "glb")


@pytest.mark.parametrize(
    ("node", "message"),
    [
        ({"scale": [1e999, 1, 1]}, r"glTF node 0 has a non-finite scale \[inf, 1, 1\]"),
        ({"matrix": [float("nan")] + [0] * 15}, r"glTF node 0 has a non-finite matrix"),
        ({"translation": [0, 0]}, r"glTF node 0: translation must be 3 numbers, got \[0, 0\]"),
        ({"rotation": ["a", 0, 0, 1]}, r"glTF node 0: rotation must be 4 numbers"),
    ],
)
def test_gltf_node_transforms_must_be_finite(not_parsed, node, message):
    document, blob = gltf_parts()
    document["nodes"] = [dict(node, mesh=0)]
    text = json.dumps(document, allow_nan=True).encode()  # NaN, Infinity: Python's JSON
    with pytest.raises(RetargetError, match=message):
        load_mesh(text.replace(b'"buffers": [{', b'"buffers": [{"uri": "data:;base64,'
                               + base64.b64encode(blob) + b'", '), "gltf")


def test_mesh_coordinates_beyond_the_bound_are_refused():
    message = r"vertex 2 has coordinate z = -2e\+09, beyond the supported ±1e\+09 units"
    with pytest.raises(RetargetError, match=message):
        mesh_from_arrays(SQUARE + [[0, 0, 0], [0, 0, 0], [0, 0, -2e9], [0, 0, 0]],
                         SQUARE_FACES)
    assert mesh_from_arrays(SQUARE * 1e9, SQUARE_FACES).n_vertices == 4


def test_ply_header_counts_are_checked_before_parsing(not_parsed):
    header = PLY_HEADER.format(n=10**12, f=1, extra="")
    with pytest.raises(RetargetError, match=r"PLY header declares 1,000,000,000,000 "
                       r"vertices, above max_vertices=1000000"):
        load_mesh(header.encode() + b"0 0 0\n", "ply")
    header = PLY_HEADER.format(n=5, f=10**9, extra="")
    with pytest.raises(RetargetError, match=r"PLY header declares 1,000,000,000 faces, "
                       r"above max_faces=2000000"):
        load_mesh(header.encode(), "ply")
    header = PLY_HEADER.format(n=1000, f=1, extra="")
    message = (
        r"PLY header declares 1,000 vertices, which need at least 6,000 bytes, but "
        r"7 bytes follow the header: truncated, or the header is wrong"
    )
    with pytest.raises(RetargetError, match=message):
        load_mesh(header.encode() + b"0 0 0\n\n", "ply")
    binary = PLY_HEADER.replace("ascii", "binary_little_endian").format(n=1000, f=1, extra="")
    with pytest.raises(RetargetError, match=r"1,000 vertices, which need at least 24,000"):
        load_mesh(binary.encode() + bytes(100), "ply")


def test_off_header_counts_are_checked_before_parsing(not_parsed):
    with pytest.raises(RetargetError, match=r"OFF header declares 10,000,000 vertices, "
                       r"above max_vertices=1000000"):
        load_mesh(b"OFF\n# a comment\n10000000 1 0\n0 0 0\n", "off")
    with pytest.raises(RetargetError, match=r"OFF header declares 9 faces, above max_faces=8"):
        load_mesh(b"OFF 3 9 0\n", "off", max_faces=8)


def test_obj_caps_are_checked_before_parsing(not_parsed):
    text = obj_text(PYRAMID, ["1 2 3", "1 3 4", "1 2 5"])
    with pytest.raises(RetargetError, match=r"has 5 vertices, above max_vertices=4"):
        load_mesh(text.encode(), "obj", max_vertices=4)
    with pytest.raises(RetargetError, match=r"has 3 faces, above max_faces=2"):
        load_mesh(text.encode(), "obj", max_faces=2)


def test_non_utf8_off_loads(no_charset_normalizer):
    text = b"OFF\n# caf\xe9\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
    assert load_mesh(text, "off").n_faces == 1


def test_ply_whose_header_is_not_utf8_loads(no_charset_normalizer):
    header = PLY_HEADER.format(n=4, f=2, extra="")
    header = header.replace("end_header", "comment caf\xe9\nend_header")
    body = ply_text(SQUARE, SQUARE_FACES.tolist()).split("end_header\n")[1]
    mesh = load_mesh((header + body).encode("latin-1"), "ply")
    np.testing.assert_array_equal(mesh.vertices, SQUARE)


def test_obj_with_a_byte_order_mark_loads(tmp_path):
    text = "\ufeff" + obj_text(PYRAMID, ["1 2 3", "1 3 4", "1 2 5"])
    mesh = load_mesh(write(tmp_path, "bom.obj", text))
    assert mesh.n_vertices == 5
    np.testing.assert_array_equal(mesh.vertices, PYRAMID)
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4]])


@pytest.mark.parametrize(
    ("faces", "extra", "message"),
    [
        (["1 2 3", "1 3 4", "1 2 0"], "",
         r"line 8: face index 0 \('0'\); OBJ vertex indices start at 1"),
        (["1 2 3", "1/1 3/0 4/1"], "vt 0 0\n",
         r"line 8: face index 0 \('3/0'\); OBJ vertex indices start at 1"),
        (["1 2 3", "  f\t1 -0 2"], "", r"line 7: face index 0 \('-0'\)"),
    ],
)
def test_obj_face_index_zero_is_refused_with_its_line(faces, extra, message):
    lines = "".join(f"{f}\n" if f.lstrip().startswith("f") else f"f {f}\n" for f in faces)
    text = obj_text(PYRAMID, [], extra) + lines
    with pytest.raises(RetargetError, match=message):
        load_mesh(text.encode(), "obj")


def test_obj_indices_ending_in_zero_are_not_index_zero():
    vertices = np.vstack([PYRAMID, PYRAMID + 2])
    text = obj_text(vertices, ["1 2 10", "10 9 8", "-10 -9 -8"])
    assert load_mesh(text.encode(), "obj").faces.tolist() == [[0, 1, 9], [9, 8, 7], [0, 1, 2]]


@pytest.mark.parametrize(
    ("vertices", "faces", "message"),
    [
        ([[1, 2, 3]], [[0, 0, 0]], r"has 1 vertex; a mesh needs at least 3 distinct"),
        ([[1, 2, 3]] * 4, SQUARE_FACES,
         r"all 4 vertices are at one point \(1, 2, 3\); a mesh needs at least 3 distinct"),
        ([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]], SQUARE_FACES,
         r"all 2 triangles have zero area \(their vertices lie on one line\); a mesh "
         r"needs at least one triangle of non-zero area"),
        (SQUARE, [[0, 0, 1], [2, 3, 3]],
         r"all 2 triangles have zero area \(each repeats a vertex or has three "
         r"collinear ones\)"),
    ],
)
def test_degenerate_meshes_are_refused(vertices, faces, message):
    with pytest.raises(RetargetError, match=message):
        mesh_from_arrays(vertices, faces)


def test_all_degenerate_obj_is_refused():
    text = obj_text([[0.5, 0.5, 0.5]] * 4, ["1 2 3", "1 3 4"])
    with pytest.raises(RetargetError, match=r"the given bytes: all 4 vertices are at one"):
        load_mesh(text.encode(), "obj")
    text = obj_text([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], ["1 2 3", "2 3 4"])
    with pytest.raises(RetargetError, match=r"all 2 triangles have zero area"):
        load_mesh(text.encode(), "obj")


def test_some_degenerate_triangles_are_accepted():
    # a scan with a zero-area triangle and a 1e-9 sliver next to a real one
    vertices = np.vstack([SQUARE, [[0.5, 1e-9, 0]]])
    faces = [[0, 1, 4], [0, 0, 1], [0, 1, 2]]
    assert mesh_from_arrays(vertices, faces).n_faces == 3
    # and a mesh far from the origin, or tiny, is judged by its own size
    assert mesh_from_arrays(SQUARE * 1e-6 + 1e6, SQUARE_FACES).n_faces == 2


@pytest.mark.parametrize(
    ("error", "message"),
    [
        (MemoryError(), r"could not read the given bytes as PLY: it needs more memory"),
        (RecursionError("maximum recursion depth exceeded"),
         r"as PLY: it is nested too deeply to read"),
        (OverflowError("int too large"), r"as PLY: a number in it is too large \(int too"),
    ],
)
def test_resource_errors_while_reading_become_retarget_errors(monkeypatch, error, message):
    def broken(*args, **kwargs):
        raise error

    monkeypatch.setattr(trimesh, "load_scene", broken)
    with pytest.raises(RetargetError, match=message):
        load_mesh(b"ply", "ply")


def test_errors_after_reading_become_retarget_errors(monkeypatch):
    import retarget.mesh

    def broken(*args, **kwargs):
        raise MemoryError()

    monkeypatch.setattr(retarget.mesh, "material_from_trimesh", broken)
    with pytest.raises(RetargetError, match=r"as GLB: it needs more memory than"):
        load_mesh(glb_bytes(*gltf_parts()), "glb")


def test_keyboard_interrupt_is_not_swallowed(monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(trimesh, "load_scene", interrupted)
    with pytest.raises(KeyboardInterrupt):
        load_mesh(b"ply", "ply")


def test_gltf_and_glb_are_read_as_what_they_are():
    document, blob = gltf_parts()
    as_glb = load_mesh(glb_bytes(document, blob), "gltf")
    as_gltf = load_mesh(b"\xef\xbb\xbf" + gltf_bytes(document, blob), "glb")  # with a BOM
    for mesh in (as_glb, as_gltf):
        np.testing.assert_allclose(mesh.vertices, PYRAMID)


def test_buffers_without_a_uri_need_a_glb_binary_chunk(not_parsed):
    document, blob = gltf_parts()
    with pytest.raises(RetargetError, match=r"glTF buffer 0 has no uri; a \.gltf must embed"):
        load_mesh(json.dumps(document).encode(), "gltf")
    data = glb_bytes(document, b"")[:-8]  # no binary chunk
    with pytest.raises(RetargetError, match=r"buffer 0 has no uri but the GLB has no binary"):
        load_mesh(data, "glb")
    document["buffers"].append({"byteLength": 4})
    with pytest.raises(RetargetError, match=r"buffer 1 has no uri, but the GLB's one binary "
                       r"chunk is buffer 0's"):
        load_mesh(glb_bytes(document, blob), "glb")


ODD_VALUES = [None, -1, 0, 1.5, "x", [], {}, True, 10**30, [0], float("inf")]


def mutations(document):
    """(path, value) for every leaf and list of `document` and every odd value."""
    def paths(node, at):
        yield at
        items = node.items() if isinstance(node, dict) else enumerate(node) \
            if isinstance(node, list) else ()
        for key, child in items:
            if key != "uri":
                yield from paths(child, at + (key,))
    for at in paths(document, ()):
        if at:
            for value in ODD_VALUES:
                yield at, value


def test_any_odd_gltf_value_gives_a_mesh_or_a_retarget_error():
    document, blob = gltf_parts()
    document["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = 0
    embedded = json.loads(gltf_bytes(document, blob))
    for at, value in mutations(document):
        for original, kind in ((embedded, "gltf"), (document, "glb")):
            changed = json.loads(json.dumps(original))
            parent = changed
            for key in at[:-1]:
                parent = parent[key]
            parent[at[-1]] = value
            text = json.dumps(changed).encode()
            try:
                load_mesh(text if kind == "gltf" else glb_bytes(changed, blob), kind)
            except RetargetError:
                pass


@pytest.mark.parametrize("kind", ["obj", "ply", "stl", "off", "glb", "gltf"])
def test_cut_or_corrupted_files_give_a_mesh_or_a_retarget_error(tmp_path, kind):
    path = tmp_path / f"pyramid.{kind}"
    if kind in ("glb", "gltf"):
        data = (glb_bytes if kind == "glb" else gltf_bytes)(*gltf_parts())
    else:
        trimesh_of(PYRAMID, PYRAMID_FACES).export(path)
        data = path.read_bytes()
    rng = np.random.default_rng(0)
    cases = [data[:n] for n in range(0, len(data), max(1, len(data) // 60))]
    for _ in range(60):
        corrupt = bytearray(data)
        for at in rng.integers(0, len(data), 3):
            corrupt[at] = rng.integers(0, 256)
        cases.append(bytes(corrupt))
    for case in cases:
        try:
            load_mesh(case, kind)
        except RetargetError:
            pass


def test_gltf_bufferviews_that_overlap_many_times_are_refused(not_parsed):
    # 80 bufferViews over one 1 MiB buffer: trimesh copies each, 80 MiB from 1 MiB
    document, blob = gltf_parts()
    blob += bytes(2**20 - len(blob))
    document["buffers"][0]["byteLength"] = len(blob)
    document["bufferViews"] += [{"buffer": 0, "byteLength": len(blob)}] * 80
    message = (
        r"would unpack 1,048,576 bytes of buffers into 83,886,344 bytes of arrays, above 4 "
        r"times the buffers plus 64 MiB \(bufferViews 83,886,212 bytes, accessors 132; the "
        r"largest, accessor 1, 72 bytes\)"
    )
    with pytest.raises(RetargetError, match=message):
        load_mesh(glb_bytes(document, blob), "glb")
