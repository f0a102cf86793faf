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
import warnings
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from retarget.errors import RetargetError
from retarget.facemesh.placement import CHECK_BELOW, find_face_mesh, layout_landmarks
from retarget.gltf import export_mesh_gltf, read_gltf
from retarget.landmarks import SurfacePoints
from retarget.layouts import Layout, get_layout
from retarget.lips import opened_mouth
from retarget.mesh import Mesh, load_mesh
from retarget.skin import SkinWeights
from retarget.sources.files import read_take
from retarget.sources.markers import track_marker_video
from retarget.sources.calibration import StereoCalibration
from retarget.sources.facemesh_video import track_video_facemesh
from retarget.sources.stereo import stereo_pair_calibration, track_stereo_videos
from retarget.sources.take import Take
from retarget.sources.video import VideoReader
from retarget.units import face_size, guess_units
from retarget.weights import METHODS, compute_weights

__all__ = ["FoundLandmarks", "ImportedProject", "OpenedMesh", "arkit", "face_mesh_take", "found_landmarks",
           "imported_project", "marker_take", "mesh_counts", "opened_mesh", "rig", "stereo_calibration", "stereo_take", "take_from_upload",
           "TrackedMarkers", "video_opens"]

def mesh_counts(data: bytes, ext: str, shown: str, max_vertices: int,
                max_bytes: int) -> tuple[int, int, dict]:
    """(vertices, triangles, unit guess) of an uploaded mesh that `retarget.mesh.load_mesh`
    accepts; the guess is ``{"unit", "size"}``, `retarget.units.guess_units` and the
    largest extent of its bounding box in its own numbers."""
    try:
        mesh = load_mesh(data, ext, max_vertices=max_vertices, max_bytes=max_bytes)
    except RetargetError as exc:
        text = str(exc).replace("the given bytes", "the file")
        raise RetargetError(f"uploaded mesh {shown!r} refused: {text}") from None
    guess = {"unit": guess_units(mesh.vertices), "size": round(face_size(mesh.vertices), 6)}
    return mesh.n_vertices, mesh.n_faces, guess


@dataclass(frozen=True)
class OpenedMesh:
    """A stored mesh with its mouth cut open, as a project stores it: a mesh-only .glb (uv,
    normals and material kept; the original vertices first), its counts and landmarks."""

    mesh_file: bytes
    n_vertices: int
    n_faces: int
    landmarks: dict
    n_points: int


def opened_mesh(mesh: Mesh, points: SurfacePoints) -> OpenedMesh:
    """`mesh` cut open along its lip contact line (`retarget.lips.opened_mouth`); not an
    upload, but its mesh file is written like an imported one (`export_mesh_gltf`)."""
    if not points.layout:
        raise RetargetError("the landmarks have no layout: the lips are found from a layout's "
                            "mouth points")
    opened = opened_mouth(mesh, points, get_layout(points.layout))
    return OpenedMesh(export_mesh_gltf(opened.mesh), opened.mesh.n_vertices,
                      opened.mesh.n_faces, opened.points.to_json(), opened.points.n_points)


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


@dataclass(frozen=True)
class FoundLandmarks:
    """A layout's points found on a mesh with no clicks, as a project stores them.

    landmarks : `SurfacePoints.to_json` with ``"layout"``, ``"confidence"`` (N,) 0..1
        (3 decimals) and ``"check_below"``, the confidence under which a point asks to
        be checked (`retarget.facemesh.placement.CHECK_BELOW`).
    n_points : N.
    check : the names of the points to check, in layout order.
    presence : the face model's face presence in the view the points were found in, 0..1.
    """

    landmarks: dict
    n_points: int
    check: list[str]
    presence: float


def found_landmarks(mesh: Mesh, layout: str, progress) -> FoundLandmarks:
    """The points of `layout` found on a stored mesh (`find_face_mesh`, then
    `layout_landmarks`); not an upload, but the face model (LiteRT) and the rasteriser
    are native code run on user geometry. Raises the library's `RetargetError` when no
    view of the mesh shows a face."""
    chosen = get_layout(layout)
    found = find_face_mesh(mesh, progress=lambda fraction: progress(0.95 * fraction))
    points, confidence = layout_landmarks(found, chosen, mesh)
    landmarks = {**points.to_json(), "layout": chosen.name,
                 "confidence": [round(float(c), 3) for c in confidence], "check_below": CHECK_BELOW}
    check = [chosen.point_names[i] for i, c in enumerate(confidence) if c < CHECK_BELOW]
    return FoundLandmarks(landmarks, chosen.n_points, check, float(found.presence))


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
    units: str | None = None


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
                           face.deformation, [clip.name for clip in face.clips], face.units)


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


def video_opens(path: Path, names: dict[Path, str], max_frames: int | None = None) -> None:
    """Nothing, once the video at `path` opens and states its size, and its header claims
    at most `max_frames` frames (refused otherwise)."""
    with _naming(names):
        reader = VideoReader(path)
        reader.close()
    if max_frames is not None and reader.n_frames > max_frames:
        raise RetargetError(_too_long(names[path], max_frames, reader.fps, reader.n_frames))


def _too_long(shown: str, max_frames: int, fps: float, frames: int | None = None) -> str:
    """Why a video with more than `max_frames` frames (`frames` when its header says) is
    refused."""
    def span(n: int) -> str:
        seconds = n / fps
        return f"{seconds:.3g} s" if seconds < 120 else f"{seconds / 60:.3g} min"

    length = (f"has {frames} frames ({span(frames)} at {fps:g} fps)" if frames is not None
              else f"runs past {max_frames} frames")
    return (f"video {shown!r} {length}; the server tracks at most {max_frames} frames "
            f"({span(max_frames)}) of a video: cut it into shorter takes")


