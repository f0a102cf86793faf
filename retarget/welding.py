"""Vertices at one position welded into one, for the computations that follow the surface.

A mesh file often holds one surface point as several vertices: glTF splits a vertex
wherever its uv or normal changes (every UV seam of a textured scan: a photogrammetry
atlas cuts the face into dozens of islands), and an STL stores each triangle with its own
three corners. The vertex count and order must stay the file's (landmarks and exports
index them, `retarget.mesh`), but a rig built on the split connectivity treats each
island as a surface of its own: the sample face cut by one seam through the cheek tore
up to 6.9 mm open along it under a 10 mm jaw drop. The deformers therefore run on the
welded surface (`retarget.weights.compute_weights`) and their weights go back to every
copy.

Only exact copies of a position are welded: surfaces meant to touch yet move apart (the
lips of a mouth cut open, `retarget.lips.opened_mouth`) keep their vertices a hair apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Welded", "welded"]


@dataclass(frozen=True, eq=False)
class Welded:
    """A mesh with its coincident vertices welded.

    vertices : (U, 3) float64, one per position, in the order first met.
    faces : (F', 3) int64 into `vertices`, the triangles that keep three corners.
    index : (V,) int64, each given vertex's welded vertex.
    """

    vertices: np.ndarray
    faces: np.ndarray
    index: np.ndarray

    @property
    def any(self) -> bool:
        """Whether some vertices were welded."""
        return len(self.vertices) < len(self.index)


def welded(vertices, faces) -> Welded:
    """(V, 3) vertices and (F, 3) faces with the vertices at one exact position made one
    (module docstring); a triangle two of whose corners become one is dropped."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    _, first, group = np.unique(v, axis=0, return_index=True, return_inverse=True)
    group = group.ravel()
    # number the welded vertices in the order their first copy comes, not by position
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    index = rank[group]
    wf = index[f]
    keep = (wf[:, 0] != wf[:, 1]) & (wf[:, 1] != wf[:, 2]) & (wf[:, 0] != wf[:, 2])
    return Welded(v[np.sort(first)], wf[keep], index)
