"""Live stereo over ``WS /api/projects/{id}/stereo/live`` (server.routers.stereo_live): a
rendered stereo rig with known truth calibrated from checkerboard views sent as JPEG pairs,
then a colour-marker performance tracked live into the project's stream; refusals of bad,
oversized and hostile messages; a dying child ends only its session."""

from __future__ import annotations

import io
import multiprocessing
import os
import signal

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from retarget.layouts import get_layout
from retarget.sources.video import VideoReader
from retarget.testing.stereo_rig import checkerboard_views, render_stereo_video, stereo_cameras
from server.routers.stereo_live import MAX_PAIRS_PER_SECOND
from server.wire import encode_stereo_pair
from tests.ws_messages import binary_frames, replies

EVIL = "https://evil.example"
N_FRAMES = 16


def jpeg(image: np.ndarray, quality: int = 90) -> bytes:
    return cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])[1].tobytes()


def pair(left, right, index: int, t: float | None = None) -> bytes:
    return encode_stereo_pair(jpeg(left), jpeg(right), frame_index=index,
                              capture_time=index / 30 if t is None else t)


@pytest.fixture(scope="module")
def rig():
    return stereo_cameras()


@pytest.fixture(scope="module")
def material(tmp_path_factory, rig):
    """Checkerboard view pairs and a colour-marker performance (dutreve21) with its truth."""
    boards = checkerboard_views(*rig, n_views=11, seed=4)
    truth = render_stereo_video(tmp_path_factory.mktemp("live") / "take.mkv", n_frames=N_FRAMES, cameras=rig,
                                start=3.6, seed=2)
    with VideoReader(truth.videos[0]) as a, VideoReader(truth.videos[1]) as b:
        frames = [(left, right) for (_, left), (_, right) in zip(a, b)]
    return boards, truth, frames


@pytest.fixture(scope="module")
def project(app, sample_id) -> str:
    """A copy of the sample face with the 21 points of dutreve21, the stickers' layout."""
    layout = get_layout("dutreve21")
    with TestClient(app) as client:
        sample = client.get(f"/api/projects/{sample_id}/landmarks").json()
        pid = client.post("/api/projects", json={"name": "stereo live"}).json()["id"]
        mesh = client.get(f"/api/projects/{sample_id}/mesh").content
        assert client.put(f"/api/projects/{pid}/mesh", files={"file": ("face.obj", mesh)}).status_code == 200
        picked = {"layout": "dutreve21", "vertex_indices": [sample["vertex_indices"][i] for i in layout.ibug68]}
        assert client.put(f"/api/projects/{pid}/landmarks", json=picked).status_code == 200
    return pid


def live(client, pid, **kwargs):
    return client.websocket_connect(f"/api/projects/{pid}/stereo/live", **kwargs)


def head_frame_truth(truth, rig) -> np.ndarray:
    """(F, N, 3) true points in the left camera's frame with the head held at frame 0's pose."""
    rot, trans = truth.head_rotation, truth.head_translation
    posed = np.einsum("fji,fnj->fni", rot, truth.points3d - trans[:, None])
    return rig[0].to_camera(posed @ rot[0].T + trans[0])


