"""Import a .glb into Blender and write what Blender made of it (run by Blender's Python).

    python evaluate_glb.py FILE.glb OUT.npz FPS FRAME [FRAME ...]

Runs in the interpreter that has Blender's `bpy` (tests/blender/requirements.txt), not in
the project's: bpy 5.0 needs numpy < 2. It imports nothing from retarget. The scene is
emptied, its frame rate set to FPS (so key times land on frames), the file imported with
Blender's own glTF importer (defaults), and the meshes it created evaluated (armature and
shape keys applied) at each FRAME, which may be fractional (a subframe, between keys).

Blender is z-up and the importer turns glTF's y-up into it; positions are turned back,
glTF (x, y, z) = Blender (x, z, -y), so they compare with the file's own coordinates.

One fix-up after import: the importer sets each shape key's slider range from the first
key of its animation only (``min(coords[1:2])`` in io_scene_gltf2's
blender/imp/animation_weight.py, Blender 5.0.1) and clamps the animation to that range,
so shape keys get the range [-1, 1] that the exporter's morph weights span.

OUT.npz holds ``positions`` (frames, V, 3) float64 of the first mesh created, ``rest``
(V, 3) its undeformed vertices, ``bone_heads`` (B, 3) the armature's bones' rest heads,
and ``info``, a JSON string: mesh, armature, bone, vertex-group, shape-key and action
names, each action's frame range, and the mesh's materials with their images' sizes.
"""

import json
import sys

import bpy
import numpy as np


def gltf_axes(blender_xyz):
    """(n, 3) Blender z-up coordinates -> glTF y-up."""
    p = np.asarray(blender_xyz, dtype=np.float64).reshape(-1, 3)
    return np.stack([p[:, 0], p[:, 2], -p[:, 1]], 1)


def world_vertices(obj, mesh):
    co = np.zeros(3 * len(mesh.vertices))
    mesh.vertices.foreach_get("co", co)
    m = np.array(obj.matrix_world)
    return gltf_axes(co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3])


def main(path, out, fps, frames):
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = round(fps), round(fps) / fps
    before = set(bpy.data.objects)
    bpy.ops.import_scene.gltf(filepath=path)
    created = [o for o in bpy.data.objects if o not in before]
    armatures = [o for o in created if o.type == "ARMATURE"]
    # the importer draws bones with a mesh of its own (an icosphere), not from the file
    shapes = {b.custom_shape for a in armatures for b in a.pose.bones}
    meshes = [o for o in created if o.type == "MESH" and o not in shapes]
    mesh = meshes[0]
    keys = mesh.data.shape_keys
    for block in (keys.key_blocks[1:] if keys else ()):
        block.slider_min, block.slider_max = -1.0, 1.0
    positions = []
    for frame in frames:
        scene.frame_set(int(np.floor(frame)), subframe=float(frame - np.floor(frame)))
        evaluated = mesh.evaluated_get(bpy.context.evaluated_depsgraph_get())
        positions.append(world_vertices(evaluated, evaluated.to_mesh()))
        evaluated.to_mesh_clear()
    scene.frame_set(0)
    heads = np.zeros((0, 3))
    if armatures:
        arm = armatures[0]
        m = np.array(arm.matrix_world)
        heads = gltf_axes(np.array([b.head_local for b in arm.data.bones]) @ m[:3, :3].T + m[:3, 3])
    info = {
        "meshes": [o.name for o in meshes],
        "armatures": [o.name for o in armatures],
        "bones": [b.name for b in armatures[0].data.bones] if armatures else [],
        "vertex_groups": [g.name for g in mesh.vertex_groups],
        "shape_keys": [b.name for b in keys.key_blocks] if keys else [],
        "actions": {a.name: list(a.frame_range) for a in bpy.data.actions},
        "modifiers": [m.type for m in mesh.modifiers],
        "materials": [{"name": m.name, "images": [n.image.size[:] for n in m.node_tree.nodes
                                                  if n.type == "TEX_IMAGE" and n.image]}
                      for m in mesh.data.materials if m],
    }
    np.savez(out, positions=np.stack(positions), rest=world_vertices(mesh, mesh.data),
             bone_heads=heads, info=json.dumps(info))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], float(sys.argv[3]), [float(f) for f in sys.argv[4:]])
