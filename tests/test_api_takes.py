"""Takes over the REST API and as stream sources: upload, list, trim, rename, delete,
download, replay through conditioning and retargeting, live points pushed over the
WebSocket and recorded into a take, and bad input that leaves everything intact."""

import io

import numpy as np
import pytest
from fastapi.testclient import TestClient

from retarget.layouts import get_layout
from retarget.pipeline import Retargeter
from retarget.sample_face import demo_weights, sample_face
from server.app import create_app
from server.stream_codec import FLAG_HEAD_ROTATION, encode_points
from tests.ws_messages import binary_frames, replies

FPS = 30.0


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    return create_app(tmp_path_factory.mktemp("data"))


@pytest.fixture(scope="module")
def client(app):
    with TestClient(app) as c:
        yield c


@pytest.fixture(scope="module")
def sample_id(client):
    return next(p["id"] for p in client.get("/api/projects").json() if p["landmarks"])


@pytest.fixture(scope="module")
def performance():
    """A performer's 68 landmarks: neutral (68, 3) and 60 frames, cm."""
    face = sample_face(identity=np.array([0.8, 0.5, -0.6, 1.0, 0.3]))
    lm = np.asarray(face.landmarks68)
    weights = demo_weights(60, FPS)
    neutral = face.vertices[lm]
    frames = neutral + np.tensordot(weights, face.expressions[:, lm], axes=1)
    return neutral.astype(np.float32), frames.astype(np.float32)


def npy_bytes(array) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.asarray(array, dtype=np.float32))
    return buffer.getvalue()


def upload(client, pid, name, data, **fields):
    return client.post(f"/api/projects/{pid}/takes", files={"file": (name, data)}, data=fields)






def test_upload_list_trim_rename_download_delete(client, sample_id, performance):
    neutral, frames = performance
    take = np.concatenate([np.repeat(neutral[None], 30, 0), frames])
    r = upload(client, sample_id, "smile.npy", npy_bytes(take), layout="ibug68", fps="30")
    assert r.status_code == 201, r.text
    info = r.json()
    assert (info["name"], info["n_frames"], info["n_points"], info["dims"]) == ("smile", 90, 68, 3)
    assert info["duration"] == pytest.approx(89 / 30) and info["trim"] == [0, pytest.approx(89 / 30)]
    assert any(t["id"] == info["id"] for t in client.get(f"/api/projects/{sample_id}/takes").json())

    r = client.patch(f"/api/projects/{sample_id}/takes/{info['id']}", json={"name": "Smile 1", "trim": [1.0, 2.0]})
    assert r.status_code == 200 and r.json()["name"] == "Smile 1" and r.json()["trim"] == [1.0, 2.0]
    got = np.load(io.BytesIO(client.get(f"/api/projects/{sample_id}/takes/{info['id']}/points").content))
    np.testing.assert_array_equal(got, take[30:60])  # [1 s, 2 s) at 30 fps

    for bad, message in (([2.0, 1.0], "after the start"), ([-1, None], "start must be"), ([0, 99], "at most")):
        r = client.patch(f"/api/projects/{sample_id}/takes/{info['id']}", json={"trim": bad})
        assert r.status_code == 422 and message in r.json()["detail"]
    assert client.get(f"/api/projects/{sample_id}/takes/{info['id']}").json()["trim"] == [1.0, 2.0]

    assert client.delete(f"/api/projects/{sample_id}/takes/{info['id']}").status_code == 204
    assert client.get(f"/api/projects/{sample_id}/takes/{info['id']}").status_code == 404


def test_bad_take_files_are_refused_and_nothing_is_stored(client, sample_id):
    before = client.get(f"/api/projects/{sample_id}/takes").json()
    cases = [
        ("take.exe", b"MZ", 415, "'.exe'"),
        ("empty.csv", b"", 422, "empty"),
        ("nan.npy", npy_bytes(np.full((5, 68, 3), np.nan)), 422, "take file 'nan.npy' refused"),
        ("short.npy", npy_bytes(np.zeros((5, 68))), 422, "take file 'short.npy' refused"),
        ("junk.c3d", b"not a c3d file at all", 422, "take file 'junk.c3d' refused"),
    ]
    for name, data, code, message in cases:
        r = upload(client, sample_id, name, data, layout="ibug68", fps="30")
        assert r.status_code == code and message in r.json()["detail"], (name, r.text)
    assert client.get(f"/api/projects/{sample_id}/takes").json() == before
    assert client.get(f"/api/projects/{sample_id}/takes/AAAAAAAAAAAAAAAA").status_code == 404
    assert client.get(f"/api/projects/{sample_id}/takes/../../etc").status_code == 404


def test_a_take_replays_through_the_retargeter(client, sample_id, performance):
    """The streamed displacements are the library's for the take's frames."""
    neutral, frames = performance
    take = np.concatenate([np.repeat(neutral[None], 15, 0), frames])
    info = upload(client, sample_id, "replay.npy", npy_bytes(take), layout="ibug68", fps="30").json()
    target = _target_points(client, sample_id)
    settings = {"neutral": {"mode": "frame", "frame": 0}, "head_pose": "keep", "filter": "none"}
    expected = Retargeter().fit(neutral, target).displacements(take)
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "start", "source": "take", "take": info["id"], "loop": False, "settings": settings})
        started = replies(ws, 1)[0]
        assert started["type"] == "started" and started["source"] == "take" and started["frames"] == 75
        got = binary_frames(ws, 20)
        for f in got:
            np.testing.assert_allclose(f.displacements, expected[f.frame_index], atol=1e-4)
            assert f.source_time == pytest.approx(f.frame_index / 30)
        ws.send_json({"type": "stop"})