def test_calibrated_live_then_tracked_into_the_stream_within_a_few_mm_of_truth(app, project, material, rig):
    boards, truth, frames = material
    lefts, rights, _ = boards
    with TestClient(app) as client:
        with live(client, project) as ws:
            hello = ws.receive_json()
            assert (hello["type"], hello["layout"], hello["n_points"], hello["calibration"]) == \
                ("hello", "dutreve21", 21, None)
            ws.send_json({"type": "start"})
            assert "no stereo calibration yet" in ws.receive_json()["detail"]
            ws.send_json({"type": "calibrate", "pattern": {"cols": 9, "rows": 6, "square": 25}, "size": [640, 480]})
            assert ws.receive_json() == {"type": "calibrating", "count": 0, "needed": 10}
            ws.send_json({"type": "calibration_save"})
            assert "0 good views of the board so far; 10 are needed" in ws.receive_json()["detail"]
            blank = np.full_like(lefts[0], 255)
            ws.send_bytes(pair(blank, blank, 0))
            assert ws.receive_json() == {"type": "views", "frame": 0, "good": False, "count": 0, "needed": 10}
            counts = []
            for i, (left, right) in enumerate(zip(lefts, rights), 1):
                ws.send_bytes(pair(left, right, i))
                counts.append(ws.receive_json()["count"])
            assert counts == list(range(1, 12))
            ws.send_json({"type": "calibration_save"})
            saved = ws.receive_json()
            assert saved["type"] == "calibrated", saved
            assert saved["calibration"]["baseline"] == pytest.approx(150.0, rel=0.02)
            assert saved["calibration"]["views"] == 11 and saved["calibration"]["rms"] < 1.0

        # the calibration is the project's now: a new session starts on it
        with client.websocket_connect(f"/api/projects/{project}/stream") as viewer, live(client, project) as ws:
            assert viewer.receive_json()["type"] == "hello"
            assert ws.receive_json()["calibration"]["views"] == 11
            ws.send_json({"type": "start", "settings": {"neutral": {"mode": "frame", "frame": 0}}})
            started = ws.receive_json()
            assert (started["type"], started["source"], started["dims"]) == ("started", "live", 3)
            viewer.send_json({"type": "record"})
            assert replies(viewer, 1)[0]["type"] == "recording"
            tracked = []
            for i, (left, right) in enumerate(frames):
                ws.send_bytes(pair(left, right, i))
                tracked.append(ws.receive_json())
            assert [t["found"] for t in tracked] == [21] * N_FRAMES, tracked[0]
            assert all(t["identified"] and t["anchored"] for t in tracked)
            shown = binary_frames(viewer, 3)  # the retargeted face in the project's stream
            assert all(f.displacements.shape == (21, 3) for f in shown)
            assert max(np.abs(f.displacements).max() for f in shown) > 1e-3
            viewer.send_json({"type": "record_stop", "name": "stereo live"})
            (recorded,) = replies(viewer, 1)
            assert recorded["type"] == "recorded", recorded
            recorded = recorded["take"]
            ws.send_json({"type": "stop"})
            assert ws.receive_json() == {"type": "stopped"}
        points = np.load(io.BytesIO(client.get(f"/api/projects/{project}/takes/{recorded['id']}/points").content))
    assert points.shape == (N_FRAMES, 21, 3)
    err = np.linalg.norm(points - head_frame_truth(truth, rig), axis=2)
    assert np.isfinite(err).all() and np.median(err) < 2.0 and np.percentile(err, 95) < 5.0


def test_bad_messages_are_refused_with_the_reason_and_the_session_goes_on(app, project, material):
    _, _, frames = material
    left, right = frames[0]
    good = pair(left, right, 1)
    small = jpeg(cv2.resize(left, (320, 240)))
    with TestClient(app) as client, live(client, project) as ws:
        ws.receive_json()
        refused = [
            ("not json", "not one JSON object"),
            ('{"type": "fly"}', "unknown control message type 'fly'"),
            ('{"type": "calibrate", "pattern": {"cols": 9, "rows": 6, "square": 25}, "size": [99999, 480]}',
             "64x64 to 1920x1080"),
            ('{"type": "calibrate", "pattern": {"cols": true, "rows": 6, "square": 25}, "size": [640, 480]}',
             "whole numbers of inner corners"),
            (good, 'send one first'),
        ]
        for message, reason in refused:
            ws.send_text(message) if isinstance(message, str) else ws.send_bytes(message)
            reply = ws.receive_json()
            assert reply["type"] == "error" and reason in reply["detail"], (reason, reply)
        ws.send_json({"type": "calibrate", "pattern": {"cols": 9, "rows": 6, "square": 25}, "size": [640, 480]})
        ws.receive_json()
        for message, reason in [
            (good[:-3], "must be"),
            (b"\0" * (2 * 400 * 1024), "at most"),
            (encode_stereo_pair(small, jpeg(right), frame_index=2, capture_time=0.1),
             "the left image is 320x240; 640x480 was expected"),
            # a JPEG header declaring a huge image is refused before the decoder sees it
            (encode_stereo_pair(jpeg(left)[:2] + b"\xff\xc0\x00\x11\x08\xff\xff\xff\xff\x03" + b"\0" * 9,
                                jpeg(right), frame_index=3, capture_time=0.1), "65535x65535"),
            # a JPEG cut short decodes to nothing: a refusal, not a crash
            (encode_stereo_pair(jpeg(left)[:600], jpeg(right), frame_index=4, capture_time=0.1),
             "not a JPEG the decoder can read"),
        ]:
            ws.send_bytes(message)
            reply = ws.receive_json()
            assert reply["type"] == "error" and reason in reply["detail"], (reason, reply)
        ws.send_bytes(good)  # and the session still works
        assert ws.receive_json()["type"] == "views"


