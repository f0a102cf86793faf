"""The FastAPI application: `create_app(data_dir)`.

Routers, one per resource, live in `server.routers`; shared dependencies in
`server.deps`; projects on disk in `server.store`. The server holds no maths: it parses
requests, calls the `retarget` library and serialises what it returns. Library refusals
(`RetargetError`) become HTTP 422 with the library's message as ``detail``; unknown
projects 404 naming the id.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI, Request, status
from fastapi.responses import JSONResponse

from retarget import __version__
from retarget.errors import RetargetError
from server.deps import Limits
from server.jobs import JobRegistry
from server.hub import StreamHub
from server.routers import exports, info, landmarks, layouts, meshes, projects, rigs, stream, takes
from server.sample import ensure_sample_project
from server.store import ProjectNotFound, ProjectStore, StaleRig, TakeNotFound
from server.web import mount_web

__all__ = ["DEFAULT_MAX_UPLOAD_BYTES", "DEFAULT_MAX_VERTICES", "UVICORN_OPTIONS", "create_app"]

DEFAULT_MAX_UPLOAD_BYTES = 64 * 2**20
DEFAULT_MAX_VERTICES = 500_000
UVICORN_OPTIONS = {
    # stream frames are float32 noise to deflate, which cost two thirds of the server's
    # streaming CPU with 50 viewers (bench/viewers.py)
    "ws_per_message_deflate": False,
}
"""How `retarget serve` runs uvicorn (benchmarks run the app the same way)."""


def create_app(data_dir: Path, *, max_upload_bytes: int = DEFAULT_MAX_UPLOAD_BYTES,
               max_vertices: int = DEFAULT_MAX_VERTICES, sample: bool = True) -> FastAPI:
    """The app serving the projects under `data_dir` (created if missing).

    max_upload_bytes : mesh uploads longer than this are refused with 413.
    max_vertices : meshes with more vertices are refused with 422.
    sample : create the built-in sample project when the data dir is new (see
        `server.sample`).
    """
    app = FastAPI(title="retarget", version=__version__, docs_url=None, redoc_url=None,
                  description="Facial animation retargeting from feature points: projects, "
                  "meshes, landmarks, rigs, takes and the live stream.")
    app.state.store = ProjectStore(data_dir)
    app.state.jobs = JobRegistry()
    app.state.hub = StreamHub()  # live streams: viewers, sources, regions per project
    app.state.limits = Limits(max_upload_bytes=int(max_upload_bytes),
                              max_vertices=int(max_vertices))
    if sample:
        ensure_sample_project(app.state.store)

    @app.exception_handler(RetargetError)
    async def _refused(request: Request, exc: RetargetError) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, 422)

    @app.exception_handler(ProjectNotFound)
    @app.exception_handler(TakeNotFound)
    async def _not_found(request: Request, exc: LookupError) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status.HTTP_404_NOT_FOUND)

    @app.exception_handler(StaleRig)
    async def _stale(request: Request, exc: StaleRig) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status.HTTP_409_CONFLICT)

    for module in (projects, meshes, landmarks, rigs, takes, exports, stream, layouts, info):
        app.include_router(module.router)
    mount_web(app)
    return app
