"""Skin weights as glTF joint influences (JOINTS_n / WEIGHTS_n) and back.

Dutreve §3.1's skinning ``v = v0 + Σ_i w_i d_i`` is a glTF skin whose joints are pure
translations: joint i sits at the neutral feature point p_i with inverse bind matrix
``T(-p_i)``, so at frame f its skinning matrix is ``T(p_i + d_if) T(-p_i) = T(d_if)``.
A glTF vertex's weights must be non-negative and sum to 1 (glTF 2.0 §3.7.3.3), so the
remainder ``1 - Σ_i w_i`` of each row goes to joint 0, a static root (the skull of
`retarget.skin`), and feature i is glTF joint i + 1.

That is possible exactly when the rig's weights are non-negative and each row sums to at
most 1: the sparse rigs (ellipsoid, geodesic). The interpolating deformers (dense RBF,
region RBF, Laplacian, biharmonic) have negative weights and rows above 1, which no glTF
skin can hold; `retarget.gltf.morph` exports those as morph targets instead.
"""

from __future__ import annotations

import numpy as np

from retarget.errors import RetargetError
from retarget.skin import SkinWeights

ROW_SUM_TOLERANCE = 1e-5
"""How far from 1 a row may sum and still count as summing to 1: float32 sums of sparse
rigs miss by a few ulp either way (ellipsoid rows that reach 1 sum to 1 ± 1.3e-7). Such
rows are scaled to 1, so a row above 1 still fits a skin, and a row just below 1 leaves
the root no share: a 1e-7 root share would make a four-feature vertex a five-influence
one, needing a second JOINTS/WEIGHTS set that three.js ignores."""


def is_joint_based(weights: SkinWeights) -> bool:
    """True when `weights` fit a glTF skin: no negative weight and no row above 1."""
    w = weights.weights
    return bool(np.all(w >= 0) and np.all(weights.row_sums() <= 1 + ROW_SUM_TOLERANCE))


def joint_influences(weights: SkinWeights) -> tuple[np.ndarray, np.ndarray]:
    """glTF joint indices and weights of every vertex, four per JOINTS_n / WEIGHTS_n set.

    Returns (joints, influence) of shape (V, 4S), S the number of sets (the most
    non-zero influences of a vertex, root included, over 4, rounded up). joints is
    uint8 when the skin has at most 256 joints (features + root), else uint16; joint 0
    is the root, feature i is joint i + 1. influence is float32, each row's non-zero
    entries first (the rig's order, then the root) and summing to 1 in float64; unused
    slots are joint 0 with weight 0. Rows within `ROW_SUM_TOLERANCE` of 1 are scaled to
    1 (no root share), so a rig of at most four influences needs one set, the most
    three.js reads.

    Raises `RetargetError` if the weights are not joint-based (see `is_joint_based`) or
    a vertex names one feature twice.
    """
    if not is_joint_based(weights):
        raise RetargetError("these skin weights have negative weights or rows summing above "
                            "1, which a glTF skin cannot hold; export them as morph targets")
    w = weights.weights.astype(np.float64)
    total = w.sum(1, keepdims=True)
    whole = np.abs(total[:, 0] - 1.0) <= ROW_SUM_TOLERANCE
    w[whole] /= total[whole]
    rest = np.where(whole[:, None], 0.0, 1.0 - total)
    joints = np.concatenate([weights.indices.astype(np.int64) + 1, np.zeros_like(rest, np.int64)], 1)
    influence = np.concatenate([w, rest], 1).astype(np.float32)
    used = influence != 0
    _refuse_repeats(np.where(used, joints, -1 - np.arange(joints.shape[1])))
    # used slots to the front, in their order: a stable sort on "unused"
    order = np.argsort(~used, axis=1, kind="stable")
    joints = np.where(used, joints, 0)
    joints = np.take_along_axis(joints, order, 1)
    influence = np.take_along_axis(influence, order, 1)
    slots = 4 * max(1, -(-int(used.sum(1).max()) // 4))
    width = min(slots, joints.shape[1])
    pad = ((0, 0), (0, slots - width))
    dtype = np.uint8 if weights.n_joints + 1 <= 256 else np.uint16
    return (np.pad(joints[:, :width], pad).astype(dtype),
            np.pad(influence[:, :width], pad))


def weights_from_influences(joints: np.ndarray, influence: np.ndarray, n_features: int,
                            method: str = "") -> SkinWeights:
    """Skin weights from (V, 4S) glTF joints and weights whose joint 0 is the root and
    joint i + 1 feature i (the layout of `joint_influences`); the root's share becomes the
    implicit remainder again. K is the most feature influences of a vertex."""
    joints = np.asarray(joints, dtype=np.int64)
    influence = np.asarray(influence, dtype=np.float32)
    if joints.shape != influence.shape or joints.ndim != 2:
        raise RetargetError(f"joints {joints.shape} and weights {influence.shape} must be "
                            "(V, 4S) arrays of one shape")
    if joints.size and joints.max() > n_features:
        raise RetargetError(f"a vertex names joint {joints.max()}, past the skin's "
                            f"{n_features + 1} joints")
    feature = (joints > 0) & (influence != 0)
    k = max(1, int(feature.sum(1).max()))
    # features first, largest |w| first (SkinWeights' order), root and unused slots last
    key = np.where(feature, -np.abs(influence), np.inf)
    order = np.argsort(key, axis=1, kind="stable")[:, :k]
    kept = np.take_along_axis(feature, order, 1)
    indices = np.where(kept, np.take_along_axis(joints, order, 1) - 1, 0).astype(np.int32)
    values = np.where(kept, np.take_along_axis(influence, order, 1), 0).astype(np.float32)
    return SkinWeights(indices, values, n_features, method)


def _refuse_repeats(joints: np.ndarray) -> None:
    """Refuse a row naming one joint twice (unused slots carry distinct negatives)."""
    ordered = np.sort(joints, axis=1)
    twice = (ordered[:, 1:] == ordered[:, :-1]) & (ordered[:, 1:] >= 0)
    if twice.any():
        vertex = int(np.flatnonzero(twice.any(1))[0])
        joint = int(ordered[vertex, 1:][twice[vertex]][0])
        raise RetargetError(f"the skin weights of vertex {vertex} name feature {joint - 1} "
                            "twice; each influence needs its own feature")
