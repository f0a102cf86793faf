"""Live single-colour stickers (retarget.sources.stereo_live_stickers, issue 17 §3): the
rendered sticker take of test_stereo_stickers against its truth, the offline columns, a
sticker that appears late, and columns named by place after a layout made from a take."""

from __future__ import annotations

import numpy as np
import pytest

from retarget.custom_layouts import layout_from_spec, take_reference
from retarget.errors import RetargetError
from retarget.sample_face import sample_face
from retarget.sources.stereo import track_stereo_frames
from retarget.sources.stereo_live_stickers import LiveStickerTracker, by_name
from retarget.sources.take import marker_names
from retarget.sources.video import VideoReader
from retarget.testing.stereo_rig import (
    FACE_CENTRE,
    MM_PER_CM,
    STICKER_ANCHORS,
    render_sticker_video,
    rig_calibration,
    sticker_scores,
    sticker_vertices,
    webcam_cameras,
)
from tests.unit.test_stereo_stickers import _disc_frames


def _padded(rows: list[np.ndarray]) -> np.ndarray:
    """(F, M, 3) from per-pair (M_f, 3) rows, M the last (columns only grow)."""
    m = len(rows[-1])
    return np.stack([np.pad(r, ((0, m - len(r)), (0, 0)), constant_values=np.nan) for r in rows])


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    """45 pairs of the hard sticker material (MPEG-4, blur, noise, head turns), seed 1."""
    truth = render_sticker_video(tmp_path_factory.mktemp("live-stickers") / "take.mp4", n_frames=45, seed=1)
    with VideoReader(truth.videos[0]) as a, VideoReader(truth.videos[1]) as b:
        frames = [(left, right) for (_, left), (_, right) in zip(a, b)]
    return truth, rig_calibration(*truth.cameras), frames


def test_live_stickers_are_the_offline_columns_in_a_steady_head_frame(take):
    truth, cal, frames = take
    # A set-up span longer than the take: the columns alone, as offline.
    columns = LiveStickerTracker(cal, setup_seconds=60.0)
    for i, pair in enumerate(frames):
        assert np.isnan(columns.push(*pair, i / 30)).all()
    # The tracker's own columns over the take, in their stable order (what the offline
    # take starts from, before its own clean-up of split tracks).
    offline = columns.tracks.points()
    assert columns.names_ == marker_names(offline.shape[1]) and len(columns.names_) == 13
    assert not columns.anchored_ and columns.setup_error_.startswith("set-up span")

    cams, out = [], []
    first = sticker_scores(offline, offline, truth)
    anchors = [columns.names_[m] for m in range(13) if first["owner"][m] < STICKER_ANCHORS]
    live = LiveStickerTracker(cal, anchors=anchors, setup_seconds=0.5)
    for i, pair in enumerate(frames):
        out.append(live.push(*pair, i / 30))
        cams.append(live.camera_)
    cams, out = _padded(cams), _padded(out)
    # Triangulated as offline, column for column (a late sticker's first pairs, before its
    # track is confirmed, are known offline only).
    seen = np.isfinite(cams)
    np.testing.assert_allclose(cams[seen], offline[seen], atol=1e-3)
    assert (np.isfinite(offline) & ~seen).sum() <= 3 * 3 * 13
    # Nothing through the set-up span (0.5 s from the first pair), then the head frame.
    assert np.isnan(out[:15]).all() and live.anchored_ and sorted(live.names_[a] for a in live.anchors_) == anchors
    scores = sticker_scores(cams, out, truth)
    assert scores["switches"] == 0
    err = scores["error"][15:]
    err = err[np.isfinite(err)]
    assert err.size > 0.7 * 30 * 13   # 293: the temples turn away
    # 1.61 / 5.35 mm in the 30 pairs after a 0.5 s set-up, the depth window seeded by the
    # span (2.63 / 7.32 with the pose fitted to the anchors alone and the window empty;
    # offline, over the whole take with centred windows, the same pairs: 1.17 / 4.59);
    # bench/stereo_live.py --stickers has the figures of longer takes.
    assert np.median(err) < 2.0 and np.percentile(err, 95) < 6.5


