"""Dense RBF interpolation of feature displacements, Zhang et al. §2.1.

Eq. 1-3: the displacement of every vertex is ``V(x) = Σ_k p_k φ(|x - x_k|)`` with the
weights p fitted so the features' own displacements are reproduced, φ(r) = exp(-r/c).
That is a (V, N) matrix applied to feature displacements, i.e. skin weights.
"""

from __future__ import annotations

from retarget.rbf import RBFInterpolant
from retarget.skin import SkinWeights


def rbf_weights(vertices, faces, points, layout=None, *, k: int | None = None,
                kernel: str = "exponential", shape: float | None = None) -> SkinWeights:
    """(V, N) RBF-interpolation weights at (V, 3) vertices for `SurfacePoints` features."""
    t0 = points.positions(vertices)
    w = RBFInterpolant(kernel, shape=shape).fit(t0).operator(vertices)
    return SkinWeights.from_dense(w, k, "rbf")
