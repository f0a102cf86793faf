"""Feature-point layouts for the landmark picker and the browser's face tracker: names,
regions, sides, mirror partners, a reference position for each point (on the built-in
sample face, cm, +y up, the face looking down +z), so the browser can show which point
comes next, and each point's MediaPipe face-mesh vertex (`mediapipe468`), so the
browser's tracker can read its 468 landmarks into the layout.

A project also saves custom layouts, its user's own markers (`retarget.custom_layouts`)::

    PUT    /api/projects/{id}/layouts/{name}   the spec JSON; 201 new, 200 replaced, 422 why not
    GET    /api/projects/{id}/layouts          the built-in layouts and the project's
    GET    /api/projects/{id}/layouts/{name}   one, by its name or its custom-<hash>
    DELETE /api/projects/{id}/layouts/{name}
    GET    /api/projects/{id}/layouts/from-take/{take_id}   the take's marker names, which
                                               a layout made from them takes as its points
    POST   /api/projects/{id}/layouts/from-take  a take file's marker names (read, not
                                               stored: a take of markers no layout of the
                                               project has yet is refused as a take)

A custom layout's JSON is a built-in one's plus ``custom: true``, ``saved_as`` (its name in
the project) and ``spec``; its ``name`` (``custom-<hash of the spec>``) is what landmarks
name as their ``layout``. A point with no reference position has ``reference: null``, one
with no face-mesh vertex ``mediapipe468: -1``.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Body, File, Form, HTTPException, Response, UploadFile, status

from retarget.custom_layouts import layout_from_spec, take_reference
from retarget.errors import RetargetError
from retarget.layouts import GROUPS, LAYOUTS, REGIONS, Layout
from server.deps import IsolationDep, LimitsDep, ProjectDep, StoreDep
from server.errors import responses
from server.limits import body_limit
from server.readers import take_from_upload
from server.routers.meshes import read_capped, upload_extension
from server.routers.takes import TAKE_EXTENSIONS
from server.store import LAYOUT_NAME, LayoutNotFound

router = APIRouter(tags=["layouts"], responses=responses())


def _layout_json(layout: Layout) -> dict:
    try:
        reference = layout.reference_points().round(3).tolist()
    except RetargetError:  # a custom layout given no positions: the picker shows none
        reference = [None] * layout.n_points
    return {
        "name": layout.name,
        "description": layout.description,
        "n_points": layout.n_points,
        "points": [
            {"name": point, "region": region, "side": side, "mirror": mirror,
             "reference": xyz, "mediapipe468": i468}
            for point, region, side, mirror, xyz, i468 in zip(
                layout.point_names, layout.regions, layout.sides, layout.mirror, reference,
                layout.mediapipe468)
        ],
        "regions": list(REGIONS),
        "groups": {group: list(members) for group, members in GROUPS.items()},
    }


def _custom_json(info: dict, spec: dict) -> dict:
    layout = layout_from_spec(spec)
    anchors = [layout.point_names[i] for i in layout.anchors]
    return {**_layout_json(layout), "custom": True, "saved_as": info["name"], "anchors": anchors,
            "updated": info["updated"], "spec": layout.spec()}


@router.get("/api/layouts")
def list_layouts() -> list[dict]:
    """Every built-in layout with its points."""
    return [_layout_json(layout) for layout in LAYOUTS.values()]


@router.get("/api/layouts/{name}")
def get_layout_json(name: str) -> dict:
    """One layout; 422 naming the known ones for an unknown name."""
    if name not in LAYOUTS:  # a custom layout is a project's: GET /api/projects/{id}/layouts/{name}
        raise RetargetError(f"unknown layout {name!r:.80}; available: {', '.join(LAYOUTS)}")
    return _layout_json(LAYOUTS[name])


@router.get("/api/projects/{project_id}/layouts", responses=responses(404))
def list_project_layouts(project: ProjectDep, store: StoreDep) -> list[dict]:
    """The built-in layouts, then the project's custom layouts by name."""
    custom = [_custom_json(*store.layout(project["id"], info["name"]))
              for info in store.layouts(project["id"])]
    return list_layouts() + custom


