"""Head motion in an export: a ``head`` node turning the face as the app's viewer does.

With "turn the head" on (`retarget.sources.conditioning.ConditionSettings.apply_rotation`),
the app turns the whole target by the performer's head rotation q_f about the centre of the
rest mesh's bounding sphere, which three.js computes as the centre of its bounding box
(`SkinnedFace.setHeadRotation`): a vertex v is drawn at ``c + R_f (v - c)``. A clip that
carries ``head_rotations`` (`retarget.clips.Clip`) is exported the same way, with two more
nodes: ``head``, at the pivot c and animated per frame by the rotation q_f (and by the
translation ``c + t_f`` when the clip has ``head_translations`` t_f), and its one child
``head_pivot``, a static translation by -c, the parent of what moves with the head; its
children are then drawn at ``c + t_f + R_f (x - c)``. LINEAR keys: glTF slerps the rotation
about the pivot, so between the keys the face turns as a rigid head does, and at the keys
it is exactly the app's pose. The quaternions are put on one hemisphere (each the sign
nearer the last), as Blender's importer interpolates their components.

Which nodes go under ``head``: a skinned mesh ignores its own node's transform (glTF
§3.7.3.1; the Khronos validator warns about a skinned mesh node that is not a root), so for
a skin only the skeleton's root joint does, and the mesh node stays at the scene's root;
a mesh without a skin (morph targets, ARKit) goes under it itself. The scene's
``extras.retarget.head`` records the two nodes and the pivot (file units) for
`retarget.gltf.read_gltf`.
"""

from __future__ import annotations

import numpy as np

from retarget.gltf.glb import GlbBuilder

__all__ = ["HEAD_NAME", "PIVOT_NAME", "add_head_motion", "head_pivot"]

HEAD_NAME, PIVOT_NAME = "head", "head_pivot"


def head_pivot(vertices) -> np.ndarray:
    """(3,) float64 the centre of the bounding box of (V, 3) rest `vertices`, where the
    app's viewer turns the face (three.js's bounding-sphere centre)."""
    v = np.asarray(vertices, dtype=np.float64)
    return 0.5 * (v.min(axis=0) + v.max(axis=0))


def add_head_motion(out: GlbBuilder, clips, pivot, moved: list[int], writers, reach: float) -> dict | None:
    """Add the ``head`` and ``head_pivot`` nodes over nodes `moved` (taken out of the
    scene's roots) and key the head in each animation of a clip with ``head_rotations``
    (animation k is clip k, keyed by ``writers[k]``, a `retarget.gltf.keys.KeyWriter`);
    nothing when no clip has them. `pivot` (3,) file units; `reach` how far from it the
    face reaches (a turn by θ moves a vertex by at most reach θ: the key tolerance of the
    rotation). Returns the ``extras.retarget.head`` record, or None."""
    if not any(getattr(clip, "head_rotations", None) is not None for clip in clips):
        return None
    doc = out.document
    c = np.asarray(pivot, dtype=np.float64)
    head, inner = len(doc["nodes"]), len(doc["nodes"]) + 1
    doc["nodes"].append({"name": _unique(HEAD_NAME, doc["nodes"]), "translation": [float(x) for x in c],
                         "children": [inner]})
    doc["nodes"].append({"name": _unique(PIVOT_NAME, doc["nodes"]), "translation": [float(-x) for x in c],
                         "children": list(moved)})
    scene = doc["scenes"][doc.get("scene", 0)]
    scene["nodes"] = [n for n in scene["nodes"] if n not in moved] + [head]
    for animation, clip, keys in zip(doc.get("animations", []), clips, writers):
        q = getattr(clip, "head_rotations", None)
        if q is None:
            continue
        # a quaternion's components hold half the angle
        keyed = [("rotation", _one_hemisphere(q), 2.0 * max(reach, 1e-12))]
        if clip.head_translations is not None:
            keyed.append(("translation", c + clip.head_translations, 1.0))
        for path, values, scale in keyed:
            animation["channels"].append({"sampler": len(animation["samplers"]),
                                          "target": {"node": head, "path": path}})
            animation["samplers"].append(keys.sampler(values, scale=scale))
    return {"node": head, "pivot_node": inner, "pivot": [float(x) for x in c]}


def _one_hemisphere(q: np.ndarray) -> np.ndarray:
    """(F, 4) quaternions, each row's sign chosen nearer the previous row's."""
    q = np.array(q, dtype=np.float64)
    for f in range(1, len(q)):
        if np.dot(q[f], q[f - 1]) < 0:
            q[f] = -q[f]
    return q


def _unique(name: str, nodes: list[dict]) -> str:
    taken = {n.get("name") for n in nodes}
    while name in taken:
        name += "_"
    return name
