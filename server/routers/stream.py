"""The live stream: ``WS /api/projects/{id}/stream``.

On connect the server sends a JSON hello ``{"type": "hello", "project", "n_points",
"layout", "source"}`` (source: the running source's description or null), then binary
frames (`server.wire`) whenever the project's source publishes. Control messages
are JSON text:

- ``{"type": "start", "source": "demo", "fps": 60}``: start (or restart) the built-in demo
  performance for the project (`server.players.DemoPlayer`);
- ``{"type": "start", "source": "take", "take": <take id>, "loop": true, "settings": {...}}``:
  replay a stored take (`server.players.TakePlayer`); settings are
  `retarget.sources.conditioning.ConditionSettings` (neutral, head pose, filter, gain);
- ``{"type": "start", "source": "live", "dims": 3, "settings": {...}}``: points tracked by
  this viewer follow as binary source-points messages (`server.wire.decode_points`,
  N = the layout's points) and are retargeted as they arrive (`server.players.LivePlayer`);
- ``{"type": "settings", "settings": {...}}``: change the running take or live source's
  conditioning (a live source keeps its captured neutral unless the neutral mode changes);
- ``{"type": "neutral"}``: a live source captures its neutral again from the next frames;
  a capture during which the performer moved is answered ``{"type": "neutral_refused",
  "detail"}`` and none is taken until the next ``neutral`` (`retarget.sources.conditioning.NeutralMoved`);
- ``{"type": "record"}`` / ``{"type": "record_stop", "name": "..."}``: record the running
  source's raw points (demo, take or live); stopping stores them as a take and answers
  ``{"type": "recorded", "take": {...}}``. A source that stops or ends while recording
  keeps its recording for one ``record_stop`` (a take played once ends by itself);
- ``{"type": "stop"}``: stop the source; every viewer then gets a neutral frame (flag bit 0,
  zero displacements) that puts the face back at rest;
- ``{"type": "mask", "regions": ["mouth", ...]}``: partial retargeting, only those
  regions, groups or points move (empty or null: all);
- ``{"type": "drive", "drive": "points" | "muscles" | "arkit"}``: what the project's
  sources are driven by, the running one from its next frame: feature points (RTDF
  frames), the project's muscles (`server.routers.muscles.project_muscles`, placed if need
  be), each frame solved into contractions and an expression (RTMC frames), or ARKit's 52
  blendshapes (`server.routers.arkit`: the shapes must have been made), each frame solved
  into the 52 weights, the user's gains applied (RTAW frames); answered
  ``{"type": "drive", "drive"}``;
- ``{"type": "format", "format": "binary" | "json"}`` (or ``?format=json`` on the URL):
  how this viewer gets ARKit weight frames: RTAW bytes (default) or JSON text
  ``{"type": "weights", "frame", "t", "sent", "weights": {"eyeBlinkLeft": 0.1, ...},
  "head_rotation", "lost", "last"}`` (`server.wire.weights_json`), the same 52 numbers
  for a tool that reads ARKit curves (a VTuber rig, a game engine, a recorder); answered
  ``{"type": "format", "format"}``. Frames of the other drives stay binary;
- ``{"type": "ping", "t": <client time>}``: answered ``{"type": "pong", "t", "server_time"}``.

A malformed control message (or a points message that does not fit) is answered
``{"type": "error", "detail"}`` and the stream goes on. An unknown project, or one without landmarks, is closed with code 1008 and a reason.
Each viewer runs a receiver and a sender coroutine in one task group; the sender always
sends the newest frame of the viewer's one-slot mailbox (`server.hub`), so a slow viewer
drops stale frames instead of queueing them. The source, its fps and its regions belong
to the project, shared by all its viewers; the last viewer leaving stops the source.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time

import numpy as np
from fastapi import APIRouter, WebSocket, WebSocketDisconnect
from starlette.websockets import WebSocketState
from uvicorn.protocols.utils import ClientDisconnected
from websockets.exceptions import ConnectionClosed

from retarget.arkit import ARKIT_NAMES
from retarget.errors import RetargetError
from retarget.landmarks import landmarks_from_json
from retarget.layouts import get_layout
from retarget.muscles.drive import MuscleDrive
from server.deps import HubDep, StoreDep
from server.hub import Mailbox, StreamHub
from retarget.sources.conditioning import ConditionSettings, NeutralMoved
from server.players import DemoPlayer, LivePlayer, TakePlayer
from server.routers.arkit import project_drive
from server.routers.muscles import project_muscles
from server.wire import FLAG_NEUTRAL, decode_points, encode_frame, is_arkit_weights, weights_json
from server.store import ProjectNotFound, TakeNotFound

router = APIRouter(tags=["stream"])
log = logging.getLogger(__name__)
POLICY_VIOLATION = 1008
DEFAULT_FPS = 60.0
DRIVES = ("points", "muscles", "arkit")
FORMATS = ("binary", "json")


@router.websocket("/api/projects/{project_id}/stream")
async def stream(websocket: WebSocket, project_id: str, store: StoreDep, hub: HubDep) -> None:
    try:
        await _serve(websocket, project_id, store, hub)
    except GONE:
        return  # the viewer left (even before the hello): nothing to answer, nothing to log


GONE = (WebSocketDisconnect, ConnectionClosed, ClientDisconnected)
"""What sending or receiving raises once the viewer has gone (uvicorn's websockets or
wsproto implementation)."""


async def _serve(websocket: WebSocket, project_id: str, store, hub: StreamHub) -> None:
    await websocket.accept()
    try:
        project = store.get(project_id)
        target_points, layout = await asyncio.to_thread(target_points_of, store, project)
    except (ProjectNotFound, RetargetError) as exc:
        await websocket.close(code=POLICY_VIOLATION, reason=str(exc)[:120])
        return
    source = hub.source(project_id)
    viewer = {"format": "json" if websocket.query_params.get("format") == "json" else "binary"}
    await websocket.send_json({"type": "hello", "project": project_id, "n_points": len(target_points),
                               "layout": layout, "source": source.describe() if source else None})
    box = hub.subscribe(project_id)
    sending = asyncio.Lock()  # the two coroutines share one socket
    try:
        async with asyncio.TaskGroup() as group:
            sender = group.create_task(_send_frames(websocket, box, sending, viewer))
            group.create_task(_receive_controls(websocket, sending, hub, store, project_id,
                                                target_points, layout, viewer, on_disconnect=sender.cancel))
    except* GONE:
        pass
    finally:
        hub.unsubscribe(project_id, box)


def target_points_of(store, project: dict):
    """(N, 3) landmark positions on the project's mesh and the layout name."""
    landmarks = store.landmarks(project["id"])
    mesh = store.mesh(project["id"])
    if landmarks is None or mesh is None:
        raise RetargetError(f"project {project['id']!r} has no landmarks yet: place them before streaming")
    points = landmarks_from_json(landmarks, mesh.vertices, mesh.faces)
    return points.positions(mesh.vertices), landmarks.get("layout") or ""


