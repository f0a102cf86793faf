"""Markerless tracking of a video file in the page (tracking/videoTake.js): every frame of
the video is tracked, at the video's own frame rate, however busy the page is.

The videos are rendered here with OpenCV (VP8 and VP9 WebM, which Debian's Chromium
plays), so the number of frames and the rate are known exactly. A busy page is simulated
by a timer that blocks the page's main thread for most of every 200 ms: playback then
shows only some of the frames to the page, from which the rate used to be measured (a
30 fps video read as 29.97 fps here, as 2.4 fps on a loaded machine). A face video (the
first frames of ``../shared/data/video/face_expressions_480.mp4``, re-encoded at 24 fps)
goes through the Performance panel into a take (5 of its 36 frames before); that test
skips only when ../shared is absent.
"""

from __future__ import annotations

import mimetypes
from pathlib import Path

import cv2
import numpy as np
import pytest

from retarget.layouts import get_layout
from tests.e2e.conftest import Server, open_project
from tests.e2e.fake_camera import video_frames
from tests.waits import scaled_ms

SHARED = Path(__file__).resolve().parents[3] / "shared"
VIDEO = SHARED / "data" / "video" / "face_expressions_480.mp4"
FACE_FRAMES, FACE_FPS, FACE_SIZE = 36, 24, 240
BUSY_MS, EVERY_MS = 150, 200  # the page's main thread blocked for 150 ms of every 200 ms

needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason="../shared is absent")

# trackVideo, with the page's one tracker, on a video the test routes to the page, the
# page's main thread blocked for `busy` ms of every `every` ms (none when busy is 0); the
# result (points: whether all are NaN) and every progress call.
_TRACK = """async ([url, indices, busy, every]) => {
    const { trackVideo, tracker } = window.retargetTracking;
    const hog = busy > 0 ? setInterval(() => { const end = performance.now() + busy;
                                                while (performance.now() < end); }, every) : null;
    const progress = [];
    try {
        const out = await trackVideo(url, { layoutIndices: indices, tracker, onProgress: (p) => progress.push(p) });
        return { ...out, points: out.points.every(Number.isNaN), times: Array.from(out.times), progress };
    } finally {
        clearInterval(hog);
    }
}"""


def write_webm(path: Path, frames, fps: float, codec: str = "VP80") -> Path:
    """`frames` ((H, W, 3) uint8 BGR each) as a WebM file at `fps`."""
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*codec), fps, (w, h))
    assert writer.isOpened(), f"OpenCV cannot write {codec} WebM"
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


def numbered_frames(n: int, size: int = 96) -> list[np.ndarray]:
    """n frames, each with its number written on it (no face)."""
    frames = []
    for i in range(n):
        frame = np.full((size, size, 3), 40, np.uint8)
        cv2.putText(frame, str(i), (10, 60), cv2.FONT_HERSHEY_SIMPLEX, 1.2, (255, 255, 255), 2)
        frames.append(frame)
    return frames


def serve(path: Path):
    """A route handler answering with the file at `path`."""
    def answer(route):
        route.fulfill(body=path.read_bytes(), content_type=mimetypes.guess_type(path.name)[0] or "video/webm")
    return answer


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    srv = Server(tmp_path_factory.mktemp("video-take") / "data").start()
    yield srv
    srv.stop()


@pytest.fixture(scope="module")
def videos(tmp_path_factory) -> dict[str, tuple[Path, int, float]]:
    """name: (path, frames, fps) of the videos without a face."""
    folder = tmp_path_factory.mktemp("videos")
    return {
        "thirty.webm": (write_webm(folder / "thirty.webm", numbered_frames(30), 30), 30, 30.0),
        "twenty-five.webm": (write_webm(folder / "twenty-five.webm", numbered_frames(20), 25, "VP90"), 20, 25.0),
    }


@pytest.fixture(scope="module")
def tracking_page(browser, server, videos):
    """The app's tracker page (track.html: the tracking modules without the app) with one
    tracker loaded for the module, the videos routed to it under /test-video/; page
    errors fail the module."""
    page = browser.new_page()
    errors = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.on("console", lambda msg: errors.append(msg.text) if msg.type == "error" else None)
    for name, (path, _, _) in videos.items():
        page.route(f"{server.url}/test-video/{name}", serve(path))
    page.goto(f"{server.url}/static/track.html")
    page.wait_for_function("() => window.retargetTracking")
    yield page
    page.close()
    assert not errors, errors


