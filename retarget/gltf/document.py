"""Reading glTF 2.0 documents: the JSON, the buffers and typed accessor data.

`GltfDocument` reads accessor data. Every read is bounds-checked against the buffers it
comes from, and an accessor may not make more than `MAX_ACCESSOR_ELEMENTS` values out of
nothing (a sparse accessor without a buffer view), so a hostile file cannot make the
reader allocate beyond its own size. External buffers are read only from the file's own
folder.

`scene_size` reads no accessor data: from the JSON and the buffers' lengths alone it
checks every buffer, bufferView and accessor, the meshes' primitives and the default
scene's node tree, and says how many vertices and triangles the scene instances, so that
a caller can refuse a file before a reader (trimesh's, in `retarget.mesh`) unpacks it.
"""

from __future__ import annotations

import base64
import binascii
import json
import math
import warnings
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from retarget.errors import RetargetError

__all__ = [
    "GltfDocument",
    "MAX_ACCESSOR_ELEMENTS",
    "MAX_NODE_DEPTH",
    "MAX_SCENE_NODES",
    "SceneSize",
    "scene_size",
]

MAX_ACCESSOR_ELEMENTS = 1 << 26
"""Most values an accessor without a buffer view may declare."""

MAX_NODE_DEPTH = 128
"""Most levels of a scene's node tree (a root node is level 1) that `scene_size` accepts.
Character rigs are a few tens of levels deep; trimesh's scene graph work grows with depth
times instances (a 1,000-level chain with a mesh at each node takes 8 s to load)."""

MAX_SCENE_NODES = 10_000
"""Most nodes a scene may reach that `scene_size` accepts: a face rig has hundreds, and
each node costs trimesh's reader far more than its few bytes of JSON (a flat scene of
20,000 nodes placing one small mesh takes 2 s to load)."""

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
        from retarget.gltf.decode import gltf_from_glb, gltf_from_json

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
                doc = gltf_from_glb(data) if binary else gltf_from_json(_utf8(data, label))
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


@dataclass(frozen=True)
class SceneSize:
    """What a glTF's default scene asks a reader to make, from its JSON alone.

    scene : index of the default scene, or None when the file has no scenes.
    n_vertices, n_triangles : of every instance of a triangle primitive (TRIANGLES or
        TRIANGLE_STRIP) that the scene's nodes place: a mesh placed by k nodes counts
        k times. Points, lines and fans count nothing.
    mesh_nodes : {mesh index: how many of the scene's nodes place it}.
    mesh_vertices : {mesh index: vertices of its triangle primitives, one instance}.
    buffer_bytes : bytes of all the buffers.
    array_bytes : bytes of the arrays made by reading every bufferView and every accessor
        (trimesh's reader copies each bufferView and reads every accessor, also those
        no mesh uses; an accessor without a bufferView is read as zeros).
    view_bytes : the bufferViews' part of `array_bytes`.
    largest_accessor : (index, bytes, has a bufferView) of the largest accessor, or None.
    """

    scene: int | None
    n_vertices: int
    n_triangles: int
    mesh_nodes: dict
    mesh_vertices: dict
    buffer_bytes: int
    array_bytes: int
    view_bytes: int
    largest_accessor: tuple | None


