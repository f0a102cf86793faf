"""What the server reads out of uploaded files, as functions that run in a child process.

Each function here takes an upload's bytes (or the scratch path a video was saved to)
and returns what its route needs; routes call them through `server.isolation.Isolation`
only, never directly, so a native parser's crash, a memory blow-up or a slow file ends a
child process and becomes a refusal, and the server keeps serving. They raise the
library's `RetargetError` with messages that name the upload as the user knows it (never
a scratch path). No FastAPI here: the forkserver imports this module once.
"""

from __future__ import annotations

import inspect
import json
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from retarget.errors import RetargetError
from retarget.gltf import export_mesh_gltf, read_gltf
from retarget.landmarks import SurfacePoints
from retarget.layouts import get_layout
from retarget.mesh import Mesh, load_mesh
from retarget.skin import SkinWeights
from retarget.sources.files import read_take
from retarget.sources.markers import track_marker_video
from retarget.sources.stereo import (
    StereoCalibration,
    calibrate_stereo,
    track_stereo_frames,
    track_stereo_videos,
)
from retarget.sources.take import Take
from retarget.sources.video import VideoReader
from retarget.weights import METHODS, compute_weights

__all__ = ["CALIBRATION_VIEWS", "ImportedProject", "imported_project", "marker_take",
           "mesh_counts", "rig", "stereo_calibration", "stereo_take", "take_from_upload",
           "video_opens"]

CALIBRATION_VIEWS = 20
"""Checkerboard frame pairs a server calibration uses at most, spread over the videos:
the pattern search costs about 0.15 s an image, and 20 well spread views calibrate as well
as hundreds of neighbouring frames."""


def mesh_counts(data: bytes, ext: str, shown: str, max_vertices: int,
                max_bytes: int) -> tuple[int, int]:
    """(vertices, triangles) of an uploaded mesh that `retarget.mesh.load_mesh` accepts."""
    try:
        mesh = load_mesh(data, ext, max_vertices=max_vertices, max_bytes=max_bytes)
    except RetargetError as exc:
        text = str(exc).replace("the given bytes", "the file")
        raise RetargetError(f"uploaded mesh {shown!r} refused: {text}") from None
    return mesh.n_vertices, mesh.n_faces


def take_from_upload(data: bytes, filename: str, shown: str, options: dict, forms: dict,
                     project_layout: str | None) -> Take:
    """The take in an uploaded file (`read_take` with `options`, and the JSON `forms`
    fields parsed here: mapping, labelled_vertices), checked to name some of the
    project's layout points when it has landmarks (a take naming none could never drive
    it: refused now rather than when it is played)."""
    try:
        parsed = {name: _json_form(value, name) for name, value in forms.items()}
        take = read_take(data, filename=filename, **options, **parsed)
        if project_layout is not None:
            take.to_layout(project_layout, partial=True)
    except RetargetError as exc:
        raise RetargetError(f"take file {shown!r} refused: {exc}") from None
    return take


def rig(mesh: Mesh, points: SurfacePoints, method: str, options: dict, progress) -> SkinWeights:
    """The skin weights of `method` (`retarget.weights.compute_weights`) for a stored mesh
    and its landmarks; not an upload, but a dense rig of a large mesh needs gigabytes
    (see `server.isolation`)."""
    if "progress" in inspect.signature(METHODS[method]).parameters:
        options = {**options, "progress": progress}
    layout = get_layout(points.layout) if points.layout else None
    return compute_weights(method, mesh.vertices, mesh.faces, points, layout, **options)


def _json_form(value: str | None, what: str):
    if value is None or value == "":
        return None
    try:
        return json.loads(value)
    except json.JSONDecodeError as exc:
        raise RetargetError(f"form field {what!r} is not JSON: {exc}") from None
    except RecursionError:
        raise RetargetError(f"form field {what!r} is JSON nested too deeply to read") from None


@dataclass(frozen=True)
class ImportedProject:
    """A .glb exported by this app, as a project is stored: the mesh as a mesh-only .glb
    (which reads back with the same vertices), the landmarks JSON, the rig."""

    mesh_file: bytes
    n_vertices: int
    n_faces: int
    landmarks: dict
    n_points: int
    layout: str
    weights: SkinWeights
    deformation: str
    animations: list[str]


def imported_project(data: bytes, shown: str, max_vertices: int) -> ImportedProject:
    """The project in an uploaded .glb this app exported (`retarget.gltf.read_gltf`)."""
    try:
        face = read_gltf(data)
    except RetargetError as exc:
        text = str(exc).replace("the given bytes", "the file")
        raise RetargetError(f"{shown!r} cannot be imported (only a .glb exported by this app "
                            f"can): {text}") from None
    mesh = face.mesh
    if mesh.n_vertices > max_vertices:
        raise RetargetError(f"{shown!r} has a mesh of {mesh.n_vertices} vertices, over the "
                            f"server's limit of {max_vertices}")
    mesh_file = export_mesh_gltf(mesh)
    stored = load_mesh(mesh_file, "glb")  # what the project will read back, checked first
    if stored.n_vertices != mesh.n_vertices:
        raise RetargetError(f"{shown!r}: its mesh does not read back as {mesh.n_vertices} vertices")
    return ImportedProject(mesh_file, mesh.n_vertices, mesh.n_faces, face.points.to_json(),
                           face.points.n_points, face.points.layout or "", face.weights,
                           face.deformation, [clip.name for clip in face.clips])


