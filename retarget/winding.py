"""Triangle winding made consistent and outward, for views that tell front from back.

A mesh file's winding is only a convention: a converter or a mirror in a modelling tool
can turn all of it inward, and meshes stitched from parts or cleaned by hand often mix the
two. Renderers that light both sides (the app's shader, Blender) show such a face as it
is, but a picture that paints back faces dark, so that eye and mouth openings read as
holes (`retarget.facemesh.views`), shows an inward face as one dark silhouette, and a mixed
one speckled, where the face detector finds nothing.

`outward_faces` re-winds the triangles (the same rows, two corners swapped where needed):

1. **Consistent**: two triangles sharing an edge run it in opposite directions. Over each
   connected patch (triangles joined by edges that exactly two triangles share, corners
   at one position counting as one vertex: a UV seam or an STL splits them, and a
   triangle listed twice counting once: its copies would make every edge round it look
   ambiguous and cut the surface into patches turned on their own), a
   breadth-first walk from one triangle flips each next one that runs the shared edge the
   same way as the one it was reached from.
2. **Outward**: a patch whose area-weighted normals point, on the whole, toward the
   patch's own centroid is turned over. A head, a face mask (a shell bulging toward the
   viewer) or a closed part (an eyeball) all have the centroid behind their outer side.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components

from retarget.welding import welded

__all__ = ["outward_faces"]


def outward_faces(vertices, faces) -> np.ndarray:
    """(F, 3) int64 `faces` (F, 3) with each triangle's corners 1 and 2 swapped where its
    winding goes against its patch's outward one (module docstring); rows keep their order
    and a triangle's corners stay its own. vertices (V, 3), any units."""
    f = np.array(faces, dtype=np.int64)
    if len(f) == 0:
        return f
    # corners at one position are one vertex (a UV seam, or an STL's triangle soup, splits
    # them), and a triangle listed twice is one: turned as its first listing is
    weld = welded(vertices, f)
    w = weld.index[f]
    _, first, listing = np.unique(np.sort(w, axis=1), axis=0, return_index=True, return_inverse=True)
    listing = listing.ravel()
    once = w[first]
    flip = _flips(weld.vertices, once)[listing]
    # a listing wound against its first one turns the other way
    own = once[listing]
    at = np.argmax(own == w[:, :1], axis=1)
    flip ^= w[:, 1] != own[np.arange(len(w)), (at + 1) % 3]
    out = f.copy()
    out[flip] = out[flip][:, [0, 2, 1]]
    return out


def _flips(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) bool: the triangles (F, 3) of distinct corners and vertex sets to turn over so
    that the winding is consistent and outward on each patch (module docstring)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = faces
    n = len(f)
    # every directed edge (a -> b) of every triangle, keyed by its undirected edge
    a = f.ravel()
    b = f[:, [1, 2, 0]].ravel()
    owner = np.repeat(np.arange(n), 3)
    key = np.minimum(a, b) * len(v) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    key, a, owner = key[order], a[order], owner[order]
    # manifold edges only: exactly two triangles (an edge of three or more is ambiguous)
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    count = np.diff(np.r_[start, len(key)])
    pair = start[count == 2]
    i, j = owner[pair], owner[pair + 1]
    # the same direction (both from the same corner) means one of the two must flip
    same = a[pair] == a[pair + 1]
    keep = i != j   # a sliver with two corners welded into one meets itself
    i, j, same = i[keep], j[keep], same[keep]
    graph = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n)).tocsr()
    graph = graph + graph.T
    parity = sp.coo_matrix((same.astype(np.float64) + 1.0, (i, j)), shape=(n, n)).tocsr()
    parity = parity + parity.T   # 1: opposite directions (agree), 2: the same (disagree)
    flip = [False] * n
    n_patches, patch = connected_components(graph, directed=False)
    # only patches with an edge run twice the same way need the walk (a consistent mesh,
    # the usual case, has none)
    first = np.unique(patch, return_index=True)[1]   # each patch's first triangle
    for root in first[np.unique(patch[i[same]])]:
        reached, pred = breadth_first_order(graph, root, directed=False, return_predecessors=True)
        reached = reached[1:]
        turn = (np.asarray(parity[pred[reached], reached]).ravel() == 2.0).tolist()
        # breadth-first: a triangle's predecessor is settled before it
        for t, p, d in zip(reached.tolist(), pred[reached].tolist(), turn):
            flip[t] = flip[p] != d
    flip = np.array(flip, dtype=bool)
    wound = f.copy()
    wound[flip] = wound[flip][:, [0, 2, 1]]
    # outward: each patch's area-weighted normals against the way out of its centroid
    corners = v[wound]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])   # 2 x area
    centre = corners.mean(1)
    area = np.linalg.norm(normal, axis=1)
    weight = np.bincount(patch, area, n_patches)
    centroid = np.stack([np.bincount(patch, area * centre[:, k], n_patches) for k in range(3)], 1)
    centroid /= np.maximum(weight, 1e-300)[:, None]
    outwardness = np.bincount(patch, np.einsum("fk,fk->f", normal, centre - centroid[patch]), n_patches)
    return flip ^ (outwardness < 0)[patch]
