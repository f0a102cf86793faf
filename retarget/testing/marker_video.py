"""Marker videos of the built-in face with ground truth, for testing and benchmarking trackers.

The performer is `retarget.sample_face.sample_face` playing `demo_weights` (talking,
surprise, smiles, blinks, ...) under a known smooth rigid head motion, with markers glued
at the vertices of a layout's points, filmed by one or more `Camera`s. Each camera's frames
go to a video file (the codec follows the suffix), and the truth (3D marker positions,
their projections, visibility, head motion, expression weights) to an ``.npz`` beside it.
Everything is deterministic for a given seed.

`render_webcam_marker_video` makes the hard material of issue 17: Dutreve et al. 2008 §5's
own set-up as someone else would film it (a 640x480 webcam at about 60 cm, 3 mm markers
about 5 px across, larger head turns, a lighting gradient, motion blur, noise, JPEG and
MPEG-4 compression, a finger over one marker in the first frames, 24 markers that match
no built-in layout), through `Footage` applied to each rendered frame.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.sample_face import SampleFace, demo_weights, posed_vertices, sample_face
from retarget.testing.camera import Camera, look_at
from retarget.testing.render import render_face, vertex_normals

__all__ = [
    "CODECS",
    "GroundTruth",
    "marker_vertices",
    "head_motion",
    "default_camera",
    "render_marker_video",
    "Footage",
    "webcam_camera",
    "webcam_marker_vertices",
    "render_webcam_marker_video",
    "unnamed_track_scores",
]

CODECS = {".avi": "MJPG", ".mp4": "mp4v", ".mkv": "FFV1"}
"""Video suffix -> FourCC written by `render_marker_video` (FFV1 is lossless)."""

_LID_OFFSET = 0.5   # cm: lid markers sit this far from the lid margin (see marker_vertices)
_PIVOT = np.array([0.0, -6.0, 2.0])   # cm: head rotations turn about the neck, behind the chin


@dataclass(frozen=True, eq=False)
class GroundTruth:
    """What a marker video shows, frame by frame.

    points3d : (F, N, 3) float64 marker centres in world units (cm x `scale`).
    points2d : (F, C, N, 2) float64 their projections in each camera (pixels, x right, y down).
    visible : (F, C, N) bool: the whole marker is drawn, facing the camera (see `FaceRender`).
    coverage : (F, C, N) float64 share of each marker's disc that is drawn.
    marker_vertices : (N,) int64 sample-face vertices carrying the markers.
    names : (N,) the layout's point names, in its order.
    cameras : (C,) the cameras; camera_names : (C,) their names (file suffixes).
    videos : (C,) paths of the written videos.
    fps : frame rate; layout : layout name (None for markers placed by vertex); style :
        marker style.
    head_rotation : (F, 3, 3) float64 and head_translation : (F, 3) float64: the rigid
        motion, world = R @ posed + t (posed = the face in its own frame).
    weights : (F, E) float64 expression weights (`EXPRESSION_NAMES` order).
    facing : (F, C, N) float64 cosine of the angle between each marker's normal and its
        line of sight to the camera (1 head-on; `visible` needs > 0.3, 73 degrees), or
        None in truth files written before it was recorded.
    """

    points3d: np.ndarray
    points2d: np.ndarray
    visible: np.ndarray
    coverage: np.ndarray
    marker_vertices: np.ndarray
    names: tuple[str, ...]
    cameras: tuple[Camera, ...]
    camera_names: tuple[str, ...]
    videos: tuple[str, ...]
    fps: float
    layout: str | None
    style: str
    head_rotation: np.ndarray
    head_translation: np.ndarray
    weights: np.ndarray
    facing: np.ndarray | None = None

    def save(self, path: str | Path) -> None:
        """Write the truth to an ``.npz`` (arrays, plus JSON for names and cameras)."""
        meta = {
            "names": list(self.names), "cameras": [c.to_dict() for c in self.cameras],
            "camera_names": list(self.camera_names), "videos": list(self.videos),
            "fps": self.fps, "layout": self.layout, "style": self.style,
        }
        np.savez_compressed(
            path, points3d=self.points3d, points2d=self.points2d, visible=self.visible,
            coverage=self.coverage, marker_vertices=self.marker_vertices,
            head_rotation=self.head_rotation, head_translation=self.head_translation,
            weights=self.weights, meta=np.array(json.dumps(meta)),
            **({} if self.facing is None else {"facing": self.facing}))

    @classmethod
    def load(cls, path: str | Path) -> GroundTruth:
        """The truth `save` wrote; RetargetError if `path` is not such a file."""
        try:
            with np.load(path) as d:
                meta = json.loads(str(d["meta"]))
                arrays = {k: d[k] for k in d.files if k != "meta"}
        except (OSError, KeyError, ValueError) as exc:
            raise RetargetError(f"{path} is not a marker-video ground truth file: {exc}") from None
        return cls(
            names=tuple(meta["names"]), cameras=tuple(Camera.from_dict(c) for c in meta["cameras"]),
            camera_names=tuple(meta["camera_names"]), videos=tuple(meta["videos"]),
            fps=float(meta["fps"]), layout=meta["layout"], style=meta["style"], **arrays)


@dataclass(frozen=True)
class Footage:
    """How a rendered frame is spoilt into other people's footage (`render_marker_video`).

    In the order a camera does it:
    gradient : uneven light, the log of the gain per 100 px along a seeded direction
        (0.25: one side of a 140 px face 1.4 times brighter than the other).
    shutter : exposure time over the frame interval; each frame is blurred along the
        markers' median image motion since the previous frame times this (a symmetric
        line kernel, so a marker's blurred centroid stays its mid-exposure position).
    noise : Gaussian sensor noise, grey levels (`render_marker_video`'s own noise is not
        added when footage is given).
    jpeg_quality : each frame goes through JPEG at this quality (8x8 DCT blocks, chroma
        subsampling: the artefacts of a low bit-rate MPEG-4 stream, whose rate OpenCV's
        writer does not let one set) before the video codec; None to skip.
    occluder : (marker index, frames): a skin-coloured finger tip (an ellipse of
        `occluder_radius` px) covers that marker from the first frame and slides off by
        the given frame; the truth marks the marker hidden while any of it is covered.
    blur : lens blur, the sigma (px) of a Gaussian applied with the motion blur (0: none).
    """

    gradient: float = 0.25
    shutter: float = 0.5
    noise: float = 3.0
    jpeg_quality: int | None = 30
    occluder: tuple[int, int] | None = None
    occluder_radius: float = 9.0
    blur: float = 0.0

    def apply(self, image: np.ndarray, motion: np.ndarray, rng: np.random.Generator,
              frame: int, points2d: np.ndarray, radius_px: np.ndarray, direction: np.ndarray):
        """(image (h, w, 3) uint8, hidden (N,) bool): one rendered frame (h, w, 3) uint8
        spoilt; motion (2,) px the image moved since the last frame; points2d (N, 2) the
        markers' projections and radius_px (N,) their outer radii in pixels; direction (2,)
        unit vector of the light gradient."""
        import cv2

        h, w = image.shape[:2]
        img = image.astype(np.float32)
        if self.gradient:
            ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
            along = ((xs - w / 2) * direction[0] + (ys - h / 2) * direction[1]) / 100.0
            img *= np.exp(self.gradient * along)[..., None]
        hidden = np.zeros(len(points2d), dtype=bool)
        if self.occluder is not None and frame < self.occluder[1]:
            k, frames = self.occluder
            # slides off up-right: centred on the marker at frame 0, clear of it by `frames`
            step = (self.occluder_radius + radius_px[k] + 2.0) * frame / max(frames - 1, 1)
            centre = points2d[k] + step * np.array([0.6, -0.8])
            hidden = np.linalg.norm(points2d - centre, axis=1) < self.occluder_radius + radius_px + 0.5
            mask = np.zeros((h, w), np.float32)
            axes = (int(round(self.occluder_radius * 1.25)), int(round(self.occluder_radius)))
            cv2.ellipse(mask, (int(round(centre[0] * 4)), int(round(centre[1] * 4))),
                        (axes[0] * 4, axes[1] * 4), 30.0, 0, 360, 1.0, -1, cv2.LINE_AA, 2)
            finger = np.array([125.0, 155.0, 205.0], np.float32) * 0.9
            img = img * (1.0 - mask[..., None]) + finger * mask[..., None]
        length = self.shutter * float(np.hypot(*motion))
        if length > 0.5:
            kernel = _line_kernel(length, np.arctan2(motion[1], motion[0]))
            img = cv2.filter2D(img, -1, kernel, borderType=cv2.BORDER_REPLICATE)
        if self.blur > 0:
            img = cv2.GaussianBlur(img, (0, 0), self.blur)
        if self.noise > 0:
            img += rng.normal(0.0, self.noise, img.shape).astype(np.float32)
        out = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        if self.jpeg_quality is not None:
            ok, data = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(self.jpeg_quality)])
            out = cv2.imdecode(data, cv2.IMREAD_COLOR)
        return out, hidden


def _line_kernel(length: float, angle: float) -> np.ndarray:
    """A normalised, symmetric, anti-aliased line kernel `length` px long at `angle` rad."""
    n = int(np.ceil(length / 2)) + 1
    ys, xs = np.mgrid[-n:n + 1, -n:n + 1].astype(np.float64)
    c, s = np.cos(angle), np.sin(angle)
    along, across = xs * c + ys * s, -xs * s + ys * c
    k = np.clip(length / 2 + 0.5 - np.abs(along), 0, 1) * np.clip(1.0 - np.abs(across), 0, 1)
    return (k / k.sum()).astype(np.float32)


def marker_vertices(face: SampleFace, layout: str = "dutreve21", lid_offset: float = _LID_OFFSET) -> np.ndarray:
    """(N,) int64 vertices where the markers of `layout`'s points are glued.

    Each point's landmark vertex, except on the eyelids: a marker there would cover the
    lid margin and touch its partner when the eye closes, so lid markers go `lid_offset`
    cm up the upper lid and down the lower lid (the vertex nearest that spot on the
    neutral face), where a real one would be stuck.
    """
    lay = get_layout(layout)
    lids = {37: 1, 38: 1, 43: 1, 44: 1, 40: -1, 41: -1, 46: -1, 47: -1}
    out = face.landmarks68[list(lay.ibug68)].copy()
    for k, i68 in enumerate(lay.ibug68):
        if i68 in lids:
            spot = face.vertices[out[k]] + [0.0, lids[i68] * lid_offset, 0.0]
            out[k] = np.argmin(np.linalg.norm(face.vertices - spot, axis=1))
    return out


def head_motion(n_frames: int, fps: float = 30.0, seed: int = 0, amplitude: float = 1.0):
    """A smooth rigid head motion: (R (F, 3, 3), t (F, 3)) float64, world = R @ p + t (cm).

    Sums of two sines per axis with seeded phases and frequencies of 0.1-0.4 Hz: yaw up to
    about 8 degrees, pitch 5, roll 3, translation 1.2 / 0.8 / 1.5 cm (x / y / z), all times
    `amplitude`; rotations turn about a neck pivot behind the chin.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames) / float(fps)
    freq = rng.uniform(0.1, 0.4, (6, 2))
    phase = rng.uniform(0, 2 * np.pi, (6, 2))
    wave = np.sin(2 * np.pi * freq[:, :, None] * t + phase[:, :, None]).mean(1)   # (6, F)
    scale = amplitude * np.array([np.radians(8), np.radians(5), np.radians(3), 1.2, 0.8, 1.5])
    yaw, pitch, roll, tx, ty, tz = wave * scale[:, None]
    R = _rotation_y(yaw) @ _rotation_x(pitch) @ _rotation_z(roll)
    t_world = _PIVOT - R @ _PIVOT + np.stack([tx, ty, tz], 1)
    return R, t_world


