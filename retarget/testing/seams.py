"""A UV seam as glTF writes one, for testing the computations that must not see it: the
vertices along a cut given second copies at the same positions (`retarget.welding`)."""

from __future__ import annotations

import numpy as np

__all__ = ["seam_split"]


def seam_split(vertices, faces, x: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The mesh (V, 3) vertices, (F, 3) faces with the triangles whose centre lies past
    `x` (along the first axis) given their own copies of the vertices they share with the
    others. Returns the vertices (V + S, 3), the faces (F, 3), the seam's vertices (S,)
    and their copies (S,), appended in that order."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    past = v[f].mean(1)[:, 0] > x
    seam = np.intersect1d(np.unique(f[past]), np.unique(f[~past]))
    copy = np.full(len(v), -1)
    copy[seam] = len(v) + np.arange(len(seam))
    split = f.copy()
    split[past] = np.where(copy[f[past]] >= 0, copy[f[past]], f[past])
    return np.vstack([v, v[seam]]), split, seam, copy[seam]
