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

Dense layouts (`DENSE_LAYOUT_POINTS`, the face mesh's 468) are not separated: each lip
is pinned along its whole length by its own points, and the two lips' Voronoi cells
interleave near the mouth corners, so the zeros would cut every lip feature's weight off
along jagged cell borders. The weights there then stop summing to one (ICT, seed 1 of
bench/accuracy.py --dense: up to 2.0 off on the mouth, 0.007 unseparated) and motion the
lips share, a jaw drop or a smile, is lost near the corners.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from retarget.operators import cotmatrix, massmatrix
from retarget.skin import SkinWeights
from retarget.weights.geodesic import nearest_features
from retarget.weights.quadratic import constrained_weights

# A layout with at least this many points is dense (every built-in sparse layout has at
# most 68; the face mesh 468): its lips are not separated (module docstring).
DENSE_LAYOUT_POINTS = 200


def biharmonic_weights(vertices, faces, points, layout=None, *, k: int | None = None,
                       damping: float = 100.0, membrane: float = 30.0,
                       separate_lips: bool | None = None, constraint_weight: float = 1e4,
                       progress=None) -> SkinWeights:
    """(V, N) biharmonic weights; ``k`` keeps the k largest per vertex (all if None).

    damping : α of the module docstring.
    membrane : β of the module docstring.
    separate_lips : hold lip features off the other lip (module docstring); None: for a
        sparse layout only.
    """
    v = np.asarray(vertices, dtype=np.float64)
    lap = cotmatrix(v, faces)
    mass = massmatrix(v, faces)
    m = mass.diagonal()
    q = lap.T @ sp.diags(1.0 / m) @ lap
    t0 = points.positions(v)
    ell = float(np.sqrt(((t0 - t0.mean(0)) ** 2).sum(1).mean()))
    q = q + ((membrane / ell**2) * (-lap) + (damping / ell**4) * mass)  # one merge with the 2-ring q
    if separate_lips is None:
        separate_lips = layout is not None and layout.n_points < DENSE_LAYOUT_POINTS
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
