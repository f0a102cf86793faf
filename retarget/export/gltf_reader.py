"""Read a .glb written by `retarget.export.export_gltf` back: mesh, landmarks, rig, clips.

The round trip of the export. What comes back, against what went in:

- the mesh: the same vertices (float32-rounded), triangles, uv, unit-length normals
  (`export_gltf` normalises them) and material, in the same vertex order;
- the landmarks from the scene's ``extras.retarget.landmarks``, exactly; a file without
  them gets the joints' neutral positions snapped to the surface;
- the skin weights: from JOINTS_n / WEIGHTS_n for a skin (the root's share becomes the
  implicit remainder again), from the morph targets otherwise; per vertex the same
  non-zero weights (float32), K being the busiest vertex's count;
- one `Clip` per animation: the feature joints' translations minus their neutral
  positions, at the animation's key times.

Files of another layout (not one skin or morph-target primitive beside a static root of
translation-only feature joints) are refused with a `RetargetError` saying what is
missing, rather than read approximately.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from retarget.errors import RetargetError
from retarget.export.clips import Clip
from retarget.export.glb import accessor_array, glb_document
from retarget.export.influences import weights_from_influences
from retarget.export.morph import weights_from_targets
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
    """

    mesh: Mesh
    points: SurfacePoints
    weights: SkinWeights
    clips: tuple[Clip, ...]
    joint_names: tuple[str, ...]
    deformation: str


def read_gltf(source) -> RiggedFace:
    """Read an `export_gltf` .glb from a path, bytes or a binary file object."""
    data, label = _source_bytes(source)
    doc, binary = glb_document(data, label)
    nodes = doc.get("nodes", [])
    extras = _retarget_extras(doc)
    mesh_node = _mesh_node(doc, label)
    primitive = _primitive(doc, nodes[mesh_node], label)
    root, features = _feature_nodes(doc, mesh_node, label)
    neutral = np.array([_translation(nodes[i]) for i in features]) + _translation(nodes[root])
    names = tuple(str(nodes[i].get("name", f"feature_{k}")) for k, i in enumerate(features))
    mesh = _mesh(doc, binary, mesh_node, primitive)
    method = str(extras.get("method", ""))
    if "skin" in nodes[mesh_node]:
        weights = _skin_weights(doc, binary, primitive, len(features), method, label)
        deformation = "skin"
    elif primitive.get("targets"):
        targets = [accessor_array(doc, binary, t["POSITION"]) for t in primitive["targets"]]
        scale = doc["meshes"][nodes[mesh_node]["mesh"]].get("extras", {}).get("targetScale", 1.0)
        weights = weights_from_targets(targets, len(features), float(scale), method)
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
    clips = tuple(_clip(doc, binary, k, joint_position, label)
                  for k in range(len(doc.get("animations", []))))
    return RiggedFace(mesh, points, weights, clips, names, deformation)


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


def _retarget_extras(doc: dict) -> dict:
    scenes = doc.get("scenes", [])
    scene = scenes[doc.get("scene", 0)] if scenes else {}
    extras = scene.get("extras", {}) if isinstance(scene, dict) else {}
    found = extras.get("retarget", {}) if isinstance(extras, dict) else {}
    return found if isinstance(found, dict) else {}


def _mesh_node(doc: dict, label: str) -> int:
    with_mesh = [i for i, node in enumerate(doc.get("nodes", [])) if "mesh" in node]
    if len(with_mesh) != 1:
        raise RetargetError(f"{label}: expected one node with a mesh, found {len(with_mesh)}")
    return with_mesh[0]


def _primitive(doc: dict, node: dict, label: str) -> dict:
    primitives = doc["meshes"][node["mesh"]].get("primitives", [])
    if len(primitives) != 1 or primitives[0].get("mode", 4) != 4:
        raise RetargetError(f"{label}: expected a mesh of one triangle primitive")
    if "POSITION" not in primitives[0].get("attributes", {}):
        raise RetargetError(f"{label}: its mesh has no POSITION attribute")
    return primitives[0]


def _feature_nodes(doc: dict, mesh_node: int, label: str) -> tuple[int, list[int]]:
    """(root node, feature nodes in joint order): the skin's joints after its root, or
    the children of the scene's other root node for a morph-target mesh."""
    nodes = doc["nodes"]
    skin = nodes[mesh_node].get("skin")
    if skin is not None:
        joints = doc["skins"][skin]["joints"]
        root, features = joints[0], list(joints[1:])
        if sorted(nodes[root].get("children", [])) != sorted(features):
            raise RetargetError(f"{label}: the skin's first joint is not the parent of the "
                                "others (not a static root with feature joints)")
    else:
        scenes = doc.get("scenes", [])
        roots = scenes[doc.get("scene", 0)]["nodes"] if scenes else []
        parents = [i for i in roots if i != mesh_node and nodes[i].get("children")]
        if len(parents) != 1:
            raise RetargetError(f"{label}: expected one root node holding the feature "
                                f"joints beside the mesh, found {len(parents)}")
        root, features = parents[0], list(nodes[parents[0]]["children"])
    for i in [root, *features]:
        if any(key in nodes[i] for key in ("rotation", "scale", "matrix")):
            raise RetargetError(f"{label}: joint node {i} ({nodes[i].get('name', '')!r}) is "
                                "not translation-only")
    return root, features


