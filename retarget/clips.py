"""`Clip`: one take retargeted, the feature displacements per frame with their timing;
`ContractionClip`: the same take driven by muscles, their contractions per frame.

`retarget.performance.take_clip` (or `Performance.play`) makes a `Clip` from a recorded
take the way the app plays it; `clip_at_rate` from displacements at a constant rate. A
`retarget.muscles.drive.MuscleDrive` solves a clip's displacements into contractions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.errors import RetargetError


@dataclass(frozen=True, eq=False)
class Clip:
    """Target feature displacements over time, as a glTF animation holds them.

    name : the animation's name.
    displacements : (F, N, 3) float32, d_f of `retarget.pipeline.Retargeter`, mesh units.
    times : (F,) float64 seconds, strictly increasing also as float32 (glTF stores
        keyframe times in float32).
    head_rotations : (F, 4) float64 unit quaternions x, y, z, w, or None: the performer's
        head rotation per frame, turning the whole target about its head pivot as the app's
        viewer does ("turn the head", `ConditionSettings.apply_rotation`); the export
        animates a ``head`` node with it (`retarget.gltf.head`).
    head_translations : (F, 3) float64 mesh units, or None: the head's translation per
        frame on top of that rotation (only with `head_rotations`).

    Build it with `clip_at_rate` for frames at a constant rate, or directly for a take's
    own times. Construction validates and makes read-only copies.
    """

    name: str
    displacements: np.ndarray
    times: np.ndarray
    head_rotations: np.ndarray | None = None
    head_translations: np.ndarray | None = None

    def __post_init__(self):
        d = np.array(self.displacements, dtype=np.float32)
        if d.ndim != 3 or d.shape[2] != 3 or len(d) == 0:
            raise RetargetError(f"clip {self.name!r}: displacements must have shape (F, N, 3) "
                                f"with F >= 1; got {d.shape}")
        if not np.isfinite(d).all():
            raise RetargetError(f"clip {self.name!r}: displacements hold NaN or infinite values")
        t = _checked_times(self.name, self.times, len(d))
        for array in (d, t):
            array.setflags(write=False)
        object.__setattr__(self, "displacements", d)
        object.__setattr__(self, "times", t)
        checked_head_motion(self, len(d))

    @property
    def n_frames(self) -> int:
        return len(self.displacements)

    @property
    def duration(self) -> float:
        """Seconds from the first frame to the last."""
        return float(self.times[-1] - self.times[0])


@dataclass(frozen=True, eq=False)
class ContractionClip:
    """Muscle contractions over time, as a muscle glTF animation holds them
    (`retarget.gltf.write_muscles_gltf`).

    name : the animation's name.
    contractions : (F, D) float64, the D dofs of a `retarget.muscles.MuscleFace` per frame
        (the muscles' contractions, then the jaw angle in radians).
    times : (F,) float64 seconds, as for `Clip`.
    head_rotations, head_translations : as for `Clip`.
    """

    name: str
    contractions: np.ndarray
    times: np.ndarray
    head_rotations: np.ndarray | None = None
    head_translations: np.ndarray | None = None

    def __post_init__(self):
        c = np.array(self.contractions, dtype=np.float64)
        if c.ndim != 2 or len(c) == 0:
            raise RetargetError(f"clip {self.name!r}: contractions must have shape (F, D) with "
                                f"F >= 1; got {c.shape}")
        if not np.isfinite(c).all():
            raise RetargetError(f"clip {self.name!r}: contractions hold NaN or infinite values")
        t = _checked_times(self.name, self.times, len(c))
        for array in (c, t):
            array.setflags(write=False)
        object.__setattr__(self, "contractions", c)
        object.__setattr__(self, "times", t)
        checked_head_motion(self, len(c))

    @property
    def n_frames(self) -> int:
        return len(self.contractions)


def _checked_times(name: str, times, n_frames: int) -> np.ndarray:
    """(F,) float64 copy of a clip's key times, refused unless one per frame, finite,
    >= 0 and strictly increasing also in float32 (glTF stores key times in float32)."""
    t = np.array(times, dtype=np.float64)
    if t.shape != (n_frames,):
        raise RetargetError(f"clip {name!r}: times must have shape ({n_frames},), one "
                            f"per frame; got {t.shape}")
    t32 = t.astype(np.float32)
    if not np.isfinite(t).all() or (t < 0).any() or (np.diff(t32) <= 0).any():
        raise RetargetError(f"clip {name!r}: times must be finite, >= 0 and strictly "
                            "increasing (also in float32)")
    return t


def checked_head_motion(clip, n_frames: int) -> None:
    """Check and freeze a clip's ``head_rotations`` (F, 4) unit quaternions (normalised
    here) and ``head_translations`` (F, 3), each None or finite with one row per frame;
    translations need rotations."""
    q, t = clip.head_rotations, clip.head_translations
    if q is not None:
        q = np.array(q, dtype=np.float64)
        if q.shape != (n_frames, 4) or not np.isfinite(q).all():
            raise RetargetError(f"clip {clip.name!r}: head_rotations must be finite quaternions of "
                                f"shape ({n_frames}, 4); got {q.shape}")
        length = np.linalg.norm(q, axis=1)
        if (length < 1e-6).any():
            raise RetargetError(f"clip {clip.name!r}: head_rotations hold a zero quaternion")
        q = q / length[:, None]
        q.setflags(write=False)
        object.__setattr__(clip, "head_rotations", q)
    if t is not None:
        if q is None:
            raise RetargetError(f"clip {clip.name!r}: head_translations need head_rotations")
        t = np.array(t, dtype=np.float64)
        if t.shape != (n_frames, 3) or not np.isfinite(t).all():
            raise RetargetError(f"clip {clip.name!r}: head_translations must be finite, of shape "
                                f"({n_frames}, 3); got {t.shape}")
        t.setflags(write=False)
        object.__setattr__(clip, "head_translations", t)


def clip_at_rate(name: str, displacements, fps: float) -> Clip:
    """A `Clip` whose frame f is at ``f / fps`` seconds."""
    if not np.isfinite(fps) or fps <= 0:
        raise RetargetError(f"fps must be a positive number; got {fps!r}")
    n = len(np.asarray(displacements))
    return Clip(name, displacements, np.arange(n) / float(fps))
