"""The live stream over a real WebSocket (in-process): hello, demo frames, masks, errors."""

import asyncio
import io
import time

import numpy as np
import pytest
from fastapi.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from retarget.layouts import get_layout
from server.hub import StreamHub
from server.wire import FLAG_NEUTRAL, decode_frame
from tests.ws_messages import binary_frames, replies


def test_hello_then_demo_frames_arrive_and_move(app, sample_id):
    with TestClient(app) as client, client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        hello = ws.receive_json()
        assert hello == {"type": "hello", "project": sample_id, "n_points": 68, "layout": "ibug68", "source": None}
        ws.send_json({"type": "start", "source": "demo", "fps": 120})
        got = binary_frames(ws, 12)
        assert all(f.displacements.shape == (68, 3) and np.isfinite(f.displacements).all() for f in got)
        indices = [f.frame_index for f in got]
        assert indices == sorted(indices) and len(set(indices)) == len(indices)
        assert max(np.abs(f.displacements).max() for f in got) > 1e-3
        ws.send_json({"type": "stop"})


def test_mask_leaves_other_regions_at_rest(app, sample_id):
    brows = get_layout("ibug68").region_mask("brows")
    with TestClient(app) as client, client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "start", "fps": 120})
        binary_frames(ws, 2)
        ws.send_json({"type": "mask", "regions": ["brows"]})
        later = binary_frames(ws, 30)[-20:]  # a frame or two may predate the mask
        assert all(np.all(f.displacements[~brows] == 0.0) for f in later)
        assert max(np.abs(f.displacements[brows]).max() for f in later) > 0.0
        ws.send_json({"type": "mask", "regions": None})
        ws.send_json({"type": "stop"})


def test_two_viewers_both_receive(app, sample_id):
    with TestClient(app) as client:
        with client.websocket_connect(f"/api/projects/{sample_id}/stream") as a, \
                client.websocket_connect(f"/api/projects/{sample_id}/stream") as b:
            a.receive_json()
            b.receive_json()
            a.send_json({"type": "start", "fps": 120})
            assert len(binary_frames(a, 5)) == 5 and len(binary_frames(b, 5)) == 5
            a.send_json({"type": "stop"})


def test_bad_control_messages_get_an_error_and_the_stream_goes_on(app, sample_id):
    with TestClient(app) as client, client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        replies = []
        for bad in ("not json", '{"no": "type"}', '{"type": "dance"}', '{"type": "mask", "regions": ["lips"]}',
                    '{"type": "start", "source": "webcam"}'):
            ws.send_text(bad)
            replies.append(ws.receive_json())
        assert [r["type"] for r in replies] == ["error"] * 5
        assert "not JSON" in replies[0]["detail"] and "'dance'" in replies[2]["detail"]
        assert "'lips'" in replies[3]["detail"] and "'webcam'" in replies[4]["detail"]
        ws.send_json({"type": "ping", "t": 1.5})
        pong = ws.receive_json()
        assert pong["type"] == "pong" and pong["t"] == 1.5 and pong["server_time"] > 0


def test_unknown_project_and_project_without_landmarks_are_closed_with_1008(app):
    with TestClient(app) as client:
        bare = client.post("/api/projects", json={"name": "no landmarks"}).json()["id"]
        for pid, reason in (("A" * 22, "no project"), (bare, "no landmarks")):
            with client.websocket_connect(f"/api/projects/{pid}/stream") as ws:
                with pytest.raises(WebSocketDisconnect) as closed:
                    ws.receive_json()
                assert closed.value.code == 1008 and reason in closed.value.reason


def test_a_slow_viewer_holds_only_the_newest_frame():
    async def scenario():
        hub = StreamHub()
        box = hub.subscribe("p")
        for i in range(100):  # a publisher far faster than the viewer
            hub.publish("p", bytes([i]))
            assert box.backlog <= 1
        newest = await box.take()
        hub.unsubscribe("p", box)
        return newest, box.dropped, hub.viewer_count("p")

    newest, dropped, left = asyncio.run(scenario())
    assert newest == bytes([99]) and dropped == 99 and left == 0




def test_bad_fps_mid_stream_is_an_error_and_frames_keep_coming(app, sample_id):
    with TestClient(app) as client, client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "start", "fps": 120})
        assert replies(ws, 1) == [{"type": "started", "source": "demo", "fps": 120.0, "recording": False,
                                  "drive": "points"}]
        before = binary_frames(ws, 2)[-1].frame_index
        for fps in (None, "fast", [60], 0, 1e6):
            ws.send_json({"type": "start", "fps": fps})
            reply = replies(ws, 1)[0]
            assert reply["type"] == "error" and "fps" in reply["detail"]
        assert binary_frames(ws, 3)[-1].frame_index > before  # the running source was not replaced
        ws.send_json({"type": "stop"})


