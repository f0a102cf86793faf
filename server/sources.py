"""Performance sources that feed a project's stream.

Every source ends in the same library calls: source points in the project's layout order
-> `retarget.sources.conditioning` (neutral, head pose, jitter filter, gain) ->
`retarget.pipeline.Retargeter` -> displacements, encoded by `server.wire`. The
server only schedules them:

- `DemoSource`: the built-in performance, a second procedural identity
  (`retarget.sample_face`) performing `demo_weights`, so a rigged project moves without a
  webcam or a file;
- `TakeSource`: a stored take replayed at its own frame times (looping or not);
- `LiveSource`: points pushed by the browser (its webcam tracker) over the WebSocket,
  retargeted as they arrive.

Every source can record what it plays into a take: the raw source points (before
conditioning, so a recording can be conditioned again on replay) at their source times.

A source whose points are a subset of the project's layout (21 markers on a 68-point
project) drives the other joints by interpolation (see `retarget.pipeline`).
"""

from __future__ import annotations

import asyncio
from functools import lru_cache

import numpy as np
from scipy.spatial.transform import Rotation

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.pipeline import Retargeter
from retarget.sample_face import demo_weights, sample_face
from retarget.sources.conditioning import ConditionSettings, SourceConditioner, condition_take
from retarget.sources.take import Take
from server.hub import StreamHub
from server.wire import FLAG_LAST, FLAG_LOST_POINTS, encode_frame

# The performer differs from the built-in target face so the demo really retargets.
_PERFORMER_IDENTITY = np.array([1.2, -0.8, 0.9, 0.6, -0.7])
DEMO_SECONDS = 10.0
MAX_RECORD_SECONDS = 600.0


class _Retargeted:
    """What every source shares: the project's layout and landmarks, the retargeter for
    the current neutral and regions, and the frame encoder."""

    kind = ""

    def __init__(self, target_points: np.ndarray, layout: str, fps: float):
        self.layout = get_layout(layout or "ibug68")
        if target_points.shape != (self.layout.n_points, 3):
            raise RetargetError(
                f"layout {self.layout.name!r} has {self.layout.n_points} points; this project "
                f"has {len(target_points)} landmarks")
        if not 1.0 <= fps <= 240.0:
            raise RetargetError(f"fps must be between 1 and 240; got {fps}")
        self.target_points = target_points
        self.fps = float(fps)
        self.regions = None
        self.neutral = None
        self.retargeter = None
        self.recording: list | None = None

    def set_regions(self, regions) -> None:
        """Partial retargeting: only the named regions/groups/points move (None: all)."""
        mask = self.layout.region_mask(regions) if regions else None  # refuses unknown names
        self.regions = regions
        if self.neutral is not None:
            self.retargeter = Retargeter(mask=mask).fit(self.neutral, self.target_points)

    def set_neutral(self, neutral: np.ndarray) -> None:
        """(N, D) neutral source points in layout order (NaN rows: points the source lacks)."""
        self.neutral = neutral
        self.driven = np.isfinite(neutral).all(axis=1)
        self.set_regions(self.regions)

    def encode(self, points: np.ndarray, index: int, t: float, rotation=None, *, last=False) -> bytes:
        """The stream frame for (N, D) conditioned source points; rotation (3, 3) or None;
        `last` marks the source's final frame."""
        d = self.retargeter.displacements(points)
        lost = bool((~np.isfinite(points[self.driven]).all(axis=1)).any())
        quaternion = None if rotation is None else Rotation.from_matrix(rotation).as_quat()
        flags = (FLAG_LOST_POINTS if lost else 0) | (FLAG_LAST if last else 0)
        return encode_frame(d, frame_index=index % 2**32, source_time=t, flags=flags,
                            head_rotation=quaternion)

    def start_recording(self) -> None:
        self.recording = []

    def record(self, points: np.ndarray, t: float) -> None:
        """Keep (N, D) raw source points played at source time `t` s, while recording;
        a recording keeps its first `MAX_RECORD_SECONDS` (what comes later is not kept,
        rather than failing the source mid-performance)."""
        if self.recording is None or (self.recording and t - self.recording[0][1] > MAX_RECORD_SECONDS):
            return
        self.recording.append((np.array(points, dtype=np.float32), float(t)))

    def stop_recording(self) -> Take:
        """The recorded raw frames as a take in the project's layout."""
        frames, self.recording = self.recording, None
        if not frames:
            raise RetargetError("nothing was recorded: no frame was played while recording")
        points = np.stack([p for p, _ in frames])
        times = np.array([t for _, t in frames], dtype=np.float64)
        times -= times[0]
        fps = (len(times) - 1) / times[-1] if times[-1] > 0 else self.fps
        return Take(points, self.layout.point_names, float(fps), times=times,
                    layout=self.layout.name, source=self.kind)

    def describe(self) -> dict:
        return {"source": self.kind, "fps": self.fps, "recording": self.recording is not None}


