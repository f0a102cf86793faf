"""Joined lips: finding the lip contact line of a face whose lips are one surface, and
opening the mouth along it.

Most scanned and sculpted heads have their lips joined. Skinning such a mesh (Dutreve
§3) drags the skin between the lips with both lips: when the lower lip points drop, the
contact line stretches into a bulge instead of opening. Every deformer here is built on
the mesh's connectivity (the Laplacian and biharmonic ones directly, the RBF ones through
their weights), so the fix is topological: cut the surface along the contact line from
one mouth corner to the other, duplicating the vertices along the cut, so the upper and
lower lips become separate sheets that meet only at the corners (as the built-in sample
face's lips are).

The contact line (`lip_crease`) is the cheapest path on the mesh's edge graph between the
two mouth corners, where an edge costs its length times a penalty that grows with its
distance from the guide: the polyline from one corner through the midpoints of the
layout's upper/lower lip point pairs to the other corner. It follows the crease between
the lips because the lip points sit on either side of it. On lips that are already
separate, that path runs along the boundary of one lip sheet: `lips_joined` tells the two
apart by whether the path runs through the surface (edges shared by two triangles) or
along its border.

`opened_mouth` keeps every original vertex first and in its order and appends the
duplicates (with their uv and normals), so vertex landmarks, uv maps and anything indexed
by vertex stay valid; lower-lip landmarks that lay on the cut move to the lower sheet.
The duplicates lie `CUT_GAP` mouth widths below the originals: the rig welds the
vertices at one exact position (`retarget.welding`, for UV seams and STL soups), which
would join the lips again.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra

from retarget.errors import RetargetError
from retarget.landmarks import SurfacePoints
from retarget.layouts import Layout
from retarget.mesh import Mesh, mesh_from_arrays

__all__ = ["OpenedMouth", "lip_crease", "lips_joined", "opened_mouth"]

# iBUG 68 indices: mouth corners (inner, outer) and upper lip point -> the lower lip point
# facing it across the mouth
_CORNERS = ((60, 64), (48, 54))
_FACING = {61: 67, 62: 66, 63: 65, 49: 59, 50: 58, 51: 57, 52: 56, 53: 55}
_LOWER_LIP = frozenset({55, 56, 57, 58, 59, 65, 66, 67})
_GUIDE_WIDTH = 0.06
"""Distance from the guide, as a share of the mouth width, at which an edge costs twice
its length: narrow enough to stay on the crease, wide enough to follow a lip line that
curves between the guide's vertices."""
CUT_GAP = 1e-3
"""Mouth widths (about 50 µm) the cut's lower copies lie below the upper lip's vertices:
apart, so that a weld by position (the rig's) leaves the lips two sheets, and near enough
to show none of it; at least several float32 steps for a face within 10^4 mouth widths of
its origin, so a .glb (float32) keeps them apart."""
_SEARCH_RADIUS = 0.9
"""Vertices further than this share of the mouth width from the guide are not searched."""


@dataclass(frozen=True, eq=False)
class OpenedMouth:
    """A mesh cut open along its lip contact line.

    mesh : the opened mesh: the V original vertices first and in their order, then the
        K duplicates; uv and normals copied to the duplicates.
    points : the landmarks on the opened mesh (lower-lip points on the cut moved to the
        lower sheet; every other point unchanged).
    cut : (K,) int64, the original vertices the cut runs through (corners excluded).
    duplicates : (K,) int64, the vertex each of them became on the lower sheet, V..V+K-1.
    """

    mesh: Mesh
    points: SurfacePoints
    cut: np.ndarray
    duplicates: np.ndarray


def _mouth(points: SurfacePoints, vertices: np.ndarray, layout: Layout):
    """(corner a, corner b, upper (P, 3), lower (P, 3), upper-lip ibug ids) positions of
    the layout's mouth points; refuses a layout without mouth corners and lip pairs."""
    at = {ib: i for i, ib in enumerate(layout.ibug68)}
    positions = points.positions(vertices)
    corners = next((c for c in _CORNERS if c[0] in at and c[1] in at), None)
    pairs = [(u, d) for u, d in _FACING.items() if u in at and d in at]
    if corners is None or not pairs:
        raise RetargetError(
            f"layout {layout.name!r} has no mouth corners and upper/lower lip points: the lip "
            "contact line cannot be found")
    # inner lip pairs when the layout has them: they lie on either side of the contact
    inner = [p for p in pairs if p[0] in (61, 62, 63)]
    pairs = inner or pairs
    upper = positions[[at[u] for u, _ in pairs]]
    lower = positions[[at[d] for _, d in pairs]]
    return positions[at[corners[0]]], positions[at[corners[1]]], upper, lower


