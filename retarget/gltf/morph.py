"""Skin weights as glTF morph targets, for rigs no glTF skin can hold, and back.

The interpolating deformers (dense RBF and region RBF, Zhang §2.1 and §4; Laplacian
editing, Zhang §2.2; biharmonic) are linear vertex deformers with negative weights, so
they are not joint-based in glTF's sense (`retarget.gltf.influences`). Their motion is
still exactly linear in the feature displacements, so three morph targets per feature
hold it: target (i, a), a in x, y, z, moves vertex v by ``s W[v, i]`` along axis a, and
its animated weight at frame f is ``d_f[i, a] / s``. glTF's morphing
``v0 + Σ_{i,a} (d_f[i, a] / s) s W[:, i] e_a`` is then Dutreve §3.1's
``v0 + Σ_i W[:, i] d_f[i]`` to float32 rounding. Target names are ``<feature>.x``,
``.y``, ``.z``.

The scale s (`morph_scale`, mesh units per unit weight) is the power of two at or above
the largest displacement of the exported clips, so every animated weight lies in
[-1, 1] (Blender clamps shape-key values to [-10, 10], and a centimetre or millimetre
face moves further than that) and scaling by it is exact in floating point.
"""

from __future__ import annotations

import numpy as np

from retarget.errors import RetargetError
from retarget.skin import SkinWeights

AXES = ("x", "y", "z")
SPARSE_SHARE = 0.75
"""A target is stored sparse when fewer than this share of vertices move: a sparse row
costs its 4-byte index on top of the 12 bytes a dense row costs."""


def target_names(joint_names) -> list[str]:
    """The 3N morph target names, ``<feature>.<axis>``, feature-major."""
    return [f"{name}.{axis}" for name in joint_names for axis in AXES]


def morph_scale(clips) -> float:
    """s: the smallest power of two >= every |d| of the clips (1 without motion)."""
    largest = max((float(np.abs(c.displacements).max()) for c in clips), default=0.0)
    return float(2.0 ** np.ceil(np.log2(largest))) if largest > 0 else 1.0


def feature_columns(weights: SkinWeights) -> np.ndarray:
    """(N, V) float32 W transposed: row i holds feature i's weight at every vertex, the
    offsets of its three morph targets (built directly from the (V, K) influences)."""
    return np.ascontiguousarray(weights.dense().T, dtype=np.float32)


def target_bounds(values: np.ndarray, count: int, axis: int) -> tuple[list, list]:
    """glTF min and max of a target that moves `values` (n,) float32 along `axis` and
    the other count - n vertices not at all: exact, without scanning the (count, 3)
    offsets."""
    lo = [0.0, 0.0, 0.0]
    hi = [0.0, 0.0, 0.0]
    if len(values):
        lo[axis] = float(min(values.min(), 0.0)) if len(values) < count else float(values.min())
        hi[axis] = float(max(values.max(), 0.0)) if len(values) < count else float(values.max())
    return lo, hi


def axis_offsets(values: np.ndarray, axis: int) -> np.ndarray:
    """(n, 3) float32 offsets of one target: `values` (n,) on `axis`, zero elsewhere."""
    out = np.zeros((len(values), 3), np.float32)
    out[:, axis] = values
    return out


def weights_from_targets(targets, n_features: int, scale: float = 1.0,
                         method: str = "") -> SkinWeights:
    """Skin weights from the 3N (V, 3) target offsets in `target_names` order, made with
    `scale` s (the offsets are s W).

    K is the most non-zero weights of a vertex (all N for a dense rig), so the rig that
    was exported comes back with its own sparsity. Raises `RetargetError` when the
    targets are not ``W[:, i] e_a`` (another file's shapes).
    """
    if len(targets) != 3 * n_features:
        raise RetargetError(f"{len(targets)} morph targets for {n_features} features; "
                            f"expected 3 per feature ({3 * n_features})")
    columns = []
    for i in range(n_features):
        column = np.asarray(targets[3 * i], dtype=np.float32)[:, 0]
        for a in range(3):
            offsets = np.asarray(targets[3 * i + a], dtype=np.float32)
            if not np.array_equal(offsets[:, a], column) or np.delete(offsets, a, 1).any():
                raise RetargetError(
                    f"morph target {3 * i + a} is not feature {i}'s weights along axis "
                    f"{AXES[a]} (a <feature>.<axis> target moves along its axis only, by "
                    "the same weights on every axis)")
        columns.append(column)
    w = np.stack(columns, 1) / np.float32(scale)  # (V, N)
    k = int((w != 0).sum(1).max()) if w.size else 0
    return SkinWeights.from_dense(w, None if k >= n_features else max(k, 1), method)
