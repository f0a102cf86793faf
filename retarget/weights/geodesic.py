"""Surface-aware ellipsoid weights: Dutreve §3.2's falloff measured along the surface.

The paper's ellipsoid uses Euclidean offsets, so a feature on the lower lip reaches the
upper lip across the closed mouth (the lips are millimetres apart in space but a mouth
corner apart on the surface). Here the ellipsoid's quadratic form is stretched by the
ratio of surface distance to straight-line distance:

    q_g = q_e · (g / |d|)²,    w = max(0, 1 - q_g)

where q_e is the paper's ellipsoid form, |d| the Euclidean and g the geodesic distance
(shortest path along mesh edges, Dijkstra). On a smooth patch g ≈ |d| and the weights are
the paper's; across an open boundary (mouth slit, eye opening) g ≫ |d| and the weight
vanishes. Surface points enter the graph as extra nodes joined to their triangle's
corners.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra
from scipy.spatial.distance import cdist

from retarget.operators import edge_graph
from retarget.skin import SkinWeights
from retarget.weights.ellipsoid import ellipsoid_values, normalised_top_k
from retarget.weights.radii import feature_radii


def geodesic_distances(vertices, faces, points, limit: float = np.inf) -> np.ndarray:
    """(N, V) float64 graph-geodesic distances from each surface point (inf beyond limit)."""
    graph, sources = _feature_graph(vertices, faces, points)
    return dijkstra(graph, directed=False, indices=sources, limit=limit)[:, :len(vertices)]


def nearest_features(vertices, faces, points) -> np.ndarray:
    """(V,) int64: index of each vertex's nearest feature along the surface (geodesic
    Voronoi cell); -1 for vertices on mesh pieces that carry no feature."""
    graph, sources = _feature_graph(vertices, faces, points)
    _, _, nearest = dijkstra(graph, directed=False, indices=sources, min_only=True,
                             return_predecessors=True)
    nearest = nearest[:len(vertices)].astype(np.int64)
    return np.where(nearest >= 0, nearest - len(vertices), -1)


def _feature_graph(vertices, faces, points):
    """Edge-length graph with one extra node per feature joined to its triangle's corners;
    returns the (V + N, V + N) graph and the (N,) feature node ids."""
    v = np.asarray(vertices, dtype=np.float64)
    n_v, n_p = len(v), points.n_points
    g = edge_graph(v, faces).tocoo()
    pos = points.positions(v)
    rows = np.repeat(np.arange(n_v, n_v + n_p), 3)
    cols = points.vertex_indices.ravel()
    lengths = np.linalg.norm(v[cols] - np.repeat(pos, 3, axis=0), axis=1)
    lengths = np.maximum(lengths, 1e-12 * max(float(g.data.max(initial=1.0)), 1e-300))
    graph = sp.csr_matrix(
        (np.concatenate([g.data, lengths, lengths]),
         (np.concatenate([g.row, rows, cols]), np.concatenate([g.col, cols, rows]))),
        shape=(n_v + n_p, n_v + n_p))
    return graph, np.arange(n_v, n_v + n_p)


def geodesic_weights(vertices, faces, points, layout=None, *, k: int = 4) -> SkinWeights:
    """Surface-aware ellipsoid weights for (V, 3) vertices and `SurfacePoints` features."""
    v = np.asarray(vertices, dtype=np.float64)
    t0 = points.positions(v)
    radii, frame = feature_radii(t0, layout)
    g = geodesic_distances(v, faces, points, limit=1.01 * float(radii.max()))
    q = ellipsoid_values(v, t0, radii, frame)
    euclid = cdist(v, t0)
    with np.errstate(divide="ignore", invalid="ignore"):
        stretch = np.where(euclid > 0, np.square(g.T / euclid), 1.0)
    w = np.maximum(0.0, 1.0 - np.nan_to_num(q * stretch, nan=np.inf, posinf=np.inf))
    return normalised_top_k(w, k, "geodesic")

