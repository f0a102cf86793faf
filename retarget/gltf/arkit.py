"""A face with ARKit's 52 blendshapes as one glTF 2.0 binary, animated by their weights.

`export_arkit_gltf` (bytes) and `write_arkit_gltf` (to a file) write the mesh (positions,
triangles, normals, uv and material as `retarget.gltf.writer` writes them) with the 52
shapes of `retarget.arkit.ArkitShapes` as morph targets named after ARKit
(``eyeBlinkLeft`` ... ``tongueOut``, Apple's order) in ``mesh.extras.targetNames``, where
Blender's importer and three.js's GLTFLoader read shape-key and morph names, and in the
primitive's ``extras.targetNames`` (UniVRM). Any ARKit pipeline (Live Link, VRM "perfect
sync", a three.js or Unity face driven by ARKit weights) finds its shapes by these names.
There is no skin and no joint: one mesh node. An `ArkitClip` is one animation keying the
mesh node's 52 morph weights per frame, LINEAR, so a viewer draws
``v0 + sum_k w_k(t) delta_k`` (`ArkitShapes.posed`).

Size: most ARKit shapes move part of the face, so each target is written sparse
(`retarget.gltf.sparse`) without the vertices it moves by at most `TOLERANCE` of the face's
size (its bounding-box diagonal): 1e-4, 28 µm on a 28 cm face, far below what a viewer can
show; a posed vertex is then off by at most that times the sum of the weights. A target that
moves most of the face stays dense and exact. The shapes the project makes (a dense RBF rig
spreads each shape thinly over the face) keep about 35 % of their rows: a 30 s take at 30 fps
is 2.5 MiB against 5.5 MiB dense on the 8,430-vertex sample face, 42 MiB against 85 MiB at
132,907 vertices, every posed vertex within 2.2e-4 of the face size of the exact shapes
(``python bench/arkit.py --export-only``).

Units: metres by default, or the mesh's own with ``units="keep"``, recorded, as
`retarget.gltf.writer` says (`retarget.gltf.units`); clips with ``head_rotations`` animate a
``head`` node over the mesh (`retarget.gltf.head`). The scene's ``extras.retarget``
records ``deformation: "arkit"``; `retarget.gltf.read_gltf` refuses such a file by name.
"""

from __future__ import annotations

import numpy as np

from retarget.arkit.clip import ArkitClip
from retarget.arkit.shapes import ArkitShapes
from retarget.errors import RetargetError
from retarget.gltf.glb import GlbBuilder
from retarget.gltf.sparse import add_morph_targets
from retarget.gltf.keys import Keys, KeyWriter
from retarget.gltf.writer import FORMAT, MESH_NODE, _face_document, _head, _scaled, _stepper
from retarget.mesh import Mesh

__all__ = ["TOLERANCE", "arkit_tolerance", "export_arkit_gltf", "write_arkit_gltf"]

TOLERANCE = 1e-4
"""A vertex a shape moves by at most this share of the face's bounding-box diagonal is left
out of the shape's sparse target (module docstring)."""


def arkit_tolerance(vertices) -> float:
    """Mesh units: `TOLERANCE` times the bounding-box diagonal of (V, 3) `vertices`."""
    v = np.asarray(vertices, dtype=np.float64)
    return TOLERANCE * float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))) if len(v) else 0.0


def export_arkit_gltf(mesh: Mesh, shapes: ArkitShapes, clips=(), *, tolerance: float | None = None,
                      rate: float | None = None, key_tolerance: float = 0.0, units: str = "m",
                      mesh_units: str = "guess", progress=None) -> bytes:
    """The .glb bytes of `mesh` with its ARKit `shapes`, with `clips` animated (arguments as
    for `write_arkit_gltf`)."""
    built = _built(mesh, shapes, clips, tolerance, progress, units, mesh_units, Keys(rate, key_tolerance))
    data = built.glb_bytes()
    if progress is not None:
        progress(1.0)
    return data


