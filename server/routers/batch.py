"""Projects and their takes as a batch for ``retarget batch`` (`retarget.batch`).

    GET /api/manifest.zip?projects=<id>,<id>|all[&outputs=gltf,arkit_csv,npy][&settings=<JSON>]
    GET /api/projects/{id}/manifest.zip[?outputs=...][&settings=<JSON>]

A zip (`retarget.batch.bundle.manifest_bundle`) of ``manifest.json``, each project as a
character (``characters/<name>.glb``: its mesh, landmarks and the rig in use, painted
weights included, as ``export.glb`` writes it with no take) and every take of those
projects (``takes/<name>.npz``, trimmed as the take list shows it) with the conditioning
it plays with: ``settings`` (ConditionSettings JSON) when given, else the project's saved
Performance-panel settings. Unzipped, ``retarget batch manifest.json --out DIR`` makes
every take on every character. A project named explicitly without landmarks or a rig is
409; ``all`` leaves such projects out.
"""

from __future__ import annotations

import json
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query, Response, status

from retarget.batch.bundle import manifest_bundle
from retarget.errors import RetargetError
from retarget.gltf import export_gltf
from retarget.landmarks import landmarks_from_json
from retarget.sources.conditioning import ConditionSettings
from server.deps import ProjectDep, StoreDep
from server.errors import responses
from server.routers.meshes import MESH_UNITS_KEY

router = APIRouter(tags=["batch"])

ZIP_MEDIA_TYPE = "application/zip"
_ZIP = {200: {"content": {ZIP_MEDIA_TYPE: {}}}}

OutputsQuery = Annotated[str, Query(description="what each pair makes: gltf, arkit_csv, npy, comma-separated")]
SettingsQuery = Annotated[str, Query(description="ConditionSettings JSON for every take (default: each "
                                     "project's saved conditioning)")]


@router.get("/api/manifest.zip", response_class=Response, responses={**_ZIP, **responses(404, 409)})
def export_manifest(store: StoreDep,
                    projects: str = Query(default="all", description="project ids, comma-separated, or 'all'"),
                    outputs: OutputsQuery = "gltf", settings: SettingsQuery = "") -> Response:
    """The projects and their takes as a batch zip (see the module docstring)."""
    if projects.strip() == "all":
        chosen = [p for p in store.list() if _ready(store, p)]
    else:
        ids = [i.strip() for i in projects.split(",") if i.strip()]
        chosen = [store.get(i) for i in dict.fromkeys(ids)]
    if not chosen:
        raise HTTPException(status.HTTP_409_CONFLICT, "no project has landmarks and a rig to export yet")
    return _bundle(store, chosen, outputs, settings, "batch")


@router.get("/api/projects/{project_id}/manifest.zip", response_class=Response,
            responses={**_ZIP, **responses(404, 409)})
def export_project_manifest(project: ProjectDep, store: StoreDep, outputs: OutputsQuery = "gltf",
                            settings: SettingsQuery = "") -> Response:
    """One project and its takes as a batch zip (see the module docstring)."""
    return _bundle(store, [project], outputs, settings, project["name"])


def _ready(store, project: dict) -> bool:
    return store.landmarks(project["id"]) is not None and store.rig(project["id"]) is not None


def _bundle(store, projects: list[dict], outputs: str, settings: str, name: str) -> Response:
    given = None
    if settings:
        try:
            given = ConditionSettings.from_dict(json.loads(settings)).to_dict()
        except json.JSONDecodeError as exc:
            raise RetargetError(f"query parameter 'settings' is not JSON: {exc}") from None
    characters, takes = [], []
    for project in projects:
        landmarks, weights, mesh = store.landmarks(project["id"]), store.rig(project["id"]), store.mesh(project["id"])
        if landmarks is None or weights is None or mesh is None:
            missing = "mesh" if mesh is None else "landmarks" if landmarks is None else "rig"
            raise HTTPException(status.HTTP_409_CONFLICT,
                                f"project {project['name']!r} has no {missing} yet: place the landmarks "
                                "and compute the rig before exporting")
        points = landmarks_from_json(landmarks, mesh.vertices, mesh.faces)
        # the unit the user chose for the mesh, as export.glb uses it (the batch reads it back)
        units = project["settings"].get(MESH_UNITS_KEY) or "guess"
        characters.append((project["name"], export_gltf(mesh, points, weights, [], mesh_units=units)))
        conditioning = given if given is not None else _saved(project)
        for info in store.takes(project["id"]):
            takes.append((info["name"], store.take(project["id"], info["id"]), conditioning))
    if not takes:
        raise HTTPException(status.HTTP_409_CONFLICT, "the projects have no takes to export")
    data = manifest_bundle(characters, takes, [o.strip() for o in outputs.split(",") if o.strip()])
    safe = "".join(c if c.isalnum() or c in "._-" else "-" for c in name).strip(".-")[:100] or "batch"
    return Response(data, media_type=ZIP_MEDIA_TYPE,
                    headers={"Content-Disposition": f'attachment; filename="{safe}.manifest.zip"'})


def _saved(project: dict) -> dict:
    """The project's saved Performance-panel conditioning, checked."""
    saved = (project.get("settings") or {}).get("conditioning")
    try:
        return ConditionSettings.from_dict(saved).to_dict()
    except RetargetError as exc:
        raise RetargetError(f"project {project['name']!r}: its saved conditioning: {exc}") from None
