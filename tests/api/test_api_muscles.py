"""The project's virtual muscles over the API (issue 15): placed from the landmarks and
stored, GET/PUT with their refusals, the played form's binary, and the stream driven by
muscles (contraction frames)."""

import json
import struct

import numpy as np

from retarget.errors import RetargetError
from retarget.landmarks import landmarks_from_json
from retarget.mesh import load_mesh
from retarget.muscles import MuscleFace
from retarget.muscles.drive import MuscleDrive, MuscleFrame
from retarget.muscles.expressions import EXPRESSIONS
from retarget.muscles.morphs import muscle_morphs
from retarget.sample_face import EXPRESSION_NAMES, demo_points, posed_vertices, sample_face
from server.players import DemoPlayer
from server.routers import stream
from server.wire import (CONTRACTIONS_MAGIC, FLAG_HEAD_ROTATION, FLAG_LAST, MORPHS_HEADER,
                         decode_contractions, decode_frame, encode_contractions, encode_frame,
                         encode_points)
from tests.api.test_wire import decode_in_node
from tests.ws_messages import replies


def _sample(client, sample_id):
    """The sample project's mesh vertices (V, 3) and landmarks (`SurfacePoints`)."""
    mesh = load_mesh(client.app.state.store.mesh_file(sample_id)[0])
    data = client.get(f"/api/projects/{sample_id}/landmarks").json()
    return mesh, landmarks_from_json(data, mesh.vertices, mesh.faces)


def test_muscles_are_placed_once_and_kept(client, sample_id):
    first = client.get(f"/api/projects/{sample_id}/muscles")
    assert first.status_code == 200
    body = first.json()
    assert len(body["names"]) == 22 and body["names"][-1] == "jaw" and len(body["limits"]) == 22
    assert body["edited"] is False and len(body["muscles"]) == 21
    stored = client.app.state.store.muscles(sample_id)
    assert stored is not None and stored[2] is False
    again = client.get(f"/api/projects/{sample_id}/muscles").json()
    assert again == body  # read back, not placed anew


def test_put_validates_and_placement_never_overwrites_it(client, sample_id):
    url = f"/api/projects/{sample_id}/muscles"
    body = client.get(url).json()
    for bad, reason in (({"muscles": []}, "malformed"),
                        ({**body, "muscles": [{**body["muscles"][0], "kind": "spring"}]}, "kind must be"),
                        ({**body, "jaw": {**body["jaw"], "weights": {**body["jaw"]["weights"], "n_vertices": 3}}},
                         "3 vertices"),
                        ({"muscles": ["x"], "jaw": {}}, "malformed"),
                        ({**body, "muscles": body["muscles"][:3]}, "Table 1's 21"),
                        ([1, 2], "")):
        answer = client.put(url, json=bad)
        assert answer.status_code == 422, answer.text
        assert reason in answer.json()["detail"]
    edited = {**body, "muscles": [{**body["muscles"][0], "strength": 2.5}, *body["muscles"][1:]]}
    saved = client.put(url, json=edited)
    assert saved.status_code == 200 and saved.json()["edited"] is True
    project = client.get(f"/api/projects/{sample_id}").json()
    store = client.app.state.store
    assert store.put_muscles(sample_id, body, revision=project["revision"], edited=False) is False
    kept = client.get(url).json()
    assert kept["edited"] is True and kept["muscles"][0]["strength"] == 2.5
    assert client.put(f"/api/projects/{'A' * 22}/muscles", json=body).status_code == 404


def test_muscles_need_landmarks(client):
    bare = client.post("/api/projects", json={"name": "no muscles"}).json()["id"]
    answer = client.get(f"/api/projects/{bare}/muscles")
    assert answer.status_code in (404, 409) and answer.json()["detail"]


