"""Animated glTF/GLB faces as takes: the labelled points of a morphed, skinned or
node-animated mesh, sampled at a frame rate."""

from __future__ import annotations

import io
import math

import numpy as np

from retarget.errors import RetargetError
from retarget.gltf_animation import (animated_weights, animation_channels, mesh_instances,
                                     node_transforms, posed_vertices, transformed)
from retarget.gltf_document import GltfDocument
from retarget.sources.labelled_points import labelled_positions, labelled_surface_points
from retarget.sources.take import DEFAULT_FPS

__all__ = ["MAX_SAMPLED_FRAMES", "gltf_points"]

MAX_SAMPLED_FRAMES = 200_000
"""Most frames an animation is sampled into."""


def gltf_points(data: bytes, label: str, kind: str, folder, labelled, layout, fps):
    """((F, K, 3) points, K names, fps, meta) of the labelled points of the first
    animation of a glTF/GLB face, sampled every 1 / fps s (see `retarget.sources.files`)."""
    gltf = GltfDocument(data, label, folder)
    doc = gltf.doc
    nodes = doc.nodes or []
    instances = mesh_instances(gltf)
    if not instances:
        raise RetargetError(f"{label} holds no triangle mesh")
    if not doc.animations:
        raise RetargetError(f"{label} holds no animation")
    animation = doc.animations[0]
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
    free = list(range(len(instances)))
    order = []
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        part = scene.geometry[name]
        if not isinstance(part, trimesh.Trimesh):
            continue
        seen = part.vertices @ transform[:3, :3].T + transform[:3, 3]
        match = next((i for i in free if len(instances[i]["positions"]) == len(seen) and np.allclose(
            transformed(static[instances[i]["node"]], instances[i]["positions"]), seen, atol=1e-5)), None)
        if match is None:
            raise RetargetError(f"{label}: could not match the mesh {name!r} to a glTF primitive")
        free.remove(match)
        order.append(match)
    return order + free
