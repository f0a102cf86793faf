"""The project's mesh: upload, download the original, and compact arrays for the browser
(``GET .../mesh/arrays``: `server.wire`'s RTMA format).

The mesh's unit: an upload guesses it from the mesh's size (`retarget.units.guess_units`) and
stores it in the project's settings as ``mesh_units`` ("m", "cm", "mm" or "in"), with the
guess as ``mesh_units_guess`` (``{"unit", "size"}``); the user changes it with ``PATCH
/api/projects/{id}`` ``{"settings": {"mesh_units": "mm"}}`` (checked there: another value
is 422 with the reason), and the glTF export scales from it to metres
(`server.routers.exports`)."""

from __future__ import annotations

import io
import os
import zipfile

from fastapi import APIRouter, File, HTTPException, Response, UploadFile, status
from fastapi.responses import FileResponse

from retarget.errors import RetargetError
from server.deps import IsolationDep, LimitsDep, MeshDep, ProjectDep, StoreDep
from server.errors import responses
from server.limits import body_limit
from server.readers import mesh_counts
from server.store import MESH_EXTENSIONS
from server.wire import mesh_arrays

MESH_UNITS_KEY, MESH_UNITS_GUESS_KEY = "mesh_units", "mesh_units_guess"

router = APIRouter(prefix="/api/projects/{project_id}/mesh", tags=["meshes"],
                   responses=responses(404))


MEDIA_TYPES = {
    "obj": "model/obj",
    "ply": "application/octet-stream",
    "stl": "model/stl",
    "off": "application/octet-stream",
    "glb": "model/gltf-binary",
    "gltf": "model/gltf+json",
    "zip": "application/zip",
}
_CHUNK = 1 << 20


def upload_extension(filename: str | None, allowed=MESH_EXTENSIONS) -> str:
    """The allow-listed, lower-case extension of an uploaded file name (which is used
    for nothing else); 415 when there is none or it is not in `allowed`."""
    base = (filename or "").replace("\\", "/").rsplit("/", 1)[-1]
    ext = os.path.splitext(base)[1].lower().lstrip(".")
    if ext not in allowed:
        shown = f"'.{ext}'" if ext else "no extension"
        raise HTTPException(
            status.HTTP_415_UNSUPPORTED_MEDIA_TYPE,
            f"file name {filename!r} has {shown}; upload one of: "
            + ", ".join(f".{e}" for e in allowed),
        )
    return ext


def read_capped(upload: UploadFile, max_bytes: int) -> bytes:
    """The upload's bytes; 413 as soon as it is over `max_bytes`."""
    chunks, size = [], 0
    while chunk := upload.file.read(_CHUNK):
        size += len(chunk)
        if size > max_bytes:
            raise HTTPException(
                413,
                f"the uploaded file is over the limit of {max_bytes} bytes "
                f"({max_bytes / 2**20:.3g} MiB)",
            )
        chunks.append(chunk)
    return b"".join(chunks)


SIDE_EXTENSIONS = ("mtl", "png", "jpg", "jpeg", "bin")
"""Files a mesh may bring along: an OBJ's MTL and texture images, a glTF's buffers."""
MAX_SIDE_FILES = 16


