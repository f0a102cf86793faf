"""The GLB container (glTF 2.0 binary): writing buffer views and accessors.

A GLB file is a 12-byte header, a JSON chunk (the glTF document) and one BIN chunk (the
buffer), each chunk padded to 4 bytes (glTF 2.0 spec, "GLB File Format Specification").
`GlbBuilder` appends arrays to the BIN chunk as buffer views, each at a 4-byte aligned
offset so that every accessor is aligned to its component size, and declares accessors
on them; `glb_bytes` joins the document and the buffer. Reading glTF is
`retarget.gltf.document.GltfDocument`'s.
"""

from __future__ import annotations

import json
import struct

import numpy as np

from retarget.errors import RetargetError

GLB_MAGIC = b"glTF"
JSON_CHUNK = 0x4E4F534A
BIN_CHUNK = 0x004E4942
ARRAY_BUFFER = 34962  # bufferView.target of vertex attributes
ELEMENT_ARRAY_BUFFER = 34963  # bufferView.target of triangle indices

COMPONENT_TYPES = {
    5120: np.dtype("<i1"),
    5121: np.dtype("<u1"),
    5122: np.dtype("<i2"),
    5123: np.dtype("<u2"),
    5125: np.dtype("<u4"),
    5126: np.dtype("<f4"),
}
_COMPONENT_CODES = {dtype: code for code, dtype in COMPONENT_TYPES.items()}
_TYPES_BY_SIZE = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
_MAX_GLB_BYTES = 2**32 - 1  # the header's uint32 length


