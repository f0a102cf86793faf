"""Driving a face by its muscles instead of its feature-point joints (Woodward §7).

Per frame: the feature points' displacements from the space transform (Dutreve §4, any
source, conditioned as in feature-point mode) are the markers' goals; the muscle IK finds
the contractions and jaw angle that put the marked vertices nearest them (warm-started from
the previous frame); the muscle model turns the contractions into vertex displacements.
The muscles only make motions they can make, so tracker noise and impossible poses are
absorbed rather than copied onto the face (bench/muscles.py measures by how much).

Units: displacements in the mesh's own; contractions as the model's limits say.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.errors import RetargetError
from retarget.landmarks import SurfacePoints
from retarget.muscles.expressions import ExpressionRecogniser, default_recogniser
from retarget.muscles.ik import MuscleIK
from retarget.muscles.model import MuscleFace

__all__ = ["MuscleDrive", "MuscleFrame"]


@dataclass(frozen=True, eq=False)
class MuscleFrame:
    """One frame driven by muscles, as a live player sends it.

    contractions : (D,) float64, the muscles' contractions then the jaw angle (radians).
    distances : (E,) float64, normalised distances to the recogniser's expressions
        (`retarget.muscles.expressions`, its ``labels`` order).
    label : index of the nearest expression in those labels.
    confidence : in [0, 1], how much nearer the nearest is than the next.
    """

    contractions: np.ndarray
    distances: np.ndarray
    label: int
    confidence: float


class MuscleDrive:
    """Feature displacements -> contractions -> vertex displacements, frame after frame.

    model : the face's `MuscleFace` (`place_muscles`).
    points : the target's N feature points (`SurfacePoints`); each is marked at its nearest
        vertex, where the model is evaluated (the point and that vertex move alike).
    method : the IK solver, "dls" or "transpose" (`retarget.muscles.ik`).
    recogniser : what `frame` reads expressions with; default `default_recogniser`.
    """

    def __init__(self, model: MuscleFace, points: SurfacePoints, method: str = "dls",
                 recogniser: ExpressionRecogniser | None = None):
        self.model = model
        self.marked = points.nearest_vertices()
        self.ik = MuscleIK(model, self.marked, method)
        self.recogniser = recogniser or default_recogniser(model.names)

    @property
    def names(self) -> tuple[str, ...]:
        return self.model.names

    def reset(self) -> None:
        """Start the next frame from the rest pose (a new take)."""
        self.ik.reset()

    def contractions(self, feature_displacements) -> np.ndarray:
        """(N, 3) or (F, N, 3) feature displacements -> (D,) or (F, D) float64 contractions,
        the frames solved in order, each started from the last. NaN rows: lost points, left
        out of that frame's solve."""
        d = np.asarray(feature_displacements, dtype=np.float64)
        one = d.ndim == 2
        frames = d[None] if one else d
        if frames.ndim != 3 or frames.shape[1:] != (len(self.marked), 3):
            raise RetargetError(f"feature displacements must be (F, {len(self.marked)}, 3); got {d.shape}")
        out = np.stack([self.ik.push(frame) for frame in frames])
        return out[0] if one else out

    def frame(self, feature_displacements, lost=None) -> MuscleFrame:
        """One live frame: (N, 3) feature displacements -> its contractions (warm-started
        from the last frame's) and the expression they show.

        lost : (N,) bool, points the source lost this frame (their displacements are
            placeholders): left out of the solve rather than pulled to rest.
        """
        d = np.array(feature_displacements, dtype=np.float64)
        if lost is not None:
            d[np.asarray(lost, dtype=bool)] = np.nan
        c = self.contractions(d)
        seen = self.recogniser.recognise(c)
        return MuscleFrame(c, seen.distances[0], self.recogniser.labels.index(str(seen.labels[0])),
                           float(seen.confidence[0]))

    def displacements(self, contractions) -> np.ndarray:
        """(D,) or (F, D) contractions -> (V, 3) or (F, V, 3) float32 vertex displacements."""
        c = np.asarray(contractions, dtype=np.float64)
        if c.shape[-1] != self.model.n_dof or c.ndim not in (1, 2):
            raise RetargetError(f"contractions must be (F, {self.model.n_dof}); got {c.shape}")
        if c.ndim == 1:
            return self.model.displacements(c).astype(np.float32)
        return np.stack([self.model.displacements(row) for row in c]).astype(np.float32)
