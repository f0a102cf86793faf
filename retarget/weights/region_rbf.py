"""Region-split RBF, Zhang et al. §4.

A single RBF over the whole face barely moves vertices that lie between features pulling
in opposite directions (their Fig. 4), so the face is split into a top (brows, eyes),
middle (nose) and bottom (lips, jaw) part, each vertex is interpolated from its own part's
features only, and the parts are put back together. A vertex belongs to the part of its
nearest feature along the surface (graph geodesic), so the mouth slit separates the lips.
"""

from __future__ import annotations

import numpy as np

from retarget.errors import RetargetError
from retarget.rbf import RBFInterpolant
from retarget.skin import SkinWeights
from retarget.weights.geodesic import nearest_features

PARTS = {
    "top": ("brows", "eyes", "forehead"),
    "middle": ("nose", "cheeks"),
    "bottom": ("upper_lip", "lower_lip", "mouth_corners", "jaw"),
}


def region_rbf_weights(vertices, faces, points, layout=None, *, k: int | None = None,
                       kernel: str = "exponential", shape: float | None = None) -> SkinWeights:
    """(V, N) weights: each vertex interpolated by the RBF of its part's features."""
    if layout is None:
        raise RetargetError("region_rbf needs a landmark layout to split the face into parts")
    v = np.asarray(vertices, dtype=np.float64)
    t0 = points.positions(v)
    regions = np.asarray(layout.regions)
    nearest = nearest_features(v, faces, points)
    w = np.zeros((len(v), points.n_points))
    for part_regions in PARTS.values():
        feats = np.flatnonzero(np.isin(regions, part_regions))
        if len(feats) == 0:
            continue
        rows = np.flatnonzero(np.isin(nearest, feats))
        if len(rows):
            rbf = RBFInterpolant(kernel, shape=shape).fit(t0[feats])
            w[np.ix_(rows, feats)] = rbf.operator(v[rows])
    return SkinWeights.from_dense(w, k, "region_rbf")
