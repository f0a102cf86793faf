"""Players: the performances that feed a project's stream, scheduled and published.

Each player holds one `retarget.performance.Performance` (conditioning, retargeting, the
regions' mask, recording: all the library's) and only decides which frame is due when,
encodes it (`server.wire`) and publishes it to the project's viewers (`server.hub`):

- `DemoPlayer`: the built-in performance (`retarget.sample_face.demo_points`, another
  identity performing a looping expression track), so a rigged project moves without a
  webcam or a file;
- `TakePlayer`: a stored take replayed at its own frame times (looping or not);
- `LivePlayer`: points pushed by the browser (its webcam tracker) over the WebSocket,
  retargeted as they arrive.

Every player can record what it plays into a take (`Performance.start_recording`). A
project saved without a layout is played as iBUG 68.

Every player plays by feature points (RTDF frames of displacements) or, given a
`retarget.muscles.drive.MuscleDrive` (`set_drive`), by muscles: each frame's feature
displacements solved into contractions and read as an expression (RTMC frames; the page
plays the muscles); or, given a `retarget.arkit.drive.ArkitDrive`, by ARKit's 52
blendshapes: each frame's feature displacements solved into the 52 weights (RTAW frames;
the page plays the shapes, other tools read the curves). A drive keeps its own warm
start, so it belongs to one player.
"""

from __future__ import annotations

import asyncio

import numpy as np

from retarget.arkit.drive import ArkitDrive
from retarget.errors import RetargetError
from retarget.muscles.drive import MuscleDrive
from retarget.performance import Performance, PerformanceFrame
from retarget.sample_face import demo_points
from retarget.sources.conditioning import ConditionSettings
from retarget.sources.take import Take
from server.hub import StreamHub
from server.wire import FLAG_LAST, FLAG_LOST_POINTS, encode_arkit_weights, encode_contractions, encode_frame

__all__ = ["DemoPlayer", "LivePlayer", "TakePlayer"]


class _Player:
    """What every player shares: its performance, its frame rate, recording and encoding."""

    kind = ""

    def __init__(self, performance: Performance, fps: float):
        if not 1.0 <= fps <= 240.0:
            raise RetargetError(f"fps must be between 1 and 240; got {fps}")
        self.performance = performance
        self.fps = float(fps)
        self.drive: MuscleDrive | ArkitDrive | None = None

    def set_drive(self, drive: MuscleDrive | ArkitDrive | None) -> None:
        """Drive by these muscles or ARKit shapes from the next frame on (None: by feature
        points)."""
        self.drive = drive

    def set_regions(self, regions) -> None:
        """Partial retargeting: only the named regions/groups/points move (None: all)."""
        self.performance.set_regions(regions)

    @property
    def recording(self) -> int | None:
        """Frames recorded so far, None when not recording."""
        return self.performance.recording

    def start_recording(self) -> None:
        self.performance.start_recording()

    def stop_recording(self) -> Take:
        """The recorded raw frames as a take in the project's layout."""
        return self.performance.stop_recording(source=self.kind, fps=self.fps)

    def encode(self, frame: PerformanceFrame, index: int, *, last: bool = False) -> bytes:
        """The stream frame of `frame`, number `index`; `last` marks the player's final one."""
        flags = (FLAG_LOST_POINTS if frame.lost.any() else 0) | (FLAG_LAST if last else 0)
        if isinstance(self.drive, ArkitDrive):
            return encode_arkit_weights(self.drive.weights(frame.displacements, frame.lost), frame_index=index % 2**32,
                                        source_time=frame.time, flags=flags, head_rotation=frame.head_rotation)
        if self.drive is not None:
            return encode_contractions(self.drive.frame(frame.displacements, frame.lost), frame_index=index % 2**32,
                                       source_time=frame.time, flags=flags, head_rotation=frame.head_rotation)
        return encode_frame(frame.displacements, frame_index=index % 2**32, source_time=frame.time,
                            flags=flags, head_rotation=frame.head_rotation)

    def describe(self) -> dict:
        return {"source": self.kind, "fps": self.fps, "recording": self.recording is not None,
                "drive": ("points" if self.drive is None else
                          "arkit" if isinstance(self.drive, ArkitDrive) else "muscles")}


