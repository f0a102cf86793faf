"""`retarget.facemesh.tracker`: MediaPipe's legacy face-mesh graph on LiteRT, checked
against ground truth on rendered faces (its agreement with the browser's own tracker on
the shared real video is in test_markerless.py, beside that tracker's run)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from retarget.facemesh.tracker import N_POINTS, FaceMeshTracker, Roi
from retarget.layouts import IBUG68_TO_MEDIAPIPE468
from retarget.sample_face import sample_face
from retarget.testing.camera import look_at
from retarget.testing.render import render_face

SIZE = 480


def rendered(yaw_deg: float = 0.0, roll_deg: float = 0.0, shift=(0.0, 0.0)):
    """A front render of the built-in face turned by `yaw_deg` and rolled by `roll_deg`
    (degrees), RGB, and its 68 iBUG landmarks in the project's convention (pixels, y up)."""
    face = sample_face(1, identity=np.array([-0.3, 0.5, 0.2, -0.4, 0.1]))
    centre = face.vertices.mean(0)
    yaw, roll = np.radians(yaw_deg), np.radians(roll_deg)
    eye = centre + 45.0 * np.array([np.sin(yaw), 0.0, np.cos(yaw)])
    up = (np.sin(roll), np.cos(roll), 0.0)
    target = centre + np.array([shift[0], shift[1], 0.0])
    camera = look_at(eye + target - centre, target, up=up, size=(SIZE, SIZE), fov_deg=30)
    image = render_face(camera, face.vertices, face.faces).image
    points = camera.R @ face.vertices[face.landmarks68].T + camera.t[:, None]
    pixels = ((camera.K @ points)[:2] / points[2]).T + 0.5  # OpenCV's centres -> continuous
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB), np.column_stack([pixels[:, 0], SIZE - pixels[:, 1]])


@pytest.fixture(scope="module")
def tracker():
    return FaceMeshTracker()


@pytest.mark.parametrize("yaw, roll", [(0, 0), (20, 0), (0, 35), (0, -60)])
def test_the_points_of_a_rendered_face_lie_on_its_features(tracker, yaw, roll):
    """Brows, eyes, nose and mouth within a few percent of the eye distance (the jaw line
    of a generated face is its own design): roughly on the frame the detector found the
    face in, closely on the next, tracked from the first's points, as MediaPipe does."""
    rgb, truth = rendered(yaw, roll)
    inter_ocular = np.linalg.norm(truth[36:42].mean(0) - truth[42:48].mean(0))
    tracker.reset()
    for frame, bound in (("detected", 0.12), ("tracked", 0.07)):
        points = tracker.track(rgb)
        assert points is not None and points.shape == (N_POINTS, 3) and points.dtype == np.float32
        ours = points[list(IBUG68_TO_MEDIAPIPE468), :2]
        error = np.linalg.norm(ours[17:] - truth[17:], axis=1) / inter_ocular
        assert np.median(error) < bound, (frame, np.median(error))
    # in the face's own frame the person's right eye is on the image's left and y is up
    # (brows above the mouth)
    eye_line = truth[42:48].mean(0) - truth[36:42].mean(0)
    turn = np.arctan2(eye_line[1], eye_line[0])  # the roll as the image shows it
    level = ours @ np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    assert level[36:42, 0].mean() < level[42:48, 0].mean()
    assert level[17:27, 1].mean() > level[48:68, 1].mean()


def test_two_inference_threads_find_the_same_points(tracker):
    """`retarget track` runs the models on the machine's cores: the same points as one
    thread, to float rounding."""
    rgb, _ = rendered(10, 5)
    tracker.reset()
    one = [tracker.track(rgb) for _ in range(2)]
    two_threads = FaceMeshTracker(threads=2)
    two = [two_threads.track(rgb) for _ in range(2)]
    for a, b in zip(one, two):
        assert a is not None and b is not None
        np.testing.assert_allclose(a, b, atol=1e-2)  # pixels


def test_the_face_is_followed_from_frame_to_frame_without_the_detector(tracker, monkeypatch):
    rgb, _ = rendered()
    tracker.reset()
    first = tracker.track(rgb)
    calls = []
    monkeypatch.setattr(tracker.detector, "detect", lambda image: calls.append(1) or [])
    moved, truth = rendered(shift=(0.6, -0.4))  # the face moves a few pixels
    second = tracker.track(moved)
    assert calls == []  # tracked from the previous points, not searched again
    assert second is not None
    shift = (second - first)[list(IBUG68_TO_MEDIAPIPE468)[17:], :2].mean(0)
    assert np.linalg.norm(shift) > 3.0  # it saw the move


def test_no_face_is_none_and_the_next_frame_is_searched_again(tracker):
    rgb, _ = rendered()
    tracker.reset()
    assert tracker.track(rgb) is not None
    assert tracker.track(np.full((SIZE, SIZE, 3), 90, np.uint8)) is None
    assert tracker.track(rgb) is not None


def test_a_rotated_roi_maps_its_corners_where_it_says():
    roi = Roi(centre=np.array([100.0, 50.0]), side=40.0, angle=np.pi / 2)
    # the square's x axis points down the frame (+y): its unit x corner offset is (0, 40)
    assert np.allclose(roi.axes() @ [1.0, 0.0], [0.0, 40.0])
    levelled = Roi.around(np.array([0.0, 0.0]), np.array([20.0, 10.0]), np.array([0.0, 0.0]), np.array([1.0, 1.0]))
    assert np.isclose(levelled.angle, np.pi / 4) and np.isclose(levelled.side, 30.0)
    assert np.allclose(levelled.centre, [10.0, 5.0])
