"""Live stereo end to end: Chromium's fake camera plays a rendered stereo pair (both views
side by side in one file, the panel's "one camera, side by side" mode), the Live stereo
panel sends the pairs as JPEGs, the server tracks and triangulates the colour markers and
the face moves in the page: the sample face with Dutreve's 21 points, every one of which
carries a sticker both cameras see (the live neutral needs each point seen).

Chromium's fake capture device plays one file, so the two cameras are the two halves of
its frame. The calibration is made beforehand over the same socket from rendered
checkerboard views of the same rig (the API tests check its counting and accuracy); the
page shows it and starts on it.
"""

from __future__ import annotations

import json

import cv2
import httpx
import numpy as np
import pytest
from websockets.sync.client import connect

from retarget.layouts import get_layout
from retarget.sources.video import VideoReader
from retarget.testing.stereo_rig import checkerboard_views, render_stereo_video, stereo_cameras
from server.wire import encode_stereo_pair
from tests.e2e.conftest import Server, open_project, wait_face_moves, chromium
from tests.e2e.fake_camera import stereo_loop_y4m
from tests.waits import scaled, scaled_ms, wait_job

FPS = 30


def jpeg(image: np.ndarray) -> bytes:
    return cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes()


@pytest.fixture(scope="module")
def material(tmp_path_factory):
    """The fake camera's file (dutreve21's colour markers filmed by the rig, the two views
    side by side) and the rig's checkerboard views."""
    folder = tmp_path_factory.mktemp("stereo-live")
    rig = stereo_cameras()
    truth = render_stereo_video(folder / "take.mkv", n_frames=12, cameras=rig, start=0.8, seed=2)
    with VideoReader(truth.videos[0]) as a, VideoReader(truth.videos[1]) as b:
        camera = stereo_loop_y4m(folder / "pair.y4m", [(left, right) for (_, left), (_, right) in zip(a, b)], FPS)
    return camera, checkerboard_views(*rig, n_views=10, seed=4)


@pytest.fixture(scope="module")
def server(module_server):
    """One server for the module (with the sample project)."""
    return module_server


@pytest.fixture(scope="module")
def browser(material):
    """Chromium whose one camera plays the side-by-side pair, granted without asking."""
    yield from chromium(material[0])


def dutreve21_project(server: Server) -> str:
    """A rigged copy of the sample face with the 21 points of dutreve21, the stickers' layout."""
    sample = next(p for p in server.api("GET", "/api/projects") if p["rig"])
    layout = get_layout("dutreve21")
    picked = {"layout": "dutreve21", "vertex_indices": [
        server.api("GET", f"/api/projects/{sample['id']}/landmarks")["vertex_indices"][i] for i in layout.ibug68]}
    pid = server.api("POST", "/api/projects", {"name": "stereo live"})["id"]
    mesh = server.read(f"/api/projects/{sample['id']}/mesh")
    assert httpx.put(f"{server.url}/api/projects/{pid}/mesh", files={"file": ("face.obj", mesh)},
                     timeout=scaled(60)).status_code == 200
    server.api("PUT", f"/api/projects/{pid}/landmarks", picked)
    job = server.api("POST", f"/api/projects/{pid}/rig", {"method": "ellipsoid"})
    assert wait_job(server, job["id"], timeout_s=120, poll_s=0.1)["state"] == "done"
    return pid


def calibrate(server: Server, project_id: str, boards) -> dict:
    """The rig's calibration made over the stereo socket from its checkerboard views."""
    lefts, rights, _ = boards
    url = server.url.replace("http://", "ws://") + f"/api/projects/{project_id}/stereo/live"
    with connect(url, open_timeout=scaled(30)) as ws:
        assert json.loads(ws.recv(timeout=scaled(30)))["type"] == "hello"
        ws.send(json.dumps({"type": "calibrate", "pattern": {"cols": 9, "rows": 6, "square": 25},
                            "size": [640, 480]}))
        ws.recv(timeout=scaled(30))
        for i, (left, right) in enumerate(zip(lefts, rights)):
            ws.send(encode_stereo_pair(jpeg(left), jpeg(right), frame_index=i, capture_time=float(i)))
            assert json.loads(ws.recv(timeout=scaled(30)))["good"]
        ws.send(json.dumps({"type": "calibration_save"}))
        return json.loads(ws.recv(timeout=scaled(60)))


def test_two_views_of_one_fake_camera_drive_the_face(server, material, page):
    pid = dutreve21_project(server)
    assert calibrate(server, pid, material[1])["type"] == "calibrated"
    open_project(page, server, pid)
    page.wait_for_function("() => window.app.face && window.app.face.nJoints === 21", timeout=scaled_ms(30_000))
    page.wait_for_function("() => window.app.stream && window.app.stream.state === 'open'", timeout=scaled_ms(10_000))
    page.select_option("#live-stereo-split", "side")
    page.click("#live-stereo-open")
    page.wait_for_function("() => document.querySelector('#live-stereo-status').textContent.startsWith('Calibrated: 10 views')",
                           timeout=scaled_ms(20_000))
    assert page.evaluate("() => window.app.stereo.capture.size") == [640, 480]
    page.click("#live-stereo-start")
    # the server tracks the 21 markers in the pairs the page sends
    page.wait_for_function("() => window.app.stereo.last?.type === 'tracked' && window.app.stereo.last.found >= 19",
                           timeout=scaled_ms(20_000))
    wait_face_moves(page, 0.05, timeout_ms=20_000)
    status = page.inner_text("#live-stereo-status")
    assert "/21 points" in status and "fps" in status and "kB/s" in status
    assert page.inner_text("#error").strip() == ""
    page.click("#live-stereo-start")  # Stop
    page.wait_for_function("() => window.app.stereo.last?.type === 'stopped'", timeout=scaled_ms(10_000))
    page.evaluate("() => window.app.stereo.close()")
