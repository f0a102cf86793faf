"""glTF export (retarget.export): structure, the Khronos validator, glTF's own skinning and
morphing evaluated in numpy from the file against `skin_displacements`, and the round trip.

The glTF evaluator here parses the GLB and decodes accessors itself, so it shares no code
with the exporter or our reader: it checks that what a glTF viewer computes from the file (node hierarchy, animation sampling, inverse bind matrices, JOINTS/WEIGHTS,
morph targets) is Dutreve's ``v0 + W d``.
"""

from __future__ import annotations

import functools
import io
import json
import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh

from retarget.errors import RetargetError
from retarget.export import Clip, clip_at_rate, export_gltf, joint_names, read_gltf
from retarget.export.influences import is_joint_based, joint_influences
from retarget.landmarks import from_vertex_indices
from retarget.layouts import get_layout
from retarget.mesh import mesh_from_arrays
from retarget.sample_face import demo_weights, posed_vertices, sample_face
from retarget.skin import SkinWeights, skin_displacements
from retarget.weights import compute_weights
from tests.gltf_check import assert_valid_gltf

FPS = 30.0
IBUG = get_layout("ibug68")


@pytest.fixture(scope="module")
def face():
    """The sample face (uv, no normals), its landmarks, two rigs and two clips."""
    f = sample_face(1)
    mesh = mesh_from_arrays(f.vertices, f.faces, uv=f.uv, name="sample_face")
    points = from_vertex_indices(f.landmarks68, mesh.n_vertices, "ibug68")
    posed = posed_vertices(f, demo_weights(45, FPS))[:, f.landmarks68]
    d = (posed - f.vertices[f.landmarks68]).astype(np.float32)
    clips = [clip_at_rate("demo", d[:30], FPS),
             Clip("uneven", d[30:], np.cumsum(np.linspace(0.02, 0.06, 15)))]
    rigs = {m: compute_weights(m, mesh.vertices, mesh.faces, points, IBUG)
            for m in ("ellipsoid", "rbf")}
    return {"mesh": mesh, "points": points, "rigs": rigs, "clips": clips,
            "size": float(np.linalg.norm(np.ptp(f.vertices, axis=0)))}


@pytest.fixture(scope="module")
def exported(face, tmp_path_factory):
    """The face exported with each rig and both clips: {method: path}."""
    d = tmp_path_factory.mktemp("gltf")
    paths = {}
    for method, weights in face["rigs"].items():
        paths[method] = d / f"{method}.glb"
        paths[method].write_bytes(export_gltf(face["mesh"], face["points"], weights, face["clips"]))
    return paths


# ---------------------------------------------------------------------------------------
# an independent glTF evaluator (pygltflib + numpy)

_DTYPES = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


@functools.lru_cache(maxsize=8)
def _load(path) -> tuple[dict, bytes]:
    """(glTF JSON, BIN chunk) of a GLB, parsed here from the spec's layout (cached: each
    test writes its own paths and never rewrites one)."""
    data = Path(path).read_bytes()
    magic, version, total = struct.unpack_from("<4sII", data)
    assert (magic, version, total) == (b"glTF", 2, len(data))
    json_length, json_type = struct.unpack_from("<II", data, 12)
    bin_at = 20 + json_length
    bin_length, bin_type = struct.unpack_from("<II", data, bin_at)
    assert (json_type, bin_type) == (0x4E4F534A, 0x004E4942)
    return json.loads(data[20:bin_at]), data[bin_at + 8:bin_at + 8 + bin_length]


def _elements(doc, blob, view_index, dtype, width, count, offset=0) -> np.ndarray:
    view = doc["bufferViews"][view_index]
    assert "byteStride" not in view
    start = view.get("byteOffset", 0) + offset
    return np.frombuffer(blob, dtype, count * width, start).reshape(count, width)


def _accessor(doc, blob, index) -> np.ndarray:
    a = doc["accessors"][index]
    dtype, width = _DTYPES[a["componentType"]], _WIDTH[a["type"]]
    if "bufferView" not in a:
        out = np.zeros((a["count"], width), dtype)
    else:
        out = _elements(doc, blob, a["bufferView"], dtype, width, a["count"],
                        a.get("byteOffset", 0)).copy()
    if "sparse" in a:
        sparse = a["sparse"]
        rows = _elements(doc, blob, sparse["indices"]["bufferView"],
                         _DTYPES[sparse["indices"]["componentType"]], 1, sparse["count"])[:, 0]
        out[rows] = _elements(doc, blob, sparse["values"]["bufferView"], dtype, width,
                              sparse["count"])
    return out


