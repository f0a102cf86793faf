"""Which points of an animated mesh are the feature points: vertices or surface points
named by the user, and their positions in posed frames."""

from __future__ import annotations

import numpy as np

from retarget.errors import RetargetError
from retarget.landmarks import from_vertex_indices, landmarks_from_json
from retarget.layouts import get_layout

__all__ = ["labelled_positions", "labelled_surface_points"]


def labelled_surface_points(labelled, rest: np.ndarray, faces: np.ndarray, layout, label):
    """((K, 3) vertex indices, (K, 3) barycentric weights, K names) of the labelled points."""
    if labelled is None:
        raise RetargetError(
            f"{label}: an animated mesh needs labelled_vertices ({{point name: vertex index}} "
            "or a landmarks JSON object) to say which vertices are the feature points")
    if not isinstance(labelled, dict) or not labelled:
        raise RetargetError(f"{label}: labelled_vertices must be a non-empty object")
    if any(key in labelled for key in ("vertex_indices", "positions", "triangles")):
        name = labelled.get("layout") or layout
        if not name:
            raise RetargetError(
                f"{label}: the landmarks JSON has no \"layout\" to name its points; give a layout")
        names = get_layout(name).point_names
        points = landmarks_from_json(labelled, rest, faces)
        if points.n_points != len(names):
            raise RetargetError(
                f"{label}: the landmarks JSON has {points.n_points} points; layout {name!r} "
                f"has {len(names)}")
    else:
        names = tuple(str(k) for k in labelled)
        indices = list(labelled.values())
        if not all(isinstance(i, int) and not isinstance(i, bool) for i in indices):
            raise RetargetError(f"{label}: labelled_vertices values must be vertex indices (integers)")
        points = from_vertex_indices(np.array(indices, dtype=np.int64), len(rest))
    return points.vertex_indices, points.barycentric, names


def labelled_positions(posed, used, vertex_indices, barycentric) -> np.ndarray:
    """(F, K, 3): surface points from (F, U, 3) posed vertices at the (U,) sorted `used`."""
    rows = np.searchsorted(used, vertex_indices)
    return np.einsum("fkjd,kj->fkd", posed[:, rows], barycentric)
