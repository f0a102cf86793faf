"""Triangle meshes: the `Mesh` container, and loading, validating and saving it.

A mesh enters the library through `load_mesh` (a file, read by trimesh) or
`mesh_from_arrays` (arrays already in memory). Both run the same checks, so code that
receives a `Mesh` may trust it: finite (V, 3) float64 vertices, (F, 3) int64 triangles
that index them, optional per-vertex uv and normals, every array read-only.

Vertex count and order are exactly the file's, because landmark vertex indices refer to
them: trimesh loads with ``process=False`` (no merging of duplicate vertices, no removal
of unreferenced ones) and ``maintain_order=True`` (no splitting at UV seams). Units are
kept as they came: nothing is rescaled or centred. `load_mesh` documents what each
format does on the way in, `save_mesh` what it does on the way out.
"""

from __future__ import annotations

import io
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh
from trimesh.visual.material import SimpleMaterial

from retarget.errors import RetargetError
from retarget.material import Material, material_from_trimesh

__all__ = [
    "DEFAULT_MAX_FACES",
    "DEFAULT_MAX_VERTICES",
    "SUPPORTED_FORMATS",
    "Mesh",
    "load_mesh",
    "mesh_from_arrays",
    "save_mesh",
]

DEFAULT_MAX_VERTICES = 1_000_000
DEFAULT_MAX_FACES = 2_000_000
SUPPORTED_FORMATS = ("obj", "ply", "stl", "off", "gltf", "glb")

# OBJ material lines: trimesh starts a new geometry at every `usemtl`, each holding all
# the file's vertices, and follows `mtllib` to side files. Geometry alone is wanted.
_OBJ_MATERIAL_LINE = re.compile(r"^[ \t]*(?:usemtl|mtllib)\b[^\n]*", re.MULTILINE)


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
        and file objects; for a path it overrides the suffix.
    max_vertices, max_faces : int
        Refuse meshes with more vertices or faces than this (checked after parsing).
    max_bytes : int or None
        Refuse sources longer than this many bytes, before parsing. For a ``.gltf``
        path it bounds the JSON file, not the buffers it references.

    Returns
    -------
    Mesh
        Validated as by `mesh_from_arrays`; `name` is the file stem ("" for bytes).

    Raises
    ------
    RetargetError
        For an unknown file type, an unreadable or oversized source, a file that holds
        no triangles, and every check of `mesh_from_arrays`. Any exception trimesh
        raises on a malformed file is re-raised as ``could not read ... as OBJ: ...``.

    Notes
    -----
    What trimesh does per format, with ``process=False, maintain_order=True``:

    * OBJ: polygons are triangulated, the vertex count unchanged. `usemtl` and `mtllib`
      lines are skipped (trimesh would split the faces into one geometry per material,
      each holding every vertex), so materials are not read. Vertices are not split at
      UV seams: a vertex used with several ``vt`` keeps one of them (the median index
      trimesh sees), so texture is approximate on faces across a seam; ``vn`` likewise.
      When faces carry ``vt`` or ``vn`` indices, trimesh drops vertices after the last
      one a face uses; as that changes the vertex count such files are refused. `uv`
      and `normals` are None when some vertex has none (trimesh drops them). Relative
      (negative) indices resolve only in faces without ``vt`` or ``vn`` indices.
    * STL stores each triangle on its own: F faces load as 3F vertices, face ``i``
      being ``[3i, 3i + 1, 3i + 2]``; nothing is merged and there are no normals.
    * PLY, OFF: polygons are triangulated; trimesh groups faces by polygon size, so
      with mixed triangles and quads the face order (not the vertex order) differs
      from the file.
    * glTF, GLB: a scene. Every triangle-mesh instance in it (each primitive of each
      node with a mesh; a mesh used by two nodes counts twice) gets its node's world
      transform (normals by the inverse transpose, triangles reversed under a mirror)
      and the instances are concatenated in the order trimesh's loader walks the node
      tree: depth first, the scene's root nodes last to first, so for a flat scene the
      reverse of the file's node list. The order is fixed for a given file. Points and
      lines are ignored. trimesh flips glTF's v so that `uv` has OBJ's convention. The
      material of the first instance is kept (`retarget.material.material_from_trimesh`).
    """
    data, suffix, label, name, resolver = _source_bytes(source, max_bytes)
    kind = _file_type(file_type if file_type is not None else suffix, label)
    n_obj_vertices = None
    if kind == "obj":
        # decoded here: for non-UTF-8 text trimesh would call charset_normalizer
        text = _OBJ_MATERIAL_LINE.sub("", data.decode("utf-8", errors="replace"))
        data = text.encode("utf-8")
        # trimesh parses `v` lines exactly so, on "\n" + text with "\r\n" folded
        n_obj_vertices = ("\n" + text.replace("\r\n", "\n")).count("\nv ")
    try:
        scene = trimesh.load_scene(
            io.BytesIO(data),
            file_type=kind,
            resolver=resolver,
            process=False,
            maintain_order=True,
        )
        parts = []
        for node in scene.graph.nodes_geometry:
            transform, geometry = scene.graph[node]
            if isinstance(scene.geometry[geometry], trimesh.Trimesh):
                parts.append((scene.geometry[geometry], transform))
    except Exception as exc:
        raise RetargetError(
            f"could not read {label} as {kind.upper()}: {type(exc).__name__}: {exc}"
        ) from exc
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
    material = material_from_trimesh(parts[0][0].visual) if kind in ("gltf", "glb") else None
    return _validated(
        vertices, faces, uv, normals, name, max_vertices, max_faces, where=label,
        material=material,
    )


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
        is NaN or infinite, or a face index is negative or past the last vertex.
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
        Destination; its suffix must be one of `SUPPORTED_FORMATS`.

    Raises
    ------
    RetargetError
        If the suffix is not a supported format.
    """
    path = Path(path)
    kind = _file_type(path.suffix, repr(str(path)))
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