async def _send_frames(websocket: WebSocket, box: Mailbox, sending: asyncio.Lock, viewer: dict) -> None:
    try:
        while True:
            frame = await box.take()
            async with sending:
                if viewer["format"] == "json" and is_arkit_weights(frame):
                    await websocket.send_text(json.dumps(weights_json(frame, ARKIT_NAMES)))
                else:
                    await websocket.send_bytes(frame)
    except (*GONE, RuntimeError):
        return  # the receiver sees the disconnect and ends the task group


async def _receive_controls(websocket, sending, hub, store, project_id, target_points, layout, viewer, *,
                            on_disconnect) -> None:
    while True:
        message = await websocket.receive()
        if message["type"] == "websocket.disconnect":
            on_disconnect()
            return
        try:
            if message.get("bytes") is not None:
                reply = _points(message["bytes"], hub, project_id)
            else:
                reply = await _control(message.get("text"), hub, store, project_id, target_points, layout, viewer)
        except NeutralMoved as exc:
            reply = {"type": "neutral_refused", "detail": str(exc)}
        except (ValueError, RetargetError, TakeNotFound) as exc:
            reply = {"type": "error", "detail": str(exc)}
        except Exception as exc:  # noqa: BLE001 - one bad message never ends the stream
            log.exception("stream control message of project %s failed", project_id)
            reply = {"type": "error", "detail": f"the server could not act on this message "
                                                f"({type(exc).__name__}); the stream goes on"}
        if reply is not None and websocket.client_state == WebSocketState.CONNECTED:
            async with sending:
                await websocket.send_json(reply)


def _points(data: bytes, hub: StreamHub, project_id) -> dict | None:
    """A tracked frame for the project's live source."""
    source = hub.source(project_id)
    if not isinstance(source, LivePlayer):
        raise ValueError('binary messages are tracked points for a live source; send '
                         '{"type": "start", "source": "live"} first')
    frame = decode_points(data)
    source.push(frame.points, frame.capture_time, frame.frame_index)
    return None


def _settings(msg: dict) -> ConditionSettings:
    settings = msg.get("settings") or {}
    if not isinstance(settings, dict):
        raise ValueError('"settings" must be an object (see ConditionSettings)')
    return ConditionSettings.from_dict(settings)


def _fps(msg: dict, default: float) -> float:
    fps = msg.get("fps", default)
    if isinstance(fps, bool) or not isinstance(fps, (int, float)):
        raise ValueError(f'"fps" must be a number of frames per second; got {fps!r}')
    return float(fps)


def _muscle_drive(store, project_id) -> MuscleDrive:
    """A new muscle drive (its own warm start) on the project's muscles and landmarks."""
    project, mesh = store.get(project_id), store.mesh(project_id)
    model, _ = project_muscles(store, project, mesh)
    return MuscleDrive(model, landmarks_from_json(store.landmarks(project_id), mesh.vertices, mesh.faces))


def _drive(store, project_id, drive: str):
    """A new drive object for `drive` (None for feature points), its own warm start."""
    if drive == "muscles":
        return _muscle_drive(store, project_id)
    if drive == "arkit":
        return project_drive(store, project_id)
    return None


