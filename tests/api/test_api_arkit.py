"""The project's ARKit 52 blendshapes over the API (issue 16): made by a job, the RTAK
binary, the user's settings (gains, painted fixes, rig) with their refusals, the stream
driven by ARKit (RTAW frames, or named weights as JSON) and the export. The formats'
JavaScript twins are cross-tested in test_wire.py. The shapes are made once
per module (about 9 s on the sample face)."""

import json
import math

import numpy as np
import pytest

from retarget.arkit import ARKIT_NAMES, ArkitDrive, ArkitShapes
from retarget.sample_face import demo_points
from retarget.sources.arkit_curves import ArkitCurves, live_link_csv
from server.players import DemoPlayer
from server.store import ProjectStore
from server.wire import ARKIT_WEIGHTS_MAGIC, FLAG_LAST, decode_arkit_shapes, decode_arkit_weights
from tests.api.test_api_muscles import _sample
from tests.waits import wait_job


@pytest.fixture(scope="module")
def made(client, sample_id) -> ArkitShapes:
    """The sample project's shapes, made once through the API (job with progress)."""
    url = f"/api/projects/{sample_id}/arkit"
    assert client.get(url).json()["state"] == "missing"
    started = client.post(url, json={"rig": "default"})
    assert started.status_code == 202 and started.json()["kind"] == "arkit"
    assert client.get(url).json()["job"]["id"] == started.json()["id"]  # a reloaded page finds it
    assert client.post(url).status_code == 409  # one job at a time
    progress = []
    job = wait_job(client, started.json()["id"], 120, poll_s=0.2, progress=progress)
    assert job["state"] == "done", job
    assert job["result"]["n_vertices"] == client.get(f"/api/projects/{sample_id}").json()["mesh"]["n_vertices"]
    assert 0 < max(progress[:-1], default=0.5) < 1  # an estimate while it runs, never the end
    return client.app.state.store.arkit_shapes(sample_id)


def test_made_shapes_are_ready_and_the_binary_decodes_to_them(client, sample_id, made):
    body = client.get(f"/api/projects/{sample_id}/arkit").json()
    assert body["state"] == "ready" and body["made_on"] == "default" and body["job"] is None
    assert body["names"] == list(ARKIT_NAMES) and body["max_gain"] == 2.0
    mesh, points = _sample(client, sample_id)
    assert made.deltas.shape == (52, mesh.n_vertices, 3) and made.at_points.shape == (52, points.n_points, 3)
    answer = client.get(f"/api/projects/{sample_id}/arkit/shapes")
    assert answer.status_code == 200 and answer.headers["content-type"] == "application/octet-stream"
    names, deltas = decode_arkit_shapes(answer.content)
    assert names == list(ARKIT_NAMES)
    peaks = np.abs(made.deltas).max(axis=(1, 2))
    error = np.linalg.norm(deltas - made.deltas, axis=2).max(axis=1)
    assert (error <= 1.01e-3 * peaks + 1e-7).all()  # the floor and the int16 step
    assert len(answer.content) < 0.5 * made.deltas.nbytes  # sparse
    assert not deltas[ARKIT_NAMES.index("tongueOut")].any()


