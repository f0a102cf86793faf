"""The project's takes: recorded performances (frames of named source feature points).

    GET    /api/projects/{id}/takes                 list, oldest first
    POST   /api/projects/{id}/takes                 upload a landmark / motion-capture /
                                                    animated-face file (multipart)
    POST   /api/projects/{id}/takes/track           upload a marker video; a job tracks it
                                                    into a take (poll GET /api/jobs/{job})
    GET    /api/projects/{id}/takes/{take}          its info
    GET    /api/projects/{id}/takes/{take}/points   (F, N, D) float32 .npy of the trimmed take
    PATCH  /api/projects/{id}/takes/{take}          {"name"?, "trim"?: [start, stop|null]} (s)
    DELETE /api/projects/{id}/takes/{take}

A take's info is ``{id, name, created, source, layout, fps, n_frames, n_points, dims,
duration, trim: [start, stop]}``. Takes keep the source's own point names; playing one
maps them to the project's layout by name (`server.sources`). Files are parsed by
`retarget.sources.files.read_take`, videos tracked by `retarget.sources.markers`; the
server only moves bytes and schedules.
"""

from __future__ import annotations

import io
import json
import math

import numpy as np
from fastapi import APIRouter, File, Form, HTTPException, Response, UploadFile, status
from pydantic import BaseModel, Field

from retarget.errors import RetargetError
from retarget.sources.files import read_take
from retarget.sources.markers import track_marker_video
from server.deps import JobsDep, LimitsDep, ProjectDep, StoreDep
from server.jobs import JobBusy
from server.routers.meshes import read_capped, upload_extension

router = APIRouter(prefix="/api/projects/{project_id}/takes", tags=["takes"])

TAKE_EXTENSIONS = ("csv", "json", "npy", "trc", "c3d", "glb", "gltf", "zip")
"""Files a take is read from (`retarget.sources.files.read_take`)."""
VIDEO_EXTENSIONS = ("mp4", "m4v", "mov", "avi", "mkv", "webm")
"""Videos the marker tracker reads (through OpenCV's FFmpeg)."""
TRACK_METHODS = ("markers",)
"""Server-side trackers. Markerless tracking runs in the browser (web/static/js/tracking),
which uploads its result as a take file."""


def _json_form(value: str | None, what: str):
    if value is None or value == "":
        return None
    try:
        return json.loads(value)
    except json.JSONDecodeError as exc:
        raise RetargetError(f"form field {what!r} is not JSON: {exc}") from exc


def _default_name(filename: str | None, fallback: str) -> str:
    base = (filename or "").replace("\\", "/").rsplit("/", 1)[-1]
    return (base.rsplit(".", 1)[0] or fallback)[:200]


@router.get("")
def list_takes(project: ProjectDep, store: StoreDep) -> list[dict]:
    """The project's takes, oldest first."""
    return store.takes(project["id"])


@router.post("", status_code=status.HTTP_201_CREATED)
def upload_take(project: ProjectDep, store: StoreDep, limits: LimitsDep,
                file: UploadFile = File(description=", ".join(f".{e}" for e in TAKE_EXTENSIONS)),
                name: str | None = Form(default=None, max_length=200),
                fps: float | None = Form(default=None, gt=0, le=1000,
                                         description="frame rate when the file has none"),
                layout: str | None = Form(default=None, description="layout of a bare .npy"),
                mapping: str | None = Form(default=None,
                                           description='JSON {"file label": "layout point name"}'),
                labelled_vertices: str | None = Form(
                    default=None, description='animated faces: JSON {"point name": vertex index}')) -> dict:
    """Read a take from a file and store it; answers the take's info. The file is
    refused (422, with the reason) and nothing is stored if it does not parse."""
    ext = upload_extension(file.filename, TAKE_EXTENSIONS)
    data = read_capped(file, limits.max_upload_bytes)
    if not data:
        raise RetargetError(f"the uploaded file {file.filename!r} is empty")
    try:
        take = read_take(data, filename=f"upload.{ext}", layout=layout or None,
                         mapping=_json_form(mapping, "mapping"), fps=fps,
                         labelled_vertices=_json_form(labelled_vertices, "labelled_vertices"))
    except RetargetError as exc:
        raise RetargetError(f"take file {file.filename!r} refused: {exc}") from exc
    return store.put_take(project["id"], take, name=name or _default_name(file.filename, "take"))


