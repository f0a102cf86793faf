"""Ring markers composited onto the real face video (`bench/markers_real.py`, issue 17 §1)
and tracked without a layout, on the clip's first 38 frames: the markers found in the first
frame followed sub-pixel on the drawn centres, with no identity switch. Not met yet, so
not asserted (issue 17's closing note): every marker facing the camera found (jaw_left,
50-65 degrees off the view on the shadow side, never starts a track: `ring_contrast`
samples the ring at a fixed radius, which on a foreshortened ring lies on the skin).

The 38 frames are the video's first 46 less its repeated frames (`repeated_frames`: 25 fps
content at 30 fps); the span ends before the first fast jaw drop (source frames 48-51: the
lower lip moves 8-14 px a frame). The first 150 frames take in the first jaw drops: there
the tracks must stay few and on their markers (before the lost tracks were carried by their
neighbours' fit and kept off faint peaks away from their last bright sighting: 43 tracks,
70 identity switches, 76.7 % within 3 px; before the whole-clip pass joined the tracks that
took a marker in turns, 30, 1, 90.5 %; before the markers' shape model placed lost
tracks, 27, 1, 92.7 %; before a long-lost track's guess was doubted, 28, 1, 93.1 %; now
27, 2, 93.8 %). The real video
is ``../shared/data/video/face_expressions_480.mp4``; the test skips only when ../shared is
absent.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

SHARED = Path(__file__).resolve().parents[3] / "shared"
VIDEO = SHARED / "data" / "video" / "face_expressions_480.mp4"
FRAMES = 38
JAW_FRAMES = 150


def _tracked(tmp_path_factory, frames: int):
    """(scores as `bench.markers_real.scores` gives them, the truth) for the first `frames`
    frames, markers of 1.5 mm radius, JPEG q40 + MPEG-4."""
    if not SHARED.is_dir():
        pytest.skip("../shared is absent")
    import cv2

    from bench.markers_real import marked_video, scores
    from retarget.sources.markers import track_marker_video

    cv2.setNumThreads(1)
    path = tmp_path_factory.mktemp("marked") / "marked.mp4"
    truth = marked_video(path, frames, radius_mm=1.5, quality=40, seed=0, video=VIDEO)
    take = track_marker_video(path, layout=None)
    points = take.points.astype(np.float64)
    points[..., 1] = take.meta["size"][1] - points[..., 1]      # y down, as the truth
    return scores(points, truth), truth


@pytest.fixture(scope="module")
def tracked(tmp_path_factory):
    """`_tracked` on the first 38 frames (before the first fast jaw drop)."""
    return _tracked(tmp_path_factory, FRAMES)


@pytest.fixture(scope="module")
def tracked_jaw(tmp_path_factory):
    """`_tracked` on the first 150 frames (fast jaw drops)."""
    return _tracked(tmp_path_factory, JAW_FRAMES)


def test_the_composite_is_the_material_it_claims(tracked):
    """27 markers about 5.3 px across (1.5 mm at the face's ~1.8 px/mm), nearly all
    visible, most facing the camera."""
    s, truth = tracked
    assert truth.points2d.shape == (FRAMES, 1, 27, 2)
    assert 4.5 < np.median(2 * truth.ring_px) < 6.0
    assert s["visible"].mean() > 0.9 and s["clear"].mean() > 0.85


def _shares(s):
    """(N,) share of each marker's clear-view frames (facing the camera within 60
    degrees) its track holds, NaN for markers in clear view in fewer than 5 frames."""
    clear = s["clear"]
    held = (np.isfinite(s["err"]) & clear).sum(0) / np.maximum(clear.sum(0), 1)
    return np.where(clear.sum(0) >= 5, held, np.nan)


def test_markers_found_in_the_first_frame_are_followed_on_their_own_marker(tracked):
    """Every marker tracked in the first frame: held in >= 95 % of its clear-view frames,
    median <= 0.2 px and >= 97 % within 3 px over them; at most 3 of the visible
    markers missed in the first frame; no track changes marker."""
    s, _ = tracked
    first = np.isfinite(s["err"][0]) & s["visible"][0]
    share = _shares(s)[first]
    assert np.nanmin(share) >= 0.95, share
    e = s["err"][:, first][s["clear"][:, first]]
    assert np.median(e) <= 0.2, np.median(e)
    assert (e < 3.0).mean() >= 0.97, (e < 3.0).mean()
    assert s["found_first"] >= s["visible_first"] - 3, (s["found_first"], s["visible_first"])
    assert s["switches"] == 0


def test_tracks_hold_their_markers_through_fast_jaw_drops(tracked_jaw):
    """Through the jaw drops (the lower lip 8-14 px a frame, its neighbours still): at most
    28 tracks for the 27 markers, at most 2 identity switches, >= 92 % of the clear-view
    marker-frames within 3 px (the module doc has the figures before)."""
    s, _ = tracked_jaw
    e = s["err"][s["clear"]]
    assert s["tracks"] <= 28, s["tracks"]
    assert s["switches"] <= 2, s["switches"]
    assert (e < 3.0).mean() >= 0.92, (e < 3.0).mean()


def test_repeated_frames_are_every_sixth_when_that_phase_stands_still():
    """25 fps content at 30 fps: the frames after steps 2, 8, 14, ... repeat; steps with
    no such phase (or too few of them) give none."""
    from bench.markers_real import repeated_frames

    rng = np.random.default_rng(0)
    steps = rng.uniform(0.5, 3.0, 60)
    steps[2::6] = rng.uniform(0.0, 0.2, 10)
    assert repeated_frames(steps).tolist() == list(range(3, 61, 6))
    assert repeated_frames(rng.uniform(0.5, 3.0, 60)).size == 0
    assert repeated_frames(steps[:8]).size == 0
