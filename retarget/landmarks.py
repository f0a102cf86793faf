"""Target landmarks: feature points that live on the target mesh's surface.

A landmark is a vertex index or a surface point (a triangle and barycentric coordinates).
Both are stored one way, `SurfacePoints`: three vertex indices and three barycentric
weights per point; a vertex landmark is ``(v, v, v)`` with ``(1, 0, 0)``. Positions, and
anything the weight methods need, follow from the mesh, so a landmark set survives any
deformation of the mesh that keeps its topology.

JSON form (what the CLI and the server read and write): ``{"vertex_indices": [...]}``,
``{"positions": [[x, y, z], ...]}`` (snapped to the closest surface point), or
``{"triangles": [[a, b, c], ...], "barycentric": [[u, v, w], ...]}``; an optional
``"layout"`` (a string, or null for none) names the landmark layout the points follow.
A custom layout's (``custom-<hash>``, `retarget.custom_layouts`) comes with its spec as
``"layout_spec"``, so the file is self-contained: reading it registers the layout.

Every constructor refuses more than `MAX_LANDMARKS` points before any work that grows with
their number, and finds repeated points in O(K log K).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from retarget.custom_layouts import layout_from_spec
from retarget.errors import RetargetError
from retarget.layouts import CUSTOM_NAME, get_layout

MAX_LANDMARKS = 2048
"""Most landmarks a set may hold. The largest layout is MediaPipe's face mesh (468
points); the cap leaves room for denser custom sets while bounding the work one request
can ask for (snapping positions to the surface, checking them for repeats)."""


@dataclass(frozen=True, eq=False)
class SurfacePoints:
    """K points on a mesh surface.

    vertex_indices : (K, 3) int64, vertices of the triangle holding each point.
    barycentric : (K, 3) float64, non-negative, rows sum to 1.
    layout : name of the landmark layout the points follow, or "".
    """

    vertex_indices: np.ndarray
    barycentric: np.ndarray
    layout: str = ""

    def __reduce__(self):
        # a custom layout's spec travels along, so a child process resolves its name too
        return _points_with_layout, (self.vertex_indices, self.barycentric, self.layout,
                                     self.layout_spec())

    @property
    def n_points(self) -> int:
        return len(self.vertex_indices)

    def layout_spec(self) -> dict | None:
        """The spec of the custom layout the points follow (`Layout.spec`), else None."""
        return get_layout(self.layout).spec() if CUSTOM_NAME.fullmatch(self.layout) else None

    def positions(self, vertices: np.ndarray) -> np.ndarray:
        """(K, 3) points on a mesh with (V, 3) vertices (or (..., V, 3) -> (..., K, 3))."""
        v = np.asarray(vertices)
        return np.einsum("...kjd,kj->...kd", v[..., self.vertex_indices, :], self.barycentric)

    def nearest_vertices(self) -> np.ndarray:
        """(K,) int64: for each point, the triangle vertex with the largest weight."""
        return self.vertex_indices[np.arange(self.n_points), self.barycentric.argmax(1)]

    def to_json(self) -> dict:
        if np.all(self.barycentric[:, 0] == 1.0):
            out = {"vertex_indices": self.vertex_indices[:, 0].tolist()}
        else:
            out = {"triangles": self.vertex_indices.tolist(), "barycentric": self.barycentric.tolist()}
        if self.layout:
            out["layout"] = self.layout
        spec = self.layout_spec()
        if spec is not None:
            out["layout_spec"] = spec
        return out


def _points_with_layout(vertex_indices, barycentric, layout: str, spec: dict | None) -> SurfacePoints:
    if spec is not None:
        layout_from_spec(spec)
    return SurfacePoints(vertex_indices, barycentric, layout)


def from_vertex_indices(indices, n_vertices: int, layout: str = "") -> SurfacePoints:
    """SurfacePoints at mesh vertices; refuses indices outside [0, n_vertices) or repeats."""
    idx = np.asarray(indices)
    if idx.ndim != 1 or len(idx) == 0 or not np.issubdtype(idx.dtype, np.integer):
        raise RetargetError(f"vertex_indices must be a non-empty list of integers; got {np.asarray(indices).tolist()!r:.80}")
    _refuse_too_many(len(idx), "vertex_indices")
    bad = (idx < 0) | (idx >= n_vertices)
    if bad.any():
        raise RetargetError(
            f"vertex_indices[{int(np.flatnonzero(bad)[0])}] = {int(idx[bad][0])} is not a vertex "
            f"of the mesh (it has {n_vertices} vertices)")
    _refuse_repeats(idx, "vertex_indices")
    k = len(idx)
    tri = np.repeat(idx.astype(np.int64)[:, None], 3, axis=1)
    bary = np.zeros((k, 3))
    bary[:, 0] = 1.0
    return SurfacePoints(tri, bary, layout)


def from_positions(positions, vertices: np.ndarray, faces: np.ndarray, layout: str = "") -> SurfacePoints:
    """SurfacePoints at the surface points closest to (K, 3) positions."""
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) == 0:
        raise RetargetError(f"positions must have shape (K, 3); got {p.shape}")
    _refuse_too_many(len(p), "positions")
    if not np.isfinite(p).all():
        raise RetargetError("positions contain NaN or inf")
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    closest, _, tri_id = trimesh.proximity.closest_point(mesh, p)
    tri = np.asarray(faces, dtype=np.int64)[tri_id]
    bary = trimesh.triangles.points_to_barycentric(np.asarray(vertices)[tri], closest)
    bary = np.clip(bary, 0.0, None)
    bary /= bary.sum(1, keepdims=True)
    points = SurfacePoints(tri, bary, layout)
    _refuse_repeats_positions(points.positions(vertices))
    return points


def from_barycentric(triangles, barycentric, n_vertices: int, layout: str = "") -> SurfacePoints:
    """SurfacePoints from (K, 3) triangle vertex indices and (K, 3) barycentric weights."""
    tri = np.asarray(triangles)
    bary = np.asarray(barycentric, dtype=np.float64)
    if tri.ndim != 2 or tri.shape[1] != 3 or bary.shape != tri.shape or len(tri) == 0:
        raise RetargetError(f"triangles and barycentric must both have shape (K, 3); got {tri.shape} and {bary.shape}")
    _refuse_too_many(len(tri), "triangles")
    if not np.issubdtype(tri.dtype, np.integer) or tri.min() < 0 or tri.max() >= n_vertices:
        raise RetargetError(f"triangles must hold vertex indices in [0, {n_vertices})")
    if not np.isfinite(bary).all() or (bary < -1e-9).any() or not np.allclose(bary.sum(1), 1.0, atol=1e-6):
        raise RetargetError("barycentric rows must be non-negative and sum to 1")
    return SurfacePoints(tri.astype(np.int64), bary, layout)


def landmarks_from_json(data: dict, vertices: np.ndarray, faces: np.ndarray) -> SurfacePoints:
    """Parse the JSON form (see module docstring) against a mesh."""
    if not isinstance(data, dict):
        raise RetargetError("landmarks JSON must be an object with 'vertex_indices', 'positions' or 'triangles'")
    layout = data.get("layout")
    if layout is None:
        layout = ""
    elif not isinstance(layout, str):
        raise RetargetError(f"landmarks JSON 'layout' must be a string or null, got {_shown(layout)}")
    if data.get("layout_spec") is not None:
        layout = _custom_layout(data["layout_spec"], layout)
    if "vertex_indices" in data:
        return from_vertex_indices(data["vertex_indices"], len(vertices), layout)
    if "positions" in data:
        return from_positions(data["positions"], vertices, faces, layout)
    if "triangles" in data:
        return from_barycentric(data["triangles"], data.get("barycentric"), len(vertices), layout)
    raise RetargetError(
        f"landmarks JSON needs 'vertex_indices', 'positions' or 'triangles'; got keys {sorted(data)}")


def _custom_layout(spec, named: str) -> str:
    """The name of the custom layout `spec` (registered), which 'layout' must name if given."""
    try:
        custom = layout_from_spec(spec)
    except RetargetError as exc:
        raise RetargetError(f"landmarks JSON 'layout_spec': {exc}") from None
    if named and named != custom.name:
        raise RetargetError(f"landmarks JSON 'layout' {_shown(named)} is not the layout its "
                            f"'layout_spec' describes ({custom.name!r})")
    return custom.name


def load_landmarks(path, vertices: np.ndarray, faces: np.ndarray) -> SurfacePoints:
    """Read a landmarks JSON file (see module docstring) for a mesh."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RetargetError(f"could not read landmarks JSON {str(path)!r}: {exc}") from exc
    return landmarks_from_json(data, vertices, faces)


