"""MediaPipe's legacy face-mesh graph (``face_landmark_front_cpu``), re-implemented around
the two LiteRT models: 468 points a frame, at about a millisecond a frame on one core.

A frame is searched by the face detector (`retarget.facemesh.detector`) only while no face
is being tracked; otherwise the region of interest (ROI) comes from the previous frame's
points. Each ROI is a rotated square, as MediaPipe builds it: centred on the bounding
box of the detection (or of the previous points), turned so that the eye line is level
(detector keypoints 0 -> 1, or points 33 -> 263), its side 1.5 times the box's longer
side. The square is resampled to the landmark model's 192 x 192 input (values 0..1,
edges replicated); the model gives 468 points in that square and a face-presence logit,
and the points are carried back into the frame. When presence drops below 0.5, the frame
has no face and the next frame is searched again.

Coordinates: the project's convention for tracked points (`retarget.sources.markerless`
and the page's FaceMeshTracker.js): pixels, x right, y up from the frame's bottom edge, z
toward the camera in the same pixel scale; continuous coordinates (pixel i spans i..i+1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from retarget.facemesh.assets import model_interpreter
from retarget.facemesh.detector import Detection, FaceDetector

__all__ = ["FaceMeshTracker", "Roi", "N_POINTS"]

N_POINTS = 468
INPUT = 192
ROI_SCALE = 1.5
MIN_PRESENCE = 0.5
EYE_LINE = (33, 263)  # the outer corners of the person's right and left eye


@dataclass(frozen=True)
class Roi:
    """A rotated square of the frame (pixels, y down): centre (2,), side, and the angle
    (radians) of its x axis from the frame's x axis, toward +y."""

    centre: np.ndarray
    side: float
    angle: float

    @classmethod
    def around(cls, lo: np.ndarray, hi: np.ndarray, start: np.ndarray, end: np.ndarray) -> "Roi":
        """MediaPipe's DetectionsToRects + RectTransformation: the box lo..hi (2,) each,
        levelled along start -> end, scaled by `ROI_SCALE` about its centre, squared on its
        longer side."""
        direction = end - start
        return cls(centre=(lo + hi) / 2, side=float(ROI_SCALE * np.max(hi - lo)),
                   angle=float(np.arctan2(direction[1], direction[0])))

    def axes(self) -> np.ndarray:
        """(2, 2): the square's x and y axes as columns, frame pixels per unit side."""
        c, s = np.cos(self.angle), np.sin(self.angle)
        return self.side * np.array([[c, -s], [s, c]])


class FaceMeshTracker:
    """`track(rgb) -> (468, 3) float32 or None`, frame after frame of one video."""

    def __init__(self, threads: int = 1):
        self.detector = FaceDetector(threads=threads)
        self._interpreter, outputs = model_interpreter("face_landmark.tflite", threads)
        self._input = self._interpreter.get_input_details()[0]["index"]
        self._points, self._presence = outputs["conv2d_21"], outputs["conv2d_31"]
        # the model's input written in place (no set_tensor copy), and the per-frame
        # images in buffers reused from frame to frame
        self._input_view = self._interpreter.tensor(self._input)
        self._rgba = np.empty((0, 0, 4), np.uint8)
        self._crop = np.empty((INPUT, INPUT, 4), np.uint8)
        self._crop_rgb = np.empty((INPUT, INPUT, 3), np.uint8)
        self._roi: Roi | None = None

    def reset(self) -> None:
        """Forget the tracked face: the next frame is searched by the detector."""
        self._roi = None

    def track(self, rgb: np.ndarray) -> np.ndarray | None:
        """The 468 points of the face in `rgb` ((H, W, 3) uint8, RGB), (468, 3) float32 in
        the project's convention (module docstring); None when there is no face."""
        roi = self._roi
        if roi is None:
            faces = self.detector.detect(rgb)
            if not faces:
                return None
            roi = roi_from_detection(faces[0])
        points, presence = self.landmarks(rgb, roi)
        if presence < MIN_PRESENCE:
            self._roi = None
            return None
        self._roi = Roi.around(points[:, :2].min(0), points[:, :2].max(0),
                               points[EYE_LINE[0], :2], points[EYE_LINE[1], :2])
        height = rgb.shape[0]
        return np.column_stack([points[:, 0], height - points[:, 1], -points[:, 2]]).astype(np.float32)

    def landmarks(self, rgb: np.ndarray, roi: Roi) -> tuple[np.ndarray, float]:
        """((468, 3) float64 points in frame pixels, y down, z away from the camera as
        MediaPipe gives it; face presence 0..1) of the landmark model on `roi`."""
        axes = roi.axes()
        # the model input's pixel u (centre u + 0.5 of 192) samples the frame at
        # centre + axes @ ((u + 0.5) / 192 - 0.5); OpenCV's pixel centres are at integers
        linear = axes / INPUT
        offset = roi.centre + axes @ np.full(2, 0.5 / INPUT - 0.5) - 0.5
        warp = np.column_stack([linear, offset])
        # OpenCV's bilinear warp has a vectorised path for 4 channels but not for 3: an
        # RGBA copy of the frame, warped, takes half the time with the same values. Only
        # the pixels the samples can reach are copied (the square's bounding box and a
        # margin, clamped to the frame, where a square partly or wholly off it reads its
        # replicated edge), in place in a frame-sized buffer, so the warp sees the same
        # image and matrix as on the whole frame and the cost does not grow with its size
        if self._rgba.shape[:2] != rgb.shape[:2]:
            self._rgba = np.empty((*rgb.shape[:2], 4), np.uint8)
        # the bounding box is the centre +- half the axes' absolute sums, in plain floats
        # (as many small numpy calls cost more than the box is worth)
        (cx, cy), (hx, hy) = roi.centre.tolist(), (np.abs(axes).sum(1) / 2).tolist()
        height, width = rgb.shape[:2]
        x0, y0 = min(max(math.floor(cx - hx) - 2, 0), width - 1), min(max(math.floor(cy - hy) - 2, 0), height - 1)
        cols = slice(x0, min(max(math.ceil(cx + hx) + 2, x0 + 1), width))
        rows = slice(y0, min(max(math.ceil(cy + hy) + 2, y0 + 1), height))
        cv2.cvtColor(rgb[rows, cols], cv2.COLOR_RGB2RGBA, dst=self._rgba[rows, cols])
        cv2.warpAffine(self._rgba, warp, (INPUT, INPUT), dst=self._crop,
                       flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
        # back to 3 contiguous channels before scaling: numpy's uint8 -> float32 division is
        # several times slower on the strided RGBA view; the tensor view must not outlive
        # the statement (invoke() refuses to run while one exists)
        cv2.cvtColor(self._crop, cv2.COLOR_RGBA2RGB, dst=self._crop_rgb)
        np.divide(self._crop_rgb, np.float32(255.0), out=self._input_view()[0])
        self._interpreter.invoke()
        raw = self._interpreter.get_tensor(self._points).reshape(N_POINTS, 3).astype(np.float64)
        logit = float(self._interpreter.get_tensor(self._presence).ravel()[0])
        presence = 1.0 / (1.0 + np.exp(-np.clip(logit, -100.0, 100.0)))
        xy = roi.centre + (raw[:, :2] / INPUT - 0.5) @ axes.T
        z = raw[:, 2] / INPUT * roi.side
        return np.column_stack([xy, z]), presence


def roi_from_detection(face: Detection) -> Roi:
    """The landmark model's ROI for a detected face: its box, levelled along the eyes."""
    return Roi.around(face.box[:2], face.box[2:], face.keypoints[0], face.keypoints[1])
