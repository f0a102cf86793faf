"""Animated glTF/GLB faces as takes: the labelled points of a morphed, skinned or
node-animated mesh, sampled at a frame rate."""

from __future__ import annotations

import io
import itertools
import math

import numpy as np

from retarget.errors import RetargetError
from retarget.gltf.animation import (animated_weights, animation_channels, mesh_instances,
                                     node_transforms, posed_vertices, transformed)
from retarget.gltf.document import GltfDocument
from retarget.sources.labelled_points import labelled_positions, labelled_surface_points
from retarget.sources.take import DEFAULT_FPS

_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}

__all__ = ["MAX_INSTANCED_VERTICES", "MAX_KEYFRAME_VALUES", "MAX_SAMPLED_FRAMES",
           "MAX_SAMPLED_VALUES", "gltf_points"]

MAX_SAMPLED_FRAMES = 200_000
"""Most frames an animation is sampled into."""

MAX_INSTANCED_VERTICES = 4_000_000
"""Most vertices the mesh nodes of a glTF take may instance, counted from the JSON before
any accessor is read. Each node that places a mesh reads its primitives again, so a mesh
placed by k nodes counts k times; each morph target and each JOINTS_n / WEIGHTS_n set
counts the vertices once more and each triangle counts as one vertex. The sample face
(8,430 vertices, 12 targets) counts 126,000."""

MAX_KEYFRAME_VALUES = 16_000_000
"""Most key times and values the first animation's channels may hold (128 MB as
float64), counted from the JSON before they are read: 200 morph weights at 60 fps for
20 minutes."""

MAX_SAMPLED_VALUES = 25_000_000
"""Most values sampling may make (200 MB as float64), checked before it starts: frames x
(32 per node, its local and world matrices, + 22 per labelled vertex, its morphed,
skinned and posed positions)."""


def gltf_points(data: bytes, label: str, kind: str, folder, labelled, layout, fps):
    """((F, K, 3) points, K names, fps, meta) of the labelled points of the first
    animation of a glTF/GLB face, sampled every 1 / fps s (see `retarget.sources.files`)."""
    gltf = GltfDocument(data, label, folder)
    doc = gltf.doc
    nodes = doc.nodes or []
    mesh_nodes, instanced = _instanced_vertices(gltf)
    if instanced > MAX_INSTANCED_VERTICES:
        raise RetargetError(
            f"{label}: its {mesh_nodes} mesh node(s) instance {instanced} vertices (each morph "
            f"target and joint set counting again); at most {MAX_INSTANCED_VERTICES} are read")
    instances = mesh_instances(gltf)
    if not instances:
        raise RetargetError(f"{label} holds no triangle mesh")
    if not doc.animations:
        raise RetargetError(f"{label} holds no animation")
    animation = doc.animations[0]
    keyframes = _keyframe_values(gltf, animation)
    if keyframes > MAX_KEYFRAME_VALUES:
        raise RetargetError(
            f"{label}: the animation's channels hold {keyframes} key times and values; at most "
            f"{MAX_KEYFRAME_VALUES} are read")
    channels = animation_channels(gltf, animation)
    keys = np.unique(np.concatenate([c[2] for c in channels]))
    start, stop = float(keys[0]), float(keys[-1])
    if fps is None:
        steps = np.diff(keys)
        even = len(steps) and np.allclose(steps, steps[0], rtol=1e-3) and steps[0] > 0
        fps, assumed = (float(1.0 / steps[0]), False) if even else (DEFAULT_FPS, True)
    else:
        assumed = False
    count = math.floor((stop - start) * fps + 1e-3) + 1  # key times are often float32
    if count > MAX_SAMPLED_FRAMES:
        raise RetargetError(
            f"{label}: the animation lasts {stop - start:.6g} s, {count} frames at {fps:g} fps; "
            f"at most {MAX_SAMPLED_FRAMES} are sampled")
    times = start + np.arange(count) / fps

    static = node_transforms(gltf, nodes, [], np.zeros(1))[0]
    order = _load_mesh_order(data, kind, folder, instances, static, gltf, label)
    blocks, offset = [], 0
    for i in order:
        blocks.append(offset)
        offset += len(instances[i]["positions"])
    rest = np.concatenate([transformed(static[instances[i]["node"]], instances[i]["positions"])
                           for i in order])
    faces = np.concatenate([instances[i]["faces"] + blocks[k] for k, i in enumerate(order)])
    vertex_indices, barycentric, names = labelled_surface_points(labelled, rest, faces, layout, label)
    used = np.unique(vertex_indices)
    sampled = count * (32 * len(nodes) + 22 * len(used))
    if sampled > MAX_SAMPLED_VALUES:
        raise RetargetError(
            f"{label}: sampling {count} frames of {len(nodes)} node(s) and {len(used)} labelled "
            f"vertices makes {sampled} values; at most {MAX_SAMPLED_VALUES} (a lower fps or "
            "fewer nodes)")

    world = node_transforms(gltf, nodes, channels, times)      # (F, nodes, 4, 4)
    weights = animated_weights(gltf, channels, times)          # {node: (F, targets)}
    posed = np.empty((len(times), len(used), 3))
    for k, i in enumerate(order):
        inst = instances[i]
        inside = (used >= blocks[k]) & (used < blocks[k] + len(inst["positions"]))
        if inside.any():
            posed[:, inside] = posed_vertices(gltf, inst, used[inside] - blocks[k], world, weights, times)
    points = labelled_positions(posed, used, vertex_indices, barycentric)
    meta = {"fps_assumed": assumed, "animation": animation.name or "0",
            "animations": len(doc.animations), "n_vertices": int(len(rest))}
    return points, names, fps, meta