def write_arkit_gltf(file, mesh: Mesh, shapes: ArkitShapes, clips=(), *,
                     tolerance: float | None = None, rate: float | None = None,
                     key_tolerance: float = 0.0, units: str = "m", mesh_units: str = "guess",
                     progress=None) -> int:
    """Write the .glb of `mesh` with its ARKit `shapes` as named morph targets and `clips`
    as animations of their weights to a binary file object (module docstring); returns the
    number of bytes written.

    mesh : the face, V vertices, in `mesh_units`.
    shapes : its 52 ARKit shapes, ``deltas`` (52, V, 3) mesh units.
    clips : `ArkitClip` objects, one animation each, in order.
    tolerance : mesh units; a vertex a shape moves no further is left out of its sparse
        target (default `arkit_tolerance` of the mesh; 0 keeps every vertex that moves).
    rate, key_tolerance, units, mesh_units : as for `retarget.gltf.write_gltf` (units "m"
        by default: metres; a weight's key tolerance is measured by the most its shape
        moves a vertex).
    progress : optional callable taking the fraction done in [0, 1].

    Raises `RetargetError` when the sizes disagree (naming both).
    """
    built = _built(mesh, shapes, clips, tolerance, progress, units, mesh_units, Keys(rate, key_tolerance))
    n_bytes = built.write(file)
    if progress is not None:
        progress(1.0)
    return n_bytes


def _built(mesh: Mesh, shapes: ArkitShapes, clips, tolerance, progress, units, mesh_units,
           keys: Keys) -> GlbBuilder:
    """The document and buffer of the export; progress reaches 0.95 (writing is left)."""
    clips = tuple(clips)
    _check(mesh, shapes, clips)
    clips = keys.resampled(clips)
    tolerance = arkit_tolerance(mesh.vertices) if tolerance is None else float(tolerance)
    if not np.isfinite(tolerance) or tolerance < 0:
        raise RetargetError(f"tolerance must be a finite number >= 0; got {tolerance!r}")
    mesh, clips, scaling = _scaled(mesh, clips, units, mesh_units)
    scale = scaling["scale"]
    tolerance *= scale
    step = _stepper(progress, len(shapes.names) + len(clips))
    out, doc, _ = _face_document(mesh)
    deltas = (delta * np.float32(scale) for delta in shapes.deltas) if scale != 1.0 else shapes.deltas
    add_morph_targets(out, doc["meshes"][0], deltas, shapes.names, tolerance=tolerance, step=step)
    doc["nodes"] = [{"name": mesh.name or "face", "mesh": 0}]
    doc["scene"] = 0
    doc["scenes"] = [{
        "name": mesh.name or "face",
        "nodes": [MESH_NODE],
        "extras": {"retarget": {"format": FORMAT, "deformation": "arkit", "method": "arkit",
                                "tolerance": tolerance, **scaling, **keys.record()}},
    }]
    writers = [KeyWriter(out, clip.times, keys.file_tolerance(scaling)) for clip in clips]
    reach = max(float(np.linalg.norm(shapes.deltas, axis=2).max(initial=0.0)) * scale, 1e-12)
    if clips:
        doc["animations"] = []
        for clip, writer in zip(clips, writers):
            doc["animations"].append({
                "name": clip.name,   # the weights (F * 52,) frame-major
                "samplers": [writer.sampler(clip.weights, scale=reach, weights=True)],
                "channels": [{"sampler": 0, "target": {"node": MESH_NODE, "path": "weights"}}],
            })
            step()
    _head(out, clips, mesh, [MESH_NODE], writers)
    return out


def _check(mesh: Mesh, shapes: ArkitShapes, clips) -> None:
    if not isinstance(shapes, ArkitShapes):
        raise RetargetError(f"shapes must be ArkitShapes; got {type(shapes).__name__}")
    if shapes.deltas.shape[1] != mesh.n_vertices:
        raise RetargetError(f"the ARKit shapes move {shapes.deltas.shape[1]} vertices but the mesh "
                            f"has {mesh.n_vertices}")
    for clip in clips:
        if not isinstance(clip, ArkitClip):
            raise RetargetError(f"clips must be ArkitClip objects; got {type(clip).__name__}")
