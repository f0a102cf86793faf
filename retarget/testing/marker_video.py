"""Marker videos of the built-in face with ground truth, for testing and benchmarking trackers.

The performer is `retarget.sample_face.sample_face` playing `demo_weights` (talking,
surprise, smiles, blinks, ...) under a known smooth rigid head motion, with markers glued
at the vertices of a layout's points, filmed by one or more `Camera`s. Each camera's frames
go to a video file (the codec follows the suffix), and the truth (3D marker positions,
their projections, visibility, head motion, expression weights) to an ``.npz`` beside it.
Everything is deterministic for a given seed.
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
from retarget.testing.render import render_face

__all__ = [
    "CODECS",
    "GroundTruth",
    "marker_vertices",
    "head_motion",
    "default_camera",
    "render_marker_video",
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
    fps : frame rate; layout : layout name; style : marker style.
    head_rotation : (F, 3, 3) float64 and head_translation : (F, 3) float64: the rigid
        motion, world = R @ posed + t (posed = the face in its own frame).
    weights : (F, E) float64 expression weights (`EXPRESSION_NAMES` order).
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
    layout: str
    style: str
    head_rotation: np.ndarray
    head_translation: np.ndarray
    weights: np.ndarray

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
            weights=self.weights, meta=np.array(json.dumps(meta)))

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
    """
    import cv2

    path = Path(path)
    if path.suffix.lower() not in CODECS:
        raise RetargetError(f"video path {path} must end in one of {tuple(CODECS)}")
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or n_frames < 1:
        raise RetargetError(f"n_frames must be a positive integer, got {n_frames!r}")
    cams, names = _cameras(cameras, scale)
    face = sample_face(resolution)
    verts = marker_vertices(face, layout)
    weights = demo_weights(n_frames + int(round(start * fps)), fps)[-n_frames:]
    R, t = _head_motion(head_motion, n_frames, fps, seed)
    videos = [str(path)] if len(cams) == 1 and names == ["cam0"] else [
        str(path.with_name(f"{path.stem}_{name}{path.suffix}")) for name in names]
    fourcc = cv2.VideoWriter_fourcc(*CODECS[path.suffix.lower()])
    writers = [cv2.VideoWriter(v, fourcc, float(fps), cam.size) for v, cam in zip(videos, cams)]
    for v, writer in zip(videos, writers):
        if not writer.isOpened():
            raise RetargetError(f"cannot write video {v} (codec {CODECS[path.suffix.lower()]})")
    rng = np.random.default_rng(seed)
    n_cam, n_pts = len(cams), len(verts)
    points3d = np.empty((n_frames, n_pts, 3))
    points2d = np.empty((n_frames, n_cam, n_pts, 2))
    visible = np.empty((n_frames, n_cam, n_pts), dtype=bool)
    coverage = np.empty((n_frames, n_cam, n_pts))
    try:
        for i in range(n_frames):
            world = (posed_vertices(face, weights[i]) @ R[i].T + t[i]) * scale
            points3d[i] = world[verts]
            for c, (cam, writer) in enumerate(zip(cams, writers)):
                frame = render_face(
                    cam, world, face.faces, verts, style=style, marker_radius=marker_radius * scale,
                    dot_radius=dot_radius * scale, marker_colors=colors, noise=noise, rng=rng)
                writer.write(frame.image)
                points2d[i, c], visible[i, c], coverage[i, c] = frame.points2d, frame.visible, frame.coverage
    finally:
        for writer in writers:
            writer.release()
    truth = GroundTruth(
        points3d, points2d, visible, coverage, verts, get_layout(layout).point_names, tuple(cams),
        tuple(names), tuple(videos), float(fps), layout, style, R, t * scale, weights)
    truth.save(path.with_suffix(".npz"))
    return truth


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