@router.post("/track", status_code=status.HTTP_202_ACCEPTED)
def track_video(project: ProjectDep, store: StoreDep, limits: LimitsDep, jobs: JobsDep,
                file: UploadFile = File(description=", ".join(f".{e}" for e in VIDEO_EXTENSIONS)),
                method: str = Form(default="markers", description=" | ".join(TRACK_METHODS)),
                layout: str = Form(default="dutreve21",
                                   description="the layout whose points the markers are"),
                name: str | None = Form(default=None, max_length=200)) -> dict:
    """Track a marker video into a take in the background; answers the job (poll
    ``GET /api/jobs/{job_id}``; its detail names the take when done)."""
    if method not in TRACK_METHODS:
        raise RetargetError(f"unknown tracking method {method!r}; the server tracks "
                            f"{', '.join(TRACK_METHODS)} (markerless tracking runs in the browser)")
    ext = upload_extension(file.filename, VIDEO_EXTENSIONS)
    data = read_capped(file, limits.max_upload_bytes)
    if not data:
        raise RetargetError(f"the uploaded video {file.filename!r} is empty")
    path = store.scratch_file(ext)
    path.write_bytes(data)
    take_name = name or _default_name(file.filename, "markers")

    def work(job) -> str:
        try:
            take = track_marker_video(
                path, layout=layout,
                progress=lambda done, total: job.report(done / total) if total else None)
        except RetargetError as exc:
            raise RetargetError(f"video {file.filename!r}: {exc}") from exc
        finally:
            path.unlink(missing_ok=True)
        info = store.put_take(project["id"], take, name=take_name)
        return json.dumps({"take": info["id"], "frames": info["n_frames"]})

    try:
        job = jobs.start(project["id"], "track", work)
    except JobBusy as exc:
        path.unlink(missing_ok=True)
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from exc
    return job.as_json()


@router.get("/{take_id}")
def get_take(project: ProjectDep, store: StoreDep, take_id: str) -> dict:
    return store.take_info(project["id"], take_id)


@router.get("/{take_id}/points", response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}}}})
def get_take_points(project: ProjectDep, store: StoreDep, take_id: str) -> Response:
    """The trimmed take's points as a NumPy .npy file: (F, N, D) float32, NaN where lost."""
    take = store.take(project["id"], take_id)
    buffer = io.BytesIO()
    np.save(buffer, np.asarray(take.points, dtype="<f4"))
    return Response(buffer.getvalue(), media_type="application/octet-stream",
                    headers={"Content-Disposition": f'attachment; filename="take-{take_id}.npy"'})


class TakePatch(BaseModel):
    name: str | None = Field(default=None, min_length=1, max_length=200, pattern=r"\S")
    trim: tuple[float, float | None] | None = Field(
        default=None, description="[start, stop] in seconds from the first frame; stop null = end")


@router.patch("/{take_id}")
def patch_take(project: ProjectDep, store: StoreDep, take_id: str, body: TakePatch) -> dict:
    """Rename and/or trim (non-destructive: the frames are kept, the span is stored)."""
    info = store.take_info(project["id"], take_id)
    trim = body.trim
    if trim is not None:
        start, stop = trim
        end = info["duration"]
        if not (math.isfinite(start) and 0 <= start <= end):
            raise RetargetError(f"trim start must be within [0, {end:.3f}] s; got {start}")
        if stop is not None and not (math.isfinite(stop) and start < stop <= end + 1e-9):
            raise RetargetError(f"trim stop must be after the start ({start}) and at most "
                                f"{end:.3f} s; got {stop}")
    return store.update_take(project["id"], take_id,
                             name=None if body.name is None else body.name.strip(), trim=trim)


@router.delete("/{take_id}", status_code=status.HTTP_204_NO_CONTENT)
def delete_take(project: ProjectDep, store: StoreDep, take_id: str) -> Response:
    store.delete_take(project["id"], take_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
