"""`ArkitClip`: a take as ARKit weights per frame, as an ARKit glTF animation
(`retarget.gltf.arkit`) and a Live Link Face CSV (`retarget.sources.arkit_curves.live_link_csv`)
hold it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.arkit.reference import ARKIT_NAMES
from retarget.clips import _checked_times, checked_head_motion  # one definition of each check
from retarget.errors import RetargetError

__all__ = ["ArkitClip"]


@dataclass(frozen=True, eq=False)
class ArkitClip:
    """ARKit weights over time.

    name : the animation's name.
    weights : (F, 52) float64 in [0, 1], `ARKIT_NAMES` order (`retarget.arkit.solve`).
    times : (F,) float64 seconds, strictly increasing also as float32 (as `retarget.clips.Clip`).
    head_rotations, head_translations : (F, 4) quaternions and (F, 3) mesh units, or None,
        as for `retarget.clips.Clip`.

    Construction validates and makes read-only copies.
    """

    name: str
    weights: np.ndarray
    times: np.ndarray
    head_rotations: np.ndarray | None = None
    head_translations: np.ndarray | None = None

    def __post_init__(self):
        w = np.array(self.weights, dtype=np.float64)
        k = len(ARKIT_NAMES)
        if w.ndim != 2 or w.shape[1] != k or len(w) == 0:
            raise RetargetError(f"clip {self.name!r}: weights must have shape (F, {k}) with F >= 1; "
                                f"got {w.shape}")
        if not np.isfinite(w).all() or (w < 0).any() or (w > 1).any():
            raise RetargetError(f"clip {self.name!r}: ARKit weights must be finite and in [0, 1]")
        t = _checked_times(self.name, self.times, len(w))
        for array in (w, t):
            array.setflags(write=False)
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "times", t)
        checked_head_motion(self, len(w))

    @property
    def n_frames(self) -> int:
        return len(self.weights)

    @classmethod
    def at_rate(cls, name: str, weights, fps: float) -> "ArkitClip":
        """A clip whose frame f is at ``f / fps`` seconds."""
        if not np.isfinite(fps) or fps <= 0:
            raise RetargetError(f"fps must be a positive number; got {fps!r}")
        return cls(name, weights, np.arange(len(np.asarray(weights))) / float(fps))
