"""Tests for retarget.mesh: loading each format, the refusals, save/load round trips.

Every file is written into tmp_path by hand or by trimesh; no external data.
"""

import io

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