async def source_from_message(msg: dict, hub: StreamHub, store, project_id, target_points, layout):
    """The player `msg` asks for, driven as the project's drive says."""
    player = await _player(msg, store, project_id, target_points, layout)
    if hub.drive(project_id) != "points":
        player.set_drive(await asyncio.to_thread(_drive, store, project_id, hub.drive(project_id)))
    return player


async def _player(msg: dict, store, project_id, target_points, layout):
    kind = msg.get("source", "demo")
    if kind == "demo":
        return await asyncio.to_thread(DemoPlayer, target_points, layout, _fps(msg, DEFAULT_FPS))
    if kind == "take":
        take_id = msg.get("take")
        if not isinstance(take_id, str):
            raise ValueError('"take" must be the id of one of the project\'s takes')
        settings = _settings(msg)

        def load():
            take = store.take(project_id, take_id)
            return TakePlayer(target_points, layout, take, settings, loop=msg.get("loop", True) is not False,
                              take_id=take_id)
        return await asyncio.to_thread(load)
    if kind == "live":
        dims = msg.get("dims", 3)
        return LivePlayer(target_points, layout, _settings(msg), dims=dims, fps=_fps(msg, 30.0))
    raise ValueError(f"unknown source {kind!r}; available: 'demo', 'take', 'live'")


async def _control(text, hub: StreamHub, store, project_id, target_points, layout, viewer) -> dict | None:
    if text is None:
        raise ValueError("control messages are JSON text")
    try:
        msg = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"control message is not JSON: {exc}") from exc
    except RecursionError:
        raise ValueError("control message is nested too deeply to be one of ours") from None
    if not isinstance(msg, dict) or not isinstance(msg.get("type"), str):
        raise ValueError('control message must be an object with a "type"')
    kind = msg["type"]
    if kind == "ping":
        return {"type": "pong", "t": msg.get("t"), "server_time": time.time()}
    if kind == "start":
        source = await source_from_message(msg, hub, store, project_id, target_points, layout)
        hub.start_source(project_id, source)
        return {"type": "started", **source.describe()}
    source = hub.source(project_id)
    if kind == "record_stop" and getattr(source, "recording", None) is None:
        source = hub.unsaved_recording(project_id) or source  # it stopped or ended while recording
    wanted = {"settings": ((LivePlayer, TakePlayer), "take or live"), "neutral": (LivePlayer, "live"),
              "record": (object, "demo, take or live"), "record_stop": (object, "demo, take or live")}
    if kind in wanted and (source is None or not isinstance(source, wanted[kind][0])):
        raise ValueError(f'"{kind}" applies to a running {wanted[kind][1]} source; none is running')
    if kind == "settings":
        settings = _settings(msg)
        await asyncio.to_thread(source.set_settings, settings)
        return {"type": "settings", "settings": settings.to_dict()}
    if kind == "neutral":
        source.recapture()
        return {"type": "neutral"}
    if kind == "record":
        source.start_recording()
        return {"type": "recording"}
    if kind == "record_stop":
        default = f"{source.kind} take"
        name = msg.get("name") or default
        if not isinstance(name, str):
            raise ValueError('"name" must be a string')
        take = source.stop_recording()
        info = await asyncio.to_thread(store.put_take, project_id, take, name=name.strip()[:200] or default)
        return {"type": "recorded", "take": info}
    if kind == "stop":
        hub.stop_source(project_id)
        # every viewer puts its face back at rest
        hub.publish(project_id, encode_frame(np.zeros((len(target_points), 3), np.float32),
                                             frame_index=0, source_time=0.0, flags=FLAG_NEUTRAL))
        return {"type": "stopped"}
    if kind == "drive":
        drive = msg.get("drive")
        if drive not in DRIVES:
            raise ValueError(f'"drive" must be one of {", ".join(map(repr, DRIVES))}; got {drive!r}')
        # made first: muscles that cannot be placed (or ARKit shapes not made) refuse the
        # switch and change nothing
        driving = await asyncio.to_thread(_drive, store, project_id, drive)
        hub.set_drive(project_id, drive)
        if source is not None:
            source.set_drive(driving)
        return {"type": "drive", "drive": drive}
    if kind == "format":
        fmt = msg.get("format")
        if fmt not in FORMATS:
            raise ValueError(f'"format" must be one of {", ".join(map(repr, FORMATS))}; got {fmt!r}')
        viewer["format"] = fmt
        return {"type": "format", "format": fmt}
    if kind == "mask":
        regions = msg.get("regions") or None
        if regions is not None and not (isinstance(regions, list) and all(isinstance(r, str) for r in regions)):
            raise ValueError('"regions" must be a list of region, group or point names')
        if regions is not None:
            get_layout(layout or "ibug68").region_mask(regions)  # RetargetError for unknown names
        hub.set_regions(project_id, regions)
        return {"type": "mask", "regions": regions}
    raise ValueError(f"unknown control message type {kind!r}")