def _refuse_too_many(k: int, name: str):
    if k > MAX_LANDMARKS:
        raise RetargetError(
            f"{name} holds {k:,} landmarks, above the limit of {MAX_LANDMARKS:,}; "
            "a landmark set marks feature points, not the whole surface")


def _shown(value) -> str:
    """`value` as the JSON text it came from (cut to 80 characters)."""
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _refuse_repeats(idx: np.ndarray, name: str):
    uniq, counts = np.unique(idx, return_counts=True)
    if (counts > 1).any():
        v = int(uniq[counts > 1][0])
        where = np.flatnonzero(idx == v)[:2].tolist()
        raise RetargetError(f"{name} repeats vertex {v} (points {where[0]} and {where[1]}); each feature point needs its own place")


def _refuse_repeats_positions(p: np.ndarray):
    """Refuse two of the (K, 3) points `p` closer than 1e-9 of their extent: each point's
    nearest other point from a k-d tree, O(K log K) time and O(K) memory."""
    if len(p) < 2:
        return
    scale = float(np.ptp(p, axis=0).max()) or 1.0
    distance, nearest = cKDTree(p).query(p, k=2)
    # a point's own index comes first, unless another point sits exactly on it
    other = np.where(nearest[:, 0] == np.arange(len(p)), nearest[:, 1], nearest[:, 0])
    i = int(distance[:, 1].argmin())
    if distance[i, 1] <= 1e-9 * scale:
        j = int(other[i])
        raise RetargetError(f"landmarks {min(i, j)} and {max(i, j)} sit on the same surface point; each feature point needs its own place")
