"""Markerless tracking: `track_video_markerless` (the command line's path: OpenCV decoding,
the browser's face-mesh tracker in headless Chromium) on a real face video and on a
generated one without a face, its refusals, and the web app's own video path
(`trackVideo`, the page decoding the video) against it.

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

ROOT = Path(__file__).resolve().parents[2]
SHARED = Path(__file__).resolve().parents[3] / "shared"
VIDEO = SHARED / "data" / "video" / "face_expressions_480.mp4"
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--ignore-gpu-blocklist"]
CLIP = 60
CLOSED, OPEN = range(0, 48), range(50, 60)

needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason="../shared is absent")


@pytest.fixture(scope="module")
def clip():
    """The first 60 frames of the real video through the command line's path, ibug68,
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


# -- the web app's video path: the page decodes and steps the <video> itself -------------

_ORIGIN = "http://tracking.localhost"
_PACKAGE = ROOT / "web" / "node_modules" / "@mediapipe" / "face_mesh"
_TYPES = {".js": "text/javascript", ".html": "text/html", ".wasm": "application/wasm",
          ".mp4": "video/mp4", ".webm": "video/webm"}


@pytest.fixture(scope="module")
def tracking_page():
    """web/static/track.html in Chromium, its files and /video/<name> (set
    `page.videos[name] = path`) answered by request interception."""
    from playwright.sync_api import sync_playwright

    videos: dict[str, Path] = {}

    def answer(route):
        path = route.request.url[len(_ORIGIN):]
        if path.startswith("/video/"):
            file = videos.get(path[len("/video/"):])
        elif path.startswith("/vendor/@mediapipe/face_mesh/"):
            file = _PACKAGE / path[len("/vendor/@mediapipe/face_mesh/"):]
        else:
            file = ROOT / "web" / path.lstrip("/")
        if file is None or not file.is_file():
            return route.fulfill(status=404)
        route.fulfill(body=file.read_bytes(), content_type=_TYPES.get(file.suffix, "application/octet-stream"))

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page()
        errors = []
        page.on("pageerror", lambda exc: errors.append(str(exc)))
        page.route(f"{_ORIGIN}/**", answer)
        page.goto(f"{_ORIGIN}/static/track.html")
        page.wait_for_function("() => window.retargetTracking")
        page.videos = videos
        yield page
        browser.close()
    assert not errors, errors


_TRACK_VIDEO = """async ([url, indices, maxFrames]) => {
    const { trackVideo, tracker } = window.retargetTracking;  // one model load for the module
    const out = await trackVideo(url, { layoutIndices: indices, maxFrames: maxFrames ?? Infinity, tracker });
    return { ...out, times: Array.from(out.times),
             points: Array.from(out.points, (v) => (Number.isNaN(v) ? null : v)) };
}"""


def _track_in_page(page, name, path, layout, max_frames=None):
    page.videos[name] = path
    result = page.evaluate(_TRACK_VIDEO, [f"/video/{name}", list(get_layout(layout).mediapipe468), max_frames])
    points = np.array([np.nan if v is None else v for v in result["points"]], dtype=np.float32)
    return result, points.reshape(result["n_frames"], result["n_points"], 3)


@needs_shared
def test_the_page_decoding_finds_the_command_lines_frames_and_rate(clip, tracking_page):
    """The browser's <video> decoding (H.264 in Chromium) and OpenCV's reach the same
    frames: the landmarks agree to a fraction of a pixel. The frame rate, which a <video>
    does not state, is measured from playback."""
    take, _ = clip
    result, points = _track_in_page(tracking_page, "face.mp4", VIDEO, "ibug68", max_frames=12)
    assert result["fps"] == 30 and result["n_frames"] == 12 and result["faces"] == 12
    assert np.allclose(result["times"], np.arange(12) / 30, atol=1e-3)
    assert (result["width"], result["height"]) == (480, 480)
    gap = np.linalg.norm(points[..., :2] - take.points[:12, :, :2], axis=-1)
    assert np.median(gap) < 0.75 and gap.max() < 5


def test_the_page_decoding_reads_a_video_to_its_end(tracking_page, noise_video):
    result, points = _track_in_page(tracking_page, "noise.webm", noise_video, "dutreve21")
    assert result["n_frames"] == 8 and result["faces"] == 0 and result["fps"] == 30
    # WebM times are whole milliseconds
    assert np.allclose(result["times"], np.arange(8) / 30, atol=1e-3)
    assert points.shape == (8, 21, 3) and np.isnan(points).all()
