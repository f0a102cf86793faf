"""Facial animation retargeting from feature points.

A pure library (numpy, scipy, trimesh): no web imports and no global state. The method is
Dutreve et al. 2008 (RBF space transform, feature points as translation-only skinning
joints, ellipsoid auto-weights, partial retargeting), with the deformers of Zhang et al.
(dense and region-split RBF, Laplacian editing) and Woodward et al.'s biharmonic RBF.

The public surface, named here (each name is imported from its module on first use, so
``import retarget`` stays light):

- meshes and their feature points: `load_mesh`, `save_mesh`, `mesh_from_arrays`, `Mesh`;
  `load_landmarks`, `landmarks_from_json`, `SurfacePoints`; layouts `LAYOUTS`,
  `get_layout`, `Layout`;
- the rig: `compute_weights`, `METHODS`, `SkinWeights`;
- retargeting: `Retargeter` (Dutreve §4's space transform), `transfer` (frames to
  vertices); `Performance` (a played performance: conditioning, retargeting, regions,
  recording), `take_clip`;
- performances: `Take`, `read_take` (landmark tables, motion capture, animated faces),
  `ConditionSettings`, `condition_take`; `Clip`, `clip_at_rate`;
- glTF: `export_gltf`, `write_gltf`, `read_gltf`;
- from files, as the command line does: `transfer_files`, `export_gltf_files`;
- the built-in performance: `demo_performance` (the built-in face itself is
  `retarget.sample_face.sample_face`: its module has its name).

A quick start::

    import retarget
    mesh = retarget.load_mesh("face.obj")
    points = retarget.load_landmarks("face_landmarks.json", mesh.vertices, mesh.faces)
    performance = retarget.Performance(points.positions(mesh.vertices), "ibug68")
    clip = performance.play(retarget.read_take("take.csv", layout="ibug68"))
"""

import importlib

from retarget.errors import RetargetError

__version__ = "0.1.0"

_HOMES = {
    "Mesh": "mesh", "load_mesh": "mesh", "save_mesh": "mesh", "mesh_from_arrays": "mesh",
    "SurfacePoints": "landmarks", "load_landmarks": "landmarks",
    "landmarks_from_json": "landmarks",
    "LAYOUTS": "layouts", "Layout": "layouts", "get_layout": "layouts",
    "METHODS": "weights", "compute_weights": "weights", "SkinWeights": "skin",
    "Retargeter": "pipeline", "transfer": "pipeline",
    "Performance": "performance", "take_clip": "performance",
    "Take": "sources.take", "read_take": "sources.files",
    "ConditionSettings": "sources.conditioning", "condition_take": "sources.conditioning",
    "Clip": "clips", "clip_at_rate": "clips",
    "export_gltf": "gltf", "write_gltf": "gltf", "read_gltf": "gltf",
    "transfer_files": "files", "export_gltf_files": "files",
    "demo_performance": "sample_face",
}

__all__ = ["RetargetError", *_HOMES]


def __getattr__(name: str):
    # imported on first use (PEP 562): the modules pull in scipy, trimesh and OpenCV, and
    # `retarget.mesh` and `retarget.gltf` import each other's parts
    if name in _HOMES:
        value = getattr(importlib.import_module(f"retarget.{_HOMES[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'retarget' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
