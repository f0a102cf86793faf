"""Performance sources that feed a project's stream.

`DemoSource` is the built-in performance: a second procedural identity
(`retarget.sample_face`) performing `demo_weights`, retargeted every frame onto the
project's own landmarks by the library's `Retargeter`, so a rigged project moves without
a webcam or a file. The server only schedules it and encodes what the library returns.
"""

from __future__ import annotations

import asyncio
from functools import lru_cache

import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.pipeline import Retargeter
from retarget.sample_face import demo_weights, sample_face
from server.hub import StreamHub
from server.stream_codec import encode_frame

# The performer differs from the built-in target face so the demo really retargets.
_PERFORMER_IDENTITY = np.array([1.2, -0.8, 0.9, 0.6, -0.7])
DEMO_SECONDS = 10.0


class DemoSource:
    """The demo performance for one project.

    target_points : (N, 3) the project's landmark positions, in its layout's order.
    layout : the project's layout name (the performer's points are picked through the
        layout's iBUG-68 indices; regions for masks). Projects saved without a layout
        are taken as iBUG 68.
    """

    def __init__(self, target_points: np.ndarray, layout: str, fps: float = 60.0):
        self.layout = get_layout(layout or "ibug68")
        if target_points.shape != (self.layout.n_points, 3):
            raise RetargetError(
                f"the demo performance drives the {self.layout.n_points} points of layout "
                f"{self.layout.name!r}; this project has {len(target_points)} landmarks")
        if not 1.0 <= fps <= 240.0:
            raise RetargetError(f"fps must be between 1 and 240; got {fps}")
        neutral68, frames68 = _performance68(float(fps))
        ibug = list(self.layout.ibug68)
        self.neutral, self.frames = neutral68[ibug], frames68[:, ibug]
        self.target_points = target_points
        self.fps = float(fps)
        self.set_regions(None)

    def set_regions(self, regions) -> None:
        """Partial retargeting: only the named regions/groups/points move (None: all)."""
        mask = self.layout.region_mask(regions) if regions else None
        self.retargeter = Retargeter(mask=mask).fit(self.neutral, self.target_points)

    def displacements(self, index: int) -> np.ndarray:
        """(N, 3) float32 target feature displacements of frame `index` (looping)."""
        return self.retargeter.displacements(self.frames[index % len(self.frames)])

    async def run(self, hub: StreamHub, project_id: str) -> None:
        """Publish frames at `fps` until cancelled or the last viewer leaves."""
        loop = asyncio.get_running_loop()
        start, index = loop.time(), 0
        while hub.viewer_count(project_id):
            # after a stall, jump to the frame that is due now: a live source skips the
            # frames it missed rather than publishing a burst of stale ones
            index = max(index, int((loop.time() - start) * self.fps))
            frame = encode_frame(self.displacements(index), frame_index=index,
                                 source_time=index / self.fps)
            hub.publish(project_id, frame)
            index += 1
            await asyncio.sleep(max(0.0, start + index / self.fps - loop.time()))


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