def test_the_last_viewer_leaving_stops_the_source(app, sample_id):
    hub = app.state.hub
    with TestClient(app) as client:
        with client.websocket_connect(f"/api/projects/{sample_id}/stream") as a, \
                client.websocket_connect(f"/api/projects/{sample_id}/stream") as b:
            a.receive_json()
            b.receive_json()
            a.send_json({"type": "start", "fps": 120})
            binary_frames(a, 2)
        with client.websocket_connect(f"/api/projects/{sample_id}/stream") as c:
            assert c.receive_json()["source"] is None  # the departed viewers' source is gone
        deadline = time.monotonic() + 5.0
        while hub.viewer_count(sample_id) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert hub.viewer_count(sample_id) == 0 and hub.source(sample_id) is None


def test_a_slow_concurrent_viewer_gets_the_newest_frame_and_never_a_backlog():
    async def scenario():
        hub = StreamHub()
        box = hub.subscribe("p")
        backlogs, received = [], []

        async def publisher():
            for i in range(60):
                hub.publish("p", i.to_bytes(4, "little"))
                backlogs.append(box.backlog)
                await asyncio.sleep(0.001)

        async def viewer():
            while not received or received[-1] != 59:
                received.append(int.from_bytes(await box.take(), "little"))
                await asyncio.sleep(0.01)  # ten times slower than the publisher

        async with asyncio.TaskGroup() as group:
            group.create_task(publisher())
            group.create_task(viewer())
        return hub, box, backlogs, received

    hub, box, backlogs, received = asyncio.run(scenario())
    assert max(backlogs) == 1 and received[-1] == 59
    assert received == sorted(set(received)) and len(received) < 30
    assert box.dropped == 60 - len(received) and box.delivered == len(received)


def test_demo_drives_every_layout_through_its_ibug_indices(app, sample_id):
    """A project picked with the 21-point Dutreve layout streams the demo too."""
    layout = get_layout("dutreve21")
    with TestClient(app) as client:
        sample = client.get(f"/api/projects/{sample_id}/landmarks").json()
        pid = client.post("/api/projects", json={"name": "21 points"}).json()["id"]
        mesh = client.get(f"/api/projects/{sample_id}/mesh").content
        assert client.put(f"/api/projects/{pid}/mesh", files={"file": ("face.obj", mesh)}).status_code == 200
        picked = {"layout": "dutreve21",
                  "vertex_indices": [sample["vertex_indices"][i] for i in layout.ibug68]}
        assert client.put(f"/api/projects/{pid}/landmarks", json=picked).status_code == 200
        with client.websocket_connect(f"/api/projects/{pid}/stream") as ws:
            assert ws.receive_json()["n_points"] == 21
            ws.send_json({"type": "start", "fps": 120})
            got = binary_frames(ws, 10)
            assert all(f.displacements.shape == (21, 3) for f in got)
            assert max(np.abs(f.displacements).max() for f in got) > 1e-3


def test_stop_sends_a_neutral_frame(app, sample_id):
    with TestClient(app) as client, client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "start", "fps": 120})
        binary_frames(ws, 3)
        ws.send_json({"type": "stop"})
        for _ in range(200):  # frames already in flight may precede it
            (frame,) = binary_frames(ws, 1)
            if frame.flags & FLAG_NEUTRAL:
                break
        assert frame.flags & FLAG_NEUTRAL and np.all(frame.displacements == 0.0)


def test_after_a_stall_the_demo_skips_to_the_due_frame_instead_of_a_stale_burst():
    from retarget.sample_face import sample_face
    from server.players import DemoPlayer

    face = sample_face(1)
    source = DemoPlayer(face.vertices[face.landmarks68], "ibug68", fps=100.0)

    class Recorder(StreamHub):
        published: list[int] = []

        def publish(self, project_id, frame):
            self.published.append(decode_frame(frame).frame_index)

    async def scenario():
        hub = Recorder()
        hub.subscribe("p")
        task = asyncio.get_running_loop().create_task(source.run(hub, "p"))
        await asyncio.sleep(0.1)
        before = len(hub.published)
        time.sleep(0.3)  # the event loop stalls for 30 frames
        await asyncio.sleep(0.1)
        task.cancel()
        return hub.published, before

    published, before = asyncio.run(scenario())
    jump = published[before] - published[before - 1]
    assert jump >= 25, f"after a 0.3 s stall the next frame index moved by {jump}, not ~30"
    assert len(published) < before + 25, "the missed frames were published as a burst"


