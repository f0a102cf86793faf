"""Triangle meshes: the `Mesh` container, and loading, validating and saving it.

A mesh enters the library through `load_mesh` (a file, read by trimesh) or
`mesh_from_arrays` (arrays already in memory). Both run the same checks, so code that
receives a `Mesh` may trust it: finite (V, 3) float64 vertices within `MAX_COORDINATE`,
(F, 3) int64 triangles that index them, at least one of non-zero area, optional
per-vertex uv and normals, every array read-only.

`load_mesh` refuses bad input at the door: before trimesh parses a file, the counts its
header or JSON declares are checked against the caps and the bytes that follow (a glTF's
buffers, bufferViews, accessors and node tree, see `retarget.gltf.document.scene_size`),
and text that is not UTF-8 is decoded here. Whatever else goes wrong while reading
leaves as a `RetargetError`.

Vertex count and order are exactly the file's, because landmark vertex indices refer to
them: trimesh loads with ``process=False`` (no merging of duplicate vertices, no removal
of unreferenced ones) and ``maintain_order=True`` (no splitting at UV seams). Units are
kept as they came: nothing is rescaled or centred. `load_mesh` documents what each
format does on the way in, `save_mesh` what it does on the way out.
"""

from __future__ import annotations

import codecs
import io
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from trimesh.visual.material import SimpleMaterial

from retarget.errors import RetargetError
from retarget.gltf.document import scene_size
from retarget.material import Material, material_from_mtl, material_from_trimesh
from retarget.zips import check_members, opened_zip, unpacked

__all__ = [
    "DEFAULT_MAX_FACES",
    "DEFAULT_MAX_VERTICES",
    "MAX_COORDINATE",
    "SUPPORTED_FORMATS",
    "Mesh",
    "load_mesh",
    "mesh_from_arrays",
    "save_mesh",
]

DEFAULT_MAX_VERTICES = 1_000_000
DEFAULT_MAX_FACES = 2_000_000
SUPPORTED_FORMATS = ("obj", "ply", "stl", "off", "gltf", "glb", "zip")
MESH_FILES = ("obj", "ply", "stl", "off", "gltf", "glb")
"""The mesh formats a zip may hold (one file of them, with the files it refers to)."""
MAX_ZIP_MEMBERS = 64
"""Most files a zipped mesh may hold: the mesh, an MTL and its images, glTF buffers."""

MAX_COORDINATE = 1e9
"""Largest |x|, |y| or |z| a vertex may have, in the mesh's own units. A face is about
0.2 m, 200 mm or 2e5 µm across, so no real unit comes near; beyond it squared distances
(1e18) are spaced hundreds apart in float64, so the RBF and skinning maths, which square
distances, lose every sub-unit detail, and a little further they overflow."""

# A triangle has zero area when twice its area (|cross product of two edges|) is at most
# this times the squared diagonal of the box around the vertices the faces use: far above
# float64 rounding for collinear points (~1e-16), far below any real triangle.
_ZERO_AREA = 1e-12

# STL binary layout: an 80-byte header, a uint32 triangle count, then 50 bytes per
# triangle (normal and 3 vertices as 12 float32, a uint16 attribute).
_STL_HEADER, _STL_TRIANGLE = 84, 50

# PLY scalar types and their sizes in bytes (binary PLY); a list property's count type.
_PLY_SIZES = {
    "char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2,
    "uint16": 2, "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4,
    "double": 8, "float64": 8,
}

# glTF: the arrays trimesh makes from a file's bufferViews and accessors may be at most
# this many times its buffers' bytes, plus the slack (for accessors without a bufferView,
# which are zeros until sparse data or an extension fills them). Well-formed files stay
# under twice their buffers (each bufferView is copied once, each accessor read once).
_GLTF_EXPANSION, _GLTF_EXPANSION_SLACK = 4, 64 << 20

# OBJ material lines: trimesh starts a new geometry at every `usemtl`, each holding all
# the file's vertices, and follows `mtllib` to side files. Geometry alone is wanted.
_OBJ_MATERIAL_LINE = re.compile(r"^[ \t]*(?:usemtl|mtllib)\b[^\n]*", re.MULTILINE)

# Bytes that end an OBJ face word's index: space, tab, "/", CR, LF.
_OBJ_SEPARATOR = np.zeros(256, dtype=bool)
_OBJ_SEPARATOR[list(b" \t/\r\n")] = True


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh; build it with `load_mesh` or `mesh_from_arrays`, which validate.

    Frozen: fields cannot be reassigned and the arrays are read-only, so a mesh can be
    shared between fits and threads.

    Attributes
    ----------
    vertices : (V, 3) float64
        Positions, in the units of the source (never rescaled). Read-only.
    faces : (F, 3) int64
        Triangles as indices into `vertices`, each in ``[0, V)``. Read-only.
    uv : (V, 2) float64 or None
        Texture coordinates, one per vertex, when the source had them. Read-only.
    normals : (V, 3) float64 or None
        Vertex normals, when the source had them (never computed here), as the source
        gave them; a glTF node transform rotates and renormalises them. Read-only.
    name : str
        The file stem for a path or a named file object, else what the caller gave.
    material : Material or None
        The surface material of a glTF/GLB source (`retarget.material`), or what the
        caller gave; None for the other formats, whose materials are not read.
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None = None
    normals: np.ndarray | None = None
    name: str = ""
    material: Material | None = None

    @property
    def n_vertices(self) -> int:
        """V, the number of vertices."""
        return len(self.vertices)

    @property
    def n_faces(self) -> int:
        """F, the number of triangles."""
        return len(self.faces)