class DemoPlayer(_Player):
    """The demo performance for one project at `fps`, looping."""

    kind = "demo"

    def __init__(self, target_points: np.ndarray, layout: str, fps: float = 60.0):
        performance = Performance(target_points, layout or "ibug68")
        super().__init__(performance, fps)
        neutral, self.frames = demo_points(performance.layout, float(fps))
        performance.set_neutral(neutral)

    def displacements(self, index: int) -> np.ndarray:
        """(N, 3) float32 target feature displacements of frame `index` (looping)."""
        return self.performance.displacements(self.frames[index % len(self.frames)])

    def frame(self, index: int) -> bytes:
        frame = self.performance.frame(self.frames[index % len(self.frames)], index / self.fps)
        return self.encode(frame, index)

    async def run(self, hub: StreamHub, project_id: str) -> None:
        """Publish frames at `fps` until cancelled or the last viewer leaves."""
        await _play(hub, project_id, n_frames=None, frame=self.frame,
                    time_of=lambda i: i / self.fps)


class TakePlayer(_Player):
    """A stored take replayed through its performance.

    take : the (trimmed) take; its point names are matched to the project's layout by name.
    settings : `ConditionSettings` (neutral, head pose, filter, gain).
    loop : start again after the last frame; else hold the last frame and end.
    """

    kind = "take"

    def __init__(self, target_points, layout, take: Take, settings: ConditionSettings,
                 *, loop: bool = True, take_id: str = ""):
        super().__init__(Performance(target_points, layout or "ibug68"),
                         min(max(take.fps, 1.0), 240.0))
        self.take = take
        self.loop = bool(loop)
        self.take_id = take_id
        self.set_settings(settings)

    def set_settings(self, settings: ConditionSettings) -> None:
        """Condition the take anew; a refused change keeps the take playing as it was."""
        self.cue = self.performance.cue(self.take, settings)

    def frame(self, index: int) -> bytes:
        n = self.cue.n_frames
        i = index % n
        t = float(self.cue.times[i]) + index // n * self.duration
        frame = self.performance.frame(self.cue.points[i], t, rotation=self.cue.rotation(i),
                                       raw=self.cue.raw[i])
        return self.encode(frame, index, last=not self.loop and index == n - 1)

    @property
    def duration(self) -> float:
        """Seconds of one pass, a frame period after the last frame's time."""
        return float(self.cue.times[-1]) + 1.0 / self.fps

    async def run(self, hub: StreamHub, project_id: str) -> None:
        n = self.cue.n_frames
        await _play(hub, project_id, n_frames=None if self.loop else n, frame=self.frame,
                    time_of=lambda i: float(self.cue.times[i % n]) + (i // n) * self.duration)

    def describe(self) -> dict:
        return {**super().describe(), "take": self.take_id, "loop": self.loop,
                "frames": self.cue.n_frames, "duration": self.duration}


class LivePlayer(_Player):
    """Points pushed by a viewer (the browser's tracker), published as they arrive.

    dims : 2 or 3, what the browser sends. The neutral is captured from the first frames
    (per the settings); `recapture()` starts a new capture.
    """

    kind = "live"

    def __init__(self, target_points, layout, settings: ConditionSettings, *, dims: int = 3,
                 fps: float = 30.0):
        super().__init__(Performance(target_points, layout or "ibug68", settings, dims=dims), fps)
        self.hub = self.project_id = None

    def set_settings(self, settings: ConditionSettings) -> None:
        """New conditioning; a captured neutral is kept unless the neutral mode changes."""
        self.performance.set_settings(settings)

    def recapture(self) -> None:
        """Capture the neutral again from the next frames."""
        self.performance.recapture()

    def push(self, points: np.ndarray, t: float, index: int) -> None:
        """One tracked frame: (N, dims) points in layout order (NaN rows lost), `t` its
        capture time in seconds, `index` the tracker's frame number (kept in the
        published frame). Publishes the retargeted frame to every viewer."""
        frame = self.performance.push(points, t)
        if frame is not None and self.hub is not None:
            self.hub.publish(self.project_id, self.encode(frame, index))

    async def run(self, hub: StreamHub, project_id: str) -> None:
        self.hub, self.project_id = hub, project_id
        try:
            await asyncio.Event().wait()  # frames arrive through push()
        finally:
            self.hub = None

    def describe(self) -> dict:
        return {**super().describe(), "dims": self.performance.dims,
                "neutral": self.performance.neutral_ is not None}


async def _play(hub: StreamHub, project_id: str, *, n_frames, frame, time_of) -> None:
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
