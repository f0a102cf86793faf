"""The project's rig (skin weights): compute it in the background, read it back, paint it.

``GET /api/projects/{id}/rig/weights`` answers ``application/octet-stream``: `server.wire`'s
RTSW format (joint indices and weights per vertex), version 1 (float32) unless
``?version=2`` (quantised, gzip-encoded for a client that accepts it: the page's).

Painting. ``PATCH /api/projects/{id}/rig/weights`` replaces the rows of some vertices
(`retarget.weights.painting` validates and normalises them against the automatic rig)
and answers the rig's info. The body is JSON ``{version, vertices, indices, weights}``
or ``application/octet-stream`` in `server.wire`'s RTSE format.

An edit made on an older rig version is refused with 409. ``POST .../rig/reset``
``{"joints": [j, ...] | null}`` paints joints back to the automatic rig (null: all).
The painted rows are stored beside the automatic rig, so both survive a restart.
"""

from __future__ import annotations

import gzip
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query, Request, Response, status
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from pydantic import BaseModel, Field, ValidationError

from retarget.errors import RetargetError
from retarget.landmarks import landmarks_from_json
from retarget.skin import SkinWeights
from retarget.weights import DEFAULT_METHOD, METHODS
from retarget.weights.painting import painted_rig, painted_rows, reset_joints, weight_edit
from server.deps import (Integer, IsolationDep, JobsDep, LimitsDep, MeshDep, Number, ProjectDep,
                         StoreDep)
from server.errors import responses
from server.jobs import JobBusy
from server.limits import body_limit
from server.readers import rig
from server.store import StaleRig
from server.wire import edit_arrays, weights_binary

router = APIRouter(tags=["rigs"], responses=responses(404))



class RigRequest(BaseModel):
    method: str = Field(default=DEFAULT_METHOD, description=f"one of {', '.join(METHODS)}")
    k: Integer | None = Field(default=None, ge=1, le=256,
                          description="influences kept per vertex (default: the method's own)")


@router.post("/api/projects/{project_id}/rig", status_code=status.HTTP_202_ACCEPTED,
             responses=responses(404, 409))
def start_rig(project: ProjectDep, mesh: MeshDep, store: StoreDep, jobs: JobsDep,
              isolation: IsolationDep, body: RigRequest) -> dict:
    """Start computing the rig from the stored mesh and landmarks, in a child process
    (`server.readers.rig`); answers the job (poll ``GET /api/jobs/{job_id}``). 409 while
    another job of the project runs."""
    if body.method not in METHODS:
        raise RetargetError(
            f"unknown rig method {body.method!r}; choose one of {', '.join(METHODS)}")
    data = store.landmarks(project["id"])
    if data is None:
        raise HTTPException(status.HTTP_409_CONFLICT,
                            f"project {project['id']!r} has no landmarks yet: "
                            f"PUT /api/projects/{project['id']}/landmarks first")
    points = landmarks_from_json(data, mesh.vertices, mesh.faces)
    options = {} if body.k is None else {"k": body.k}
    revision = project["revision"]

    def work(job) -> tuple[str, dict]:
        weights = isolation.call(rig, mesh, points, body.method, options, job=True,
                                 progress=job.report, what=f"the {body.method} rig")
        store.put_rig(project["id"], weights, revision=revision)
        return (f"rig {weights.method}: {weights.n_joints} joints, "
                f"{weights.n_influences} influences per vertex",
                {"method": weights.method, "n_joints": weights.n_joints,
                 "n_influences": weights.n_influences})

    try:
        job = jobs.start(project["id"], "rig", work)
    except JobBusy as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from exc
    return job.as_json()


@router.get("/api/jobs/{job_id}")
def get_job(job_id: str, jobs: JobsDep) -> dict:
    """``{id, project_id, kind, state: running|done|failed, progress: 0..1, detail, result}``:
    detail a sentence, result what a done job made (a rig ``{method, n_joints,
    n_influences}``, a tracked take ``{take, frames[, truncated, frames_claimed]}``, found
    landmarks ``{saved, layout, n_points, check, presence, reason}``)."""
    job = jobs.get(job_id)
    if job is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no job with id {job_id!r}")
    return job.as_json()


def _rig(project: dict, store) -> SkinWeights:
    rig = store.rig(project["id"])
    if rig is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            f"project {project['id']!r} has no rig yet")
    return rig


def rig_info(rig: SkinWeights, rig_status: dict) -> dict:
    return {"method": rig.method, "n_vertices": rig.n_vertices, "n_joints": rig.n_joints,
            "n_influences": rig.n_influences, **rig_status}


@router.get("/api/projects/{project_id}/rig")
def get_rig(project: ProjectDep, store: StoreDep) -> dict:
    """``{method, n_vertices, n_joints, n_influences, version, painted_vertices}``:
    `version` counts the rig's changes (compute, paint, reset); `painted_vertices` is how
    many rows differ from the automatic rig's."""
    rig = _rig(project, store)
    rig_status = store.rig_status(project["id"])
    if rig_status is None:  # dropped by a landmark edit since the rig was read
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"project {project['id']!r} has no rig yet")
    return rig_info(rig, rig_status)