PREVIEW_WIDTH = 640
"""Widest first-frame preview a marker take keeps, px (the page shows it in a panel)."""


@dataclass(frozen=True)
class TrackedMarkers:
    """A ring-marker video's take and a JPEG of its first frame (at most `PREVIEW_WIDTH`
    px wide), for the page to show where each marker column was; the take's
    ``meta["first_frame"]`` has each column's place there (`marker_take`)."""

    take: Take
    preview: bytes


def marker_take(path: Path, layout: str | Layout | None, names: dict[Path, str],
                progress) -> TrackedMarkers:
    """Ring markers tracked through a video (Dutreve §5, `track_marker_video`; layout None:
    every marker in view, columns m01..mM), with the first frame's preview. The take's
    ``meta["first_frame"]`` is ``[[x, y] | null per column]``: where each column is on the
    first frame in the video's pixels, x right and y down as in the image (the take's
    points have y up), null for a marker not seen there."""
    shown = names[path]
    try:
        with _naming(names):
            take = track_marker_video(path, layout=layout, progress=progress)
            preview = _first_frame_jpeg(path)
    except RetargetError as exc:
        if repr(shown) in str(exc):
            raise
        raise RetargetError(f"video {shown!r}: {exc}") from None
    height = take.meta["size"][1]
    take.meta["first_frame"] = [
        [round(float(x), 2), round(float(height - y), 2)] if np.isfinite([x, y]).all() else None
        for x, y in take.points[0]] if take.n_frames else []
    return TrackedMarkers(take, preview)


def _first_frame_jpeg(path: Path) -> bytes:
    """The video's first frame as a JPEG at most `PREVIEW_WIDTH` px wide (re-encoded
    here, so what the page shows is never the upload's own bytes)."""
    import cv2

    with VideoReader(path) as reader:
        _, frame = next(iter(reader))
    height, width = frame.shape[:2]
    if width > PREVIEW_WIDTH:
        size = (PREVIEW_WIDTH, max(1, round(height * PREVIEW_WIDTH / width)))
        frame = cv2.resize(frame, size, interpolation=cv2.INTER_AREA)
    ok, jpeg = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, 85])
    if not ok:
        raise RetargetError("its first frame cannot be encoded as a JPEG")
    return jpeg.tobytes()


def face_mesh_take(path: Path, layout: str, max_frames: int, names: dict[Path, str],
                   progress) -> Take:
    """The face tracked through a video by the native face mesh (`track_video_facemesh`),
    labelled with the video's name. Refused when no frame holds a face (a take of NaN
    frames drives nothing) and when the video runs past `max_frames`, which its header
    may not have said."""
    shown = names[path]
    with _naming(names), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # no face: refused below, in words
        take = track_video_facemesh(path, layout=layout, progress=progress, max_frames=max_frames + 1)
    if take.n_frames > max_frames:
        raise RetargetError(_too_long(shown, max_frames, take.fps))
    if take.meta["frames_with_face"] == 0:
        raise RetargetError(f"no face was found in any of the {take.n_frames} frames of "
                            f"{shown!r}: nothing to keep")
    take.source = f"video: {shown}"[:200]  # the take list says where it came from
    return take


def stereo_calibration(videos: list[Path], calibration: Path | None, boards: list[Path] | None,
                       pattern: tuple, layout, names: dict[Path, str],
                       color="blue") -> tuple[StereoCalibration, str]:
    """(calibration, "file" | "checkerboard") of a stereo pair once everything that can be
    checked before tracking is (`retarget.sources.stereo.stereo_pair_calibration`): from
    the .npz, or computed from the checkerboard videos, which takes a few seconds. Layout
    None: stickers of `color`."""
    with _naming(names):
        return stereo_pair_calibration(*videos, layout=layout, calibration=calibration,
                                       boards=boards, pattern=pattern, color=color)


def stereo_take(videos: list[Path], cal: StereoCalibration, layout, names: dict[Path, str],
                stickers: dict | None, progress) -> Take:
    """Colour markers tracked through a stereo pair (Woodward §5), head motion kept; or, with
    layout None and `stickers` ``{"color", "anchors"}``, every sticker of one colour in the
    head frame (a layout made from the take keeps where each sits)."""
    options = {"head_motion": "keep"} if stickers is None else {"head_motion": "remove", **stickers}
    with _naming(names):
        take = track_stereo_videos(*videos, cal, layout=layout, progress=progress, **options)
    take.meta.update(videos=[names[v] for v in videos], calibration=cal.to_dict())
    return take


def arkit(mesh: Mesh, points: SurfacePoints, layout: str, rig_weights: SkinWeights | None, progress):
    """ARKit's 52 shapes on a stored mesh (`retarget.arkit.arkit_shapes`), on `rig_weights`
    or the default dense rig. The library reports no progress, so `progress` gets an
    estimate from the elapsed time and the vertex count (2-9 s for the 8,430-vertex
    sample face and 32-53 s for the 132,907-vertex one on this project's 2-core machine,
    by its load), approaching 0.95 and never claiming the end."""
    import math
    import threading
    import time

    from retarget.arkit import arkit_shapes

    expected = 3.0 + 2.5e-4 * len(mesh.vertices)
    stop = threading.Event()

    def tick():
        start = time.monotonic()
        while not stop.wait(0.25):
            progress(0.95 * (1.0 - math.exp(-(time.monotonic() - start) / expected)))

    ticker = threading.Thread(target=tick, daemon=True)
    ticker.start()
    try:
        return arkit_shapes(mesh.vertices, mesh.faces, points, layout, rig_weights)
    finally:
        stop.set()
        ticker.join()
