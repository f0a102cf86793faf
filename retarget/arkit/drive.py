"""Driving a face by ARKit's 52 blendshapes instead of its feature-point joints (issue 16).

Per frame: the feature points' displacements from the space transform (Dutreve §4, any
source, conditioned as in feature-point mode) are fitted by the 52 shapes' motion at the
points (`retarget.arkit.solve.ArkitSolver`, warm-started from the previous frame); the
weights, times the user's gain per shape (`retarget.arkit.settings`), are what the frame
sends: the page plays them as morph targets, and other tools read them as ARKit curves.

Gain: applied **after** the solver's [0, 1] box, then clipped to [0, 1] again, so the
output is always in ARKit's range (what Live Link, VRM and game engines expect): a gain of
1.5 makes a half smile 0.75 and saturates a full one at 1; 0 silences the shape. The solver
itself never sees the gains, so a gain does not change which shapes it picks.
"""

from __future__ import annotations

import numpy as np

from retarget.arkit.reference import ARKIT_NAMES
from retarget.arkit.shapes import ArkitShapes
from retarget.arkit.solve import ArkitSolver
from retarget.errors import RetargetError

__all__ = ["ArkitDrive"]


class ArkitDrive:
    """Feature displacements -> 52 ARKit weights, frame after frame.

    shapes : the face's `ArkitShapes` (its ``at_points`` are what is fitted).
    gains : (52,) per-shape gains in [0, 2] (default 1), `ARKIT_NAMES` order.
    """

    def __init__(self, shapes: ArkitShapes, gains=None):
        self.shapes = shapes
        self.solver = ArkitSolver(shapes.at_points)
        self.set_gains(np.ones(len(ARKIT_NAMES)) if gains is None else gains)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.shapes.names)

    def set_gains(self, gains) -> None:
        """(52,) gains in [0, 2], from the next frame on."""
        g = np.asarray(gains, dtype=np.float64)
        if g.shape != (len(ARKIT_NAMES),) or not np.isfinite(g).all() or (g < 0).any() or (g > 2).any():
            raise RetargetError(f"gains must be {len(ARKIT_NAMES)} numbers in [0, 2]; got shape {g.shape}")
        self.gains = g

    def reset(self) -> None:
        """Start the next frame from all weights 0 (a new take)."""
        self.solver.reset()

    def weights(self, feature_displacements, lost=None) -> np.ndarray:
        """(52,) float32 weights in [0, 1] of one frame of (N, 3) feature displacements
        (the mesh's units), warm-started from the last frame, gains applied (module
        docstring).

        lost : (N,) bool, points the source lost this frame: left out of the fit.
        """
        d = np.array(feature_displacements, dtype=np.float64)
        if lost is not None:
            d[np.asarray(lost, dtype=bool)] = np.nan
        return np.clip(self.solver.solve(d) * self.gains, 0.0, 1.0).astype(np.float32)

    def weights_frames(self, feature_displacements) -> np.ndarray:
        """(F, 52) float32 weights of (F, N, 3) displacements, each frame warm-starting the
        next."""
        d = np.asarray(feature_displacements, dtype=np.float64)
        if d.ndim != 3:
            raise RetargetError(f"feature displacements must be (F, N, 3); got {d.shape}")
        return np.stack([self.weights(frame) for frame in d]) if len(d) else np.zeros((0, 52), np.float32)

    def displacements(self, weights) -> np.ndarray:
        """(V, 3) float32 vertex displacements of (52,) weights (the shapes' morph targets)."""
        return self.shapes.posed(np.zeros(self.shapes.deltas.shape[1:], np.float32), weights)
