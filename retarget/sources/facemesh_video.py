"""Markerless face tracking of a video file with the native face mesh
(`retarget.facemesh.tracker`): the ``retarget track --method markerless`` path.

OpenCV decodes the video (`retarget.sources.video.VideoReader`), the face mesh tracks each
frame in this process, and the layout's points are picked out of the 468 by its
``mediapipe468`` indices. Points and meta are those of the browser's tracker
(`retarget.sources.markerless`), which runs the same two models and agrees with this one
within 0.2 px median (``bench/facemesh.py``).
"""

from __future__ import annotations

import time
import warnings

import cv2
import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import LAYOUTS, Layout, get_layout
from retarget.sources.take import Take

__all__ = ["track_video_facemesh", "TRACKER", "check_max_frames", "face_mesh_take"]

TRACKER = "MediaPipe face mesh (legacy, 468 points) on LiteRT, models of @mediapipe/face_mesh 0.4.1633559619"


def track_video_facemesh(path, *, layout: str | Layout, progress=None, max_frames: int | None = None,
                         threads: int = 1) -> Take:
    """Track the face in a video file.

    path : a video file OpenCV can decode.
    layout : a layout name or a `Layout`; its `mediapipe468` indices pick its points.
    progress : optional ``progress(done, total)`` after each frame; total is the expected
        frame count (`max_frames` or the header's), None when unknown.
    max_frames : track at most this many frames from the start.
    threads : the models' inference threads (LiteRT's XNNPACK). One by default: a server
        job or a batch worker shares the machine with others; a command that has it to
        itself gives it its cores (0.44 ms a frame less on this 2-core machine with 2).

    Returns a `Take`: points (F, N, 3) float32 in pixels (x right, y up from the bottom
    edge, z toward the camera in the scale of x), a frame without a face all NaN; source
    "markerless"; meta: width, height, units, tracker, frames_with_face, face_share,
    fps_tracked (decoding and tracking; model loading is startup_s), truncated,
    fps_from_header, frames_claimed (the header's frame count, 0 when it states none). A
    video with no face in any frame warns (`RuntimeWarning`).

    Raises `RetargetError` for a missing or undecodable video or a bad `max_frames`.
    """
    lay = layout if isinstance(layout, Layout) else get_layout(layout)
    check_max_frames(max_frames)
    from retarget.facemesh.tracker import FaceMeshTracker
    from retarget.sources.video import VideoReader

    start = time.perf_counter()
    tracker = FaceMeshTracker(threads=threads)
    startup = time.perf_counter() - start
    indices = list(lay.mediapipe468)
    frames = []
    with VideoReader(path) as reader:
        width, height = reader.size
        claimed = reader.n_frames
        expected = claimed or None
        if max_frames is not None:
            expected = min(expected, int(max_frames)) if expected else int(max_frames)
        tracking = time.perf_counter()
        for _, frame in reader:
            points = tracker.track(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
            frames.append(np.full((lay.n_points, 3), np.nan, np.float32) if points is None else points[indices])
            if progress is not None:
                progress(len(frames), expected)
            if max_frames is not None and len(frames) == max_frames:
                break
        seconds = time.perf_counter() - tracking
        fps, fps_known = float(reader.fps), bool(reader.fps_known)
        truncated = bool(getattr(reader, "truncated", False))
    if not frames:
        raise RetargetError(f"{str(path)!r}: no frame could be decoded")
    take = face_mesh_take(path, np.stack(frames), lay, size=(width, height), fps=fps, fps_known=fps_known,
                          tracker=TRACKER, seconds=seconds, startup=startup, truncated=truncated)
    take.meta["frames_claimed"] = claimed
    return take


def check_max_frames(max_frames) -> None:
    """Refuse a `max_frames` that is not None or a positive integer."""
    if max_frames is not None and (isinstance(max_frames, bool) or not isinstance(max_frames, (int, np.integer))
                                   or max_frames < 1):
        raise RetargetError(f"max_frames must be a positive integer or None, got {max_frames!r}")


def face_mesh_take(path, points: np.ndarray, layout: Layout, *, size: tuple[int, int], fps: float,
                   fps_known: bool, tracker: str, seconds: float, startup: float, truncated: bool) -> Take:
    """The take of a face-mesh tracker (this one or the browser's) with its meta.

    points : (F, N, 3) float32, a frame without a face all NaN (a `RuntimeWarning` when
        every frame is); size : (width, height) of the video; seconds : decoding and
        tracking; startup : before the first frame (models, browser)."""
    count = len(points)
    faces = int(np.isfinite(points[:, 0, 0]).sum())
    if faces == 0:
        warnings.warn(f"markerless: no face found in any of the {count} frames of {str(path)!r}",
                      RuntimeWarning, stacklevel=3)
    meta = {
        "width": int(size[0]), "height": int(size[1]),
        "units": "px; x right, y up (origin bottom-left), z toward the camera in the scale of x",
        "tracker": tracker,
        "frames_with_face": faces,
        "face_share": faces / count,
        "fps_tracked": count / seconds if seconds > 0 else None,
        "startup_s": round(startup, 3),
        "truncated": truncated,
        "fps_from_header": fps_known,
    }
    return Take(points=points, names=layout.point_names, fps=fps,
                layout=layout.name if LAYOUTS.get(layout.name) == layout else None,
                source="markerless", meta=meta)
