"""Joined lips: whether the project's mesh has its lips in one surface, opening its mouth
(a new mesh revision cut along the lip contact line, `retarget.lips`) and going back.

``GET .../mesh/lips`` answers ``{"joined": bool | null, "detail": str}`` (null when the
landmarks' layout has no mouth corners and lip points to tell). ``POST .../mesh/open-mouth``
stores the opened mesh and its landmarks as a new revision (the rig is dropped, as for any
new mesh) and keeps the replaced ones; ``POST .../mesh/revert`` goes back to them. Both
answer the project, whose ``previous_mesh`` says whether there is one to go back to.
"""

from __future__ import annotations

from fastapi import APIRouter, HTTPException, status

from retarget.errors import RetargetError
from retarget.landmarks import SurfacePoints, landmarks_from_json
from retarget.layouts import get_layout
from retarget.lips import lips_joined
from retarget.mesh import Mesh
from server.deps import IsolationDep, MeshDep, ProjectDep, StoreDep
from server.errors import responses
from server.readers import opened_mesh

router = APIRouter(prefix="/api/projects/{project_id}/mesh", tags=["meshes"],
                   responses=responses(404))

JOINED = "The lips are joined in one surface: the mouth cannot open."


def _points(project: dict, mesh: Mesh, store) -> SurfacePoints:
    """The project's landmarks on `mesh`; 409 when it has none yet."""
    data = store.landmarks(project["id"])
    if data is None:
        raise HTTPException(status.HTTP_409_CONFLICT,
                            f"project {project['id']!r} has no landmarks yet: the lips are "
                            "found from the landmarks' mouth points")
    return landmarks_from_json(data, mesh.vertices, mesh.faces)


@router.get("/lips", responses=responses(404, 409))
def get_lips(project: ProjectDep, mesh: MeshDep, store: StoreDep) -> dict:
    """Whether the lips are one surface (`retarget.lips.lips_joined`), with a sentence."""
    points = _points(project, mesh, store)
    if not points.layout:
        return {"joined": None, "detail": "the landmarks have no layout to find the lips by"}
    try:
        joined = lips_joined(mesh.vertices, mesh.faces, points, get_layout(points.layout))
    except RetargetError as exc:  # a layout without lip points, lips far apart
        return {"joined": None, "detail": str(exc)}
    return {"joined": joined,
            "detail": JOINED if joined else "The lips are separate: the mouth opens."}


@router.post("/open-mouth", responses=responses(404, 409, 503))
def open_mouth(project: ProjectDep, mesh: MeshDep, store: StoreDep,
               isolation: IsolationDep) -> dict:
    """Cut the mesh open along its lip contact line (in a child process, as uploads are
    read) and store it with its landmarks as a new revision; answers the project. 422 when
    the lips are already separate."""
    points = _points(project, mesh, store)
    opened = isolation.call(opened_mesh, mesh, points, what="opening the mouth")
    mesh_info = project["mesh"]
    return store.put_mesh_revision(
        project["id"], opened.mesh_file, "glb", filename=f"{mesh_info['filename']} (mouth opened)",
        n_vertices=opened.n_vertices, n_faces=opened.n_faces, landmarks=opened.landmarks,
        n_points=opened.n_points, revision=project["revision"])


@router.post("/revert", responses=responses(404, 409))
def revert_mesh(project: ProjectDep, store: StoreDep) -> dict:
    """Go back to the mesh and landmarks the last opening replaced (the rig is dropped);
    answers the project. 409 when there is none."""
    return store.revert_mesh(project["id"])
