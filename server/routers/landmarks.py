"""The project's landmarks (target feature points), in the library's JSON form.

``PUT`` takes what `retarget.landmarks.landmarks_from_json` reads::

    {"vertex_indices": [...]}  |  {"positions": [[x, y, z], ...]}
    |  {"triangles": [[a, b, c], ...], "barycentric": [[u, v, w], ...]}
    plus an optional "layout": a name of `retarget.layouts.LAYOUTS`

checked against the stored mesh; with a layout the point count must be the layout's.
What is stored and answered by ``GET`` is `SurfacePoints.to_json` (positions are
snapped to the surface, so they come back as triangles and barycentric weights).
Setting landmarks drops the rig, which was made for the previous ones.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Body, HTTPException, status

from retarget.errors import RetargetError
from retarget.landmarks import landmarks_from_json
from retarget.layouts import get_layout
from server.deps import MeshDep, ProjectDep, StoreDep
from server.errors import responses

router = APIRouter(prefix="/api/projects/{project_id}/landmarks", tags=["landmarks"],
                   responses=responses(404))


@router.put("", responses=responses(404, 409))
def put_landmarks(project: ProjectDep, mesh: MeshDep, store: StoreDep,
                  body: dict[str, Any] = Body(examples=[{"vertex_indices": [0, 1, 2]}])) -> dict:
    """Validate the landmarks against the mesh and store them; answers them as stored."""
    layout_name = body.get("layout")
    layout_name = "" if layout_name is None else layout_name
    if not isinstance(layout_name, str):
        raise RetargetError(f"landmarks 'layout' must be a layout name, got {layout_name!r}")
    layout = get_layout(layout_name) if layout_name else None
    try:
        points = landmarks_from_json(body, mesh.vertices, mesh.faces)
    except RetargetError:
        raise
    except (TypeError, ValueError) as exc:  # numpy refusing a malformed value
        raise RetargetError(f"landmarks JSON is malformed: {exc}") from exc
    if layout is not None and points.n_points != layout.n_points:
        raise RetargetError(
            f"layout {layout_name!r} has {layout.n_points} points but {points.n_points} "
            "landmarks were given"
        )
    stored = points.to_json()
    store.put_landmarks(project["id"], stored, n_points=points.n_points, layout=layout_name,
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
