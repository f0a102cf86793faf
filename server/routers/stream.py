"""The live stream: ``WS /api/projects/{id}/stream``.

On connect the server sends a JSON hello ``{"type": "hello", "project", "n_points",
"layout", "fps"}``, then binary frames (`server.stream_codec`) whenever the project's
source publishes. Control messages are JSON text:

- ``{"type": "start", "source": "demo", "fps": 60}``: start (or restart) the built-in demo
  performance for the project (`server.sources.DemoSource`);
- ``{"type": "stop"}``: stop it; every viewer then gets a neutral frame (flag bit 0, zero
  displacements) that puts the face back at rest;
- ``{"type": "mask", "regions": ["mouth", ...]}``: partial retargeting, only those
  regions, groups or points move (empty or null: all);
- ``{"type": "ping", "t": <client time>}``: answered ``{"type": "pong", "t", "server_time"}``.

A malformed control message is answered ``{"type": "error", "detail"}`` and the stream goes
on. An unknown project, or one without landmarks, is closed with code 1008 and a reason.
Each viewer runs a receiver and a sender coroutine in one task group; the sender always
sends the newest frame of the viewer's one-slot mailbox (`server.hub`), so a slow viewer
drops stale frames instead of queueing them. The source, its fps and its regions belong
to the project, shared by all its viewers; the last viewer leaving stops the source.
"""

from __future__ import annotations

import asyncio
import json
import time

import numpy as np
from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from starlette.websockets import WebSocketState

from retarget.errors import RetargetError
from retarget.landmarks import landmarks_from_json
from retarget.layouts import get_layout
from server.deps import HubDep, StoreDep
from server.hub import Mailbox, StreamHub
from server.sources import DemoSource
from server.stream_codec import FLAG_NEUTRAL, encode_frame
from server.store import ProjectNotFound

router = APIRouter(tags=["stream"])
POLICY_VIOLATION = 1008
DEFAULT_FPS = 60.0


@router.websocket("/api/projects/{project_id}/stream")
async def stream(websocket: WebSocket, project_id: str, store: StoreDep, hub: HubDep) -> None:
    await websocket.accept()
    try:
        project = store.get(project_id)
        target_points, layout = await asyncio.to_thread(_target_points, store, project)
    except (ProjectNotFound, RetargetError) as exc:
        await websocket.close(code=POLICY_VIOLATION, reason=str(exc)[:120])
        return
    source = hub.source(project_id)
    await websocket.send_json({"type": "hello", "project": project_id, "n_points": len(target_points),
                               "layout": layout, "fps": source.fps if source else None})
    box = hub.subscribe(project_id)
    sending = asyncio.Lock()  # the two coroutines share one socket
    try:
        async with asyncio.TaskGroup() as group:
            sender = group.create_task(_send_frames(websocket, box, sending))
            group.create_task(_receive_controls(websocket, sending, hub, project_id, target_points,
                                                layout, on_disconnect=sender.cancel))
    finally:
        hub.unsubscribe(project_id, box)


def _target_points(store, project: dict):
    """(N, 3) landmark positions on the project's mesh and the layout name."""
    landmarks = store.landmarks(project["id"])
    mesh = store.mesh(project["id"])
    if landmarks is None or mesh is None:
        raise RetargetError(f"project {project['id']!r} has no landmarks yet: place them before streaming")
    points = landmarks_from_json(landmarks, mesh.vertices, mesh.faces)
    return points.positions(mesh.vertices), landmarks.get("layout") or ""


async def _send_frames(websocket: WebSocket, box: Mailbox, sending: asyncio.Lock) -> None:
    try:
        while True:
            frame = await box.take()
            async with sending:
                await websocket.send_bytes(frame)
    except (WebSocketDisconnect, RuntimeError):
        return  # the receiver sees the disconnect and ends the task group


async def _receive_controls(websocket, sending, hub, project_id, target_points, layout, *,
                            on_disconnect) -> None:
    while True:
        message = await websocket.receive()
        if message["type"] == "websocket.disconnect":
            on_disconnect()
            return
        try:
            reply = await _control(message.get("text"), hub, project_id, target_points, layout)
        except (ValueError, RetargetError) as exc:
            reply = {"type": "error", "detail": str(exc)}
        if reply is not None and websocket.client_state == WebSocketState.CONNECTED:
            async with sending:
                await websocket.send_json(reply)


async def _control(text, hub: StreamHub, project_id, target_points, layout) -> dict | None:
    if text is None:
        raise ValueError("control messages are JSON text; binary messages are not accepted")
    try:
        msg = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"control message is not JSON: {exc}") from exc
    if not isinstance(msg, dict) or not isinstance(msg.get("type"), str):
        raise ValueError('control message must be an object with a "type"')
    kind = msg["type"]
    if kind == "ping":
        return {"type": "pong", "t": msg.get("t"), "server_time": time.time()}
    if kind == "start":
        if msg.get("source", "demo") != "demo":
            raise ValueError(f"unknown source {msg.get('source')!r}; available: 'demo'")
        fps = msg.get("fps", DEFAULT_FPS)
        if isinstance(fps, bool) or not isinstance(fps, (int, float)):
            raise ValueError(f'"fps" must be a number of frames per second; got {fps!r}')
        source = await asyncio.to_thread(DemoSource, target_points, layout, float(fps))
        hub.start_source(project_id, source)
        return {"type": "started", "source": "demo", "fps": source.fps}
    if kind == "stop":
        hub.stop_source(project_id)
        # every viewer puts its face back at rest
        hub.publish(project_id, encode_frame(np.zeros((len(target_points), 3), np.float32),
                                             frame_index=0, source_time=0.0, flags=FLAG_NEUTRAL))
        return {"type": "stopped"}
    if kind == "mask":
        regions = msg.get("regions") or None
        if regions is not None and not (isinstance(regions, list) and all(isinstance(r, str) for r in regions)):
            raise ValueError('"regions" must be a list of region, group or point names')
        if regions is not None:
            get_layout(layout or "ibug68").region_mask(regions)  # RetargetError for unknown names
        hub.set_regions(project_id, regions)
        return {"type": "mask", "regions": regions}
    raise ValueError(f"unknown control message type {kind!r}")