def load_mesh(
    source,
    file_type: str | None = None,
    *,
    files: Mapping[str, bytes] | None = None,
    max_vertices: int = DEFAULT_MAX_VERTICES,
    max_faces: int = DEFAULT_MAX_FACES,
    max_bytes: int | None = None,
) -> Mesh:
    """Read a triangle mesh from a file, keeping the file's vertex count and order.

    Parameters
    ----------
    source : str, os.PathLike, bytes or binary file object
        The mesh file, its contents, or an open binary file positioned at its start.
    file_type : str or None
        One of `SUPPORTED_FORMATS` (case and a leading dot ignored). Required for bytes
        and file objects; for a path it overrides the suffix. ``zip``: a zip holding one
        mesh file and the files it refers to (an OBJ with its MTL and images, say).
    files : {name: bytes} or None
        The files the mesh refers to, for bytes and file objects: an OBJ's MTL and its
        texture images, a glTF's buffers and images. Looked up by base name (folders
        stripped), in any case. A path's files are read from beside it instead.
    max_vertices, max_faces : int
        Refuse meshes with more vertices or faces than this: before parsing, from what
        the file declares (see Notes), and again after.
    max_bytes : int or None
        Refuse sources longer than this many bytes, before parsing. For a ``.gltf``
        path it bounds the JSON file, not the buffers it references; for a zip, the
        bytes it unpacks to as well.

    Returns
    -------
    Mesh
        Validated as by `mesh_from_arrays`; `name` is the file stem ("" for bytes).

    Raises
    ------
    RetargetError
        For an unknown file type, an unreadable or oversized source, a file that holds
        no triangles, each check of the Notes, and every check of `mesh_from_arrays`.
        Any other exception while reading (trimesh's on a malformed file, running out
        of memory, recursion, overflow; anything but KeyboardInterrupt and SystemExit)
        is re-raised as ``could not read ... as OBJ: ...``.

    Notes
    -----
    Checked before trimesh parses, per format:

    * OBJ: decoded as UTF-8 here (a byte-order mark is dropped, other bytes that are
      not UTF-8 become U+FFFD), ``v`` and ``f`` lines counted against the caps, and a
      face index 0 refused with its line number (indices start at 1; negative ones
      count back from the last vertex).
    * STL: binary when the file is 84 + 50 F bytes for the F its header states;
      otherwise ASCII if it starts with ``solid``, holds no NUL byte and has ``facet``
      lines (decoded as for OBJ); otherwise refused, naming the F the header states and
      the size that implies. Triangles and vertices are counted before parsing.
    * PLY: the header's vertex and face counts against the caps, and the bytes its
      elements need at least against the bytes after it; the header decoded as for OBJ.
      A header that does not parse is left to trimesh.
    * OFF: decoded as for OBJ; the counts line against the caps.
    * glTF, GLB: `retarget.gltf.document.scene_size` checks every buffer, bufferView
      and accessor against the bytes it refers to, the meshes' primitives, and the
      default scene's node tree (no cycles or shared nodes, at most
      `~retarget.gltf.document.MAX_NODE_DEPTH` levels and
      `~retarget.gltf.document.MAX_SCENE_NODES` nodes, finite transforms), and counts
      the vertices and triangles the scene instances, refused over the caps; and
      the arrays trimesh would make from the bufferViews and accessors may be at most
      4 times the buffers plus 64 MiB. Buffers must be embedded (GLB binary chunk or
      base64 data: URI) unless `source` is a path: then files beside it are read too.
      A GLB given as ``gltf``, or JSON given as ``glb``, is read as what it is.

    What trimesh does per format, with ``process=False, maintain_order=True``:

    * OBJ: polygons are triangulated, the vertex count unchanged. `usemtl` and `mtllib`
      lines are hidden from trimesh (it would split the faces into one geometry per
      material, each holding every vertex); the material is read here instead, from the
      MTL file among `files` or beside the path (`retarget.material.material_from_mtl`:
      the first material used, its colour and ``map_Kd`` texture). Vertices are not split at
      UV seams: a vertex used with several ``vt`` keeps one of them (the median index
      trimesh sees), so texture is approximate on faces across a seam; ``vn`` likewise.
      When faces carry ``vt`` or ``vn`` indices, trimesh drops vertices after the last
      one a face uses; as that changes the vertex count such files are refused. `uv`
      and `normals` are None when some vertex has none (trimesh drops them). Relative
      (negative) indices resolve only in faces without ``vt`` or ``vn`` indices.
    * STL stores each triangle on its own: F faces load as 3F vertices, face ``i``
      being ``[3i, 3i + 1, 3i + 2]``; nothing is merged and there are no normals (the
      rig welds the corners at one position: `retarget.welding`).
    * PLY, OFF: polygons are triangulated; trimesh groups faces by polygon size, so
      with mixed triangles and quads the face order (not the vertex order) differs
      from the file.
    * glTF, GLB: a scene. Every triangle-mesh instance in it (each primitive of each
      node with a mesh; a mesh used by two nodes counts twice) gets its node's world
      transform (normals by the inverse transpose, triangles reversed under a mirror)
      and the instances are concatenated in the order trimesh's loader walks the node
      tree: depth first, the scene's root nodes last to first, so for a flat scene the
      reverse of the file's node list. The order is fixed for a given file. Points,
      lines and triangle fans are ignored. trimesh flips glTF's v so that `uv` has OBJ's
      convention. The material of the first instance is kept
      (`retarget.material.material_from_trimesh`).
    """
    data, suffix, label, name, resolver = _source_bytes(source, max_bytes)
    kind = _file_type(file_type if file_type is not None else suffix, label)
    if files is not None:
        resolver = _Files(files)
    try:
        if kind == "zip":
            data, kind, resolver = _zipped(data, label, max_bytes)
        with np.errstate(all="ignore"):  # overflow in a transform: refused below
            return _loaded(data, kind, label, name, resolver, max_vertices, max_faces)
    except RetargetError:
        raise
    except Exception as exc:  # not KeyboardInterrupt or SystemExit
        raise RetargetError(
            f"could not read {label} as {kind.upper()}: {_reason(exc)}"
        ) from exc


