"""The project's takes: recorded performances (frames of named source feature points).

    GET    /api/projects/{id}/takes                 list, oldest first
    POST   /api/projects/{id}/takes                 upload a landmark / motion-capture /
                                                    animated-face file (multipart)
    POST   /api/projects/{id}/takes/track           upload a video of a face (markerless) or of
                                                    ring markers, or a stereo pair of
                                                    colour-marker videos with their calibration;
                                                    a job tracks it into a take (poll
                                                    GET /api/jobs/{job})
    GET    /api/projects/{id}/takes/{take}          its info
    GET    /api/projects/{id}/takes/{take}/points   (F, N, D) float32 .npy of the trimmed take
    GET    /api/projects/{id}/takes/{take}/calibration  a stereo take's calibration (.npz)
    GET    /api/projects/{id}/takes/{take}/preview  a marker take's first video frame (JPEG)
    GET    /api/projects/{id}/takes/{take}/preview/markers  where each marker is on it (JSON)
    PATCH  /api/projects/{id}/takes/{take}          {"name"?, "trim"?: [start, stop|null]} (s)
    DELETE /api/projects/{id}/takes/{take}

A take's info is ``{id, name, created, source, layout, fps, n_frames, n_points, dims,
duration, trim: [start, stop]}``. Takes keep the source's own point names; playing one
maps them to the project's layout by name (`retarget.performance`). A ring-marker video
tracked with layout ``*`` keeps every marker in view, named m01..mM: the page shows the
take's first frame with each marker on it, and the user makes their own layout of them
(a click on a marker, then on the mesh). Files are parsed by
`retarget.sources.files.read_take`, videos tracked by `retarget.sources.facemesh_video`
(markerless: MediaPipe's face mesh, run natively), `retarget.sources.markers` and
`retarget.sources.stereo`, all in child processes (`server.readers` through
`server.isolation`: no file can crash the server); the server only moves bytes and
schedules. An upload sent with an ``Idempotency-Key`` header is stored once however
often it is retried.

Stereo (Woodward §5): the calibration is an uploaded .npz (`retarget calibrate`, or a
stereo take's calibration download) or is computed here from two checkerboard videos.
What can be checked before tracking is checked in the request, so it is refused with 4xx
and nothing starts: the pair (both videos, equal frame counts and sizes, readable), the
calibration (a real one, for the videos' size; with checkerboards the calibration itself,
which takes a few seconds) and the markers of the first frame pair. The take keeps the
head motion and no temporal mean: the Performance panel's conditioning removes, filters
or applies them when the take plays. Its points are in the left camera's frame, in the
pattern's units (mm), and it carries its calibration for reuse. With layout ``*`` the pair
shows Woodward's unnamed stickers of one colour (``color``, default blue; ``anchors``,
e.g. "m01,m03,m04", the stickers that fix the head, default the most mutually rigid): every
sticker in view is a column m01..mM, in the head frame of its first pose (the head motion
removed on those anchors, as ``retarget track --method stereo`` does without a layout), so
that a custom layout made from the take (``GET .../layouts/from-take/{take}``) keeps where
each sticker sits, and live sticker sessions are named by it.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
from fastapi import APIRouter, File, Form, HTTPException, Response, UploadFile, status
from pydantic import BaseModel, Field

from retarget.errors import RetargetError
from retarget.layouts import Layout
from retarget.sources.calibration import StereoCalibration, pattern_points
from retarget.sources.take import Take
from server.deps import IsolationDep, JobsDep, LimitsDep, Number, ProjectDep, StoreDep, UploadKeyDep
from server.errors import responses
from server.jobs import JobBusy
from server.limits import body_limit
from server.project_layouts import resolve_layout
from server.readers import (face_mesh_take, marker_take, stereo_calibration, stereo_take,
                            take_from_upload, video_opens)
from server.routers.meshes import read_capped, upload_extension
from server.stickers import sticker_anchors, sticker_color

router = APIRouter(prefix="/api/projects/{project_id}/takes", tags=["takes"],
                   responses=responses(404))

TAKE_EXTENSIONS = ("csv", "json", "npy", "trc", "c3d", "glb", "gltf", "zip")
"""Files a take is read from (`retarget.sources.files.read_take`)."""
VIDEO_EXTENSIONS = ("mp4", "m4v", "mov", "avi", "mkv", "webm")
"""Videos the trackers read (through OpenCV's FFmpeg)."""
TRACK_METHODS = ("markerless", "markers", "stereo")
"""The trackers: markerless, any face (the layout's points picked out of the face mesh's
468); markers, white dots with a black ring (Dutreve §5); stereo, colour markers seen by
a calibrated pair (Woodward §5)."""
EVERY_MARKER = "*"
"""The layout form value that asks the marker tracker for every marker in view (columns
m01..mM, `retarget.sources.markers.track_marker_video` with no layout), and the stereo
tracker for every sticker of one colour."""
JOB_META = ("truncated", "frames_claimed", "frames_with_face")
"""What a tracking job's result repeats of its take's meta, for the page to say."""
CALIBRATION_EXTENSIONS = ("npz",)
"""A stereo calibration as `StereoCalibration.save` writes it."""
STEREO_FIELDS = ("right", "calibration", "calibration_left", "calibration_right")


def _default_name(filename: str | None, fallback: str) -> str:
    base = (filename or "").replace("\\", "/").rsplit("/", 1)[-1]
    return (base.rsplit(".", 1)[0] or fallback)[:200]


@router.get("")
def list_takes(project: ProjectDep, store: StoreDep) -> list[dict]:
    """The project's takes, oldest first."""
    return store.takes(project["id"])


@router.post("", status_code=status.HTTP_201_CREATED,
             responses={200: {"description": "the take already stored under this Idempotency-Key"},
                        **responses(404, 415, 503)})
@body_limit(files=1)
def upload_take(project: ProjectDep, store: StoreDep, limits: LimitsDep, isolation: IsolationDep,
                response: Response, key: UploadKeyDep = None,
                file: UploadFile = File(description=", ".join(f".{e}" for e in TAKE_EXTENSIONS)),
                name: str | None = Form(default=None, max_length=200),
                fps: float | None = Form(default=None, gt=0, le=1000,
                                         description="frame rate when the file has none"),
                layout: str | None = Form(default=None, description="layout of a bare .npy"),
                mapping: str | None = Form(default=None,
                                           description='JSON {"file label": "layout point name"}'),
                labelled_vertices: str | None = Form(
                    default=None, description='animated faces: JSON {"point name": vertex index}'),
                source: str | None = Form(
                    default=None, max_length=200,
                    description="what made the take, for the take list (e.g. 'video: clip.mp4' "
                                "for points the page tracked); default: the file's format")) -> dict:
    """Read a take from a file (in a child process, `server.isolation`) and store it;
    answers the take's info. The file is refused (422, with the reason) and nothing is
    stored if it does not parse. A retry with the same Idempotency-Key answers the take
    the first try stored (200)."""
    earlier = store.keyed_take(project["id"], key)
    if earlier is not None:
        response.status_code = status.HTTP_200_OK
        return earlier
    ext = upload_extension(file.filename, TAKE_EXTENSIONS)
    data = read_capped(file, limits.max_upload_bytes)
    if not data:
        raise RetargetError(f"the uploaded file {file.filename!r} is empty")
    options = {"layout": layout or None, "fps": fps}
    forms = {"mapping": mapping, "labelled_vertices": labelled_vertices}  # JSON, parsed there
    # the Layout itself, so a custom one reaches the child process with its spec
    project_layout = (resolve_layout(store, project["id"], project["landmarks"]["layout"] or "ibug68")
                      if project["landmarks"] else None)
    take = isolation.call(
        take_from_upload, data, f"{_default_name(file.filename, 'take')}.{ext}", file.filename,
        options, forms, project_layout,
        what=f"take file {file.filename!r} refused: not a readable {ext.upper()} file")
    if source:
        take.source = source
    return store.put_take(project["id"], take, name=name or _default_name(file.filename, "take"),
                          key=key)


@router.post("/track", status_code=status.HTTP_202_ACCEPTED, responses=responses(404, 409, 415, 503))
@body_limit(files=4)
def track_video(project: ProjectDep, store: StoreDep, limits: LimitsDep, jobs: JobsDep,
                isolation: IsolationDep,
                file: UploadFile | None = File(
                    default=None, description="the video; for stereo the left camera's: "
                    + ", ".join(f".{e}" for e in VIDEO_EXTENSIONS)),
                method: str = Form(default="markers", description=" | ".join(TRACK_METHODS)),
                layout: str | None = Form(
                    default=None, description="the layout whose points the take holds: for "
                    "markers and stereo the markers' (default dutreve21), for markers '*' "
                    "for every marker in view, named m01..mM; markerless, any (default the "
                    "project's landmarks', else ibug68)"),
                name: str | None = Form(default=None, max_length=200),
                right: UploadFile | None = File(default=None,
                                                description="stereo: the right camera's video"),
                calibration: UploadFile | None = File(
                    default=None, description="stereo: the pair's calibration, a .npz written by "
                    "`retarget calibrate` (or a stereo take's calibration download)"),
                calibration_left: UploadFile | None = File(
                    default=None, description="stereo, instead of a calibration file: the left "
                    "camera's video of the calibration pattern moved around"),
                calibration_right: UploadFile | None = File(
                    default=None, description="stereo: the right camera's video of the pattern, "
                    "filmed at the same time"),
                pattern: str = Form(default="checkerboard",
                                    description="checkerboard | circles | acircles"),
                cols: int | None = Form(default=None, ge=2, le=64,
                                        description="inner corners (circles) per pattern row"),
                rows: int | None = Form(default=None, ge=2, le=64,
                                        description="inner corners (circles) per pattern column"),
                square: float | None = Form(default=None, gt=0, le=1000,
                                            description="square side (circle spacing), mm: the "
                                            "unit of the take's points"),
                color: str | None = Form(default=None, max_length=40,
                                         description="stereo with layout '*': the stickers' colour, "
                                         "a name, B,G,R or hsv:H,S,V (default blue)"),
                anchors: str | None = Form(default=None, max_length=400,
                                           description="stereo with layout '*': the stickers that fix "
                                           "the head, e.g. m01,m03,m04 (default the most rigid)")) -> dict:
    """Track a video of a face (markerless), a ring-marker video, or a stereo pair of
    colour-marker videos into a take in the background; answers the job (poll
    ``GET /api/jobs/{job_id}``; its result names the take when done, with its frame
    count, ``truncated`` and ``frames_claimed`` for a cut-off file, and markerless
    ``frames_with_face``). What can be refused before tracking is (422): a file that is
    not a video, a markerless video whose header claims more frames than the server's
    limit. A stereo answer also has the calibration it uses,
    ``calibration: {source, rms, baseline, size, views}`` (rms px, baseline mm)."""
    if method not in TRACK_METHODS:
        raise RetargetError(f"unknown tracking method {method!r}; the server tracks "
                            f"{', '.join(TRACK_METHODS)}")
    if file is None:
        raise RetargetError("no video: upload it as 'file'" if method != "stereo" else
                            "method 'stereo' needs two videos: the left camera's as 'file', "
                            "which is missing, and the right camera's as 'right'")
    if layout is None:
        saved = project["landmarks"] and project["landmarks"]["layout"]
        layout = (saved or "ibug68") if method == "markerless" else "dutreve21"
    if layout == EVERY_MARKER and method == "markerless":
        raise RetargetError(f"layout {EVERY_MARKER!r} (every marker in view) is for methods "
                            "'markers' and 'stereo'; 'markerless' tracks a layout's points")
    stickers = None
    if method == "stereo" and layout == EVERY_MARKER:
        stickers = {"color": sticker_color("blue" if color is None else color),
                    "anchors": None if anchors is None else sticker_anchors(
                        [a.strip() for a in anchors.split(",") if a.strip()])}
    elif color is not None or anchors is not None:
        raise RetargetError("'color' and 'anchors' are for method 'stereo' with layout '*' "
                            "(stickers of one colour)")
    if layout == EVERY_MARKER:
        layout = None  # the library's "no layout"
    else:
        chosen = resolve_layout(store, project["id"], layout)  # 422 for an unknown name
        if method == "markerless" and not chosen.has_mediapipe468:
            raise RetargetError(f"layout {layout!r} has points that are no face-mesh vertex: "
                                "markerless tracking cannot follow them; track markers, or upload "
                                "a take of them")
        if chosen.is_custom:
            layout = chosen  # pickled with its spec: the tracking child registers it
    scratch = _Scratch(store, limits.max_upload_bytes)
    try:
        if method == "stereo":
            run, answer = _stereo_tracker(scratch, isolation, file, right, calibration,
                                          (calibration_left, calibration_right),
                                          (pattern, cols, rows, square), layout, stickers)
        else:
            stray = [f for f, v in zip(STEREO_FIELDS, (right, calibration, calibration_left,
                                                       calibration_right)) if v is not None]
            if stray:
                raise RetargetError(f"{', '.join(stray)}: for method 'stereo', not {method!r}")
            if method == "markers":
                run, answer = _marker_tracker(scratch, isolation, file, layout), {}
            else:
                run, answer = _face_mesh_tracker(scratch, isolation, file, layout,
                                                 limits.max_video_frames), {}
        take_name = name or _default_name(file.filename, method)

        def work(job) -> tuple[str, dict]:
            try:
                take, preview = run(lambda done, total: job.report(done / total) if total else None)
            finally:
                scratch.remove()
            info = store.put_take(project["id"], take, name=take_name, preview=preview)
            meta = {k: take.meta[k] for k in JOB_META if k in take.meta}
            # a cut-off video still gives the frames up to the cut: the page says so
            cut_note = (f" (the video ends early: {info['n_frames']} of {meta['frames_claimed']} "
                        "frames)" if meta.get("truncated") else "")
            return (f"tracked {info['n_frames']} frames into take {info['name']!r}{cut_note}",
                    {"take": info["id"], "frames": info["n_frames"], **meta})

        job = jobs.start(project["id"], "track", work)
    except JobBusy as exc:
        scratch.remove()
        raise HTTPException(status.HTTP_409_CONFLICT, str(exc)) from exc
    except BaseException:
        scratch.remove()
        raise
    return {**job.as_json(), **answer}


class _Scratch:
    """Uploads written to the scratch folder, for the library to read by path; `names`
    maps each path to its upload's file name. `remove()` deletes them all."""

    def __init__(self, store, max_bytes: int):
        self.store, self.max_bytes = store, max_bytes
        self.names: dict[Path, str] = {}

    def save(self, upload: UploadFile, allowed, what: str) -> Path:
        """The path of `upload` saved; 415 for an extension not in `allowed`, 413 when over
        the size limit, 422 when empty."""
        ext = upload_extension(upload.filename, allowed)
        data = read_capped(upload, self.max_bytes)
        shown = (upload.filename or what).replace("\\", "/").rsplit("/", 1)[-1]
        if not data:
            raise RetargetError(f"the uploaded {what} {shown!r} is empty")
        path = self.store.scratch_file(ext)
        self.names[path] = shown
        path.write_bytes(data)
        return path

    def remove(self) -> None:
        for path in self.names:
            path.unlink(missing_ok=True)


def _marker_tracker(scratch: _Scratch, isolation, video: UploadFile, layout: str | Layout | None):
    """The marker job's work, ``run(progress) -> (take, first-frame JPEG)``, once the
    video opens (layout None: every marker in view). Videos are decoded by FFmpeg, and
    the preview encoded by OpenCV, so both run in a child process (`server.isolation`)."""
    path = scratch.save(video, VIDEO_EXTENSIONS, "video")
    what = f"video {scratch.names[path]!r} refused: not a readable video"
    isolation.call(video_opens, path, scratch.names, what=what)

    def run(progress) -> tuple[Take, bytes]:
        tracked = isolation.call(marker_take, path, layout, scratch.names, what=what,
                                 progress=progress, job=True)
        return tracked.take, tracked.preview

    return run


def _face_mesh_tracker(scratch: _Scratch, isolation, video: UploadFile, layout: str,
                       max_frames: int):
    """The markerless job's work, ``run(progress) -> (take, None)``, once the video opens and its
    header claims at most `max_frames` frames (`Limits.max_video_frames`); as for markers,
    FFmpeg decodes it in a child process."""
    path = scratch.save(video, VIDEO_EXTENSIONS, "video")
    what = f"video {scratch.names[path]!r} refused: not a readable video"
    isolation.call(video_opens, path, scratch.names, max_frames, what=what)

    def run(progress) -> tuple[Take, None]:
        return isolation.call(face_mesh_take, path, layout, max_frames, scratch.names, what=what,
                              progress=progress, job=True), None

    return run


def _stereo_tracker(scratch: _Scratch, isolation, left: UploadFile, right: UploadFile | None,
                    calibration: UploadFile | None, boards: tuple, pattern: tuple, layout,
                    stickers: dict | None):
    """The stereo job's work, ``run(progress) -> (take, None)``, once everything that can be
    checked before tracking is (see the module docstring, `retarget.sources.stereo.stereo_pair_calibration`);
    and the answer's extras. `stickers` ``{"color", "anchors"}`` with layout None: unnamed
    stickers of one colour."""
    _require_stereo_fields(right, calibration, boards, pattern)
    videos = [scratch.save(left, VIDEO_EXTENSIONS, "left video"),
              scratch.save(right, VIDEO_EXTENSIONS, "right video")]
    cal_file = board_videos = None
    if calibration is not None:
        cal_file = scratch.save(calibration, CALIBRATION_EXTENSIONS, "calibration file")
    else:
        board_videos = [scratch.save(v, VIDEO_EXTENSIONS, f"{side} checkerboard video")
                        for v, side in zip(boards, ("left", "right"))]
    what = (f"the stereo pair {scratch.names[videos[0]]!r} and {scratch.names[videos[1]]!r} "
            "refused: not readable videos or calibration")
    color = "blue" if stickers is None else stickers["color"]
    cal, source = isolation.call(stereo_calibration, videos, cal_file, board_videos, pattern,
                                 layout, scratch.names, color, what=what)

    def run(progress) -> tuple[Take, None]:
        return isolation.call(stereo_take, videos, cal, layout, scratch.names, stickers, what=what,
                              progress=progress, job=True), None

    views = cal.meta.get("views")
    return run, {"calibration": {"source": source, "rms": cal.rms, "baseline": cal.baseline,
                                 "size": list(cal.size), "views": views}}


def _require_stereo_fields(right, calibration, boards, pattern) -> None:
    if right is None:
        raise RetargetError("method 'stereo' needs two videos: the left camera's as 'file' and "
                            "the right camera's as 'right', which is missing")
    given = [b is not None for b in boards]
    if calibration is not None:
        if any(given):
            raise RetargetError("give the stereo calibration as a file ('calibration') or as "
                                "checkerboard videos ('calibration_left', 'calibration_right'), "
                                "not both")
        return
    if not any(given):
        raise RetargetError("method 'stereo' needs the cameras' calibration: a .npz as "
                            "'calibration' (from `retarget calibrate`), or both cameras' videos "
                            "of a checkerboard as 'calibration_left' and 'calibration_right' "
                            "with its cols, rows and square")
    if not all(given):
        missing = "calibration_right" if given[0] else "calibration_left"
        raise RetargetError(f"a checkerboard calibration needs a video from each camera; "
                            f"{missing!r} is missing")
    absent = [n for n, v in zip(("cols", "rows", "square"), pattern[1:]) if v is None]
    if absent:
        raise RetargetError(f"a checkerboard calibration needs the pattern's {', '.join(absent)} "
                            "(inner corners per row and per column, square side in mm)")
    pattern_points(pattern)  # refuses a malformed pattern before any upload is read


@router.get("/{take_id}")
def get_take(project: ProjectDep, store: StoreDep, take_id: str) -> dict:
    return store.take_info(project["id"], take_id)


@router.get("/{take_id}/points", response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}}}})
def get_take_points(project: ProjectDep, store: StoreDep, take_id: str) -> Response:
    """The trimmed take's points as a NumPy .npy file: (F, N, D) float32, NaN where lost."""
    take = store.take(project["id"], take_id)
    buffer = io.BytesIO()
    np.save(buffer, np.asarray(take.points, dtype="<f4"))
    return Response(buffer.getvalue(), media_type="application/octet-stream",
                    headers={"Content-Disposition": f'attachment; filename="take-{take_id}.npy"'})


