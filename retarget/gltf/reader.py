"""Read a .glb written by `retarget.gltf.export_gltf` back: mesh, landmarks, rig, clips.

The round trip of the export. What comes back, against what went in:

- the mesh: the same vertices (float32-rounded), triangles, uv, unit-length normals
  (`export_gltf` normalises them) and material, in the same vertex order;
- the landmarks from the scene's ``extras.retarget.landmarks``, exactly; a file without
  them gets the joints' neutral positions snapped to the surface;
- the skin weights: from JOINTS_n / WEIGHTS_n for a skin (the root's share becomes the
  implicit remainder again), from the morph targets otherwise; per vertex the same
  non-zero weights (float32), K being the busiest vertex's count;
- one `Clip` per animation: the feature joints' translations minus their neutral
  positions, at the animation's key times (the union of its channels' keys when a
  key-reduced export keys each channel apart), and the ``head`` node's rotations as its
  ``head_rotations`` when the export turned the head (`retarget.gltf.head`; a head
  translation beyond the turn about the pivot is not read back);
- the units: the scale the export applied (``extras.retarget.scale``,
  `retarget.gltf.units`) is divided out, so a face exported in metres comes back in its
  own units, named in ``units``.

The file is parsed and its accessors read by `retarget.gltf.document.GltfDocument`
(bounds-checked), its animation channels by `retarget.gltf.animation`. Files of another
layout (not one skin or morph-target primitive beside a static root of translation-only
feature joints) are refused with a `RetargetError` saying what is missing, rather than
read approximately.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from retarget.errors import RetargetError
from retarget.clips import Clip
from retarget.gltf.influences import weights_from_influences
from retarget.gltf.morph import weights_from_targets
from retarget.gltf.animation import animation_channels, sampled
from retarget.gltf.document import GltfDocument
from retarget.gltf.units import file_scale
from retarget.landmarks import SurfacePoints, from_positions, landmarks_from_json
from retarget.material import Material
from retarget.mesh import Mesh, mesh_from_arrays
from retarget.skin import SkinWeights


@dataclass(frozen=True, eq=False)
class RiggedFace:
    """What a .glb export holds.

    mesh : the target mesh (V vertices), units as exported.
    points : its N landmarks.
    weights : (V, K) skin weights over the N features.
    clips : one `Clip` per animation, in file order.
    joint_names : the N feature joints' names.
    deformation : "skin" (a glTF skin) or "morph" (morph targets).
    units : the mesh's unit as the export recorded it ("m", "cm", "mm", "in"), or None
        for a file that records none (its numbers are taken as they are).
    """

    mesh: Mesh
    points: SurfacePoints
    weights: SkinWeights
    clips: tuple[Clip, ...]
    joint_names: tuple[str, ...]
    deformation: str
    units: str | None = None



def read_gltf(source) -> RiggedFace:
    """Read an `export_gltf` .glb from a path, bytes or a binary file object."""
    data, label = _source_bytes(source)
    gltf = _document(data, label)
    nodes = gltf.doc.nodes or []
    extras = _retarget_extras(gltf)
    if extras.get("deformation") == "muscles":
        raise RetargetError(f"{label} is a muscle export (a morph target per muscle and a jaw "
                            "joint, animated by contractions): it holds no feature-point rig to read")
    if extras.get("deformation") == "arkit":
        raise RetargetError(f"{label} is an ARKit export (ARKit's 52 blendshapes as morph targets, "
                            "animated by their weights): it holds no feature-point rig to read")
    units, scale = file_scale(extras)
    head = _head_node(extras, nodes)
    mesh_node = _mesh_node(nodes, label)
    primitive = _primitive(gltf, nodes[mesh_node])
    root, features = _feature_nodes(gltf, mesh_node, head)
    neutral = np.array([_translation(nodes[i]) for i in features]) + _translation(nodes[root])
    names = tuple(str(nodes[i].name or f"feature_{k}") for k, i in enumerate(features))
    mesh = _mesh(gltf, nodes[mesh_node], primitive, scale)
    method = str(extras.get("method", ""))
    if nodes[mesh_node].skin is not None:
        weights = _skin_weights(gltf, primitive, len(features), method)
        deformation = "skin"
    elif primitive.targets:
        # target by target: a dense rig's 3N (V, 3) offsets are never stacked
        targets = [gltf.accessor(_index(t.get("POSITION"), label, "a morph target's POSITION"))
                   for t in primitive.targets]
        target_scale = gltf.doc.meshes[nodes[mesh_node].mesh].extras.get("targetScale", 1.0)
        weights = weights_from_targets(targets, len(features), float(target_scale), method)
        deformation = "morph"
    else:
        raise RetargetError(f"{label}: its mesh has neither a skin nor morph targets")
    if weights.n_vertices != mesh.n_vertices:
        raise RetargetError(f"{label}: {weights.n_vertices} skinned vertices for a mesh of "
                            f"{mesh.n_vertices}")
    if "landmarks" in extras:
        points = landmarks_from_json(extras["landmarks"], mesh.vertices, mesh.faces)
        if points.n_points != len(features):
            raise RetargetError(f"{label}: {points.n_points} landmarks for "
                                f"{len(features)} feature joints")
    else:
        points = from_positions(neutral, mesh.vertices, mesh.faces)
    joint_position = {node: p for node, p in zip(features, neutral.astype(np.float32))}
    clips = tuple(_clip(gltf, k, joint_position, head, scale)
                  for k in range(len(gltf.doc.animations or [])))
    return RiggedFace(mesh, points, weights, clips, names, deformation, units)


def _source_bytes(source) -> tuple[bytes, str]:
    if isinstance(source, (bytes, bytearray, memoryview)):
        return bytes(source), "the given bytes"
    if isinstance(source, (str, os.PathLike)):
        try:
            return Path(source).read_bytes(), repr(str(source))
        except OSError as exc:
            raise RetargetError(f"could not read {str(source)!r}: {exc}") from exc
    if hasattr(source, "read"):
        data = source.read()
        if not isinstance(data, bytes):
            raise RetargetError("the glTF file object must be opened in binary mode")
        return data, f"file {getattr(source, 'name', 'object')!r}"
    raise RetargetError(f"source must be a path, bytes or a binary file object, "
                        f"got {type(source).__name__}")


def _document(data: bytes, label: str) -> GltfDocument:
    """The parsed GLB (the export is always binary, never a .gltf's JSON)."""
    if data[:4] != b"glTF":
        raise RetargetError(f"{label} is not a GLB file (it does not start with 'glTF')")
    return GltfDocument(data, label, None)


def _index(value, label: str, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise RetargetError(f"{label}: {what} is not an accessor index ({value!r})")
    return value


def _retarget_extras(gltf: GltfDocument) -> dict:
    scenes = gltf.doc.scenes or []
    scene = gltf.item(scenes, gltf.doc.scene or 0, "scene") if scenes else None
    extras = scene.extras if scene is not None else {}
    found = extras.get("retarget", {}) if isinstance(extras, dict) else {}
    return found if isinstance(found, dict) else {}


def _head_node(extras: dict, nodes) -> tuple[int, int] | None:
    """The ``head`` and ``head_pivot`` nodes the export recorded (`retarget.gltf.head`), or
    None."""
    head = extras.get("head")
    if not isinstance(head, dict):
        return None
    found = head.get("node"), head.get("pivot_node")
    if any(isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < len(nodes) for i in found):
        return None
    return found


def _mesh_node(nodes, label: str) -> int:
    with_mesh = [i for i, node in enumerate(nodes) if node.mesh is not None]
    if len(with_mesh) != 1:
        raise RetargetError(f"{label}: expected one node with a mesh, found {len(with_mesh)}")
    return with_mesh[0]


def _primitive(gltf: GltfDocument, node):
    primitives = gltf.item(gltf.doc.meshes, node.mesh, "mesh").primitives
    if len(primitives) != 1 or (primitives[0].mode if primitives[0].mode is not None else 4) != 4:
        raise RetargetError(f"{gltf.label}: expected a mesh of one triangle primitive")
    if primitives[0].attributes.POSITION is None:
        raise RetargetError(f"{gltf.label}: its mesh has no POSITION attribute")
    return primitives[0]


def _feature_nodes(gltf: GltfDocument, mesh_node: int, head) -> tuple[int, list[int]]:
    """(root node, feature nodes in joint order): the skin's joints after its root, or
    the children of the scene's other root node for a morph-target mesh (the ``head``
    node, when there is one, stands for the children of its ``head_pivot``)."""
    nodes, label = gltf.doc.nodes, gltf.label
    skin = nodes[mesh_node].skin
    if skin is not None:
        joints = gltf.item(gltf.doc.skins, skin, "skin").joints
        if not joints:
            raise RetargetError(f"{label}: skin {skin} has no joints")
        root, features = joints[0], list(joints[1:])
        gltf.item(nodes, root, "skin joint")
        if sorted(nodes[root].children or []) != sorted(features):
            raise RetargetError(f"{label}: the skin's first joint is not the parent of the "
                                "others (not a static root with feature joints)")
    else:
        scenes = gltf.doc.scenes or []
        roots = list(scenes[gltf.doc.scene or 0].nodes or []) if scenes else []
        if head is not None and head[0] in roots:
            roots = [i for i in roots if i != head[0]] + list(nodes[head[1]].children or [])
        parents = [i for i in roots
                   if i != mesh_node and gltf.item(nodes, i, "scene node").children]
        if len(parents) != 1:
            raise RetargetError(f"{label}: expected one root node holding the feature "
                                f"joints beside the mesh, found {len(parents)}")
        root, features = parents[0], list(nodes[parents[0]].children)
    for i in [root, *features]:
        node = gltf.item(nodes, i, "joint node")
        if any(value is not None for value in (node.rotation, node.scale, node.matrix)):
            raise RetargetError(f"{label}: joint node {i} ({node.name or ''!r}) is "
                                "not translation-only")
    return root, features


def _translation(node) -> np.ndarray:
    return np.array(node.translation or (0.0, 0.0, 0.0), dtype=np.float64)


def _mesh(gltf: GltfDocument, node, primitive, scale: float) -> Mesh:
    attributes = primitive.attributes
    vertices = gltf.accessor(attributes.POSITION)
    if scale != 1.0:  # back to the mesh's units, float32-rounded as the file's numbers are
        vertices = (vertices.astype(np.float64) / scale).astype(np.float32)
    if primitive.indices is not None:
        faces = gltf.accessor(primitive.indices)[:, 0].astype(np.int64)
    else:
        faces = np.arange(len(vertices), dtype=np.int64)
    if len(faces) % 3:
        raise RetargetError(f"{gltf.label}: its triangle indices are not a multiple of 3")
    normals = uv = None
    if attributes.NORMAL is not None:
        normals = gltf.accessor(attributes.NORMAL)
    if attributes.TEXCOORD_0 is not None:
        st = gltf.accessor(attributes.TEXCOORD_0)
        uv = np.column_stack([st[:, 0], 1.0 - st[:, 1]])  # back to OBJ's v
    material = None if primitive.material is None else _material(gltf, primitive.material)
    return mesh_from_arrays(vertices, faces.reshape(-1, 3), uv=uv, normals=normals,
                            name=node.name or "", material=material)


def _material(gltf: GltfDocument, index: int) -> Material:
    """Material `index` as `retarget.material.Material` (base colour image included)."""
    entry = gltf.item(gltf.doc.materials, index, "material")
    pbr = entry.pbrMetallicRoughness
    texture = None
    if pbr is not None and pbr.baseColorTexture is not None:
        source = gltf.item(gltf.doc.textures, pbr.baseColorTexture.index, "texture").source
        image = gltf.item(gltf.doc.images, source, "image")
        texture = _view_bytes(gltf, image.bufferView)
    return Material(
        name=entry.name or "",
        base_color=tuple(pbr.baseColorFactor if pbr is not None else (1.0, 1.0, 1.0, 1.0)),
        metallic=pbr.metallicFactor if pbr is not None else 1.0,
        roughness=pbr.roughnessFactor if pbr is not None else 1.0,
        double_sided=bool(entry.doubleSided),
        alpha_mode=entry.alphaMode or "OPAQUE",
        base_color_texture=texture,
    )


def _view_bytes(gltf: GltfDocument, index) -> bytes:
    """The bytes of buffer view `index` (an embedded image)."""
    view = gltf.item(gltf.doc.bufferViews, index, "image bufferView")
    data = gltf.item(gltf.buffers, view.buffer, f"bufferView {index}: buffer")
    start = view.byteOffset or 0
    if start + view.byteLength > len(data):
        raise RetargetError(f"{gltf.label}: bufferView {index} reads past the end of its buffer")
    return bytes(data[start:start + view.byteLength])


def _skin_weights(gltf: GltfDocument, primitive, n_features: int, method: str) -> SkinWeights:
    attributes = vars(primitive.attributes)
    sets = sorted(int(key.split("_")[1]) for key, value in attributes.items()
                  if key.startswith("JOINTS_") and value is not None)
    if not sets or sets != list(range(len(sets))):
        raise RetargetError(f"{gltf.label}: its skinned mesh has JOINTS sets {sets}; expected "
                            "JOINTS_0 onwards")
    missing = [f"WEIGHTS_{s}" for s in sets if attributes.get(f"WEIGHTS_{s}") is None]
    if missing:
        raise RetargetError(f"{gltf.label}: {missing[0]} is missing beside its JOINTS set")
    joints = np.hstack([gltf.accessor(attributes[f"JOINTS_{s}"]) for s in sets])
    influence = np.hstack([gltf.accessor(attributes[f"WEIGHTS_{s}"]) for s in sets])
    return weights_from_influences(joints.astype(np.int64), influence, n_features, method)


def _clip(gltf: GltfDocument, k: int, joint_position: dict, head, scale: float) -> Clip:
    """Animation k as a Clip: feature translations minus neutral over `scale`, and the head
    node's rotations, at every time any of them is keyed (each channel sampled there as a
    viewer interpolates it: exact at its own keys, so an export whose channels share their
    keys comes back at exactly those, and a key-reduced one at the union of its keys)."""
    animation = gltf.doc.animations[k]
    name = str(animation.name or f"animation_{k}")
    moved, turns = {}, None
    for node, path, keys, values, interpolation in animation_channels(gltf, animation):
        read = head is not None and node == head[0] and path == "rotation"
        if not read and (path != "translation" or node not in joint_position):
            continue
        if interpolation != "LINEAR":
            raise RetargetError(f"{gltf.label}: animation {name!r} interpolates "
                                f"{interpolation}; LINEAR keys are read")
        if read:
            turns = keys, values
        else:
            moved[node] = keys, values
    if not moved:
        raise RetargetError(f"{gltf.label}: animation {name!r} moves no feature joint")
    keyed = [keys for keys, _ in moved.values()] + ([turns[0]] if turns is not None else [])
    times = keyed[0] if all(np.array_equal(keyed[0], t) for t in keyed) else np.unique(np.concatenate(keyed))
    displacements = np.zeros((len(times), len(joint_position), 3), np.float32)
    for i, (node, rest) in enumerate(joint_position.items()):
        if node in moved:
            displacements[:, i] = _at(times, *moved[node]) - rest
    if scale != 1.0:
        displacements = displacements / np.float32(scale)
    rotations = None if turns is None else _at(times, *turns, rotation=True)
    return Clip(name, displacements, times, head_rotations=rotations)


def _at(times: np.ndarray, keys: np.ndarray, values: np.ndarray, rotation: bool = False) -> np.ndarray:
    """A LINEAR channel's values at `times`: its own where they are its keys."""
    if np.array_equal(keys, times):
        return values
    return sampled(keys.astype(np.float64), values.astype(np.float64), "LINEAR",
                   times.astype(np.float64), rotation)