class DemoSource(_Retargeted):
    """The demo performance for one project (see the module docstring). Projects saved
    without a layout are taken as iBUG 68."""

    kind = "demo"

    def __init__(self, target_points: np.ndarray, layout: str, fps: float = 60.0):
        super().__init__(target_points, layout, fps)
        neutral68, frames68 = _performance68(float(fps))
        ibug = list(self.layout.ibug68)
        self.frames = frames68[:, ibug]
        self.set_neutral(neutral68[ibug])

    def displacements(self, index: int) -> np.ndarray:
        """(N, 3) float32 target feature displacements of frame `index` (looping)."""
        return self.retargeter.displacements(self.frames[index % len(self.frames)])

    def frame(self, index: int) -> bytes:
        self.record(self.frames[index % len(self.frames)], index / self.fps)
        return encode_frame(self.displacements(index), frame_index=index, source_time=index / self.fps)

    async def run(self, hub: StreamHub, project_id: str) -> None:
        """Publish frames at `fps` until cancelled or the last viewer leaves."""
        await _play(self, hub, project_id, n_frames=None, frame=self.frame,
                    time_of=lambda i: i / self.fps)


class TakeSource(_Retargeted):
    """A stored take replayed through conditioning and retargeting.

    take : the (trimmed) take; its point names are matched to the project's layout by
        name (a subset drives the rest by interpolation).
    settings : `ConditionSettings` (neutral, head pose, filter, gain).
    loop : start again after the last frame; else hold the last frame and end.
    """

    kind = "take"

    def __init__(self, target_points, layout, take: Take, settings: ConditionSettings,
                 *, loop: bool = True, take_id: str = ""):
        super().__init__(target_points, layout, min(max(take.fps, 1.0), 240.0))
        self.take = take.to_layout(self.layout.name, partial=True)
        self.loop = bool(loop)
        self.take_id = take_id
        self.set_settings(settings)

    def set_settings(self, settings: ConditionSettings) -> None:
        conditioned, neutral, rotations = condition_take(self.take, settings, with_rotations=True)
        self.settings = settings
        self.points = conditioned.points
        self.times = conditioned.frame_times() - conditioned.frame_times()[0]
        self.rotations = rotations if settings.apply_rotation else None
        self.set_neutral(neutral)

    def frame(self, index: int) -> bytes:
        i = index % len(self.points)
        t = float(self.times[i]) + index // len(self.points) * self.duration
        rotation = None if self.rotations is None else self.rotations[i]
        self.record(self.take.points[i], t)
        last = not self.loop and index == len(self.points) - 1
        return self.encode(self.points[i], index, t, rotation, last=last)

    @property
    def duration(self) -> float:
        """Seconds of one pass, a frame period after the last frame's time."""
        return float(self.times[-1]) + 1.0 / self.fps

    async def run(self, hub: StreamHub, project_id: str) -> None:
        n = len(self.points)
        await _play(self, hub, project_id, n_frames=None if self.loop else n, frame=self.frame,
                    time_of=lambda i: float(self.times[i % n]) + (i // n) * self.duration)

    def describe(self) -> dict:
        return {**super().describe(), "take": self.take_id, "loop": self.loop,
                "frames": len(self.points), "duration": self.duration}


class LiveSource(_Retargeted):
    """Points pushed by a viewer (the browser's tracker), retargeted as they arrive.

    dims : 2 or 3, what the browser sends. The neutral is captured by the conditioner
    (the first seconds, by default); `recapture()` starts a new capture.
    """

    kind = "live"

    def __init__(self, target_points, layout, settings: ConditionSettings, *, dims: int = 3,
                 fps: float = 30.0):
        super().__init__(target_points, layout, fps)
        if dims not in (2, 3):
            raise RetargetError(f"live points must be 2D or 3D; got dims {dims!r}")
        self.dims = dims
        self.hub = self.project_id = None
        self.set_settings(settings)

    def set_settings(self, settings: ConditionSettings) -> None:
        """New conditioning; a neutral already captured is kept unless the new settings
        choose the neutral another way than the old ones."""
        old = getattr(self, "settings", None)
        keep = self.neutral is not None and old is not None and old.neutral == settings.neutral
        self.settings = settings
        if keep:
            given = ConditionSettings.from_dict({**settings.to_dict(), "neutral": {"mode": "given"}})
            self.conditioner = SourceConditioner(self.layout.name, self.dims, given,
                                                 neutral=self.conditioner.neutral_)
        else:
            self.neutral = self.retargeter = None
            self.conditioner = SourceConditioner(self.layout.name, self.dims, settings)

    def recapture(self) -> None:
        """Capture the neutral again from the next frames."""
        self.neutral = self.retargeter = None
        self.conditioner = SourceConditioner(self.layout.name, self.dims, self.settings)

    def push(self, points: np.ndarray, t: float, index: int) -> None:
        """One tracked frame: (N, dims) points in layout order (NaN rows lost), `t` its
        capture time in seconds, `index` the tracker's frame number (kept in the
        published frame). Publishes the retargeted frame to every viewer."""
        if points.shape != (self.layout.n_points, self.dims):
            raise RetargetError(f"live frame must hold {self.layout.n_points} points of "
                                f"{self.dims} coordinates; got {points.shape}")
        self.record(points, t)
        conditioned = self.conditioner.push(points, t)
        if conditioned is None:
            return  # still capturing the neutral
        if self.retargeter is None:
            self.set_neutral(self.conditioner.neutral_)
        rotation = self.conditioner.rotation_ if self.settings.apply_rotation else None
        if self.hub is not None:
            self.hub.publish(self.project_id, self.encode(conditioned, index, t, rotation))

    async def run(self, hub: StreamHub, project_id: str) -> None:
        self.hub, self.project_id = hub, project_id
        try:
            await asyncio.Event().wait()  # frames arrive through push()
        finally:
            self.hub = None

    def describe(self) -> dict:
        return {**super().describe(), "dims": self.dims, "neutral": self.neutral is not None}


async def _play(source, hub: StreamHub, project_id: str, *, n_frames, frame, time_of) -> None:
    """Publish ``frame(i)`` at ``time_of(i)`` seconds after the start, until cancelled,
    the last viewer leaves or `n_frames` frames are played (None: forever)."""
    loop = asyncio.get_running_loop()
    start, index = loop.time(), 0
    while hub.viewer_count(project_id) and (n_frames is None or index < n_frames):
        # after a stall, jump to the frame that is due now: a live source skips the frames
        # it missed rather than publishing a burst of stale ones
        now = loop.time() - start
        while time_of(index + 1) <= now and (n_frames is None or index + 1 < n_frames):
            index += 1
        hub.publish(project_id, frame(index))
        index += 1
        if n_frames is None or index < n_frames:
            await asyncio.sleep(max(0.0, start + time_of(index) - loop.time()))


@lru_cache(maxsize=4)
def _performance68(fps: float) -> tuple[np.ndarray, np.ndarray]:
    """The performer's 68 landmarks: neutral (68, 3) and the looping performance
    (F, 68, 3) at `fps`, built once per fps (generating the performer takes ~0.7 s)."""
    performer = sample_face(identity=_PERFORMER_IDENTITY)
    lm = np.asarray(performer.landmarks68)
    weights = demo_weights(int(round(DEMO_SECONDS * fps)), fps)
    neutral = performer.vertices[lm]
    frames = neutral + np.tensordot(weights, performer.expressions[:, lm], axes=1)
    neutral.flags.writeable = frames.flags.writeable = False  # shared by every source
    return neutral, frames