def mesh_from_arrays(
    vertices,
    faces,
    *,
    uv=None,
    normals=None,
    name: str = "",
    material: Material | None = None,
    max_vertices: int = DEFAULT_MAX_VERTICES,
    max_faces: int = DEFAULT_MAX_FACES,
) -> Mesh:
    """Validate arrays and build a `Mesh` from copies (the checks of `load_mesh`).

    Parameters
    ----------
    vertices : (V, 3) array_like of float
        Positions, any units; stored as float64.
    faces : (F, 3) array_like of int
        Triangles as indices into `vertices`; stored as int64.
    uv : (V, 2) array_like of float or None
        Per-vertex texture coordinates.
    normals : (V, 3) array_like of float or None
        Per-vertex normals, stored as given (not renormalised).
    name : str
        Carried on the mesh.
    material : Material or None
        Carried on the mesh.
    max_vertices, max_faces : int
        Refuse meshes with more vertices or faces than this.

    Raises
    ------
    RetargetError
        If a shape or dtype is wrong, the mesh is empty or above a cap, a coordinate
        is NaN or infinite or beyond `MAX_COORDINATE`, a face index is negative or past
        the last vertex, or the mesh is degenerate: fewer than 3 vertices, all of them
        at one point, or every triangle of zero area (to ``1e-12`` of the squared
        diagonal of the box around the vertices the faces use). Some zero-area
        triangles among others are kept: scans have slivers.
    """
    return _validated(
        vertices, faces, uv, normals, name, max_vertices, max_faces, where="mesh",
        material=material,
    )


def save_mesh(mesh: Mesh, path) -> None:
    """Write `mesh` through trimesh, in the format named by the suffix of `path`.

    Vertex order is kept. `uv` and `normals` are written where the format holds them
    (OBJ, PLY, glTF, GLB; STL and OFF hold neither). An OBJ with uv gets a sidecar
    ``<stem>.mtl`` holding a plain material; a ``.gltf`` embeds its buffers. PLY, STL,
    glTF and GLB store float32 coordinates, OBJ and OFF about 8 decimals, so a round
    trip matches to that precision. STL stores each triangle on its own (see
    `load_mesh`).

    Parameters
    ----------
    mesh : Mesh
    path : str or os.PathLike
        Destination; its suffix must be one of `MESH_FILES`.

    Raises
    ------
    RetargetError
        If the suffix is not a supported format.
    """
    path = Path(path)
    kind = _file_type(path.suffix, repr(str(path)))
    if kind not in MESH_FILES:
        raise RetargetError(f"save_mesh writes one of {', '.join(MESH_FILES)}; got {path.suffix!r}")
    # a plain material: trimesh's default one is an image, which needs Pillow
    visual = None
    if mesh.uv is not None:
        visual = trimesh.visual.TextureVisuals(uv=mesh.uv, material=SimpleMaterial())
    exported = trimesh.Trimesh(
        vertices=mesh.vertices,
        faces=mesh.faces,
        vertex_normals=mesh.normals,
        visual=visual,
        process=False,
    )
    options = {"obj": {"mtl_name": f"{path.stem}.mtl"}, "gltf": {"embed_buffers": True}}
    exported.export(path, file_type=kind, **options.get(kind, {}))