@router.get("/{take_id}/calibration", response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}}}})
def get_take_calibration(project: ProjectDep, store: StoreDep, take_id: str) -> Response:
    """The stereo calibration a stereo take was tracked with, as the .npz `retarget
    calibrate` writes: upload it with the next pairs from the same cameras. 404 for a take
    that has none."""
    take = store.take(project["id"], take_id, trimmed=False)
    if "calibration" not in take.meta:
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            f"take {take_id!r} has no stereo calibration: only takes tracked "
                            "from a stereo pair here carry one")
    buffer = io.BytesIO()
    StereoCalibration.from_dict(take.meta["calibration"]).save(buffer)
    return Response(buffer.getvalue(), media_type="application/octet-stream",
                    headers={"Content-Disposition":
                             f'attachment; filename="calibration-{take_id}.npz"'})


@router.get("/{take_id}/preview", response_class=Response,
            responses={200: {"content": {"image/jpeg": {}}}})
def get_take_preview(project: ProjectDep, store: StoreDep, take_id: str) -> Response:
    """The first frame of the video a ring-marker take was tracked from, a JPEG at most
    640 px wide; 404 for a take that has none (files, markerless and stereo takes)."""
    jpeg = store.take_preview(project["id"], take_id)
    if jpeg is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, _NO_PREVIEW.format(take_id))
    return Response(jpeg, media_type="image/jpeg")


