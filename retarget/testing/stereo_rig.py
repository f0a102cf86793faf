"""A synthetic stereo webcam rig with known truth: colour-marker videos and calibration views.

Woodward et al., §3: two webcams (640 x 480) about 1 m from the performer, calibrated on a
target of known geometry, filming coloured stickers. Here both cameras are
`retarget.testing.camera.Camera`s in **millimetres** (the built-in face, in cm, is
scaled by 10), `distance` from the face along its viewing axis, `baseline` apart side by
side and verged on the face. The performance and its truth come from
`retarget.testing.marker_video.render_marker_video` (style "color"); the calibration
views from `retarget.testing.render.render_checkerboard`.

Naming follows stereo practice: the "left" camera is the one on the left as seen from
behind the cameras, which is on the subject's left (world +x); 3D results of
`retarget.sources.stereo` are in its frame.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from retarget.errors import RetargetError
from retarget.sample_face import SampleFace, sample_face
from retarget.sources.color_markers import layout_marker_colors
from retarget.sources.calibration import StereoCalibration
from retarget.sources.headpose import rigid_transform
from retarget.testing.camera import Camera, look_at
from retarget.testing.marker_video import (
    Footage,
    GroundTruth,
    head_motion as demo_head_motion,
    marker_vertices,
    render_marker_video,
)
from retarget.testing.render import MARKER_COLORS, render_checkerboard, render_face

__all__ = [
    "FACE_CENTRE",
    "MM_PER_CM",
    "stereo_cameras",
    "webcam_cameras",
    "webcam_look",
    "rig_calibration",
    "checkerboard_views",
    "render_stereo_video",
    "still_frames",
    "STICKER_NAMES",
    "STICKER_ANCHORS",
    "sticker_vertices",
    "sticker_head_motion",
    "render_sticker_video",
    "sticker_truth",
    "sticker_scores",
    "live_sticker_anchors",
]

MM_PER_CM = 10.0
"""World units (mm) per unit of the built-in face (cm)."""

FACE_CENTRE = np.array([0.0, 10.0, 80.0])
"""mm: the point the cameras verge on, between the eyes and the mouth near the nose."""


def stereo_cameras(
    distance: float = 1000.0,
    baseline: float = 150.0,
    fov_deg: float = 20.0,
    size: tuple[int, int] = (640, 480),
    dist: np.ndarray | None = None,
) -> tuple[Camera, Camera]:
    """(left, right) cameras `distance` mm in front of the face, `baseline` mm apart.

    Both look at `FACE_CENTRE` (verged), upright; `fov_deg` is the vertical field of view
    (20 degrees frames the head at 1 m: about 1360 px focal length at 640 x 480).
    dist : optional (5,) OpenCV distortion for both.
    """
    if not distance > 0 or not baseline > 0:
        raise RetargetError(f"distance and baseline must be > 0 mm, got {distance!r} and {baseline!r}")
    eye = FACE_CENTRE + [0.0, 0.0, float(distance)]
    half = np.array([0.5 * baseline, 0.0, 0.0])
    left = look_at(eye + half, FACE_CENTRE, (0.0, 1.0, 0.0), fov_deg, size, dist)
    right = look_at(eye - half, FACE_CENTRE, (0.0, 1.0, 0.0), fov_deg, size, dist)
    return left, right


def webcam_cameras(
    distance: float = 1000.0,
    baseline: float = 80.0,
    focal: float = 768.0,
    size: tuple[int, int] = (640, 480),
) -> tuple[Camera, Camera]:
    """(upper, lower) webcams one above the other, `baseline` mm apart and centred on a
    point `distance` mm in front of `FACE_CENTRE`, both looking towards it along parallel
    axes; `focal` px, square pixels, principal point at the image centre.

    The rig of a tester's report (issue 17): two 640 x 480 webcams stacked 8 cm apart at
    1 m. The upper one plays the "left" camera (camera 0) of `retarget.sources.stereo`.
    """
    if not distance > 0 or not baseline > 0 or not focal > 0:
        raise RetargetError(f"distance, baseline and focal must be > 0; got {distance!r}, "
                            f"{baseline!r}, {focal!r}")
    fov = 2 * np.degrees(np.arctan(0.5 * size[1] / focal))
    forward = np.array([0.0, 0.0, -float(distance)])
    half = np.array([0.0, 0.5 * baseline, 0.0])
    eyes = (FACE_CENTRE - forward + half, FACE_CENTRE - forward - half)
    return tuple(look_at(eye, eye + forward, (0.0, 1.0, 0.0), fov, size) for eye in eyes)


def webcam_look(image: np.ndarray, rng: np.random.Generator, poor: bool = False) -> np.ndarray:
    """(H, W, 3) uint8 BGR: a clean grey render (H, W, 3) uint8 (its first channel is
    used) as a cheap webcam delivers it.

    In order: lens blur (Gaussian, sigma 0.6-1 px), uneven light (exposure 0.6-1, a
    linear fall-off of up to 15 % either way from the centre to the edges, vignetting
    of 15 % at the corners, a black level up to 20), sensor noise (1.5-3.5 grey levels)
    and JPEG at quality 50-80 (what a webcam's MJPEG stream or a compressed clip
    leaves). `poor`: the view of a board moved too fast or badly lit: blur 1.8 times,
    light fall-off 1.6 times, noise 1.5 times, JPEG quality 35.
    """
    gray = cv2.GaussianBlur(image[..., 0].astype(np.float64), (0, 0),
                            rng.uniform(0.6, 1.0) * (1.8 if poor else 1.0))
    h, w = gray.shape
    y, x = np.mgrid[0:h, 0:w] / np.array([h, w], dtype=np.float64)[:, None, None] - 0.5
    a, b = rng.uniform(-0.3, 0.3, 2) * (1.6 if poor else 1.0)
    gain = rng.uniform(0.6, 1.0) * (1 + a * x + b * y) * (1 - 0.3 * (x**2 + y**2))
    gray = gray * gain + rng.uniform(0, 20)
    gray += rng.normal(0.0, rng.uniform(1.5, 3.5) * (1.5 if poor else 1.0), gray.shape)
    gray = np.clip(np.rint(gray), 0, 255).astype(np.uint8)
    quality = 35 if poor else int(rng.uniform(50, 80))
    _, jpeg = cv2.imencode(".jpg", gray, [cv2.IMWRITE_JPEG_QUALITY, quality])
    return cv2.cvtColor(cv2.imdecode(jpeg, cv2.IMREAD_GRAYSCALE), cv2.COLOR_GRAY2BGR)


def rig_calibration(left: Camera, right: Camera) -> StereoCalibration:
    """The exact `StereoCalibration` of two cameras (what a perfect calibration finds).

    R, T take left camera coordinates to right ones; E = [T]x R and F = K2^-T E K1^-1.
    """
    if left.size != right.size:
        raise RetargetError(f"the rig's cameras differ in size: {left.size} and {right.size}")
    rot = right.R @ left.R.T
    trans = right.t - rot @ left.t
    cross = np.array([[0.0, -trans[2], trans[1]], [trans[2], 0.0, -trans[0]],
                      [-trans[1], trans[0], 0.0]])
    essential = cross @ rot
    fundamental = np.linalg.inv(right.K).T @ essential @ np.linalg.inv(left.K)
    zero = np.zeros(5)
    return StereoCalibration(
        left.K, zero if left.dist is None else left.dist, right.K,
        zero if right.dist is None else right.dist, rot, trans, essential, fundamental,
        left.size, 0.0, {"source": "rig_calibration (exact)"})


def checkerboard_views(
    left: Camera,
    right: Camera,
    n_views: int = 20,
    *,
    rows: int = 6,
    cols: int = 9,
    square: float = 25.0,
    max_tilt: float = 40.0,
    poor: float | None = None,
    seed: int = 0,
) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray]:
    """Rendered view pairs of a checkerboard held in front of the rig, for calibration.

    The board (`rows` x `cols` inner corners, `square` mm) is placed at random, tilted
    up to `max_tilt` degrees about each in-plane axis, 0.75-1.15 times the rig's distance
    from it and spread over the shared field of view; a pose is kept only when every
    corner lies 10 px inside both images. Returns the left images, the right images
    (each (H, W, 3) uint8 BGR) and the corners' true world positions (V, rows * cols, 3)
    float64, mm.
    poor : None for clean renders; else each pair as webcams film it (`webcam_look`),
        this share of the pairs poor ones.
    """
    rng = np.random.default_rng(seed)
    centre = 0.5 * (left.center + right.center)
    axis = FACE_CENTRE - centre
    reach = np.linalg.norm(axis)
    axis /= reach
    up = np.array([0.0, 1.0, 0.0])
    side = np.cross(axis, up)
    half_h = 0.5 * left.size[1] / left.K[1, 1]  # tan of half the vertical field of view
    board = np.array([(cols - 1) * square, (rows - 1) * square]) / 2
    lefts, rights, corners = [], [], []
    for _ in range(200 * n_views):
        if len(lefts) == n_views:
            break
        depth = reach * rng.uniform(0.75, 1.15)
        spread = half_h * depth * np.array([left.size[0] / left.size[1], 1.0]) * 0.7
        offset = rng.uniform(-1, 1, 2) * spread
        origin = centre + depth * axis + offset[0] * side + offset[1] * up
        tilt = Rotation.from_euler("xyz", [*rng.uniform(-max_tilt, max_tilt, 2),
                                           rng.uniform(-15, 15)], degrees=True).as_matrix()
        # Board x along the image's x (world -x), y down the image, facing the cameras.
        facing = np.stack([-side, -up, -axis], 1) @ tilt
        t = origin - facing[:, :2] @ board
        pts = _board_points(rows, cols, square) @ facing.T + t
        if not all(_inside(cam.project(pts), cam.size, 10.0) for cam in (left, right)):
            continue
        bad = poor is not None and rng.uniform() < poor
        for cam, out in ((left, lefts), (right, rights)):
            image = render_checkerboard(cam, (facing, t), rows, cols, square).image
            out.append(image if poor is None else webcam_look(image, rng, bad))
        corners.append(pts)
    if len(lefts) < n_views:
        raise RetargetError(
            f"checkerboard_views: found only {len(lefts)} board poses visible to both cameras")
    return lefts, rights, np.stack(corners)


def _board_points(rows: int, cols: int, square: float) -> np.ndarray:
    j, i = np.meshgrid(np.arange(cols), np.arange(rows))
    return np.stack([j.ravel() * square, i.ravel() * square, np.zeros(rows * cols)], 1)


def _inside(px: np.ndarray, size: tuple[int, int], margin: float) -> bool:
    return bool(np.all(np.isfinite(px)) and np.all(px >= margin)
                and np.all(px <= np.array(size) - 1 - margin))


def render_stereo_video(
    path: str | Path,
    *,
    n_frames: int,
    fps: float = 30.0,
    cameras: tuple[Camera, Camera] | None = None,
    layout: str = "dutreve21",
    head_motion: bool | tuple[np.ndarray, np.ndarray] = True,
    marker_radius: float = 0.4,
    noise: float = 2.0,
    start: float = 0.0,
    seed: int = 0,
) -> GroundTruth:
    """A colour-marker performance filmed by the rig: two videos and their truth.

    path : video path (suffix in `retarget.testing.marker_video.CODECS`; ``.mkv`` is
        lossless); the videos are ``<stem>_left<suffix>`` and ``<stem>_right<suffix>``,
        the truth ``<stem>.npz``. Truth is in world mm (``points3d``), with the cameras.
    cameras : (left, right); default `stereo_cameras()`.
    layout : the points carrying stickers, coloured by `layout_marker_colors`.
    marker_radius : sticker radius in cm on the face (0.4: 8 mm stickers).
    head_motion, noise, start, seed : as `render_marker_video` (head motion in cm).
    """
    left, right = cameras if cameras is not None else stereo_cameras()
    colors = np.array([MARKER_COLORS[c] for c in layout_marker_colors(layout)], dtype=np.float64)
    return render_marker_video(
        path, n_frames=n_frames, fps=fps, cameras={"left": left, "right": right},
        style="color", layout=layout, head_motion=head_motion, seed=seed, start=start,
        scale=MM_PER_CM, marker_radius=marker_radius, colors=colors, noise=noise,
    )


def still_frames(
    n_frames: int,
    *,
    cameras: tuple[Camera, Camera] | None = None,
    layout: str = "dutreve21",
    marker_radius: float = 0.4,
    noise: float = 2.0,
    seed: int = 0,
) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """Stereo frames of the neutral face held still, differing only by sensor noise.

    The material of Woodward's jitter figure (§5: the spread of still markers' positions,
    before and after the temporal mean). Returns `n_frames` (left, right) BGR image pairs
    and the markers' true positions (N, 3) float64 in world mm.
    noise : Gaussian sensor noise, grey levels; other parameters as `render_stereo_video`.
    """
    if isinstance(n_frames, bool) or not isinstance(n_frames, (int, np.integer)) or n_frames < 1:
        raise RetargetError(f"n_frames must be a positive integer, got {n_frames!r}")
    left, right = cameras if cameras is not None else stereo_cameras()
    face = sample_face(1)
    world = face.vertices * MM_PER_CM
    verts = marker_vertices(face, layout)
    colors = np.array([MARKER_COLORS[c] for c in layout_marker_colors(layout)], dtype=np.float64)
    rng = np.random.default_rng(seed)
    # The scene does not change: render it once and add fresh noise per frame (which
    # differs from rendering each frame with noise only by one more rounding).
    clean = [render_face(cam, world, face.faces, verts, style="color",
                         marker_radius=marker_radius * MM_PER_CM, marker_colors=colors).image
             for cam in (left, right)]
    frames = [tuple(np.clip(np.rint(img + rng.normal(0.0, noise, img.shape)), 0, 255).astype(np.uint8)
                    for img in clean) for _ in range(n_frames)]
    return frames, world[verts]


STICKER_NAMES: tuple[str, ...] = (
    "temple_right", "temple_left", "forehead", "nose_bridge",
    "brow_right", "brow_left", "cheek_right", "cheek_left",
    "mouth_right", "mouth_left", "lip_upper", "lip_lower", "chin",
)
"""The 13 stickers of Woodward et al.'s set-up (§5, one colour), in truth order; the
first `STICKER_ANCHORS` are the head anchors of §5.1 (both temples, forehead, nose bridge).
"Right" is the subject's right (the face's -x)."""

STICKER_ANCHORS = 4


def sticker_vertices(face: SampleFace) -> np.ndarray:
    """(13,) int64 vertices of `face` carrying the `STICKER_NAMES` stickers.

    Temples 1 cm outward, 0.5 cm up and 2 cm back from the outer brow ends (on the side of
    the head: seen from the front at a grazing angle, and hidden when the head turns);
    forehead 4.5 cm above the nose root; nose bridge at iBUG 28; mid brows, cheeks (half way
    from the jaw line to the nose ala), mouth corners, chin; the lip stickers sit half way
    between the outer lip centres and the lip line, about 12 mm apart with the mouth shut
    (9 px at 1 m with a 768 px focal length: with blur they touch, one blob).
    """
    lm = face.vertices[face.landmarks68]
    spots = np.stack([
        lm[17] + [-1.0, 0.5, -2.0], lm[26] + [1.0, 0.5, -2.0],
        lm[27] + [0.0, 4.5, -1.0], lm[28],
        lm[19], lm[24], 0.5 * (lm[2] + lm[31]), 0.5 * (lm[14] + lm[35]),
        lm[48], lm[54], 0.5 * (lm[51] + lm[62]), 0.5 * (lm[57] + lm[66]),
        0.5 * (lm[57] + lm[8]),
    ])
    return np.linalg.norm(face.vertices[None] - spots[:, None], axis=2).argmin(1).astype(np.int64)


def sticker_head_motion(n_frames: int, fps: float = 30.0, seed: int = 0, yaw: float = 30.0,
                        period: float = 4.0):
    """(R (F, 3, 3), t (F, 3) cm) head motion of the sticker material: `head_motion`'s
    (amplitude 1.5: pitch up to about 8 degrees, roll 5, translation 2 cm) with a yaw sweep
    of `yaw` degrees either way every `period` s on top, so that each temple turns out of
    view in turn (no frame need see all four anchors)."""
    R, t = demo_head_motion(n_frames, fps, seed, amplitude=1.5)
    phase = np.random.default_rng(seed + 101).uniform(0, 2 * np.pi)
    a = np.radians(yaw) * np.sin(2 * np.pi * np.arange(n_frames) / (period * fps) + phase)
    c, s = np.cos(a), np.sin(a)
    turn = np.zeros((n_frames, 3, 3))
    turn[:, 0, 0], turn[:, 0, 2], turn[:, 1, 1], turn[:, 2, 0], turn[:, 2, 2] = c, s, 1, -s, c
    pivot = np.array([0.0, -6.0, 2.0])   # the neck, as `head_motion` turns about
    return turn @ R, np.einsum("fij,fj->fi", turn, t - pivot) + pivot


def render_sticker_video(
    path: str | Path,
    *,
    n_frames: int = 60,
    seed: int = 0,
    cameras: tuple[Camera, Camera] | None = None,
    marker_radius: float = 0.4,
    color: str = "blue",
    yaw: float = 30.0,
    pace: float = 2.0,
    start: float = 1.2,
    footage: Footage | None = None,
    face: SampleFace | None = None,
) -> GroundTruth:
    """Issue 17's hard stereo material: 13 single-colour stickers (`sticker_vertices`,
    radius `marker_radius` cm) filmed by a vertical pair of webcams (`webcam_cameras`,
    default) through webcam-like footage, with its truth.

    path : ``.mp4`` (MPEG-4 Part 2, lossy) or ``.mkv``; videos ``<stem>_left``/``_right``.
    The demo expressions play at `pace` from `start` s (talking, a pucker, blinks,
    surprise, smiles); the head moves as `sticker_head_motion(yaw=yaw)`.
    footage : default lens blur 0.8 px, a light gradient, shutter blur, noise 3 grey levels
        and JPEG quality 75 (blocking and chroma subsampling), then MPEG-4 for ``.mp4``.
    face : the performer (default the built-in face; an ICT identity as a `SampleFace`).
    Truth in world mm; `sticker_truth` gives it in the left camera's frame.
    """
    face = sample_face(1) if face is None else face
    cams = cameras if cameras is not None else webcam_cameras()
    if footage is None:
        footage = Footage(gradient=0.15, shutter=0.5, noise=3.0, jpeg_quality=75, blur=0.7)
    fps = 30.0
    motion = sticker_head_motion(n_frames, fps / pace, seed, yaw)
    verts = sticker_vertices(face)
    colors = np.tile(np.asarray(MARKER_COLORS[color], dtype=np.float64), (len(verts), 1))
    return render_marker_video(
        path, n_frames=n_frames, fps=fps, cameras={"left": cams[0], "right": cams[1]},
        style="color", head_motion=motion, seed=seed, start=start, scale=MM_PER_CM,
        marker_radius=marker_radius, colors=colors, vertices=verts, pace=pace,
        footage=footage, face=face)


def sticker_truth(truth: GroundTruth) -> tuple[np.ndarray, np.ndarray]:
    """(points (F, N, 3), stabilised (F, N, 3)) float64 mm in the left camera's frame.

    points : the stickers as filmed; stabilised : the same with the head held at its
    first frame's pose (the expression alone: what `head_motion="remove"` aims at, up to
    the rigid choice of head frame).
    """
    left = truth.cameras[0]
    rot, trans = truth.head_rotation, truth.head_translation
    posed = np.einsum("fnj,fjk->fnk", truth.points3d - trans[:, None], rot)   # R^T (p - t)
    still = posed @ rot[0].T + trans[0]
    return left.to_camera(truth.points3d.reshape(-1, 3)).reshape(truth.points3d.shape), \
        left.to_camera(still.reshape(-1, 3)).reshape(still.shape)


def sticker_scores(points, stabilised, truth: GroundTruth, facing: float = 0.5) -> dict:
    """How unnamed stereo sticker tracks fare against the truth (issue 17's figures).

    points : (F, M, 3) tracked stickers in the left camera's frame (head motion kept);
    stabilised : (F, M, 3) the same with the head motion removed; mm, NaN where unseen.
    Each column is the truth sticker its left-image projection is nearest in most of its
    frames (the image position is a tenth of a pixel sure, the depth millimetres); an
    identity switch is a change of a column's nearest sticker from one of its frames to
    the next. Returns a dict: owner (M,) truth index per column; switches; found (N,)
    share of the frames where each sticker is seen clearly by both cameras (visible, its
    normal within acos(`facing`) of both lines of sight) in which its column has a point
    (0 for a sticker no column follows; NaN for one never seen clearly); error (F, N) mm,
    the shape error: stabilised columns against `sticker_truth`'s stabilised truth, after
    the one rigid transform that best aligns the take (the head frame's choice), NaN
    where not tracked.
    """
    pts = np.asarray(points, dtype=np.float64)
    stab = np.asarray(stabilised, dtype=np.float64)
    left = truth.cameras[0]
    # Projection of left-camera-frame points: x, y over z through the left camera's K.
    with np.errstate(invalid="ignore", divide="ignore"):
        px = pts[..., :2] / pts[..., 2:] * left.K[[0, 1], [0, 1]] + left.K[:2, 2]
    d = np.linalg.norm(px[:, :, None] - truth.points2d[:, 0][:, None], axis=3)   # (F, M, N)
    tracked = np.isfinite(px[..., 0])
    nearest = np.where(tracked, np.nan_to_num(d, nan=np.inf).argmin(2), -1)
    owner = np.full(pts.shape[1], -1)
    switches = 0
    for m in range(pts.shape[1]):
        ids = nearest[tracked[:, m], m]
        switches += int((np.diff(ids) != 0).sum())
        if ids.size:
            owner[m] = np.bincount(ids).argmax()
    n = truth.points3d.shape[1]
    clear = (truth.visible & (truth.facing > facing)).all(axis=1)               # (F, N)
    found = np.full(n, np.nan)
    _, still = sticker_truth(truth)
    error = np.full(clear.shape, np.nan)
    column = np.full(n, -1)
    for k in range(n):
        mine = np.flatnonzero(owner == k)
        if mine.size:
            column[k] = mine[tracked[:, mine].sum(0).argmax()]
        if clear[:, k].any():
            found[k] = tracked[clear[:, k], column[k]].mean() if column[k] >= 0 else 0.0
    have = column >= 0
    a, b = stab[:, column[have]], still[:, have]
    ok = np.isfinite(a[..., 0])
    rot, trans = rigid_transform(a[ok], b[ok])
    error[:, have] = np.linalg.norm(a @ rot.T + trans - b, axis=2)
    return {"owner": owner, "switches": switches, "found": found, "error": error}


def live_sticker_anchors(frames, calibration: StereoCalibration, truth: GroundTruth,
                         color="blue") -> list[str]:
    """The names (m01..) of the truth's head-anchor stickers (the first `STICKER_ANCHORS`)
    among a live session's own columns, for `LiveStickerTracker(anchors=...)`.

    frames : the take's (left, right) BGR pairs. A live tracker names its columns in the
    order their tracks are confirmed; `StickerTracks.points()` orders the same tracks by
    the pair each was first seen in, and a track confirmed after others can have been
    seen first (issue 17's take, seeds 0 and 5: the left cheek came out where the nose
    bridge is live, so a session "named" by that order was anchored on the cheek). So
    the columns are taken from a live session that never leaves its set-up."""
    from retarget.sources.stereo_live_stickers import LiveStickerTracker

    tracker = LiveStickerTracker(calibration, color, setup_seconds=float(len(frames)),
                                 setup_frames=len(frames) + 1)
    rows = []
    for i, (left, right) in enumerate(frames):
        tracker.push(left, right, i / 30)
        rows.append(tracker.camera_)
    m = len(rows[-1])
    seen = np.stack([np.pad(r, ((0, m - len(r)), (0, 0)), constant_values=np.nan) for r in rows])
    owner = sticker_scores(seen, seen, truth)["owner"]
    return [name for name, k in zip(tracker.names_, owner) if 0 <= k < STICKER_ANCHORS]
