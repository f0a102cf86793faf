"""Live stereo capture: colour markers tracked frame by frame, and a calibration built live.

Woodward et al. run two webcams live (§5): each new frame pair is searched for the
stickers near where the marker template last saw them, the matched pairs triangulated,
the rigid head motion removed on anchor markers (§5.1) and the points steadied by a
three-frame mean. `track_stereo_frames` does this for a whole recording; here every step
is causal, one frame pair in, that frame's points out, for a source that never ends:

- `LiveStereoTracker`: ``push(left, right, time) -> (N, 3)`` points of a layout in the
  head frame (NaN where lost);
- `LiveCalibration`: checkerboard views added as they come (``add_views``), a count of
  the good ones, and the `StereoCalibration` once there are enough (``calibrate``).

Unnamed stickers of one colour are `retarget.sources.stereo_live_stickers`'s.

3D points are in the calibration pattern's units (e.g. mm), in the left camera's frame
at the head pose of the frame the head frame was set up on.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import Layout, get_layout
from retarget.sources.calibration import (
    StereoCalibration,
    calibration_from_points,
    find_pattern,
    pattern_points,
)
from retarget.sources.color_markers import MarkerTemplate, color_blobs, layout_marker_colors
from retarget.sources.filters import TemporalMean
from retarget.sources.headpose import HeadMotionRemover, stable_indices
from retarget.sources.stereo import identified_markers

__all__ = ["LiveStereoTracker", "LiveCalibration", "MIN_CALIBRATION_VIEWS", "checked_pair"]

MIN_CALIBRATION_VIEWS = 10
"""Good view pairs `LiveCalibration.calibrate` asks for by default: fewer leave the
distortion and the principal point loosely pinned (see `calibration_from_points`)."""


class LiveStereoTracker:
    """A layout's colour markers followed live by a calibrated camera pair (Woodward §5).

    calibration : the pair's `StereoCalibration`; frames must be its size.
    layout : the points carrying stickers; colors (N,) their colours (default
        `layout_marker_colors(layout)`); anchors : head-frame points (indices or names,
        default `stable_indices(layout)`).
    temporal_window : frames of the causal mean (Woodward §5: 3; 1 = none).
    max_jump, hold : the marker templates' gate (px) and lost-marker hold (frames).
    max_epipolar : px; a pair further than this from its epipolar line (an identity
        swap in one camera) is lost for that frame.
    setup_frames : frames the automatic identification (`identified_markers`) may fail
        on (the performer not yet in view) before `push` raises.

    ``push(left, right, time)`` takes (H, W, 3) uint8 BGR images and the capture time
    (s, only checked to increase) and returns (N, 3) float32 points. Until the markers are
    identified and three anchors seen, every point is NaN. The head frame is that of the
    first frame with three anchors: each later frame is mapped into it by the rigid
    motion of the anchors seen so far (an anchor first seen later joins at its place in
    the head frame), holding the last pose while fewer than three are in view.
    After a call: ``identified_`` (the templates are set up), ``anchored_`` (the head
    frame is), ``frames_`` (pairs pushed).
    """

    def __init__(self, calibration: StereoCalibration, layout: Layout | str = "dutreve21", *,
                 colors: Sequence[str] | None = None, anchors: Sequence[int | str] | None = None,
                 temporal_window: int = 3, max_jump: float = 15.0, hold: int = 5,
                 max_epipolar: float = 3.0, setup_frames: int = 300):
        self.calibration = calibration
        self.layout = layout if isinstance(layout, Layout) else get_layout(layout)
        self.colors = tuple(colors) if colors is not None else layout_marker_colors(self.layout)
        if len(self.colors) != self.layout.n_points:
            raise RetargetError(f"colors must give {self.layout.n_points} colours for layout "
                                f"{self.layout.name!r}; got {len(self.colors)}")
        self.anchors = (stable_indices(self.layout) if anchors is None else
                        np.array([self.layout.index(a) if isinstance(a, str) else int(a) for a in anchors]))
        if self.anchors.size < 3:
            raise RetargetError(f"anchors must name at least 3 points; got {anchors!r}")
        self.palette = tuple(dict.fromkeys(self.colors))
        self.max_epipolar = float(max_epipolar)
        self.setup_frames = int(setup_frames)
        self._templates = [MarkerTemplate(self.layout.point_names, self.colors, max_jump=max_jump, hold=hold)
                           for _ in range(2)]
        self._mean = TemporalMean(temporal_window)
        self.identified_ = self.anchored_ = False
        self.frames_ = 0
        self._time = -np.inf
        self._head: HeadMotionRemover | None = None
        self.setup_error_ = ""

    def push(self, left: np.ndarray, right: np.ndarray, time: float) -> np.ndarray:
        """(N, 3) float32 head-frame points of this pair, after the temporal mean."""
        self._check(left, right, time)
        self.frames_ += 1
        lost = np.full((self.layout.n_points, 3), np.nan, np.float32)
        px = self._pixels(left, right)
        if px is None:
            return lost
        xyz = self.calibration.triangulate(px[0], px[1])
        xyz[self.calibration.epipolar_distances(px[0], px[1]) > self.max_epipolar] = np.nan
        stabilised = self._stabilised(xyz)
        return lost if stabilised is None else self._mean(stabilised)

    def _check(self, left, right, time) -> None:
        self._time = checked_pair(self.calibration, left, right, time, self._time)

    def _pixels(self, left, right):
        """(left (N, 2), right (N, 2)) marker pixels, None while not yet identified."""
        if self.identified_:
            return [t(color_blobs(img, self.palette)) for t, img in zip(self._templates, (left, right))]
        blobs = [color_blobs(left, self.palette), color_blobs(right, self.palette)]
        try:
            start_l, start_r, _, _ = identified_markers(self.calibration, *blobs, self.layout, self.colors,
                                                        max_epipolar=self.max_epipolar)
        except RetargetError as exc:
            # the performer may not be in view yet: try again on the next pairs
            self.setup_error_ = str(exc)
            if self.frames_ >= self.setup_frames:
                raise RetargetError(f"live stereo: no markers identified in {self.frames_} frame "
                                    f"pairs; the last try: {exc}") from None
            return None
        self.identified_ = True
        return [t.fit(b, s).positions_ for t, b, s in zip(self._templates, blobs, (start_l, start_r))]

    def _stabilised(self, xyz: np.ndarray) -> np.ndarray | None:
        """(N, 3) points in the head frame, None before it is set up (Woodward §5.1)."""
        seen = np.isfinite(xyz[self.anchors]).all(axis=1)
        if self._head is None:
            if seen.sum() < 3:
                return None
            neutral = np.full(xyz.shape, np.nan)
            neutral[self.anchors[seen]] = xyz[self.anchors[seen]]
            self._head = HeadMotionRemover(neutral, self.anchors)
            self.anchored_ = True
            return xyz.astype(np.float32)
        out = self._head(xyz)
        if not np.isfinite(self._head.rotation_).all():
            return None
        # an anchor seen for the first time joins at its place in the head frame
        new = self.anchors[seen & ~np.isin(self.anchors, self._head.stable)]
        if new.size and not self._head.held_:
            self._head.place(new, out[new])
        return out


def checked_pair(calibration: StereoCalibration, left, right, time, last: float) -> float:
    """`time` as a float once the pair is fit to track: both images (H, W, 3) uint8 BGR of
    the calibration's size, and `time` (s) finite and after `last`; else `RetargetError`."""
    want = tuple(calibration.size)
    for name, img in (("left", left), ("right", right)):
        if not (isinstance(img, np.ndarray) and img.dtype == np.uint8 and img.ndim == 3
                and img.shape[2] == 3):
            raise RetargetError(f"live stereo: the {name} image must be (H, W, 3) uint8 BGR")
        if img.shape[1::-1] != want:
            raise RetargetError(f"live stereo: the {name} image is {img.shape[1]}x{img.shape[0]}, "
                                f"the calibration is for {want[0]}x{want[1]}")
    if not np.isfinite(time) or time <= last:
        raise RetargetError(f"live stereo: capture times must increase; got {time!r} after {last!r}")
    return float(time)


