"""MediaPipe's short-range face detector (BlazeFace, 128 x 128 input) on LiteRT.

The graph it reimplements is MediaPipe's ``face_detection_short_range_cpu``: the frame is
letterboxed into the model's square input (values in -1..1), 896 SSD anchors (strides 8,
16, 16, 16; two anchors a cell; fixed size) decode the regressors into boxes and six
keypoints (right eye, left eye, nose tip, mouth, right ear, left ear, as the person
sees them), scores pass a sigmoid, and overlapping boxes are merged by weighted
non-maximum suppression (IoU 0.3), as ``TensorsToDetectionsCalculator`` and
``NonMaxSuppressionCalculator`` do.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from retarget.facemesh.assets import model_interpreter

__all__ = ["Detection", "FaceDetector", "ssd_anchors"]

INPUT = 128
STRIDES = (8, 16, 16, 16)
ANCHORS_PER_LAYER = 2  # aspect ratio 1 and the interpolated scale, both of size 1 (fixed)
MIN_SCORE = 0.5
MIN_SUPPRESSION_IOU = 0.3
SCORE_CLIP = 100.0


@dataclass(frozen=True)
class Detection:
    """One face, in the frame's pixels (x right, y down, origin top-left).

    box : (4,) float, x_min, y_min, x_max, y_max
    keypoints : (6, 2) float, right eye, left eye, nose tip, mouth centre, right ear
        tragion, left ear tragion (the person's right and left)
    score : float in 0..1
    """

    box: np.ndarray
    keypoints: np.ndarray
    score: float


def ssd_anchors() -> np.ndarray:
    """(896, 2) float32: the anchor centres in 0..1 of the model input, in the model's order
    (per layer, row-major cells, then the anchors of a cell). Layers of equal stride share
    their grid, so the three stride-16 layers give six anchors a cell."""
    centres = []
    layer = 0
    while layer < len(STRIDES):
        stride = STRIDES[layer]
        repeats = 0
        while layer < len(STRIDES) and STRIDES[layer] == stride:
            repeats += ANCHORS_PER_LAYER
            layer += 1
        n = INPUT // stride
        y, x = np.mgrid[0:n, 0:n]
        cells = np.stack([(x.ravel() + 0.5) / n, (y.ravel() + 0.5) / n], axis=1)
        centres.append(np.repeat(cells, repeats, axis=0))
    return np.concatenate(centres).astype(np.float32)


class FaceDetector:
    """Faces in a frame: `detect(rgb) -> list[Detection]`, best first."""

    def __init__(self, threads: int = 1):
        self._interpreter, outputs = model_interpreter("face_detection_short_range.tflite", threads)
        self._input = self._interpreter.get_input_details()[0]["index"]
        self._regressors, self._scores = outputs["regressors"], outputs["classificators"]
        self._anchors = ssd_anchors()

    def detect(self, rgb: np.ndarray) -> list[Detection]:
        """The faces in `rgb` ((H, W, 3) uint8, RGB), best first; empty when none scores
        `MIN_SCORE`."""
        height, width = rgb.shape[:2]
        side = max(height, width)
        # letterbox: the frame centred in a square, as keep_aspect_ratio does
        pad_x, pad_y = (side - width) / 2, (side - height) / 2
        square = cv2.copyMakeBorder(rgb, int(pad_y), side - height - int(pad_y), int(pad_x),
                                    side - width - int(pad_x), cv2.BORDER_CONSTANT, value=0)
        tensor = cv2.resize(square, (INPUT, INPUT), interpolation=cv2.INTER_AREA).astype(np.float32)
        tensor = tensor[None] / 127.5 - 1.0
        self._interpreter.set_tensor(self._input, tensor)
        self._interpreter.invoke()
        raw = self._interpreter.get_tensor(self._regressors)[0]
        logits = np.clip(self._interpreter.get_tensor(self._scores)[0, :, 0].astype(np.float64), -SCORE_CLIP, SCORE_CLIP)
        scores = 1.0 / (1.0 + np.exp(-logits))
        keep = scores >= MIN_SCORE
        if not keep.any():
            return []
        raw, scores, anchors = raw[keep], scores[keep], self._anchors[keep]
        # offsets in input pixels around the anchor centre; sizes in input pixels
        centre = anchors + raw[:, 0:2] / INPUT
        half = raw[:, 2:4] / INPUT / 2
        boxes = np.concatenate([centre - half, centre + half], axis=1)
        keypoints = anchors[:, None, :] + raw[:, 4:16].reshape(-1, 6, 2) / INPUT
        # from the square's 0..1 to the frame's pixels
        boxes = boxes * side - np.array([pad_x, pad_y, pad_x, pad_y])
        keypoints = keypoints * side - np.array([pad_x, pad_y])
        return _weighted_nms(boxes, keypoints, scores)


def _weighted_nms(boxes: np.ndarray, keypoints: np.ndarray, scores: np.ndarray) -> list[Detection]:
    """MediaPipe's weighted non-maximum suppression: each cluster of boxes overlapping the
    best remaining one by IoU > `MIN_SUPPRESSION_IOU` becomes one detection, its box and
    keypoints the score-weighted mean of the cluster's, its score the best one's."""
    order = np.argsort(-scores)
    remaining = list(order)
    faces = []
    area = np.prod(np.maximum(boxes[:, 2:] - boxes[:, :2], 0), axis=1)
    while remaining:
        best = remaining[0]
        rest = np.array(remaining)
        lo = np.maximum(boxes[rest, :2], boxes[best, :2])
        hi = np.minimum(boxes[rest, 2:], boxes[best, 2:])
        inter = np.prod(np.maximum(hi - lo, 0), axis=1)
        iou = inter / np.maximum(area[rest] + area[best] - inter, 1e-12)
        cluster = rest[iou > MIN_SUPPRESSION_IOU]
        if len(cluster) == 0:
            cluster = np.array([best])
        w = scores[cluster] / scores[cluster].sum()
        faces.append(Detection(box=(w[:, None] * boxes[cluster]).sum(0),
                               keypoints=(w[:, None, None] * keypoints[cluster]).sum(0),
                               score=float(scores[best])))
        merged = set(cluster.tolist())
        remaining = [i for i in remaining if i not in merged]
    return faces