@router.put("", responses=responses(404, 415, 503))
@body_limit(files=3)
def put_mesh(project: ProjectDep, store: StoreDep, limits: LimitsDep, isolation: IsolationDep,
             file: UploadFile = File(description="obj, ply, stl, off, glb, gltf, or a zip of one "
                                     "of them with the files it refers to"),
             files: list[UploadFile] | None = File(
                 default=None, description="the files the mesh refers to: an OBJ's .mtl and "
                 "texture images (.png, .jpg), a glTF's .bin buffers and images")) -> dict:
    """Upload the project's mesh, with the files it refers to (or a zip of them all). It is
    parsed by `retarget.mesh.load_mesh` (in a child process, `server.isolation`) and stored
    only if valid: its bytes unchanged, or, with side files, one zip of them all (names
    kept for matching only; they never reach the filesystem). The landmarks and rig of a
    previous mesh are dropped. Answers the project."""
    ext = upload_extension(file.filename)
    data = read_capped(file, limits.max_upload_bytes)
    if not data:
        raise RetargetError(f"the uploaded file {file.filename!r} is empty")
    if files:
        if ext == "zip":
            raise RetargetError("a zip already holds the mesh's files: upload it alone")
        data, ext = _zipped(file.filename, data, files, limits), "zip"
    unpacked = 2 * limits.max_upload_bytes if ext == "zip" else limits.max_upload_bytes
    n_vertices, n_faces, guess = isolation.call(
        mesh_counts, data, ext, file.filename, limits.max_vertices, unpacked,
        what=f"uploaded mesh {file.filename!r} refused: not a readable {ext.upper()} file")
    store.put_mesh(project["id"], data, ext, filename=file.filename or "",
                   n_vertices=n_vertices, n_faces=n_faces)
    return store.update(project["id"], settings=units_settings(guess["unit"], guess))


def units_settings(unit: str, guess: dict | None = None) -> dict:
    """The project settings that record the mesh's unit (`MESH_UNITS_KEY`: the unit the
    export scales from, one of `retarget.units.UNITS`) and the guess made at upload
    (`MESH_UNITS_GUESS_KEY`: ``{"unit", "size"}``, None when the unit came otherwise)."""
    return {MESH_UNITS_KEY: unit, MESH_UNITS_GUESS_KEY: guess}


def _zipped(name: str | None, data: bytes, files: list[UploadFile], limits) -> bytes:
    """One stored (uncompressed) zip of the mesh and its side files; 415 for a side file
    that is not one of `SIDE_EXTENSIONS`, 413 over the upload limit in all."""
    if len(files) > MAX_SIDE_FILES:
        raise RetargetError(f"{len(files)} side files; a mesh may bring at most {MAX_SIDE_FILES}")
    members = {_base(name) or "mesh": data}
    total = len(data)
    for side in files:
        upload_extension(side.filename, SIDE_EXTENSIONS)
        content = read_capped(side, limits.max_upload_bytes)
        total += len(content)
        if total > 2 * limits.max_upload_bytes:
            raise HTTPException(413, f"the mesh and its files are over the limit of "
                                     f"{2 * limits.max_upload_bytes} bytes in all")
        members[_base(side.filename)] = content
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as archive:
        for member, content in members.items():
            archive.writestr(member, content)
    return out.getvalue()


def _base(filename: str | None) -> str:
    return (filename or "").replace("\\", "/").rsplit("/", 1)[-1]


@router.get("/texture", response_class=Response,
            responses={200: {"content": {"image/png": {}}}, **responses(404, 409)})
def get_mesh_texture(project: ProjectDep, mesh: MeshDep) -> Response:
    """The mesh's base-colour texture as PNG (sampled with its uv); 404 when it has none."""
    material = mesh.material
    if material is None or material.base_color_texture is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            f"the mesh of project {project['id']!r} has no texture")
    return Response(material.base_color_texture, media_type="image/png")


@router.get("", response_class=FileResponse)
def get_mesh_file(project: ProjectDep, store: StoreDep):
    """The mesh exactly as uploaded."""
    found = store.mesh_file(project["id"])
    if found is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            f"project {project['id']!r} has no mesh yet")
    path, ext = found
    return FileResponse(path, media_type=MEDIA_TYPES[ext], filename=f"mesh.{ext}")


@router.get("/arrays", response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}}}, **responses(404, 409)})
def get_mesh_arrays(mesh: MeshDep) -> Response:
    """Vertices, faces and uv as `server.wire`'s RTMA bytes, flagged when the mesh has a
    texture (GET .../mesh/texture)."""
    textured = mesh.material is not None and mesh.material.base_color_texture is not None
    return Response(mesh_arrays(mesh.vertices, mesh.faces, mesh.uv, textured=textured),
                    media_type="application/octet-stream")
