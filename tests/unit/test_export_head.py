"""Head motion (issue 19): with "turn the head" on (``apply_rotation``), a take's clip carries
the head rotations the take player streams, and the export animates a ``head`` node with them
so that a glTF viewer draws the face as the app's viewer does: ``c + R_f (v0 + W d_f - c)``,
c the centre of the rest mesh's bounding box (`SkinnedFace.setHeadRotation`).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from retarget.clips import Clip
from retarget.errors import RetargetError
from retarget.gltf import export_gltf, read_gltf
from retarget.gltf.animation import animated_weights, animation_channels, mesh_instances, node_transforms
from retarget.gltf.animation import posed_vertices as gltf_posed
from retarget.gltf.document import GltfDocument
from retarget.gltf.head import head_pivot
from retarget.landmarks import from_vertex_indices
from retarget.layouts import get_layout
from retarget.mesh import mesh_from_arrays
from retarget.performance import Performance
from retarget.sample_face import demo_weights, sample_face
from retarget.skin import skin_displacements
from retarget.sources.take import Take
from retarget.weights import compute_weights
from tests.gltf_check import assert_valid_gltf

FPS = 30.0
IBUG = get_layout("ibug68")
SETTINGS = {"neutral": {"mode": "frame", "frame": 0}, "head_pose": "remove", "apply_rotation": True}


def turning_take(frames: int = 40) -> tuple[Take, np.ndarray]:
    """Another identity performing the demo while turning its head (up to 25° about y, 10°
    about x) and moving it: the take and the true (F, 3, 3) rotations."""
    performer = sample_face(identity=np.array([0.8, 0.5, -0.6, 1.0, 0.3]))
    lm = np.asarray(performer.landmarks68)
    points = performer.vertices[lm] + np.tensordot(demo_weights(frames, FPS), performer.expressions[:, lm], axes=1)
    s = np.linspace(0, 1, frames)
    turns = Rotation.from_euler("yx", np.column_stack([25 * np.sin(np.pi * s), 10 * s]), degrees=True)
    centre = points[0].mean(axis=0)
    moved = np.einsum("fij,fnj->fni", turns.as_matrix(), points - centre) + centre + s[:, None, None] * [1.0, 0.5, 0]
    return Take(moved.astype(np.float32), IBUG.point_names, FPS, layout="ibug68", source="test"), turns.as_matrix()


@pytest.fixture(scope="module")
def played():
    f = sample_face(1)
    mesh = mesh_from_arrays(f.vertices, f.faces, name="face")
    points = from_vertex_indices(f.landmarks68, mesh.n_vertices, "ibug68")
    take, turns = turning_take()
    performance = Performance(points.positions(mesh.vertices), "ibug68", SETTINGS)
    clip = performance.play(take, "turn")
    # what the take player streams: Performance.cue, then frame() per frame
    cue = performance.cue(take)
    streamed = np.stack([performance.frame(cue.points[i], cue.times[i], rotation=cue.rotation(i)).head_rotation
                         for i in range(cue.n_frames)])
    return {"mesh": mesh, "points": points, "clip": clip, "streamed": streamed, "turns": turns}


def app_vertices(mesh, weights, clip, k: int) -> np.ndarray:
    """(V, 3) frame k as the app's viewer draws it: the skinned face turned about the centre of
    its rest bounding box by the frame's quaternion."""
    c = head_pivot(mesh.vertices)
    posed = mesh.vertices + skin_displacements(weights, clip.displacements[k])
    return c + Rotation.from_quat(clip.head_rotations[k]).apply(posed - c)


def test_a_take_with_turn_the_head_carries_the_streamed_rotations(played):
    clip = played["clip"]
    assert clip.head_rotations.shape == (clip.n_frames, 4)
    np.testing.assert_allclose(clip.head_rotations, played["streamed"], atol=1e-12)
    # the rotations are the performer's own turn (relative to the neutral frame 0)
    true = Rotation.from_matrix(played["turns"])
    error = (Rotation.from_quat(clip.head_rotations) * true.inv()).magnitude().max()
    assert np.degrees(error) < 1.0
    assert np.degrees(Rotation.from_quat(clip.head_rotations).magnitude().max()) > 20
    off = Performance(played["points"].positions(played["mesh"].vertices), "ibug68",
                      {**SETTINGS, "apply_rotation": False})
    assert off.play(turning_take()[0]).head_rotations is None