def test_played_form_binary_decodes_to_muscle_morphs(client, sample_id):
    mesh, _ = _sample(client, sample_id)
    model = MuscleFace.from_json(client.get(f"/api/projects/{sample_id}/muscles").json(), mesh.vertices)
    morphs = muscle_morphs(model)
    answer = client.get(f"/api/projects/{sample_id}/muscles/played")
    assert answer.status_code == 200 and answer.headers["content-type"] == "application/octet-stream"
    data = answer.content
    magic, version, v, t, j = MORPHS_HEADER.unpack_from(data)
    m, c = len(morphs.names), len(morphs.corrective_of)
    assert (magic, version, v, t) == (b"RTMM", 1, mesh.n_vertices, m + c) and m == 21 and c > 0 and j % 4 == 0
    header = json.loads(data[MORPHS_HEADER.size:MORPHS_HEADER.size + j])
    assert header["names"] == [*morphs.names, *morphs.corrective_names] and header["dofs"] == list(model.names)
    assert header["corrective_of"] == morphs.corrective_of.tolist()
    assert header["expressions"] == list(EXPRESSIONS)
    for key, value in (("high", morphs.high), ("limits", model.limits), ("jaw_limits", morphs.jaw_limits),
                       ("jaw_pivot", morphs.jaw_pivot), ("jaw_axis", morphs.jaw_axis)):
        np.testing.assert_allclose(header[key], value)
    at = MORPHS_HEADER.size + j
    targets = np.frombuffer(data, "<f4", t * v * 3, at).reshape(t, v, 3)
    weights = np.frombuffer(data, "<f4", v, at + 12 * t * v)
    assert len(data) == at + 12 * t * v + 4 * v
    np.testing.assert_array_equal(targets[:m], morphs.targets)
    np.testing.assert_array_equal(targets[m:], morphs.correctives)
    np.testing.assert_array_equal(weights, morphs.jaw_weights)


def test_contraction_frames_reproduce_the_muscle_ik(client, sample_id):
    mesh, points = _sample(client, sample_id)
    model = MuscleFace.from_json(client.get(f"/api/projects/{sample_id}/muscles").json(), mesh.vertices)
    player = DemoPlayer(points.positions(mesh.vertices), "ibug68", fps=30)
    player.set_drive(MuscleDrive(model, points))
    twin = MuscleDrive(model, points)
    _, frames = demo_points(player.performance.layout, 30.0)
    for i in range(0, 40, 4):
        frame = decode_contractions(player.frame(i))
        c = twin.contractions(player.performance.displacements(frames[i]))
        np.testing.assert_allclose(frame.contractions, c.astype(np.float32), rtol=1e-6, atol=1e-6)
        seen = twin.recogniser.recognise(c)
        np.testing.assert_allclose(frame.distances, seen.distances[0].astype(np.float32), rtol=1e-6)
        assert EXPRESSIONS[frame.label] == seen.labels[0] and frame.frame_index == i
    assert np.abs(frame.contractions).max() > 1e-3


def test_stream_in_muscle_mode_sends_contraction_frames(client, sample_id, capsys):
    mesh, points = _sample(client, sample_id)
    model = MuscleFace.from_json(client.get(f"/api/projects/{sample_id}/muscles").json(), mesh.vertices)
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "drive", "drive": "wings"})
        assert "'muscles'" in ws.receive_json()["detail"]
        ws.send_json({"type": "drive", "drive": "muscles"})
        assert ws.receive_json() == {"type": "drive", "drive": "muscles"}
        ws.send_json({"type": "start", "source": "demo", "fps": 5})
        first = None
        while first is None:
            message = ws.receive()
            if message.get("bytes") is not None:
                first = message["bytes"]
        assert first[:4] == CONTRACTIONS_MAGIC
        frame = decode_contractions(first)
        assert frame.contractions.shape == (22,) and frame.distances.shape == (7,)
        assert 0 <= frame.label < 7 and 0.0 <= frame.confidence <= 1.0
        if frame.frame_index == 0:  # a fresh drive's first frame: the IK from rest
            player = DemoPlayer(points.positions(mesh.vertices), "ibug68", fps=5)
            expected = MuscleDrive(model, points).contractions(player.displacements(0))
            np.testing.assert_allclose(frame.contractions, expected.astype(np.float32), atol=1e-5)
        ws.send_json({"type": "drive", "drive": "points"})
        assert replies(ws, 1)[0] == {"type": "drive", "drive": "points"}
        while True:
            message = ws.receive()
            if message.get("bytes") is not None and message["bytes"][:4] == b"RTDF":
                points_frame = message["bytes"]
                break
        ws.send_json({"type": "stop"})
    assert decode_frame(points_frame).displacements.shape == (68, 3)
    rotated = 16
    with capsys.disabled():
        print(f"\nstream bytes per frame, 68 points: feature points {len(points_frame)} "
              f"(+{rotated} with head rotation), muscles {len(first)}")
    assert len(first) == 32 + 4 * (22 + 7 + 2) < len(encode_frame(np.zeros((68, 3)), frame_index=0,
                                                                   source_time=0.0))
    assert struct.unpack_from("<H", first, 12)[0] == 22


