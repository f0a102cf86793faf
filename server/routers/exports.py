"""A project as a glTF 2.0 binary, and a project from one.

    GET  /api/projects/{id}/export.glb[?takes=<id>,<id>|all][&settings=<JSON>][&regions=<a>,<b>]
                                       [&drive=points|muscles|arkit][&units=m|keep]
                                       [&form=exact|skin][&rate=24|25|30|60][&key_tolerance=<mm>]
    POST /api/projects/import          multipart: file (.glb), name (optional)

The export (`retarget.gltf.export_gltf`) holds the project's mesh, landmarks and the rig
in use (painted weights included): a glTF skin for a joint-based rig (ellipsoid,
geodesic), morph targets for the interpolating ones (biharmonic, rbf, region_rbf,
laplacian). Each take named in ``takes`` becomes one animation named after the take, its
frames retargeted as the take player plays them (`retarget.performance.take_clip`: conditioned
by ``settings``, the Performance panel's ConditionSettings JSON, defaults when absent;
``regions`` moves only those regions, groups or points). It answers as an attachment
named after the project. A plain request: the sample face with a 30 s take at 30 fps
exports in well under a second. With ``drive=muscles`` it holds the project's muscles
instead of the rig (`retarget.gltf.export_muscles_gltf`: a morph target per muscle and a
jaw joint; the rig is not needed), each take's feature motion solved into contractions by
the muscle IK (`retarget.muscles.drive.MuscleDrive`, from the take's first frame). With
``drive=arkit`` it holds the project's ARKit shapes (`server.routers.arkit`: made, with the
user's painted fixes) as 52 named morph targets (`retarget.gltf.export_arkit_gltf`), each
take solved into their weights with the user's gains as the stream solves it
(`retarget.arkit.ArkitDrive`); 409 when the shapes are not made for the current landmarks.
Lengths are in metres (``units=m``, the default) from the mesh's unit in the project's
settings (``mesh_units``, `server.routers.meshes`; guessed from the mesh's size when a
project has none), or the mesh's own numbers with ``units=keep``; the file records the scale
(`retarget.gltf.units`). With "turn the head" on in ``settings`` (``apply_rotation``) each
take's head rotations turn a ``head`` node as the app's viewer turns the face
(`retarget.gltf.head`). ``form=skin`` writes the rig as a skin of four influences a vertex
fitted to the takes (`retarget.weights.skin_fit`; a 133k-vertex face with a dense rig and a
30 s take: 296 MiB of morph targets as it is, 9 MiB so), its error in the file and in the
``X-Retarget-Fit`` header (the record's JSON); ``rate`` puts the keys at that many frames a
second, ``key_tolerance`` (millimetres, at most 10) drops the keys a line reproduces
(`retarget.gltf.keys`).

The import reads a .glb this app exported (`retarget.gltf.read_gltf`) into a new
project: its mesh (stored as a mesh-only .glb, `retarget.gltf.export_mesh_gltf`), its
landmarks and its rig, which becomes the new project's automatic rig (a painted rig
comes in as painted, with nothing to reset to); the scale the export applied is undone, and
the unit it recorded becomes the new project's ``mesh_units``. Animations are not imported: they hold
the target's feature displacements, not a performer's points, so they cannot be takes;
the answer names them. A file another tool made, a corrupt one or one over the upload
limit is refused (415 for another extension, 413 over the limit, 422 with the reason)
and no project is made.
"""

from __future__ import annotations

import io
import json
import re
from typing import Literal

from fastapi import APIRouter, File, Form, HTTPException, Query, Response, UploadFile, status

from retarget.arkit.clip import ArkitClip
from retarget.clips import ContractionClip
from retarget.errors import RetargetError
from retarget.gltf import export_arkit_gltf, export_gltf, export_muscles_gltf
from retarget.gltf.glb import glb_document
from retarget.landmarks import landmarks_from_json
from retarget.muscles.drive import MuscleDrive
from retarget.muscles.morphs import muscle_morphs
from retarget.performance import take_clip
from server.deps import IsolationDep, LimitsDep, MeshDep, ProjectDep, StoreDep
from server.errors import responses
from server.limits import body_limit
from server.readers import imported_project
from server.routers.meshes import MESH_UNITS_KEY, read_capped, units_settings, upload_extension
from server.routers.arkit import project_drive, project_settings
from server.routers.muscles import project_muscles

router = APIRouter(tags=["exports"])

GLB_MEDIA_TYPE = "model/gltf-binary"


@router.get("/api/projects/{project_id}/export.glb", response_class=Response,
            responses={200: {"content": {GLB_MEDIA_TYPE: {}}}, **responses(404, 409)})