@pytest.mark.parametrize("method", ["ellipsoid", "rbf"])
def test_the_export_turns_the_head_as_the_app_does(played, method, tmp_path):
    mesh, points, clip = played["mesh"], played["points"], played["clip"]
    weights = compute_weights(method, mesh.vertices, mesh.faces, points, IBUG)
    path = tmp_path / "turn.glb"
    path.write_bytes(export_gltf(mesh, points, weights, [clip]))
    assert_valid_gltf(path)
    gltf = GltfDocument(path.read_bytes(), "turn", None)
    head = gltf.doc.scenes[0].extras["retarget"]["head"]
    assert gltf.doc.nodes[head["node"]].name == "head" and gltf.doc.scenes[0].nodes == (
        [0, head["node"]] if method == "ellipsoid" else [head["node"]])
    assert gltf.doc.nodes[head["pivot_node"]].children == ([1] if method == "ellipsoid" else [0, 1])
    (instance,) = mesh_instances(gltf)
    channels = animation_channels(gltf, gltf.doc.animations[0])
    size = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    worst = 0.0
    for k in (0, 9, 20, 31, clip.n_frames - 1):
        t = np.array([clip.times[k]])
        drawn = gltf_posed(gltf, instance, np.arange(mesh.n_vertices), node_transforms(gltf, gltf.doc.nodes, channels, t),
                           animated_weights(gltf, channels, t), t)[0] / 0.01
        worst = max(worst, np.abs(drawn - app_vertices(mesh, weights, clip, k)).max() / size)
    print(f"{method}: the export's posed vertices against the app's, worst {worst:.1e} of the face size")
    assert worst < 1e-5
    back = read_gltf(path)
    np.testing.assert_allclose(np.abs(np.sum(back.clips[0].head_rotations * clip.head_rotations, axis=1)), 1.0,
                               atol=1e-6)
    np.testing.assert_allclose(back.clips[0].displacements, clip.displacements, atol=1e-5)
    np.testing.assert_array_equal(back.points.vertex_indices, points.vertex_indices)


def test_head_motion_refusals():
    d = np.zeros((2, 3, 3))
    with pytest.raises(RetargetError, match=r"head_rotations must be finite quaternions of shape \(2, 4\)"):
        Clip("x", d, [0.0, 1.0], head_rotations=np.zeros((3, 4)))
    with pytest.raises(RetargetError, match="zero quaternion"):
        Clip("x", d, [0.0, 1.0], head_rotations=np.zeros((2, 4)))
    with pytest.raises(RetargetError, match="head_translations need head_rotations"):
        Clip("x", d, [0.0, 1.0], head_translations=np.zeros((2, 3)))


def test_a_head_translation_moves_the_turned_face(played):
    """A clip's head_translations (a source that tracks the head's position) add to the turn:
    a viewer draws ``c + t_f + R_f (v - c)``, in metres in the file."""
    import dataclasses

    mesh, points, clip = played["mesh"], played["points"], played["clip"]
    weights = compute_weights("ellipsoid", mesh.vertices, mesh.faces, points, IBUG)
    shift = np.outer(np.linspace(0, 1, clip.n_frames), [2.0, -1.0, 0.5])               # cm
    moved = dataclasses.replace(clip, head_translations=shift)
    gltf = GltfDocument(export_gltf(mesh, points, weights, [moved]), "moved", None)
    (instance,) = mesh_instances(gltf)
    channels = animation_channels(gltf, gltf.doc.animations[0])
    k = 25
    t = np.array([clip.times[k]])
    drawn = gltf_posed(gltf, instance, np.arange(mesh.n_vertices), node_transforms(gltf, gltf.doc.nodes, channels, t),
                       animated_weights(gltf, channels, t), t)[0] / 0.01
    np.testing.assert_allclose(drawn, app_vertices(mesh, weights, clip, k) + shift[k], atol=1e-5)
