"""Ellipsoid auto-weights, Dutreve et al. 2008 §3.2.

``w_ij = max(0, 1 - (d_x²/r_x² + d_y²/r_y² + d_z²/r_z²))`` with ``d = v_i - t_j`` in the face
frame and per-feature radii from the layout (`radii.feature_radii`); per vertex the k
largest weights are kept and normalised to sum 1, as the paper does. Vertices no ellipsoid
reaches get no feature weight: they stay on the static root joint (the skull).
"""

from __future__ import annotations

import numpy as np

from retarget.skin import SkinWeights
from retarget.weights.radii import feature_radii


def ellipsoid_values(vertices: np.ndarray, points: np.ndarray, radii: np.ndarray,
                     frame: np.ndarray) -> np.ndarray:
    """(V, N) float64 ellipsoid quadratic form ``sum_a d_a² / r_a²`` (0 at the feature)."""
    local_v = np.asarray(vertices, dtype=np.float64) @ frame.T
    local_p = np.asarray(points, dtype=np.float64) @ frame.T
    inv = 1.0 / np.square(radii)
    # Expanded (v - p)² / r² summed over axes: three small matmuls instead of a (V, N, 3) temporary.
    q = (local_v**2) @ inv.T - 2.0 * local_v @ (local_p * inv).T + ((local_p**2) * inv).sum(1)
    return np.maximum(q, 0.0)


def ellipsoid_weights(vertices, faces, points, layout=None, *, k: int = 4) -> SkinWeights:
    """Dutreve §3.2 weights for (V, 3) vertices and `SurfacePoints` feature points."""
    t0 = points.positions(vertices)
    radii, frame = feature_radii(t0, layout)
    w = np.maximum(0.0, 1.0 - ellipsoid_values(vertices, t0, radii, frame))
    return normalised_top_k(w, k, "ellipsoid")


def normalised_top_k(w: np.ndarray, k: int, method: str) -> SkinWeights:
    """Keep the k largest of (V, N) non-negative weights per row and scale reached rows to sum 1."""
    sk = SkinWeights.from_dense(w, k, method)
    s = sk.weights.sum(1, keepdims=True)
    weights = np.divide(sk.weights, s, out=np.zeros_like(sk.weights), where=s > 0)
    return SkinWeights(sk.indices, weights.astype(np.float32), sk.n_joints, method)