def _instanced_vertices(gltf) -> tuple[int, int]:
    """(nodes with a mesh, vertices they instance as `MAX_INSTANCED_VERTICES` counts
    them), from the JSON's accessor counts (what `mesh_instances` will read)."""
    doc = gltf.doc
    nodes = total = 0
    for n, node in enumerate(doc.nodes or []):
        if node.mesh is None:
            continue
        nodes += 1
        mesh = gltf.item(doc.meshes, node.mesh, f"node {n}: mesh")
        for prim in mesh.primitives or []:
            if (prim.mode if prim.mode is not None else 4) != 4 or prim.attributes.POSITION is None:
                continue
            vertices = _count(gltf, prim.attributes.POSITION)
            sets = sum(getattr(prim.attributes, f"JOINTS_{s}", None) is not None for s in range(8))
            total += vertices * (1 + len(prim.targets or []) + 2 * sets)
            total += (_count(gltf, prim.indices) if prim.indices is not None else vertices) // 3
    return nodes, total


def _keyframe_values(gltf, animation) -> int:
    """Key times and values (elements x width) of the animation's samplers that its
    channels use, from the JSON's accessor counts."""
    total = 0
    for c, channel in enumerate(animation.channels or []):
        sampler = gltf.item(animation.samplers, channel.sampler, f"animation channel {c}: sampler")
        for index in (sampler.input, sampler.output):
            accessor = gltf.item(gltf.doc.accessors, index, f"animation channel {c}: accessor")
            total += _count(gltf, index) * _WIDTHS.get(accessor.type, 16)
    return total


def _count(gltf, index) -> int:
    """An accessor's declared element count, checked (as `GltfDocument.accessor` will
    check it, with the same message) to lie within its buffer when it has a bufferView."""
    accessor = gltf.item(gltf.doc.accessors, index, "accessor")
    count = accessor.count
    if isinstance(count, bool) or not isinstance(count, int) or count < 0:
        raise RetargetError(f"{gltf.label}: accessor {index} has count {count!r}")
    if accessor.bufferView is not None and count:
        view = gltf.item(gltf.doc.bufferViews, accessor.bufferView, f"accessor {index}: bufferView")
        data = gltf.item(gltf.buffers, view.buffer, f"accessor {index}: buffer")
        element = _WIDTHS.get(accessor.type, 16) * _COMPONENT_BYTES.get(accessor.componentType, 4)
        start = (view.byteOffset or 0) + (accessor.byteOffset or 0)
        end_view = (view.byteOffset or 0) + (view.byteLength or 0)
        if start + (view.byteStride or element) * (count - 1) + element > min(end_view, len(data)):
            raise RetargetError(f"{gltf.label}: accessor {index} reads past the end of its buffer")
    return count


def _load_mesh_order(data, kind, folder, instances, static, gltf, label) -> list[int]:
    """Indices into `instances` in the order `retarget.mesh.load_mesh` concatenates the
    file's meshes (trimesh's scene order), matched by vertex count and rest positions."""
    if len(instances) == 1:
        return [0]
    import trimesh

    resolver = trimesh.resolvers.FilePathResolver(str(folder)) if folder is not None else None
    try:
        scene = trimesh.load_scene(io.BytesIO(data), file_type=kind, resolver=resolver,
                                   process=False, maintain_order=True)
    except Exception as exc:
        raise RetargetError(f"could not read {label} as a mesh: {exc}") from None
    # rest positions once per instance, and instances bucketed by vertex count and rounded
    # centroid, so each of trimesh's meshes is compared with its likely match only (a
    # scan of every free instance per mesh took 97 s for 2,000 instances of a triangle)
    rests = [transformed(static[inst["node"]], inst["positions"]) for inst in instances]
    buckets: dict[tuple, list[int]] = {}
    for i, rest in enumerate(rests):
        buckets.setdefault(_match_key(rest), []).append(i)
    free = set(range(len(instances)))
    order = []
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        part = scene.geometry[name]
        if not isinstance(part, trimesh.Trimesh):
            continue
        seen = part.vertices @ transform[:3, :3].T + transform[:3, 3]
        likely = [i for i in buckets.get(_match_key(seen), ()) if i in free]
        others = (i for i in sorted(free) if len(rests[i]) == len(seen))  # rounding at an edge
        match = next((i for i in itertools.chain(likely, others) if len(rests[i]) == len(seen)
                      and np.allclose(rests[i], seen, atol=1e-5)), None)
        if match is None:
            raise RetargetError(f"{label}: could not match the mesh {name!r} to a glTF primitive")
        free.discard(match)
        order.append(match)
    return order + sorted(free)


def _match_key(positions: np.ndarray) -> tuple:
    """(vertex count, centroid rounded to 1e-4): equal for the same positions read twice."""
    return (len(positions), *np.round(positions.mean(axis=0), 4).tolist())