def test_javascript_decodes_contraction_frames_and_played_muscles(client, sample_id, tmp_path):
    rng = np.random.default_rng(5)
    muscle = MuscleFrame(rng.normal(size=22), rng.random(7), 4, 0.25)
    q = np.array([0.1, -0.2, 0.05, 0.97], np.float32)
    frames = [encode_contractions(muscle, frame_index=2**32 - 1, source_time=-3.25, send_time=1.7e9),
              encode_contractions(muscle, frame_index=7, source_time=0.5, flags=FLAG_LAST, send_time=1.7e9,
                                  head_rotation=q)]
    plain, rotated = decode_in_node(tmp_path, frames, "decode-contractions")
    for js in (plain, rotated):
        assert js["bits"] == _bits(muscle.contractions) and js["distanceBits"] == _bits(muscle.distances)
        assert js["label"] == 4 and js["confidenceBits"] == _bits([0.25]) and js["sendTime"] == 1.7e9
    assert plain["frameIndex"] == 2**32 - 1 and plain["sourceTime"] == -3.25 and plain["rotationBits"] is None
    assert rotated["flags"] == FLAG_LAST | FLAG_HEAD_ROTATION and rotated["rotationBits"] == _bits(q)
    assert "ContractionDecoder" in decode_in_node(tmp_path, [frames[0][:-4]], "decode-contractions")[0]["error"]

    data = client.get(f"/api/projects/{sample_id}/muscles/played").content
    js, = decode_in_node(tmp_path, [data], "decode-morphs")
    _, _, v, m, j = MORPHS_HEADER.unpack_from(data)
    assert (js["nVertices"], js["nTargets"]) == (v, m)
    assert js["header"] == json.loads(data[MORPHS_HEADER.size:MORPHS_HEADER.size + j])
    at = MORPHS_HEADER.size + j
    assert js["targetBits"] == np.frombuffer(data, "<u4", 3 * m * v, at).tolist()
    assert js["jawBits"] == np.frombuffer(data, "<u4", v, at + 12 * m * v).tolist()
    assert "MuscleMorphsDecoder" in decode_in_node(tmp_path, [data[:-4]], "decode-morphs")[0]["error"]


def _bits(values) -> list[int]:
    return np.ascontiguousarray(values, dtype="<f4").view(np.uint32).tolist()


def test_new_landmarks_place_the_muscles_anew_unless_the_user_saved_his(client, sample_id):
    """Saves the sample's landmarks again, which drops its rig (no later test needs it)."""
    store, url = client.app.state.store, f"/api/projects/{sample_id}/muscles"
    client.put(url, json=client.get(url).json())  # the user's
    landmarks = client.get(f"/api/projects/{sample_id}/landmarks").json()
    assert client.put(f"/api/projects/{sample_id}/landmarks", json=landmarks).status_code == 200
    kept = client.get(url).json()
    assert kept["edited"] is True  # outlives the landmarks change (it fits the mesh)
    revision = client.get(f"/api/projects/{sample_id}").json()["revision"]
    assert store.put_muscles(sample_id, kept, revision=revision, edited=False)  # placed over older edits
    assert client.put(f"/api/projects/{sample_id}/landmarks", json=landmarks).status_code == 200
    placed = client.get(url).json()
    assert placed["edited"] is False and store.muscles(sample_id)[1] == revision + 1


def test_a_drive_that_cannot_be_made_is_refused_and_changes_nothing(client, sample_id, monkeypatch):
    def refuse(store, project_id):
        raise RetargetError("placing muscles needs six iBUG points")

    monkeypatch.setattr(stream, "_muscle_drive", refuse)
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "drive", "drive": "muscles"})
        assert "six iBUG points" in ws.receive_json()["detail"]
        assert client.app.state.hub.drive(sample_id) == "points"


def test_a_live_source_driven_by_muscles_sends_contraction_frames(client, sample_id):
    face = sample_face(1)
    weights = np.zeros(len(EXPRESSION_NAMES))
    weights[EXPRESSION_NAMES.index("jawOpen")] = 1.0
    neutral = face.vertices[face.landmarks68].astype(np.float32)
    opened = posed_vertices(face, weights)[face.landmarks68].astype(np.float32)
    with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "drive", "drive": "muscles"})
        ws.send_json({"type": "start", "source": "live", "dims": 3,
                      "settings": {"neutral": {"mode": "frame", "frame": 0}, "filter": "none"}})
        assert [r["type"] for r in replies(ws, 2)] == ["drive", "started"]
        for i, points in enumerate([neutral] + [opened] * 4):
            ws.send_bytes(encode_points(points, frame_index=i, capture_time=i / 30))
        last = None
        while last is None or last.frame_index < 4:
            message = ws.receive()
            if message.get("bytes") is not None:
                last = decode_contractions(message["bytes"])
        ws.send_json({"type": "stop"})
    assert last.contractions[-1] > 0.1  # the performer's open mouth opens the target's jaw
