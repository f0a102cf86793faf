"""glTF export (retarget.gltf): structure, the Khronos validator, glTF's own skinning and
morphing evaluated from the file against `skin_displacements`, and the round trip.

What a glTF viewer computes from the file (node hierarchy, animation sampling, inverse
bind matrices, JOINTS/WEIGHTS, morph targets) is evaluated by `retarget.gltf.animation`,
which shares no code with the exporter, and must be Dutreve's ``v0 + W d``.
"""

from __future__ import annotations

import functools
import io
from pathlib import Path

import numpy as np
import pytest
import trimesh

from retarget.errors import RetargetError
from retarget.clips import Clip, clip_at_rate
from retarget.performance import take_clip
from retarget.gltf import export_gltf, export_mesh_gltf, joint_names, read_gltf
from retarget.gltf.influences import is_joint_based, joint_influences
from retarget.gltf.animation import (animated_weights, animation_channels, mesh_instances,
                                       node_transforms, posed_vertices)
from retarget.gltf.document import GltfDocument
from retarget.landmarks import from_vertex_indices
from retarget.layouts import get_layout
from retarget.mesh import mesh_from_arrays
from retarget.sample_face import demo_weights, sample_face
from retarget.sample_face import posed_vertices as face_vertices
from retarget.skin import SkinWeights, skin_displacements
from retarget.sources.take import Take
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
    posed = face_vertices(f, demo_weights(45, FPS))[:, f.landmarks68]
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
# what a glTF viewer draws: retarget.gltf.animation, the glTF 2.0 specification's morphing
# and skinning (§3.7) and animation sampling (§3.11), written to read animated takes. It
# shares no code with the exporter (GltfDocument parses, GlbBuilder writes), so it checks
# the file, not the exporter's own idea of it; three.js (tests/e2e/test_export_threejs.py)
# and Blender (tests/unit/test_blender.py) check it again.


@functools.lru_cache(maxsize=8)
def _load(path) -> GltfDocument:
    """The parsed file (cached: each test writes its own paths and never rewrites one)."""
    return GltfDocument(Path(path).read_bytes(), Path(path).name, None)


@functools.lru_cache(maxsize=8)
def _instance(path) -> dict:
    (instance,) = mesh_instances(_load(path))
    return instance


def _file_scale(path) -> float:
    """What the export multiplied every length by (``extras.retarget.scale``: 0.01 for the
    sample face, in centimetres, exported in metres)."""
    return _load(path).doc.scenes[0].extras["retarget"]["scale"]


def _sample(times, values, t) -> np.ndarray:
    """LINEAR sampling of (F, k) keyed `values` at time t (clamped at the ends)."""
    return np.array([np.interp(t, times, values[:, c]) for c in range(values.shape[1])])


def _gltf_vertices(path, animation: int, t: float) -> np.ndarray:
    """(V, 3) float64 positions a glTF viewer draws at time t of an animation, in the
    mesh's units (the file's over its scale)."""
    gltf, instance = _load(path), _instance(path)
    channels = animation_channels(gltf, gltf.doc.animations[animation])
    times = np.array([t], dtype=np.float64)
    world = node_transforms(gltf, gltf.doc.nodes, channels, times)
    rows = np.arange(len(instance["positions"]))
    return posed_vertices(gltf, instance, rows, world, animated_weights(gltf, channels, times),
                          times)[0] / _file_scale(path)


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
    gltf = _load(exported["ellipsoid"])
    doc, n = gltf.doc, face["points"].n_points
    nodes, skin = doc.nodes, doc.skins[0]
    assert [nodes[j].name for j in skin.joints] == ["root"] + list(IBUG.point_names)
    assert nodes[skin.joints[0]].children == skin.joints[1:]
    assert all(node.rotation is None and node.scale is None and node.matrix is None
               for node in nodes)  # translation-only joints
    neutral = face["points"].positions(face["mesh"].vertices)
    joints_at = np.array([nodes[j].translation for j in skin.joints[1:]])
    assert _file_scale(exported["ellipsoid"]) == 0.01  # centimetres to metres
    np.testing.assert_allclose(joints_at, 0.01 * neutral, atol=1e-7)
    ibm = gltf.accessor(skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
    np.testing.assert_array_equal(ibm[0], np.eye(4))
    np.testing.assert_array_equal(ibm[1:, :3, 3], -joints_at.astype(np.float32))
    attributes = {k: v for k, v in vars(doc.meshes[0].primitives[0].attributes).items()
                  if v is not None}
    # rows with four features sum to 1 (to float32 rounding): the root gets no share and
    # one set of four holds every vertex, the one set three.js reads
    assert sorted(a for a in attributes if a[:7] in ("JOINTS_", "WEIGHTS")) == ["JOINTS_0", "WEIGHTS_0"]
    assert (face["rigs"]["ellipsoid"].weights != 0).sum(1).max() == 4
    assert doc.accessors[attributes["JOINTS_0"]].componentType == 5121  # 69 joints: bytes
    w = gltf.accessor(attributes["WEIGHTS_0"])
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-6)
    assert (w >= 0).all()
    anim = doc.animations[0]
    assert anim.name == "demo" and len(anim.channels) == n
    assert {sampler.interpolation for sampler in anim.samplers} == {"LINEAR"}
    times = gltf.accessor(anim.samplers[0].input)[:, 0]
    np.testing.assert_allclose(times, np.arange(30) / FPS, rtol=1e-6)