def export_project(project: ProjectDep, mesh: MeshDep, store: StoreDep,
                   takes: str = Query(default="", description="take ids, comma-separated, or 'all'"),
                   settings: str = Query(default="", description="ConditionSettings JSON"),
                   regions: str = Query(default="", description="regions that move, comma-separated"),
                   drive: Literal["points", "muscles", "arkit"] = Query(
                       default="points", description="points: the rig; muscles: the muscles; arkit: ARKit's 52 shapes"),
                   units: Literal["m", "keep"] = Query(
                       default="m", description="m: lengths in metres (glTF's unit); keep: the mesh's own numbers"),
                   form: Literal["exact", "skin"] = Query(
                       default="exact", description="exact: the rig as it is; skin: four influences a vertex, fitted"),
                   rate: Literal["24", "25", "30", "60", ""] = Query(
                       default="", description="the animation's keys at this many frames a second (default: the takes' own)"),
                   key_tolerance: float = Query(
                       default=0.0, ge=0.0, le=10.0, description="millimetres: drop keys a line reproduces this closely"),
                   ) -> Response:
    """The project rigged and animated as a .glb download (see the module docstring)."""
    landmarks = store.landmarks(project["id"])
    weights = store.rig(project["id"])
    if landmarks is None or (weights is None and drive == "points"):
        missing = "landmarks" if landmarks is None else "rig"
        raise HTTPException(status.HTTP_409_CONFLICT,
                            f"project {project['name']!r} has no {missing} yet: place the landmarks "
                            "and compute the rig before exporting")
    points = landmarks_from_json(landmarks, mesh.vertices, mesh.faces)
    target, layout = points.positions(mesh.vertices), landmarks.get("layout") or ""
    conditioning = _settings(settings)
    scaling = {"units": units, "mesh_units": project["settings"].get(MESH_UNITS_KEY) or "guess",
               "rate": float(rate) if rate else None, "key_tolerance": key_tolerance}
    if form != "exact" and drive != "points":
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_ENTITY,
                            f"form={form} shapes the rig's export: it goes with drive=points")
    moving = [r.strip() for r in regions.split(",") if r.strip()] or None
    clips, names = [], set()
    for info in _takes(store, project["id"], takes):
        name = _unique(info["name"], names)
        try:
            clips.append(take_clip(name, store.take(project["id"], info["id"]), target, layout,
                                   conditioning, regions=moving))
        except RetargetError as exc:
            raise RetargetError(f"take {info['name']!r}: {exc}") from exc
    if drive == "arkit":
        try:
            arkit = project_drive(store, project["id"])
        except RetargetError as exc:
            raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from None
        solved = []
        for clip in clips:
            arkit.reset()
            solved.append(ArkitClip(clip.name, arkit.weights_frames(clip.displacements), clip.times,
                                    head_rotations=clip.head_rotations))
        shapes = arkit.shapes
        fixed = type(shapes)(shapes.names, project_settings(store, project).fixed_deltas(shapes.deltas),
                             shapes.at_points)
        data = export_arkit_gltf(mesh, fixed, solved, **scaling)
    elif drive == "muscles":
        model, _ = project_muscles(store, project, mesh)
        muscles = MuscleDrive(model, points)
        solved = []
        for clip in clips:
            muscles.reset()
            solved.append(ContractionClip(clip.name, muscles.contractions(clip.displacements), clip.times,
                                          head_rotations=clip.head_rotations))
        data = export_muscles_gltf(mesh, muscle_morphs(model), solved, **scaling)
    else:
        data = export_gltf(mesh, points, weights, clips, form=form, **scaling)
    headers = {"Content-Disposition": f'attachment; filename="{_file_name(project["name"])}.glb"'}
    fit = glb_document(io.BytesIO(data))["scenes"][0]["extras"]["retarget"].get("fit")
    if fit is not None:
        headers["X-Retarget-Fit"] = json.dumps(fit)
    return Response(data, media_type=GLB_MEDIA_TYPE, headers=headers)


@router.post("/api/projects/import", status_code=status.HTTP_201_CREATED,
             responses=responses(415, 503))
@body_limit(files=1)
def import_project(store: StoreDep, limits: LimitsDep, isolation: IsolationDep,
                   file: UploadFile = File(description="a .glb exported by this app"),
                   name: str | None = Form(default=None, max_length=200)) -> dict:
    """A new project from an exported .glb, named `name` or after the file; answers
    ``{project, deformation, animations}`` (the animation names, which are not imported).
    The file is read in a child process (`server.readers.imported_project`)."""
    upload_extension(file.filename, ("glb",))
    data = read_capped(file, limits.max_upload_bytes)
    shown = (file.filename or "upload.glb").replace("\\", "/").rsplit("/", 1)[-1]
    if not data:
        raise RetargetError(f"the uploaded file {shown!r} is empty")
    face = isolation.call(imported_project, data, shown, limits.max_vertices,
                          what=f"{shown!r} cannot be imported: not a readable .glb")
    project = store.create((name or "").strip() or shown.rsplit(".", 1)[0] or "imported")
    try:
        project = store.put_mesh(project["id"], face.mesh_file, "glb", filename=shown,
                                 n_vertices=face.n_vertices, n_faces=face.n_faces)
        project = store.put_landmarks(project["id"], face.landmarks, n_points=face.n_points,
                                      layout=face.layout, revision=project["revision"])
        project = store.put_rig(project["id"], face.weights, revision=project["revision"])
        if face.units is not None:
            project = store.update(project["id"], settings=units_settings(face.units))
    except BaseException:
        store.delete(project["id"])  # no half-imported project
        raise
    return {"project": project, "deformation": face.deformation, "animations": face.animations}


def _takes(store, project_id: str, wanted: str) -> list[dict]:
    """The infos of the takes named in `wanted` ('all', or ids separated by commas), in
    that order; an unknown id is `TakeNotFound` (404)."""
    if wanted.strip() == "all":
        return store.takes(project_id)
    ids = [t.strip() for t in wanted.split(",") if t.strip()]
    return [store.take_info(project_id, take_id) for take_id in dict.fromkeys(ids)]


def _settings(text: str):
    if not text:
        return None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise RetargetError(f"query parameter 'settings' is not JSON: {exc}") from exc


def _unique(name: str, taken: set) -> str:
    """`name`, or ``name (2)``... when an earlier animation has it (glTF viewers pick
    clips by name)."""
    unique, n = name, 1
    while unique in taken:
        n += 1
        unique = f"{name} ({n})"
    taken.add(unique)
    return unique


def _file_name(project_name: str) -> str:
    """A file name safe in any file system and header: the project name's letters,
    digits, dots, dashes and underscores, other runs as one dash."""
    safe = re.sub(r"[^A-Za-z0-9._-]+", "-", project_name).strip(".-")[:100]
    return safe or "project"
