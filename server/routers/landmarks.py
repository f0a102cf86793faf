"""The project's landmarks (target feature points), in the library's JSON form.

``PUT`` takes what `retarget.landmarks.landmarks_from_json` reads::

    {"vertex_indices": [...]}  |  {"positions": [[x, y, z], ...]}
    |  {"triangles": [[a, b, c], ...], "barycentric": [[u, v, w], ...]}
    plus an optional "layout": a name of `retarget.layouts.LAYOUTS`, or of a custom
    layout the project saved (``PUT .../layouts/{name}``: its saved name or custom-<hash>),
    or with "layout_spec" a custom layout's spec inline (a landmarks file of the CLI's)

checked against the stored mesh; with a layout the point count must be the layout's. A
custom layout's landmarks are stored with its spec (``layout`` is its custom-<hash>), so
they stay readable whatever happens to the saved layout.
What is stored and answered by ``GET`` is `SurfacePoints.to_json` (positions are
snapped to the surface, so they come back as triangles and barycentric weights).
Setting landmarks drops the rig, which was made for the previous ones.

``POST .../landmarks/find`` finds a layout's points with no clicks
(`retarget.facemesh.placement`, in a child process: `server.readers.found_landmarks`) as a
job. Found landmarks are stored with ``"confidence"`` (N,) 0..1 and ``"check_below"``
beside the points (GET answers them; a point under ``check_below`` asks to be checked);
landmarks saved with PUT are the user's and have neither. The job stores what it found
unless that would overwrite the user's work (`ProjectStore.put_found_landmarks`): then it
ends done with ``saved: false`` and the reason.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Body, HTTPException, status
from pydantic import BaseModel, Field, StrictBool

from retarget.errors import RetargetError
from retarget.landmarks import landmarks_from_json
from retarget.layouts import LAYOUTS, get_layout
from server.deps import IsolationDep, JobsDep, MeshDep, ProjectDep, StoreDep
from server.errors import responses
from server.jobs import JobBusy
from server.project_layouts import resolve_layout
from server.readers import found_landmarks

router = APIRouter(prefix="/api/projects/{project_id}/landmarks", tags=["landmarks"],
                   responses=responses(404))

FIND_LAYOUT = "dutreve22"
"""The layout found for a project that has none yet: the page's default for a new project
(Dutreve's points and the chin)."""


@router.put("", responses=responses(404, 409))
def put_landmarks(project: ProjectDep, mesh: MeshDep, store: StoreDep,
                  body: dict[str, Any] = Body(examples=[{"vertex_indices": [0, 1, 2]}])) -> dict:
    """Validate the landmarks against the mesh and store them; answers them as stored."""
    layout_name = body.get("layout")
    layout_name = "" if layout_name is None else layout_name
    if not isinstance(layout_name, str):
        raise RetargetError(f"landmarks 'layout' must be a layout name, got {layout_name!r}")
    if layout_name and body.get("layout_spec") is None:  # the library's name for the project's
        body = {**body, "layout": resolve_layout(store, project["id"], layout_name).name}
    try:
        points = landmarks_from_json(body, mesh.vertices, mesh.faces)
    except RetargetError:
        raise
    except (TypeError, ValueError) as exc:  # numpy refusing a malformed value
        raise RetargetError(f"landmarks JSON is malformed: {exc}") from exc
    layout = get_layout(points.layout) if points.layout else None
    if layout is not None and points.n_points != layout.n_points:
        raise RetargetError(
            f"layout {layout_name!r} has {layout.n_points} points but {points.n_points} "
            "landmarks were given"
        )
    stored = points.to_json()
    store.put_landmarks(project["id"], stored, n_points=points.n_points, layout=points.layout,
                        revision=project["revision"])
    return stored


@router.get("")
def get_landmarks(project: ProjectDep, store: StoreDep) -> dict:
    """The stored landmarks JSON."""
    landmarks = store.landmarks(project["id"])
    if landmarks is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            f"project {project['id']!r} has no landmarks yet")
    return landmarks


class FindRequest(BaseModel):
    layout: str | None = Field(default=None, description="one of " + ", ".join(LAYOUTS) + "; default: "
                               f"the project's landmarks' layout, else {FIND_LAYOUT}")
    replace: StrictBool = Field(default=False, description="store the points found even over "
                                "landmarks or unsaved points placed by hand on this mesh")


@router.post("/find", status_code=status.HTTP_202_ACCEPTED, responses=responses(404, 409))
def find_landmarks(project: ProjectDep, mesh: MeshDep, store: StoreDep, jobs: JobsDep,
                   isolation: IsolationDep, body: FindRequest) -> dict:
    """Start finding the layout's points on the stored mesh with no clicks, in a child
    process; answers the job (poll ``GET /api/jobs/{job_id}``). Its result:
    ``{saved, layout, n_points, check: [point names], presence, reason}``; with ``saved``
    the points are the project's landmarks, with their confidence. No face on the mesh
    fails the job, saying so; the project keeps what it had. 409 when the project has
    landmarks placed by hand (unless ``replace``) or is already finding points. It runs
    beside a rig or tracking job of the project."""
    current = project["landmarks"]
    layout = resolve_layout(store, project["id"], body.layout or (
        current["layout"] if current and current["layout"] else FIND_LAYOUT))
    if not layout.has_mediapipe468:
        raise RetargetError(f"layout {layout.name!r} ({layout.description}) has points that are no "
                            "face-mesh vertex: they cannot be found with no clicks; place them by hand")
    if current is not None and not body.replace and "confidence" not in store.landmarks(project["id"]):
        raise HTTPException(status.HTTP_409_CONFLICT,
                            f"project {project['id']!r} has landmarks placed by hand: find "
                            "points with replace: true to replace them")
    revision = project["revision"]

    def work(job) -> tuple[str, dict]:
        # the Layout itself, so a custom one reaches the child process with its spec
        found = isolation.call(found_landmarks, mesh, layout, job=True, progress=job.report,
                               what="finding the landmarks")
        why_not = store.put_found_landmarks(project["id"], found.landmarks, n_points=found.n_points,
                                            layout=layout.name, revision=revision,
                                            replace=body.replace)
        check = f"; check {len(found.check)}: {', '.join(found.check)}" if found.check else ""
        kept = "" if why_not is None else f"; not saved: {why_not}"
        return (f"found {found.n_points} {layout.name} points (face presence "
                f"{found.presence:.2f}){check}{kept}",
                {"saved": why_not is None, "layout": layout.name, "n_points": found.n_points,
                 "check": found.check, "presence": round(found.presence, 3), "reason": why_not})

    try:
        job = jobs.start(project["id"], "landmarks", work, exclusive=False)
    except JobBusy as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from exc
    return job.as_json()
