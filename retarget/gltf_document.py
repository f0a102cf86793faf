"""Reading glTF 2.0 documents: the JSON, the buffers and typed accessor data.

Every read is bounds-checked against the buffers it comes from, and an accessor may not
make more than `MAX_ACCESSOR_ELEMENTS` values out of nothing (a sparse accessor without a
buffer view), so a hostile file cannot make the reader allocate beyond its own size.
External buffers are read only from the file's own folder.
"""

from __future__ import annotations

import base64
import json
import warnings
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from retarget.errors import RetargetError

__all__ = ["GltfDocument", "MAX_ACCESSOR_ELEMENTS"]

MAX_ACCESSOR_ELEMENTS = 1 << 26
"""Most values an accessor without a buffer view may declare."""

_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16,
               5125: np.uint32, 5126: np.float32}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


class GltfDocument:
    """A parsed glTF 2.0 document (GLB or JSON) with bounds-checked accessor reads.

    data : the file's bytes; label : how messages name it; folder : where a .gltf's
    external buffers may be read from (None for an upload: only embedded data then).
    `doc` is the `pygltflib.GLTF2`, `buffers` the bytes of each buffer and
    `node_weights` the nodes' default morph weights (which pygltflib drops).
    """

    def __init__(self, data: bytes, label: str, folder):
        import pygltflib

        self.label = label
        binary = data[:4] == b"glTF"
        declared = int.from_bytes(data[8:12], "little") if binary else 0
        if binary and declared > len(data):
            raise RetargetError(f"{label} is truncated: the header says {declared} bytes, "
                                f"the file has {len(data)}")
        if binary and (len(data) < 20 or int.from_bytes(data[4:8], "little") != 2
                       or data[16:20] != b"JSON"):
            raise RetargetError(f"could not read {label} as glTF: not a version 2 GLB with a JSON chunk")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # pygltflib warns on odd chunks; errors come below
                doc = pygltflib.GLTF2.load_from_bytes(data) if binary \
                    else pygltflib.GLTF2.from_json(_utf8(data, label))
        except RetargetError:
            raise
        except Exception as exc:
            raise RetargetError(f"could not read {label} as glTF: {type(exc).__name__}: {exc}") from None
        if doc is None:
            raise RetargetError(f"could not read {label} as glTF")
        self.doc = doc
        self.buffers = [self._buffer(i, b, folder) for i, b in enumerate(self.doc.buffers or [])]
        self.node_weights = _node_weights(data, label)

    def _buffer(self, index, buffer, folder) -> bytes:
        uri = buffer.uri
        if uri is None:
            blob = self.doc.binary_blob()
            if blob is None:
                raise RetargetError(f"{self.label}: buffer {index} has no data (no GLB binary chunk)")
            return blob
        if uri.startswith("data:"):
            try:
                return base64.b64decode(uri.split(",", 1)[1], validate=True)
            except (IndexError, ValueError):
                raise RetargetError(f"{self.label}: buffer {index} has a malformed data URI") from None
        name = unquote(uri)
        if folder is None:
            raise RetargetError(
                f"{self.label}: buffer {index} is the external file {name!r}, which cannot be "
                "read from an upload; export a .glb or embed the buffers")
        path = (folder / name).resolve()
        if path.parent != Path(folder).resolve():
            raise RetargetError(f"{self.label}: buffer {index} names {name!r}, outside the file's folder")
        try:
            return path.read_bytes()
        except OSError as exc:
            raise RetargetError(f"{self.label}: buffer {index}: could not read {name!r}: {exc}") from None

    def item(self, items, index, what):
        """`items[index]`, or a RetargetError naming `what` when it does not exist."""
        if items is None or isinstance(index, bool) or not isinstance(index, int) \
                or not 0 <= index < len(items):
            raise RetargetError(f"{self.label}: {what} {index!r} does not exist")
        return items[index]

    def accessor(self, index: int) -> np.ndarray:
        """(count, width) float64 values of an accessor (normalised integers scaled to
        [0, 1] or [-1, 1]; sparse substitutions applied)."""
        acc = self.item(self.doc.accessors, index, "accessor")
        dtype = _COMPONENTS.get(acc.componentType)
        width = _WIDTHS.get(acc.type)
        count = acc.count
        if dtype is None or width is None or not isinstance(count, int) or count < 0:
            raise RetargetError(f"{self.label}: accessor {index} has an unknown type or count")
        if acc.bufferView is None:
            if count * width > MAX_ACCESSOR_ELEMENTS:
                raise RetargetError(f"{self.label}: accessor {index} declares {count} elements")
            values = np.zeros((count, width))
        else:
            values = self._view_array(acc.bufferView, acc.byteOffset or 0, count, dtype, width,
                                      f"accessor {index}").astype(np.float64)
        if acc.sparse is not None and acc.sparse.count:
            sparse = acc.sparse
            idx_type = _COMPONENTS.get(sparse.indices.componentType)
            if idx_type is None:
                raise RetargetError(f"{self.label}: accessor {index} has sparse indices of unknown type")
            rows = self._view_array(sparse.indices.bufferView, sparse.indices.byteOffset or 0,
                                    sparse.count, idx_type, 1, f"accessor {index} sparse indices")[:, 0]
            if (rows >= count).any():
                raise RetargetError(f"{self.label}: accessor {index} has sparse indices past its count")
            values[rows.astype(np.int64)] = self._view_array(
                sparse.values.bufferView, sparse.values.byteOffset or 0, sparse.count, dtype,
                width, f"accessor {index} sparse values")
        if acc.normalized and dtype is not np.float32:
            info = np.iinfo(dtype)
            values = np.maximum(values / info.max, -1.0)
        return values

    def _view_array(self, view_index, offset, count, dtype, width, what) -> np.ndarray:
        view = self.item(self.doc.bufferViews, view_index, f"{what}: bufferView")
        data = self.item(self.buffers, view.buffer, f"{what}: buffer")
        item = np.dtype(dtype).itemsize
        element = item * width
        stride = view.byteStride or element
        start = (view.byteOffset or 0) + offset
        end_view = (view.byteOffset or 0) + view.byteLength
        end = start + stride * (count - 1) + element if count else start
        if stride < element or end > end_view or end_view > len(data):
            raise RetargetError(f"{self.label}: {what} reads past the end of its buffer")
        if count == 0:
            return np.zeros((0, width), dtype)
        return np.ndarray((count, width), np.dtype(dtype).newbyteorder("<"), data, start,
                          (stride, item)).copy()


def _node_weights(data: bytes, label: str) -> dict[int, list]:
    """{node: default morph weights} read from the glTF JSON (pygltflib's Node drops them)."""
    if data[:4] == b"glTF":
        length = int.from_bytes(data[12:16], "little")
        data = data[20:20 + length]
    try:
        nodes = json.loads(data.decode("utf-8-sig")).get("nodes") or []
    except (UnicodeDecodeError, json.JSONDecodeError, AttributeError):
        raise RetargetError(f"could not read {label} as glTF: its JSON is malformed") from None
    return {n: node["weights"] for n, node in enumerate(nodes)
            if isinstance(node, dict) and isinstance(node.get("weights"), list)}



def _utf8(data: bytes, label: str) -> str:
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise RetargetError(f"{label} is not UTF-8 text (byte {exc.start})") from None
