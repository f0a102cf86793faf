"""Blender imports our glTF export: the armature, vertex groups, shape keys, animation and
material, and the positions Blender evaluates equal our linear blend skinning; the muscle
export (morph targets per muscle and a jaw joint) plays as glTF defines it, and the ARKit
export (52 named morph targets in sparse accessors) as `ArkitShapes.posed`.

Blender runs as a Python module (PyPI ``bpy``) in its own interpreter, ``.venv-blender``
beside ``.venv`` (or the one named by ``RETARGET_BLENDER_PYTHON``), because bpy 5.0 needs
numpy < 2 (see tests/blender/requirements.txt); tests/blender/evaluate_glb.py does the
Blender side in a subprocess. A missing interpreter fails the tests with the command
that makes it.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from retarget.arkit.clip import ArkitClip
from retarget.arkit.reference import ARKIT_NAMES
from retarget.arkit.shapes import arkit_shapes
from retarget.clips import ContractionClip, clip_at_rate

from retarget.gltf import export_arkit_gltf, export_gltf, export_muscles_gltf, joint_names
from retarget.gltf.arkit import arkit_tolerance
from retarget.gltf.animation import (animated_weights, animation_channels, mesh_instances,
                                       node_transforms)
from retarget.gltf.animation import posed_vertices as gltf_vertices
from retarget.gltf.document import GltfDocument
from retarget.landmarks import from_vertex_indices
from retarget.layouts import get_layout
from retarget.material import Material
from retarget.mesh import mesh_from_arrays
from retarget.muscles import place_muscles
from retarget.muscles.morphs import muscle_morphs
from retarget.sample_face import demo_weights, posed_vertices, sample_face
from retarget.skin import skin_displacements
from retarget.weights import compute_weights

ROOT = Path(__file__).resolve().parents[2]
EVALUATE = ROOT / "tests" / "blender" / "evaluate_glb.py"
FPS = 30.0
# key frames, subframes between keys (LINEAR interpolation), the last key
FRAMES = (0.0, 6.0, 11.5, 17.25, 29.0)


def blender_python() -> Path:
    path = Path(os.environ.get("RETARGET_BLENDER_PYTHON", ROOT / ".venv-blender" / "bin" / "python"))
    if not path.is_file():
        pytest.fail(f"no Python with Blender's bpy at {path}: create it with `python3.11 -m venv "
                    ".venv-blender && .venv-blender/bin/pip install -r tests/blender/requirements.txt` "
                    "or name one in RETARGET_BLENDER_PYTHON")
    return path


@pytest.fixture(scope="module")
def face():
    f = sample_face(1)
    image = io.BytesIO()
    Image.new("RGB", (16, 8), (230, 180, 160)).save(image, format="PNG")
    skin = Material(name="skin", base_color=(0.9, 0.8, 0.7, 1.0), metallic=0.0, roughness=0.6,
                    base_color_texture=image.getvalue())
    mesh = mesh_from_arrays(f.vertices, f.faces, uv=f.uv, name="sample_face", material=skin)
    points = from_vertex_indices(f.landmarks68, mesh.n_vertices, "ibug68")
    # a second of the demo around its surprise (3.7 s): jaw open, brows up
    posed = posed_vertices(f, demo_weights(126, FPS)[96:])[:, f.landmarks68]
    clip = clip_at_rate("demo", posed - f.vertices[f.landmarks68], FPS)
    return {"mesh": mesh, "points": points, "clip": clip,
            "size": float(np.linalg.norm(np.ptp(f.vertices, axis=0)))}


def _blender(face, method, tmp_path_factory):
    """Export with `method`'s rig, import in Blender: (weights, Blender's results)."""
    mesh, points = face["mesh"], face["points"]
    weights = compute_weights(method, mesh.vertices, mesh.faces, points, get_layout("ibug68"))
    d = tmp_path_factory.mktemp(f"blender_{method}")
    path = d / "face.glb"
    path.write_bytes(export_gltf(mesh, points, weights, [face["clip"]]))
    return weights, _evaluated(path, d)


def _evaluated(path, d, frames=FRAMES) -> dict:
    """Blender's import of the .glb at `path` evaluated at `frames`, positions in the mesh's
    units (Blender's, in the file's metres, over the export's recorded scale)."""
    run = subprocess.run([str(blender_python()), str(EVALUATE), str(path), str(d / "out.npz"),
                          str(FPS), *map(str, frames)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    scale = _file_scale(Path(path).read_bytes())
    with np.load(d / "out.npz") as z:
        result = {key: z[key] / scale for key in ("positions", "rest", "bone_heads")}
        result["info"] = json.loads(str(z["info"]))
    return result


def _file_scale(data: bytes) -> float:
    """What the export multiplied every length by (0.01: the centimetre face in metres)."""
    return GltfDocument(data, "face.glb", None).doc.scenes[0].extras["retarget"]["scale"]


@pytest.fixture(scope="module")
def skinned(face, tmp_path_factory):
    return _blender(face, "ellipsoid", tmp_path_factory)


@pytest.fixture(scope="module")
def morphed(face, tmp_path_factory):
    return _blender(face, "rbf", tmp_path_factory)


def _assert_matches_our_skinning(face, weights, result):
    """Blender's evaluated vertices at FRAMES equal v0 + W d(t) within 1e-4 of the mesh
    size, d linearly interpolated between the clip's frames (glTF LINEAR)."""
    clip, v0 = face["clip"], face["mesh"].vertices
    assert result["positions"].shape == (len(FRAMES), len(v0), 3)
    np.testing.assert_allclose(result["rest"], v0, atol=1e-6 * face["size"])
    motion = 0.0
    for frame, got in zip(FRAMES, result["positions"]):
        i, u = int(np.floor(frame)), frame % 1.0
        d = (1 - u) * clip.displacements[i] + u * clip.displacements[min(i + 1, clip.n_frames - 1)]
        expected = v0 + skin_displacements(weights, d)
        error = np.abs(got - expected).max()
        assert error < 1e-4 * face["size"], (frame, error)
        motion = max(motion, np.abs(expected - v0).max())
    assert motion > 100 * 1e-4 * face["size"]  # the comparison has motion to get wrong


def test_blender_builds_an_armature_with_one_bone_per_feature(face, skinned):
    _, result = skinned
    info = result["info"]
    names = joint_names(face["points"])
    assert len(info["armatures"]) == 1 and info["meshes"] == ["sample_face"]
    assert sorted(info["bones"]) == sorted(["root", *names])
    assert "ARMATURE" in info["modifiers"]
    assert set(names) <= set(info["vertex_groups"])
    heads = dict(zip(info["bones"], result["bone_heads"]))
    neutral = face["points"].positions(face["mesh"].vertices)
    np.testing.assert_allclose([heads[n] for n in names], neutral, atol=1e-5 * face["size"])
    assert info["actions"] == {"demo": [0.0, FPS - 1]}
    assert info["materials"] == [{"name": "skin", "images": [[16, 8]]}]


def test_blender_skins_like_we_do(face, skinned):
    _assert_matches_our_skinning(face, *skinned)


def test_blender_morphs_like_we_do(face, morphed):
    weights, result = morphed
    info = result["info"]
    assert info["armatures"] == [] and info["shape_keys"][0] == "Basis"
    assert info["shape_keys"][1:4] == [f"{joint_names(face['points'])[0]}.{a}" for a in "xyz"]
    assert len(info["shape_keys"]) == 1 + 3 * face["points"].n_points
    _assert_matches_our_skinning(face, weights, result)


def test_blender_plays_the_muscle_export_as_gltf_defines_it(face, tmp_path_factory):
    """A shape key per muscle and corrective, a jaw bone: Blender's positions at FRAMES are
    glTF's morphing then skinning of the file (`retarget.gltf.animation`) within 1e-4 of the
    mesh size. Blender interpolates the jaw's quaternion per component where glTF slerps, the
    largest part of what differs between keys (1e-3 cm here, 4e-6 cm on the keys)."""
    mesh = face["mesh"]
    model = place_muscles(mesh.vertices, mesh.faces, face["points"].positions(mesh.vertices))
    morphs = muscle_morphs(model)
    rng = np.random.default_rng(0)
    contractions = rng.uniform(model.limits[:, 0], model.limits[:, 1], (30, model.n_dof))
    data = export_muscles_gltf(mesh, morphs, [ContractionClip("muscles", contractions, np.arange(30) / FPS)])
    d = tmp_path_factory.mktemp("blender_muscles")
    (d / "face.glb").write_bytes(data)
    result = _evaluated(d / "face.glb", d)
    info = result["info"]
    assert info["bones"] == ["root", "jaw"] and "ARMATURE" in info["modifiers"]
    assert info["shape_keys"] == ["Basis", *morphs.names, *morphs.corrective_names]
    gltf = GltfDocument(data, "face.glb", None)
    (instance,) = mesh_instances(gltf)
    channels = animation_channels(gltf, gltf.doc.animations[0])
    times = np.array(FRAMES) / FPS
    expected = gltf_vertices(gltf, instance, np.arange(mesh.n_vertices),
                             node_transforms(gltf, gltf.doc.nodes, channels, times),
                             animated_weights(gltf, channels, times), times) / _file_scale(data)
    assert np.abs(result["positions"] - expected).max() < 1e-4 * face["size"]
    assert np.abs(expected - mesh.vertices).max() > 100 * 1e-4 * face["size"]


def test_blender_plays_the_arkit_export_from_sparse_targets(face, tmp_path_factory):
    """52 shape keys named after ARKit, read from sparse accessors (all but the empty
    tongueOut): Blender's positions at FRAMES (keys and between them) are the shapes posed by
    the weights interpolated linearly, within the targets' tolerance (1e-4 of the face size
    per unit of weight)."""
    mesh, points = face["mesh"], face["points"]
    rig = compute_weights("ellipsoid", mesh.vertices, mesh.faces, points, get_layout("ibug68"))
    shapes = arkit_shapes(mesh.vertices, mesh.faces, points, "ibug68", rig)
    rng = np.random.default_rng(2)
    weights = rng.uniform(0, 1, (30, 52)) * (rng.random((30, 52)) < 0.15)
    data = export_arkit_gltf(mesh, shapes, [ArkitClip.at_rate("arkit", weights, FPS)])
    doc = GltfDocument(data, "face.glb", None).doc
    targets = [doc.accessors[t["POSITION"]] for t in doc.meshes[0].primitives[0].targets]
    assert sum(a.sparse is not None and a.bufferView is None for a in targets) == 51
    d = tmp_path_factory.mktemp("blender_arkit")
    (d / "face.glb").write_bytes(data)
    result = _evaluated(d / "face.glb", d)
    info = result["info"]
    assert info["armatures"] == [] and info["shape_keys"] == ["Basis", *ARKIT_NAMES]
    assert info["actions"] and list(info["actions"].values())[0] == [0.0, FPS - 1]
    v0 = mesh.vertices
    for frame, got in zip(FRAMES, result["positions"]):
        w = np.array([np.interp(frame, np.arange(30), weights[:, k]) for k in range(52)])
        expected = shapes.posed(v0, w)
        bound = arkit_tolerance(v0) * w.sum() + 1e-5 * face["size"]
        print(f"ARKit, frame {frame}: |Blender - posed| = {np.abs(got - expected).max() / face['size']:.1e} "
              f"of the mesh size (bound {bound / face['size']:.1e})")
        assert np.abs(got - expected).max() < bound, frame
        assert np.abs(expected - v0).max() > 0.03 * face["size"]       # the pose moves the face


def test_blender_turns_the_head_as_the_app_does(face, tmp_path_factory):
    """'Turn the head' (issue 19): a take whose performer turns the head (up to 25°), played
    with apply_rotation, exported with an ellipsoid skin: the ``head`` node above the skeleton
    root becomes an animated empty over the armature, and Blender's positions at the keys are
    the app's (the skinned face turned about its rest bounding-box centre by the streamed
    quaternion) within 1e-4 of the mesh size."""
    from retarget.performance import Performance
    from tests.unit.test_export_head import SETTINGS, app_vertices, turning_take

    mesh, points = face["mesh"], face["points"]
    weights = compute_weights("ellipsoid", mesh.vertices, mesh.faces, points, get_layout("ibug68"))
    clip = Performance(points.positions(mesh.vertices), "ibug68", SETTINGS).play(turning_take(32)[0], "turn")
    d = tmp_path_factory.mktemp("blender_head")
    (d / "face.glb").write_bytes(export_gltf(mesh, points, weights, [clip]))
    keys = (0, 10, 16, 31)
    result = _evaluated(d / "face.glb", d, [float(k) for k in keys])
    worst = 0.0
    for k, got in zip(keys, result["positions"]):
        worst = max(worst, np.abs(got - app_vertices(mesh, weights, clip, k)).max() / face["size"])
    print(f"head motion: |Blender - app| = {worst:.1e} of the mesh size")
    assert worst < 1e-4
    turned = app_vertices(mesh, weights, clip, 16) - (mesh.vertices + skin_displacements(weights, clip.displacements[16]))
    assert np.abs(turned).max() > 0.1 * face["size"]                   # the head does turn


def test_blender_plays_the_four_joint_skin_form_with_reduced_keys_as_gltf_defines_it(face, tmp_path_factory):
    """A biharmonic rig (negative weights) exported as a four-joint skin (form="skin") with
    keys at 24 fps reduced to 0.05 mm: an armature without shape keys, and Blender's positions
    at keys and between them are what glTF defines (`retarget.gltf.animation`), so Blender and
    three.js (tests/e2e/test_export_threejs.py) play the file alike."""
    mesh, points = face["mesh"], face["points"]
    weights = compute_weights("biharmonic", mesh.vertices, mesh.faces, points, get_layout("ibug68"))
    d = tmp_path_factory.mktemp("blender_skin_form")
    data = export_gltf(mesh, points, weights, [face["clip"]], form="skin", rate=24, key_tolerance=0.05)
    (d / "face.glb").write_bytes(data)
    frames = (0.0, 5.5, 12.0, 20.25)
    result = subprocess.run([str(blender_python()), str(EVALUATE), str(d / "face.glb"), str(d / "out.npz"),
                             "24", *map(str, frames)], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    with np.load(d / "out.npz") as z:
        blender, info = z["positions"], json.loads(str(z["info"]))
    assert len(info["armatures"]) == 1 and info["shape_keys"] == []
    gltf = GltfDocument(data, "face.glb", None)
    (instance,) = mesh_instances(gltf)
    channels = animation_channels(gltf, gltf.doc.animations[0])
    assert max(len(c[2]) for c in channels) < 24  # fewer keys than the 24 of a second at 24 fps
    times = np.array(frames) / 24.0
    expected = gltf_vertices(gltf, instance, np.arange(len(instance["positions"])),
                             node_transforms(gltf, gltf.doc.nodes, channels, times),
                             animated_weights(gltf, channels, times), times)
    size = _file_scale(data) * face["size"]
    worst = np.abs(blender - expected).max() / size
    print(f"four-joint skin form: |Blender - glTF| = {worst:.1e} of the mesh size")
    assert worst < 1e-4
    assert np.abs(expected - instance["positions"]).max() / size > 0.01  # the face does move