def default_camera(size: tuple[int, int] = (640, 480), scale: float = 1.0) -> Camera:
    """A frontal camera 54 cm from the face (x `scale` in world units), framing the head."""
    target = np.array([0.0, 1.0, 8.0]) * scale
    return look_at(target + [0.0, 0.0, 54.0 * scale], target, (0.0, 1.0, 0.0), 24.0, size)


def render_marker_video(
    path: str | Path,
    *,
    n_frames: int,
    fps: float = 30.0,
    cameras: Camera | Sequence[Camera] | Mapping[str, Camera] | None = None,
    style: str = "ring",
    layout: str = "dutreve21",
    head_motion: bool | tuple[np.ndarray, np.ndarray] = True,
    seed: int = 0,
    start: float = 0.0,
    scale: float = 1.0,
    marker_radius: float = 0.3,
    dot_radius: float = 0.15,
    colors: np.ndarray | None = None,
    noise: float = 2.0,
    resolution: int = 1,
    vertices: np.ndarray | None = None,
    pace: float = 1.0,
    footage: Footage | None = None,
    face: SampleFace | None = None,
) -> GroundTruth:
    """Render the marker performance to video(s) and return (and save) its ground truth.

    path : the video file (suffix in `CODECS`). With several cameras, camera k's video is
        ``<stem>_<name><suffix>`` (names "cam0", "cam1", ... or the mapping's keys); the
        truth goes to ``<path minus suffix>.npz``.
    cameras : one camera, several, or {name: camera}; default `default_camera`.
    style : "ring" (Dutreve §5) or "color" (Woodward §5), see `render_face`.
    layout : which points carry markers (see `marker_vertices`).
    head_motion : True for `head_motion(n_frames, fps, seed)`, False for none, or an
        explicit (R (F, 3, 3), t (F, 3) in cm of the face).
    seed : head motion phases and sensor noise; start : seconds into the demo loop.
    scale : world units per cm of the face (10 gives mm); the cameras are in world units.
    marker_radius, dot_radius : cm on the face; colors : (N, 3) BGR for "color".
    noise : Gaussian sensor noise, grey levels; resolution : sample-face resolution.
    vertices : (N,) int sample-face vertices carrying the markers instead of `layout`'s
        (the truth's layout is then None and its names m01..mN).
    pace : demo seconds per second of video (3 plays the demo loop three times as fast:
        more expressions in a short clip, faster motion).
    footage : spoil each frame as other people's footage is (`Footage`), after rendering.
    face : the performer (any `SampleFace`: vertices in cm, +y up, +z out, with shapes
        named as `EXPRESSION_NAMES`), default `sample_face(resolution)`.
    """
    import cv2

    path = Path(path)
    if path.suffix.lower() not in CODECS:
        raise RetargetError(f"video path {path} must end in one of {tuple(CODECS)}")
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or n_frames < 1:
        raise RetargetError(f"n_frames must be a positive integer, got {n_frames!r}")
    cams, names = _cameras(cameras, scale)
    face = sample_face(resolution) if face is None else face
    if vertices is None:
        verts = marker_vertices(face, layout)
        point_names = get_layout(layout).point_names
    else:
        verts = np.asarray(vertices, dtype=np.int64).reshape(-1)
        layout = None
        point_names = tuple(f"m{k + 1:02d}" for k in range(len(verts)))
    if not (np.isfinite(pace) and pace > 0):
        raise RetargetError(f"pace must be a positive number, got {pace!r}")
    weights = demo_weights(n_frames + int(round(start * fps)), fps / pace)[-n_frames:]
    R, t = _head_motion(head_motion, n_frames, fps, seed)
    videos = [str(path)] if len(cams) == 1 and names == ["cam0"] else [
        str(path.with_name(f"{path.stem}_{name}{path.suffix}")) for name in names]
    fourcc = cv2.VideoWriter_fourcc(*CODECS[path.suffix.lower()])
    writers = [cv2.VideoWriter(v, fourcc, float(fps), cam.size) for v, cam in zip(videos, cams)]
    for v, writer in zip(videos, writers):
        if not writer.isOpened():
            raise RetargetError(f"cannot write video {v} (codec {CODECS[path.suffix.lower()]})")
    rng = np.random.default_rng(seed)
    light = np.random.default_rng(seed + 7919).normal(size=2)
    light /= np.linalg.norm(light)
    n_cam, n_pts = len(cams), len(verts)
    points3d = np.empty((n_frames, n_pts, 3))
    points2d = np.empty((n_frames, n_cam, n_pts, 2))
    visible = np.empty((n_frames, n_cam, n_pts), dtype=bool)
    coverage = np.empty((n_frames, n_cam, n_pts))
    facing = np.empty((n_frames, n_cam, n_pts))
    try:
        for i in range(n_frames):
            world = (posed_vertices(face, weights[i]) @ R[i].T + t[i]) * scale
            points3d[i] = world[verts]
            normals = vertex_normals(world, face.faces)[verts]
            for c, (cam, writer) in enumerate(zip(cams, writers)):
                frame = render_face(
                    cam, world, face.faces, verts, style=style, marker_radius=marker_radius * scale,
                    dot_radius=dot_radius * scale, marker_colors=colors,
                    noise=noise if footage is None else 0.0, rng=rng)
                points2d[i, c], visible[i, c], coverage[i, c] = frame.points2d, frame.visible, frame.coverage
                sight = cam.center - points3d[i]
                facing[i, c] = np.einsum("nk,nk->n", normals, sight) / np.linalg.norm(sight, axis=1)
                image = frame.image
                if footage is not None:
                    moved = np.median(points2d[i, c] - points2d[max(i - 1, 0), c], axis=0)
                    radius_px = cam.K[0, 0] * marker_radius * scale / cam.depth(points3d[i])
                    image, hidden = footage.apply(image, moved, rng, i, points2d[i, c], radius_px, light)
                    visible[i, c] &= ~hidden
                    coverage[i, c][hidden] = 0.0
                writer.write(image)
    finally:
        for writer in writers:
            writer.release()
    truth = GroundTruth(
        points3d, points2d, visible, coverage, verts, point_names, tuple(cams),
        tuple(names), tuple(videos), float(fps), layout, style, R, t * scale, weights, facing)
    truth.save(path.with_suffix(".npz"))
    return truth


