"""The project's rig (skin weights): compute it in the background, read it back.

``GET /api/projects/{id}/rig/weights`` answers ``application/octet-stream``,
little-endian::

    offset      size    field
    0           4       magic b"RTSW"
    4           4       uint32 format version (1)
    8           4       uint32 V, vertex count
    12          4       uint32 K, influences per vertex
    16          4       uint32 N, joint (feature point) count
    20          2 V K   uint16 joint indices, (V, K) row-major, each in [0, N)
    20+2VK      0 or 2  zero padding, so the weights start at a multiple of 4
    ...         4 V K   float32 weights, (V, K) row-major

Weights are `retarget.skin.SkinWeights`: unused slots have weight 0; the rest of a row's
1 belongs to the static root joint.
"""

from __future__ import annotations

import inspect
import struct

import numpy as np
from fastapi import APIRouter, HTTPException, Response, status
from pydantic import BaseModel, Field

from retarget.errors import RetargetError
from retarget.landmarks import landmarks_from_json
from retarget.layouts import get_layout
from retarget.skin import SkinWeights
from retarget.weights import DEFAULT_METHOD, METHODS, compute_weights
from server.deps import JobsDep, MeshDep, ProjectDep, StoreDep
from server.jobs import JobBusy

router = APIRouter(tags=["rigs"])

WEIGHTS_MAGIC = b"RTSW"
WEIGHTS_VERSION = 1
WEIGHTS_HEADER = struct.Struct("<4sIIII")


class RigRequest(BaseModel):
    method: str = Field(default=DEFAULT_METHOD, description=f"one of {', '.join(METHODS)}")
    k: int | None = Field(default=None, ge=1, le=256,
                          description="influences kept per vertex (default: the method's own)")


@router.post("/api/projects/{project_id}/rig", status_code=status.HTTP_202_ACCEPTED)
def start_rig(project: ProjectDep, mesh: MeshDep, store: StoreDep, jobs: JobsDep,
              body: RigRequest) -> dict:
    """Start computing the rig from the stored mesh and landmarks; answers the job
    (poll ``GET /api/jobs/{job_id}``). 409 while another job of the project runs."""
    if body.method not in METHODS:
        raise RetargetError(
            f"unknown rig method {body.method!r}; choose one of {', '.join(METHODS)}")
    data = store.landmarks(project["id"])
    if data is None:
        raise HTTPException(status.HTTP_409_CONFLICT,
                            f"project {project['id']!r} has no landmarks yet: "
                            f"PUT /api/projects/{project['id']}/landmarks first")
    points = landmarks_from_json(data, mesh.vertices, mesh.faces)
    layout = get_layout(points.layout) if points.layout else None
    options = {} if body.k is None else {"k": body.k}
    revision = project["revision"]

    def work(job) -> str:
        if "progress" in inspect.signature(METHODS[body.method]).parameters:
            options["progress"] = job.report
        weights = compute_weights(body.method, mesh.vertices, mesh.faces, points, layout,
                                  **options)
        store.put_rig(project["id"], weights, revision=revision)
        return (f"rig {weights.method}: {weights.n_joints} joints, "
                f"{weights.n_influences} influences per vertex")

    try:
        job = jobs.start(project["id"], "rig", work)
    except JobBusy as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from exc
    return job.as_json()


@router.get("/api/jobs/{job_id}")
def get_job(job_id: str, jobs: JobsDep) -> dict:
    """``{id, project_id, kind, state: running|done|failed, progress: 0..1, detail}``."""
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


@router.get("/api/projects/{project_id}/rig")
def get_rig(project: ProjectDep, store: StoreDep) -> dict:
    """``{method, n_vertices, n_joints, n_influences}``."""
    rig = _rig(project, store)
    return {"method": rig.method, "n_vertices": rig.n_vertices, "n_joints": rig.n_joints,
            "n_influences": rig.n_influences}


def weights_binary(rig: SkinWeights) -> bytes:
    """The binary form of the module docstring."""
    if rig.n_joints > 0xFFFF:
        raise RetargetError(f"rig has {rig.n_joints} joints; the binary form holds 65535")
    v, k = rig.indices.shape
    indices = np.ascontiguousarray(rig.indices, dtype="<u2").tobytes()
    padding = b"\0" * (-len(indices) % 4)
    weights = np.ascontiguousarray(rig.weights, dtype="<f4").tobytes()
    header = WEIGHTS_HEADER.pack(WEIGHTS_MAGIC, WEIGHTS_VERSION, v, k, rig.n_joints)
    return header + indices + padding + weights


@router.get("/api/projects/{project_id}/rig/weights", response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}}}})
def get_rig_weights(project: ProjectDep, store: StoreDep) -> Response:
    """Joint indices and weights as little-endian binary (format in the module docstring)."""
    return Response(weights_binary(_rig(project, store)), media_type="application/octet-stream")
