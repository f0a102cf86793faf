"""A live source's neutral capture over the stream (issue 13 item 4): a performer who moves
during it is answered ``neutral_refused`` with the reason and the face is not driven from
that neutral; a ``neutral`` request captures again, and a still face is taken."""

import numpy as np
import pytest
from fastapi.testclient import TestClient

from retarget.sample_face import EXPRESSION_NAMES, posed_vertices, sample_face
from server.app import create_app
from server.wire import encode_points
from tests.ws_messages import binary_frames, replies

FACE = sample_face(1)
NEUTRAL = FACE.vertices[FACE.landmarks68].astype(np.float32)
WEIGHTS = np.zeros(len(EXPRESSION_NAMES))
WEIGHTS[EXPRESSION_NAMES.index("cheekPuff")] = WEIGHTS[EXPRESSION_NAMES.index("jawOpen")] = 1.0
PUFFED = posed_vertices(FACE, WEIGHTS)[FACE.landmarks68].astype(np.float32)


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    return create_app(tmp_path_factory.mktemp("data"))  # with the built-in sample project


def _push(ws, frames, start_index, t0):
    for i, points in enumerate(frames):
        ws.send_bytes(encode_points(points, frame_index=start_index + i, capture_time=t0 + i / 30))


def test_moving_during_the_capture_is_refused_and_a_still_capture_is_taken(app):
    with TestClient(app) as client:
        sample = next(p["id"] for p in client.get("/api/projects").json() if p["landmarks"])
        with client.websocket_connect(f"/api/projects/{sample}/stream") as ws:
            ws.receive_json()
            ws.send_json({"type": "start", "source": "live", "dims": 3,
                          "settings": {"neutral": {"mode": "first_seconds", "seconds": 0.5}}})
            assert replies(ws, 1)[0]["type"] == "started"
            # 0.25 s still, then the cheeks puff and the jaw opens within the window
            _push(ws, [NEUTRAL] * 8 + [PUFFED] * 12, 0, 0.0)
            refused = replies(ws, 1)[0]
            assert refused["type"] == "neutral_refused"
            assert refused["detail"].startswith("You moved during the neutral capture: hold still and capture again")
            # no neutral from the still frames that follow either, until asked again
            _push(ws, [NEUTRAL] * 30, 20, 1.0)
            ws.send_json({"type": "ping", "t": 0})
            message = ws.receive()
            assert message.get("text") is not None and '"pong"' in message["text"]  # no frame came first
            ws.send_json({"type": "neutral"})
            assert replies(ws, 1)[0]["type"] == "neutral"
            _push(ws, [NEUTRAL] * 16 + [PUFFED], 50, 3.0)  # t <= 3.5 s: the window
            frame = binary_frames(ws, 1)[0]
            assert frame.frame_index == 66  # the first frame past the still window
            assert np.abs(frame.displacements).max() > 0.1  # cm: the puffed face moves the target
            ws.send_json({"type": "stop"})