def webcam_camera(distance: float = 60.0, hfov_deg: float = 60.0, size: tuple[int, int] = (640, 480)) -> Camera:
    """A webcam `distance` cm in front of the sample face (a 60 degree horizontal field, the
    usual 640x480 webcam's): 3 mm marker radius is about 2.8 px at 60 cm (Dutreve §5)."""
    w, h = size
    vfov = 2.0 * np.degrees(np.arctan(np.tan(np.radians(hfov_deg) / 2) * h / w))
    target = np.array([0.0, 1.0, 8.0])
    return look_at(target + [0.0, 0.0, float(distance)], target, (0.0, 1.0, 0.0), vfov, size)


def webcam_marker_vertices(face: SampleFace) -> np.ndarray:
    """(24,) int64 vertices for 24 markers: `marker_vertices` of dutreve21 plus the nose
    bridge (iBUG 27) and one marker on each cheek (halfway between iBUG 2 and 31, 14 and
    35), a count no built-in layout has."""
    base = marker_vertices(face, "dutreve21")
    lm = face.vertices[face.landmarks68]
    spots = np.stack([lm[27], 0.5 * (lm[2] + lm[31]), 0.5 * (lm[14] + lm[35])])
    extra = np.linalg.norm(face.vertices[None] - spots[:, None], axis=2).argmin(1)
    return np.concatenate([base, extra]).astype(np.int64)