def test_settings_are_checked_saved_and_survive_a_reload(client, sample_id, made):
    url = f"/api/projects/{sample_id}/arkit"
    n = made.deltas.shape[1]
    blink = ARKIT_NAMES.index("eyeBlinkLeft")
    moving = np.flatnonzero(np.linalg.norm(made.deltas[blink], axis=1) > 0)[:3]
    settings = {"rig": "default", "gains": {"jawOpen": 1.5, "mouthSmileLeft": 0},
                "masks": {"eyeBlinkLeft": {"vertices": moving.tolist(), "values": [0.0, 0.5, 1.0]}}}
    saved = client.put(url, json=settings)
    assert saved.status_code == 200, saved.text
    body = saved.json()
    assert body["settings"]["gains"]["jawOpen"] == 1.5 and body["settings"]["gains"]["eyeBlinkRight"] == 1.0
    # a vertex at 1 keeps the shape whole: not stored
    assert body["settings"]["masks"] == {"eyeBlinkLeft": {"vertices": moving[:2].tolist(), "values": [0.0, 0.5]}}
    assert body["state"] == "ready"
    for bad, reason in (
            ({"gains": {"jawOpen": math.nan}}, "gain of jawOpen"),
            ({"gains": {"jawOpen": 2.5}}, "[0, 2]"),
            ({"gains": {"jawOpen": "1"}}, "gain of jawOpen"),
            ({"gains": {"jawOpen": True}}, "gain of jawOpen"),
            ({"gains": {"jawOpened": 1}}, "'jawOpened' is not one of ARKit's 52"),
            ({"masks": {"eyeBlinkLeft": {"vertices": [1, 2], "values": [0.5]}}}, "2 vertices and 1 values"),
            ({"masks": {"eyeBlinkLeft": {"vertices": [n], "values": [0.5]}}}, f"vertex {n} is not one of"),
            ({"masks": {"eyeBlinkLeft": {"vertices": [2, 1], "values": [0.5, 0.5]}}}, "ascending"),
            ({"masks": {"eyeBlinkLeft": {"vertices": [1], "values": [1.5]}}}, "[0, 1]"),
            ({"masks": {"browUp": {"vertices": [], "values": []}}}, "'browUp'"),
            ({"rig": "mine"}, "rig must be one of"),
            ({"colour": 1}, "unknown fields"),
            ([1], "valid dictionary")):
        answer = client.put(url, content=json.dumps(bad), headers={"content-type": "application/json"})
        assert answer.status_code == 422, (bad, answer.text)
        assert reason in answer.json()["detail"], (reason, answer.json()["detail"])
    assert client.get(url).json()["settings"] == body["settings"]  # refusals changed nothing
    # the project's store read anew from its folder (a server restart) keeps them
    again = ProjectStore(client.app.state.store.data_dir)
    try:
        assert again.arkit_settings(sample_id) == body["settings"]
    finally:
        again.close()
    # fixed=true: the masks applied for other tools
    _, fixed = decode_arkit_shapes(client.get(f"{url}/shapes", params={"fixed": "true"}).content)
    _, raw = decode_arkit_shapes(client.get(f"{url}/shapes").content)
    np.testing.assert_allclose(fixed[blink, moving[0]], 0.0)
    np.testing.assert_allclose(fixed[blink, moving[1]], 0.5 * raw[blink, moving[1]], rtol=1e-6)
    np.testing.assert_array_equal(fixed[blink, moving[2]], raw[blink, moving[2]])
    # another rig asked for: the shapes are stale until made again
    assert client.put(url, json={**body["settings"], "rig": "project"}).json()["state"] == "stale"
    assert client.get(f"{url}/shapes").status_code == 409
    assert client.put(url, json=body["settings"]).json()["state"] == "ready"


def test_weight_frames_are_the_drives_weights(client, sample_id, made):
    mesh, points = _sample(client, sample_id)
    gains = np.ones(52)
    gains[ARKIT_NAMES.index("jawOpen")] = 1.5
    player = DemoPlayer(points.positions(mesh.vertices), "ibug68", fps=30)
    player.set_drive(ArkitDrive(made, gains))
    twin = ArkitDrive(made, gains)
    _, frames = demo_points(player.performance.layout, 30.0)
    seen = []
    for i in range(0, 60, 3):
        data = player.frame(i)
        assert data[:4] == ARKIT_WEIGHTS_MAGIC and len(data) == 32 + 4 * 52
        frame = decode_arkit_weights(data)
        expected = twin.weights(player.performance.displacements(frames[i]))
        np.testing.assert_array_equal(frame.weights, expected)
        assert frame.frame_index == i and ((0 <= frame.weights) & (frame.weights <= 1)).all()
        seen.append(frame.weights)
    assert np.max(seen) > 0.2  # the demo moves the face: some shape is well on
    assert player.describe()["drive"] == "arkit"


