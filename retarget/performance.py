"""A played performance: one performer's source points driving one target's feature points.

`Performance` is the chain every player of a performance shares (the web app's demo, take and
live sources, the glTF export's takes, the command line's files):

    source points (N, D) -> conditioning (`retarget.sources.conditioning`: neutral, head pose,
    jitter filter, gain) -> the RBF space transform of Dutreve et al. 2008 §4
    (`retarget.pipeline.Retargeter`, fitted once per neutral) -> target feature displacements
    d (N, 3), masked per frame by the regions that move (partial retargeting, §4 and Fig. 3:
    changing the regions refits nothing).

Three ways in, one per kind of source:

- ``push(points, t)``: frames as they come (a live tracker). The neutral is captured from the
  first frames as the settings say (Woodward §5.1), `recapture` captures it again; a capture
  during which the performer moved is refused (`NeutralMoved`, `LIVE_NEUTRAL_MOTION`) and
  none is taken until `recapture`;
- ``cue(take)``, then ``frame(...)`` per frame: a recorded take conditioned whole once, then
  played frame by frame at its own times by a scheduler (which may loop it); ``play(take)``
  is the whole take at once, a `retarget.clips.Clip`;
- ``set_neutral(neutral)``, then ``frame(points, t)`` or ``displacements(frames)``: frames that
  need no conditioning (the built-in demo performer, S0 and S read from files).

Every frame played can be recorded (`start_recording`, `stop_recording`): the raw source points,
before conditioning, at their source times, so a recording is conditioned again when it is
played. A source with fewer points than the target's layout (21 markers driving 68 joints)
has NaN rows for the points it lacks; the retargeter drives those by interpolation
(`retarget.pipeline`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from retarget.clips import Clip
from retarget.errors import RetargetError
from retarget.layouts import Layout, get_layout
from retarget.pipeline import DEFAULT_KERNEL, Retargeter
from retarget.rbf import as_points
from retarget.sources.conditioning import ConditionSettings, SourceConditioner, condition_take
from retarget.sources.take import Take

__all__ = ["LIVE_LOST_WAIT", "LIVE_NEUTRAL_MOTION", "MAX_RECORD_SECONDS", "Cue", "Performance", "PerformanceFrame", "take_clip"]

LIVE_NEUTRAL_MOTION = 0.1
"""The most a point of pushed frames may move during their neutral capture, in eye distances
(`SourceConditioner`'s ``max_neutral_motion``): a tracker's jitter on a still face is a few
hundredths, a puffed cheek or a spoken word several tenths."""

LIVE_LOST_WAIT = 2.0
"""Seconds a live neutral capture goes on past its span for points not yet seen in it
(`SourceConditioner`'s ``lost_wait``): a tracker may find the last markers a few frames in,
and a loaded machine may deliver only a frame or two in the span. Points still unseen then
join once they show. (0.5 s moved the face 0.24 s sooner in one of 9 live sticker sessions
of `bench/stereo_live.py --stickers` and left 2 of 13 points waiting to its end in that
one.)"""

MAX_RECORD_SECONDS = 600.0
"""A recording keeps its first ten minutes; what comes later is not kept (rather than failing
the performance midway)."""


@dataclass(frozen=True, eq=False)
class PerformanceFrame:
    """One retargeted frame.

    displacements : (N, 3) float32 target feature displacements d, target units; zero for
        the points outside the regions and for lost points (they keep their neutral place).
    lost : (N,) bool, the points the source drives that are lost (NaN) in this frame.
    head_rotation : (4,) float64 unit quaternion x, y, z, w: the performer's head rotation
        relative to the neutral, in the source's axes, for a viewer that turns the whole
        target with it; None unless the settings apply it
        (`ConditionSettings.apply_rotation`).
    time : the frame's source time, seconds.
    """

    displacements: np.ndarray
    lost: np.ndarray
    head_rotation: np.ndarray | None
    time: float


@dataclass(frozen=True, eq=False)
class Cue:
    """A take ready to play frame by frame (`Performance.cue`).

    raw : (F, N, D) float32, the take's own points in the target layout's order (NaN rows for
        the points it lacks). Frame i of a recording of the cue keeps ``raw[i]`` at
        ``times[i]``, so a recording plays back conditioned alike.
    points : (F, N, D) float32, every frame conditioned (`condition_take`: the neutral is
        found first, no frame is left out).
    times : (F,) float64 seconds, 0 at the first frame.
    rotations : (F, 3, 3) float64, the performer's head rotation per frame, or None when
        the settings do not apply it.
    """

    raw: np.ndarray
    points: np.ndarray
    times: np.ndarray
    rotations: np.ndarray | None

    @property
    def n_frames(self) -> int:
        return len(self.points)

    def rotation(self, index: int) -> np.ndarray | None:
        """(3, 3) head rotation of frame `index`, or None."""
        return None if self.rotations is None else self.rotations[index]


class Performance:
    """A performer driving a target's feature points (see the module docstring).

    target_points : (N, 3) float, the target's feature points T0 in `layout`'s order, mesh
        units.
    layout : the target's layout (a name or `Layout`), or None for points without one (then
        regions are feature masks only, and takes cannot be matched by name).
    settings : `ConditionSettings`, its dict form, or None for the defaults: how pushed and
        cued frames are conditioned.
    regions : the points that move, as region, group or point names of the layout or an
        (N,) bool mask; None (or empty) for all.
    dims : 2 or 3, the dimension of pushed frames.
    kernel, smoothing : the space transform's (`retarget.pipeline.Retargeter`).

    State: ``neutral_`` (N, D) the neutral frames are retargeted against (None until it is
    set, cued or captured), ``mask_`` (N,) bool the active points, ``settings``, ``regions``,
    ``max_neutral_motion`` the still check of a neutral captured from pushed frames
    (`LIVE_NEUTRAL_MOTION` eye distances; None: none, for a source whose points jitter
    more than a performer's moves, set before the first push).
    """

    def __init__(self, target_points, layout: str | Layout | None = None, settings=None,
                 regions=None, *, dims: int = 3, kernel: str = DEFAULT_KERNEL,
                 smoothing: float | None = None):
        self.layout = layout if layout is None or isinstance(layout, Layout) else get_layout(layout)
        self.target_points = as_points(target_points, "target points", dims=(3,))
        n = len(self.target_points)
        if self.layout is not None and n != self.layout.n_points:
            raise RetargetError(f"layout {self.layout.name!r} has {self.layout.n_points} points; "
                                f"the target has {n} feature points")
        if dims not in (2, 3):
            raise RetargetError(f"live points must be 2D or 3D; got dims {dims!r}")
        self.dims = dims
        self.kernel, self.smoothing = kernel, smoothing
        self.settings = _settings(settings)
        self.set_regions(regions)
        self.neutral_ = self._retargeter = self._conditioner = self._captured = None
        self._recording: list | None = None
        self.max_neutral_motion: float | None = LIVE_NEUTRAL_MOTION

    @property
    def n_points(self) -> int:
        return len(self.target_points)

    # -- settings ---------------------------------------------------------------------------

    def set_regions(self, regions) -> None:
        """Partial retargeting from the next frame on: only these regions, groups or points
        move (names of the layout, or an (N,) bool mask); None or empty for all. Unknown
        names are refused before anything changes. Nothing is refitted."""
        if regions is None or (not isinstance(regions, np.ndarray) and len(regions) == 0):
            mask = np.ones(self.n_points, dtype=bool)
        elif isinstance(regions, np.ndarray) and regions.dtype == bool:
            if regions.shape != (self.n_points,):
                raise RetargetError(f"a regions mask must have shape ({self.n_points},); got "
                                    f"{regions.shape}")
            mask = regions.copy()
        elif self.layout is None:
            raise RetargetError("region names need the target's layout")
        else:
            mask = self.layout.region_mask(regions)
        self.regions = None if regions is None or not len(regions) else regions
        self.mask_ = mask

    def set_settings(self, settings) -> None:
        """New conditioning of pushed frames. A neutral already captured is kept unless the
        new settings choose the neutral another way than the old ones."""
        settings = _settings(settings)
        old = self._conditioner
        captured = old is not None and old.neutral_ is not None
        if captured and self.settings.neutral == settings.neutral:
            given = ConditionSettings.from_dict({**settings.to_dict(),
                                                 "neutral": {"mode": "given"}})
            self._conditioner = SourceConditioner(self.layout, self.dims, given,
                                                  neutral=old.neutral_)
        else:
            self._forget_neutral()
        self.settings = settings

    def recapture(self) -> None:
        """Capture the neutral again from the next pushed frames."""
        self._forget_neutral()

    def set_neutral(self, neutral) -> None:
        """Retarget against `neutral`: (N, D) source points at rest, in layout order, NaN rows
        for the points the source lacks (the retargeter is fitted here, the costly step).
        Frames given to `frame` and `displacements` are then taken as conditioned."""
        self._fit(neutral)
        self._captured = None

    @property
    def waiting(self) -> tuple[str, ...]:
        """The points a live neutral capture was taken without, not seen yet: each joins
        once it shows (`SourceConditioner`'s ``waiting_``; Woodward's temple stickers show
        when the head turns). Empty before the capture and when none is missing."""
        return () if self._conditioner is None else self._conditioner.waiting_

    # -- frames -----------------------------------------------------------------------------

    def push(self, points, t: float) -> PerformanceFrame | None:
        """One frame as it comes: (N, dims) raw source points in layout order (NaN rows lost),
        `t` its capture time in seconds. Recorded, conditioned and retargeted; None while the
        neutral is being captured."""
        points = np.asarray(points)
        if points.shape != (self.n_points, self.dims):
            raise RetargetError(f"live frame must hold {self.n_points} points of {self.dims} "
                                f"coordinates; got {points.shape}")
        self._record(points, t)
        if self._conditioner is None:
            self._conditioner = SourceConditioner(self.layout, self.dims, self.settings,
                                                  max_neutral_motion=self.max_neutral_motion,
                                                  lost_wait=LIVE_LOST_WAIT)
        conditioned = self._conditioner.push(points, t)
        if conditioned is None:
            return None
        if self._captured is not self._conditioner.neutral_:
            self._fit(self._conditioner.neutral_)
            self._captured = self._conditioner.neutral_
        rotation = self._conditioner.rotation_ if self.settings.apply_rotation else None
        return self._frame(conditioned, t, rotation)

    def cue(self, take: Take, settings=None) -> Cue:
        """`take` ready to play: its points matched to the layout by name (a subset drives
        the rest by interpolation), conditioned whole (`condition_take`, with `settings` or
        the performance's own), and its neutral retargeted against. The performance takes
        the settings only once the take is conditioned, so a refused change leaves it as it
        was."""
        if self.layout is None:
            raise RetargetError("a take is matched to the target's points by name, which needs "
                                "the target's layout")
        settings = self.settings if settings is None else _settings(settings)
        raw = take.to_layout(self.layout.name, partial=True)
        conditioned, neutral, rotations = condition_take(raw, settings, with_rotations=True)
        times = conditioned.frame_times()
        self.set_neutral(neutral)
        self.settings, self._conditioner = settings, None  # pushed frames capture anew
        return Cue(raw.points, conditioned.points, times - times[0],
                   rotations if settings.apply_rotation else None)

    def frame(self, points, t: float, *, rotation=None, raw=None) -> PerformanceFrame:
        """One conditioned frame, (N, D) source points at source time `t` s, retargeted against
        the neutral; `rotation` (3, 3) the performer's head rotation or None. A recording keeps
        `raw` (default: `points`)."""
        self._record(points if raw is None else raw, t)
        return self._frame(points, t, rotation)

    def displacements(self, frames) -> np.ndarray:
        """(F, N, D) or (N, D) conditioned source points -> (F, N, 3) or (N, 3) float32 target
        feature displacements, the regions' mask applied."""
        return self._fitted().displacements(frames, mask=self.mask_)

    def play(self, take: Take, name: str = "take", settings=None) -> Clip:
        """The whole take retargeted (`cue`, then every frame) as a `Clip` named `name`, at
        the take's own times from 0 s at its first frame. When the settings turn the head
        (``apply_rotation``), the clip's ``head_rotations`` are the quaternions the take
        player streams with each frame (the viewer turns the face by them; the export
        animates a ``head`` node, `retarget.gltf.head`)."""
        cue = self.cue(take, settings)
        turns = None if cue.rotations is None else Rotation.from_matrix(cue.rotations).as_quat()
        return Clip(name, self.displacements(cue.points), cue.times, head_rotations=turns)

    # -- recording --------------------------------------------------------------------------

    @property
    def recording(self) -> int | None:
        """Frames recorded so far, or None when not recording."""
        return None if self._recording is None else len(self._recording)

    def start_recording(self) -> None:
        """Keep every frame played from now on (raw source points at their source times)."""
        self._recording = []

    def stop_recording(self, *, source: str = "", fps: float = 30.0) -> Take:
        """The frames recorded since `start_recording` as a take in the target's layout at
        their true times from 0; `source` names what played them, `fps` is the rate they
        were played at (the stream's nominal rate: a live camera that dropped frames still
        recorded a 30 fps take, whose times say when each frame came). `RetargetError`
        when nothing was recorded."""
        frames, self._recording = self._recording, None
        if not frames:
            raise RetargetError("nothing was recorded: no frame was played while recording")
        points = np.stack([p for p, _ in frames])
        times = np.array([t for _, t in frames], dtype=np.float64)
        times -= times[0]
        if self.layout is None:
            names, layout = tuple(f"point_{i}" for i in range(self.n_points)), None
        else:
            names, layout = self.layout.point_names, self.layout.name
        return Take(points, names, float(fps), times=times, layout=layout, source=source)

    # -- inside -----------------------------------------------------------------------------

    def _fit(self, neutral) -> None:
        neutral = np.asarray(neutral)
        self._retargeter = Retargeter(self.kernel, smoothing=self.smoothing).fit(
            neutral, self.target_points)
        self.neutral_ = neutral
        self._driven = np.isfinite(neutral).all(axis=1)

    def _fitted(self) -> Retargeter:
        if self._retargeter is None:
            raise RetargetError("the performance has no neutral yet: set it, cue a take or push "
                                "frames first")
        return self._retargeter

    def _forget_neutral(self) -> None:
        self.neutral_ = self._retargeter = self._conditioner = self._captured = None

    def _frame(self, points, t: float, rotation) -> PerformanceFrame:
        points = np.asarray(points)
        d = self._fitted().displacements(points, mask=self.mask_)
        lost = self._driven & ~np.isfinite(points).all(axis=1)
        quaternion = None if rotation is None else Rotation.from_matrix(rotation).as_quat()
        return PerformanceFrame(d, lost, quaternion, float(t))

    def _record(self, points, t: float) -> None:
        frames = self._recording
        if frames is None or (frames and t - frames[0][1] > MAX_RECORD_SECONDS):
            return
        frames.append((np.array(points, dtype=np.float32), float(t)))


def take_clip(name: str, take: Take, target_points, layout: str, settings=None, *,
              regions=None) -> Clip:
    """A `Clip` of `take` retargeted onto the target as the app plays it
    (`Performance.play`).

    target_points : (N, 3) the target's feature points, mesh units, in `layout`'s order.
    layout : the target's layout name ("" is iBUG 68, as the app takes a project saved
        without one).
    settings : `ConditionSettings`, its dict form, or None for the defaults.
    regions : region, group or point names that move (partial retargeting), None for all.
    """
    return Performance(target_points, layout or "ibug68", settings, regions).play(take, name)


def _settings(settings) -> ConditionSettings:
    if isinstance(settings, ConditionSettings):
        return settings
    return ConditionSettings.from_dict(settings)
