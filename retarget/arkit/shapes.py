"""ARKit's 52 blendshapes generated on any face from its feature points.

For each shape, the reference motion (`retarget.arkit.reference`: the ICT generic face
making the shape) is carried onto the target like any source frame (Dutreve et al. 2008,
§4): the RBF space transform fitted from the reference neutral's feature points to the
target's maps the reference face making the shape to target displacements, and a rig
spreads them over the mesh. The result is one dense morph target per ARKit name, left and
right as ARKit has them (the subject's left). The transform is nearly affine
(`retarget.pipeline.DEFAULT_SMOOTHING`), so the target's own scale, orientation and units
are taken care of, as for a performer's.

Which rig:

- **Given** (`rig`, any deformer's `SkinWeights` on the layout's points): the shapes are
  the layout's point motion through it (Dutreve §3), exactly what playing the same motion
  on that rig shows.
- **Default**: the rig that makes the best shapes. A layout of a few dozen points cannot
  say how a blink rolls the lid between two lid points (on the ICT face model, 68 points
  through the default biharmonic rig leave 44 % of the shapes' motion wrong, the lids
  worst); so the reference's 468 face-mesh points are placed on the face by a space
  transform from the layout's points, snapped to its surface, and drive a dense RBF rig
  (Zhang et al. §2.1, `retarget.weights.rbf`) with their own reference motion: 24.5 % on
  ICT over three identity pairs (``bench/arkit.py``), about a second for an 11k-vertex
  face. A face placed in the ``mediapipe468`` layout uses its own 468 points.

`ArkitShapes.at_points` is always the layout's point motion, what the solver
(`retarget.arkit.solve`) fits a frame's feature displacements with.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from retarget.arkit.reference import ARKIT_NAMES, ArkitReference, arkit_reference
from retarget.errors import RetargetError
from retarget.landmarks import SurfacePoints
from retarget.layouts import Layout, get_layout
from retarget.pipeline import DEFAULT_KERNEL, Retargeter
from retarget.rbf import RBFTransform
from retarget.skin import SkinWeights, skin_displacements
from retarget.weights import compute_weights

__all__ = ["ArkitShapes", "arkit_shapes"]

DENSE = "mediapipe468"  # the reference layout the default rig is made on


@dataclass(frozen=True, eq=False)
class ArkitShapes:
    """ARKit's 52 shapes on one face.

    names : (52,) `ARKIT_NAMES`.
    deltas : (52, V, 3) float32 morph targets: vertex displacements at weight 1, the
        mesh's units.
    at_points : (52, N, 3) float32 the same shapes' displacements of the layout's N
        feature points, what `retarget.arkit.solve.ArkitSolver` fits weights to.
    """

    names: tuple[str, ...]
    deltas: np.ndarray
    at_points: np.ndarray

    def posed(self, vertices, weights) -> np.ndarray:
        """(V, 3) or (F, V, 3) float32 ``vertices + sum_k w_k deltas_k`` for (52,) or (F, 52)
        weights."""
        w = np.asarray(weights, dtype=np.float32)
        if w.shape[-1:] != (len(self.names),) or w.ndim > 2:
            raise RetargetError(f"weights must have shape ({len(self.names)},) or "
                                f"(F, {len(self.names)}); got {w.shape}")
        posed = np.asarray(vertices, dtype=np.float32) + np.tensordot(w, self.deltas, axes=1)
        return posed.astype(np.float32)

    def save(self, path) -> None:
        """Write an ``.npz`` with ``names`` (52,) str, ``deltas`` (52, V, 3) float32 and
        ``at_points`` (52, N, 3) float32."""
        np.savez_compressed(path, names=np.array(self.names), deltas=self.deltas,
                            at_points=self.at_points)

    @classmethod
    def load(cls, path) -> "ArkitShapes":
        """The shapes `save` wrote (``retarget arkit``'s SHAPES.npz), checked: the 52 names
        in Apple's order, finite ``deltas`` (52, V, 3) and ``at_points`` (52, N, 3). Raises
        `RetargetError` naming the file and what is wrong."""
        label = f"ARKit shapes {str(path)!r}"
        try:
            with np.load(path, allow_pickle=False) as z:
                missing = [key for key in ("names", "deltas", "at_points") if key not in z.files]
                if missing:
                    raise RetargetError(f"{label} lack {', '.join(missing)}: make them with "
                                        "'retarget arkit'")
                names, deltas, at_points = (z[key] for key in ("names", "deltas", "at_points"))
        except (OSError, ValueError, EOFError) as exc:
            raise RetargetError(f"could not read {label} as .npz: {exc}") from None
        if tuple(str(n) for n in names) != ARKIT_NAMES:
            raise RetargetError(f"{label} do not name ARKit's 52 shapes in Apple's order")
        k = len(ARKIT_NAMES)
        for key, array in (("deltas", deltas), ("at_points", at_points)):
            if array.ndim != 3 or array.shape[0] != k or array.shape[2] != 3 \
                    or array.dtype.kind not in "fiu":
                raise RetargetError(f"{label}: {key} must be numbers of shape ({k}, n, 3); got "
                                    f"{array.shape} {array.dtype}")
            if not np.isfinite(array).all():
                raise RetargetError(f"{label}: {key} hold NaN or infinite values")
        return cls(ARKIT_NAMES, deltas.astype(np.float32), at_points.astype(np.float32))


def arkit_shapes(vertices, faces, points: SurfacePoints, layout: Layout | str,
                 rig: SkinWeights | None = None, *, reference: ArkitReference | None = None,
                 dense_reference: ArkitReference | None = None) -> ArkitShapes:
    """The 52 ARKit shapes on a face (module docstring).

    vertices : (V, 3) float, the target's neutral mesh, any units.
    faces : (F, 3) int triangles.
    points : the target's N feature points on its surface, in `layout`'s order.
    layout : the points' layout (name or `Layout`): it picks the reference's rows.
    rig : the target's skin weights on the N points, or None for the default rig (the
        reference's 468 face-mesh points carried onto the face, module docstring).
    reference, dense_reference : the reference motion at the layout's points and at the
        468 face-mesh points; default the shipped table (`arkit_reference`). The ICT
        benchmark passes another identity's.
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
    if rig is not None and (rig.n_vertices != len(v) or rig.n_joints != points.n_points):
        raise RetargetError(f"the rig has {rig.n_joints} joints for {rig.n_vertices} vertices; the "
                            f"face has {points.n_points} points and {len(v)} vertices")
    retargeter = Retargeter().fit(ref.neutral, points.positions(v))
    # the reference face making each shape is a source frame (Dutreve §4)
    at_points = _motionless_kept(retargeter.displacements(ref.neutral + ref.motion), ref.motion)
    if rig is not None:
        deltas = skin_displacements(rig, at_points)
    elif _is_dense(layout):
        deltas = skin_displacements(compute_weights("rbf", v, faces, points, None), at_points)
    else:
        dense = arkit_reference(DENSE) if dense_reference is None else dense_reference
        deltas = _dense_deltas(v, faces, retargeter, dense, ref.neutral, points.positions(v))
    return ArkitShapes(ARKIT_NAMES, deltas.astype(np.float32), at_points)


def _dense_deltas(vertices: np.ndarray, faces, retargeter: Retargeter,
                  dense: ArkitReference, source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(52, V, 3) the shapes through the default rig: the dense reference points placed on
    the face and snapped to its surface, their motion carried by the fitted transform, and
    an RBF rig on them. `source` (N, 3) and `target` (N, 3) are the layout's reference and
    face points.

    The placing transform interpolates (smoothing 0): the layout's reference points land
    exactly on the face's and the dense ones between follow the face's own shape (its lips
    most of all: on ICT, 28 % off against 35 % with the near-affine one for the worst of
    three identity pairs); the motion goes through the retargeter's near-affine transform,
    as any source's does."""
    transform = retargeter.transform_
    motion = transform.transform(dense.neutral + dense.motion) - transform.transform(dense.neutral)
    placed = RBFTransform(DEFAULT_KERNEL, smoothing=0.0).fit(source, target).transform(dense.neutral)
    surface = trimesh.Trimesh(vertices, np.asarray(faces), process=False)
    closest, _, triangle = trimesh.proximity.closest_point(surface, placed)
    # two reference points snapped to one spot would make the RBF system singular
    _, first = np.unique(np.round(closest / (1e-6 * np.ptp(vertices, axis=0).max()), 0),
                         axis=0, return_index=True)
    keep = np.sort(first)
    corners = np.asarray(faces)[triangle[keep]]
    bary = np.clip(trimesh.triangles.points_to_barycentric(vertices[corners], closest[keep]), 0, None)
    on_surface = SurfacePoints(corners, bary / bary.sum(1, keepdims=True))
    weights = compute_weights("rbf", vertices, faces, on_surface, None)
    return skin_displacements(weights, _motionless_kept(motion[:, keep], dense.motion[:, keep]))


def _motionless_kept(displacements: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """`displacements` (52, N, 3) float32 with exact zeros where the reference `motion`
    has none (ICT's tongueOut), not the transform's round-off."""
    out = np.asarray(displacements, dtype=np.float32).copy()
    out[~np.any(motion != 0, axis=(1, 2))] = 0.0
    return out


def _is_dense(layout: Layout) -> bool:
    """Whether the layout's points are the 468 face-mesh points themselves."""
    return layout.n_points == 468 and layout.mediapipe468 == tuple(range(468))
