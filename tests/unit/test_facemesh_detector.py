"""`retarget.facemesh`: the face-mesh models shipped in the package (extracted from the npm
package the browser runs) and MediaPipe's short-range face detector on LiteRT."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.facemesh.assets import MODEL_DIR, MODELS, extract_models, model_bytes
from retarget.facemesh.detector import FaceDetector, ssd_anchors
from retarget.sample_face import sample_face
from retarget.testing.camera import look_at
from retarget.testing.render import render_face

NPM_PACKAGE = Path(__file__).resolve().parents[2] / "web" / "node_modules" / "@mediapipe" / "face_mesh"
VIDEO = Path(__file__).resolve().parents[3] / "shared" / "data" / "video" / "face_expressions_480.mp4"


@pytest.fixture(scope="module")
def detector():
    return FaceDetector()


@pytest.fixture(scope="module")
def rendered_face():
    """A 480 x 480 front render of the built-in face (cm) and its 68 landmarks in pixels."""
    face = sample_face(1, identity=np.array([0.5, -0.4, 0.3, 0.0, -0.2]))
    centre = face.vertices.mean(0)
    camera = look_at(centre + np.array([0.0, 0.0, 45.0]), centre, size=(480, 480), fov_deg=30)
    image = render_face(camera, face.vertices, face.faces).image
    camera_points = camera.R @ face.vertices[face.landmarks68].T + camera.t[:, None]
    pixels = (camera.K @ camera_points)[:2] / camera_points[2]
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB), pixels.T


def test_the_shipped_models_are_the_npm_package_s_bytes(tmp_path):
    assert NPM_PACKAGE.is_dir(), "the README's install step `npm ci --prefix web` provides it"
    manifest = extract_models(NPM_PACKAGE, tmp_path)
    assert manifest == json.loads((MODEL_DIR / "MODELS.json").read_text())
    for name in MODELS:
        assert (tmp_path / name).read_bytes() == model_bytes(name)
        assert hashlib.sha256(model_bytes(name)).hexdigest() == manifest["files"][name]["sha256"]


def test_a_damaged_or_missing_model_is_refused_by_name(tmp_path):
    shutil.copytree(MODEL_DIR, tmp_path / "models")
    path = tmp_path / "models" / "face_landmark.tflite"
    data = bytearray(path.read_bytes())
    data[1000] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(RetargetError, match="face_landmark.tflite is damaged"):
        model_bytes("face_landmark.tflite", tmp_path / "models")
    (tmp_path / "models" / "face_detection_short_range.tflite").unlink()
    with pytest.raises(RetargetError, match="face_detection_short_range.tflite is missing"):
        model_bytes("face_detection_short_range.tflite", tmp_path / "models")
    with pytest.raises(RetargetError, match="unknown face-mesh model"):
        model_bytes("face_detection_full_range.tflite")


def test_the_anchors_are_the_ssd_grid_of_the_short_range_model():
    anchors = ssd_anchors()
    assert anchors.shape == (896, 2)
    # stride 8: a 16 x 16 grid, two anchors a cell; strides 16 (three layers): 8 x 8, six a cell
    assert np.allclose(anchors[0], anchors[1]) and np.allclose(anchors[0], [0.5 / 16, 0.5 / 16])
    assert np.allclose(anchors[2], [1.5 / 16, 0.5 / 16])
    assert np.allclose(anchors[512:518], [0.5 / 8, 0.5 / 8]) and np.allclose(anchors[518], [1.5 / 8, 0.5 / 8])
    assert np.allclose(anchors[-1], [7.5 / 8, 7.5 / 8])


def test_a_rendered_face_is_found_with_its_eyes_nose_and_mouth_where_they_are(detector, rendered_face):
    rgb, landmarks = rendered_face
    (face,) = detector.detect(rgb)
    assert face.score > 0.7
    right_eye, left_eye = landmarks[36:42].mean(0), landmarks[42:48].mean(0)
    eye_distance = np.linalg.norm(left_eye - right_eye)
    found = {"right eye": (face.keypoints[0], right_eye), "left eye": (face.keypoints[1], left_eye),
             "nose tip": (face.keypoints[2], landmarks[30]),
             "mouth": (face.keypoints[3], landmarks[[62, 66]].mean(0))}
    for name, (point, truth) in found.items():
        assert np.linalg.norm(point - truth) < 0.15 * eye_distance, (name, point, truth)
    x0, y0, x1, y1 = face.box
    inner = landmarks[17:]  # brows, eyes, nose, mouth
    assert (inner[:, 0] > x0).all() and (inner[:, 0] < x1).all()
    assert (inner[:, 1] > y0).all() and (inner[:, 1] < y1).all()


def test_a_frame_of_any_shape_maps_back_to_its_own_pixels(detector, rendered_face):
    # letterboxing into the square input must not shift the answer: the same face padded
    # into a wide frame is found at the same place, offset by the padding
    rgb, _ = rendered_face
    (square,) = detector.detect(rgb)
    wide = np.zeros((480, 800, 3), np.uint8)
    wide[:, 200:680] = rgb
    (shifted,) = detector.detect(wide)
    # the network sees the face at 60% of the size, so single points move by up to a few
    # pixels; a wrong padding or scale would move them all, by tens or hundreds
    offset = shifted.keypoints - square.keypoints
    size = square.box[2] - square.box[0]
    assert np.allclose(offset.mean(0), [200, 0], atol=3.0), offset.mean(0)
    assert np.abs(offset - [200, 0]).max() < 0.03 * size
    assert np.abs(shifted.box - (square.box + [200, 0, 200, 0])).max() < 0.03 * size


def test_no_face_in_noise_or_a_blank_frame(detector):
    rng = np.random.default_rng(3)
    assert detector.detect(rng.integers(0, 256, (360, 640, 3), dtype=np.uint8)) == []
    assert detector.detect(np.full((480, 480, 3), 128, np.uint8)) == []


def test_the_face_in_every_frame_of_the_real_video(detector):
    if not VIDEO.parent.parent.parent.is_dir():
        pytest.skip("../shared is absent")
    video = cv2.VideoCapture(str(VIDEO))
    missed, eye_spans = [], []
    for index in range(0, 150):
        ok, frame = video.read()
        assert ok, f"frame {index} unreadable"
        faces = detector.detect(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
        if len(faces) != 1:
            missed.append((index, len(faces)))
            continue
        right, left = faces[0].keypoints[:2]
        assert right[0] < left[0]  # the person's right eye is on the image's left
        eye_spans.append(left[0] - right[0])
    assert missed == []
    assert 60 < np.median(eye_spans) < 160  # a 480 px frame filled by a face
