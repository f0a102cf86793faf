"""Stereo colour-marker capture: matching, triangulation, tracking.

Woodward et al., §3 and §5: two synchronised webcams about 1 m from the face, calibrated
on a target of known geometry (`retarget.sources.calibration`); coloured stickers are
found in each image (`retarget.sources.color_markers`), matched between the images by the
epipolar geometry, triangulated, and the rigid head motion is removed with anchor markers
(§5.1, `retarget.sources.headpose`); a three-frame temporal mean steadies the jitter of
the triangulated points (§5, `retarget.sources.filters.temporal_mean`).

3D points are in the **left camera's frame** (x right, y down, z along the left camera's
axis) in the units of the calibration pattern's square (e.g. mm).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment

from retarget.errors import RetargetError
from retarget.layouts import LAYOUTS, Layout, get_layout
from retarget.sources.calibration import StereoCalibration, calibrate_stereo_videos, video_pair_size
from retarget.sources.color_markers import Blobs, MarkerTemplate, color_blobs, layout_marker_colors
from retarget.sources.filters import temporal_mean
from retarget.sources.headpose import (
    anchored_poses,
    head_neutral,
    remove_head_motion,
    rigid_anchors,
    rigid_transform,
    stable_indices,
)
from retarget.sources.stereo_depth import expression_depth, sight_smoothed
from retarget.sources.stereo_tracks import StickerTracks, rejoined_tracks
from retarget.sources.take import Take, marker_names
from retarget.sources.video import VideoReader

__all__ = [
    "stereo_matches",
    "identified_markers",
    "track_stereo_frames",
    "track_stereo_videos",
    "stereo_pair_calibration",
    "stereo_layout",
]

def stereo_matches(calibration: StereoCalibration, left, right, left_labels=None,
                   right_labels=None, *, max_epipolar: float = 3.0,
                   depth_range: tuple[float, float] | None = None,
                   depth_tol: float | None = None) -> np.ndarray:
    """(L, 2) int64 pairs (left index, right index) of matching points (Woodward §5).

    left : (M, 2), right : (P, 2) pixels; left_labels (M,), right_labels (P,) optional
    labels (e.g. marker colours) that must agree. A pair is allowed when its symmetric
    epipolar distance is within `max_epipolar` px and its triangulated depth lies in
    `depth_range` (z in the left camera, pattern units; default: in front of both
    cameras). Points on one epipolar line (a face's left/right pairs with a horizontal
    baseline) are told apart by depth: the cost adds each pair's distance from the
    median depth of the allowed pairs over `depth_tol` (default a tenth of that depth),
    so the assignment (Hungarian) prefers the matches that put the face in one piece.
    """
    left = np.asarray(left, dtype=np.float64).reshape(-1, 2)
    right = np.asarray(right, dtype=np.float64).reshape(-1, 2)
    if len(left) == 0 or len(right) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    epi = calibration.epipolar_distances(left[:, None, :], right[None, :, :])
    same = np.ones(epi.shape, dtype=bool)
    if left_labels is not None or right_labels is not None:
        if left_labels is None or right_labels is None:
            raise RetargetError("stereo_matches: give labels for both sides or neither")
        same = np.asarray(left_labels)[:, None] == np.asarray(right_labels)[None, :]
    ii, jj = np.nonzero(same & (epi <= max_epipolar))
    if ii.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    xyz = calibration.triangulate(left[ii], right[jj])
    z = xyz[:, 2]
    right_z = (xyz @ calibration.R.T + calibration.T)[:, 2]
    lo, hi = depth_range if depth_range is not None else (0.0, np.inf)
    ok = (z > lo) & (z < hi) & (right_z > 0)
    ii, jj, z = ii[ok], jj[ok], z[ok]
    if ii.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    z0 = np.median(z)
    tol = depth_tol if depth_tol is not None else 0.1 * z0
    cost = np.full(epi.shape, np.inf)
    cost[ii, jj] = epi[ii, jj] / max_epipolar + np.abs(z - z0) / tol
    big = np.nanmax(cost[ii, jj]) * (min(epi.shape) + 1) + 1.0
    rows, cols = linear_sum_assignment(np.where(np.isfinite(cost), cost, big))
    keep = np.isfinite(cost[rows, cols])
    return np.stack([rows[keep], cols[keep]], 1).astype(np.int64)


# The face's frame seen by a camera in front of it: face +x (subject's left) is the
# image's x, face up is the image's -y, face forward (+z) comes toward the camera (-z).
_FACING_CAMERA = np.diag([1.0, -1.0, -1.0])
# How many times noisier a depth-smoothed sticker is along its line of sight than across
# it, for the head pose (`anchored_poses`): measured on issue 17's webcam pair (80 mm apart
# at 1 m), median / p95 shape error with named anchors, median over 3 seeds: 1 (a plain
# fit) 1.27 / 3.59 mm, 3: 0.94 / 3.27, 6: 0.84 / 2.91, 10: 0.89 / 2.88.
_SIGHT_RATIO = 6.0
_SMOOTHING_PASSES = 5   # depth smoothing and head pose, in turn (`_track_stickers`)
# The anchors' head-frame places from poses fitted to every sticker, the others weighing
# this much (`anchored_poses`' marker_weight: the temples, never seen together, tied by the
# rest), and the poses smoothed over this many frames (pose_window). Issue 17, named
# anchors, median / p95 shape error (bench/stereo.py), seeds 0-6: 0.63 / 2.24, 0.66 / 2.13,
# 0.63 / 1.96, 0.67 / 2.20, 0.70 / 2.54, 0.60 / 2.38, 0.69 / 2.57 mm (neither: 0.63 / 2.48,
# 0.82 / 2.72, 0.69 / 2.33, 0.71 / 2.73, 1.62 / 4.24, 0.72 / 2.68, 0.85 / 2.94); weight 10:
# seed 4 0.72 / 2.63, seed 6 0.79 / 2.70; 15: seed 4 0.85 / 2.88; window 13 (weight 10):
# seed 4 0.83 / 2.67; window 21 (weight 10, isotropic fits): seeds 0-2's medians 0.72-0.78.
_MARKER_WEIGHT = 5.0
_POSE_WINDOW = 17
_POSE_OPTIONS = {"sight_ratio": _SIGHT_RATIO, "marker_weight": _MARKER_WEIGHT,
                 "pose_window": _POSE_WINDOW}
# Expression modes of the stickers' shape model and the share of its depth taken, after
# the passes (`expression_depth`; issue 17, p95 shape error 2.82 -> 2.73 mm on seed 1).
_EXPRESSION_MODES = 8
_EXPRESSION_SHARE = 0.5


def _projected(calibration: StereoCalibration, points: np.ndarray, camera: int) -> np.ndarray:
    """(N, 2) float64 pixels of left-camera-frame points (N, 3) in camera 0 or 1."""
    if camera == 0:
        rvec, tvec, K, d = np.zeros(3), np.zeros(3), calibration.K1, calibration.d1
    else:
        rvec, tvec, K, d = cv2.Rodrigues(calibration.R)[0], calibration.T, calibration.K2, calibration.d2
    px, _ = cv2.projectPoints(points.reshape(-1, 1, 3), rvec, tvec, K, d)
    return px.reshape(-1, 2)


def identified_markers(calibration: StereoCalibration, left: Blobs, right: Blobs,
                       layout: Layout | str, colors: Sequence[str], *,
                       max_epipolar: float = 3.0, iterations: int = 30):
    """Which candidates of a first stereo frame are which layout point (automatic set-up).

    The candidates are matched across the cameras (`stereo_matches`, colours agreeing)
    and triangulated; the layout's points on the built-in face (`Layout.reference_points`),
    started upright and facing the cameras at the candidates' centre and spread, are
    fitted to them by a similarity transform alternating with a colour-constrained
    one-to-one assignment (iterative closest points with the Hungarian method).
    Returns left (N, 2) and right (N, 2) float64 pixel positions, found (N,) bool, and
    the fitted reference (N, 3) in the left camera's frame. A point without a
    candidate gets the projection of the fitted reference, and found False.
    """
    layout = layout if isinstance(layout, Layout) else get_layout(layout)
    colors = np.asarray(colors)
    l_names = np.asarray(left.names)[left.colors]
    r_names = np.asarray(right.names)[right.colors]
    pairs = stereo_matches(calibration, left.centroids, right.centroids, l_names, r_names,
                           max_epipolar=max_epipolar)
    if len(pairs) < 3:
        raise RetargetError(
            f"stereo set-up: {len(pairs)} markers matched between the two first frames "
            f"({len(left)} found left, {len(right)} right); at least 3 are needed"
        )
    found_xyz = calibration.triangulate(left.centroids[pairs[:, 0]], right.centroids[pairs[:, 1]])
    found_color = l_names[pairs[:, 0]]
    ref = layout.reference_points()
    ref_c = ref - ref.mean(axis=0)
    x_mean = found_xyz.mean(axis=0)
    scale = np.sqrt(((found_xyz - x_mean) ** 2).sum(1).mean() / (ref_c**2).sum(1).mean())
    rot, trans = _FACING_CAMERA, x_mean
    allowed = colors[:, None] == found_color[None, :]
    match = np.full(len(ref), -1)
    for _ in range(iterations):
        fitted = scale * ref_c @ rot.T + trans
        d = np.linalg.norm(fitted[:, None] - found_xyz[None], axis=2)
        # Gate at a third of the reference's spread: wrong-colour or far pairs are no match.
        gate = allowed & (d < 0.33 * scale * np.sqrt((ref_c**2).sum(1).mean()))
        big = d.max() * (len(ref) + 1) + 1.0
        rows, cols = linear_sum_assignment(np.where(gate, d, big))
        keep = gate[rows, cols]
        new = np.full(len(ref), -1)
        new[rows[keep]] = cols[keep]
        if keep.sum() < 3:
            break
        a, b = ref_c[rows[keep]], found_xyz[cols[keep]]
        scale = np.sqrt(((b - b.mean(0)) ** 2).sum() / ((a - a.mean(0)) ** 2).sum())
        rot, trans = rigid_transform(scale * a, b)
        if np.array_equal(new, match):
            break
        match = new
    found = match >= 0
    if found.sum() < max(3, len(ref) // 2):
        raise RetargetError(
            f"stereo set-up: only {int(found.sum())} of the {len(ref)} markers of layout "
            f"{layout.name!r} were identified in the first frames (missing: "
            f"{', '.join(np.asarray(layout.point_names)[~found])})"
        )
    fitted = scale * ref_c @ rot.T + trans
    left_px = _projected(calibration, fitted, 0)
    right_px = _projected(calibration, fitted, 1)
    left_px[found] = left.centroids[pairs[match[found], 0]]
    right_px[found] = right.centroids[pairs[match[found], 1]]
    return left_px, right_px, found, fitted


def _anchor_indices(anchors, layout: Layout) -> np.ndarray:
    if anchors is None:
        return stable_indices(layout)
    items = [anchors] if isinstance(anchors, (str, int, np.integer)) else list(anchors)
    idx = np.array([layout.index(a) if isinstance(a, str) else int(a) for a in items], dtype=np.int64)
    if idx.size < 3 or np.any((idx < 0) | (idx >= layout.n_points)):
        raise RetargetError(
            f"anchors must name at least 3 points of layout {layout.name!r}; got {anchors!r}"
        )
    return idx


def track_stereo_frames(
    frames: Iterable[tuple[np.ndarray, np.ndarray]],
    calibration: StereoCalibration,
    *,
    layout: Layout | str | None,
    fps: float = 30.0,
    color="blue",
    depth_window: int = 45,
    colors: Sequence[str] | None = None,
    assignment: tuple[np.ndarray, np.ndarray] | None = None,
    anchors: Sequence[str | int] | None = None,
    head_motion: str = "remove",
    temporal_window: int = 1,
    hold: int = 5,
    max_jump: float = 15.0,
    max_epipolar: float = 3.0,
    progress: Callable[[int, int], None] | None = None,
    n_frames: int = 0,
) -> Take:
    """A 3D `Take` from synchronised stereo frame pairs (Woodward §5, Algorithm 1).

    frames : iterable of (left, right) (H, W, 3) uint8 BGR images.
    calibration : the pair's `StereoCalibration`; points come out in its left camera's
        frame, in its pattern's units.
    layout : the points carrying stickers; colors : (N,) sticker colour per point
        (default `layout_marker_colors(layout)`). None: stickers of one colour `color`
        (Woodward's 13 blue ones; a name, B,G,R or hsv:H,S,V, see `sticker_color`), every
        one in view followed in 3D (`StickerTracks`) into columns m01..mM, by when each is
        first seen, then top to bottom; `anchors` then name columns (default: the 4 most
        mutually rigid, `rigid_anchors`) and each frame's head pose comes from the anchors
        it sees (`anchored_poses`, weighing each anchor's noise along its line of sight);
        with the head motion removed, the stickers' depth noise is smoothed along their
        lines of sight over `depth_window` frames in the head frame, frames where a
        sticker was elsewhere across its ray counting less (`sight_smoothed`, 1 = none; kept, the points are as triangulated: the
        smoothing's head frame carries the pose's own noise back into the camera's).
        `assignment`, `colors`, `hold` and `max_jump` are for layouts only.
    assignment : optional (left (N, 2), right (N, 2)) first-frame pixel positions of
        the markers; default: identified automatically (`identified_markers`).
    anchors : points that define the head frame (names or indices; default
        `stable_indices(layout)`).
    head_motion : "remove" (every frame mapped into the head frame of the take's
        first frames, Woodward §5.1) or "keep". Either way the head pose per frame is
        in ``meta["head_pose"]`` (R as rotation vectors and t, ``stabilised = R p + t``).
    temporal_window : frames of the causal temporal mean (Woodward §5 use 3; 1 = none).
    hold, max_jump : the `MarkerTemplate`s' lost-marker hold (frames) and gate (px).
    max_epipolar : px; a named pair further than this from its epipolar line (an
        identity swap in one camera) is dropped for that frame.
    progress : called as ``progress(frames_done, n_frames)`` (n_frames 0 if unknown).
    A marker is NaN in a frame where either camera lost it for longer than `hold`.
    """
    if head_motion not in ("remove", "keep"):
        raise RetargetError(f"head_motion must be 'remove' or 'keep'; got {head_motion!r}")
    if layout is None:
        return _track_stickers(frames, calibration, fps=fps, color=color, anchors=anchors,
                               depth_window=depth_window,
                               head_motion=head_motion, temporal_window=temporal_window,
                               max_epipolar=max_epipolar, progress=progress, n_frames=n_frames)
    layout = layout if isinstance(layout, Layout) else get_layout(layout)
    colors = tuple(colors) if colors is not None else layout_marker_colors(layout)
    if len(colors) != layout.n_points:
        raise RetargetError(
            f"colors must give {layout.n_points} colours for layout {layout.name!r}; got {len(colors)}"
        )
    anchor_idx = _anchor_indices(anchors, layout)
    palette = tuple(dict.fromkeys(colors))
    templates = [MarkerTemplate(layout.point_names, colors, max_jump=max_jump, hold=hold)
                 for _ in range(2)]
    points, found_at_start = [], None
    for i, (left_img, right_img) in enumerate(frames):
        if left_img.shape != right_img.shape:
            raise RetargetError(
                f"stereo frame {i}: left is {left_img.shape[1]}x{left_img.shape[0]}, right "
                f"{right_img.shape[1]}x{right_img.shape[0]}"
            )
        if i == 0:
            blobs = [color_blobs(left_img, palette), color_blobs(right_img, palette)]
            if assignment is None:
                start_l, start_r, found_at_start, _ = identified_markers(
                    calibration, blobs[0], blobs[1], layout, colors, max_epipolar=max_epipolar)
            else:
                start_l, start_r = (np.asarray(a, dtype=np.float64) for a in assignment)
            px = [t.fit(b, s).positions_ for t, b, s in zip(templates, blobs, (start_l, start_r))]
        else:
            px = [t(_blobs_near(img, t, palette)) for t, img in zip(templates, (left_img, right_img))]
        xyz = calibration.triangulate(px[0], px[1])
        swapped = calibration.epipolar_distances(px[0], px[1]) > max_epipolar
        xyz[swapped] = np.nan
        points.append(xyz)
        if progress is not None:
            progress(i + 1, n_frames)
    if not points:
        raise RetargetError("track_stereo: no stereo frames to track")
    points = np.stack(points)
    meta = {"units": "calibration pattern units", "calibration_rms": calibration.rms,
            "colors": list(colors), "anchors": [layout.point_names[k] for k in anchor_idx],
            "lost_share": np.isnan(points).any(axis=2).mean(axis=0).round(4).tolist(),
            "head_motion": head_motion, "temporal_window": int(temporal_window)}
    if found_at_start is not None:
        meta["identified_at_start"] = found_at_start.tolist()
    points, meta["head_pose"] = _head_stabilised(points, anchor_idx, head_motion == "remove")
    if temporal_window > 1:
        points = temporal_mean(points, temporal_window)
    return Take(points.astype(np.float32), layout.point_names, fps,
                layout=layout.name if layout.name in LAYOUTS else None, source="stereo", meta=meta)


def _track_stickers(frames, calibration: StereoCalibration, *, fps, color, anchors, depth_window,
                    head_motion, temporal_window, max_epipolar, progress, n_frames) -> Take:
    """`track_stereo_frames` without a layout: unnamed stickers of one colour."""
    tracks = StickerTracks(calibration, color, max_epipolar=max_epipolar)
    for i, (left_img, right_img) in enumerate(frames):
        if left_img.shape != right_img.shape:
            raise RetargetError(
                f"stereo frame {i}: left is {left_img.shape[1]}x{left_img.shape[0]}, right "
                f"{right_img.shape[1]}x{right_img.shape[0]}"
            )
        tracks(left_img, right_img)
        if progress is not None:
            progress(i + 1, n_frames)
    if not tracks.n_frames:
        raise RetargetError("track_stereo: no stereo frames to track")
    # A sticker lost long enough for its track to end comes back as a new one: one column.
    points, _ = rejoined_tracks(tracks.points())
    m = points.shape[1]
    names = marker_names(m)
    if m < 3:
        raise RetargetError(f"track_stereo: {m} stickers found in both cameras; at least 3 are "
                            f"needed for the head pose (colour {tracks.color.name!r})")
    if anchors is None:
        anchor_idx = rigid_anchors(points, min(4, m))
    else:
        items = [anchors] if isinstance(anchors, str) else list(anchors)
        unknown = [a for a in items if a not in names]
        if len(items) < 3 or unknown:
            raise RetargetError(f"anchors must name at least 3 of the tracked stickers "
                                f"{', '.join(names)}; got {anchors!r}")
        anchor_idx = np.array([names.index(a) for a in items], dtype=np.int64)
    try:
        rot, trans, _ = anchored_poses(points, anchor_idx, **_POSE_OPTIONS)
        # Alternately: each pose, from depth-smoothed anchors, is steadier, and so is the
        # head frame the next smoothing works in (issue 17, median / p95 shape error: 2
        # passes 0.84 / 2.91 mm, 3: 0.79 / 2.88, 5: 0.74 / 2.81, 6: 0.72 / 2.81).
        steady = points
        for _ in range(_SMOOTHING_PASSES if depth_window > 1 else 0):
            steady = sight_smoothed(steady, rot, trans, depth_window)
            rot, trans, _ = anchored_poses(steady, anchor_idx, **_POSE_OPTIONS)
        if depth_window > 1:
            # What is left of the depth noise is the sticker's own; its neighbours' fine
            # across-ray motion predicts its depth through the take's expression modes.
            steady = expression_depth(steady, rot, trans, _EXPRESSION_MODES, share=_EXPRESSION_SHARE,
                                      sight_ratio=_SIGHT_RATIO)
    except RetargetError as exc:
        raise RetargetError(f"track_stereo: the head frame cannot be set up: {exc}") from None
    stabilised = np.einsum("fnj,fij->fni", steady, rot) + trans[:, None]
    meta = {"units": "calibration pattern units", "calibration_rms": calibration.rms,
            "color": tracks.color.name, "anchors": [names[k] for k in anchor_idx],
            "lost_share": np.isnan(points).any(axis=2).mean(axis=0).round(4).tolist(),
            "head_motion": head_motion, "temporal_window": int(temporal_window),
            "depth_window": int(depth_window), "head_pose": _pose_json(rot, trans)}
    points = stabilised if head_motion == "remove" else points
    if temporal_window > 1:
        points = temporal_mean(points, temporal_window)
    return Take(points.astype(np.float32), names, fps, layout=None, source="stereo", meta=meta)


def _pose_json(rot: np.ndarray, trans: np.ndarray) -> dict:
    """Per-frame poses (F, 3, 3), (F, 3) as JSON lists of rotation vectors and translations."""
    rotvec = np.full((len(rot), 3), np.nan)
    ok = np.isfinite(rot).all(axis=(1, 2))
    rotvec[ok] = np.array([cv2.Rodrigues(r)[0].ravel() for r in rot[ok]]).reshape(-1, 3)
    return {"rotvec": _json_rows(rotvec, 6), "translation": _json_rows(trans, 4)}


def _blobs_near(image: np.ndarray, template: MarkerTemplate, palette: Sequence[str]) -> Blobs:
    """Candidates in the part of the image the template's markers can have reached.

    Woodward §5, Algorithm 1, step 2: once the template is set up only the regions
    around the markers are searched. The region is the box round every marker's last
    position (lost ones included), widened by the template's gate and a sticker's size.
    """
    margin = template.max_jump + 16.0
    h, w = image.shape[:2]
    lo = np.maximum(np.floor(template.position_.min(axis=0) - margin), 0).astype(int)
    hi = np.minimum(np.ceil(template.position_.max(axis=0) + margin) + 1, [w, h]).astype(int)
    if np.any(hi - lo < 3):  # every marker's last position lies off the image
        return Blobs(np.zeros((0, 2), np.float32), np.zeros(0, np.int64),
                     np.zeros(0, np.int32), tuple(palette))
    found = color_blobs(np.ascontiguousarray(image[lo[1]:hi[1], lo[0]:hi[0]]), palette)
    return Blobs(found.centroids + lo.astype(np.float32), found.colors, found.areas, found.names)


def _head_stabilised(points: np.ndarray, anchors: np.ndarray, remove: bool):
    """Points with the head motion removed (or kept) and the per-frame pose as JSON lists."""
    neutral = np.full(points.shape[1:], np.nan)
    try:
        neutral[anchors] = head_neutral(points[:, anchors], np.arange(len(anchors)))
    except RetargetError as exc:
        raise RetargetError(f"track_stereo: the head frame cannot be set up: {exc}") from None
    stabilised, rot, trans = remove_head_motion(points, neutral, anchors)
    return (stabilised if remove else points), _pose_json(rot, trans)


def _json_rows(values: np.ndarray, decimals: int) -> list:
    """Rows of floats for JSON, None where a value is NaN (JSON has no NaN)."""
    return [[None if np.isnan(v) else round(float(v), decimals) for v in row] for row in values]


def track_stereo_videos(left, right, calibration: StereoCalibration | str | os.PathLike, *,
                        layout: Layout | str | None,
                        anchors: Sequence[str | int] | None = None,
                        progress: Callable[[int, int], None] | None = None,
                        **options) -> Take:
    """A 3D `Take` from a pair of synchronised colour-marker videos (Woodward §5).

    left, right : video paths (the left camera's and the right one's);
    calibration : a `StereoCalibration` or the path of one saved by `save`.
    layout, anchors, progress and the `options` (color, colors, assignment, head_motion,
    temporal_window, hold, max_jump, max_epipolar) as `track_stereo_frames` (layout None:
    unnamed stickers of one colour).
    The shorter video sets the length (``meta["frames_dropped"]`` counts the other's
    extra frames); the left video's frame rate is the take's.
    """
    if not isinstance(calibration, StereoCalibration):
        calibration = StereoCalibration.load(calibration)
    with VideoReader(left) as lr, VideoReader(right) as rr:
        for name, reader in (("left", lr), ("right", rr)):
            if tuple(reader.size) != calibration.size:
                raise RetargetError(
                    f"{name} video {reader.path} is {reader.size[0]}x{reader.size[1]}, the "
                    f"calibration is for {calibration.size[0]}x{calibration.size[1]}"
                )
        n = min(lr.n_frames, rr.n_frames) if lr.n_frames and rr.n_frames else 0
        pairs = ((a, b) for (_, a), (_, b) in zip(lr, rr))
        take = track_stereo_frames(pairs, calibration, layout=layout, fps=lr.fps,
                                   anchors=anchors, progress=progress, n_frames=n, **options)
        dropped = abs(lr.n_frames - rr.n_frames) if lr.n_frames and rr.n_frames else 0
    take.meta.update(frames_dropped=dropped, video_size=list(calibration.size),
                     videos=[str(left), str(right)])
    return take


def stereo_pair_calibration(left, right, *, layout: Layout | str | None, calibration=None,
                            boards=None, pattern=None, color="blue") -> tuple[StereoCalibration, str]:
    """(calibration, "file" | "checkerboard") for tracking a pair of colour-marker videos,
    once everything that can be checked before tracking is: both videos readable with
    equal sizes and frame counts (`video_pair_size`), a real calibration for that size and
    the layout's markers in the first frame pair, or with layout None 3 stickers of
    `color` seen by both cameras there (tracking one pair costs about 0.2 s, a whole pair
    of videos minutes).

    left, right : the pair's video paths.
    calibration : a `StereoCalibration` or the path of one saved by `save`; else
    boards, pattern : the pair's two videos of the calibration pattern (paths, checked as
        the pair is) and the pattern (`pattern_points`), calibrated from
        (`calibrate_stereo_videos`, a few seconds).
    Refusals name the videos by path.
    """
    size = video_pair_size(left, right)
    if calibration is not None:
        source = "file"
        if not isinstance(calibration, StereoCalibration):
            calibration = StereoCalibration.load(calibration)
    elif boards is None or pattern is None:
        raise RetargetError("a stereo pair needs its calibration, or its two videos of the "
                            "calibration pattern and the pattern")
    else:
        source = "checkerboard"
        video_pair_size(*boards)
        calibration = calibrate_stereo_videos(*boards, pattern)
    if calibration.size != size:
        raise RetargetError(
            f"the stereo videos are {size[0]}x{size[1]} but the calibration is for "
            f"{calibration.size[0]}x{calibration.size[1]}: calibrate the cameras at the size "
            "they film")
    _check_first_markers(left, right, calibration, layout, color)
    return calibration, source


def _check_first_markers(left, right, calibration: StereoCalibration, layout: Layout | str | None,
                         color) -> None:
    """Refuse a pair whose first frames show too few of the layout's colour markers (with
    no layout, fewer than 3 stickers of `color` seen by both cameras)."""
    with VideoReader(left) as a, VideoReader(right) as b:
        first = (next(iter(a))[1], next(iter(b))[1])
    if layout is None:
        tracks = StickerTracks(calibration, color, confirm=1)
        tracks(*first)
        seen = int(np.isfinite(tracks.points()[-1]).all(axis=1).sum()) if tracks.n_frames else 0
        if seen < 3:
            raise RetargetError(
                f"the first frames of {str(left)!r} and {str(right)!r} show {seen} "
                f"sticker{'' if seen == 1 else 's'} of colour {tracks.color.name!r} seen by both "
                "cameras; at least 3 are needed (the head pose takes 3): check the colour, or "
                "start the videos with the face in view")
        return
    name = layout.name if isinstance(layout, Layout) else layout
    try:
        track_stereo_frames([first], calibration, layout=layout, head_motion="keep")
    except RetargetError as exc:
        raise RetargetError(f"the colour markers of {name!r} in the first frames of "
                            f"{str(left)!r} and {str(right)!r}: {exc}") from exc


def stereo_layout(left, right, calibration: StereoCalibration, layout: str = "dutreve21") -> str | None:
    """`layout` when the first frames of the video pair show its coloured markers (its
    palette, identified by `identified_markers`), else None: stickers of one colour, tracked
    without a layout (what `retarget track --method stereo` does without --layout)."""
    with VideoReader(left) as a, VideoReader(right) as b:
        first = (next(iter(a))[1], next(iter(b))[1])
    colors = layout_marker_colors(layout)
    palette = tuple(dict.fromkeys(colors))
    blobs = [color_blobs(img, palette) for img in first]
    try:
        identified_markers(calibration, *blobs, layout, colors)
    except RetargetError:
        return None
    return layout