@contextmanager
def _naming(names: dict[Path, str]):
    """Library refusals that name a scratch file name the upload instead (the paths are
    the server's own and mean nothing to the user)."""
    try:
        yield
    except RetargetError as exc:
        message = str(exc)
        for path, shown in names.items():
            message = message.replace(repr(str(path)), repr(shown))
            message = message.replace(str(path), repr(shown))
        raise RetargetError(message) from None


def video_opens(path: Path, names: dict[Path, str]) -> None:
    """Nothing, once the video at `path` opens and states its size (refused otherwise)."""
    with _naming(names):
        VideoReader(path).close()


def marker_take(path: Path, layout: str, names: dict[Path, str], progress) -> Take:
    """Ring markers tracked through a video (Dutreve §5, `track_marker_video`)."""
    shown = names[path]
    try:
        with _naming(names):
            return track_marker_video(path, layout=layout, progress=progress)
    except RetargetError as exc:
        if repr(shown) in str(exc):
            raise
        raise RetargetError(f"video {shown!r}: {exc}") from None


def stereo_calibration(videos: list[Path], calibration: Path | None, boards: list[Path] | None,
                       pattern: tuple, layout: str,
                       names: dict[Path, str]) -> tuple[StereoCalibration, str]:
    """(calibration, "file" | "checkerboard") of a stereo pair once everything that can be
    checked before tracking is: both videos readable with equal sizes and frame counts,
    a real calibration for that size (from the .npz, or computed from the checkerboard
    videos, which takes a few seconds) and the layout's markers in the first frame pair."""
    with _naming(names):
        size = _pair_size(videos, names)
        if calibration is not None:
            cal, source = StereoCalibration.load(calibration), "file"
        else:
            _pair_size(boards, names)
            cal, source = _calibration(boards, pattern, names), "checkerboard"
        if cal.size != size:
            raise RetargetError(
                f"the stereo videos are {size[0]}x{size[1]} but the calibration is for "
                f"{cal.size[0]}x{cal.size[1]}: calibrate the cameras at the size they film")
        _check_first_markers(videos, cal, layout, names)
    return cal, source


def stereo_take(videos: list[Path], cal: StereoCalibration, layout: str,
                names: dict[Path, str], progress) -> Take:
    """Colour markers tracked through a stereo pair (Woodward §5), head motion kept."""
    with _naming(names):
        take = track_stereo_videos(*videos, cal, layout=layout, head_motion="keep",
                                   progress=progress)
    take.meta.update(videos=[names[v] for v in videos], calibration=cal.to_dict())
    return take


def _pair_size(videos: list[Path], names: dict[Path, str]) -> tuple[int, int]:
    """(width, height) of two videos of one moment, which must agree in size and in the
    frame count their headers state (frames are paired by index)."""
    sizes, counts = [], []
    for path in videos:
        with VideoReader(path) as reader:
            sizes.append(tuple(reader.size))
            counts.append(reader.n_frames)
    a, b = (names[v] for v in videos)
    if sizes[0] != sizes[1]:
        raise RetargetError(f"{a!r} is {sizes[0][0]}x{sizes[0][1]} but {b!r} is "
                            f"{sizes[1][0]}x{sizes[1][1]}: the two cameras must film at one size")
    if all(counts) and counts[0] != counts[1]:
        raise RetargetError(f"{a!r} has {counts[0]} frames but {b!r} has {counts[1]}: a stereo "
                            "pair is matched frame by frame, so both videos must start and end "
                            "on the same moment")
    return sizes[0]


def _calibration(boards: list[Path], pattern: tuple, names: dict[Path, str]) -> StereoCalibration:
    """The pair's calibration from its checkerboard videos (`CALIBRATION_VIEWS` pairs)."""
    lefts, rights = _view_pairs(*boards, CALIBRATION_VIEWS)
    try:
        return calibrate_stereo(lefts, rights, pattern)
    except RetargetError as exc:
        a, b = (names[v] for v in boards)
        raise RetargetError(f"checkerboard videos {a!r} and {b!r} ({len(lefts)} frame pairs "
                            f"searched): {exc}") from exc


def _view_pairs(left: Path, right: Path, count: int) -> tuple[list, list]:
    """At most `count` frame pairs spread over two calibration videos, (H, W, 3) uint8 BGR.

    Every `step`-th pair is kept; when more than ``2 count`` are held the step doubles and
    every other pair goes, so memory stays bounded without trusting the headers' counts.
    """
    kept, step = [], 1
    with VideoReader(left) as a, VideoReader(right) as b:
        for (index, image_a), (_, image_b) in zip(a, b):
            if index % step == 0:
                kept.append((image_a, image_b))
                if len(kept) > 2 * count:
                    kept, step = kept[::2], 2 * step
    kept = kept[::-(-len(kept) // count)]
    return [a for a, _ in kept], [b for _, b in kept]


def _check_first_markers(videos: list[Path], cal: StereoCalibration, layout: str,
                         names: dict[Path, str]) -> None:
    """Refuse a pair whose first frames show too few of the layout's colour markers, so
    it fails in the request rather than in the job (tracking one pair costs ~0.2 s)."""
    with VideoReader(videos[0]) as a, VideoReader(videos[1]) as b:
        first = (next(iter(a))[1], next(iter(b))[1])
    try:
        track_stereo_frames([first], cal, layout=layout, head_motion="keep")
    except RetargetError as exc:
        raise RetargetError(f"the colour markers of {layout!r} in the first frames of "
                            f"{names[videos[0]]!r} and {names[videos[1]]!r}: {exc}") from exc