def _source_bytes(source, max_bytes: int | None):
    """Read `source` whole: (data, suffix, label for messages, name, resolver)."""
    suffix, name, resolver = None, "", None
    if isinstance(source, (bytes, bytearray, memoryview)):
        data, label = bytes(source), "the given bytes"
        size = len(data)
    elif isinstance(source, (str, os.PathLike)):
        path = Path(source)
        label, suffix, name = repr(str(path)), path.suffix, path.stem
        resolver = trimesh.resolvers.FilePathResolver(str(path))
        try:
            size = path.stat().st_size
            # a file over the limit is refused below without being read
            data = path.read_bytes() if max_bytes is None or size <= max_bytes else b""
        except OSError as exc:
            raise RetargetError(f"could not read {label}: {exc}") from exc
    elif hasattr(source, "read"):
        file_name = getattr(source, "name", None)
        label = "the given file object"
        if isinstance(file_name, str):
            label, name = f"file {file_name!r}", Path(file_name).stem
        # one byte past the limit tells that the file is over it
        data = source.read() if max_bytes is None else source.read(max_bytes + 1)
        if not isinstance(data, bytes):
            raise RetargetError(
                f"{label} must be opened in binary mode: "
                f"read() gave {type(data).__name__}"
            )
        if max_bytes is not None and len(data) > max_bytes:
            raise RetargetError(f"{label} is over max_bytes={max_bytes} bytes long")
        size = len(data)
    else:
        raise RetargetError(
            "source must be a path, bytes or a binary file object, "
            f"got {type(source).__name__}"
        )
    if max_bytes is not None and size > max_bytes:
        raise RetargetError(
            f"{label} is {size} bytes long, above max_bytes={max_bytes}"
        )
    return data, suffix, label, name, resolver


def _file_type(file_type: str | None, label: str) -> str:
    """`file_type` lower-cased without its dot, if it is in `SUPPORTED_FORMATS`."""
    supported = ", ".join(SUPPORTED_FORMATS)
    if not file_type:
        raise RetargetError(
            f"cannot tell the file type of {label}: name one of {supported} "
            "as file_type or as the path's suffix"
        )
    kind = file_type.lower().lstrip(".")
    if kind not in SUPPORTED_FORMATS:
        raise RetargetError(
            f"unsupported file type {file_type!r}; supported: {supported}"
        )
    return kind


def _loaded(data, kind, label, name, resolver, max_vertices, max_faces) -> Mesh:
    """The body of `load_mesh`: the door checks of its Notes, trimesh, `_validated`."""
    n_obj_vertices, read_as, original = None, kind, data
    if kind == "obj":
        data, n_obj_vertices = _obj_checked(data, label, max_vertices, max_faces)
    elif kind == "stl":
        data = _stl_checked(data, label, max_vertices, max_faces)
    elif kind == "ply":
        data = _ply_checked(data, label, max_vertices, max_faces)
    elif kind == "off":
        data = _off_checked(data, label, max_vertices, max_faces)
    else:
        data, read_as = _gltf_checked(data, kind, label, resolver, max_vertices, max_faces)
    scene = trimesh.load_scene(
        io.BytesIO(data),
        file_type=read_as,
        resolver=resolver,
        process=False,
        maintain_order=True,
    )
    parts = []
    for node in scene.graph.nodes_geometry:
        transform, geometry = scene.graph[node]
        if isinstance(scene.geometry[geometry], trimesh.Trimesh):
            parts.append((scene.geometry[geometry], transform))
    if not parts:
        found = sorted({type(g).__name__ for g in scene.geometry.values()})
        raise RetargetError(
            f"{label} holds no triangle mesh as {kind.upper()}"
            + (f" (found {', '.join(found)})" if found else " (nothing was read)")
        )
    vertices, faces, uv, normals = _concatenated(parts)
    if n_obj_vertices is not None and len(vertices) != n_obj_vertices:
        raise RetargetError(
            f"{label} declares {n_obj_vertices} vertices but its faces, which carry "
            f"vt or vn indices, use only the first {len(vertices)}; trimesh drops the "
            f"{n_obj_vertices - len(vertices)} unused ones at the end, which would "
            "change the vertex count: remove them from the file"
        )
    material = None
    if kind in ("gltf", "glb"):
        material = material_from_trimesh(parts[0][0].visual)
    elif kind == "obj" and resolver is not None:
        material = material_from_mtl(_text(original), lambda name: _side_file(resolver, name))
    return _validated(
        vertices, faces, uv, normals, name, max_vertices, max_faces, where=label,
        material=material,
    )


def _reason(exc: BaseException) -> str:
    """Why reading failed, for a message: a sentence where one says it better."""
    if isinstance(exc, MemoryError):
        return "it needs more memory than this process may use"
    if isinstance(exc, RecursionError):
        return "it is nested too deeply to read"
    if isinstance(exc, OverflowError):
        return f"a number in it is too large ({exc})"
    return f"{type(exc).__name__}: {exc}"


def _refuse_over_caps(label, n_vertices, n_faces, max_vertices, max_faces, why=""):
    """Refuse `n_vertices` or `n_faces` over the caps; `why` ends the message."""
    if n_vertices > max_vertices:
        raise RetargetError(
            f"{label} has {n_vertices:,} vertices, above max_vertices={max_vertices}{why}"
        )
    if n_faces > max_faces:
        raise RetargetError(
            f"{label} has {n_faces:,} faces, above max_faces={max_faces}{why}"
        )


def _text(data: bytes) -> str:
    """`data` decoded as UTF-8 without a byte-order mark; other bytes become U+FFFD
    (trimesh would guess their encoding with charset_normalizer)."""
    return data.decode("utf-8", errors="replace").removeprefix("\ufeff")