def test_morph_structure(face, exported):
    gltf = _load(exported["rbf"])
    gmesh, n = gltf.doc.meshes[0], face["points"].n_points
    targets = gmesh.primitives[0].targets
    assert not gltf.doc.skins and len(targets) == 3 * n
    assert gmesh.extras["targetNames"][:4] == \
        [f"{IBUG.point_names[0]}.{a}" for a in "xyz"] + [f"{IBUG.point_names[1]}.x"]
    # target (i, y) is feature i's weights along y only, times a power of two that puts
    # the animated weights (displacements over it) within [-1, 1]
    scale = gmesh.extras["targetScale"]
    largest = _file_scale(exported["rbf"]) * max(np.abs(c.displacements).max() for c in face["clips"])
    assert largest <= scale < 2 * largest and np.log2(scale) % 1 == 0
    dense = face["rigs"]["rbf"].dense()
    target = gltf.accessor(targets[3 * 5 + 1]["POSITION"])
    np.testing.assert_array_equal(target[:, [0, 2]], 0)
    np.testing.assert_allclose(target[:, 1], scale * dense[:, 5], atol=1e-7)
    largest_weight = max(
        np.abs(gltf.accessor(a.samplers[a.channels[-1].sampler].output)).max()
        for a in gltf.doc.animations)
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
    # exported in metres, read back in centimetres: to float32 rounding (one ulp)
    assert back.units == "cm"
    np.testing.assert_allclose(back.mesh.vertices, mesh.vertices, rtol=2.4e-7, atol=0)
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
        doc = _load(path).doc
        primitive = doc.meshes[0].primitives[0]
        if name == "short":
            assert doc.accessors[primitive.attributes.JOINTS_0].componentType == 5123
        else:
            stored = [doc.accessors[t["POSITION"]] for t in primitive.targets]
            assert all(a.sparse is not None or a.bufferView is None for a in stored)
            assert any(a.bufferView is None and a.sparse is None for a in stored)
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
    # rows that miss 1 by float32 rounding, above or below, are scaled to 1: no root share
    ulp = SkinWeights(np.array([[0, 1], [0, 1]], np.int32),
                      np.array([[0.5, 0.50000006], [0.5, 0.49999997]], np.float32), 2)
    joints, influence = joint_influences(ulp)
    assert joints.tolist() == [[1, 2, 0, 0]] * 2 and not influence[:, 2:].any()
    np.testing.assert_allclose(influence.sum(1, dtype=np.float64), 1.0, atol=1e-7)
    # five features, or four and a root share, need a second set
    five = SkinWeights(np.array([[0, 1, 2, 3, 4], [0, 1, 2, 3, 0]], np.int32),
                       np.array([[0.2] * 5, [0.2] * 4 + [0.0]], np.float32), 5)
    joints, influence = joint_influences(five)
    assert joints.tolist() == [[1, 2, 3, 4, 5, 0, 0, 0], [1, 2, 3, 4, 0, 0, 0, 0]]
    np.testing.assert_allclose(influence[1, :5], [0.2, 0.2, 0.2, 0.2, 0.2], rtol=1e-6)


