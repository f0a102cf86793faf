"""Animated faces as a zip of OBJ frames: one ``.obj`` per frame, ordered by the last
number in each file name, all of one topology.

A zip can claim anything in its central directory and unpack to far more than its own
size, so the work is bounded before it is done (`retarget.zips`): the entry count before
the directory is parsed; the members' declared sizes (in all, `max_bytes`; each,
`MAX_FRAME_BYTES`) and compression ratios before any is unpacked; frames x vertices
(`MAX_SEQUENCE_VERTICES`, from the first frame's vertex count) before the other frames
are parsed. Members are unpacked and parsed a block at a time, so memory stays
proportional to one block and the labelled points, not to the members; every read is
bounded whatever the headers say, and a frame that runs past the first frame's vertex
count is refused there.
"""

from __future__ import annotations

import hashlib
import io
import re

import numpy as np

from retarget.errors import RetargetError
from retarget.mesh import load_mesh
from retarget.sources.labelled_points import labelled_positions, labelled_surface_points
from retarget.zips import ZIP_ERRORS, check_members, opened_zip, unpacked, zip_problem

__all__ = ["MAX_FRAME_BYTES", "MAX_SEQUENCE_VERTICES", "obj_sequence_points"]

MAX_FRAME_BYTES = 16 << 20
"""Most bytes one frame may unpack to: an OBJ of about 230,000 vertices with their faces,
far above a face mesh (the sample face has 8,430). The first frame is parsed whole by
`retarget.mesh.load_mesh`, whose trimesh parser holds about 10 times the text, so this
keeps that under 200 MB."""

MAX_SEQUENCE_VERTICES = 50_000_000
"""Most vertices parsed over the whole sequence (frames x the first frame's vertex
count): 3,000 frames of a 16,000-vertex face; about a minute of parsing."""

_BLOCK = 1 << 20  # bytes unpacked and parsed at once
_MAX_LINE = 1 << 20  # no OBJ line is longer
_V_LINE = re.compile(r"^[ \t]*v[ \t]", re.MULTILINE)


def obj_sequence_points(data: bytes, label: str, labelled, layout, max_bytes: int):
    """((F, K, 3) points, K names, meta) of the labelled points of a zip of OBJ frames;
    at most `max_bytes` are unpacked (see the module docstring for the other bounds)."""
    archive = opened_zip(data, label)
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
    infos = [info for _, info in members]
    check_members(infos, label, max_bytes, MAX_FRAME_BYTES, things="frames", thing="frame",
                  content="OBJ text", advice=" (fewer frames, or a coarser mesh)", total=".obj files")
    budget = [max_bytes]  # bytes still to unpack: the headers may lie, the reads may not

    first = infos[0]
    raw = unpacked(archive, first, label, budget)
    mesh = load_mesh(raw, "obj")
    if len(infos) * mesh.n_vertices > MAX_SEQUENCE_VERTICES:
        raise RetargetError(
            f"{label}: {len(infos)} frames of {mesh.n_vertices} vertices are "
            f"{len(infos) * mesh.n_vertices} vertices to parse; at most {MAX_SEQUENCE_VERTICES} "
            "are read (fewer frames, or a coarser mesh)")
    vertex_indices, barycentric, names = labelled_surface_points(
        labelled, mesh.vertices, mesh.faces, layout, label)
    used = np.unique(vertex_indices)
    posed = np.empty((len(infos), len(used), 3))
    topology = None
    for f, info in enumerate(infos):
        where = f"{label}: {info.filename!r}"
        if f == 0:
            vertices, faces = _frame(io.BytesIO(raw), where, mesh.n_vertices, first.filename)
            del raw
            topology = faces
        else:
            vertices, faces = _read_frame(archive, info, label, budget, mesh.n_vertices,
                                          first.filename)
            if faces != topology:
                raise RetargetError(
                    f"{where} has other faces than {first.filename!r}; every frame needs the "
                    "same topology")
        posed[f] = vertices[used]
    points = labelled_positions(posed, used, vertex_indices, barycentric)
    return points, names, {"n_vertices": mesh.n_vertices}


def _read_frame(archive, info, label, budget: list, n_vertices: int, first: str):
    """(vertices, faces digest) of a member, unpacked a block at a time (`_frame`)."""
    where = f"{label}: {info.filename!r}"
    try:
        with archive.open(info) as handle:
            return _frame(_Bounded(handle, info.file_size, budget, where), where, n_vertices, first)
    except RetargetError:
        raise
    except ZIP_ERRORS as exc:
        raise RetargetError(f"{where} could not be unpacked: {zip_problem(exc)}") from None


class _Bounded:
    """A member's stream that refuses to give more than its declared size or the budget."""

    def __init__(self, handle, size: int, budget: list, where: str):
        self.handle, self.left, self.budget, self.where = handle, size, budget, where

    def read(self, n: int) -> bytes:
        chunk = self.handle.read(min(n, self.left + 1, self.budget[0] + 1))
        self.left -= len(chunk)
        self.budget[0] -= len(chunk)
        if self.left < 0 or self.budget[0] < 0:
            raise RetargetError(f"{self.where} unpacks to more than it declares")
        return chunk


def _frame(stream, where: str, n_vertices: int, first: str) -> tuple[np.ndarray, str]:
    """((V, 3) float64 vertices in file order, a digest of the faces' vertex indices) of
    one OBJ frame, parsed `_BLOCK` bytes at a time; a frame whose vertex count differs
    from `n_vertices` (the first frame's, of file `first`) is refused, as soon as it runs
    past it."""
    digest = hashlib.blake2b(digest_size=16)
    blocks, count, rest = [], 0, b""
    while True:
        chunk = stream.read(_BLOCK)
        text = rest + chunk
        if chunk:
            cut = text.rfind(b"\n") + 1
            text, rest = text[:cut], text[cut:]
            if len(rest) > _MAX_LINE:
                raise RetargetError(f"{where} has a line longer than {_MAX_LINE} bytes")
        lines = text.decode("utf-8", errors="replace")
        if count > n_vertices:  # too many already: only count the rest, for the message
            count += len(_V_LINE.findall(lines))
        else:
            vertices = _obj_vertices(lines, where)
            count += len(vertices)
            blocks.append(vertices)
            digest.update(_obj_faces(lines).encode("utf-8"))
        if not chunk:
            break
    if count != n_vertices:
        raise RetargetError(
            f"{where} has {count} vertices, {first!r} has {n_vertices}; every frame needs "
            "the same topology")
    return np.concatenate(blocks), digest.hexdigest()


def _obj_vertices(text: str, where: str) -> np.ndarray:
    """(V, 3) float64 from an OBJ's ``v`` lines, in file order (colours after xyz ignored)."""
    found = re.findall(r"^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)", text, re.MULTILINE)
    try:
        vertices = np.array(found, dtype=np.float64).reshape(-1, 3)
    except ValueError:
        raise RetargetError(f"{where}: a v line holds something that is not a number") from None
    if len(vertices) != len(_V_LINE.findall(text)):
        raise RetargetError(f"{where}: a v line has fewer than 3 coordinates")
    if not np.isfinite(vertices).all():
        raise RetargetError(f"{where}: a vertex is NaN or infinite")
    return vertices


def _obj_faces(text: str) -> str:
    """The vertex indices of an OBJ's ``f`` lines (texture / normal indices out), a line
    each."""
    lines = re.findall(r"^[ \t]*f[ \t]+(.*?)[ \t]*$", text, re.MULTILINE)
    return re.sub(r"/\S*", "", "\n".join(lines)) + "\n" if lines else ""