@pytest.mark.parametrize("name, busy", [("thirty.webm", False), ("thirty.webm", True), ("twenty-five.webm", True)],
                         ids=["30 fps, idle page", "30 fps, busy page", "25 fps VP9, busy page"])
def test_every_frame_is_tracked_at_the_videos_rate(tracking_page, videos, name, busy):
    _, n_frames, fps = videos[name]
    result = tracking_page.evaluate(_TRACK, [f"/test-video/{name}", list(get_layout("dutreve21").mediapipe468),
                                             BUSY_MS if busy else 0, EVERY_MS])
    assert result["fps"] == fps
    assert result["n_frames"] == n_frames and result["faces"] == 0 and result["points"]  # all NaN
    # each frame once, in order, at its own presentation time (WebM: whole milliseconds)
    assert np.allclose(result["times"], np.arange(n_frames) / fps, atol=1e-3)
    assert [p["done"] for p in result["progress"]] == list(range(1, n_frames + 1))
    assert {p["total"] for p in result["progress"]} == {n_frames}
    assert (result["width"], result["height"]) == (96, 96)


@pytest.mark.parametrize("kind", ["VP8 WebM", "MPEG-4 MP4", "H.264 MP4", "cut WebM", "text"])
def test_the_container_states_the_frames_and_their_rate(tracking_page, server, tmp_path, kind):
    """containerFrames reads the file's index, without decoding: OpenCV's count and rate
    are the truth (the MPEG-4 Part 2 file is one Chromium cannot play; the index is read all
    the same)."""
    frames = numbered_frames(40)
    if kind == "H.264 MP4":
        if not VIDEO.exists():
            pytest.skip("../shared is absent")
        path = VIDEO
    elif kind == "MPEG-4 MP4":
        path = tmp_path / "clip.mp4"
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 50, (96, 96))
        for frame in frames:
            writer.write(frame)
        writer.release()
    elif kind == "text":
        path = tmp_path / "notes.webm"
        path.write_text("not a video at all\n" * 50)
    else:
        path = write_webm(tmp_path / "clip.webm", frames, 24)
        if kind == "cut WebM":
            data = path.read_bytes()
            path.write_bytes(data[:len(data) // 2])
    tracking_page.route(f"{server.url}/test-file/{path.name}", serve(path))
    listed = tracking_page.evaluate("""async (url) => {
        const { containerFrames } = await import('/static/js/tracking/containerFrames.js');
        return containerFrames(await (await fetch(url)).blob());
    }""", f"/test-file/{path.name}")
    if kind == "text":
        assert listed is None
        return
    reader = cv2.VideoCapture(str(path))
    decoded = 0
    while reader.read()[0]:
        decoded += 1
    if kind == "cut WebM":
        # the blocks before the cut, the last of which OpenCV may not decode whole
        assert 0 < decoded <= listed["count"] <= decoded + 1 and listed["count"] < len(frames)
    else:
        assert listed["count"] == decoded == int(reader.get(cv2.CAP_PROP_FRAME_COUNT))
    assert listed["fps"] == reader.get(cv2.CAP_PROP_FPS) and listed["start"] == 0


@needs_shared
def test_a_face_video_tracked_in_the_panel_is_a_take_of_all_its_frames(server, page, tmp_path):
    path = write_webm(tmp_path / "performer.webm", video_frames(VIDEO, FACE_FRAMES, FACE_SIZE), FACE_FPS)
    sample = next(p for p in server.api("GET", "/api/projects") if p["rig"])
    open_project(page, server, sample["id"])
    before = {t["id"] for t in server.api("GET", f"/api/projects/{sample['id']}/takes")}
    page.select_option("#video-method", "markerless")
    page.set_input_files("#video-file", str(path))
    page.wait_for_selector("#take-list li:has-text('performer')", timeout=scaled_ms(120_000))
    [take] = [t for t in server.api("GET", f"/api/projects/{sample['id']}/takes") if t["id"] not in before]
    assert take["n_frames"] == FACE_FRAMES and take["fps"] == FACE_FPS
    assert take["duration"] == pytest.approx((FACE_FRAMES - 1) / FACE_FPS)
    note = page.inner_text("#source-note")
    assert f"{FACE_FRAMES} frames at {FACE_FPS} fps, a face in 100 %" in note, note
    assert page.inner_text("#error").strip() == ""