def scene_size(data: bytes, where: str, external=None) -> SceneSize | None:
    """Check a glTF/GLB's layout against its buffers and size its default scene.

    Parameters
    ----------
    data : the .gltf or .glb file's bytes (told apart by the GLB magic ``glTF``).
    where : prefixes every message, e.g. "could not read 'face.glb' as GLB".
    external : callable(uri) -> int, the byte length of an external buffer file, or
        None when there is no folder to read from (an upload): such buffers are refused.

    Returns
    -------
    SceneSize, or None when `data` is no glTF 2.0 document at all (shorter than a GLB
    header, JSON that is no object, an ``asset`` that is no object or a version other
    than 2): a reader's own error names that.

    Raises
    ------
    RetargetError
        Naming the part and the byte range at fault: JSON that is not UTF-8 or does not
        parse; a GLB of another version, without a JSON chunk or with a truncated chunk;
        an external buffer without `external`, a malformed data URI, a buffer shorter
        than its byteLength, a bufferView past its buffer, an accessor past its
        bufferView (or of unknown type); a mesh primitive without POSITION or with
        attributes or indices of the wrong type or count; a reference to a part that
        does not exist; a scene node reached twice (a cycle or two parents), deeper than
        `MAX_NODE_DEPTH`, or more than `MAX_SCENE_NODES` nodes; a non-finite transform.
    """
    parsed = _json_and_binary(data, where)
    if parsed is None:
        return None
    header, binary_length = parsed
    check = _Checker(header, where)
    lengths = check.buffers(data[:4] == b"glTF", binary_length, external)
    views = check.buffer_views(lengths)
    accessors, array_bytes, largest = check.accessors(views)
    check.images(len(views))
    meshes = check.meshes(accessors)
    scene, mesh_nodes = check.scene(len(meshes))
    return SceneSize(
        scene=scene,
        n_vertices=sum(k * meshes[m][0] for m, k in mesh_nodes.items()),
        n_triangles=sum(k * meshes[m][1] for m, k in mesh_nodes.items()),
        mesh_nodes=dict(mesh_nodes),
        mesh_vertices={m: meshes[m][0] for m in mesh_nodes},
        buffer_bytes=sum(lengths),
        array_bytes=array_bytes + sum(view[1] for view in views),
        view_bytes=sum(view[1] for view in views),
        largest_accessor=largest,
    )