class LiveCalibration:
    """A stereo calibration built from checkerboard views as they come (Woodward §3).

    pattern : ``("checkerboard", cols, rows, square)`` and the like (`pattern_points`);
        its square's unit becomes the unit of every 3D point.
    size : (width, height) px of both cameras' images.
    min_views : good views `calibrate` needs; max_views : views kept (later ones refused).
    min_move : px; a view whose corners moved less than this (mean) from the last good
        view adds nothing (the board held still) and is not counted.

    ``add_views(left, right) -> bool``: True when the pattern was found whole in both
    images (and moved); ``count`` the good views so far; ``calibrate()`` the
    `StereoCalibration` (`RetargetError` below `min_views`).
    """

    def __init__(self, pattern, size: tuple[int, int], *, min_views: int = MIN_CALIBRATION_VIEWS,
                 max_views: int = 60, min_move: float = 10.0):
        self.pattern = tuple(pattern)
        self.points = pattern_points(self.pattern)  # checks the pattern
        self.size = (int(size[0]), int(size[1]))
        if min_views < 3 or max_views < min_views:
            raise RetargetError(f"min_views must be >= 3 and <= max_views; got {min_views}, {max_views}")
        self.min_views, self.max_views, self.min_move = int(min_views), int(max_views), float(min_move)
        self._left: list[np.ndarray] = []
        self._right: list[np.ndarray] = []

    @property
    def count(self) -> int:
        """Good view pairs so far."""
        return len(self._left)

    def add_views(self, left: np.ndarray, right: np.ndarray) -> bool:
        """Whether this pair of (H, W, 3) uint8 BGR images is a new good view."""
        for name, img in (("left", left), ("right", right)):
            if img.shape[1::-1] != self.size:
                raise RetargetError(f"calibration: the {name} image is {img.shape[1]}x{img.shape[0]}, "
                                    f"the cameras are {self.size[0]}x{self.size[1]}")
        if self.count >= self.max_views:
            return False
        found_l = find_pattern(left, self.pattern)
        found_r = find_pattern(right, self.pattern) if found_l is not None else None
        if found_r is None:
            return False
        if self.pattern[0] != "acircles" and np.dot(found_l[-1] - found_l[0], found_r[-1] - found_r[0]) < 0:
            found_r = found_r[::-1]  # the detectors started from opposite ends of the board
        if self._left and np.linalg.norm(found_l - self._left[-1], axis=1).mean() < self.min_move:
            return False
        self._left.append(found_l)
        self._right.append(found_r)
        return True

    def calibrate(self) -> StereoCalibration:
        """The pair's calibration from the good views (`calibration_from_points`)."""
        if self.count < self.min_views:
            raise RetargetError(f"calibration: {self.count} good views of the board so far; "
                                f"{self.min_views} are needed")
        meta = {"pattern": list(self.pattern), "source": "live"}
        return calibration_from_points(self.points, np.stack(self._left), np.stack(self._right),
                                       self.size, meta)
