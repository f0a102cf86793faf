"""Projects: create, list, read, rename / change settings, delete.

A project is JSON::

    {"id": str, "name": str, "created": ISO 8601, "updated": ISO 8601,
     "mesh": {"filename", "format", "n_vertices", "n_faces"} | null,
     "landmarks": {"layout", "n_points"} | null,
     "rig": {"method"} | null,
     "revision": int,          # bumped whenever the mesh or the landmarks change
     "settings": {...}}        # free-form JSON object kept for the browser

One settings key is the server's own: ``mesh_units``, the unit of the mesh ("m", "cm", "mm",
"in"; `server.routers.meshes`), which the export scales from; another value is refused.
"""

from __future__ import annotations

import json
from typing import Any

from fastapi import APIRouter, Response, status
from pydantic import BaseModel, Field

from retarget.errors import RetargetError
from retarget.units import unit_scale
from server.deps import LimitsDep, ProjectDep, StoreDep
from server.errors import responses
from server.routers.meshes import MESH_UNITS_KEY

router = APIRouter(prefix="/api/projects", tags=["projects"], responses=responses())

_NAME = {"min_length": 1, "max_length": 200, "pattern": r"\S"}


class ProjectCreate(BaseModel):
    name: str = Field(**_NAME)
    settings: dict[str, Any] = Field(default_factory=dict)


class ProjectPatch(BaseModel):
    name: str | None = Field(default=None, **_NAME)
    settings: dict[str, Any] | None = Field(
        default=None, description="merged into the stored settings; a key set to null is removed")


def _bounded(settings: dict, limits) -> dict:
    """`settings`, refused when its JSON is over `Limits.max_settings_bytes` (every list
    call answers it)."""
    size = len(json.dumps(settings))
    if size > limits.max_settings_bytes:
        raise RetargetError(f"project settings would take {size} bytes of JSON; the limit is "
                            f"{limits.max_settings_bytes}")
    return settings


@router.post("", status_code=status.HTTP_201_CREATED)
def create_project(body: ProjectCreate, store: StoreDep, limits: LimitsDep) -> dict:
    """Create an empty project."""
    return store.create(body.name.strip(), _bounded(body.settings, limits))


@router.get("")
def list_projects(store: StoreDep) -> list[dict]:
    """Every project, oldest first."""
    return store.list()


@router.get("/{project_id}", responses=responses(404))
def get_project(project: ProjectDep) -> dict:
    return project


@router.patch("/{project_id}", responses=responses(404))
def patch_project(project: ProjectDep, body: ProjectPatch, store: StoreDep, limits: LimitsDep) -> dict:
    """Rename the project and/or merge `settings` into its settings."""
    name = None if body.name is None else body.name.strip()
    if body.settings:
        if body.settings.get(MESH_UNITS_KEY) is not None:
            unit = body.settings[MESH_UNITS_KEY]
            unit_scale(unit if isinstance(unit, str) else repr(unit))  # 422 naming the value
        merged = {**project["settings"], **body.settings}
        _bounded({k: v for k, v in merged.items() if v is not None}, limits)
    return store.update(project["id"], name=name, settings=body.settings)


@router.delete("/{project_id}", status_code=status.HTTP_204_NO_CONTENT, responses=responses(404))
def delete_project(project: ProjectDep, store: StoreDep) -> Response:
    """Delete the project and its files."""
    store.delete(project["id"])
    return Response(status_code=status.HTTP_204_NO_CONTENT)