def render_webcam_marker_video(
    path: str | Path,
    *,
    n_frames: int = 48,
    seed: int = 0,
    distance: float = 60.0,
    marker_radius: float = 0.3,
    dot_radius: float = 0.15,
    amplitude: float = 2.2,
    pace: float = 2.0,
    start: float = 1.2,
    footage: Footage | None = None,
    occluded: int = 21,
    occluded_frames: int = 8,
    face: SampleFace | None = None,
) -> GroundTruth:
    """Issue 17's hard mono material: `render_marker_video` with `webcam_camera(distance)`,
    the 24 `webcam_marker_vertices`, head motion `amplitude` times `head_motion`'s (2.2:
    yaw up to about 18 degrees, pitch 11, roll 7, so that side markers turn oblique), the
    demo played at `pace` from `start` s (48 frames at pace 3: talking, a pucker, a blink,
    surprise, another blink and the start of a smile), and `footage` (default: `Footage()`
    with marker `occluded` under a finger for the first `occluded_frames` frames); `face`
    as `render_marker_video`'s. Suffix .mp4 (MPEG-4 Part 2) for the compressed stream.
    Returns the ground truth."""
    fps = 30.0
    face = sample_face(1) if face is None else face
    if footage is None:
        footage = Footage(occluder=(occluded, occluded_frames) if occluded_frames else None)
    motion = head_motion(n_frames, fps / pace, seed, amplitude)
    return render_marker_video(
        path, n_frames=n_frames, fps=fps, cameras=webcam_camera(distance), head_motion=motion,
        seed=seed, start=start, marker_radius=marker_radius, dot_radius=dot_radius,
        vertices=webcam_marker_vertices(face), pace=pace, footage=footage, face=face)


