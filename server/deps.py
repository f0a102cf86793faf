"""Shared FastAPI dependencies, declared once as `Annotated` aliases.

Tests may point the app at another store with
``app.dependency_overrides[get_store] = lambda: other_store``.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Header, HTTPException, Path, status
from pydantic import StrictFloat, StrictInt
from starlette.requests import HTTPConnection

from retarget.mesh import Mesh

from server.hub import StreamHub
from server.isolation import Isolation
from server.jobs import JobRegistry
from server.limits import Limits
from server.store import ProjectStore

__all__ = ["HubDep", "IsolationDep", "JobsDep", "Limits", "LimitsDep", "MeshDep", "ProjectDep", "ProjectIdDep", "StoreDep", "UploadKeyDep",
           "Integer", "Number", "get_hub", "get_jobs", "get_limits", "get_store"]


Integer = StrictInt
"""A JSON body's integer field: `false` is not 0 and "3" is not 3 (what the schema says a
field is, it must be)."""
Number = StrictFloat | StrictInt
"""A JSON body's number field, likewise strict."""


# The getters take an HTTPConnection so HTTP and WebSocket routes share them (and tests'
# dependency_overrides reach both).
def get_store(connection: HTTPConnection) -> ProjectStore:
    return connection.app.state.store


def get_jobs(connection: HTTPConnection) -> JobRegistry:
    return connection.app.state.jobs


def get_limits(connection: HTTPConnection) -> Limits:
    return connection.app.state.limits


def get_hub(connection: HTTPConnection) -> StreamHub:
    return connection.app.state.hub


def get_isolation(connection: HTTPConnection) -> Isolation:
    return connection.app.state.isolation


StoreDep = Annotated[ProjectStore, Depends(get_store)]
JobsDep = Annotated[JobRegistry, Depends(get_jobs)]
LimitsDep = Annotated[Limits, Depends(get_limits)]
HubDep = Annotated[StreamHub, Depends(get_hub)]
IsolationDep = Annotated[Isolation, Depends(get_isolation)]
ProjectIdDep = Annotated[str, Path(description="Project id (22 URL-safe characters)")]
UploadKeyDep = Annotated[str | None, Header(
    alias="Idempotency-Key", min_length=1, max_length=128, pattern=r"^[A-Za-z0-9._:-]+$",
    description="a key the client makes once per upload and sends again on a retry: an upload "
    "already stored under it is answered (200) and not stored twice")]


def get_project(project_id: ProjectIdDep, store: StoreDep) -> dict:
    """The project named in the path; `ProjectNotFound` (-> 404) for an unknown or
    malformed id, checked before the id reaches any path."""
    return store.get(project_id)


ProjectDep = Annotated[dict, Depends(get_project)]


def get_mesh(project: ProjectDep, store: StoreDep) -> Mesh:
    """The project's stored mesh, parsed by `retarget.mesh.load_mesh`; 409 when the
    project has none yet."""
    mesh = store.mesh(project["id"])
    if mesh is None:
        raise HTTPException(
            status.HTTP_409_CONFLICT,
            f"project {project['id']!r} has no mesh yet: upload one with "
            f"PUT /api/projects/{project['id']}/mesh",
        )
    return mesh


MeshDep = Annotated[Mesh, Depends(get_mesh)]
