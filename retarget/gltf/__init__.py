"""glTF 2.0: reading any file safely, evaluating its animation, and the rigged export.

Reading: `document` (`GltfDocument`, bounds-checked glTF/GLB parsing, and `scene_size`,
what a scene would unpack to, counted before anything is read), `decode` (the JSON into
pygltflib's objects, as pygltflib makes them, at a fraction of its cost) and `animation`
(glTF's skinning, morphing and node animation evaluated as the specification defines them).

The export: `export_gltf` (bytes) and `write_gltf` (to a file) write a target mesh, its
feature points as translation-only joints (Dutreve §3), its rig (a glTF skin, or morph
targets for rigs with negative weights) and retargeted takes (`retarget.clips.Clip`) as
animations, as one .glb (`writer` documents the layout and the units); `read_gltf` reads
such a file back into the mesh, landmarks, skin weights and clips (`reader`);
`export_mesh_gltf` writes the mesh alone; `export_muscles_gltf` and `write_muscles_gltf`
a face driven by its muscles (`retarget.muscles.morphs`: morph targets and a jaw joint)
with takes of muscle contractions (`retarget.clips.ContractionClip`);
`export_arkit_gltf` and `write_arkit_gltf` (`arkit`) a face with ARKit's 52 blendshapes
as named morph targets animated by their weights (`retarget.arkit.ArkitClip`). `glb` is
the binary container, `influences` the weights as JOINTS_n / WEIGHTS_n, `morph` the
weights as morph targets, `sparse` morph targets that keep only the vertices they move,
`units` the export's scale to metres (recorded, undone by `read_gltf`), `head` the ``head``
node that turns the face by a take's head rotations, `keys` the animation's key rate
and key reduction.
"""

import importlib

__all__ = ["RiggedFace", "export_arkit_gltf", "export_gltf", "export_mesh_gltf", "export_muscles_gltf",
           "joint_names", "read_gltf", "write_arkit_gltf", "write_gltf", "write_muscles_gltf"]

_HOMES = {"RiggedFace": "reader", "read_gltf": "reader", "export_gltf": "writer",
          "export_mesh_gltf": "writer", "export_muscles_gltf": "writer", "joint_names": "writer",
          "write_gltf": "writer", "write_muscles_gltf": "writer", "export_arkit_gltf": "arkit",
          "write_arkit_gltf": "arkit"}


def __getattr__(name: str):
    # the export's names are imported on first use (PEP 562): `retarget.mesh` reads glTF
    # through `document`, and the export is built on `retarget.mesh`
    if name in _HOMES:
        return getattr(importlib.import_module(f"retarget.gltf.{_HOMES[name]}"), name)
    raise AttributeError(f"module 'retarget.gltf' has no attribute {name!r}")