def _translation(node: dict) -> np.ndarray:
    return np.array(node.get("translation", (0.0, 0.0, 0.0)), dtype=np.float64)


def _mesh(doc: dict, binary: bytes, mesh_node: int, primitive: dict) -> Mesh:
    attributes = primitive["attributes"]
    vertices = accessor_array(doc, binary, attributes["POSITION"])
    if "indices" in primitive:
        faces = accessor_array(doc, binary, primitive["indices"]).astype(np.int64)
    else:
        faces = np.arange(len(vertices), dtype=np.int64)
    normals = uv = None
    if "NORMAL" in attributes:
        normals = accessor_array(doc, binary, attributes["NORMAL"])
    if "TEXCOORD_0" in attributes:
        st = accessor_array(doc, binary, attributes["TEXCOORD_0"]).astype(np.float64)
        uv = np.column_stack([st[:, 0], 1.0 - st[:, 1]])  # back to OBJ's v
    name = doc["nodes"][mesh_node].get("name", "")
    material = _material(doc, binary, primitive["material"]) if "material" in primitive else None
    return mesh_from_arrays(vertices, faces.reshape(-1, 3), uv=uv, normals=normals, name=name,
                            material=material)


def _material(doc: dict, binary: bytes, index: int) -> Material:
    """Material `index` as `retarget.material.Material` (base colour image included)."""
    entry = doc["materials"][index]
    pbr = entry.get("pbrMetallicRoughness", {})
    texture = None
    if "baseColorTexture" in pbr:
        image = doc["images"][doc["textures"][pbr["baseColorTexture"]["index"]]["source"]]
        view = doc["bufferViews"][image["bufferView"]]
        start = view.get("byteOffset", 0)
        texture = binary[start:start + view["byteLength"]]
    return Material(
        name=entry.get("name", ""),
        base_color=tuple(pbr.get("baseColorFactor", (1.0, 1.0, 1.0, 1.0))),
        metallic=pbr.get("metallicFactor", 1.0),
        roughness=pbr.get("roughnessFactor", 1.0),
        double_sided=entry.get("doubleSided", False),
        alpha_mode=entry.get("alphaMode", "OPAQUE"),
        base_color_texture=texture,
    )


def _skin_weights(doc, binary, primitive, n_features, method, label) -> SkinWeights:
    attributes = primitive["attributes"]
    sets = sorted(int(key.split("_")[1]) for key in attributes if key.startswith("JOINTS_"))
    if not sets or sets != list(range(len(sets))):
        raise RetargetError(f"{label}: its skinned mesh has JOINTS sets {sets}; expected "
                            "JOINTS_0 onwards")
    try:
        joints = np.hstack([accessor_array(doc, binary, attributes[f"JOINTS_{s}"]) for s in sets])
        influence = np.hstack([accessor_array(doc, binary, attributes[f"WEIGHTS_{s}"]) for s in sets])
    except KeyError as exc:
        raise RetargetError(f"{label}: {exc.args[0]} is missing beside its JOINTS set") from None
    if influence.dtype != np.float32:
        raise RetargetError(f"{label}: its skin weights are {influence.dtype}; float weights "
                            "are read")
    return weights_from_influences(joints, influence, n_features, method)


def _clip(doc, binary, k, joint_position, label) -> Clip:
    """Animation k as a Clip: feature translations minus neutral, at the shared times."""
    animation = doc["animations"][k]
    name = str(animation.get("name", f"animation_{k}"))
    samplers = animation.get("samplers", [])
    times, moved = None, {}
    for channel in animation.get("channels", []):
        target = channel.get("target", {})
        node = target.get("node")
        if target.get("path") != "translation" or node not in joint_position:
            continue
        sampler = samplers[channel["sampler"]]
        if sampler.get("interpolation", "LINEAR") != "LINEAR":
            raise RetargetError(f"{label}: animation {name!r} interpolates "
                                f"{sampler['interpolation']}; LINEAR keys are read")
        t = accessor_array(doc, binary, sampler["input"])
        if times is None:
            times = t
        elif not np.array_equal(times, t):
            raise RetargetError(f"{label}: animation {name!r} keys its joints at different "
                                "times; one set of key times is read")
        moved[node] = accessor_array(doc, binary, sampler["output"])
    if times is None:
        raise RetargetError(f"{label}: animation {name!r} moves no feature joint")
    displacements = np.zeros((len(times), len(joint_position), 3), np.float32)
    for i, (node, rest) in enumerate(joint_position.items()):
        if node in moved:
            displacements[:, i] = moved[node] - rest
    return Clip(name, displacements, times.astype(np.float64))
