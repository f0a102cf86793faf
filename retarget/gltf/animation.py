"""Evaluating glTF 2.0 animation: sampled channels, node world matrices, and the posed
vertices of morphed and skinned meshes, as the glTF 2.0 specification defines them
(§3.7 skins and morph targets: morphing first, then skinning; §3.11 animation samplers).

Used to read animated faces as takes and to check our own skinned exports against what
any conforming viewer computes.
"""

from __future__ import annotations

import numpy as np

from retarget.errors import RetargetError
from retarget.gltf.document import GltfDocument

__all__ = ["animated_weights", "animation_channels", "drawn_vertices", "mesh_instances",
           "node_transforms", "posed_vertices", "sampled", "transformed", "trs_matrices"]


def mesh_instances(gltf: GltfDocument) -> list[dict]:
    """Every triangle primitive of every node with a mesh, in node then primitive order:
    {node, mesh, positions (n, 3), faces (m, 3) local, targets (T, n, 3), skin, joints,
    weights, default_weights}."""
    doc = gltf.doc
    out = []
    for n, node in enumerate(doc.nodes or []):
        if node.mesh is None:
            continue
        mesh = gltf.item(doc.meshes, node.mesh, f"node {n}: mesh")
        for p, prim in enumerate(mesh.primitives):
            if (prim.mode if prim.mode is not None else 4) != 4:
                continue
            attributes = prim.attributes
            if attributes.POSITION is None:
                raise RetargetError(f"{gltf.label}: mesh {node.mesh} primitive {p} has no POSITION")
            positions = gltf.accessor(attributes.POSITION)[:, :3]
            if prim.indices is not None:
                faces = gltf.accessor(prim.indices)[:, 0].astype(np.int64)
            else:
                faces = np.arange(len(positions), dtype=np.int64)
            faces = faces[:len(faces) // 3 * 3].reshape(-1, 3)
            if len(faces) and (faces.max() >= len(positions)):
                raise RetargetError(f"{gltf.label}: mesh {node.mesh} primitive {p} indexes past its vertices")
            targets = np.stack([gltf.accessor(t["POSITION"])[:, :3] if t.get("POSITION") is not None
                                else np.zeros_like(positions) for t in (prim.targets or [])]) \
                if prim.targets else np.zeros((0, len(positions), 3))
            if targets.shape[1:] != positions.shape:
                raise RetargetError(
                    f"{gltf.label}: mesh {node.mesh} primitive {p} has morph targets of another size")
            joints, weights = [], []
            for s in range(8):
                j, w = getattr(attributes, f"JOINTS_{s}", None), getattr(attributes, f"WEIGHTS_{s}", None)
                if j is None or w is None:
                    break
                joints.append(gltf.accessor(j).astype(np.int64))
                weights.append(gltf.accessor(w))
            default = gltf.node_weights.get(n, mesh.weights)
            out.append({
                "node": n, "mesh": node.mesh, "positions": positions, "faces": faces,
                "targets": targets, "skin": node.skin if joints else None,
                "joints": np.concatenate(joints, axis=1) if joints else None,
                "weights": np.concatenate(weights, axis=1) if weights else None,
                "default_weights": np.zeros(len(targets)) if default is None
                else np.resize(np.asarray(default, dtype=np.float64), len(targets)),
            })
    return out


def animation_channels(gltf: GltfDocument, animation) -> list[tuple]:
    """[(node, path, (K,) key times, (K, width) or (K, 3, width) values, interpolation)]."""
    out = []
    for c, channel in enumerate(animation.channels):
        target = channel.target
        if target.node is None or target.path not in ("translation", "rotation", "scale", "weights"):
            continue
        gltf.item(gltf.doc.nodes, target.node, f"animation channel {c}: node")
        sampler = gltf.item(animation.samplers, channel.sampler, f"animation channel {c}: sampler")
        keys = gltf.accessor(sampler.input)[:, 0]
        values = gltf.accessor(sampler.output)
        interpolation = sampler.interpolation or "LINEAR"
        if len(keys) == 0 or not np.isfinite(keys).all() or (np.diff(keys) < 0).any():
            raise RetargetError(f"{gltf.label}: animation channel {c} has no or unordered key times")
        per_key = 3 if interpolation == "CUBICSPLINE" else 1
        if target.path == "weights":
            if len(values) % (len(keys) * per_key):
                raise RetargetError(f"{gltf.label}: animation channel {c}: weights do not fit the keys")
            values = values.reshape(len(keys) * per_key, -1)
        if len(values) != len(keys) * per_key:
            raise RetargetError(
                f"{gltf.label}: animation channel {c} has {len(values)} values for {len(keys)} keys")
        if per_key == 3:
            values = values.reshape(len(keys), 3, -1)
        out.append((target.node, target.path, keys, values, interpolation))
    if not out:
        raise RetargetError(f"{gltf.label}: the animation animates no node or morph weights")
    return out


def sampled(keys, values, interpolation, times, rotation: bool) -> np.ndarray:
    """(F, width) values of one glTF animation sampler at `times` (glTF 2.0 §3.11;
    held at the first and last key outside them)."""
    t = np.clip(times, keys[0], keys[-1])
    if len(keys) == 1:
        value = values[0, 1] if interpolation == "CUBICSPLINE" else values[0]
        return np.repeat(value[None], len(times), axis=0)
    i = np.clip(np.searchsorted(keys, t, side="right") - 1, 0, len(keys) - 2)
    span = keys[i + 1] - keys[i]
    u = np.divide(t - keys[i], span, out=np.zeros_like(t), where=span > 0)[:, None]
    if interpolation == "STEP":
        return values[np.where(t >= keys[i + 1], i + 1, i)]
    if interpolation == "CUBICSPLINE":
        d = span[:, None]
        a, v, b = values[:, 0], values[:, 1], values[:, 2]
        out = ((2 * u**3 - 3 * u**2 + 1) * v[i] + (u**3 - 2 * u**2 + u) * d * b[i]
               + (-2 * u**3 + 3 * u**2) * v[i + 1] + (u**3 - u**2) * d * a[i + 1])
        return out / np.linalg.norm(out, axis=1, keepdims=True) if rotation else out
    if not rotation:
        return (1 - u) * values[i] + u * values[i + 1]
    q0, q1 = values[i], values[i + 1]
    dot = np.sum(q0 * q1, axis=1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)  # the short way round
    theta = np.arccos(np.clip(np.abs(dot), -1.0, 1.0))
    sin = np.sin(theta)
    small = sin < 1e-6
    w0 = np.where(small, 1 - u, np.sin((1 - u) * theta) / np.where(small, 1, sin))
    w1 = np.where(small, u, np.sin(u * theta) / np.where(small, 1, sin))
    out = w0 * q0 + w1 * q1
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def node_transforms(gltf, nodes, channels, times) -> np.ndarray:
    """(F, nodes, 4, 4) world matrices of every node at `times` (animated TRS)."""
    f = len(times)
    local = np.empty((f, len(nodes), 4, 4))
    animated = {(c[0], c[1]): c for c in channels if c[1] != "weights"}
    for n, node in enumerate(nodes):
        if node.matrix is not None and not any((n, p) in animated for p in ("translation", "rotation", "scale")):
            local[:, n] = np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T
            continue
        trs = {}
        for path, default in (("translation", node.translation or [0, 0, 0]),
                              ("rotation", node.rotation or [0, 0, 0, 1]),
                              ("scale", node.scale or [1, 1, 1])):
            if (n, path) in animated:
                _, _, keys, values, interpolation = animated[(n, path)]
                trs[path] = sampled(keys, values, interpolation, times, path == "rotation")
            else:
                trs[path] = np.repeat(np.asarray(default, dtype=np.float64)[None], f, axis=0)
        local[:, n] = trs_matrices(trs["translation"], trs["rotation"], trs["scale"])
    parent = {}
    for n, node in enumerate(nodes):
        for child in node.children or []:
            gltf.item(nodes, child, f"node {n}: child")
            parent[child] = n
    world = np.empty_like(local)
    done = np.zeros(len(nodes), dtype=bool)

    def resolve(n, depth=0):
        if done[n]:
            return
        if depth > len(nodes):
            raise RetargetError(f"{gltf.label}: the node hierarchy has a cycle")
        if n in parent:
            resolve(parent[n], depth + 1)
            world[:, n] = world[:, parent[n]] @ local[:, n]
        else:
            world[:, n] = local[:, n]
        done[n] = True

    for n in range(len(nodes)):
        resolve(n)
    return world


def trs_matrices(t, q, s) -> np.ndarray:
    """(F, 4, 4) T R S from (F, 3) translations, (F, 4) xyzw quaternions, (F, 3) scales."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    x, y, z, w = q.T
    r = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], 1)
    m = np.zeros((len(t), 4, 4))
    m[:, :3, :3] = r * s[:, None, :]
    m[:, :3, 3] = t
    m[:, 3, 3] = 1.0
    return m


def transformed(matrix, points) -> np.ndarray:
    """(..., n, 3) points moved by (..., 4, 4) matrices."""
    return points @ np.swapaxes(matrix[..., :3, :3], -1, -2) + matrix[..., None, :3, 3]


def animated_weights(gltf, channels, times) -> dict[int, np.ndarray]:
    """{node: (F, targets) morph weights at `times`} of the animated weight channels."""
    return {node: sampled(keys, values, interpolation, times, False)
            for node, path, keys, values, interpolation in channels if path == "weights"}


def posed_vertices(gltf, inst, rows, world, weights, times) -> np.ndarray:
    """(F, len(rows), 3) positions of the primitive's vertices `rows` at every time:
    morph targets, then skinning (or the node's world transform), glTF 2.0 §3.7."""
    f = len(times)
    base = inst["positions"][rows]
    targets = inst["targets"][:, rows]
    w = weights.get(inst["node"])
    if w is None:
        w = np.repeat(inst["default_weights"][None], f, axis=0)
    elif w.shape[1] != len(targets):
        raise RetargetError(
            f"{gltf.label}: the animation gives {w.shape[1]} morph weights for node {inst['node']}, "
            f"whose mesh has {len(targets)} targets")
    morphed = base[None] + np.einsum("ft,tnd->fnd", w, targets)
    if inst["skin"] is None:
        return transformed(world[:, inst["node"]], morphed)
    skin = gltf.item(gltf.doc.skins, inst["skin"], f"node {inst['node']}: skin")
    joints = np.asarray(skin.joints, dtype=np.int64)
    if skin.inverseBindMatrices is not None:
        inverse = gltf.accessor(skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
        if len(inverse) != len(joints):
            raise RetargetError(f"{gltf.label}: skin {inst['skin']} has {len(inverse)} inverse bind "
                                f"matrices for {len(joints)} joints")
    else:
        inverse = np.repeat(np.eye(4)[None], len(joints), axis=0)
    index, weight = inst["joints"][rows], inst["weights"][rows]
    if index.max(initial=0) >= len(joints) or index.min(initial=0) < 0:
        raise RetargetError(f"{gltf.label}: skin {inst['skin']}: a vertex names a joint the skin lacks")
    joint_matrices = world[:, joints] @ inverse[None]                      # (F, J, 4, 4)
    blended = np.einsum("nk,fnkab->fnab", weight, joint_matrices[:, index])  # (F, n, 4, 4)
    return np.einsum("fnab,fnb->fna", blended[..., :3, :3], morphed) + blended[..., :3, 3]


def drawn_vertices(gltf, times, animation: int = 0) -> np.ndarray:
    """(F, V, 3) float64 positions a glTF viewer draws at `times` (seconds) of an animation,
    for a file of one mesh instance (an export of ours), in the file's units."""
    (inst,) = mesh_instances(gltf)
    times = np.asarray(times, dtype=np.float64)
    channels = animation_channels(gltf, gltf.item(gltf.doc.animations, animation, "animation"))
    world = node_transforms(gltf, gltf.doc.nodes, channels, times)
    return posed_vertices(gltf, inst, np.arange(len(inst["positions"])), world,
                          animated_weights(gltf, channels, times), times)