def test_a_sticker_that_appears_late_gets_a_column_and_the_head_motion_goes():
    cams = webcam_cameras()
    cal = rig_calibration(*cams)
    n = 40
    base = FACE_CENTRE + np.array([[-60, 30, -40], [60, 30, -40], [0, 60, 10], [0, 25, 25],
                                   [0, -30, 20], [45, -5, 0]], dtype=np.float64)
    points = np.repeat(base[None], n, axis=0)
    points[..., 1] += np.linspace(0, 20, n)[:, None]   # the head nods, the face is still
    points[:20, 5] = np.nan                            # a cheek sticker under a finger
    frames = _disc_frames(cams, points)
    # The columns run top to bottom: forehead, the temples, nose, chin; the cheek last.
    tracker = LiveStickerTracker(cal, anchors=["m01", "m02", "m03", "m04"], setup_seconds=0.2,
                                 depth_window=9, history=30)
    out = [tracker.push(*pair, i / 30) for i, pair in enumerate(frames)]
    assert [len(o) for o in out[:20]] == [5] * 20 and [len(o) for o in out[25:]] == [6] * 15
    assert tracker.names_ == ("m01", "m02", "m03", "m04", "m05", "m06")
    assert tracker.tracks.n_frames <= 30 + 30 // 4   # the history a session keeps stays bounded
    head = _padded(out)
    assert np.isnan(head[:6]).all() and np.isfinite(head[8:, :5]).all() and np.isfinite(head[25:, 5]).all()
    # A still face in a nodding head: the head frame holds every point still.
    still = head[8:, :5] - head[8, :5]
    assert np.linalg.norm(still, axis=2).max() < 2.0
    moved = np.linalg.norm(tracker.camera_[:5] - cams[0].to_camera(points[8, [2, 0, 1, 3, 4]]), axis=1)
    assert moved.min() > 10   # the camera-frame points did move
    # Columns to a layout's points by name; a point no column has is lost.
    mapped = by_name(out[-1], tracker.names_, ["m06", "nose", "m01"])
    np.testing.assert_array_equal(mapped[[0, 2]], out[-1][[5, 0]])
    assert np.isnan(mapped[1]).all()


def test_a_jaw_dropping_fast_is_followed_without_lag():
    # The chin drops 6 mm a pair (a jaw opening at 30 fps, as issue 17's take talks):
    # Woodward's causal 3-frame mean would trail it by a pair, 6 mm; the default has none.
    cams = webcam_cameras()
    cal = rig_calibration(*cams)
    n = 30
    base = FACE_CENTRE + np.array([[-60, 30, -40], [60, 30, -40], [0, 60, 10], [0, 25, 25],
                                   [0, -45, 20]], dtype=np.float64)
    points = np.repeat(base[None], n, axis=0)
    drop = np.clip(np.arange(n) - 15, 0, 10) * 6.0   # still through the set-up, then 60 mm down
    points[:, 4, 1] -= drop
    frames = _disc_frames(cams, points)
    anchors = ["m01", "m02", "m03", "m04"]   # forehead, temples, nose: top to bottom
    moved = {}
    for window in (1, 3):
        tracker = LiveStickerTracker(cal, anchors=anchors, setup_seconds=0.2, temporal_window=window)
        head = _padded([tracker.push(*pair, i / 30) for i, pair in enumerate(frames)])
        assert tracker.names_[4] == "m05"
        moved[window] = np.linalg.norm(head[:, 4] - head[14, 4], axis=1)
    assert LiveStickerTracker(cal).temporal_window == 1
    np.testing.assert_allclose(moved[1][16:26], drop[16:26], atol=1.5)
    assert (drop[17:26] - moved[3][17:26]).min() > 5.0   # the mean's lag, for the record


def _turned(points: np.ndarray, yaw: float, roll: float) -> np.ndarray:
    """(N, 3) world mm `points` turned `yaw` degrees about the vertical through the face
    centre, then rolled `roll` about the line of sight."""
    a, b = np.radians(yaw), np.radians(roll)
    turn = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    tilt = np.array([[np.cos(b), -np.sin(b), 0], [np.sin(b), np.cos(b), 0], [0, 0, 1]])
    return (points - FACE_CENTRE) @ (tilt @ turn).T + FACE_CENTRE


def _owners(camera_points: np.ndarray, truth_camera: np.ndarray) -> np.ndarray:
    """(M,) the truth sticker (rows of (N, 3)) nearest each column's point (M, 3), mm apart
    at most 5 (asserted: the column follows it)."""
    d = np.linalg.norm(camera_points[:, None] - truth_camera[None], axis=2)
    assert d.min(axis=1).max() < 5.0
    return d.argmin(axis=1)


def _still_take_layout():
    """The 13 stickers of the sticker material on the still built-in face, and a layout
    m01..m13 with their places made from a take of them (every one in view, the face
    still): (cameras, calibration, (13, 3) world mm stickers, the take, the layout, (13,)
    each take column's sticker)."""
    cams = webcam_cameras()
    cal = rig_calibration(*cams)
    face = sample_face(1)
    stickers = face.vertices[sticker_vertices(face)] * MM_PER_CM
    take = track_stereo_frames(_disc_frames(cams, np.repeat(stickers[None], 10, axis=0)), cal, layout=None)
    layout = layout_from_spec({"points": [{"name": name, "region": "cheeks", "side": "center", "reference": xyz}
                                          for name, xyz in zip(take.names, take_reference(take))]})
    took = _owners(take.points[-1], cams[0].to_camera(stickers))   # head frame = camera frame: still
    return cams, cal, stickers, take, layout, took


