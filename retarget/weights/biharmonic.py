"""Biharmonic deformation weights with a damped far field.

A second-order surface energy (Jacobson et al. 2011; Botsch & Sorkine 2008, "On linear
variational surface deformation methods") on the cotangent Laplacian ``L`` and mass ``M``:

    E(d) = dᵀ Lᵀ M⁻¹ L d + β / ℓ² · dᵀ (-L) d + α / ℓ⁴ · dᵀ M d

under near-hard feature constraints (`quadratic.constrained_weights`). The first term
(the discrete biharmonic energy) spreads each feature's motion smoothly along the surface,
so the two sides of the mouth slit, an open boundary, do not drag each other. The second
(membrane, Dirichlet) term makes motion fall off faster between features than the
bending term alone would, as skin under tension does. The third term damps motion far
from every feature, so the skull and neck stay put instead of floating with the nearest
feature. ℓ is the landmark layout's size (RMS distance of the features from their
centroid), so α and β are unit-free; their defaults are the best pair on the ICT
benchmark (bench/accuracy.py, true feature motion).

Lip separation: the energy alone still lets a lower-lip feature pull upper-lip vertices
near the mouth corners (the surface path round a corner is short). With a layout, each
vertex is given to its nearest feature along the surface (a geodesic Voronoi cell), and
lower-lip and jaw features are held at zero weight on the upper lip's cells, upper-lip
features on the lower lip's and jaw's: the lips move only with their own features, the
corners with both.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from retarget.operators import cotmatrix, massmatrix
from retarget.skin import SkinWeights
from retarget.weights.geodesic import nearest_features
from retarget.weights.quadratic import constrained_weights


def biharmonic_weights(vertices, faces, points, layout=None, *, k: int | None = None,
                       damping: float = 100.0, membrane: float = 30.0,
                       separate_lips: bool = True, constraint_weight: float = 1e4,
                       progress=None) -> SkinWeights:
    """(V, N) biharmonic weights; ``k`` keeps the k largest per vertex (all if None).

    damping : α of the module docstring.
    membrane : β of the module docstring.
    """
    v = np.asarray(vertices, dtype=np.float64)
    lap = cotmatrix(v, faces)
    mass = massmatrix(v, faces)
    m = mass.diagonal()
    q = lap.T @ sp.diags(1.0 / m) @ lap
    t0 = points.positions(v)
    ell = float(np.sqrt(((t0 - t0.mean(0)) ** 2).sum(1).mean()))
    q = q + ((membrane / ell**2) * (-lap) + (damping / ell**4) * mass)  # one merge with the 2-ring q
    supports = lip_supports(v, faces, points, layout) if separate_lips and layout is not None else ()
    w = constrained_weights(q, points, constraint_weight, progress, supports, vertices=v)
    return SkinWeights.from_dense(w, k, "biharmonic")


def lip_supports(vertices, faces, points, layout) -> list[tuple[np.ndarray, np.ndarray]]:
    """(features, outside) pairs for `quadratic.constrained_weights`: lower lip and jaw
    features stay off the upper lip's Voronoi cells, upper-lip features off the lower lip's
    and jaw's."""
    regions = np.asarray(layout.regions)
    cell = regions[nearest_features(vertices, faces, points)]
    lower = np.isin(regions, ("lower_lip", "jaw"))
    upper = regions == "upper_lip"
    if not (lower.any() and upper.any()):
        return []
    return [(lower, cell == "upper_lip"), (upper, np.isin(cell, ("lower_lip", "jaw")))]
