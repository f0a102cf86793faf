"""Skin weights for every deformer: each is a linear map from feature to vertex displacements.

`compute_weights(method, ...)` is the one entry point; `METHODS` lists the names:

- ``ellipsoid``: Dutreve §3.2, the paper's automatic rig (sparse, k = 4).
- ``geodesic``: the ellipsoid falloff measured along the surface (sparse; no leakage
  across the mouth slit).
- ``rbf``: dense RBF interpolation of displacements, Zhang §2.1.
- ``region_rbf``: Zhang §4's top/middle/bottom split RBF.
- ``laplacian``: Laplacian surface editing with soft constraints, Zhang §2.2.
- ``biharmonic``: second-order surface energy with a damped far field.
"""

from __future__ import annotations

from retarget.errors import RetargetError
from retarget.landmarks import SurfacePoints
from retarget.skin import SkinWeights
from retarget.weights.biharmonic import biharmonic_weights
from retarget.weights.ellipsoid import ellipsoid_weights
from retarget.weights.geodesic import geodesic_weights
from retarget.weights.laplacian import laplacian_weights
from retarget.weights.rbf import rbf_weights
from retarget.weights.region_rbf import region_rbf_weights
from retarget.welding import welded

METHODS = {
    "ellipsoid": ellipsoid_weights,
    "geodesic": geodesic_weights,
    "rbf": rbf_weights,
    "region_rbf": region_rbf_weights,
    "laplacian": laplacian_weights,
    "biharmonic": biharmonic_weights,
}
DEFAULT_METHOD = "biharmonic"


def compute_weights(method: str, vertices, faces, points, layout=None, **options) -> SkinWeights:
    """Skin weights of `method` for a mesh ((V, 3) vertices, (F, 3) faces) and its
    `SurfacePoints` features; options go to the method (k, damping, kernel, ...).

    The method runs on the surface with its coincident vertices welded (`retarget.welding`:
    a UV seam or an STL's triangle soup splits them) and every copy gets its welded
    vertex's weights, so the rig never tears along a seam."""
    try:
        fn = METHODS[method]
    except KeyError:
        raise RetargetError(f"unknown weight method {method!r}; choose one of {', '.join(METHODS)}") from None
    weld = welded(vertices, faces)
    if not weld.any:
        return fn(vertices, faces, points, layout, **options)
    on_weld = SurfacePoints(weld.index[points.vertex_indices], points.barycentric, points.layout)
    w = fn(weld.vertices, weld.faces, on_weld, layout, **options)
    return SkinWeights(w.indices[weld.index], w.weights[weld.index], w.n_joints, w.method)


__all__ = ["METHODS", "DEFAULT_METHOD", "SkinWeights", "compute_weights"]