@router.get("/api/projects/{project_id}/layouts/from-take/{take_id}", responses=responses(404))
def get_take_markers(project: ProjectDep, store: StoreDep, take_id: str) -> dict:
    """The names of a take's points (its markers, in its order), for making a custom layout
    of them: ``{take, names, reference}``, the reference (`take_reference`) null unless the
    take is 2D or from stereo stickers, with every marker seen; 404 for no such take."""
    take = store.take(project["id"], take_id, trimmed=False)
    return {"take": take_id, "names": list(take.names), "reference": take_reference(take)}


@router.post("/api/projects/{project_id}/layouts/from-take", responses=responses(404, 415, 503))
@body_limit(files=1)
def post_take_markers(project: ProjectDep, limits: LimitsDep, isolation: IsolationDep,
                      file: UploadFile = File(description=", ".join(f".{e}" for e in TAKE_EXTENSIONS)),
                      fps: float | None = Form(default=None, gt=0, le=1000,
                                               description="frame rate when the file has none")) -> dict:
    """The names of the points of a take file, read as ``POST .../takes`` reads one (in a
    child process) but not stored: ``{take: null, names, reference}`` (as the GET's); 422
    for a file that is no take."""
    ext = upload_extension(file.filename, TAKE_EXTENSIONS)
    data = read_capped(file, limits.max_upload_bytes)
    if not data:
        raise RetargetError(f"the uploaded file {file.filename!r} is empty")
    take = isolation.call(take_from_upload, data, f"take.{ext}", file.filename,
                          {"layout": None, "fps": fps}, {}, None,
                          what=f"take file {file.filename!r} refused: not a readable {ext.upper()} file")
    return {"take": None, "names": list(take.names), "reference": take_reference(take)}


@router.get("/api/projects/{project_id}/layouts/{name}", responses=responses(404))
def get_project_layout(project: ProjectDep, store: StoreDep, name: str) -> dict:
    """A built-in layout, or one of the project's custom layouts by the name it was saved
    under or its ``custom-<hash>``; 404 for none."""
    if name in LAYOUTS:
        return _layout_json(LAYOUTS[name])
    try:
        return _custom_json(*store.layout(project["id"], name))
    except LayoutNotFound as exc:
        raise HTTPException(status.HTTP_404_NOT_FOUND, str(exc)) from None


@router.put("/api/projects/{project_id}/layouts/{name}", status_code=status.HTTP_201_CREATED,
            responses={200: {"description": "a layout of that name replaced"}, **responses(404, 409)})
def put_project_layout(project: ProjectDep, store: StoreDep, name: str, response: Response,
                       spec: dict[str, Any] = Body(examples=[{"points": [
                           {"name": "m01", "region": "brows", "side": "right", "mirror": "m02"},
                           {"name": "m02", "region": "brows", "side": "left", "mirror": "m01"},
                           {"name": "m03", "region": "nose", "side": "center"}]}])) -> dict:
    """Save a custom layout (its spec, `retarget.custom_layouts`) as `name`: 201 when new,
    200 when it replaces one of that name (landmarks saved in the old one keep its spec).
    422 says what is wrong with the name or the spec (at most 1000 points, names of at most
    64 safe characters); 409 when the project already has its most custom layouts."""
    if not LAYOUT_NAME.fullmatch(name):
        raise RetargetError(f"layout name {name!r:.80} must be 1 to 64 letters, digits, '_' or '-'")
    if name in LAYOUTS or name.startswith("custom-"):
        raise RetargetError(f"layout name {name!r} is taken by the library's layouts: choose another")
    layout = layout_from_spec(spec)  # counts the points before any per-point work
    try:
        info, new = store.put_layout(project["id"], name, layout.spec(), layout=layout.name,
                                     n_points=layout.n_points)
    except ValueError as exc:
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
    if not new:
        response.status_code = status.HTTP_200_OK
    return _custom_json(info, layout.spec())


@router.delete("/api/projects/{project_id}/layouts/{name}", status_code=status.HTTP_204_NO_CONTENT,
               responses=responses(404))
def delete_project_layout(project: ProjectDep, store: StoreDep, name: str) -> Response:
    """Forget a saved custom layout (landmarks saved in it keep its spec); 404 for none."""
    try:
        store.delete_layout(project["id"], name)
    except LayoutNotFound as exc:
        raise HTTPException(status.HTTP_404_NOT_FOUND, str(exc)) from None
    return Response(status_code=status.HTTP_204_NO_CONTENT)

