"""ARKit's 52 blendshapes generated on any face from its feature points.

For each shape, the reference motion at the layout's feature points
(`retarget.arkit.reference`: the ICT generic face making the shape) is carried onto the
target like any source frame (Dutreve et al. 2008, §4): the RBF space transform fitted
from the reference neutral points to the target's maps the reference face making the
shape to target feature displacements, and the rig (§3, any deformer's `SkinWeights`)
spreads them over the mesh. The result is one dense morph target per ARKit name, left and
right as ARKit has them (the subject's left). Since the transform is nearly affine
(`retarget.pipeline.DEFAULT_SMOOTHING`) the target's own scale, orientation and units are
taken care of, as for a performer's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.arkit.reference import ARKIT_NAMES, ArkitReference, arkit_reference
from retarget.errors import RetargetError
from retarget.landmarks import SurfacePoints
from retarget.layouts import Layout, get_layout
from retarget.pipeline import Retargeter
from retarget.skin import SkinWeights, skin_displacements
from retarget.weights import DEFAULT_METHOD, compute_weights

__all__ = ["ArkitShapes", "arkit_shapes"]


@dataclass(frozen=True, eq=False)
class ArkitShapes:
    """ARKit's 52 shapes on one face.

    names : (52,) `ARKIT_NAMES`.
    deltas : (52, V, 3) float32 morph targets: vertex displacements at weight 1, the
        mesh's units.
    at_points : (52, N, 3) float32 the same shapes' displacements of the N feature points
        (the rig's joints), what `retarget.arkit.solve.ArkitSolver` fits weights to.
    """

    names: tuple[str, ...]
    deltas: np.ndarray
    at_points: np.ndarray

    def posed(self, vertices, weights) -> np.ndarray:
        """(V, 3) or (F, V, 3) float32 ``vertices + sum_k w_k deltas_k`` for (52,) or (F, 52)
        weights."""
        w = np.asarray(weights, dtype=np.float32)
        if w.shape[-1:] != (len(self.names),) or w.ndim > 2:
            raise RetargetError(f"weights must have shape ({len(self.names)},) or (F, {len(self.names)}); "
                                f"got {w.shape}")
        posed = np.asarray(vertices, dtype=np.float32) + np.tensordot(w, self.deltas, axes=1)
        return posed.astype(np.float32)

    def save(self, path) -> None:
        """Write an ``.npz`` with ``names`` (52,) str, ``deltas`` (52, V, 3) float32 and
        ``at_points`` (52, N, 3) float32."""
        np.savez_compressed(path, names=np.array(self.names), deltas=self.deltas,
                            at_points=self.at_points)


def arkit_shapes(vertices, faces, points: SurfacePoints, layout: Layout | str,
                 rig: SkinWeights | None = None, *, reference: ArkitReference | None = None,
                 method: str = DEFAULT_METHOD) -> ArkitShapes:
    """The 52 ARKit shapes on a face (module docstring).

    vertices : (V, 3) float, the target's neutral mesh, any units.
    faces : (F, 3) int triangles.
    points : the target's N feature points on its surface, in `layout`'s order.
    layout : the points' layout (name or `Layout`): it picks the reference's rows.
    rig : the target's skin weights (N joints); default: `method`'s (the default
        deformer's, as the app rigs a face).
    reference : the reference motion at the layout's points; default the shipped table
        (`arkit_reference`). The ICT benchmark passes another identity's.
    """
    layout = get_layout(layout) if isinstance(layout, str) else layout
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all():
        raise RetargetError(f"vertices must be finite with shape (V, 3); got {v.shape}")
    if points.n_points != layout.n_points:
        raise RetargetError(f"layout {layout.name!r} has {layout.n_points} points; the face has "
                            f"{points.n_points}")
    ref = arkit_reference(layout) if reference is None else reference
    if ref.neutral.shape[0] != points.n_points:
        raise RetargetError(f"the reference has {ref.neutral.shape[0]} points; the face has "
                            f"{points.n_points}")
    if rig is None:
        rig = compute_weights(method, v, faces, points, layout)
    if rig.n_vertices != len(v) or rig.n_joints != points.n_points:
        raise RetargetError(f"the rig has {rig.n_joints} joints for {rig.n_vertices} vertices; the "
                            f"face has {points.n_points} points and {len(v)} vertices")
    retargeter = Retargeter().fit(ref.neutral, points.positions(v))
    # the reference face making each shape is a source frame (Dutreve §4)
    at_points = retargeter.displacements(ref.neutral + ref.motion)
    # ICT's tongueOut has no skin motion: keep it exactly zero, not the transform's round-off
    at_points[~np.any(ref.motion != 0, axis=(1, 2))] = 0.0
    deltas = skin_displacements(rig, at_points)
    return ArkitShapes(ARKIT_NAMES, deltas.astype(np.float32), at_points)
