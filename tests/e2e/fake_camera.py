"""Y4M files for Chromium's fake camera (`--use-file-for-fake-video-capture=FILE.y4m`).

Chromium reads a YUV4MPEG2 file (4:2:0 planar) as its camera and loops it at the header's
frame rate; the tests and bench/webcam_latency.py write the file from frames they choose.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from retarget.sources.video import VideoReader


def write_y4m(path: Path, frames_bgr, fps: int) -> Path:
    """Write `frames_bgr` (each (H, W, 3) uint8 BGR, H and W even) as a 4:2:0 Y4M file at
    `fps` frames per second; the path."""
    frames = list(frames_bgr)
    if not frames:
        raise ValueError("write_y4m: no frames")
    h, w = frames[0].shape[:2]
    if h % 2 or w % 2:
        raise ValueError(f"write_y4m: 4:2:0 needs an even frame size; got {w}x{h}")
    with open(path, "wb") as out:
        out.write(f"YUV4MPEG2 W{w} H{h} F{int(fps)}:1 Ip A1:1 C420jpeg\n".encode())
        for frame in frames:
            if frame.shape != (h, w, 3) or frame.dtype != np.uint8:
                raise ValueError(f"write_y4m: every frame must be ({h}, {w}, 3) uint8; got "
                                 f"{frame.shape} {frame.dtype}")
            out.write(b"FRAME\n")
            out.write(cv2.cvtColor(frame, cv2.COLOR_BGR2YUV_I420).tobytes())
    return Path(path)


def stereo_loop_y4m(path: Path, pairs, fps: int) -> Path:
    """Write the (left, right) BGR image `pairs` as one camera's Y4M file, the two views side
    by side in each frame, played forth and back (the camera loops the file, and a jump
    from the last frame's expression to the first's would be no performer's motion); the
    path."""
    frames = [np.hstack(pair) for pair in pairs]
    return write_y4m(path, frames + frames[-2:0:-1], fps)


def video_frames(video: Path, n_frames: int, size: int | None = None) -> list[np.ndarray]:
    """The first `n_frames` frames of `video` as (H, W, 3) uint8 BGR, resized to
    `size` x `size` pixels when given (area interpolation)."""
    frames = []
    with VideoReader(video) as reader:
        for i, frame in reader:
            if i >= n_frames:
                break
            frames.append(frame if size is None else cv2.resize(frame, (size, size), interpolation=cv2.INTER_AREA))
    return frames


def checkerboard(size: int = 240, square: int = 30) -> np.ndarray:
    """(size, size, 3) uint8 BGR grey-and-white checkerboard: a camera that sees no face."""
    yy, xx = np.mgrid[:size, :size] // square
    grey = np.where((yy + xx) % 2 == 0, 230, 60).astype(np.uint8)
    return np.repeat(grey[:, :, None], 3, axis=2)