def _cameras(cameras, scale: float) -> tuple[list[Camera], list[str]]:
    if cameras is None:
        return [default_camera(scale=scale)], ["cam0"]
    if isinstance(cameras, Camera):
        return [cameras], ["cam0"]
    if isinstance(cameras, Mapping):
        return list(cameras.values()), [str(k) for k in cameras]
    cams = list(cameras)
    if not cams or not all(isinstance(c, Camera) for c in cams):
        raise RetargetError("cameras must be a Camera, a non-empty sequence of them or {name: Camera}")
    return cams, [f"cam{k}" for k in range(len(cams))]


def _head_motion(spec, n_frames: int, fps: float, seed: int):
    if spec is True:
        return head_motion(n_frames, fps, seed)
    if spec is False:
        return np.broadcast_to(np.eye(3), (n_frames, 3, 3)).copy(), np.zeros((n_frames, 3))
    R, t = (np.asarray(a, dtype=np.float64) for a in spec)
    if R.shape != (n_frames, 3, 3) or t.shape != (n_frames, 3):
        raise RetargetError(
            f"head_motion must be (R ({n_frames}, 3, 3), t ({n_frames}, 3)), got {R.shape} and {t.shape}")
    return R, t


def _rotation_x(a):
    c, s, z, o = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack([o, z, z, z, c, -s, z, s, c], -1).reshape(-1, 3, 3)


