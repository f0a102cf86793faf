"""`Clip`: one take retargeted, the feature displacements per frame with their timing.

`take_clip` makes one from a recorded take the way the app plays it (conditioning, then
Dutreve §4's retargeting onto the target's feature points).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.pipeline import Retargeter
from retarget.sources.conditioning import ConditionSettings, condition_take
from retarget.sources.take import Take


@dataclass(frozen=True, eq=False)
class Clip:
    """Target feature displacements over time, as a glTF animation holds them.

    name : the animation's name.
    displacements : (F, N, 3) float32, d_f of `retarget.pipeline.Retargeter`, mesh units.
    times : (F,) float64 seconds, strictly increasing also as float32 (glTF stores
        keyframe times in float32).

    Build it with `clip_at_rate` for frames at a constant rate, or directly for a take's
    own times. Construction validates and makes read-only copies.
    """

    name: str
    displacements: np.ndarray
    times: np.ndarray

    def __post_init__(self):
        d = np.array(self.displacements, dtype=np.float32)
        t = np.array(self.times, dtype=np.float64)
        if d.ndim != 3 or d.shape[2] != 3 or len(d) == 0:
            raise RetargetError(f"clip {self.name!r}: displacements must have shape (F, N, 3) "
                                f"with F >= 1; got {d.shape}")
        if not np.isfinite(d).all():
            raise RetargetError(f"clip {self.name!r}: displacements hold NaN or infinite values")
        if t.shape != (len(d),):
            raise RetargetError(f"clip {self.name!r}: times must have shape ({len(d)},), one "
                                f"per frame; got {t.shape}")
        t32 = t.astype(np.float32)
        if not np.isfinite(t).all() or (t < 0).any() or (np.diff(t32) <= 0).any():
            raise RetargetError(f"clip {self.name!r}: times must be finite, >= 0 and strictly "
                                "increasing (also in float32)")
        for array in (d, t):
            array.setflags(write=False)
        object.__setattr__(self, "displacements", d)
        object.__setattr__(self, "times", t)

    @property
    def n_frames(self) -> int:
        return len(self.displacements)

    @property
    def duration(self) -> float:
        """Seconds from the first frame to the last."""
        return float(self.times[-1] - self.times[0])


def clip_at_rate(name: str, displacements, fps: float) -> Clip:
    """A `Clip` whose frame f is at ``f / fps`` seconds."""
    if not np.isfinite(fps) or fps <= 0:
        raise RetargetError(f"fps must be a positive number; got {fps!r}")
    n = len(np.asarray(displacements))
    return Clip(name, displacements, np.arange(n) / float(fps))


def take_clip(name: str, take: Take, target_points, layout: str, settings=None, *,
              regions=None) -> Clip:
    """A `Clip` of `take` retargeted onto the target, as the app's take player
    (``server.sources.TakeSource``) plays it: the take's points matched to `layout` by
    name (a subset drives the rest by interpolation), conditioned by
    `retarget.sources.conditioning.condition_take` (the neutral-capture frames are left
    out), then `retarget.pipeline.Retargeter` trained on the conditioned neutral and the
    target's points.

    target_points : (N, 3) the target's feature points, mesh units, in `layout`'s order.
    layout : the target's layout name ("" is iBUG 68, as the player takes it).
    settings : `ConditionSettings`, its dict form, or None for the defaults.
    regions : region, group or point names that move (partial retargeting), None for all.

    The clip's times are the kept frames' own, from 0 s at the first kept frame. The
    head's rotation is not part of the clip (feature displacements carry no rigid head
    motion).
    """
    target = get_layout(layout or "ibug68")
    if not isinstance(settings, ConditionSettings):
        settings = ConditionSettings.from_dict(settings)
    conditioned, neutral = condition_take(take.to_layout(target.name, partial=True), settings)
    mask = target.region_mask(regions) if regions else None
    retargeter = Retargeter(mask=mask).fit(neutral, target_points)
    return Clip(name, retargeter.displacements(conditioned.points), conditioned.frame_times())
