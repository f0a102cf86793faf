"""The glTF export in metres against the mesh's own units, and the head motion (issue 19).

    python bench/export_units.py

Prints, on the sample face (8,430 vertices, centimetres) with a 90-frame take: each
export's size with ``units="keep"`` and in metres (the default), and whether the file
reads back to the same mesh; then a take whose performer turns the head, played with
"turn the head", exported with the head node: the posed vertices a glTF viewer draws
(`retarget.gltf.animation`) against the app's (the skinned face turned about its rest
bounding-box centre by the streamed quaternion), at the keys and halfway between them
(where glTF slerps the rotation and interpolates the pivot's translation linearly).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from retarget.arkit.clip import ArkitClip  # noqa: E402
from retarget.arkit.shapes import arkit_shapes  # noqa: E402
from retarget.clips import ContractionClip, clip_at_rate  # noqa: E402
from retarget.gltf import export_arkit_gltf, export_gltf, export_muscles_gltf, read_gltf  # noqa: E402
from retarget.gltf.animation import (animated_weights, animation_channels, mesh_instances,  # noqa: E402
                                     node_transforms, posed_vertices)
from retarget.gltf.document import GltfDocument  # noqa: E402
from retarget.gltf.head import head_pivot  # noqa: E402
from retarget.landmarks import from_vertex_indices  # noqa: E402
from retarget.layouts import get_layout  # noqa: E402
from retarget.mesh import mesh_from_arrays  # noqa: E402
from retarget.muscles import place_muscles  # noqa: E402
from retarget.muscles.morphs import muscle_morphs  # noqa: E402
from retarget.performance import Performance  # noqa: E402
from retarget.sample_face import demo_weights, posed_vertices as face_posed, sample_face  # noqa: E402
from retarget.skin import skin_displacements  # noqa: E402
from retarget.sources.take import Take  # noqa: E402
from retarget.weights import compute_weights  # noqa: E402

FPS = 30.0
IBUG = get_layout("ibug68")


def main() -> None:
    f = sample_face(1)
    mesh = mesh_from_arrays(f.vertices, f.faces, uv=f.uv, name="face")
    points = from_vertex_indices(f.landmarks68, mesh.n_vertices, "ibug68")
    lm = np.asarray(f.landmarks68)
    clip = clip_at_rate("demo", face_posed(f, demo_weights(90, FPS))[:, lm] - f.vertices[lm], FPS)
    rigs = {m: compute_weights(m, mesh.vertices, mesh.faces, points, IBUG) for m in ("ellipsoid", "biharmonic")}
    model = place_muscles(mesh.vertices, mesh.faces, points.positions(mesh.vertices))
    contractions = np.random.default_rng(0).uniform(model.limits[:, 0], model.limits[:, 1], (90, model.n_dof))
    shapes = arkit_shapes(mesh.vertices, mesh.faces, points, "ibug68", rigs["ellipsoid"])
    weights = np.random.default_rng(1).uniform(0, 1, (90, 52)) * (np.random.default_rng(2).random((90, 52)) < 0.2)
    exports = {
        "ellipsoid skin": lambda u: export_gltf(mesh, points, rigs["ellipsoid"], [clip], units=u),
        "biharmonic morph targets": lambda u: export_gltf(mesh, points, rigs["biharmonic"], [clip], units=u),
        "muscles": lambda u: export_muscles_gltf(mesh, muscle_morphs(model),
                                                 [ContractionClip("m", contractions, np.arange(90) / FPS)], units=u),
        "ARKit (sparse)": lambda u: export_arkit_gltf(mesh, shapes, [ArkitClip.at_rate("a", weights, FPS)], units=u),
    }
    print(f"sample face, {mesh.n_vertices} vertices in cm, a 90-frame take: bytes kept -> metres "
          "(of which the binary chunk)")
    nonzero = mesh.vertices != 0
    for name, write in exports.items():
        kept, metres = write("keep"), write("m")
        line = (f"  {name:26s} {len(kept):>10,d} -> {len(metres):>10,d} ({len(metres) - len(kept):+d}; "
                f"binary {binary_bytes(kept):,d} -> {binary_bytes(metres):,d})")
        if "muscles" not in name and "ARKit" not in name:
            back = read_gltf(metres)
            relative = np.abs(back.mesh.vertices[nonzero] / mesh.vertices[nonzero] - 1).max()
            line += f"; read back: units {back.units}, vertices within {relative:.1e} relative"
        print(line)
    head_motion(mesh, points, rigs)


def binary_bytes(glb: bytes) -> int:
    """The length of a GLB's binary chunk (after the 12-byte header and the JSON chunk)."""
    json_length = int.from_bytes(glb[12:16], "little")
    return int.from_bytes(glb[20 + json_length:24 + json_length], "little")


def head_motion(mesh, points, rigs) -> None:
    performer = sample_face(identity=np.array([0.8, 0.5, -0.6, 1.0, 0.3]))
    lm = np.asarray(performer.landmarks68)
    n = 90
    frames = performer.vertices[lm] + np.tensordot(demo_weights(n, FPS), performer.expressions[:, lm], axes=1)
    s = np.linspace(0, 1, n)
    turns = Rotation.from_euler("yx", np.column_stack([30 * np.sin(2 * np.pi * s), 10 * s]), degrees=True)
    centre = frames[0].mean(axis=0)
    moved = np.einsum("fij,fnj->fni", turns.as_matrix(), frames - centre) + centre
    take = Take(moved.astype(np.float32), IBUG.point_names, FPS, layout="ibug68", source="bench")
    settings = {"neutral": {"mode": "frame", "frame": 0}, "apply_rotation": True}
    clip = Performance(points.positions(mesh.vertices), "ibug68", settings).play(take, "turn")
    size = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    c = head_pivot(mesh.vertices)
    step = np.degrees((Rotation.from_quat(clip.head_rotations[1:]) * Rotation.from_quat(clip.head_rotations[:-1]).inv()).magnitude())
    print(f"head motion: a {n}-frame take turning up to 30° ({step.max():.1f}° a frame at most), "
          "posed vertices a glTF viewer draws against the app's, worst over the frames, of the face size:")
    for method, weights in rigs.items():
        gltf = GltfDocument(export_gltf(mesh, points, weights, [clip]), method, None)
        scale = gltf.doc.scenes[0].extras["retarget"]["scale"]
        (instance,) = mesh_instances(gltf)
        channels = animation_channels(gltf, gltf.doc.animations[0])
        slerp = Slerp(clip.times, Rotation.from_quat(clip.head_rotations))
        worst = {"keys": 0.0, "halfway": 0.0}
        for k in range(0, n - 1, 3):
            for where, t in (("keys", clip.times[k]), ("halfway", 0.5 * (clip.times[k] + clip.times[k + 1]))):
                at = np.array([t])
                drawn = posed_vertices(gltf, instance, np.arange(mesh.n_vertices),
                                       node_transforms(gltf, gltf.doc.nodes, channels, at),
                                       animated_weights(gltf, channels, at), at)[0] / scale
                u = (t - clip.times[k]) / (clip.times[k + 1] - clip.times[k])
                d = (1 - u) * clip.displacements[k] + u * clip.displacements[k + 1]
                app = c + slerp([t])[0].apply(mesh.vertices + skin_displacements(weights, d) - c)
                worst[where] = max(worst[where], float(np.abs(drawn - app).max()) / size)
        print(f"  {method:11s} at the keys {worst['keys']:.1e}, halfway between them {worst['halfway']:.1e}")


if __name__ == "__main__":
    main()