class GlbBuilder:
    """A glTF document under construction with its binary buffer.

    `document` is the glTF JSON as a dict; callers add nodes, meshes, skins, animations
    to it and use `view` and `accessor` for the binary data.
    """

    def __init__(self, generator: str):
        self.document: dict = {
            "asset": {"version": "2.0", "generator": generator},
            "buffers": [{"byteLength": 0}],
            "bufferViews": [],
            "accessors": [],
        }
        self._parts: list[memoryview] = []
        self._length = 0

    def view(self, data, target: int | None = None) -> int:
        """Append raw bytes (or an array's little-endian bytes) as a buffer view at a
        4-byte aligned offset; returns the view's index. An array is not copied: it must
        not change until the file is written."""
        # arrays are kept as views of their own memory: no copy until the file is written
        raw = (memoryview(np.ascontiguousarray(data)).cast("B") if isinstance(data, np.ndarray)
               else memoryview(bytes(data)))
        self._pad()
        view = {"buffer": 0, "byteOffset": self._length, "byteLength": len(raw)}
        if target is not None:
            view["target"] = target
        self._parts.append(raw)
        self._length += len(raw)
        self.document["bufferViews"].append(view)
        return len(self.document["bufferViews"]) - 1

    def accessor(self, array: np.ndarray, *, target: int | None = None,
                 bounds=False, view: int | None = None, offset: int = 0) -> int:
        """Declare an accessor on `array`, (count,) or (count, k) with k in 2, 3, 4, 16
        (MAT4 as 16 column-major values), of a dtype in `COMPONENT_TYPES`.

        view : an existing buffer view the array already lies in at byte `offset`;
            None appends the array as a view of its own (with `target`).
        bounds : write ``min`` and ``max`` (required for POSITION and animation inputs):
            True computes them from the stored values so they match to the last bit; a
            (min, max) pair of lists is written as given (a caller that knows them).
        """
        array = np.ascontiguousarray(array, dtype=array.dtype.newbyteorder("<"))
        if view is None:
            view = self.view(array, target)
        accessor = {
            "bufferView": view,
            "componentType": _component_code(array.dtype),
            "count": len(array),
            "type": _TYPES_BY_SIZE[1 if array.ndim == 1 else array.shape[1]],
        }
        if offset:
            accessor["byteOffset"] = offset
        if bounds is True:
            accessor["min"], accessor["max"] = _bounds(array)
        elif bounds:
            accessor["min"], accessor["max"] = bounds
        return self._add(accessor)

    def sparse_accessor(self, count: int, indices: np.ndarray, values: np.ndarray,
                        *, indices_view: int | None = None, bounds=False) -> int:
        """A (count, k) float32 accessor that is zero except at `indices` (ascending,
        (n,) uint16 or uint32, n may be 0) where it holds `values` (n, k) float32; no
        base view.

        indices_view : a view already holding these indices (targets of the same rows
            share it); None appends them.
        bounds : as for `accessor`.
        """
        k = 1 if values.ndim == 1 else values.shape[1]
        accessor = {
            "componentType": _component_code(np.dtype("<f4")),
            "count": int(count),
            "type": _TYPES_BY_SIZE[k],
        }
        if len(indices):  # glTF has no empty sparse set: no rows is an all-zero accessor
            if indices_view is None:
                indices_view = self.view(indices)
            accessor["sparse"] = {
                "count": len(indices),
                "indices": {"bufferView": indices_view,
                            "componentType": _component_code(indices.dtype)},
                "values": {"bufferView": self.view(values.astype("<f4"))},
            }
        if bounds is True:
            stored = values.astype("<f4").reshape(len(values), k)
            if len(indices) < count:  # the zeros between the sparse rows count too
                stored = np.vstack([stored, np.zeros((1, k), np.float32)])
            accessor["min"], accessor["max"] = _bounds(stored)
        elif bounds:
            accessor["min"], accessor["max"] = bounds
        return self._add(accessor)

    @property
    def n_bytes(self) -> int:
        """Bytes in the binary buffer so far."""
        return self._length

    def glb_bytes(self) -> bytes:
        """The GLB file: header, JSON chunk, BIN chunk."""
        return b"".join(self._glb_parts())

    def write(self, file) -> int:
        """Write the GLB file to a binary file object piece by piece (no copy of the
        whole file in memory); returns the number of bytes written."""
        return sum(file.write(part) for part in self._glb_parts())

    def _glb_parts(self) -> list:
        self._pad()
        self.document["buffers"][0]["byteLength"] = self._length
        text = json.dumps(self.document, separators=(",", ":"), allow_nan=False).encode()
        text += b" " * (-len(text) % 4)
        total = 12 + 8 + len(text) + 8 + self._length
        if total > _MAX_GLB_BYTES:
            raise RetargetError(f"the glTF would be {total} bytes long, above the GLB "
                                f"format's limit of {_MAX_GLB_BYTES} bytes")
        return [
            struct.pack("<4sII", GLB_MAGIC, 2, total),
            struct.pack("<II", len(text), JSON_CHUNK), text,
            struct.pack("<II", self._length, BIN_CHUNK), *self._parts,
        ]

    def _pad(self) -> None:
        if self._length % 4:
            pad = 4 - self._length % 4
            self._parts.append(memoryview(b"\0" * pad))
            self._length += pad

    def _add(self, accessor: dict) -> int:
        self.document["accessors"].append(accessor)
        return len(self.document["accessors"]) - 1


def _component_code(dtype: np.dtype) -> int:
    try:
        return _COMPONENT_CODES[np.dtype(dtype).newbyteorder("<")]
    except KeyError:
        raise RetargetError(f"no glTF component type for dtype {dtype}") from None


def _bounds(array: np.ndarray) -> tuple[list, list]:
    """Per-component min and max as JSON numbers (exact for float32 and integers)."""
    # column-major: a reduction down each column is then contiguous, several times
    # faster than down the columns of a (V, 3) row-major array
    values = np.asfortranarray(array.reshape(len(array), -1))
    cast = float if values.dtype.kind == "f" else int
    return ([cast(x) for x in values.min(0)], [cast(x) for x in values.max(0)])


def glb_document(file) -> dict:
    """The glTF document (JSON chunk) of a GLB this module wrote, read from a binary file
    object at its start without reading the buffer (what an export records, afterwards)."""
    magic, _, _ = struct.unpack("<4sII", file.read(12))
    length, kind = struct.unpack("<II", file.read(8))
    if magic != GLB_MAGIC or kind != JSON_CHUNK:
        raise RetargetError("not a GLB with a JSON chunk first")
    return json.loads(file.read(length))