def test_a_flood_of_pairs_is_refused_before_decoding(app, project, material):
    _, _, frames = material
    tiny = jpeg(np.zeros((8, 8, 3), np.uint8))  # wrong size: decoded pairs would be refused for that
    with TestClient(app) as client, live(client, project) as ws:
        ws.receive_json()
        ws.send_json({"type": "calibrate", "pattern": {"cols": 9, "rows": 6, "square": 25}, "size": [640, 480]})
        ws.receive_json()
        details = []
        for i in range(MAX_PAIRS_PER_SECOND + 5):
            ws.send_bytes(encode_stereo_pair(tiny, tiny, frame_index=i, capture_time=i))
            details.append(ws.receive_json()["detail"])
    flooded = [d for d in details if "stereo pairs a second; this one was dropped" in d]
    assert flooded and all("8x8" in d for d in details if d not in flooded)


def test_another_origin_is_refused(app, project):
    with TestClient(app) as client:
        with pytest.raises(WebSocketDisconnect) as refused:
            with live(client, project, headers={"origin": EVIL}):
                pass
        assert refused.value.code == 1008
        with live(client, project, headers={"origin": "http://testserver"}) as ws:
            assert ws.receive_json()["type"] == "hello"


def test_a_project_without_landmarks_is_closed_with_the_reason(app):
    with TestClient(app) as client:
        pid = client.post("/api/projects", json={"name": "bare"}).json()["id"]
        with pytest.raises(WebSocketDisconnect) as closed:
            with live(client, pid) as ws:
                ws.receive_json()
        assert closed.value.code == 1008 and "no landmarks" in closed.value.reason


def test_a_crashed_child_ends_its_session_only(app, project, material):
    """A decoder crash (a hostile JPEG's effect, here the signal itself) ends the session
    with the reason; the server and a new session go on."""
    _, _, frames = material
    with TestClient(app) as client:
        with live(client, project) as ws:
            ws.receive_json()
            ws.send_json({"type": "calibrate", "pattern": {"cols": 9, "rows": 6, "square": 25},
                          "size": [640, 480]})
            ws.receive_json()
            (child,) = [p for p in multiprocessing.active_children() if p.name == f"stereo-live-{project}"]
            os.kill(child.pid, signal.SIGSEGV)
            ws.send_bytes(pair(*frames[0], 1))
            ended = ws.receive_json()
            assert ended["type"] == "ended" and "parser crashed on it (SIGSEGV)" in ended["detail"]
            with pytest.raises(WebSocketDisconnect) as closed:
                ws.receive_json()
            assert closed.value.code == 1011
        assert client.get("/api/projects").status_code == 200
        with live(client, project) as ws:
            assert ws.receive_json()["type"] == "hello"
            ws.send_json({"type": "calibrate", "pattern": {"cols": 9, "rows": 6, "square": 25},
                          "size": [640, 480]})
            assert ws.receive_json()["type"] == "calibrating"
