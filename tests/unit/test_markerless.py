"""The browser's face-mesh tracker on video files: `track_video_markerless` (OpenCV
decoding, the web app's tracker in headless Chromium: the reference the native face mesh
is checked against) on a real face video and on a generated one without a face, and its
refusals; the native tracker's agreement with it on the real video.

The real video is ``../shared/data/video/face_expressions_480.mp4``; the tests that need it
skip only when ../shared is absent. Its first 60 frames were labelled by eye: the mouth is
closed in frames 0-47 and open (teeth apart) in frames 50-59.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.sources.markerless import track_video_markerless
from server.web import WEB_DIR

SHARED = Path(__file__).resolve().parents[3] / "shared"
VIDEO = SHARED / "data" / "video" / "face_expressions_480.mp4"
CLIP = 60
CLOSED, OPEN = range(0, 48), range(50, 60)

needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason="../shared is absent")


@pytest.fixture(scope="module")
def clip():
    """The first 60 frames of the real video through the browser's tracker, ibug68,
    and the progress calls it made."""
    if not SHARED.is_dir():
        pytest.skip("../shared is absent")
    calls = []
    take = track_video_markerless(VIDEO, layout="ibug68", web_root=WEB_DIR, max_frames=CLIP,
                                  progress=lambda done, total: calls.append((done, total)))
    return take, calls


@pytest.fixture(scope="module")
def noise_video(tmp_path_factory):
    """8 frames of 96 x 96 noise, 30 fps, VP8 WebM (OpenCV reads it, Chromium plays it)."""
    path = tmp_path_factory.mktemp("noise") / "noise.webm"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"VP80"), 30, (96, 96))
    rng = np.random.default_rng(4)
    for _ in range(8):
        writer.write(rng.integers(0, 256, (96, 96, 3), dtype=np.uint8))
    writer.release()
    return path


@needs_shared
def test_the_native_tracker_agrees_with_the_browser_s_on_the_real_video(clip):
    """Within 1 px median (issue 14): the page's MediaPipe and ours (`retarget.facemesh`) on
    the same frames, with no constant offset."""
    from retarget.facemesh.tracker import FaceMeshTracker

    take, _ = clip
    columns = list(get_layout("ibug68").mediapipe468)
    video = cv2.VideoCapture(str(VIDEO))
    tracker = FaceMeshTracker()
    ours = []
    for _ in range(CLIP):
        ok, frame = video.read()
        assert ok
        points = tracker.track(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
        assert points is not None
        ours.append(points[columns])
    difference = np.asarray(ours)[:, :, :2] - np.asarray(take.points)[:, :, :2]
    distance = np.linalg.norm(difference, axis=2)
    assert np.median(distance) < 1.0, np.median(distance)
    assert np.abs(difference.reshape(-1, 2).mean(0)).max() < 0.3  # no constant offset


def _point(take, name):
    """(F, 3) track of one named point."""
    return take.points[:, take.names.index(name)]


@needs_shared
def test_take_holds_every_frame_in_the_layout_with_progress(clip):
    take, calls = clip
    assert take.points.shape == (CLIP, 68, 3) and take.points.dtype == np.float32
    assert take.names == get_layout("ibug68").point_names and take.layout == "ibug68"
    assert take.source == "markerless" and take.fps == 30.0
    assert (take.meta["width"], take.meta["height"]) == (480, 480)
    # the shared video's README: a face is found in every frame
    assert take.meta["frames_with_face"] == CLIP and take.meta["face_share"] == 1.0
    assert np.isfinite(take.points).all()
    assert take.meta["fps_tracked"] > 0 and not take.meta["truncated"]
    assert calls == [(i, CLIP) for i in range(1, CLIP + 1)]


@needs_shared
def test_points_are_in_the_image_with_y_up_and_z_toward_the_camera(clip):
    take, _ = clip
    x, y = take.points[..., 0], take.points[..., 1]
    assert (x >= 0).all() and (x <= 480).all() and (y >= 0).all() and (y <= 480).all()
    layout = get_layout("ibug68")
    regions = np.array(layout.regions)
    brows = take.points[:, regions == "brows", 1].mean(axis=1)
    eyes = take.points[:, regions == "eyes", 1].mean(axis=1)
    # y up: each frame, top to bottom of the face
    chain = [brows, eyes, _point(take, "nose_tip")[:, 1], _point(take, "lip_upper_center")[:, 1],
             _point(take, "lip_lower_center")[:, 1], _point(take, "chin")[:, 1]]
    for upper, lower in zip(chain, chain[1:]):
        assert (upper > lower).all()
    # z toward the camera: the nose tip is nearer than the face oval beside the ears
    nose = _point(take, "nose_tip")[:, 2]
    for ear in ("jaw_right_1", "jaw_left_1"):
        assert (nose > _point(take, ear)[:, 2]).all()
    # z in pixels of the width, like x: the nose stands out a sizeable part of the
    # distance between the outer eye corners, not a thousandth of it
    eyes_apart = _point(take, "eye_left_outer")[:, 0] - _point(take, "eye_right_outer")[:, 0]
    depth = nose - (_point(take, "jaw_right_1")[:, 2] + _point(take, "jaw_left_1")[:, 2]) / 2
    assert (depth > 0.3 * eyes_apart).all() and (depth < 3 * eyes_apart).all()


@needs_shared
def test_the_subjects_right_is_on_the_image_left(clip):
    """A camera facing the subject shows the subject's right side on the image's left:
    every "right" point has a smaller x than its "left" mirror partner, every frame."""
    take, _ = clip
    layout = get_layout("ibug68")
    right = [i for i, side in enumerate(layout.sides) if side == "right"]
    partners = [layout.mirror[i] for i in right]
    assert (take.points[:, right, 0] < take.points[:, partners, 0]).all()


@needs_shared
def test_open_mouth_frames_have_a_larger_lip_gap(clip):
    take, _ = clip
    gap = _point(take, "lip_upper_inner_center")[:, 1] - _point(take, "lip_lower_inner_center")[:, 1]
    eyes_apart = _point(take, "eye_left_outer")[:, 0] - _point(take, "eye_right_outer")[:, 0]
    relative = gap / eyes_apart
    assert relative[list(OPEN)].min() > 3 * max(relative[list(CLOSED)].max(), 0.01)
    assert relative[list(OPEN)].min() > 0.1  # teeth apart: a tenth of the eye span at least


def test_a_video_without_a_face_gives_nan_frames_and_a_warning(noise_video):
    with pytest.warns(RuntimeWarning, match="no face found in any of the 8 frames"):
        take = track_video_markerless(noise_video, layout="dutreve21", web_root=WEB_DIR)
    assert take.points.shape == (8, 21, 3) and np.isnan(take.points).all()
    assert take.meta["face_share"] == 0.0 and take.meta["frames_with_face"] == 0
    assert (take.meta["width"], take.meta["height"]) == (96, 96)


def test_broken_missing_and_bad_arguments_are_refused(tmp_path):
    broken = tmp_path / "broken.mp4"
    broken.write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(range(256)) * 40)
    with pytest.raises(RetargetError, match="broken.mp4"):
        track_video_markerless(broken, layout="ibug68", web_root=WEB_DIR)
    with pytest.raises(RetargetError, match="does not exist"):
        track_video_markerless(tmp_path / "missing.mp4", layout="ibug68", web_root=WEB_DIR)
    with pytest.raises(RetargetError, match="max_frames"):
        track_video_markerless(broken, layout="ibug68", web_root=WEB_DIR, max_frames=0)
    with pytest.raises(RetargetError, match="unknown layout"):
        track_video_markerless(broken, layout="nope", web_root=WEB_DIR)


def test_missing_playwright_or_chromium_says_how_to_get_them(tmp_path, monkeypatch, noise_video):
    with pytest.raises(RetargetError, match=r"Chromium not found at .*apt-get install chromium"):
        track_video_markerless(noise_video, layout="ibug68", web_root=WEB_DIR,
                               chromium=str(tmp_path / "no-chromium"))
    monkeypatch.setitem(sys.modules, "playwright.sync_api", None)  # import fails as if absent
    with pytest.raises(RetargetError, match=r"pip install 'retarget\[markerless\]'"):
        track_video_markerless(noise_video, layout="ibug68", web_root=WEB_DIR)