def test_live_columns_are_named_by_place_as_the_stereo_take_that_made_the_layout():
    # A layout made from a take of the 13 stickers on the still face (`_still_take_layout`).
    cams, cal, stickers, take, layout, took = _still_take_layout()
    # Live, the head turned (15 to 23 degrees) and rolled 10, and the first sticker the take met (the
    # forehead's, the top one) under a finger for the first 12 pairs: the tracker meets
    # the stickers in another order, and the forehead's last.
    n = 40
    live = np.stack([_turned(stickers, 15.0 + 0.2 * i, -10.0) for i in range(n)])
    live[:12, took[0]] = np.nan
    tracker = LiveStickerTracker(cal, setup_seconds=0.2, depth_window=9, layout=layout)
    out = [tracker.push(*pair, i / 30) for i, pair in enumerate(_disc_frames(cams, live))]
    owners = _owners(tracker.camera_, cams[0].to_camera(live[-1]))
    assert tracker.names_ != take.names[:len(tracker.names_)]          # met in another order
    assert tracker.names_ == tuple(take.names[list(took).index(k)] for k in owners)   # named by place
    # The layout's points take the columns of their stickers (the forehead's too, named
    # once placed after it appeared).
    mapped = by_name(out[-1], tracker.names_, layout.point_names)
    assert np.isfinite(mapped).all()
    # A layout that marks its head anchors (temples, forehead, nose bridge) gives them to
    # the tracker by place: those seen in the set-up span, then the forehead once named.
    spec = layout.spec()
    for k, point in enumerate(spec["points"]):
        point["anchor"] = bool(took[k] < STICKER_ANCHORS)
    tracker = LiveStickerTracker(cal, setup_seconds=0.2, depth_window=9, layout=layout_from_spec(spec))
    anchors = []
    for i, pair in enumerate(_disc_frames(cams, live)):
        tracker.push(*pair, i / 30)
        anchors.append(tracker.anchors_)
    owners = _owners(tracker.camera_, cams[0].to_camera(live[-1]))
    assert sorted(owners[anchors[10]]) == sorted({0, 1, 2, 3} - {took[0]})
    assert sorted(owners[anchors[-1]]) == [0, 1, 2, 3]


def test_a_column_first_placed_off_its_sticker_is_named_once_its_place_firms_up():
    # A temple turning into view is half hidden for its first pairs: its triangulation
    # is millimetres to centimetres off, and so is the place its first registrations
    # give, past the naming gate. Here a cheek sticker hidden for the first 12 pairs shows
    # 30 mm too deep for its first 8 (along the left camera's line of sight: the same
    # image there, the depth wrong), then where it is. Its column is left unnamed at
    # first and named once its place (the median of its registrations) is right. Before,
    # a column was matched once, and this one stayed unnamed: its point was never driven
    # (the browser e2e's live session waited for it to its end).
    cams, cal, stickers, take, layout, took = _still_take_layout()
    cheek = STICKER_ANCHORS + 2          # a sticker that is no head anchor
    n, hidden, off = 44, 12, 8
    live = np.stack([_turned(stickers, 10.0 + 0.2 * i, -5.0) for i in range(n)])
    live[:hidden, cheek] = np.nan
    ray = live[hidden:hidden + off, cheek] - cams[0].center
    live[hidden:hidden + off, cheek] += 30.0 * ray / np.linalg.norm(ray, axis=1, keepdims=True)
    tracker = LiveStickerTracker(cal, setup_seconds=0.2, depth_window=9, layout=layout)
    names = []
    for i, pair in enumerate(_disc_frames(cams, live)):
        tracker.push(*pair, i / 30)
        names.append(tracker.names_)
    owners = _owners(tracker.camera_, cams[0].to_camera(live[-1]))
    column = int(np.flatnonzero(owners == cheek)[0])
    wanted = take.names[list(took).index(cheek)]
    assert names[hidden + off][column] == ""          # placed off its sticker: left unnamed
    assert tracker.names_[column] == wanted            # then named as its sticker
    assert tracker.names_ == tuple(take.names[list(took).index(k)] for k in owners)


def test_bad_inputs_are_refused_precisely():
    cal = rig_calibration(*webcam_cameras())
    for anchors, match in ((["m01", "m02"], "at least 3 different"), (["m01", "m02", "m01"], "at least 3"),
                           (["m01", "m02", "nose"], "named m01..m99"), ([0, 1, 120], "index is 0..98")):
        with pytest.raises(RetargetError, match=match):
            LiveStickerTracker(cal, anchors=anchors)
    with pytest.raises(RetargetError, match="unknown sticker colour"):
        LiveStickerTracker(cal, "teal-ish")
    tracker = LiveStickerTracker(cal)
    with pytest.raises(RetargetError, match="is 320x240, the calibration is for 640x480"):
        small = np.zeros((240, 320, 3), np.uint8)
        tracker.push(small, small, 0.0)
    blank = np.zeros((480, 640, 3), np.uint8)
    assert np.isnan(tracker.push(blank, blank, 1.0)).all() and not tracker.identified_
    with pytest.raises(RetargetError, match="capture times must increase"):
        tracker.push(blank, blank, 1.0)
