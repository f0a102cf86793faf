"""The live stereo tracker and calibration (retarget.sources.stereo_live) on a rendered rig
with known truth."""

from __future__ import annotations

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.sources.stereo_live import LiveCalibration, LiveStereoTracker
from retarget.sources.video import VideoReader
from retarget.testing.stereo_rig import checkerboard_views, render_stereo_video, rig_calibration, stereo_cameras


def head_frame_truth(truth, rig, first: int = 0) -> np.ndarray:
    """(F, N, 3) true marker positions in the left camera's frame with the head held at
    frame `first`'s pose (what the tracker's head frame is)."""
    rot, trans = truth.head_rotation, truth.head_translation
    posed = np.einsum("fji,fnj->fni", rot, truth.points3d - trans[:, None])
    return rig[0].to_camera(posed @ rot[first].T + trans[first])


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    rig = stereo_cameras()
    truth = render_stereo_video(tmp_path_factory.mktemp("live") / "take.mkv", n_frames=10, cameras=rig,
                                start=3.6, seed=2)
    with VideoReader(truth.videos[0]) as a, VideoReader(truth.videos[1]) as b:
        frames = [(left, right) for (_, left), (_, right) in zip(a, b)]
    return rig, truth, frames


def test_pushed_pairs_give_the_head_frame_points(pair):
    rig, truth, frames = pair
    tracker = LiveStereoTracker(rig_calibration(*rig), "dutreve21", temporal_window=1)
    points = np.stack([tracker.push(left, right, i / 30) for i, (left, right) in enumerate(frames)])
    assert points.shape == (10, 21, 3) and tracker.identified_ and tracker.anchored_
    err = np.linalg.norm(points - head_frame_truth(truth, rig), axis=2)
    assert np.isfinite(err).all() and np.median(err) < 0.5 and err.max() < 3.0
    # the head moves in these frames: without its removal the error would be far larger
    moved = np.linalg.norm(rig[0].to_camera(truth.points3d) - head_frame_truth(truth, rig), axis=2)
    assert np.median(moved) > 5 * np.median(err)


def test_the_temporal_mean_is_causal(pair):
    rig, _, frames = pair
    raw = LiveStereoTracker(rig_calibration(*rig), "dutreve21", temporal_window=1)
    mean = LiveStereoTracker(rig_calibration(*rig), "dutreve21", temporal_window=3)
    a = np.stack([raw.push(*f, i / 30) for i, f in enumerate(frames[:5])])
    b = np.stack([mean.push(*f, i / 30) for i, f in enumerate(frames[:5])])
    np.testing.assert_allclose(b[4], a[2:5].mean(axis=0), atol=1e-4)
    np.testing.assert_allclose(b[0], a[0], atol=1e-5)


def test_a_face_out_of_view_is_lost_then_found(pair):
    rig, truth, frames = pair
    tracker = LiveStereoTracker(rig_calibration(*rig), "dutreve21", temporal_window=1)
    blank = np.zeros_like(frames[0][0])
    assert np.isnan(tracker.push(blank, blank, 0.0)).all() and not tracker.identified_
    assert "markers matched" in tracker.setup_error_
    got = tracker.push(*frames[1], 1 / 30)
    assert np.isfinite(got).all()


def test_bad_frames_are_refused(pair):
    rig, _, frames = pair
    tracker = LiveStereoTracker(rig_calibration(*rig), "dutreve21")
    with pytest.raises(RetargetError, match="320x240, the calibration is for 640x480"):
        tracker.push(np.zeros((240, 320, 3), np.uint8), frames[0][1], 0.0)
    tracker.push(*frames[0], 1.0)
    with pytest.raises(RetargetError, match="times must increase"):
        tracker.push(*frames[1], 1.0)


def test_the_live_calibration_counts_good_views_and_calibrates():
    rig = stereo_cameras()
    lefts, rights, _ = checkerboard_views(*rig, n_views=11, seed=3)
    live = LiveCalibration(("checkerboard", 9, 6, 25.0), (640, 480))
    blank = np.full_like(lefts[0], 255)
    assert not live.add_views(blank, rights[0]) and live.count == 0
    assert live.add_views(lefts[0], rights[0]) and not live.add_views(lefts[0], rights[0])  # held still
    with pytest.raises(RetargetError, match="1 good views of the board so far; 10 are needed"):
        live.calibrate()
    for left, right in zip(lefts[1:], rights[1:]):
        assert live.add_views(left, right)
    assert live.count == 11
    calibration = live.calibrate()
    assert calibration.baseline == pytest.approx(150.0, rel=0.02) and calibration.rms < 1.0
