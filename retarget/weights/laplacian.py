"""Laplacian surface editing with soft feature constraints, Zhang et al. §2.2 (Sorkine 2004).

Eq. 4-5: differential coordinates ``δ = L v`` with the umbrella operator ``L = I - D⁻¹A``.
Eq. 7: ``V' = argmin |L V' - δ|² + Σ_j w_j² |v'_j - c_j|²``. Because ``δ = L V`` and the
problem is linear, the displacement ``d = V' - V`` solves ``argmin |L d|² + Σ w² |d_j - Δc_j|²``:
a quadratic energy ``Q = LᵀL`` under feature constraints (`quadratic.constrained_weights`).
Eq. 6's convex weights are replaced by uniform ones, which eq. 5 writes.
"""

from __future__ import annotations

from retarget.operators import uniform_laplacian
from retarget.skin import SkinWeights
from retarget.weights.quadratic import constrained_weights


def laplacian_weights(vertices, faces, points, layout=None, *, k: int | None = None,
                      constraint_weight: float = 1.0, progress=None) -> SkinWeights:
    """(V, N) Laplacian-editing weights; ``k`` keeps the k largest per vertex (all if None).

    constraint_weight : w² of eq. 7 relative to the energy's diagonal; Zhang's soft
    constraints are w = 1.
    """
    lap = uniform_laplacian(faces, len(vertices))
    w = constrained_weights((lap.T @ lap), points, constraint_weight, progress,
                            vertices=vertices)
    return SkinWeights.from_dense(w, k, "laplacian")
