"""Animated faces as a zip of OBJ frames: one ``.obj`` per frame, ordered by the last
number in each file name, all of one topology."""

from __future__ import annotations

import io
import re
import zipfile

import numpy as np

from retarget.errors import RetargetError
from retarget.mesh import load_mesh
from retarget.sources.labelled_points import labelled_positions, labelled_surface_points

__all__ = ["obj_sequence_points"]


def obj_sequence_points(data: bytes, label: str, labelled, layout, max_bytes: int):
    """((F, K, 3) points, K names, meta) of the labelled points of a zip of OBJ frames;
    at most `max_bytes` are unpacked."""
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
    except zipfile.BadZipFile as exc:
        raise RetargetError(f"{label} is not a zip archive: {exc}") from None
    members = []
    for info in archive.infolist():
        base = info.filename.rsplit("/", 1)[-1]
        if info.is_dir() or info.filename.startswith("__MACOSX/") or base.startswith(".") \
                or not base.lower().endswith(".obj"):
            continue
        numbers = re.findall(r"\d+", base[:-4])
        if not numbers:
            raise RetargetError(f"{label}: {info.filename!r} has no frame number in its name")
        members.append((int(numbers[-1]), info))
    if not members:
        raise RetargetError(f"{label} holds no .obj files")
    members.sort(key=lambda m: m[0])
    for (a, first), (b, second) in zip(members, members[1:]):
        if a == b:
            raise RetargetError(
                f"{label}: {first.filename!r} and {second.filename!r} have the same frame number {a}")
    budget = max_bytes

    def member_text(info) -> str:
        nonlocal budget
        with archive.open(info) as handle:
            raw = handle.read(budget + 1)  # the header's size may lie: bound the read itself
        budget -= len(raw)
        if budget < 0:
            raise RetargetError(f"{label} unpacks to more than {max_bytes} bytes")
        return raw.decode("utf-8", errors="replace")

    first_name = members[0][1].filename
    first_text = member_text(members[0][1])
    mesh = load_mesh(first_text.encode("utf-8"), "obj")
    vertex_indices, barycentric, names = labelled_surface_points(
        labelled, mesh.vertices, mesh.faces, layout, label)
    used = np.unique(vertex_indices)
    topology = _obj_faces(first_text)
    posed = np.empty((len(members), len(used), 3))
    for f, (_, info) in enumerate(members):
        text = first_text if f == 0 else member_text(info)
        vertices = _obj_vertices(text, f"{label}: {info.filename!r}")
        if len(vertices) != mesh.n_vertices:
            raise RetargetError(
                f"{label}: {info.filename!r} has {len(vertices)} vertices, {first_name!r} has "
                f"{mesh.n_vertices}; every frame needs the same topology")
        if f and _obj_faces(text) != topology:
            raise RetargetError(
                f"{label}: {info.filename!r} has other faces than {first_name!r}; every frame "
                "needs the same topology")
        posed[f] = vertices[used]
    points = labelled_positions(posed, used, vertex_indices, barycentric)
    return points, names, {"n_vertices": mesh.n_vertices}


def _obj_vertices(text: str, where: str) -> np.ndarray:
    """(V, 3) float64 from an OBJ's ``v`` lines, in file order (colours after xyz ignored)."""
    found = re.findall(r"^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)", text, re.MULTILINE)
    try:
        vertices = np.array(found, dtype=np.float64).reshape(-1, 3)
    except ValueError:
        raise RetargetError(f"{where}: a v line holds something that is not a number") from None
    if len(vertices) != len(re.findall(r"^[ \t]*v[ \t]", text, re.MULTILINE)):
        raise RetargetError(f"{where}: a v line has fewer than 3 coordinates")
    if not np.isfinite(vertices).all():
        raise RetargetError(f"{where}: a vertex is NaN or infinite")
    return vertices


def _obj_faces(text: str) -> int:
    """A hash of the vertex indices of an OBJ's ``f`` lines (texture / normal indices out)."""
    lines = re.findall(r"^[ \t]*f[ \t]+(.*?)[ \t]*$", text, re.MULTILINE)
    return hash(re.sub(r"/\S*", "", "\n".join(lines)))
