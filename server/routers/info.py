"""What this server accepts, so the browser can check an upload before sending it and
offer the rig methods the library has."""

from __future__ import annotations

from fastapi import APIRouter

from retarget import __version__
from retarget.weights import DEFAULT_METHOD, METHODS
from server.deps import LimitsDep
from server.store import MESH_EXTENSIONS
from server.errors import responses

router = APIRouter(prefix="/api/info", tags=["info"], responses=responses())


@router.get("")
def get_info(limits: LimitsDep) -> dict:
    """``{version, max_upload_bytes, max_vertices, mesh_extensions, rig_methods, default_rig_method}``."""
    return {
        "version": __version__,
        "max_upload_bytes": limits.max_upload_bytes,
        "max_vertices": limits.max_vertices,
        "mesh_extensions": list(MESH_EXTENSIONS),
        "rig_methods": list(METHODS),
        "default_rig_method": DEFAULT_METHOD,
    }