def test_morph_targets_of_another_kind_are_refused():
    from retarget.gltf.morph import weights_from_targets

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


def test_mesh_alone_loads_back_as_the_same_mesh(face, tmp_path):
    """export_mesh_gltf: what load_mesh reads back is the mesh (order, uv, normals, material)."""
    from PIL import Image

    from retarget.material import Material
    from retarget.mesh import load_mesh

    plain = face["mesh"]
    png = io.BytesIO()
    Image.new("RGB", (4, 4), (10, 200, 30)).save(png, format="PNG")
    box = trimesh.creation.box()
    textured = mesh_from_arrays(
        box.vertices, box.faces, uv=np.random.default_rng(2).uniform(0, 1, (8, 2)),
        normals=box.vertex_normals, name="box",
        material=Material(name="skin", base_color=(0.5, 0.25, 1.0, 1.0), metallic=0.0,
                          roughness=0.5, double_sided=True, base_color_texture=png.getvalue()))
    for mesh in (plain, textured):
        path = tmp_path / f"{mesh.name}.glb"
        path.write_bytes(export_mesh_gltf(mesh))
        report = assert_valid_gltf(path)
        assert report["info"]["animationCount"] == 0 and not report["info"]["hasSkins"]
        back = load_mesh(path)
        np.testing.assert_array_equal(back.vertices, mesh.vertices.astype(np.float32))
        np.testing.assert_array_equal(back.faces, mesh.faces)
        np.testing.assert_allclose(back.uv, mesh.uv, atol=1e-6)
        assert back.name == mesh.name
    # uv without a material: glTF's default material carries them
    assert load_mesh(tmp_path / "sample_face.glb").material == Material()
    np.testing.assert_allclose(back.normals, textured.normals, atol=1e-6)
    assert back.material.name == "skin" and back.material.double_sided
    # trimesh keeps the colour factor in 8 bits
    np.testing.assert_allclose(back.material.base_color, textured.material.base_color, atol=1 / 255)
    assert Image.open(io.BytesIO(back.material.base_color_texture)).getpixel((1, 1)) == (10, 200, 30)


def _performance(face, seconds_between):
    """A take of the target's own landmarks performing the fixture's clip: a rest frame,
    then T0 + d_f, at the given gaps (s); and those d_f (F, 68, 3)."""
    rest = face["points"].positions(face["mesh"].vertices)
    d = np.concatenate([np.zeros((1, 68, 3)), face["clips"][0].displacements])
    times = np.concatenate([[0.0], np.cumsum(seconds_between[:len(d) - 1])])
    take = Take(rest + d, IBUG.point_names, FPS, times=times, layout="ibug68", source="test")
    return take, d, times


def test_a_take_retargeted_onto_its_own_face_is_its_motion(face):
    """take_clip: a take of the target's own feature points, its neutral the first frame,
    retargets to exactly its own displacements (the space transform of S0 = T0 is the
    identity) at the take's own times; a region mask keeps the other points still."""
    gaps = np.random.default_rng(3).uniform(0.02, 0.05, 40)
    take, d, times = _performance(face, gaps)
    settings = {"neutral": {"mode": "frame", "frame": 0}, "head_pose": "keep", "filter": "none"}
    rest = face["points"].positions(face["mesh"].vertices)
    clip = take_clip("own", take, rest, "ibug68", settings)
    assert clip.name == "own" and clip.n_frames == len(d)
    np.testing.assert_allclose(clip.times, times, rtol=1e-12)
    np.testing.assert_allclose(clip.displacements, d, atol=1e-5 * face["size"])
    assert np.abs(d).max() > 0.05  # the take does move
    mouth = IBUG.region_mask("mouth")
    partial = take_clip("mouth", take, rest, "", settings, regions=["mouth"])
    np.testing.assert_allclose(partial.displacements[:, mouth], d[:, mouth], atol=1e-5 * face["size"])
    assert not partial.displacements[:, ~mouth].any()
    # the default conditioning takes the neutral from the first 0.5 s and keeps every frame
    default = take_clip("default", take, rest, "ibug68")
    np.testing.assert_allclose(default.times, times, atol=1e-12)
    with pytest.raises(RetargetError, match="ends before its neutral capture"):
        take_clip("short", take, rest, "ibug68", {"neutral": {"mode": "first_seconds", "seconds": 5.0}})
