"""The FastAPI application: `create_app(data_dir)`.

Routers, one per resource, live in `server.routers`; shared dependencies in
`server.deps`; projects on disk in `server.store`. The server holds no maths: it parses
requests, calls the `retarget` library and serialises what it returns. Refusals are
``{"detail": str}`` with a 4xx (`server.errors`): library refusals (`RetargetError`) 422,
unknown projects 404, stale rigs 409. In front of the routes, `server.access` refuses
other hosts, other web pages and (off loopback) requests without the access token, and
`server.limits` holds every request body to its route's cap as it streams in. Uploaded
files are read in child processes (`server.isolation`), so no file can crash the server.
"""

from __future__ import annotations

import threading
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI

from retarget import __version__
from server import errors
from server.access import Access, AccessGuard
from server.isolation import Isolation, IsolationLimits
from server.jobs import JobRegistry
from server.hub import StreamHub
from server.limits import BodyLimit, Limits
from server.routers import (arkit, batch, exports, info, landmarks, layouts, meshes, mouth, muscles, projects,
                            rigs, stereo_live, stream, takes)
from server.sample import ensure_sample_project
from server.store import ProjectStore
from server.web import mount_web

__all__ = ["DEFAULT_MAX_UPLOAD_BYTES", "DEFAULT_MAX_VERTICES", "DEFAULT_MAX_VIDEO_FRAMES",
           "UVICORN_OPTIONS", "create_app"]

DEFAULT_MAX_UPLOAD_BYTES = 64 * 2**20
DEFAULT_MAX_VERTICES = 500_000
DEFAULT_MAX_VIDEO_FRAMES = 18_000  # 10 min at 30 fps
UVICORN_OPTIONS = {
    # stream frames are float32 noise to deflate, which cost two thirds of the server's
    # streaming CPU with 50 viewers (bench/viewers.py)
    "ws_per_message_deflate": False,
    # a control message is a few hundred bytes and a tracked frame of 478 points 6 kB;
    # uvicorn's default would let one message take 16 MiB
    "ws_max_size": 1 << 20,
}
"""How `retarget serve` runs uvicorn (benchmarks run the app the same way)."""


def create_app(data_dir: Path, *, max_upload_bytes: int = DEFAULT_MAX_UPLOAD_BYTES,
               max_vertices: int = DEFAULT_MAX_VERTICES,
               max_video_frames: int = DEFAULT_MAX_VIDEO_FRAMES, sample: bool = True,
               access: Access = Access(), isolation: IsolationLimits = IsolationLimits()) -> FastAPI:
    """The app serving the projects under `data_dir` (created if missing).

    max_upload_bytes : uploaded files longer than this are refused with 413.
    max_vertices : meshes with more vertices are refused with 422.
    max_video_frames : videos with more frames are not tracked markerless (422, or a
        failed job when the header did not say).
    sample : create the built-in sample project when the data dir is new (see
        `server.sample`).
    access : the Host names, origin rule and token requests must meet (`server.access`);
        the default answers loopback names only, with no token.
    isolation : the limits of the child processes that read uploaded files.
    """

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        # the forkserver imports the library once (seconds): before the first upload
        threading.Thread(target=app.state.isolation.warm_up, daemon=True).start()
        yield

    app = FastAPI(title="retarget", version=__version__, docs_url=None, redoc_url=None,
                  lifespan=lifespan,
                  description="Facial animation retargeting from feature points: projects, "
                  "meshes, landmarks, rigs, takes and the live stream. Every refusal is "
                  '`{"detail": "<reason>"}` with a 4xx status.')
    app.state.store = ProjectStore(data_dir)
    app.state.jobs = JobRegistry()
    app.state.hub = StreamHub()  # live streams: viewers, sources, regions per project
    app.state.limits = Limits(max_upload_bytes=int(max_upload_bytes),
                              max_vertices=int(max_vertices),
                              max_video_frames=int(max_video_frames))
    app.state.isolation = Isolation(isolation)
    app.state.access = access
    if sample:
        ensure_sample_project(app.state.store)
    errors.install(app)
    for module in (projects, meshes, mouth, landmarks, rigs, muscles, arkit, takes, exports, batch, stream,
                   stereo_live, layouts, info):
        app.include_router(module.router)
    mount_web(app)
    app.add_middleware(BodyLimit, limits=app.state.limits)
    app.add_middleware(AccessGuard, access=access)  # added last: runs first
    return app
