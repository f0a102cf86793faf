"""MediaPipe's canonical face model: the 468 face-mesh points on a neutral face, in cm.

Read from ``geometry_pipeline_metadata_landmarks.binarypb`` (shipped in
``retarget/facemesh/models/``, see `retarget.facemesh.assets`), a protocol-buffer
``FaceGeometry`` metadata message whose field 1 is the canonical ``Mesh3d``: its vertex
buffer (field 3) holds x, y, z, u, v per vertex and its index buffer (field 4) the
triangles. The few lines of wire-format reading here spare a protobuf dependency.

Axes as MediaPipe's canonical model and the ICT face model have them: +y up, +z out of
the face, +x toward the subject's left; the model is symmetric about x = 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from retarget.errors import RetargetError
from retarget.facemesh.assets import model_bytes

__all__ = ["BROWS", "FACE_OVAL", "CanonicalFace", "canonical_face"]

FACE_OVAL = (10, 338, 297, 332, 284, 251, 389, 356, 454, 323, 361, 288, 397, 365, 379, 378, 400,
             377, 152, 148, 176, 149, 150, 136, 172, 58, 132, 93, 234, 127, 162, 21, 54, 103, 67, 109)
"""The face-mesh vertices on the face's outline (MediaPipe's FACEMESH_FACE_OVAL ring)."""

BROWS = (46, 53, 52, 65, 55, 70, 63, 105, 66, 107, 276, 283, 282, 295, 285, 300, 293, 334, 296, 336)
"""The face-mesh vertices on the eyebrows (MediaPipe's FACEMESH_LEFT_EYEBROW and
FACEMESH_RIGHT_EYEBROW rings)."""

_FILE = "geometry_pipeline_metadata_landmarks.binarypb"
_MESH, _VERTICES, _INDICES = 1, 3, 4
_PER_VERTEX = 5  # x, y, z, u, v


@dataclass(frozen=True, eq=False)
class CanonicalFace:
    """vertices (468, 3) float64 cm; uv (468, 2) float64; triangles (T, 3) int64."""

    vertices: np.ndarray
    uv: np.ndarray
    triangles: np.ndarray


@lru_cache(maxsize=1)
def canonical_face() -> CanonicalFace:
    """The canonical face model (read once)."""
    mesh = [value for number, value in _fields(model_bytes(_FILE)) if number == _MESH]
    if len(mesh) != 1 or not isinstance(mesh[0], bytes):
        raise RetargetError(f"{_FILE} holds no canonical mesh")
    floats, indices = [], []
    for number, value in _fields(mesh[0]):
        if number == _VERTICES:
            floats.append(np.frombuffer(value, "<f4") if isinstance(value, bytes) else value)
        elif number == _INDICES:
            indices.extend(_packed_varints(value) if isinstance(value, bytes) else [value])
    buffer = np.concatenate([np.atleast_1d(np.asarray(f, dtype=np.float64)) for f in floats])
    if buffer.size % _PER_VERTEX or len(indices) % 3:
        raise RetargetError(f"{_FILE}: a vertex buffer of {buffer.size} values or {len(indices)} indices")
    table = buffer.reshape(-1, _PER_VERTEX)
    return CanonicalFace(table[:, :3].copy(), table[:, 3:].copy(), np.asarray(indices, dtype=np.int64).reshape(-1, 3))


def _varint(data: bytes, at: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[at]
        at += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, at


def _fields(data: bytes):
    """(field number, value) of a message: an int (varint), a float (32-bit) or bytes."""
    at = 0
    while at < len(data):
        key, at = _varint(data, at)
        number, wire = key >> 3, key & 7
        if wire == 0:
            value, at = _varint(data, at)
        elif wire == 2:
            size, at = _varint(data, at)
            value, at = data[at:at + size], at + size
        elif wire == 5:
            value, at = float(np.frombuffer(data[at:at + 4], "<f4")[0]), at + 4
        elif wire == 1:
            value, at = float(np.frombuffer(data[at:at + 8], "<f8")[0]), at + 8
        else:
            raise RetargetError(f"{_FILE}: unknown protobuf wire type {wire}")
        yield number, value


def _packed_varints(data: bytes) -> list[int]:
    out, at = [], 0
    while at < len(data):
        value, at = _varint(data, at)
        out.append(value)
    return out
