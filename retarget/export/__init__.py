"""Export to glTF 2.0 and read the export back.

`export_gltf` (bytes) and `write_gltf` (to a file) write a target mesh, its feature points as translation-only joints
(Dutreve §3), its rig (a glTF skin, or morph targets for rigs with negative weights) and
retargeted takes as animations, as one .glb (`retarget.export.gltf_writer` documents the
layout and the units). `read_gltf` reads such a file back into the mesh, landmarks, skin
weights and clips (`retarget.export.gltf_reader`). `take_clip` retargets a recorded take
into a `Clip` as the app plays it; `export_mesh_gltf` writes the mesh alone.

Modules: `glb` (the binary container), `influences` (weights as JOINTS_n / WEIGHTS_n),
`morph` (weights as morph targets), `clips` (`Clip`, the animated displacements),
`gltf_writer`, `gltf_reader`.
"""

from retarget.export.clips import Clip, clip_at_rate, take_clip
from retarget.export.gltf_reader import RiggedFace, read_gltf
from retarget.export.gltf_writer import export_gltf, export_mesh_gltf, joint_names, write_gltf

__all__ = ["Clip", "RiggedFace", "clip_at_rate", "export_gltf", "export_mesh_gltf",
           "joint_names", "read_gltf", "take_clip", "write_gltf"]