@router.get("/api/projects/{project_id}/rig/weights", response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}}}})
def get_rig_weights(project: ProjectDep, store: StoreDep, request: Request,
                    version: Annotated[int, Query(ge=1, le=2, description=(
                        "RTSW format version: 1 float32, 2 quantised (20 bits over a "
                        "power-of-two step) and gzip-encoded when the client accepts it"))] = 1) -> Response:
    """Joint indices and weights as `server.wire`'s RTSW bytes."""
    data = weights_binary(_rig(project, store), version)
    headers = {"Vary": "Accept-Encoding"}
    if version >= 2 and "gzip" in request.headers.get("accept-encoding", ""):
        # version 2's byte planes deflate to a fifth (5.7 of 25.9 MiB, bench/rig.py) at
        # level 1 in 0.2 s; level 6 makes 4.8 MiB in 0.55 s
        data = gzip.compress(data, compresslevel=1, mtime=0)
        headers["Content-Encoding"] = "gzip"
    return Response(data, media_type="application/octet-stream", headers=headers)


class ResetRequest(BaseModel):
    joints: list[Integer] | None = Field(description="joints to paint back to the automatic rig; "
                                     "null: the whole rig")
    version: Integer | None = Field(default=None, description="refuse (409) unless the rig is at "
                                "this version")


class WeightEditJSON(BaseModel):
    version: Integer = Field(description="the rig version the edit was made on (GET rig)")
    vertices: list[Integer] = Field(description="R vertex indices")
    indices: list[list[Integer]] = Field(description="(R, K) joint indices")
    weights: list[list[Number]] = Field(description="(R, K) weights")


def _rigs(project: dict, store) -> tuple[SkinWeights, SkinWeights, int]:
    found = store.rigs(project["id"])
    if found is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"project {project['id']!r} has no rig yet")
    return found


def _store_painted(store, project_id: str, rig: SkinWeights, automatic: SkinWeights,
                   version: int) -> dict:
    rig_status = store.put_painting(project_id, painted_rows(rig, automatic), version=version)
    return rig_info(rig, rig_status)


@router.patch("/api/projects/{project_id}/rig/weights", responses=responses(404, 409),
              openapi_extra={"requestBody": {"required": True, "content": {
                  "application/octet-stream": {}, "application/json": {}}}})
@body_limit(files=1)
async def patch_rig_weights(project: ProjectDep, store: StoreDep, limits: LimitsDep,
                            request: Request) -> dict:
    """Replace the rows of some vertices (binary or JSON form in the module docstring);
    answers the rig's info. 409 when the rig changed since the edit's version, 422 with
    the reason for a row the library refuses."""
    body = await request.body()  # `server.limits.BodyLimit` caps it as it streams in
    if len(body) > limits.max_upload_bytes:
        raise HTTPException(status.HTTP_413_CONTENT_TOO_LARGE,
                            f"a weight edit may be at most {limits.max_upload_bytes} bytes")
    if request.headers.get("content-type", "").startswith("application/json"):
        if len(body) > limits.max_json_bytes:  # Python lists of numbers take ~20x the text
            raise HTTPException(status.HTTP_413_CONTENT_TOO_LARGE,
                                f"a JSON weight edit may be at most {limits.max_json_bytes} bytes; "
                                "send larger edits in the binary form")
        try:
            edit = WeightEditJSON.model_validate_json(body)
        except ValidationError as exc:
            raise RequestValidationError(exc.errors(include_url=False)) from None
        version, n, vertices, joints, weights = (edit.version, None, edit.vertices,
                                                 edit.indices, edit.weights)
    else:
        version, n, vertices, joints, weights = edit_arrays(body)

    def paint() -> dict:
        current, automatic, current_version = _rigs(project, store)
        if version != current_version:
            raise StaleRig.painted_on(version, current_version)
        if n is not None and n != automatic.n_joints:
            raise RetargetError(f"weight edit is for {n} joints; the rig has {automatic.n_joints}")
        edit = weight_edit(vertices, joints, weights, automatic)
        return _store_painted(store, project["id"], painted_rig(current, edit), automatic, version)

    return await run_in_threadpool(paint)


@router.post("/api/projects/{project_id}/rig/reset", responses=responses(404, 409))
def reset_rig(project: ProjectDep, store: StoreDep, body: ResetRequest) -> dict:
    """Paint `joints` back to the automatic rig (null: the whole rig); answers the rig's
    info."""
    current, automatic, version = _rigs(project, store)
    if body.version is not None and body.version != version:
        raise StaleRig.painted_on(body.version, version)
    rig = automatic if body.joints is None else reset_joints(current, automatic, body.joints)
    return _store_painted(store, project["id"], rig, automatic, version)