def _guide(a: np.ndarray, b: np.ndarray, upper: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """(P + 2, 3) polyline from corner a through the lip-pair midpoints, ordered along
    a->b, to corner b."""
    mids = 0.5 * (upper + lower)
    order = np.argsort((mids - a) @ (b - a))
    return np.vstack([a, mids[order], b])


def _distance_to_polyline(p: np.ndarray, line: np.ndarray) -> np.ndarray:
    """(M,) distance of (M, 3) points to a polyline of (S + 1, 3) points."""
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.einsum("msd,sd->ms", p[:, None, :] - a[None], ab) / np.maximum((ab * ab).sum(1), 1e-30)
    closest = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
    return np.linalg.norm(p[:, None, :] - closest, axis=2).min(axis=1)


def _edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(E, 2) unique undirected edges (i < j) and (E,) how many triangles share each."""
    e = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(e, axis=0, return_counts=True)
    return unique, counts


def lip_crease(vertices: np.ndarray, faces: np.ndarray, points: SurfacePoints,
               layout: Layout) -> tuple[np.ndarray, np.ndarray]:
    """The lip contact line: ((L,) int64 vertex path from one mouth corner to the other,
    (L - 1,) bool whether each of its edges is shared by two triangles).

    vertices : (V, 3); faces : (F, 3); points : the landmarks of `layout`.
    Refuses a mesh on which the corners are not connected near the lips.
    """
    vertices, faces = np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
    a, b, upper, lower = _mouth(points, vertices, layout)
    guide = _guide(a, b, upper, lower)
    width = float(np.linalg.norm(b - a))
    if width <= 0:
        raise RetargetError("the two mouth corners are at one point")
    near = np.flatnonzero(_distance_to_polyline(vertices, guide) < _SEARCH_RADIUS * width)
    local = np.full(len(vertices), -1)
    local[near] = np.arange(len(near))
    edges, shared = _edges(faces)
    keep = (local[edges[:, 0]] >= 0) & (local[edges[:, 1]] >= 0)
    edges, shared = edges[keep], shared[keep]
    p, q = vertices[edges[:, 0]], vertices[edges[:, 1]]
    off = _distance_to_polyline(0.5 * (p + q), guide) / (_GUIDE_WIDTH * width)
    cost = np.linalg.norm(p - q, axis=1) * (1.0 + off * off)
    n = len(near)
    graph = coo_matrix((np.r_[cost, cost], (np.r_[local[edges[:, 0]], local[edges[:, 1]]],
                                             np.r_[local[edges[:, 1]], local[edges[:, 0]]])),
                       shape=(n, n)).tocsr()
    start = near[np.argmin(np.linalg.norm(vertices[near] - a, axis=1))]
    end = near[np.argmin(np.linalg.norm(vertices[near] - b, axis=1))]
    _, previous = dijkstra(graph, indices=local[start], return_predecessors=True)
    if previous[local[end]] < 0:
        raise RetargetError("the mouth corners are not connected by the surface near the lips")
    path = [local[end]]
    while path[-1] != local[start]:
        path.append(previous[path[-1]])
    path = near[np.array(path[::-1])]
    lookup = {tuple(e): s for e, s in zip(edges.tolist(), (shared == 2).tolist())}
    inside = np.array([lookup[tuple(sorted(e))] for e in zip(path[:-1].tolist(), path[1:].tolist())])
    return path, inside


def lips_joined(vertices: np.ndarray, faces: np.ndarray, points: SurfacePoints,
                layout: Layout) -> bool:
    """Whether the lips are one surface: the contact line between the mouth corners runs
    through the surface (edges shared by two triangles) rather than along the border of
    a lip sheet, for most of its length."""
    path, inside = lip_crease(vertices, faces, points, layout)
    v = np.asarray(vertices, np.float64)
    length = np.linalg.norm(np.diff(v[path], axis=0), axis=1)
    return bool(length[inside].sum() > 0.5 * length.sum())


def opened_mouth(mesh: Mesh, points: SurfacePoints, layout: Layout) -> OpenedMouth:
    """`mesh` cut open along its lip contact line (module docstring).

    Refuses lips that are already separate, and a cut that does not split the faces
    around a contact-line vertex into an upper and a lower side (a non-manifold crease).
    """
    vertices, faces = mesh.vertices, np.array(mesh.faces)
    path, inside = lip_crease(vertices, faces, points, layout)
    if not lips_joined(vertices, faces, points, layout):
        raise RetargetError("the lips are already separate: the mouth opens as it is")
    a, b, upper, lower = _mouth(points, vertices, layout)
    up = upper.mean(0) - lower.mean(0)
    if np.linalg.norm(up) < 1e-12 * np.linalg.norm(b - a):
        up = np.cross(b - a, mesh.normals.mean(0) if mesh.normals is not None else [0, 0, 1])
    cut = path[1:-1]
    duplicates = len(vertices) + np.arange(len(cut))
    lower_faces = _lower_sides(faces, vertices, path, up)
    renamed = dict(zip(cut.tolist(), duplicates.tolist()))
    rows = faces[lower_faces]
    faces[lower_faces] = np.vectorize(lambda v: renamed.get(v, v), otypes=[np.int64])(rows) \
        if len(rows) else rows
    # the lower lip's copies a hair below the upper's: two sheets that touch, not one
    # surface (the rig welds exact copies of a position, `retarget.welding`)
    below = CUT_GAP * np.linalg.norm(b - a) * up / np.linalg.norm(up)
    opened = mesh_from_arrays(
        np.vstack([vertices, vertices[cut] - below]), faces,
        uv=None if mesh.uv is None else np.vstack([mesh.uv, mesh.uv[cut]]),
        normals=None if mesh.normals is None else np.vstack([mesh.normals, mesh.normals[cut]]),
        name=mesh.name, material=mesh.material)
    return OpenedMouth(opened, _moved_points(points, layout, renamed), cut, duplicates)


def _lower_sides(faces: np.ndarray, vertices: np.ndarray, path: np.ndarray,
                 up: np.ndarray) -> np.ndarray:
    """(M,) indices of the faces on the lower side of the cut, at its inner vertices.

    Around each inner path vertex, its triangles are grouped by the edges they share
    that are not cut; a contact-line vertex inside the surface gives two groups, and the
    one whose centroids lie lower along `up` is the lower lip's.
    """
    cut_edges = {tuple(sorted(e)) for e in zip(path[:-1].tolist(), path[1:].tolist())}
    lower = []
    for v in path[1:-1].tolist():
        around = np.flatnonzero((faces == v).any(axis=1))
        groups = _fan_groups(faces[around], v, cut_edges)
        if groups.max() != 1:
            raise RetargetError(
                f"the lip contact line cannot be cut at vertex {v}: its triangles do not "
                f"fall into an upper and a lower side ({groups.max() + 1} groups)")
        height = (vertices[faces[around]].mean(1) - vertices[v]) @ up
        side = [height[groups == g].mean() for g in (0, 1)]
        lower.extend(around[groups == int(np.argmin(side))].tolist())
    return np.unique(np.array(lower, np.int64))


def _fan_groups(fan: np.ndarray, v: int, cut_edges: set) -> np.ndarray:
    """(n,) group of each triangle of `fan` (all holding vertex v): triangles sharing an
    edge (v, w) that is not cut are in one group."""
    n = len(fan)
    pairs = [[], []]
    for i in range(n):
        for j in range(i + 1, n):
            common = set(fan[i].tolist()) & set(fan[j].tolist())
            if len(common) == 2 and tuple(sorted(common)) not in cut_edges:
                pairs[0].append(i)
                pairs[1].append(j)
    graph = coo_matrix((np.ones(len(pairs[0])), (pairs[0], pairs[1])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _moved_points(points: SurfacePoints, layout: Layout, renamed: dict) -> SurfacePoints:
    """The landmarks on the opened mesh: lower-lip points that reference a cut vertex
    reference its lower duplicate."""
    triangles = points.vertex_indices.copy()
    for k, ib in enumerate(layout.ibug68):
        if ib in _LOWER_LIP:
            triangles[k] = [renamed.get(v, v) for v in triangles[k].tolist()]
    return SurfacePoints(triangles, points.barycentric.copy(), points.layout)
