"""Live single-colour stickers over ``WS /api/projects/{id}/stereo/live`` (issue 17 §3):
the rendered sticker take sent as JPEG pairs to a project whose landmarks are a custom
layout named m01..m13, tracked into its live source; to one whose layout was made from an
offline take of the stickers (named by place); the start message's refusals."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from retarget.layouts import get_layout
from retarget.similarity import similarity_transform
from retarget.sources.stereo import track_stereo_frames
from retarget.sources.video import VideoReader
from retarget.testing.stereo_rig import (
    live_sticker_anchors,
    render_sticker_video,
    rig_calibration,
)
from server.wire import encode_stereo_pair

N_FRAMES = 40
IBUG = get_layout("ibug68")
SPOTS = (17, 26, 27, 28, 19, 24, 2, 14, 48, 54, 51, 57, 8)   # iBUG points near the 13 stickers


def pair(left, right, index: int) -> bytes:
    jpeg = [cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 90])[1].tobytes() for img in (left, right)]
    return encode_stereo_pair(*jpeg, frame_index=index, capture_time=index / 30)


@pytest.fixture(scope="module")
def material(tmp_path_factory):
    """The sticker take (seed 1), its calibration, and the named anchors (the columns the
    temples, forehead and nose bridge have live)."""
    truth = render_sticker_video(tmp_path_factory.mktemp("stickers") / "take.mp4", n_frames=N_FRAMES, seed=1)
    with VideoReader(truth.videos[0]) as a, VideoReader(truth.videos[1]) as b:
        frames = [(left, right) for (_, left), (_, right) in zip(a, b)]
    cal = rig_calibration(*truth.cameras)
    return frames, cal, live_sticker_anchors(frames, cal, truth)


@pytest.fixture(scope="module")
def project(app, sample_id, material) -> str:
    """The sample face with landmarks in a custom layout m01..m13 (the anchors marked: the
    live source's conditioning removes the head pose on them too), and the rig's calibration."""
    spec = {"points": [{"name": f"m{k + 1:02d}", "region": IBUG.regions[i], "side": IBUG.sides[i]}
                       | ({"anchor": True} if f"m{k + 1:02d}" in material[2] else {})
                       for k, i in enumerate(SPOTS)]}
    with TestClient(app) as client:
        sample = client.get(f"/api/projects/{sample_id}/landmarks").json()
        pid = client.post("/api/projects", json={"name": "stickers live"}).json()["id"]
        mesh = client.get(f"/api/projects/{sample_id}/mesh").content
        assert client.put(f"/api/projects/{pid}/mesh", files={"file": ("face.obj", mesh)}).status_code == 200
        assert client.put(f"/api/projects/{pid}/layouts/stickers", json=spec).status_code == 201
        picked = {"layout": "stickers", "vertex_indices": [sample["vertex_indices"][i] for i in SPOTS]}
        assert client.put(f"/api/projects/{pid}/landmarks", json=picked).status_code == 200
    app.state.store.put_stereo_calibration(pid, material[1].to_dict())
    return pid


def test_stickers_are_tracked_live_into_the_stream_by_name(app, project, material):
    frames, _, anchors = material
    with TestClient(app) as client, client.websocket_connect(f"/api/projects/{project}/stereo/live") as ws:
        hello = ws.receive_json()
        assert (hello["n_points"], hello["sticker_points"]) == (13, 13)
        ws.send_json({"type": "start", "markers": "stickers", "color": "blue", "anchors": anchors})
        started = ws.receive_json()
        assert (started["type"], started["source"]) == ("started", "live"), started
        tracked = []
        for i, (left, right) in enumerate(frames):
            ws.send_bytes(pair(left, right, i))
            tracked.append(ws.receive_json())
        assert {t["type"] for t in tracked} == {"tracked"}, [t for t in tracked if t["type"] != "tracked"][:2]
        # 1 s of set-up (named anchors): nothing found, then the 13 stickers in the head frame.
        assert all(t["found"] == 0 and not t["anchored"] for t in tracked[:29])
        assert tracked[5]["detail"] == "set-up span: keep the stickers in view"
        last = tracked[-1]
        assert last["anchored"] and last["n_points"] == 13 and last["stickers"] == 13, last
        assert last["found"] >= 10 and sorted(last["anchors"]) == anchors
        # The points went to the project's live source (its neutral is captured from them).
        assert app.state.hub.source(project).describe()["source"] == "live"
        ws.send_json({"type": "stop"})
        assert ws.receive_json()["type"] == "stopped"


def test_a_patterned_cloth_in_view_is_refused_and_the_session_goes_on(app, project, material):
    # A blue polka-dot cloth held up to both cameras: 20 x 27 dots, hundreds of pairings.
    frames, _, anchors = material
    cloth = np.full_like(frames[0][0], (120, 150, 200))
    for y in range(12, cloth.shape[0], 24):
        for x in range(12, cloth.shape[1], 24):
            cv2.circle(cloth, (x, y), 4, (230, 80, 30), -1)
    with TestClient(app) as client, client.websocket_connect(f"/api/projects/{project}/stereo/live") as ws:
        ws.receive_json()
        ws.send_json({"type": "start", "markers": "stickers", "color": "blue", "anchors": anchors})
        assert ws.receive_json()["type"] == "started"
        ws.send_bytes(pair(cloth, cloth, 0))
        refused = ws.receive_json()
        assert refused["type"] == "error", refused
        assert "blue spots followed at once" in refused["detail"] and "does not look like a take" in refused["detail"]
        tracked = []
        for i, (left, right) in enumerate(frames, start=1):
            ws.send_bytes(pair(left, right, i))
            tracked.append(ws.receive_json())
        assert {t["type"] for t in tracked} == {"tracked"}, [t for t in tracked if t["type"] != "tracked"][:2]
        last = tracked[-1]
        assert last["anchored"] and last["stickers"] == 13 and sorted(last["anchors"]) == anchors, last


@pytest.fixture(scope="module")
def placed_project(app, sample_id, material) -> tuple[str, np.ndarray]:
    """The sample face with landmarks in a layout made from an offline take of the
    stickers (stored in the project; its 3D reference from ``GET .../layouts/from-take``),
    its points renamed (no m01..: only their places can name them) and listed in reverse;
    and the take's last frame (N, 3) mm in the layout's order."""
    frames, cal, anchors = material
    with TestClient(app) as client:
        pid = client.post("/api/projects", json={"name": "stickers by place"}).json()["id"]
        take = track_stereo_frames(frames, cal, layout=None)
        info = app.state.store.put_take(pid, take, name="sticker take")
        made = client.get(f"/api/projects/{pid}/layouts/from-take/{info['id']}").json()
        assert made["reference"] is not None and len(made["names"]) == len(SPOTS)
        # The head anchors (the conditioning's too) are the columns of the temples,
        # forehead and nose bridge (the take's columns are the live tracker's here).
        spec = {"points": [{"name": f"sticker_{name}", "region": IBUG.regions[i], "side": "center",
                            "reference": xyz, "anchor": name in anchors}
                           for name, xyz, i in zip(made["names"], made["reference"], SPOTS)][::-1]}
        sample = client.get(f"/api/projects/{sample_id}/landmarks").json()
        mesh = client.get(f"/api/projects/{sample_id}/mesh").content
        assert client.put(f"/api/projects/{pid}/mesh", files={"file": ("face.obj", mesh)}).status_code == 200
        assert client.put(f"/api/projects/{pid}/layouts/placed", json=spec).status_code == 201, spec
        picked = {"layout": "placed", "vertex_indices": [sample["vertex_indices"][i] for i in SPOTS]}
        assert client.put(f"/api/projects/{pid}/landmarks", json=picked).status_code == 200
    app.state.store.put_stereo_calibration(pid, cal.to_dict())
    return pid, take.points[-1, ::-1]


def test_stickers_drive_a_layout_made_from_a_take_by_where_they_sit(app, placed_project, material):
    (frames, _, anchors), (project, offline) = material, placed_project

    with TestClient(app) as client, client.websocket_connect(f"/api/projects/{project}/stereo/live") as ws:
        assert ws.receive_json()["sticker_points"] == len(offline)   # every point: named by place
        # No anchors: the layout's own, found by place (1 s set-up).
        ws.send_json({"type": "start", "markers": "stickers", "color": "blue", "anchors": None})
        assert ws.receive_json()["type"] == "started"
        player, pushed = app.state.hub.source(project), []
        push = player.push
        player.push = lambda points, t, index: (pushed.append(points), push(points, t, index))
        tracked = []
        for i, (left, right) in enumerate(frames):
            ws.send_bytes(pair(left, right, i))
            tracked.append(ws.receive_json())
        assert tracked[-1]["anchored"] and tracked[-1]["found"] >= 10, [(t["anchored"], t["detail"]) for t in tracked]
        assert sorted(tracked[-1]["anchors"]) == anchors   # the columns of the layout's anchors
    # The last pair's points reach the live source in the layout's order: the offline
    # take's last frame to a few mm (its head frame up to a similarity), where two
    # stickers swapped would be centimetres off.
    last = pushed[-1]
    seen = np.isfinite(last).all(axis=1)
    scale, rot, trans = similarity_transform(last[seen], offline[seen])
    residual = np.linalg.norm(scale * last[seen] @ rot.T + trans - offline[seen], axis=1)
    assert seen.sum() >= 10 and residual.max() < 5.0, residual


@pytest.mark.parametrize("message, detail", [
    ({"markers": "dots"}, '"markers" must be "layout"'),
    ({"markers": "stickers", "color": "teal"}, "unknown sticker colour 'teal'"),
    ({"markers": "stickers", "color": 3}, '"color" must be a colour name'),
    ({"markers": "stickers", "color": "300,0,0"}, "B, G and R are 0-255"),
    ({"markers": "stickers", "color": "hsv:200,90,90"}, "H 0-179"),
    ({"markers": "stickers", "anchors": ["m01", "m02"]}, "at least 3 different stickers"),
    ({"markers": "stickers", "anchors": ["m01", "m02", "nose"]}, "'nose' is none"),
    ({"markers": "stickers", "anchors": "m01,m02,m03"}, '"anchors" must be a list'),
    ({"color": "blue"}, '"color" is for "markers": "stickers"'),
])
def test_a_bad_sticker_start_is_refused_precisely(app, project, message, detail):
    with TestClient(app) as client, client.websocket_connect(f"/api/projects/{project}/stereo/live") as ws:
        ws.receive_json()
        ws.send_json({"type": "start", **message})
        reply = ws.receive_json()
        assert reply["type"] == "error" and detail in reply["detail"], reply


def test_stickers_need_landmarks_named_as_their_columns(app, sample_id):
    with TestClient(app) as client, client.websocket_connect(f"/api/projects/{sample_id}/stereo/live") as ws:
        assert ws.receive_json()["sticker_points"] == 0
        ws.send_json({"type": "start", "markers": "stickers", "color": "40,90,200"})
        reply = ws.receive_json()
        assert reply["type"] == "error" and "has none; place the landmarks with a custom layout" in reply["detail"]
