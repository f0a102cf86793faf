"""The project's mesh: upload, download the original, and compact arrays for the browser
(``GET .../mesh/arrays``: `server.wire`'s RTMA format)."""

from __future__ import annotations

import os

from fastapi import APIRouter, File, HTTPException, Response, UploadFile, status
from fastapi.responses import FileResponse

from retarget.errors import RetargetError
from server.deps import IsolationDep, LimitsDep, MeshDep, ProjectDep, StoreDep
from server.errors import responses
from server.limits import body_limit
from server.readers import mesh_counts
from server.store import MESH_EXTENSIONS
from server.wire import mesh_arrays

router = APIRouter(prefix="/api/projects/{project_id}/mesh", tags=["meshes"],
                   responses=responses(404))


MEDIA_TYPES = {
    "obj": "model/obj",
    "ply": "application/octet-stream",
    "stl": "model/stl",
    "off": "application/octet-stream",
    "glb": "model/gltf-binary",
    "gltf": "model/gltf+json",
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


@router.put("", responses=responses(404, 415, 503))
@body_limit(files=1)
def put_mesh(project: ProjectDep, store: StoreDep, limits: LimitsDep, isolation: IsolationDep,
             file: UploadFile = File(description="obj, ply, stl, off, glb or gltf (embedded buffers)")) -> dict:
    """Upload the project's mesh. It is parsed by `retarget.mesh.load_mesh` (in a child
    process, `server.isolation`) and stored (its bytes unchanged) only if valid; the
    landmarks and rig of a previous mesh are dropped. Answers the project."""
    ext = upload_extension(file.filename)
    data = read_capped(file, limits.max_upload_bytes)
    if not data:
        raise RetargetError(f"the uploaded file {file.filename!r} is empty")
    n_vertices, n_faces = isolation.call(
        mesh_counts, data, ext, file.filename, limits.max_vertices, limits.max_upload_bytes,
        what=f"uploaded mesh {file.filename!r} refused: not a readable {ext.upper()} file")
    return store.put_mesh(project["id"], data, ext, filename=file.filename or "",
                          n_vertices=n_vertices, n_faces=n_faces)


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
    """Vertices and faces as `server.wire`'s RTMA bytes."""
    return Response(mesh_arrays(mesh.vertices, mesh.faces), media_type="application/octet-stream")