def _sample(times, values, t) -> np.ndarray:
    """LINEAR glTF sampling of (F, k) keyed `values` at time t (clamped at the ends)."""
    return np.array([np.interp(t, times, values[:, c]) for c in range(values.shape[1])])


def _gltf_vertices(path, animation: int, t: float) -> np.ndarray:
    """(V, 3) float64 positions a glTF viewer draws at time t of an animation."""
    doc, blob = _load(path)
    nodes = doc["nodes"]
    translation = {i: np.array(n.get("translation", (0.0, 0.0, 0.0))) for i, n in enumerate(nodes)}
    assert not any(key in n for n in nodes for key in ("rotation", "scale", "matrix"))
    mesh_node = next(i for i, n in enumerate(nodes) if "mesh" in n)
    gmesh = doc["meshes"][nodes[mesh_node]["mesh"]]
    morph = np.array(gmesh.get("weights", []), dtype=np.float64)
    anim = doc["animations"][animation]
    for channel in anim["channels"]:
        sampler = anim["samplers"][channel["sampler"]]
        assert sampler["interpolation"] == "LINEAR"
        times = _accessor(doc, blob, sampler["input"])[:, 0]
        values = _accessor(doc, blob, sampler["output"]).astype(np.float64)
        target = channel["target"]
        if target["path"] == "translation":
            translation[target["node"]] = _sample(times, values, t)
        else:
            assert target["path"] == "weights" and target["node"] == mesh_node
            morph = _sample(times, values.reshape(len(times), -1), t)
    parent = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}

    def world(i):
        m = np.eye(4)
        m[:3, 3] = translation[i]
        return world(parent[i]) @ m if i in parent else m

    primitive = gmesh["primitives"][0]
    attributes = primitive["attributes"]
    v = _accessor(doc, blob, attributes["POSITION"]).astype(np.float64)
    for k, target in enumerate(primitive.get("targets", [])):
        v = v + morph[k] * _accessor(doc, blob, target["POSITION"])
    if "skin" not in nodes[mesh_node]:
        return v @ world(mesh_node)[:3, :3].T + world(mesh_node)[:3, 3]
    skin = doc["skins"][nodes[mesh_node]["skin"]]
    ibm = _accessor(doc, blob, skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
    matrices = np.stack([world(j) @ ibm[k] for k, j in enumerate(skin["joints"])])
    out = np.zeros_like(v)
    for s in range(len([a for a in attributes if a.startswith("JOINTS_")])):
        j = _accessor(doc, blob, attributes[f"JOINTS_{s}"]).astype(np.int64)
        w = _accessor(doc, blob, attributes[f"WEIGHTS_{s}"]).astype(np.float64)
        for c in range(4):
            m = matrices[j[:, c]]
            out += w[:, c, None] * (np.einsum("vij,vj->vi", m[:, :3, :3], v) + m[:, :3, 3])
    return out


def _expected(face, weights, clip, t) -> np.ndarray:
    """v0 + W d(t), d linearly interpolated between the clip's frames."""
    d = clip.displacements.reshape(clip.n_frames, -1).astype(np.float64)
    d_t = _sample(clip.times, d, t).reshape(-1, 3)
    return face["mesh"].vertices + skin_displacements(weights, d_t)


# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["ellipsoid", "rbf"])
def test_exports_pass_the_khronos_validator(exported, method):
    report = assert_valid_gltf(exported[method])
    info = report["info"]
    assert info["animationCount"] == 2 and info["totalVertexCount"] == 8430
    assert info["hasSkins"] == (method == "ellipsoid")
    assert info["hasMorphTargets"] == (method == "rbf")


def test_skin_structure(face, exported):
    doc, blob = _load(exported["ellipsoid"])
    nodes, n = doc["nodes"], face["points"].n_points
    skin = doc["skins"][0]
    assert [nodes[j]["name"] for j in skin["joints"]] == ["root"] + list(IBUG.point_names)
    assert nodes[skin["joints"][0]]["children"] == skin["joints"][1:]
    neutral = face["points"].positions(face["mesh"].vertices)
    joints_at = np.array([nodes[j]["translation"] for j in skin["joints"][1:]])
    np.testing.assert_allclose(joints_at, neutral, atol=1e-5)
    ibm = _accessor(doc, blob, skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
    np.testing.assert_array_equal(ibm[0], np.eye(4))
    np.testing.assert_array_equal(ibm[1:, :3, 3], -joints_at.astype(np.float32))
    attributes = doc["meshes"][0]["primitives"][0]["attributes"]
    # four features + the root need two sets of four
    assert sorted(a for a in attributes if a[:7] in ("JOINTS_", "WEIGHTS")) == \
        ["JOINTS_0", "JOINTS_1", "WEIGHTS_0", "WEIGHTS_1"]
    assert doc["accessors"][attributes["JOINTS_0"]]["componentType"] == 5121  # 69 joints: bytes
    w = np.hstack([_accessor(doc, blob, attributes[f"WEIGHTS_{s}"]) for s in (0, 1)])
    np.testing.assert_allclose(w.astype(np.float64).sum(1), 1.0, atol=1e-6)
    assert (w >= 0).all()
    anim = doc["animations"][0]
    assert anim["name"] == "demo" and len(anim["channels"]) == n
    times = _accessor(doc, blob, anim["samplers"][0]["input"])[:, 0]
    np.testing.assert_allclose(times, np.arange(30) / FPS, rtol=1e-6)


def test_morph_structure(face, exported):
    doc, blob = _load(exported["rbf"])
    gmesh, n = doc["meshes"][0], face["points"].n_points
    targets = gmesh["primitives"][0]["targets"]
    assert "skins" not in doc and len(targets) == 3 * n
    assert gmesh["extras"]["targetNames"][:4] == \
        [f"{IBUG.point_names[0]}.{a}" for a in "xyz"] + [f"{IBUG.point_names[1]}.x"]
    # target (i, y) is feature i's weights along y only, times a power of two that puts
    # the animated weights (displacements over it) within [-1, 1]
    scale = gmesh["extras"]["targetScale"]
    largest = max(np.abs(c.displacements).max() for c in face["clips"])
    assert largest <= scale < 2 * largest and np.log2(scale) % 1 == 0
    dense = face["rigs"]["rbf"].dense()
    target = _accessor(doc, blob, targets[3 * 5 + 1]["POSITION"])
    np.testing.assert_array_equal(target[:, [0, 2]], 0)
    np.testing.assert_allclose(target[:, 1], scale * dense[:, 5], atol=1e-7)
    largest_weight = max(
        np.abs(_accessor(doc, blob, a["samplers"][a["channels"][-1]["sampler"]]["output"])).max()
        for a in doc["animations"])
    assert 0.5 < largest_weight <= 1


@pytest.mark.parametrize("method", ["ellipsoid", "rbf"])
def test_gltf_deformation_is_linear_blend_skinning(face, exported, method):
    """What a viewer draws at key times and between keys is v0 + W d(t)."""
    weights = face["rigs"][method]
    for animation, clip in enumerate(face["clips"]):
        between = 0.5 * (clip.times[:-1] + clip.times[1:])
        for t in (clip.times[0], clip.times[7], between[3], between[-1], clip.times[-1]):
            got = _gltf_vertices(exported[method], animation, t)
            err = np.abs(got - _expected(face, weights, clip, t)).max()
            assert err < 1e-5 * face["size"], (method, animation, t, err)
    # the test is not vacuous: the face does move
    clip = face["clips"][0]
    assert np.abs(_expected(face, weights, clip, clip.times[-1]) - face["mesh"].vertices).max() > 0.05


@pytest.mark.parametrize("method", ["ellipsoid", "rbf"])
def test_round_trip(face, exported, method):
    back = read_gltf(exported[method])
    mesh, weights = face["mesh"], face["rigs"][method]
    assert back.deformation == ("skin" if method == "ellipsoid" else "morph")
    np.testing.assert_array_equal(back.mesh.vertices, mesh.vertices.astype(np.float32))
    np.testing.assert_array_equal(back.mesh.faces, mesh.faces)
    np.testing.assert_allclose(back.mesh.uv, mesh.uv, atol=1e-6)
    assert back.mesh.normals is None and back.mesh.name == "sample_face"
    np.testing.assert_array_equal(back.points.vertex_indices, face["points"].vertex_indices)
    assert back.points.layout == "ibug68" and back.joint_names == tuple(IBUG.point_names)
    assert back.weights.n_joints == weights.n_joints and back.weights.method == method
    assert back.weights.n_influences == weights.n_influences
    np.testing.assert_allclose(back.weights.dense(), weights.dense(), atol=1e-6)
    assert [c.name for c in back.clips] == ["demo", "uneven"]
    for got, clip in zip(back.clips, face["clips"]):
        np.testing.assert_allclose(got.times, clip.times, rtol=1e-6)
        np.testing.assert_allclose(got.displacements, clip.displacements, atol=1e-5)


def test_unit_normals_and_a_file_object(face, tmp_path):
    """Normals are normalised (a zero one gets the surface's); bytes and file objects read."""
    box = trimesh.creation.box()
    normals = 3.0 * np.asarray(box.vertex_normals)
    normals[0] = 0.0
    mesh = mesh_from_arrays(box.vertices, box.faces, normals=normals, name="box")
    points = from_vertex_indices([0, 5], mesh.n_vertices)
    weights = SkinWeights.from_dense(np.where(np.arange(8)[:, None] == [0, 5], 0.6, 0.0))
    clip = clip_at_rate("nod", np.ones((3, 2, 3), np.float32) * [[[0.0, 0.2, 0.0]]], 24.0)
    path = tmp_path / "box.glb"
    data = export_gltf(mesh, points, weights, [clip])
    path.write_bytes(data)
    assert_valid_gltf(path)
    back = read_gltf(io.BytesIO(data))
    assert back.joint_names == ("feature_00", "feature_01")
    np.testing.assert_allclose(np.linalg.norm(back.mesh.normals, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(back.mesh.normals[1:], box.vertex_normals[1:], atol=1e-6)
    np.testing.assert_allclose(back.mesh.normals[0], box.vertex_normals[0], atol=1e-6)
    np.testing.assert_allclose(read_gltf(data).clips[0].times, np.arange(3) / 24.0, rtol=1e-6)


def test_many_joints_and_a_sparse_morph_rig(tmp_path):
    """260 features (JOINTS as unsigned shorts), then the same rig with one negative weight
    (morph targets, stored sparse, one all-zero feature): valid, and read back exactly."""
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=10.0)  # 2562 vertices
    mesh = mesh_from_arrays(sphere.vertices, sphere.faces)
    rng = np.random.default_rng(0)
    joints = rng.choice(mesh.n_vertices, 260, replace=False)
    points = from_vertex_indices(joints, mesh.n_vertices)
    near = np.argsort(np.linalg.norm(mesh.vertices[:, None] - mesh.vertices[joints][None], axis=2), 1)[:, :3]
    w = rng.uniform(0.1, 0.3, near.shape).astype(np.float32)
    weights = SkinWeights(near.astype(np.int32), w, 260, "random")
    d = rng.normal(0, 0.2, (4, 260, 3)).astype(np.float32)
    clip = clip_at_rate("noise", d, FPS)
    signed = np.where(np.arange(3) == 2, -w, w)
    signed[near == 7] = 0.0  # feature 7 moves nothing
    for name, rig in (("short", weights),
                      ("morph", SkinWeights(near.astype(np.int32), signed, 260, "signed"))):
        path = tmp_path / f"{name}.glb"
        path.write_bytes(export_gltf(mesh, points, rig, [clip]))
        assert_valid_gltf(path)
        doc, _ = _load(path)
        primitive = doc["meshes"][0]["primitives"][0]
        if name == "short":
            assert doc["accessors"][primitive["attributes"]["JOINTS_0"]]["componentType"] == 5123
        else:
            stored = [doc["accessors"][t["POSITION"]] for t in primitive["targets"]]
            assert all("sparse" in a or "bufferView" not in a for a in stored)
            assert any("bufferView" not in a and "sparse" not in a for a in stored)
        back = read_gltf(path)
        np.testing.assert_allclose(back.weights.dense(), rig.dense(), atol=1e-7)
        got = _gltf_vertices(path, 0, clip.times[2])
        np.testing.assert_allclose(got, mesh.vertices + skin_displacements(rig, d[2]), atol=1e-5 * 20.0)


def test_joint_based_rigs(face):
    assert is_joint_based(face["rigs"]["ellipsoid"])
    assert not is_joint_based(face["rigs"]["rbf"])
    with pytest.raises(RetargetError, match="morph targets"):
        joint_influences(face["rigs"]["rbf"])
    twice = SkinWeights(np.array([[3, 3]], np.int32), np.array([[0.2, 0.3]], np.float32), 5)
    with pytest.raises(RetargetError, match="vertex 0 name feature 3 twice"):
        joint_influences(twice)
    # rows that overshoot 1 by float32 rounding are scaled to 1: no root share
    ulp = SkinWeights(np.array([[0, 1]], np.int32), np.array([[0.5, 0.50000006]], np.float32), 2)
    joints, influence = joint_influences(ulp)
    assert joints[0].tolist() == [1, 2, 0, 0] and influence[0, 2:].tolist() == [0, 0]


def test_morph_targets_of_another_kind_are_refused():
    from retarget.export.morph import weights_from_targets

    unit = [np.eye(3)[a] * np.array([[0.5], [0.0]]) for a in range(3)]
    assert weights_from_targets(unit, 1).dense().tolist() == [[0.5], [0.0]]
    with pytest.raises(RetargetError, match="morph target 1 is not feature 0's weights along axis y"):
        weights_from_targets([unit[0], unit[1] + [[0.1, 0, 0]], unit[2]], 1)
    with pytest.raises(RetargetError, match="2 morph targets for 1 features"):
        weights_from_targets(unit[:2], 1)


def test_joint_names(face):
    assert joint_names(face["points"]) == list(IBUG.point_names)
    plain = from_vertex_indices(np.arange(120), face["mesh"].n_vertices)
    assert joint_names(plain)[:2] == ["feature_000", "feature_001"]


def test_export_refusals(face):
    mesh, points, weights = face["mesh"], face["points"], face["rigs"]["ellipsoid"]
    fewer = from_vertex_indices(face["points"].vertex_indices[:10, 0], mesh.n_vertices)
    with pytest.raises(RetargetError, match="68 joints but there are 10 landmarks"):
        export_gltf(mesh, fewer, weights)
    small = mesh_from_arrays(mesh.vertices[:3], [[0, 1, 2]])
    with pytest.raises(RetargetError, match="8430 vertices but the mesh has 3"):
        export_gltf(small, points, weights)
    with pytest.raises(RetargetError, match="moves 2 features but there are 68"):
        export_gltf(mesh, points, weights, [clip_at_rate("x", np.zeros((2, 2, 3)), FPS)])
    with pytest.raises(RetargetError, match="strictly increasing"):
        Clip("x", np.zeros((2, 68, 3)), [0.0, 0.0])
    with pytest.raises(RetargetError, match="fps must be a positive number"):
        clip_at_rate("x", np.zeros((2, 68, 3)), 0.0)


def test_reader_refusals(tmp_path):
    with pytest.raises(RetargetError, match="is not a GLB file"):
        read_gltf(b"solid ascii stl")
    with pytest.raises(RetargetError, match="does not exist|No such file"):
        read_gltf(tmp_path / "missing.glb")
    plain = trimesh.creation.box().export(file_type="glb")
    with pytest.raises(RetargetError, match="one root node holding the feature joints"):
        read_gltf(plain)
    with pytest.raises(RetargetError, match="truncated"):
        read_gltf(plain[:-40])


def test_a_glb_upload_keeps_its_material_uv_and_normals(tmp_path):
    """A textured glTF upload (load_mesh) exports with its material, image, uv and normals."""
    from PIL import Image

    from retarget.mesh import load_mesh

    box = trimesh.creation.box()
    image = Image.new("RGB", (8, 4), (200, 30, 10))
    material = trimesh.visual.material.PBRMaterial(
        name="skin", baseColorFactor=[0.8, 0.6, 0.4, 1.0], metallicFactor=0.0,
        roughnessFactor=0.7, baseColorTexture=image, doubleSided=True)
    uv = np.random.default_rng(1).uniform(0, 1, (len(box.vertices), 2))
    box.visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    box.vertex_normals  # noqa: B018 - computed here so the upload carries NORMAL
    mesh = load_mesh(box.export(file_type="glb"), "glb")
    assert mesh.material is not None and mesh.normals is not None
    assert mesh.material.name == "skin" and mesh.material.double_sided
    np.testing.assert_allclose(mesh.material.base_color, [0.8, 0.6, 0.4, 1.0], atol=1 / 255)
    points = from_vertex_indices([0, 3], mesh.n_vertices)
    weights = SkinWeights.from_dense(np.where(np.arange(8)[:, None] == [0, 3], 0.5, 0.0))
    path = tmp_path / "textured.glb"
    path.write_bytes(export_gltf(mesh, points, weights))
    report = assert_valid_gltf(path)
    assert report["info"]["materialCount"] == 1 and report["info"]["hasTextures"]
    back = read_gltf(path)
    assert back.mesh.material == mesh.material
    assert Image.open(io.BytesIO(back.mesh.material.base_color_texture)).getpixel((3, 2)) == (200, 30, 10)
    np.testing.assert_allclose(back.mesh.uv, mesh.uv, atol=1e-6)
    np.testing.assert_allclose(back.mesh.normals, mesh.normals, atol=1e-6)