def test_stream_drive_arkit_sends_weight_frames_and_json_on_request(client, sample_id, made, capsys):
    mesh, points = _sample(client, sample_id)
    url = f"/api/projects/{sample_id}/stream"
    with client.websocket_connect(url) as ws:
        ws.receive_json()
        ws.send_json({"type": "drive", "drive": "arkit"})
        assert ws.receive_json() == {"type": "drive", "drive": "arkit"}
        ws.send_json({"type": "format", "format": "xml"})
        assert "'json'" in ws.receive_json()["detail"]
        ws.send_json({"type": "start", "source": "demo", "fps": 5})
        first = _next_bytes(ws)
        assert first[:4] == ARKIT_WEIGHTS_MAGIC
        frame = decode_arkit_weights(first)
        if frame.frame_index == 0:  # a fresh drive's first frame: solved from zero weights
            player = DemoPlayer(points.positions(mesh.vertices), "ibug68", fps=5)
            gains = np.array([client.get(f"/api/projects/{sample_id}/arkit").json()["settings"]["gains"][n]
                              for n in ARKIT_NAMES])
            np.testing.assert_array_equal(frame.weights, ArkitDrive(made, gains).weights(player.displacements(0)))
        ws.send_json({"type": "format", "format": "json"})
        named = None
        while named is None:
            message = ws.receive()
            if message.get("text") is not None and json.loads(message["text"])["type"] == "weights":
                named = json.loads(message["text"])
        assert list(named["weights"]) == list(ARKIT_NAMES) and isinstance(named["frame"], int)
        assert all(0 <= w <= 1 for w in named["weights"].values()) and named["lost"] is False
        ws.send_json({"type": "drive", "drive": "points"})
        while True:  # the other drives' frames stay binary
            message = ws.receive()
            if message.get("bytes") is not None and message["bytes"][:4] == b"RTDF":
                points_frame = message["bytes"]
                break
        ws.send_json({"type": "stop"})
    with capsys.disabled():
        print(f"\nstream bytes per frame, 68 points: feature points {len(points_frame)}, ARKit weights {len(first)}, "
              f"ARKit JSON {len(json.dumps(named))}")
    # a viewer may ask for JSON on the URL
    with client.websocket_connect(url + "?format=json") as ws:
        ws.receive_json()
        ws.send_json({"type": "drive", "drive": "arkit"})
        ws.send_json({"type": "start", "source": "demo", "fps": 5})
        while True:
            message = json.loads(ws.receive()["text"])
            if message["type"] == "weights":
                break
        ws.send_json({"type": "stop"})
    assert len(message["weights"]) == 52


def _next_bytes(ws) -> bytes:
    while True:
        message = ws.receive()
        if message.get("bytes") is not None:
            return message["bytes"]


def test_export_and_a_playing_source_follow_the_arkit_settings(client, sample_id, made):
    url = f"/api/projects/{sample_id}/arkit"
    answer = client.get(f"/api/projects/{sample_id}/export.glb", params={"drive": "arkit"})
    assert answer.status_code == 200, answer.text
    data = answer.content
    length, kind = np.frombuffer(data, "<u4", 2, 12)
    document = json.loads(data[20:20 + length])
    assert kind == 0x4E4F534A and document["meshes"][0]["extras"]["targetNames"] == list(ARKIT_NAMES)
    settings = client.get(url).json()["settings"]
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "drive", "drive": "arkit"})
        ws.send_json({"type": "start", "source": "demo", "fps": 5})
        assert _next_bytes(ws)[:4] == ARKIT_WEIGHTS_MAGIC
        gains = {**settings["gains"], "jawOpen": 0.0}
        assert client.put(url, json={**settings, "gains": gains}).status_code == 200
        playing = client.app.state.hub.source(sample_id).drive
        assert playing.gains[ARKIT_NAMES.index("jawOpen")] == 0.0  # from its next frame
        ws.send_json({"type": "stop"})
    client.put(url, json=settings)


