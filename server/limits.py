"""How much a request may send: the app's limits, and the ASGI middleware that holds every
request body to its route's cap while it streams in, before any of it is parsed.

Starlette reads a body whole (JSON) or spools it to disk (multipart) before a route
runs, so a limit checked in the route comes after the bytes are in. `BodyLimit` caps the
body at its first read, when routing has picked the endpoint: the endpoint's cap
(`body_limit`, for uploads) or `Limits.max_json_bytes`. A ``Content-Length`` over the cap
is answered 413 before a byte is read, and a chunked body is counted as it arrives and
cut off with 413 at the first byte past it. (FastAPI's own ``max_body_size`` is fixed
when a route is declared; these caps follow the app's configured limits.)
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from fastapi import HTTPException, status

__all__ = ["BodyLimit", "Limits", "MULTIPART_SLACK", "body_limit"]

MULTIPART_SLACK = 256 * 1024
"""Bytes a multipart body may carry beside its files: boundaries, part headers and the
form's small fields."""


@dataclass(frozen=True)
class Limits:
    """The app's limits.

    max_upload_bytes : one uploaded file (mesh, take, video, .glb, weight edit).
    max_vertices : vertices of a mesh.
    max_video_frames : frames of a video tracked markerless (a take holds each frame's
        points: 18,000 frames of all 468 face-mesh points are 100 MB).
    max_json_bytes : a JSON (or other small) request body.
    max_settings_bytes : a project's ``settings`` object, serialised.
    """

    max_upload_bytes: int
    max_vertices: int
    max_video_frames: int
    max_json_bytes: int = 1 << 20
    max_settings_bytes: int = 64 * 1024


def body_limit(files: int):
    """Mark an endpoint as taking up to `files` uploads of `Limits.max_upload_bytes` each
    (plus `MULTIPART_SLACK`); unmarked endpoints take `Limits.max_json_bytes`."""
    def mark(endpoint):
        endpoint.body_files = files
        return endpoint
    return mark


class _TooLarge(HTTPException):
    """Raised from `receive` when a streamed body passes its cap. An HTTPException, so
    FastAPI's body parsing re-raises it as it is and it answers 413."""

    def __init__(self, cap: int):
        # Connection: close, so the server stops receiving the rest instead of draining it
        super().__init__(status.HTTP_413_CONTENT_TOO_LARGE,
                         f"the request body is over the limit of {cap} bytes "
                         f"({cap / 2**20:.3g} MiB) for this request",
                         headers={"Connection": "close"})


class BodyLimit:
    """ASGI middleware: every HTTP request body within its route's cap (module docstring)."""

    def __init__(self, app, limits: Limits):
        self.app, self.limits = app, limits

    def cap(self, scope) -> int:
        """The body cap of the route `scope` was routed to, bytes (routing has happened
        by the time a route reads its body, and it records the endpoint in the scope)."""
        files = getattr(scope.get("endpoint"), "body_files", 0)
        if files:
            return files * self.limits.max_upload_bytes + MULTIPART_SLACK
        return self.limits.max_json_bytes

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        declared = dict(scope["headers"]).get(b"content-length")
        if declared is not None and not declared.isdigit():
            return await _refuse(send, HTTPException(400, "Content-Length is not a number"))
        received, cap = 0, None

        async def counted():
            nonlocal received, cap
            if cap is None:
                cap = self.cap(scope)
                if declared is not None and int(declared) > cap:
                    raise _TooLarge(cap)  # before a byte of it is read
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > cap:
                    raise _TooLarge(cap)
            return message

        started = False

        async def tracked(message):
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, counted, tracked)
        except _TooLarge as exc:  # raised outside a route (no handler turned it into 413)
            if started:
                raise
            await _refuse(send, exc)


async def _refuse(send, exc: HTTPException) -> None:
    body = json.dumps({"detail": exc.detail}).encode()
    await send({"type": "http.response.start", "status": exc.status_code, "headers": [
        (b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
        (b"connection", b"close")]})
    await send({"type": "http.response.body", "body": body})
