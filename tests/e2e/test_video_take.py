"""Markerless tracking of a video file from the Performance panel: the page uploads the
video, a server job tracks it with the native face mesh (``POST .../takes/track``), the
bar shows the upload and then the job's progress, and the take holds every frame of the
video at the container's rate, with the very points the library finds in that file. A
video over the server's frame limit is refused with the reason before any job; a file
that is not a video and a video without a face are in test_performance_panel.py and
test_take_sources.py.

The face video is the built-in face opening its jaw (`retarget.testing.face_video`),
encoded as VP9 WebM at 25 fps, so that neither the codec nor the rate is the default.
"""

from __future__ import annotations

import io
from pathlib import Path

import cv2
import numpy as np
import pytest

from retarget.sources.facemesh_video import track_video_facemesh
from retarget.testing.face_video import render_face_video
from tests.e2e.conftest import Server, open_project, sample_copy
from tests.e2e.test_performance_panel import WATCH_PROGRESS, assert_upload_then_job
from tests.waits import scaled_ms

FACE_FRAMES, FACE_FPS, FACE_SIZE = 12, 25.0, 320
MAX_FRAMES = 30  # the module server's --max-video-frames


def write_webm(path: Path, frames, fps: float, codec: str = "VP80") -> Path:
    """`frames` ((H, W, 3) uint8 BGR each) as a WebM file at `fps`."""
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*codec), fps, (w, h))
    assert writer.isOpened(), f"OpenCV cannot write {codec} WebM"
    for frame in frames:
        writer.write(frame)
    writer.release()
    return path


@pytest.fixture(scope="module")
def server(tmp_path_factory, sample_data_dir):
    srv = Server(sample_copy(sample_data_dir, tmp_path_factory.mktemp("video-take") / "data"),
                 args=("--max-video-frames", str(MAX_FRAMES))).start()
    yield srv
    srv.stop()


@pytest.fixture(scope="module")
def face_video(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("face") / "performer.webm"
    render_face_video(path, FACE_FRAMES, size=FACE_SIZE, fps=FACE_FPS, codec="VP90")
    return path


def _sample(server) -> dict:
    return next(p for p in server.api("GET", "/api/projects") if p["rig"])


def test_a_face_video_is_tracked_by_a_server_job_into_a_take_of_all_its_frames(server, page, face_video):
    sample = _sample(server)
    open_project(page, server, sample["id"])
    before = {t["id"] for t in server.api("GET", f"/api/projects/{sample['id']}/takes")}
    page.select_option("#video-method", "markerless")
    page.evaluate(WATCH_PROGRESS)
    page.set_input_files("#video-file", str(face_video))
    page.wait_for_selector("#take-list li.selected:has-text('performer')", timeout=scaled_ms(120_000))
    page.wait_for_selector("#source-progress", state="hidden")
    [take] = [t for t in server.api("GET", f"/api/projects/{sample['id']}/takes") if t["id"] not in before]
    assert (take["n_frames"], take["fps"], take["n_points"], take["dims"]) == (FACE_FRAMES, FACE_FPS, 68, 3)
    assert take["duration"] == pytest.approx((FACE_FRAMES - 1) / FACE_FPS)
    assert (take["source"], take["layout"]) == ("video: performer.webm", sample["landmarks"]["layout"])
    assert page.input_value("#source-select") == "take"
    note = page.inner_text("#source-note")
    assert note == f'Tracked "performer": {FACE_FRAMES} frames at {FACE_FPS:g} fps, a face in 100 % of them.', note
    assert page.inner_text("#error").strip() == ""
    assert page.is_enabled("#video-file") and page.is_enabled("#take-file")

    assert_upload_then_job(page)

    # the points are the library's on the same file
    stored = np.load(io.BytesIO(server.read(f"/api/projects/{sample['id']}/takes/{take['id']}/points")))
    expected = track_video_facemesh(face_video, layout=take["layout"]).points
    assert stored.shape == expected.shape and np.isfinite(stored).all()
    np.testing.assert_allclose(stored, expected, atol=1e-3)


def test_a_video_over_the_servers_frame_limit_says_so(server, page, tmp_path):
    path = tmp_path / "long.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30, (64, 64))
    for i in range(MAX_FRAMES + 10):
        writer.write(np.full((64, 64, 3), 5 * i, np.uint8))
    writer.release()
    sample = _sample(server)
    before = server.api("GET", f"/api/projects/{sample['id']}/takes")
    open_project(page, server, sample["id"])
    page.select_option("#video-method", "markerless")
    page.set_input_files("#video-file", str(path))
    page.wait_for_function("() => !document.getElementById('error').hidden", timeout=scaled_ms(60_000))
    shown = page.inner_text("#error-text")
    assert (f"video 'long.avi' has {MAX_FRAMES + 10} frames (1.33 s at 30 fps); the server tracks at "
            f"most {MAX_FRAMES} frames (1 s) of a video: cut it into shorter takes") in shown, shown
    page.wait_for_selector("#source-progress", state="hidden")
    assert page.is_enabled("#video-file") and page.inner_text("#source-note") == ""
    assert server.api("GET", f"/api/projects/{sample['id']}/takes") == before