def test_a_take_with_fewer_points_drives_the_whole_rig(client, sample_id, performance):
    """A dutreve21 take (21 named points) on the 68-point sample project."""
    neutral, frames = performance
    layout = get_layout("dutreve21")
    take = np.concatenate([np.repeat(neutral[None], 5, 0), frames])[:, list(layout.ibug68)]
    info = upload(client, sample_id, "markers.npy", npy_bytes(take), layout="dutreve21", fps="30").json()
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "start", "source": "take", "take": info["id"],
                      "settings": {"neutral": {"mode": "frame", "frame": 0}}})
        got = binary_frames(ws, 40)
        moving = np.stack([f.displacements for f in got])
        driven = np.zeros(68, bool)
        driven[list(layout.ibug68)] = True
        assert np.abs(moving[:, ~driven]).max() > 1e-3  # undriven joints follow
        ws.send_json({"type": "stop"})


def test_live_points_are_retargeted_and_recorded(client, sample_id, performance):
    neutral, frames = performance
    target = _target_points(client, sample_id)
    # the performer's head turns 10 degrees about y while performing
    angle = np.radians(10)
    turn = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    centre = neutral.mean(0)
    settings = {"neutral": {"mode": "first_seconds", "seconds": 0.2}, "head_pose": "remove",
                "apply_rotation": True, "filter": "none"}
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "start", "source": "live", "dims": 3, "settings": settings})
        assert replies(ws, 1)[0]["source"] == "live"
        ws.send_json({"type": "record"})
        assert replies(ws, 1)[0]["type"] == "recording"
        t = 0.0
        for i in range(10):  # neutral capture: 0.2 s at 30 fps
            ws.send_bytes(encode_points(neutral, frame_index=i, capture_time=t))
            t += 1 / FPS
        sent = []
        for j, frame in enumerate(frames[:20]):
            turned = (frame - centre) @ turn.T + centre
            ws.send_bytes(encode_points(turned, frame_index=10 + j, capture_time=t))
            sent.append(frame)
            t += 1 / FPS
        got = binary_frames(ws, 5)
        expected = Retargeter().fit(neutral, target).displacements(np.stack(sent))
        last = got[-1]
        assert last.flags & FLAG_HEAD_ROTATION
        # the head turn is taken out of the points and comes back as the rotation
        np.testing.assert_allclose(last.displacements, expected[last.frame_index - 10], atol=0.02)
        w = last.head_rotation[3]
        assert 2 * np.degrees(np.arccos(min(1.0, abs(w)))) == pytest.approx(10, abs=0.5)
        ws.send_json({"type": "record_stop", "name": "webcam take"})
        recorded = replies(ws, 1)[0]
        assert recorded["type"] == "recorded" and recorded["take"]["n_frames"] == 30
        assert recorded["take"]["name"] == "webcam take" and recorded["take"]["source"] == "live"
        # malformed points get an error and the stream goes on
        ws.send_bytes(encode_points(neutral[:10], frame_index=99, capture_time=t))
        assert "68 points" in replies(ws, 1)[0]["detail"]
        ws.send_bytes(b"RTSP" + b"\0" * 10)
        assert "shorter than" in replies(ws, 1)[0]["detail"]
        ws.send_json({"type": "stop"})
    stored = np.load(io.BytesIO(client.get(
        f"/api/projects/{sample_id}/takes/{recorded['take']['id']}/points").content))
    assert stored.shape == (30, 68, 3)
    np.testing.assert_allclose(stored[:10], np.repeat(neutral[None], 10, 0), atol=1e-6)


def test_points_without_a_live_source_and_unknown_takes_are_errors(client, sample_id):
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_bytes(encode_points(np.zeros((68, 3)), frame_index=0, capture_time=0.0))
        assert "live source" in replies(ws, 1)[0]["detail"]
        ws.send_json({"type": "start", "source": "take", "take": "AAAAAAAAAAAAAAAA"})
        assert "no take" in replies(ws, 1)[0]["detail"]
        ws.send_json({"type": "record"})
        assert "live" in replies(ws, 1)[0]["detail"]


def test_takes_survive_a_restart_and_a_new_mesh(tmp_path, performance):
    neutral, frames = performance
    app = create_app(tmp_path)
    with TestClient(app) as client:
        pid = next(p["id"] for p in client.get("/api/projects").json() if p["landmarks"])
        info = upload(client, pid, "keep.npy", npy_bytes(frames), layout="ibug68", fps="30").json()
        mesh = client.get(f"/api/projects/{pid}/mesh")
        fmt = client.get(f"/api/projects/{pid}").json()["mesh"]["format"]
        assert client.put(f"/api/projects/{pid}/mesh", files={"file": (f"again.{fmt}", mesh.content)}).status_code == 200
    with TestClient(create_app(tmp_path)) as client:
        takes = client.get(f"/api/projects/{pid}/takes").json()
        assert [t["id"] for t in takes] == [info["id"]]
        got = np.load(io.BytesIO(client.get(f"/api/projects/{pid}/takes/{info['id']}/points").content))
        np.testing.assert_array_equal(got, frames)


def _target_points(client, pid):
    from retarget.landmarks import landmarks_from_json
    from retarget.mesh import load_mesh

    project = client.get(f"/api/projects/{pid}").json()
    mesh = load_mesh(client.get(f"/api/projects/{pid}/mesh").content, project["mesh"]["format"])
    points = landmarks_from_json(client.get(f"/api/projects/{pid}/landmarks").json(), mesh.vertices, mesh.faces)
    return points.positions(mesh.vertices)