def _obj_checked(data, label, max_vertices, max_faces):
    """(UTF-8 bytes for trimesh without material lines, number of ``v`` lines)."""
    text = _text(data)
    if "usemtl" in text or "mtllib" in text:  # the expression costs more than the test
        text = _OBJ_MATERIAL_LINE.sub("", text)  # keeps the line breaks
    # trimesh parses `v` lines exactly so, on "\n" + text with "\r\n" folded
    folded = "\n" + text.replace("\r\n", "\n")
    n_vertices = folded.count("\nv ")
    _refuse_over_caps(label, n_vertices, folded.count("\nf "), max_vertices, max_faces)
    data = text.encode("utf-8")
    zero = _obj_zero_index(data)
    if zero is not None:
        line_start = data.rfind(b"\n", 0, zero) + 1
        word_start = max(data.rfind(b" ", 0, zero), data.rfind(b"\t", 0, zero)) + 1
        word = data[word_start:zero] + re.match(rb"\S*", data[zero:zero + 100])[0]
        line = data.count(b"\n", 0, line_start) + 1
        raise RetargetError(
            f"{label}: line {line}: face index 0 "
            f"({word.decode()!r}); OBJ vertex indices start at 1 (negative ones count "
            "back from the last vertex)"
        )
    return data, n_vertices


def _obj_zero_index(data: bytes) -> int | None:
    """Offset in OBJ `data` of the first face index 0 (``0``, ``-0``, ``00``, as a
    vertex, texture or normal index of an ``f`` line), or None.

    Vectorised over 16 MiB runs of whole lines: a regular expression took 2 s on a
    46 MB file, longer than trimesh's parse of it."""
    chunk = 1 << 24
    start = 0
    while start < len(data):
        end = data.find(b"\n", start + chunk)
        end = len(data) if end < 0 else end + 1
        found = _obj_zero_index_in(data, start, end)
        if found is not None:
            return found
        start = end
    return None


def _obj_zero_index_in(data: bytes, start: int, end: int) -> int | None:
    """`_obj_zero_index` for ``data[start:end]``, whole lines; an offset into `data`."""
    b = np.frombuffer(data, dtype=np.uint8, count=end - start, offset=start)
    zero = b == ord("0")
    # the last "0" of a run followed by a separator or the end: a number ending in 0
    last = np.flatnonzero(zero & np.append(_OBJ_SEPARATOR[b[1:]], True))
    if not len(last):
        return None
    runs = np.flatnonzero(zero & np.insert(~zero[:-1], 0, True))  # first "0" of runs
    first = runs[np.searchsorted(runs, last, side="right") - 1]
    first -= np.isin(b[np.maximum(first - 1, 0)], list(b"+-")) & (first > 0)  # a sign
    # the number is all zeros if a space, tab or "/" precedes it
    first = first[(first > 0) & np.isin(b[np.maximum(first - 1, 0)], list(b" \t/"))]
    if not len(first):
        return None
    newlines = np.flatnonzero(b == ord("\n"))
    lines = np.append(0, newlines + 1)[np.searchsorted(newlines, first)]
    face = (b[lines] == ord("f")) & np.isin(b[lines + 1], list(b" \t"))
    indented = np.isin(b[lines], list(b" \t"))  # rare: checked one by one
    for offset, line in zip(first[face | indented].tolist(), lines[face | indented].tolist()):
        head = bytes(b[line:offset])
        if re.match(rb"[ \t]*f[ \t][^#]*\Z", head):  # an f line, not in a comment
            return start + offset
    return None


