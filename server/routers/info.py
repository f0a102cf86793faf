"""What this server accepts, so the browser can check an upload before sending it and
offer the rig methods the library has."""

from __future__ import annotations

from fastapi import APIRouter

from retarget import __version__
from retarget.weights import DEFAULT_METHOD, METHODS
from server.deps import LimitsDep
from server.routers.meshes import MAX_SIDE_FILES, SIDE_EXTENSIONS
from server.store import MESH_EXTENSIONS
from server.errors import responses

router = APIRouter(prefix="/api/info", tags=["info"], responses=responses())


@router.get("")
def get_info(limits: LimitsDep) -> dict:
    """``{version, max_upload_bytes, max_vertices, mesh_extensions, mesh_side_extensions,
    max_mesh_side_files, rig_methods, default_rig_method}``: side files are those a mesh
    may bring along (an OBJ's MTL and images, a glTF's buffers), up to twice the upload
    limit with the mesh."""
    return {
        "version": __version__,
        "max_upload_bytes": limits.max_upload_bytes,
        "max_vertices": limits.max_vertices,
        "mesh_extensions": list(MESH_EXTENSIONS),
        "mesh_side_extensions": list(SIDE_EXTENSIONS),
        "max_mesh_side_files": MAX_SIDE_FILES,
        "rig_methods": list(METHODS),
        "default_rig_method": DEFAULT_METHOD,
    }
