"""`VideoReader`: frames of a video file through OpenCV, with precise errors for bad files.

Opening checks what can be checked up front (the file exists, OpenCV can open it, it
decodes at least one frame) and raises `RetargetError` naming the file and the problem.
A file that stops decoding before the frame count its header promises is not an error:
the frames read so far are kept, and `truncated` says so after the iteration.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from retarget.errors import RetargetError
from retarget.sources.take import DEFAULT_FPS

__all__ = ["VideoReader"]


class VideoReader:
    """Sequential reader of one video file.

    path : the video (anything OpenCV's FFmpeg backend decodes).

    Attributes
    ----------
    fps : float, the container's frame rate, `DEFAULT_FPS` when it states none
        (`fps_known` is then False).
    n_frames : int, the frame count the container claims; 0 when it does not say.
    size : (width, height) in pixels, from the first decoded frame.
    frames_read : int, frames yielded so far.
    truncated : bool, after a full iteration: decoding stopped before the `n_frames` the
        header claims (a cut-off or damaged file); the frames before stay valid.

    Iterating yields ``(index, frame)`` with frame a (height, width, 3) uint8 BGR array;
    a reader is iterated once. Use as a context manager, or call `close`.
    """

    def __init__(self, path: str | Path) -> None:
        import cv2

        self.path = Path(path)
        if not self.path.exists():
            raise RetargetError(f"video file {self.path} does not exist")
        if not self.path.is_file():
            raise RetargetError(f"video path {self.path} is not a file")
        if self.path.stat().st_size == 0:
            raise RetargetError(f"video file {self.path} is empty (0 bytes)")
        self._cap = cv2.VideoCapture(str(self.path), cv2.CAP_FFMPEG)
        if not self._cap.isOpened():
            self._cap.release()
            raise RetargetError(
                f"{self.path} is not a video OpenCV can open (unknown format, or a damaged or "
                "cut-off file: an MP4 whose index was never written cannot be read)")
        fps = self._cap.get(cv2.CAP_PROP_FPS)
        self.fps_known = bool(np.isfinite(fps) and 0 < fps < 1000)
        self.fps = float(fps) if self.fps_known else DEFAULT_FPS
        count = self._cap.get(cv2.CAP_PROP_FRAME_COUNT)
        self.n_frames = int(count) if np.isfinite(count) and count > 0 else 0
        ok, first = self._cap.read()
        if not ok or first is None:
            self._cap.release()
            claim = f"its header claims {self.n_frames}" if self.n_frames else "its header claims none"
            raise RetargetError(f"{self.path} has no decodable video frames ({claim})")
        self._first = _bgr(first)
        self.size = (self._first.shape[1], self._first.shape[0])
        self.frames_read = 0
        self.truncated = False
        self._started = False

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        if self._started:
            raise RetargetError(f"{self.path}: a VideoReader is iterated once; open a new one")
        self._started = True
        return self._frames()

    def _frames(self) -> Iterator[tuple[int, np.ndarray]]:
        frame, self._first = self._first, None
        try:
            while frame is not None:
                yield self.frames_read, frame
                self.frames_read += 1
                ok, raw = self._cap.read()
                frame = _bgr(raw) if ok and raw is not None else None
                if frame is None:
                    self.truncated = self.frames_read < self.n_frames
                if frame is not None and frame.shape[1::-1] != self.size:
                    raise RetargetError(
                        f"{self.path}: frame {self.frames_read} is {frame.shape[1]}x{frame.shape[0]}, "
                        f"the video started at {self.size[0]}x{self.size[1]}")
        finally:
            self.close()

    def close(self) -> None:
        """Release the decoder (idempotent)."""
        self._cap.release()

    def __enter__(self) -> VideoReader:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _bgr(frame: np.ndarray) -> np.ndarray:
    """(h, w, 3) uint8 BGR from what OpenCV decoded (grey or BGRA frames converted)."""
    if frame.ndim == 2:
        return np.repeat(frame[..., None], 3, 2)
    if frame.shape[2] == 4:
        return np.ascontiguousarray(frame[..., :3])
    return frame