def _rotation_y(a):
    c, s, z, o = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack([c, z, s, z, o, z, -s, z, c], -1).reshape(-1, 3, 3)


def _rotation_z(a):
    c, s, z, o = np.cos(a), np.sin(a), np.zeros_like(a), np.ones_like(a)
    return np.stack([c, -s, z, s, c, z, z, z, o], -1).reshape(-1, 3, 3)


def unnamed_track_scores(points, truth: GroundTruth, facing: float = 0.5) -> dict:
    """How tracks of unnamed markers fare against the truth of the first camera.

    points : (F, M, 2) image pixels (x right, y down), NaN where a track has no point.
    facing : cosine between a marker's normal and the view under which it counts as seen
        clearly (0.5: within 60 degrees; an edge-on dot a few pixels across is a smudge).

    Each track is the truth marker it is nearest in most of its frames; an identity switch
    is a change of a track's nearest truth marker from one of its frames to the next. The
    errors are over the marker-frames the truth calls visible and facing the camera, a
    marker without a track there counting as lost (an infinite error). Returns a dict:
    found (set of truth markers with a track), wanted (set of those seen clearly in 5
    frames or more: a track needs 3 to be told from a skin feature), tracks (M), switches,
    median and p95 (px, lost included), within3 (share within 3 px), lost (share), oblique
    (share within 3 px of the visible marker-frames not facing the camera; NaN if none),
    err (F, N) each truth marker's distance to its track (the longest of those it owns;
    inf where that track has no point or the marker none), owner (M,) each track's truth
    marker (-1 for a track with no point).
    """
    p = np.asarray(points, dtype=np.float64)
    gt = truth.points2d[:, 0]
    clear = truth.visible[:, 0] & (truth.facing[:, 0] > facing)
    oblique = truth.visible[:, 0] & (truth.facing[:, 0] <= facing)
    d = np.linalg.norm(p[:, :, None] - gt[:, None], axis=3)              # (F, M, N)
    tracked = np.isfinite(p[..., 0])
    nearest = np.where(tracked, np.nan_to_num(d, nan=np.inf).argmin(2), -1)
    switches, owner = 0, np.full(p.shape[1], -1)
    for m in range(p.shape[1]):
        ids = nearest[tracked[:, m], m]
        switches += int((np.diff(ids) != 0).sum())
        if ids.size:
            owner[m] = np.bincount(ids).argmax()
    err = np.full(clear.shape, np.inf)
    for n in range(gt.shape[1]):
        mine = np.flatnonzero(owner == n)
        if mine.size:
            m = mine[tracked[:, mine].sum(0).argmax()]
            err[:, n] = np.where(tracked[:, m], d[:, m, n], np.inf)
    e = err[clear]
    return {
        "found": set(owner[owner >= 0].tolist()), "wanted": set(np.flatnonzero(clear.sum(0) >= 5).tolist()),
        "tracks": p.shape[1], "switches": switches, "median": float(np.median(e)),
        "p95": float(np.percentile(e, 95)), "within3": float((e < 3.0).mean()),
        "lost": float(np.isinf(e).mean()),
        "oblique": float((err[oblique] < 3.0).mean()) if oblique.any() else float("nan"),
        "err": err, "owner": owner,
    }
