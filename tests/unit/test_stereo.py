"""Tests for retarget.sources.stereo and retarget.testing.stereo_rig: calibration from
rendered checkerboard and circle-grid views against the rig's true cameras, save/load,
epipolar matching, triangulation, and colour-marker stereo tracking of rendered videos
against their ground truth (3D error, head motion removal, lost markers, bad input)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.sources.color_markers import color_blobs, layout_marker_colors
from retarget.sources.calibration import StereoCalibration, calibrate_stereo, find_pattern, pattern_points
from retarget.sources.stereo import (
    identified_markers,
    stereo_matches,
    track_stereo_frames,
    track_stereo_videos,
)
from retarget.sources.take import Take
from retarget.testing.stereo_rig import (
    checkerboard_views,
    render_stereo_video,
    rig_calibration,
    stereo_cameras,
    still_frames,
    webcam_cameras,
)

BOARD = ("checkerboard", 9, 6, 25.0)


@pytest.fixture(scope="module")
def rig():
    return stereo_cameras()


@pytest.fixture(scope="module")
def clip(tmp_path_factory, rig):
    """A 10-frame rendered colour-marker stereo take (lossless) and its truth."""
    path = tmp_path_factory.mktemp("stereo") / "take.mkv"
    return render_stereo_video(path, n_frames=10, cameras=rig, start=3.6, seed=2)


def _rotation_deg(a, b):
    return np.degrees(np.linalg.norm(Rotation.from_matrix(a @ b.T).as_rotvec()))


def test_calibration_from_rendered_checkerboards_finds_the_rig():
    left, right = stereo_cameras(size=(320, 240))
    lefts, rights, _ = checkerboard_views(left, right, 8, seed=0)
    blank = np.full_like(lefts[0], 90)
    cal = calibrate_stereo(lefts + [blank], rights + [rights[0]], BOARD)
    truth = rig_calibration(left, right)
    assert cal.rms < 0.2  # px
    assert abs(cal.K1[0, 0] / truth.K1[0, 0] - 1) < 0.01 and abs(cal.K2[1, 1] / truth.K2[1, 1] - 1) < 0.01
    assert abs(cal.baseline / truth.baseline - 1) < 0.01
    assert _rotation_deg(cal.R, truth.R) < 0.3
    assert cal.meta["views"] == 8 and cal.meta["skipped"] == [{"pair": 8, "missing_in": ["left"]}]
    # Points at the face's distance triangulate to within a millimetre or two.
    rng = np.random.default_rng(0)
    pts = rng.uniform([-60, -80, 40], [60, 80, 120], (50, 3))
    xyz = cal.triangulate(left.project(pts), right.project(pts))
    assert np.median(np.linalg.norm(xyz - left.to_camera(pts), axis=1)) < 2.0


def test_calibration_from_webcam_like_boards_finds_the_focal_length():
    # Issue 17: stacked 640 x 480 webcams 80 mm apart, the board about 1 m away, filmed
    # blurred, unevenly lit, noisy and JPEG-compressed, a fifth of the pairs poor. The
    # detector's own corners (no cornerSubPix) put the focal lengths 1.2 % off here.
    upper, lower = webcam_cameras()
    lefts, rights, _ = checkerboard_views(upper, lower, 8, max_tilt=30.0, poor=0.2, seed=3)
    cal = calibrate_stereo(lefts, rights, BOARD)
    truth = rig_calibration(upper, lower)
    focal = np.array([cal.K1[0, 0], cal.K1[1, 1], cal.K2[0, 0], cal.K2[1, 1]])
    assert np.abs(focal / truth.K1[0, 0] - 1).max() < 0.002
    assert abs(cal.baseline - truth.baseline) < 0.04  # mm of 80
    assert _rotation_deg(cal.R, truth.R) < 0.03
    assert cal.meta["views"] == 8 and cal.rms < 0.1  # px


def test_calibration_without_the_pattern_is_refused(tmp_path):
    gray = np.full((240, 320), 128, np.uint8)
    with pytest.raises(RetargetError,
                       match=r"found in both images of 0 of 3 pairs.*pair 0: not found in left and right"):
        calibrate_stereo([gray] * 3, [gray] * 3, BOARD)
    with pytest.raises(RetargetError, match="3 left images but 2 right"):
        calibrate_stereo([gray] * 3, [gray] * 2, BOARD)
    with pytest.raises(RetargetError, match="right image 0 is 160x120"):
        calibrate_stereo([gray] * 3, [gray[:120, :160]] * 3, BOARD)
    with pytest.raises(RetargetError, match="no image file"):
        calibrate_stereo([tmp_path / "missing.png"] * 3, [gray] * 3, BOARD)
    (tmp_path / "text.png").write_text("not an image")
    with pytest.raises(RetargetError, match="not a readable image"):
        calibrate_stereo([tmp_path / "text.png"] * 3, [gray] * 3, BOARD)
    with pytest.raises(RetargetError, match="pattern must be"):
        calibrate_stereo([gray] * 3, [gray] * 3, ("chessboard", 9, 6, 25.0))


def test_circle_grid_is_found_in_pattern_order_up_to_its_symmetry():
    # A symmetric 4 x 3 grid of black dots on white, drawn anti-aliased at known centres.
    cols, rows, spacing, scale = 4, 3, 40.0, 8
    centres = pattern_points(("circles", cols, rows, spacing))[:, :2] + [60.3, 50.7]
    big = np.full((240 * scale, 320 * scale), 255, np.uint8)
    for x, y in centres:
        cv2.circle(big, (int((x + 0.5) * scale), int((y + 0.5) * scale)), 10 * scale, 0, -1)
    img = cv2.resize(big, (320, 240), interpolation=cv2.INTER_AREA)
    found = find_pattern(img, ("circles", cols, rows, spacing))
    assert found is not None and found.shape == (12, 2)
    # A symmetric grid may be reported from either end (180 degrees apart).
    err = min(np.abs(found - centres).max(), np.abs(found[::-1] - centres).max())
    assert err < 0.2
    assert find_pattern(np.full((240, 320), 255, np.uint8), ("circles", cols, rows, spacing)) is None
    asym = pattern_points(("acircles", 4, 3, 10.0))
    assert np.allclose(asym[:5, :2], [[0, 0], [20, 0], [40, 0], [60, 0], [10, 10]])


def test_save_and_load_round_trip(tmp_path, rig):
    cal = rig_calibration(*rig)
    cal.meta["note"] = "exact"
    cal.save(tmp_path / "cal.npz")
    back = StereoCalibration.load(tmp_path / "cal.npz")
    for name in ("K1", "d1", "K2", "d2", "R", "T", "E", "F"):
        assert np.array_equal(getattr(back, name), getattr(cal, name)), name
    assert back.size == cal.size and back.rms == cal.rms and back.meta == cal.meta
    assert StereoCalibration.from_dict(cal.to_dict()).baseline == pytest.approx(150.0)
    np.savez(tmp_path / "other.npz", points=np.zeros(3))
    with pytest.raises(RetargetError, match="not a stereo calibration"):
        StereoCalibration.load(tmp_path / "other.npz")
    with pytest.raises(RetargetError, match="does not exist"):
        StereoCalibration.load(tmp_path / "missing.npz")
    with pytest.raises(RetargetError, match="lacks T, E"):
        StereoCalibration.from_dict({k: v for k, v in cal.to_dict().items() if k not in ("T", "E")})


def test_triangulation_is_exact_with_distortion_and_keeps_nan_rows():
    dist = np.array([-0.12, 0.05, 0.001, -0.0005, 0.0])
    left, right = stereo_cameras(dist=dist)
    cal = rig_calibration(left, right)
    rng = np.random.default_rng(1)
    pts = rng.uniform([-80, -100, 30], [80, 100, 130], (40, 3))
    pl, pr = left.project(pts), right.project(pts)
    pl[5] = np.nan
    xyz = cal.triangulate(pl, pr)
    truth = left.to_camera(pts)
    assert np.isnan(xyz[5]).all()
    assert np.abs(np.delete(xyz - truth, 5, axis=0)).max() < 1e-6  # mm
    assert np.delete(cal.epipolar_distances(pl, pr), 5).max() < 1e-6
    # Off the epipolar line by 2 px vertically: the distance says so.
    assert cal.epipolar_distances(pl[:1], pr[:1] + [0.0, 2.0])[0] == pytest.approx(2.0, rel=0.1)


def test_matching_uses_colour_epipolar_lines_and_depth(rig):
    left, right = rig
    cal = rig_calibration(left, right)
    # Mirror pairs of points at one height share an epipolar line; no labels at all.
    rng = np.random.default_rng(2)
    half = rng.uniform([10, -80, 60], [70, 80, 100], (8, 3))
    pts = np.concatenate([half, half * [-1, 1, 1]])
    order = rng.permutation(len(pts))
    pr = right.project(pts)[order]
    pr = np.concatenate([pr, [[300.0, 10.0]]])  # a stray candidate in the right image only
    pairs = stereo_matches(cal, left.project(pts), pr)
    assert len(pairs) == len(pts)
    assert np.array_equal(order[pairs[:, 1]], pairs[:, 0])
    # Labels that disagree forbid a pair.
    labels = np.array(["green"] * len(pts))
    pairs = stereo_matches(cal, left.project(pts), right.project(pts), labels,
                           np.array(["blue"] * len(pts)))
    assert len(pairs) == 0


def test_tracked_points_match_the_truth(clip, rig):
    cal = rig_calibration(*rig)
    take = track_stereo_videos(*clip.videos, cal, layout="dutreve21", head_motion="keep")
    assert isinstance(take, Take) and take.source == "stereo" and take.layout == "dutreve21"
    assert take.points.shape == (10, 21, 3) and take.fps == pytest.approx(30.0)
    assert take.meta["identified_at_start"] == [True] * 21
    truth = rig[0].to_camera(clip.points3d)
    err = np.linalg.norm(take.points - truth, axis=2)
    assert np.isfinite(err).all()
    assert np.median(err) < 0.3 and err.max() < 1.5  # mm at 1 m


def test_head_motion_is_removed_into_the_first_frames_head_frame(clip, rig):
    cal = rig_calibration(*rig)
    take = track_stereo_videos(*clip.videos, cal, layout="dutreve21")
    # The truth without head motion, placed where the head was in frame 0.
    posed = np.einsum("fnj,fji->fni", clip.points3d - clip.head_translation[:, None],
                      clip.head_rotation)
    expected = rig[0].to_camera(posed @ clip.head_rotation[0].T + clip.head_translation[0])
    moving = rig[0].to_camera(clip.points3d)
    err = np.linalg.norm(take.points - expected, axis=2)
    assert np.median(err) < 0.5
    head = np.linalg.norm(moving - expected, axis=2)
    assert np.median(head) > 5 * np.median(err)  # the head did move
    assert len(take.meta["head_pose"]["rotvec"]) == 10


def test_markers_lost_in_one_camera_are_held_then_nan(clip, rig):
    from retarget.sources.video import VideoReader

    cal = rig_calibration(*rig)
    with VideoReader(clip.videos[0]) as a, VideoReader(clip.videos[1]) as b:
        frames = [(fa.copy(), fb.copy()) for (_, fa), (_, fb) in zip(a, b)]
    k = get_layout("dutreve21").index("lip_upper_center")
    for i in range(3, 8):  # covered in the right camera in frames 3-7
        x, y = np.rint(clip.points2d[i, 1, k]).astype(int)
        cv2.circle(frames[i][1], (x, y), 9, (120, 150, 200), -1)
    take = track_stereo_frames(frames, cal, layout="dutreve21", head_motion="keep", hold=2)
    p = take.points[:, k]
    assert np.isfinite(p[:5]).all() and np.isnan(p[5:8]).all() and np.isfinite(p[8:]).all()
    # Held frames pair the left camera's new position with the right one's last.
    for i in (3, 4):
        point = p[i].astype(np.float64)
        left_px = cv2.projectPoints(point, np.zeros(3), np.zeros(3), cal.K1, cal.d1)[0]
        right_px = cv2.projectPoints(point, cv2.Rodrigues(cal.R)[0], cal.T, cal.K2, cal.d2)[0]
        assert np.linalg.norm(left_px.ravel() - clip.points2d[i, 0, k]) < 1.0
        assert np.linalg.norm(right_px.ravel() - clip.points2d[2, 1, k]) < 1.0
    truth = rig[0].to_camera(clip.points3d[8, k])
    assert np.linalg.norm(p[8] - truth) < 1.0


def test_temporal_mean_steadies_still_markers(rig):
    frames, truth = still_frames(12, cameras=rig, noise=6.0, seed=3)
    cal = rig_calibration(*rig)
    raw = track_stereo_frames(frames, cal, layout="dutreve21", head_motion="keep")
    mean = track_stereo_frames(frames, cal, layout="dutreve21", head_motion="keep",
                               temporal_window=3)
    def spread(p):  # median over markers of the RMS distance from the marker's mean
        return np.median(np.sqrt((np.linalg.norm(p - p.mean(axis=0), axis=2) ** 2).mean(axis=0)))

    assert np.median(np.linalg.norm(raw.points - rig[0].to_camera(truth), axis=2)) < 0.5
    assert spread(mean.points[2:]) < 0.75 * spread(raw.points)


def test_identification_and_tracking_refuse_bad_input(tmp_path, clip, rig):
    cal = rig_calibration(*rig)
    skin = np.zeros((480, 640, 3), np.uint8) + np.array([120, 150, 200], np.uint8)
    with pytest.raises(RetargetError, match="0 markers matched"):
        track_stereo_frames([(skin, skin)], cal, layout="dutreve21")
    with pytest.raises(RetargetError, match="left is 640x480, right 320x240"):
        track_stereo_frames([(skin, skin[:240, :320])], cal, layout="dutreve21")
    with pytest.raises(RetargetError, match="head_motion"):
        track_stereo_frames([(skin, skin)], cal, layout="dutreve21", head_motion="drop")
    small = rig_calibration(*stereo_cameras(size=(320, 240)))
    with pytest.raises(RetargetError, match="calibration is for 320x240"):
        track_stereo_videos(*clip.videos, small, layout="dutreve21")
    with pytest.raises(RetargetError, match="does not exist"):
        track_stereo_videos(tmp_path / "none.mkv", clip.videos[1], cal, layout="dutreve21")
    with pytest.raises(RetargetError, match="does not exist"):
        track_stereo_videos(*clip.videos, tmp_path / "none.npz", layout="dutreve21")


def test_identification_names_every_marker_of_a_frame(clip, rig):
    from retarget.sources.video import VideoReader

    cal = rig_calibration(*rig)
    with VideoReader(clip.videos[0]) as a, VideoReader(clip.videos[1]) as b:
        (_, fa), (_, fb) = next(iter(a)), next(iter(b))
    colors = layout_marker_colors("dutreve21")
    palette = tuple(dict.fromkeys(colors))
    pl, pr, found, _ = identified_markers(cal, color_blobs(fa, palette), color_blobs(fb, palette),
                                          "dutreve21", colors)
    assert found.all()
    assert np.abs(pl - clip.points2d[0, 0]).max() < 0.5
    assert np.abs(pr - clip.points2d[0, 1]).max() < 0.5