@router.get("/{take_id}/preview/markers")
def get_take_preview_markers(project: ProjectDep, store: StoreDep, take_id: str) -> dict:
    """Where each of a ring-marker take's columns is on its first frame:
    ``{size: [width, height], markers: [{name, x, y}]}`` in the video's pixels (x right,
    y down, as in the image; the preview is the frame scaled to at most 640 px wide), x
    and y null for a marker not seen there. 404 for a take that has no preview."""
    take = store.take(project["id"], take_id, trimmed=False)
    places = take.meta.get("first_frame")
    if places is None or store.take_preview(project["id"], take_id) is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, _NO_PREVIEW.format(take_id))
    markers = []
    for name, xy in zip(take.names, places):
        x, y = xy or (None, None)
        markers.append({"name": name, "x": x, "y": y})
    return {"size": take.meta["size"], "markers": markers}


_NO_PREVIEW = ("take {!r} has no first-frame preview: only takes tracked here from a "
               "ring-marker video have one")


class TakePatch(BaseModel):
    name: str | None = Field(default=None, min_length=1, max_length=200, pattern=r"\S")
    trim: tuple[Number, Number | None] | None = Field(
        default=None, description="[start, stop] in seconds from the first frame; stop null = end")


@router.patch("/{take_id}")
def patch_take(project: ProjectDep, store: StoreDep, take_id: str, body: TakePatch) -> dict:
    """Rename and/or trim (non-destructive: the frames are kept, the span is stored)."""
    info = store.take_info(project["id"], take_id)
    trim = body.trim
    if trim is not None:
        start, stop = trim
        end = info["duration"]
        if not (math.isfinite(start) and 0 <= start <= end):
            raise RetargetError(f"trim start must be within [0, {end:.3f}] s; got {start}")
        if stop is not None and not (math.isfinite(stop) and start < stop <= end + 1e-9):
            raise RetargetError(f"trim stop must be after the start ({start}) and at most "
                                f"{end:.3f} s; got {stop}")
    return store.update_take(project["id"], take_id,
                             name=None if body.name is None else body.name.strip(), trim=trim)


@router.delete("/{take_id}", status_code=status.HTTP_204_NO_CONTENT)
def delete_take(project: ProjectDep, store: StoreDep, take_id: str) -> Response:
    store.delete_take(project["id"], take_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