def _json_and_binary(data: bytes, where: str):
    """(JSON object, byte length of the GLB binary chunk or None), or None when `data`
    is no glTF 2.0."""
    binary_length = None
    if data[:4] == b"glTF":
        if len(data) < 20:
            return None
        version = int.from_bytes(data[4:8], "little")
        if version != 2:
            raise RetargetError(f"{where}: it is a version {version} GLB; only glTF 2 is read")
        if data[16:20] != b"JSON":
            raise RetargetError(f"{where}: its first GLB chunk is not JSON: the file is corrupt")
        length = int.from_bytes(data[12:16], "little")
        if 20 + length > len(data):
            raise RetargetError(f"{where}: GLB JSON chunk says {length:,} bytes but "
                                f"{len(data) - 20:,} follow: the file is truncated")
        text, at = data[20:20 + length], 20 + length
        while at + 8 <= len(data) and binary_length is None:  # the first BIN chunk, as trimesh
            size = int.from_bytes(data[at:at + 4], "little")
            is_binary = data[at + 4:at + 8] == b"BIN\0"
            if at + 8 + size > len(data):
                raise RetargetError(f"{where}: GLB {'binary' if is_binary else 'a'} chunk says "
                                    f"{size:,} bytes but {len(data) - at - 8:,} follow: the "
                                    "file is truncated")
            if is_binary:
                binary_length = size
            at += 8 + size
    else:
        text = data
    try:
        header = json.loads(text.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise RetargetError(f"{where}: its glTF JSON is not UTF-8 text "
                            f"(byte {exc.start})") from None
    except json.JSONDecodeError as exc:
        raise RetargetError(f"{where}: its glTF JSON is malformed: {exc.msg} at line "
                            f"{exc.lineno}, column {exc.colno}") from None
    except RecursionError:
        raise RetargetError(f"{where}: its glTF JSON is nested too deeply") from None
    if not isinstance(header, dict) or not isinstance(header.get("asset", {}), dict):
        return None
    try:
        major = int(str(header.get("asset", {}).get("version", "2.0")).split(".")[0])
    except ValueError:
        return None
    return (header, binary_length) if major == 2 else None


class _Checker:
    """The checks of `scene_size`, one method per part of the glTF JSON `header`."""

    def __init__(self, header: dict, where: str):
        self.header = header
        self.where = where

    def refuse(self, problem: str):
        raise RetargetError(f"{self.where}: {problem}")

    def items(self, key: str) -> list:
        value = self.header.get(key, [])
        if not isinstance(value, list):
            self.refuse(f"glTF '{key}' must be a list, got {_shown(value)}")
        for i, item in enumerate(value):
            if not isinstance(item, dict):
                self.refuse(f"glTF {key[:-1]} {i} must be an object, got {_shown(item)}")
        return value

    def index(self, value, count: int, refers: str, noun: str) -> int:
        """`value` as an index into `count` items; `refers` is e.g. "glTF node 3 refers to"."""
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < count:
            self.refuse(f"{refers} {noun} {_shown(value)}, which does not exist")
        return value

    def whole(self, item: dict, key: str, subject: str, low: int, high: int | None = None,
              default: int | None = None) -> int:
        """``item[key]`` as an integer in [low, high]; `default` when it is absent (and
        None: it is required)."""
        if key not in item and default is None:
            self.refuse(f"{subject} has no {key}")
        value = item.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < low \
                or (high is not None and value > high):
            bound = f"from {low} to {high}" if high is not None else f"of at least {low}"
            self.refuse(f"{subject} has {key} {_shown(value)}; it must be a whole number {bound}")
        return value

    def buffers(self, glb: bool, binary_length, external) -> list[int]:
        """The byte length of each buffer."""
        lengths, binary_buffer = [], None
        for i, buffer in enumerate(self.items("buffers")):
            uri = buffer.get("uri")
            if "uri" not in buffer:
                if not glb:
                    self.refuse(f"glTF buffer {i} has no uri; a .gltf must embed its buffers "
                                "as base64 data: URIs (or upload a .glb)")
                if binary_length is None:
                    self.refuse(f"glTF buffer {i} has no uri but the GLB has no binary chunk: "
                                "the file is truncated or corrupt")
                if binary_buffer is not None:
                    self.refuse(f"glTF buffer {i} has no uri, but the GLB's one binary chunk "
                                f"is buffer {binary_buffer}'s")
                length, binary_buffer = binary_length, i
            elif not isinstance(uri, str):
                self.refuse(f"glTF buffer {i} has uri {_shown(uri)}, which is not a string")
            elif "base64," in uri:  # trimesh decodes what follows, data: or not
                try:
                    length = len(base64.b64decode(uri[uri.find("base64,") + 7:]))
                except (binascii.Error, ValueError) as exc:
                    self.refuse(f"glTF buffer {i} has a malformed base64 data URI ({exc})")
            elif uri.startswith("data:"):
                self.refuse(f"glTF buffer {i} has a data URI that is not base64")
            elif external is None:
                self.refuse(f"glTF buffer {i} refers to the external file {_shown_text(uri)}; "
                            "upload a .glb or a .gltf with embedded (data: URI) buffers")
            else:
                try:
                    length = external(uri)
                except Exception as exc:
                    self.refuse(f"glTF buffer {i} refers to the file {_shown_text(uri)}, which "
                                f"could not be read ({type(exc).__name__}: {exc})")
            if "byteLength" in buffer:  # required, but unused by trimesh
                declared = self.whole(buffer, "byteLength", f"glTF buffer {i}", 0)
                if declared > length:
                    self.refuse(f"glTF buffer {i} declares {declared:,} bytes but holds "
                                f"{length:,}: the file is truncated or corrupt")
            lengths.append(length)
        return lengths

    def buffer_views(self, lengths: list[int]) -> list[tuple]:
        """(byteOffset, byteLength, byteStride or None) of each bufferView, each within
        its buffer."""
        views = []
        for v, view in enumerate(self.items("bufferViews")):
            subject = f"glTF bufferView {v}"
            b = self.index(view.get("buffer"), len(lengths), f"{subject} refers to", "buffer")
            offset = self.whole(view, "byteOffset", subject, 0, default=0)
            length = self.whole(view, "byteLength", subject, 0)
            stride = self.whole(view, "byteStride", subject, 4, 252) \
                if "byteStride" in view else None
            if offset + length > lengths[b]:
                self.refuse(f"{subject} spans bytes {offset:,}..{offset + length:,} of buffer "
                            f"{b}, which holds {lengths[b]:,} bytes")
            views.append((offset, length, stride))
        return views

    def accessors(self, views: list[tuple]):
        """([(type, componentType, count)] per accessor, bytes of all their values,
        the largest accessor); each accessor within its bufferView."""
        accessors, total, largest = [], 0, None
        for a, accessor in enumerate(self.items("accessors")):
            subject = f"glTF accessor {a}"
            component = accessor.get("componentType")
            if isinstance(component, bool) or not isinstance(component, int) \
                    or component not in _COMPONENTS:
                self.refuse(f"{subject} has componentType {_shown(component)}, not one of "
                            + ", ".join(map(str, _COMPONENTS)))
            kind = accessor.get("type")
            if not isinstance(kind, str) or kind not in _WIDTHS:
                self.refuse(f"{subject} has type {_shown(kind)}, not one of " + ", ".join(_WIDTHS))
            count = self.whole(accessor, "count", subject, 1)
            element = np.dtype(_COMPONENTS[component]).itemsize * _WIDTHS[kind]
            nbytes = count * element
            total += nbytes
            if largest is None or nbytes > largest[1]:
                largest = (a, nbytes, "bufferView" in accessor)
            if "bufferView" in accessor:
                v = self.index(accessor["bufferView"], len(views), f"{subject} refers to",
                               "bufferView")
                offset = self.whole(accessor, "byteOffset", subject, 0, default=0)
                _, length, stride = views[v]
                if stride is not None and stride < element:
                    self.refuse(f"glTF bufferView {v} has byteStride {stride}, less than "
                                f"accessor {a}'s {element}-byte values")
                end = offset + (count - 1) * (stride or element) + element
                if end > length:
                    self.refuse(f"{subject} ({count:,} {kind} values of {element} bytes, from "
                                f"byte {offset:,} of bufferView {v}) needs bytes "
                                f"{offset:,}..{end:,} of the bufferView, which is "
                                f"{length:,} bytes long")
            accessors.append((kind, component, count))
        return accessors, total, largest

    def images(self, n_views: int):
        """Images stored in a bufferView (trimesh reads them with the materials)."""
        for i, image in enumerate(self.items("images")):
            if "bufferView" in image:
                self.index(image["bufferView"], n_views, f"glTF image {i} refers to", "bufferView")

    def meshes(self, accessors: list[tuple]) -> list[tuple]:
        """(vertices, triangles) of one instance of each mesh's triangle primitives."""
        n_materials = len(self.items("materials"))
        sizes = []
        for m, mesh in enumerate(self.items("meshes")):
            primitives = mesh.get("primitives")
            if not isinstance(primitives, list):
                self.refuse(f"glTF mesh {m} has no primitives list")
            n_vertices = n_triangles = 0
            for p, primitive in enumerate(primitives):
                vertices, triangles = self.primitive(f"glTF mesh {m} primitive {p}", primitive,
                                                     accessors, n_materials)
                n_vertices += vertices
                n_triangles += triangles
            sizes.append((n_vertices, n_triangles))
        return sizes

    def primitive(self, subject, primitive, accessors, n_materials) -> tuple[int, int]:
        """(vertices, triangles) that a reader makes of one primitive."""
        if not isinstance(primitive, dict) or not isinstance(primitive.get("attributes"), dict):
            self.refuse(f"{subject} has no attributes object")
        attributes = primitive["attributes"]
        for name, value in attributes.items():
            self.index(value, len(accessors), f"{subject}: its {name} attribute refers to",
                       "accessor")
        mode = self.whole(primitive, "mode", subject, 0, 6, default=4)
        if "material" in primitive:
            self.index(primitive["material"], n_materials, f"{subject} refers to", "material")
        if mode not in (0, 1, 4, 5):  # LINE_LOOP, LINE_STRIP, TRIANGLE_FAN: trimesh skips
            return 0, 0
        if "POSITION" not in attributes:
            self.refuse(f"{subject} has no POSITION attribute")
        n = accessors[attributes["POSITION"]][2]
        for name, kind in (("POSITION", "VEC3"), ("NORMAL", "VEC3"), ("TEXCOORD_0", "VEC2")):
            if name in attributes:
                a = attributes[name]
                if accessors[a][0] != kind:
                    self.refuse(f"{subject}: {name} (accessor {a}) must be {kind}, "
                                f"got {accessors[a][0]}")
                if accessors[a][2] != n:
                    self.refuse(f"{subject}: {name} (accessor {a}) has {accessors[a][2]:,} "
                                f"values but POSITION has {n:,}")
        if mode in (0, 1):
            return 0, 0
        k = n
        if "indices" in primitive:
            i = self.index(primitive["indices"], len(accessors),
                           f"{subject}: its indices refer to", "accessor")
            kind, component, k = accessors[i]
            if kind != "SCALAR" or component not in (5121, 5123, 5125):
                self.refuse(f"{subject}: its indices (accessor {i}) must be unsigned integer "
                            f"SCALARs, got {kind} of componentType {component}")
            if mode == 4 and k % 3:
                self.refuse(f"{subject}: its indices (accessor {i}) hold {k:,} values, not a "
                            "multiple of 3")
        elif mode == 4 and n % 3:
            self.refuse(f"{subject} has no indices and {n:,} POSITION values, not a multiple of 3")
        return n, (k // 3 if mode == 4 else max(k - 2, 0))

    def scene(self, n_meshes: int):
        """(default scene index or None, Counter {mesh index: nodes placing it})."""
        scenes = self.items("scenes")
        nodes = self.items("nodes")
        if not scenes:
            return None, Counter()
        s = self.header.get("scene", 0)
        if isinstance(s, bool) or not isinstance(s, int) or not 0 <= s < len(scenes):
            self.refuse(f"glTF scene {_shown(s)} does not exist (the file has "
                        f"{len(scenes)} scene{'s' if len(scenes) != 1 else ''})")
        roots = scenes[s].get("nodes", [])
        if not isinstance(roots, list):
            self.refuse(f"glTF scene {s}: nodes must be a list, got {_shown(roots)}")
        for r in roots:
            self.index(r, len(nodes), f"glTF scene {s} refers to", "node")
        placed, seen = Counter(), set()
        stack = [(r, 1) for r in reversed(roots)]
        while stack:
            n, depth = stack.pop()
            if n in seen:
                self.refuse(f"glTF node {n} is reached twice from scene {s}'s roots (a cycle, "
                            "or a node with two parents); glTF nodes must form trees")
            seen.add(n)
            if len(seen) > MAX_SCENE_NODES:
                self.refuse(f"glTF scene {s} places more than {MAX_SCENE_NODES:,} nodes, the "
                            "most that are read")
            if depth > MAX_NODE_DEPTH:
                self.refuse(f"glTF node {n} is {depth} levels deep; at most {MAX_NODE_DEPTH} "
                            "are read")
            node = nodes[n]
            self.transform(n, node)
            if "mesh" in node:
                placed[self.index(node["mesh"], n_meshes, f"glTF node {n} refers to", "mesh")] += 1
            children = node.get("children", [])
            if not isinstance(children, list):
                self.refuse(f"glTF node {n}: children must be a list, got {_shown(children)}")
            for c in reversed(children):
                stack.append((self.index(c, len(nodes), f"glTF node {n} refers to child", "node"),
                              depth + 1))
        return s, placed

    def transform(self, n: int, node: dict):
        for key, size in (("matrix", 16), ("translation", 3), ("rotation", 4), ("scale", 3)):
            if key not in node:
                continue
            value = node[key]
            if not isinstance(value, list) or len(value) != size or any(
                    isinstance(x, bool) or not isinstance(x, (int, float)) for x in value):
                self.refuse(f"glTF node {n}: {key} must be {size} numbers, got {_shown(value)}")
            if not all(_finite(x) for x in value):
                shown = "[" + ", ".join(_number(x) for x in value) + "]"
                self.refuse(f"glTF node {n} has a non-finite {key} {_cut(shown)}")


def _finite(x) -> bool:
    try:
        return math.isfinite(x)
    except OverflowError:  # an integer too large for a float
        return False


def _number(x) -> str:
    try:
        return f"{x:g}"
    except OverflowError:
        return "inf"


def _cut(text: str, limit: int = 80) -> str:
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _shown(value) -> str:
    """`value` as JSON text, cut to 80 characters."""
    try:
        return _cut(json.dumps(value))
    except (TypeError, ValueError):
        return _cut(repr(value))


def _shown_text(text: str) -> str:
    """A string quoted as Python does in messages ('mesh.bin'), cut to 80 characters."""
    return repr(_cut(text))