def test_a_live_link_take_plays_back_as_its_own_weights(client, sample_id, made):
    """A Live Link Face CSV is a take like any other (listed, trimmed, played); played driven
    by ARKit on the project's own shapes, it gives back the weights it was recorded with."""
    url = f"/api/projects/{sample_id}/arkit"
    kept = client.get(url).json()["settings"]
    assert client.put(url, json={"rig": kept["rig"]}).status_code == 200  # every gain 1
    t = np.arange(60) / 30.0
    weights = np.zeros((60, 52))
    ramp = np.clip(np.sin(np.pi * t / t[-1]), 0, None)  # from rest to rest: frame 0 is the neutral
    for name, peak in (("jawOpen", 0.6), ("eyeBlinkLeft", 0.8), ("eyeBlinkRight", 0.8),
                       ("mouthSmileLeft", 0.5), ("mouthSmileRight", 0.5), ("browInnerUp", 0.4)):
        weights[:, ARKIT_NAMES.index(name)] = peak * ramp
    text = live_link_csv(ArkitCurves(weights, 30.0, None, None, {}))
    answer = client.post(f"/api/projects/{sample_id}/takes", data={"layout": "ibug68"},
                         files={"file": ("MySlate_3_iPhone.csv", text.encode())})
    assert answer.status_code == 201, answer.text
    take = answer.json()
    assert (take["n_frames"], take["n_points"], take["dims"]) == (60, 68, 3)
    assert take["duration"] == pytest.approx(59 / 30)
    trimmed = client.patch(f"/api/projects/{sample_id}/takes/{take['id']}", json={"trim": [0.5, 1.5]})
    assert trimmed.status_code == 200 and trimmed.json()["trim"] == [0.5, 1.5]
    client.patch(f"/api/projects/{sample_id}/takes/{take['id']}", json={"trim": [0, None]})
    settings = {"neutral": {"mode": "frame", "frame": 0}, "head_pose": "keep", "filter": "none"}
    got = {}
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "drive", "drive": "arkit"})
        ws.send_json({"type": "start", "source": "take", "take": take["id"], "loop": False,
                      "settings": settings})
        while len(got) < 60:
            frame = decode_arkit_weights(_next_bytes(ws))
            got[frame.frame_index] = frame.weights
            if frame.flags & FLAG_LAST:
                break
        ws.send_json({"type": "stop"})
    frames = sorted(got)
    assert len(frames) >= 50, f"only {len(frames)} of 60 frames arrived"
    error = np.abs(np.array([got[i] for i in frames]) - weights[frames])
    on = weights[frames] > 0.05
    # the take's points are the reference face making the weights; carried onto the sample
    # face and solved on its shapes, they come back (the library's round trip, through the server)
    assert error.mean() < 0.01 and error[on].mean() < 0.06, (error.mean(), error[on].mean())
    assert client.put(url, json=kept).status_code == 200
    assert client.delete(f"/api/projects/{sample_id}/takes/{take['id']}").status_code == 204


def test_new_landmarks_make_the_shapes_stale(client, sample_id, made):
    """Saves the sample's landmarks again, which drops its rig (no later test needs it)."""
    url = f"/api/projects/{sample_id}/arkit"
    settings = client.get(url).json()["settings"]
    landmarks = client.get(f"/api/projects/{sample_id}/landmarks").json()
    assert client.put(f"/api/projects/{sample_id}/landmarks", json=landmarks).status_code == 200
    body = client.get(url).json()
    assert body["state"] == "stale" and body["settings"] == settings  # the user's settings stay
    assert client.get(f"{url}/shapes").status_code == 409
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "drive", "drive": "arkit"})
        refused = ws.receive_json()
    assert refused["type"] == "error" and "stale" in refused["detail"]
    bare = client.post("/api/projects", json={"name": "no arkit"}).json()["id"]
    assert client.post(f"/api/projects/{bare}/arkit").status_code == 409
    assert client.get(f"/api/projects/{bare}/arkit").json()["state"] == "missing"
    answer = client.get(f"/api/projects/{sample_id}/export.glb", params={"drive": "arkit"})
    assert answer.status_code == 409 and "stale" in answer.json()["detail"]
