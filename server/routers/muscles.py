"""The project's virtual muscles (Woodward et al. §4; issue 15), in the library's JSON form.

``GET /api/projects/{id}/muscles`` answers `retarget.muscles.MuscleFace.to_json` plus
``"names"`` (the D dofs), ``"limits"`` (D, 2) and ``"edited"`` (saved by the user, not
placed). The first GET of a project with landmarks places them
(`retarget.muscles.place_muscles`, any layout holding at least six iBUG points) and stores
them with the project; a later landmarks change places them again unless the user saved
his own (`ProjectStore.put_muscles` never lets placed muscles replace those).

``PUT`` stores the user's muscles: what `MuscleFace.from_json` reads on the project's
mesh, Table 1's 21 muscles (`retarget.muscles.dof_names`: the expressions are read from
them), refused with 422 and the reason otherwise.

``GET .../muscles/played`` answers ``application/octet-stream``: `server.wire`'s RTMM
format, the muscles as the page's shader plays them
(`retarget.muscles.morphs.muscle_morphs`: one morph target per muscle and a jaw joint).
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Body, HTTPException, Response, status

from retarget.errors import RetargetError
from retarget.landmarks import landmarks_from_json
from retarget.mesh import Mesh
from retarget.muscles import MuscleFace, dof_names, place_muscles
from retarget.muscles.expressions import EXPRESSIONS
from retarget.muscles.morphs import muscle_morphs
from server.deps import MeshDep, ProjectDep, StoreDep
from server.errors import responses
from server.store import ProjectStore
from server.wire import morphs_binary

router = APIRouter(prefix="/api/projects/{project_id}/muscles", tags=["muscles"],
                   responses=responses(404, 409, 422))


def project_muscles(store: ProjectStore, project: dict, mesh: Mesh) -> tuple[MuscleFace, bool]:
    """The project's muscles and whether the user saved them: the stored ones while they
    fit the mesh (placed ones only for the current landmarks), else placed now and stored."""
    stored = store.muscles(project["id"])
    if stored is not None:
        data, revision, edited = stored
        if revision == project["revision"] or edited:
            try:
                return MuscleFace.from_json(data, mesh.vertices), edited
            except RetargetError:
                if revision == project["revision"]:
                    raise
                # saved for a mesh that has changed since (another vertex count): unusable
    landmarks = store.landmarks(project["id"])
    if landmarks is None:
        raise HTTPException(status.HTTP_409_CONFLICT, f"project {project['id']!r} has no landmarks yet: "
                                                      "the muscles are placed from them")
    points = landmarks_from_json(landmarks, mesh.vertices, mesh.faces)
    model = place_muscles(mesh.vertices, mesh.faces, points, landmarks.get("layout") or "ibug68")
    if not store.put_muscles(project["id"], model.to_json(), revision=project["revision"], edited=False):
        return project_muscles(store, store.get(project["id"]), mesh)  # the user's were saved meanwhile
    return model, False


def _answer(model: MuscleFace, edited: bool) -> dict:
    return {**model.to_json(), "names": list(model.names), "limits": model.limits.tolist(), "edited": edited}


@router.get("")
def get_muscles(project: ProjectDep, mesh: MeshDep, store: StoreDep) -> dict:
    """The muscles, placed from the landmarks if the project has none yet."""
    return _answer(*project_muscles(store, project, mesh))


@router.put("")
def put_muscles(project: ProjectDep, mesh: MeshDep, store: StoreDep,
                body: dict[str, Any] = Body(examples=[{"version": 1, "muscles": [], "jaw": {}}])) -> dict:
    """Validate the muscles on the mesh and store them as the user's; answers them."""
    try:
        model = MuscleFace.from_json(body, mesh.vertices)
    except RetargetError:
        raise
    except (AttributeError, TypeError, ValueError, KeyError, IndexError) as exc:  # a value of the wrong kind
        raise RetargetError(f"muscle JSON is malformed: {exc!r}") from None
    if model.names != dof_names():
        raise RetargetError(f"muscles must be Table 1's {len(dof_names()) - 1}, in its order "
                            f"({', '.join(dof_names()[:-1])}); got {', '.join(model.names[:-1])}")
    store.put_muscles(project["id"], model.to_json(), revision=project["revision"], edited=True)
    return _answer(model, True)


@router.get("/played", response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}},
                             "description": "RTMM: morph targets, jaw weights and pivot (server.wire)"}})
def get_played(project: ProjectDep, mesh: MeshDep, store: StoreDep) -> Response:
    """The muscles' played form as RTMM bytes."""
    model, _ = project_muscles(store, project, mesh)
    return Response(morphs_binary(muscle_morphs(model), model.names, model.limits, EXPRESSIONS),
                    media_type="application/octet-stream")