def _stl_checked(data, label, max_vertices, max_faces) -> bytes:
    """`data` for trimesh's STL reader, binary or ASCII told apart here (see Notes)."""
    if not data:
        return data  # trimesh reads nothing: refused as holding no triangle mesh
    where = f"could not read {label} as STL"
    count = None
    if len(data) >= _STL_HEADER:
        count = int.from_bytes(data[80:84], "little")
        if len(data) == _STL_HEADER + _STL_TRIANGLE * count:
            _refuse_over_caps(label, 3 * count, count, max_vertices, max_faces)
            return data
    if data[:1024].lstrip()[:5].lower() == b"solid" and b"\0" not in data:
        text = _text(data)
        lower = text.lower()
        if "facet" not in lower:
            raise RetargetError(
                f"{where}: it starts like an ASCII STL ('solid') but holds no 'facet'"
            )
        n_vertices = lower.count("vertex")  # trimesh reads what follows each
        _refuse_over_caps(label, n_vertices, n_vertices // 3, max_vertices, max_faces)
        return text.encode("utf-8")
    if count is None:
        raise RetargetError(
            f"{where}: it is {len(data):,} bytes long, shorter than the 84-byte header "
            "of a binary STL, and not an ASCII STL (text that starts with 'solid')"
        )
    raise RetargetError(
        f"{where}: binary STL header says {count:,} triangles "
        f"({_STL_HEADER + _STL_TRIANGLE * count:,} bytes) but the file is "
        f"{len(data):,} bytes: truncated or not an STL"
    )


def _ply_checked(data, label, max_vertices, max_faces) -> bytes:
    """`data` for trimesh with its header as UTF-8 (its comments may be in another
    encoding), after refusing a header that declares more vertices or faces than the
    caps, or elements that need more bytes than follow it. A header that does not parse
    is left to trimesh, whose error is wrapped."""
    end = data.find(b"end_header", 0, 1 << 20)
    newline = data.find(b"\n", end) if end >= 0 else -1
    if not data.startswith(b"ply") or newline < 0:
        return data
    data = _text(data[:newline + 1]).encode("utf-8") + data[newline + 1:]
    end = data.find(b"end_header")
    newline = data.find(b"\n", end)
    body = len(data) - newline - 1
    ascii_format, elements = None, []  # [name, count, binary row bytes, properties]
    for line in data[:end].decode("latin-1").splitlines()[1:]:
        words = line.split()
        if words[:1] == ["format"] and len(words) >= 2:
            ascii_format = "ascii" in words[1]
        elif words[:1] == ["element"] and len(words) == 3:
            if not words[2].isdigit():
                return data
            elements.append([words[1], int(words[2]), 0, 0])
        elif words[:1] == ["property"] and elements:
            if len(words) not in (3, 5):
                return data
            size = _PLY_SIZES.get(words[2] if len(words) == 5 else words[1])
            if size is None:
                return data
            elements[-1][2] += size  # a list: its count; the list itself may be empty
            elements[-1][3] += 1
    if ascii_format is None:
        return data
    counts = {name: count for name, count, _, _ in elements}
    for noun, count, cap in (("vertices", counts.get("vertex", 0), max_vertices),
                             ("faces", counts.get("face", 0), max_faces)):
        if count > cap:
            raise RetargetError(
                f"{label}: PLY header declares {count:,} {noun}, above "
                f"max_{noun}={cap}"
            )
    need = 0
    for name, count, row, n_properties in elements:
        # an ASCII value takes a digit and a separator at least
        need += count * (2 * n_properties if ascii_format else row)
        if need > body + 1:  # + 1: the last value may lack its line break
            noun = {"vertex": "vertices", "face": "faces"}.get(name, f"{name!r} elements")
            raise RetargetError(
                f"{label}: PLY header declares {count:,} {noun}, which need at least "
                f"{need:,} bytes, but {body:,} bytes follow the header: truncated, or "
                "the header is wrong"
            )
    return data


def _off_checked(data, label, max_vertices, max_faces) -> bytes:
    """UTF-8 `data` for trimesh, after its counts line is checked against the caps (an
    unreadable counts line is left to trimesh)."""
    text = _text(data)
    header = re.search(r"C?OFF", re.sub(r"#[^\n]*", "", text[:1 << 16]))
    if header:
        rest = header.string[header.end():].split("\n")
        words = next((line.split() for line in rest if line.strip()), [])
        if len(words) >= 2 and words[0].isdigit() and words[1].isdigit():
            for noun, count, cap in (("vertices", int(words[0]), max_vertices),
                                     ("faces", int(words[1]), max_faces)):
                if count > cap:
                    raise RetargetError(
                        f"{label}: OFF header declares {count:,} {noun}, above "
                        f"max_{noun}={cap}"
                    )
    return text.encode("utf-8")


def _gltf_checked(data, kind, label, resolver, max_vertices, max_faces):
    """(`data` for trimesh, the file type to read it as) after `scene_size`'s checks."""
    read_as = kind
    if kind == "gltf" and data[:4] == b"glTF":
        read_as = "glb"
    elif kind == "glb" and data[:64].lstrip(codecs.BOM_UTF8 + b" \t\r\n")[:1] == b"{":
        read_as = "gltf"
    if read_as == "gltf":
        data = data.removeprefix(codecs.BOM_UTF8)  # trimesh's JSON would refuse it
    elif data[:4] != b"glTF":
        raise RetargetError(
            f"could not read {label} as {kind.upper()}: it is not a GLB file (one starts "
            "with 'glTF') nor glTF JSON"
        )
    def external(uri):  # a path's folder; bytes and file objects have none
        return len(resolver.get(uri))

    where = f"could not read {label} as {kind.upper()}"
    size = scene_size(data, where, None if resolver is None else external)
    if size is None:  # no glTF 2.0 document: trimesh's error says so
        return data, read_as
    if size.scene is None:
        raise RetargetError(
            f"{label} holds no triangle mesh as {kind.upper()}: it has no scene (a glTF "
            "'scenes' list) to place its meshes"
        )
    if size.mesh_nodes:
        mesh = max(size.mesh_nodes, key=lambda m: size.mesh_nodes[m] * size.mesh_vertices[m])
        instances = sum(size.mesh_nodes.values())
        why = (
            f": its glTF scene places {instances:,} mesh instance"
            f"{'s' if instances != 1 else ''} (mesh {mesh}, of "
            f"{size.mesh_vertices[mesh]:,} vertices, at {size.mesh_nodes[mesh]:,} node"
            f"{'s' if size.mesh_nodes[mesh] != 1 else ''})"
        )
        _refuse_over_caps(label, size.n_vertices, size.n_triangles, max_vertices,
                          max_faces, why)
    limit = _GLTF_EXPANSION * size.buffer_bytes + _GLTF_EXPANSION_SLACK
    if size.array_bytes > limit:
        largest = ""
        if size.largest_accessor is not None:
            index, nbytes, has_view = size.largest_accessor
            largest = (f"; the largest, accessor {index}"
                       f"{'' if has_view else ', with no bufferView'}, {nbytes:,} bytes")
        raise RetargetError(
            f"{where}: its accessors and bufferViews would unpack {size.buffer_bytes:,} "
            f"bytes of buffers into {size.array_bytes:,} bytes of arrays, above "
            f"{_GLTF_EXPANSION} times the buffers plus {_GLTF_EXPANSION_SLACK >> 20} MiB "
            f"(bufferViews {size.view_bytes:,} bytes, accessors "
            f"{size.array_bytes - size.view_bytes:,}{largest})"
        )
    return data, read_as


def _concatenated(parts):
    """Stack (trimesh.Trimesh, (4, 4) world transform) pairs into one set of arrays.

    Returns (vertices (V, 3), faces (F, 3), uv (V, 2) or None, normals (V, 3) or None);
    uv and normals are None unless every part has them.
    """
    vertices, faces, uvs, normals = [], [], [], []
    offset = 0
    for part, transform in parts:
        # trimesh keeps normals read from the file in its cache and computes none
        # unless asked: presence in the cache means the file had them
        n = part.vertex_normals if "vertex_normals" in part._cache else None
        v, f = part.vertices, part.faces
        if not np.array_equal(transform, np.eye(4)):  # only glTF nodes move
            linear = transform[:3, :3]
            v = v @ linear.T + transform[:3, 3]
            # a mirroring transform turns counter-clockwise triangles clockwise
            f = f[:, ::-1] if np.linalg.det(linear) < 0 else f
            if n is not None:
                n = n @ np.linalg.pinv(linear)
                length = np.linalg.norm(n, axis=1, keepdims=True)
                n = np.divide(n, length, out=np.zeros_like(n), where=length > 0)
        uv = getattr(part.visual, "uv", None)
        vertices.append(v)
        faces.append(f + offset)
        uvs.append(uv if uv is not None and len(uv) == len(v) else None)
        normals.append(n)
        offset += len(v)
    return (
        np.concatenate(vertices),
        np.concatenate(faces),
        None if any(u is None for u in uvs) else np.concatenate(uvs),
        None if any(n is None for n in normals) else np.concatenate(normals),
    )


def _validated(vertices, faces, uv, normals, name, max_vertices, max_faces, *, where,
               material=None):
    """The checks of `load_mesh` and `mesh_from_arrays`; `where` prefixes messages."""
    try:
        vertices = np.array(vertices, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise RetargetError(
            f"{where}: vertices must be a numeric (V, 3) array: {exc}"
        ) from exc
    try:
        faces = np.asarray(faces)
    except (TypeError, ValueError) as exc:
        raise RetargetError(
            f"{where}: faces must be an integer (F, 3) array: {exc}"
        ) from exc
    for array, label in ((vertices, "vertices"), (faces, "faces")):
        if array.size == 0:
            raise RetargetError(
                f"{where} is an empty mesh: {label} has shape {array.shape}"
            )
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise RetargetError(
            f"{where}: vertices must have shape (V, 3), got {vertices.shape}"
        )
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise RetargetError(
            f"{where}: faces must be triangles, shape (F, 3), got {faces.shape}"
        )
    if faces.dtype.kind not in "iu":
        raise RetargetError(
            f"{where}: faces must hold integer vertex indices, got dtype {faces.dtype}"
        )
    n_vertices, n_faces = len(vertices), len(faces)
    if n_vertices > max_vertices:
        raise RetargetError(
            f"{where} has {n_vertices} vertices, above max_vertices={max_vertices}"
        )
    if n_faces > max_faces:
        raise RetargetError(f"{where} has {n_faces} faces, above max_faces={max_faces}")
    bad = np.flatnonzero(~np.isfinite(vertices).all(axis=1))
    if len(bad):
        raise RetargetError(
            f"{where}: {len(bad)} vertices have NaN or infinite coordinates "
            f"(first: vertex {bad[0]})"
        )
    largest = int(np.abs(vertices).argmax())
    if abs(vertices.flat[largest]) > MAX_COORDINATE:
        vertex, axis = divmod(largest, 3)
        raise RetargetError(
            f"{where}: vertex {vertex} has coordinate {'xyz'[axis]} = "
            f"{vertices.flat[largest]:g}, beyond the supported ±{MAX_COORDINATE:g} "
            "units; rescale the mesh (to metres or millimetres, say)"
        )
    negative = np.flatnonzero((faces < 0).any(axis=1))
    if len(negative):
        first = negative[0]
        raise RetargetError(
            f"{where}: {len(negative)} faces hold negative vertex indices "
            f"(first: face {first}, {faces[first].tolist()})"
        )
    if faces.max() >= n_vertices:
        raise RetargetError(
            f"{where}: faces index vertex {faces.max()} but there are only "
            f"{n_vertices} vertices (valid indices 0..{n_vertices - 1})"
        )
    _refuse_degenerate(vertices, faces, where)
    if material is not None and not isinstance(material, Material):
        raise RetargetError(
            f"{where}: material must be a retarget.material.Material or None, "
            f"got {type(material).__name__}"
        )
    return Mesh(
        vertices=_read_only(vertices),
        faces=_read_only(faces.astype(np.int64)),
        uv=_per_vertex(uv, "uv", 2, n_vertices, where),
        normals=_per_vertex(normals, "normals", 3, n_vertices, where),
        name=name,
        material=material,
    )


def _refuse_degenerate(vertices: np.ndarray, faces: np.ndarray, where: str) -> None:
    """Refuse fewer than 3 vertices, all at one point, or only zero-area triangles.

    vertices : (V, 3) float64, finite; faces : (F, 3) int, each in [0, V).
    """
    n_vertices = len(vertices)
    if n_vertices < 3:
        raise RetargetError(
            f"{where} has {n_vertices} vert{'ex' if n_vertices == 1 else 'ices'}; a mesh "
            "needs at least 3 distinct vertices"
        )
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    if (low == high).all():
        point = ", ".join(f"{x:g}" for x in low)
        raise RetargetError(
            f"{where}: all {n_vertices:,} vertices are at one point ({point}); a mesh "
            "needs at least 3 distinct vertices"
        )
    used = np.zeros(n_vertices, dtype=bool)
    used[faces.ravel()] = True
    points = vertices[used]
    size2 = float(np.sum((points.max(axis=0) - points.min(axis=0)) ** 2))
    chunk = 1 << 16  # real meshes pass in the first chunk
    for start in range(0, len(faces), chunk):
        a, b, c = (vertices[faces[start:start + chunk, i]] for i in range(3))
        twice_area = np.linalg.norm(np.cross(b - a, c - a), axis=1)
        if (twice_area > _ZERO_AREA * size2).any():
            return
    centred = points - points.mean(axis=0)
    spread = np.linalg.eigvalsh(centred.T @ centred)  # ascending
    if size2 == 0:
        detail = "the vertices they use are all at one point"
    elif spread[1] <= _ZERO_AREA * spread[2]:
        detail = "their vertices lie on one line"
    else:
        detail = "each repeats a vertex or has three collinear ones"
    count = "its 1 triangle has" if len(faces) == 1 else f"all {len(faces):,} triangles have"
    raise RetargetError(
        f"{where}: {count} zero area ({detail}); a mesh needs at least one triangle of "
        "non-zero area"
    )


def _per_vertex(values, label: str, width: int, n_vertices: int, where: str):
    """`values` as a read-only finite (V, width) float64 copy, or None if None."""
    if values is None:
        return None
    try:
        values = np.array(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise RetargetError(f"{where}: {label} must be a numeric array: {exc}") from exc
    if values.shape != (n_vertices, width):
        raise RetargetError(
            f"{where}: {label} must have shape ({n_vertices}, {width}), one row per "
            f"vertex, got {values.shape}"
        )
    bad = np.flatnonzero(~np.isfinite(values).all(axis=1))
    if len(bad):
        raise RetargetError(
            f"{where}: {label} of {len(bad)} vertices are NaN or infinite "
            f"(first: vertex {bad[0]})"
        )
    return _read_only(values)


def _read_only(array: np.ndarray) -> np.ndarray:
    """`array` itself, flagged read-only (callers pass a fresh copy)."""
    array.setflags(write=False)
    return array


class _Files(trimesh.resolvers.Resolver):
    """Side files given in memory, looked up by base name in any case (a glTF's
    ``textures/skin.png`` and an MTL's ``C:\\scans\\skin.png`` both find
    ``skin.png``)."""

    def __init__(self, files: Mapping[str, bytes]):
        self._files = {_base(str(k)).lower(): bytes(v) for k, v in files.items()}

    def get(self, name):
        key = _base(name.decode() if isinstance(name, bytes) else str(name)).lower()
        if key not in self._files:
            raise RetargetError(f"the file {name!r} it refers to was not given")
        return self._files[key]

    def keys(self):
        return self._files.keys()

    def write(self, name, data):
        raise RetargetError("side files are read only")

    def namespaced(self, namespace):
        return self


def _base(name: str) -> str:
    return name.strip().replace("\\", "/").rsplit("/", 1)[-1]


def _side_file(resolver, name: str) -> bytes | None:
    """The side file `name` from a resolver, or None when it has none by that name."""
    try:
        return resolver.get(name)
    except Exception:  # noqa: BLE001 - a missing file is None, however a resolver says it
        return None


def _zipped(data: bytes, label: str, max_bytes: int | None):
    """(the mesh file's bytes, its kind, a resolver of the other files) of a zipped mesh,
    read within `retarget.zips`' bounds: at most `MAX_ZIP_MEMBERS` files, unpacking to at
    most `max_bytes` (or 256 MiB) in all."""
    budget = max_bytes if max_bytes is not None else 256 << 20
    archive = opened_zip(data, label)
    infos = [i for i in archive.infolist() if not i.is_dir() and not i.filename.startswith("__MACOSX/")
             and not _base(i.filename).startswith(".")]
    if len(infos) > MAX_ZIP_MEMBERS:
        raise RetargetError(f"{label} holds {len(infos)} files; a zipped mesh may hold at most "
                            f"{MAX_ZIP_MEMBERS} (the mesh and the files it refers to)")
    meshes = [i for i in infos if _base(i.filename).rsplit(".", 1)[-1].lower() in MESH_FILES]
    if len(meshes) != 1:
        found = ", ".join(repr(i.filename) for i in meshes[:5]) or "none"
        raise RetargetError(f"{label} must hold one mesh file ({', '.join(MESH_FILES)}); it holds "
                            f"{len(meshes)}: {found}")
    check_members(infos, label, budget, budget, things="files", thing="file",
                  content="a mesh's files")
    left = [budget]
    files = {info.filename: unpacked(archive, info, label, left) for info in infos}
    mesh = meshes[0].filename
    return files.pop(mesh), _base(mesh).rsplit(".", 1)[-1].lower(), _Files(files)
