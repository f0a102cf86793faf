"""Reading a stream WebSocket in tests: the next binary frames or JSON replies."""

import json

from server.wire import decode_frame


def binary_frames(ws, n: int) -> list:
    """The next n binary frames, decoded, skipping JSON replies."""
    out = []
    while len(out) < n:
        message = ws.receive()
        if message.get("bytes") is not None:
            out.append(decode_frame(message["bytes"]))
    return out


def replies(ws, n: int) -> list[dict]:
    """The next n JSON replies, skipping binary frames."""
    out = []
    while len(out) < n:
        message = ws.receive()
        if message.get("text") is not None:
            out.append(json.loads(message["text"]))
    return out