def test_any_source_records_its_raw_points_into_a_take(app, sample_id):
    """Record the demo, then record a replay of that recording: each take holds the raw
    source points played, in order (a loaded server may skip frames that came due while
    it was busy, so the frames need not be consecutive)."""
    from retarget.sample_face import demo_performance

    fps = 60.0
    neutral68, frames68 = demo_performance(fps)
    with TestClient(app) as client, client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "record"})
        assert "none is running" in replies(ws, 1)[0]["detail"]
        ws.send_json({"type": "start", "source": "demo", "fps": fps})
        assert replies(ws, 1)[0]["type"] == "started"
        ws.send_json({"type": "record"})
        assert replies(ws, 1)[0]["type"] == "recording"
        binary_frames(ws, 40)
        ws.send_json({"type": "record_stop"})
        demo_take = replies(ws, 1)[0]["take"]
        assert demo_take["name"] == "demo take" and demo_take["source"] == "demo"
        recorded = np.load(io.BytesIO(client.get(
            f"/api/projects/{sample_id}/takes/{demo_take['id']}/points").content))
        assert recorded.shape[1:] == (68, 3) and len(recorded) >= 30
        assert_frames_in_order(recorded, frames68)

        ws.send_json({"type": "start", "source": "take", "take": demo_take["id"], "loop": False,
                      "settings": {"neutral": {"mode": "frame", "frame": 0}}})
        assert replies(ws, 1)[0]["type"] == "started"
        ws.send_json({"type": "record"})
        assert replies(ws, 1)[0]["type"] == "recording"
        binary_frames(ws, 5)
        ws.send_json({"type": "record_stop", "name": "replay"})
        replay = replies(ws, 1)[0]["take"]
    again = np.load(io.BytesIO(client.get(f"/api/projects/{sample_id}/takes/{replay['id']}/points").content))
    assert replay["source"] == "take" and len(again) >= 5
    assert_frames_in_order(again, recorded)


def assert_frames_in_order(recorded: np.ndarray, played: np.ndarray) -> None:
    """Every recorded (N, 3) frame is one of `played`, and they come in playing order
    (one wrap-around allowed: the demo loops)."""
    distance = np.abs(recorded[:, None] - played[None]).max(axis=(2, 3))   # (R, P)
    index = distance.argmin(axis=1)
    assert distance[np.arange(len(recorded)), index].max() < 1e-5
    steps = np.diff(index)
    assert (steps > 0).sum() >= len(steps) - 1, index


def test_a_take_played_once_marks_its_last_frame(app, sample_id):
    from retarget.sample_face import demo_performance
    from server.wire import FLAG_LAST

    _, frames68 = demo_performance(30.0)
    buffer = io.BytesIO()
    np.save(buffer, frames68[:45].astype(np.float32))
    with TestClient(app) as client:
        take = client.post(f"/api/projects/{sample_id}/takes", files={"file": ("once.npy", buffer.getvalue())},
                           data={"layout": "ibug68"}).json()
        with client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
            ws.receive_json()
            ws.send_json({"type": "start", "source": "take", "take": take["id"], "loop": False,
                          "settings": {"neutral": {"mode": "frame", "frame": 0}}})
            started = replies(ws, 1)[0]
            got = []
            while not got or not got[-1].flags & FLAG_LAST:
                got += binary_frames(ws, 1)
    assert started["frames"] == 45 and got[-1].frame_index == 44
    assert not any(f.flags & FLAG_LAST for f in got[:-1])


def test_a_recording_outlives_its_source(app, sample_id):
    """Stopping the source (or a take played once ending) while recording keeps the
    recording for the next record_stop; a second record_stop has nothing left."""
    with TestClient(app) as client, client.websocket_connect(f"/api/projects/{sample_id}/stream") as ws:
        ws.receive_json()
        ws.send_json({"type": "start", "source": "demo", "fps": 60})
        ws.send_json({"type": "record"})
        assert [r["type"] for r in replies(ws, 2)] == ["started", "recording"]
        binary_frames(ws, 20)
        ws.send_json({"type": "stop"})
        assert replies(ws, 1)[0]["type"] == "stopped"
        ws.send_json({"type": "record_stop", "name": "after stop"})
        saved = replies(ws, 1)[0]
        assert saved["type"] == "recorded" and saved["take"]["n_frames"] >= 15
        ws.send_json({"type": "record_stop"})
        assert "none is running" in replies(ws, 1)[0]["detail"]

        ws.send_json({"type": "start", "source": "take", "take": saved["take"]["id"], "loop": False,
                      "settings": {"neutral": {"mode": "frame", "frame": 0}}})
        ws.send_json({"type": "record"})
        assert [r["type"] for r in replies(ws, 2)] == ["started", "recording"]
        played = binary_frames(ws, 1)
        while not played[-1].flags & 8:  # FLAG_LAST: the take has ended
            played += binary_frames(ws, 1)
        ws.send_json({"type": "record_stop", "name": "to the end"})
        replay = replies(ws, 1)[0]
    assert replay["type"] == "recorded" and replay["take"]["source"] == "take"
    # every frame played while recording is in the recording; a loaded machine may skip
    # frames that fell due during a stall (a live player does not burst stale frames), so
    # the count is the frames seen, not the take's
    assert played[-1].frame_index == saved["take"]["n_frames"] - 1
    assert replay["take"]["n_frames"] >= len(played)
