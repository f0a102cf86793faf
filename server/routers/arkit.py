"""The project's ARKit 52 blendshapes (issue 16): made from its landmarks, with the user's
settings, played by the page and streamed as weights.

``GET /api/projects/{id}/arkit`` answers ``{"names": the 52 (Apple's order), "state":
"missing" | "stale" | "ready", "made_on": "default" | "project" | null, "settings":
`retarget.arkit.ArkitSettings` JSON (rig, gains, masks), "max_gain", "rigs", "job": the
running job or null}``. ``stale``: the mesh or landmarks changed since the shapes were made
(or the settings ask for another rig than they were made on, or the project's rig
changed under shapes made on it).

``PUT`` stores the settings (a running source driven by ARKit takes the new gains from
its next frame; the whole JSON form, checked: a gain out of [0, 2] or not a
number, an unknown shape name, a mask whose vertices and values differ in length or whose
vertex is not the mesh's are refused with 422 and the reason) and answers as GET does.
Painted masks belong to the mesh: a later mesh of another vertex count drops those that
do not fit.

``POST`` (optional body ``{"rig": "default" | "project"}``, saved with the settings)
makes the shapes again in the background (`retarget.arkit.arkit_shapes` in a child
process, `server.readers.arkit`); answers the job (``kind: "arkit"``, poll ``GET
/api/jobs/{job_id}``; progress is an estimate: the library reports none). 9 s for the
8,430-vertex sample face, 53 s for a 133k-vertex face, on this project's loaded 2-core
machine. 409 without landmarks, with ``"project"`` and no rig, or while another job runs.

``GET .../arkit/shapes`` answers ``application/octet-stream``, `server.wire`'s RTAK: the
52 morph targets as made (the page applies the masks as it paints them); ``?fixed=true``
applies the saved masks first (for other tools). 409 unless the shapes are ``ready``.

The stream's ``{"type": "drive", "drive": "arkit"}`` (`server.routers.stream`) plays a
source as the 52 weights (RTAW frames, or JSON named weights for a viewer that asks).
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Body, HTTPException, Query, Response, status

from retarget.arkit import ARKIT_NAMES, ArkitSettings
from retarget.arkit.drive import ArkitDrive
from retarget.arkit.settings import MAX_GAIN, RIGS
from retarget.errors import RetargetError
from retarget.landmarks import landmarks_from_json
from server.deps import HubDep, IsolationDep, JobsDep, MeshDep, ProjectDep, StoreDep
from server.errors import responses
from server.jobs import JobBusy
from server.readers import arkit
from server.store import ProjectStore
from server.wire import arkit_shapes_binary

router = APIRouter(prefix="/api/projects/{project_id}/arkit", tags=["arkit"],
                   responses=responses(404, 409, 422))


def project_settings(store: ProjectStore, project: dict) -> ArkitSettings:
    """The project's saved ARKit settings (defaults when none), masks that do not fit its
    mesh dropped."""
    data = store.arkit_settings(project["id"])
    settings = ArkitSettings() if data is None else ArkitSettings.from_json(data)
    mesh = project.get("mesh")
    return settings.fitting(mesh["n_vertices"]) if mesh else settings


def shapes_state(store: ProjectStore, project: dict, settings: ArkitSettings) -> tuple[str, str | None]:
    """("missing" | "stale" | "ready", the rig the stored shapes were made on or None)."""
    made = store.arkit_status(project["id"])
    if made is None:
        return "missing", None
    made_on = "default" if made["rig_version"] is None else "project"
    rig = store.rig_status(project["id"])
    fresh = made["revision"] == project["revision"] and made_on == settings.rig and (
        made_on == "default" or (rig is not None and rig["version"] == made["rig_version"]))
    return ("ready" if fresh else "stale"), made_on


def project_drive(store: ProjectStore, project_id: str) -> ArkitDrive:
    """A new ARKit drive (its own warm start) on the project's shapes and gains; 409-style
    `RetargetError` when the shapes are not ready."""
    project = store.get(project_id)
    settings = project_settings(store, project)
    state, _ = shapes_state(store, project, settings)
    if state != "ready":
        raise RetargetError(f"the project's ARKit shapes are {state}: make them first "
                            f"(POST /api/projects/{project_id}/arkit, the Blendshapes panel's Generate)")
    return ArkitDrive(store.arkit_shapes(project_id), settings.gains)


def _answer(store: ProjectStore, project: dict, jobs, settings: ArkitSettings | None = None) -> dict:
    settings = settings or project_settings(store, project)
    state, made_on = shapes_state(store, project, settings)
    job = jobs.running(project["id"], "arkit")
    return {"names": list(ARKIT_NAMES), "state": state, "made_on": made_on, "settings": settings.to_json(),
            "max_gain": MAX_GAIN, "rigs": list(RIGS), "job": None if job is None else job.as_json()}


@router.get("")
def get_arkit(project: ProjectDep, store: StoreDep, jobs: JobsDep) -> dict:
    """The shapes' state and the user's settings (module docstring)."""
    return _answer(store, project, jobs)


@router.put("")
def put_arkit(project: ProjectDep, store: StoreDep, jobs: JobsDep, hub: HubDep,
              body: dict[str, Any] = Body(examples=[{"rig": "default", "gains": {"jawOpen": 1.2},
                                                     "masks": {"eyeBlinkLeft": {"vertices": [10, 11],
                                                                                "values": [0.0, 0.5]}}}])) -> dict:
    """Validate and store the settings; answers as GET does."""
    mesh = project.get("mesh")
    settings = ArkitSettings.from_json(body, mesh["n_vertices"] if mesh else None)
    store.put_arkit_settings(project["id"], settings.to_json())
    playing = getattr(hub.source(project["id"]), "drive", None)
    if isinstance(playing, ArkitDrive):
        playing.set_gains(settings.gains)
    return _answer(store, store.get(project["id"]), jobs, settings)


@router.post("", status_code=status.HTTP_202_ACCEPTED)
def make_arkit(project: ProjectDep, mesh: MeshDep, store: StoreDep, jobs: JobsDep, isolation: IsolationDep,
               body: dict[str, Any] | None = Body(default=None, examples=[{"rig": "default"}])) -> dict:
    """Make the 52 shapes again in the background (module docstring); answers the job."""
    landmarks = store.landmarks(project["id"])
    if landmarks is None:
        raise HTTPException(status.HTTP_409_CONFLICT, f"project {project['id']!r} has no landmarks yet: "
                                                      "the ARKit shapes are made from them")
    settings = project_settings(store, project)
    body = body or {}
    if set(body) - {"rig"}:
        raise RetargetError(f"the body may only hold \"rig\"; got {sorted(body)}")
    if "rig" in body:
        settings = ArkitSettings.from_json({**settings.to_json(), "rig": body["rig"]}, len(mesh.vertices))
        store.put_arkit_settings(project["id"], settings.to_json())
    rig, rig_version = None, None
    if settings.rig == "project":
        found = store.rigs(project["id"])
        if found is None:
            raise HTTPException(status.HTTP_409_CONFLICT, f"project {project['id']!r} has no rig yet: compute it, "
                                                          "or make the shapes on the default rig")
        rig, _, rig_version = found
    points = landmarks_from_json(landmarks, mesh.vertices, mesh.faces)
    layout = landmarks.get("layout") or "ibug68"
    revision = project["revision"]

    def work(job) -> tuple[str, dict]:
        shapes = isolation.call(arkit, mesh, points, layout, rig, job=True, progress=job.report,
                                what="the ARKit shapes")
        store.put_arkit_shapes(project["id"], shapes, revision=revision, rig_version=rig_version)
        return (f"52 ARKit shapes on the {settings.rig} rig, {shapes.deltas.shape[1]} vertices",
                {"rig": settings.rig, "n_vertices": int(shapes.deltas.shape[1])})

    try:
        job = jobs.start(project["id"], "arkit", work)
    except JobBusy as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from exc
    return job.as_json()


@router.get("/shapes", response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}},
                             "description": "RTAK: the 52 morph targets, sparse int16 (server.wire)"}})
def get_shapes(project: ProjectDep, store: StoreDep,
               fixed: bool = Query(default=False, description="apply the saved masks")) -> Response:
    """The shapes as RTAK bytes; 409 unless they are ready."""
    settings = project_settings(store, project)
    state, _ = shapes_state(store, project, settings)
    if state != "ready":
        raise HTTPException(status.HTTP_409_CONFLICT, f"the project's ARKit shapes are {state}: "
                                                      f"make them with POST /api/projects/{project['id']}/arkit")
    shapes = store.arkit_shapes(project["id"])
    deltas = settings.fixed_deltas(shapes.deltas) if fixed else shapes.deltas
    return Response(arkit_shapes_binary(shapes.names, deltas), media_type="application/octet-stream")
