"""Stereo colour-marker capture: calibration, matching, triangulation, tracking.

Woodward et al., §3 and §5: two synchronised webcams about 1 m from the face, calibrated
on a target of known geometry; coloured stickers are found in each image
(`retarget.sources.color_markers`), matched between the images by the epipolar geometry,
triangulated, and the rigid head motion is removed with anchor markers (§5.1,
`retarget.sources.headpose`); a three-frame temporal mean steadies the jitter of the
triangulated points (§5, `retarget.sources.filters.temporal_mean`).

Calibration here is OpenCV's (Zhang's method) rather than Tsai's: `cv2.calibrateCamera`
per camera on checkerboard or circle-grid views, then `cv2.stereoCalibrate` for the pose
of the right camera in the left camera's frame. 3D points are in the **left camera's
frame** (x right, y down, z along the left camera's axis) in the units of the pattern's
square (e.g. mm).
"""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from scipy.optimize import linear_sum_assignment

from retarget.errors import RetargetError
from retarget.layouts import LAYOUTS, Layout, get_layout
from retarget.sources.color_markers import Blobs, MarkerTemplate, color_blobs, layout_marker_colors
from retarget.sources.filters import temporal_mean
from retarget.sources.headpose import head_neutral, remove_head_motion, rigid_transform, stable_indices
from retarget.sources.take import Take

__all__ = [
    "StereoCalibration",
    "pattern_points",
    "find_pattern",
    "calibrate_stereo",
    "calibration_from_points",
    "stereo_matches",
    "identified_markers",
    "track_stereo_frames",
    "track_stereo_videos",
]

_FORMAT = "retarget-stereo-calibration-1"
_PATTERN_KINDS = ("checkerboard", "circles", "acircles")


def _pattern(pattern) -> tuple[str, int, int, float]:
    try:
        kind, cols, rows, size = pattern
        cols, rows, size = int(cols), int(rows), float(size)
    except (TypeError, ValueError):
        raise RetargetError(
            f"pattern must be (kind, cols, rows, size) with kind one of {_PATTERN_KINDS}; "
            f"got {pattern!r}"
        ) from None
    if kind not in _PATTERN_KINDS or cols < 2 or rows < 2 or not size > 0:
        raise RetargetError(
            f"pattern must be (kind, cols >= 2, rows >= 2, size > 0) with kind one of "
            f"{_PATTERN_KINDS}; got {pattern!r}"
        )
    return kind, cols, rows, size


def pattern_points(pattern) -> np.ndarray:
    """(P, 3) float32 the pattern's feature points on its own plane z = 0.

    pattern : ``("checkerboard", cols, rows, square)`` (inner corners per row and column;
        square side), ``("circles", cols, rows, spacing)`` (symmetric circle grid) or
        ``("acircles", cols, rows, spacing)`` (OpenCV's asymmetric grid, `spacing` the
        distance between neighbouring circles of one row / 2). Units are the caller's,
        and become the units of every 3D result.
    Points run along rows first, as OpenCV's detectors report them.
    """
    kind, cols, rows, size = _pattern(pattern)
    j, i = np.meshgrid(np.arange(cols), np.arange(rows))
    if kind == "acircles":
        x = (2 * j + i % 2) * size
    else:
        x = j * size
    pts = np.stack([x.ravel(), (i * size).ravel(), np.zeros(cols * rows)], 1)
    return pts.astype(np.float32)


def _gray(image, what: str) -> np.ndarray:
    if isinstance(image, (str, os.PathLike)):
        path = Path(image)
        if not path.is_file():
            raise RetargetError(f"{what}: no image file {str(path)!r}")
        img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise RetargetError(f"{what}: {str(path)!r} is not a readable image")
        return img
    img = np.asarray(image)
    if img.dtype != np.uint8 or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
        raise RetargetError(
            f"{what}: an image must be a path, a (H, W) gray or (H, W, 3) BGR uint8 array; "
            f"got {img.dtype} {img.shape}"
        )
    return img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)


def find_pattern(image, pattern) -> np.ndarray | None:
    """(P, 2) float32 sub-pixel positions of the pattern's points in `image`, or None.

    image : a path or a (H, W) / (H, W, 3) uint8 array. The order matches
    `pattern_points`, or its reverse for patterns that look the same turned by 180
    degrees (checkerboards, symmetric circle grids): which end the detector starts
    from is its choice; `calibrate_stereo` makes the two orders of each pair agree.
    Checkerboards use OpenCV's sector-based detector
    (`findChessboardCornersSB`, accurate without a separate sub-pixel step); circle
    grids use `findCirclesGrid` (blob centres).
    """
    kind, cols, rows, _ = _pattern(pattern)
    gray = _gray(image, "find_pattern")
    if kind == "checkerboard":
        found, corners = cv2.findChessboardCornersSB(
            gray, (cols, rows), flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
        )
    else:
        flag = cv2.CALIB_CB_SYMMETRIC_GRID if kind == "circles" else cv2.CALIB_CB_ASYMMETRIC_GRID
        found, corners = cv2.findCirclesGrid(gray, (cols, rows), flags=flag)
        if not found:
            # The clustering search finds grids the default graph search misses (e.g.
            # fronto-parallel views), at some cost in speed.
            found, corners = cv2.findCirclesGrid(gray, (cols, rows), flags=flag | cv2.CALIB_CB_CLUSTERING)
    if not found:
        return None
    return corners.reshape(-1, 2).astype(np.float32)


@dataclass(eq=False)
class StereoCalibration:
    """A calibrated camera pair (OpenCV conventions).

    K1, K2 : (3, 3) float64 intrinsics of the left and right camera (px).
    d1, d2 : (5,) float64 distortion (k1, k2, p1, p2, k3).
    R : (3, 3) float64, T : (3,) float64: left camera coordinates -> right camera
        coordinates, ``x_right = R @ x_left + T`` (units of the pattern).
    E, F : (3, 3) float64 essential and fundamental matrices (F for undistorted pixels).
    size : (width, height) of the images, px.
    rms : stereo reprojection RMS error, px.
    meta : JSON-able extras (pattern, views used, per-camera RMS, units).
    """

    K1: np.ndarray
    d1: np.ndarray
    K2: np.ndarray
    d2: np.ndarray
    R: np.ndarray
    T: np.ndarray
    E: np.ndarray
    F: np.ndarray
    size: tuple[int, int]
    rms: float
    meta: dict = field(default_factory=dict)

    _SHAPES = {"K1": (3, 3), "d1": (5,), "K2": (3, 3), "d2": (5,), "R": (3, 3), "T": (3,),
               "E": (3, 3), "F": (3, 3)}

    def __post_init__(self) -> None:
        for name, shape in self._SHAPES.items():
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if name in ("d1", "d2") and value.size in (4, 5):
                value = np.concatenate([value.ravel(), np.zeros(5 - value.size)])
            if name == "T":
                value = value.ravel()
            if value.shape != shape or not np.all(np.isfinite(value)):
                raise RetargetError(
                    f"StereoCalibration {name} must be finite with shape {shape}; got {value.shape}"
                )
            setattr(self, name, value)
        size = tuple(int(s) for s in self.size)
        if len(size) != 2 or min(size) < 1:
            raise RetargetError(f"StereoCalibration size must be (width, height); got {self.size!r}")
        self.size = size
        self.rms = float(self.rms)

    @property
    def baseline(self) -> float:
        """Distance between the camera centres (units of the pattern)."""
        return float(np.linalg.norm(self.T))

    def undistorted(self, points, camera: int) -> np.ndarray:
        """(N, 2) float64 normalised image coordinates (x / z, y / z) of pixels (N, 2).

        camera : 0 left, 1 right. NaN rows stay NaN.
        """
        p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.full_like(p, np.nan)
        ok = np.isfinite(p).all(axis=1)
        if ok.any():
            K, d = (self.K1, self.d1) if camera == 0 else (self.K2, self.d2)
            out[ok] = cv2.undistortPoints(
                p[ok].reshape(-1, 1, 2), K, d,
                criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10),
            ).reshape(-1, 2)
        return out

    def epipolar_distances(self, left, right) -> np.ndarray:
        """(...) float64 symmetric epipolar distance of pixel pairs, px.

        left, right : (..., 2) pixels that broadcast against each other: (N, 2) and
        (N, 2) give one distance per pair, (M, 1, 2) and (1, P, 2) every combination.
        The distance is the mean of each point's distance to the other's epipolar line,
        in undistorted pixels of its own camera (the essential matrix applied to
        undistorted rays, scaled by the focal length).
        """
        left, right = np.asarray(left, dtype=np.float64), np.asarray(right, dtype=np.float64)
        xl = self.undistorted(left.reshape(-1, 2), 0).reshape(left.shape)
        xr = self.undistorted(right.reshape(-1, 2), 1).reshape(right.shape)
        hl = np.concatenate([xl, np.ones(xl.shape[:-1] + (1,))], -1)
        hr = np.concatenate([xr, np.ones(xr.shape[:-1] + (1,))], -1)
        line_r = hl @ self.E.T  # lines in the right image: E x_l
        line_l = hr @ self.E    # lines in the left image: E^T x_r
        num = np.abs(np.sum(hr * line_r, axis=-1))
        # Point-line distances in normalised units, scaled to pixels by each focal length.
        d_r = num / np.hypot(line_r[..., 0], line_r[..., 1]) * self.K2[0, 0]
        d_l = num / np.hypot(line_l[..., 0], line_l[..., 1]) * self.K1[0, 0]
        return 0.5 * (d_l + d_r)

    def triangulate(self, left, right) -> np.ndarray:
        """(N, 3) float64 points in the left camera's frame from pixel pairs (N, 2), (N, 2).

        The pairs are undistorted, moved onto each other's epipolar lines by the optimal
        correction of Hartley and Sturm (`cv2.correctMatches`), then triangulated
        (`cv2.triangulatePoints`). A pair with a NaN gives a NaN row.
        """
        xl = self.undistorted(left, 0)
        xr = self.undistorted(right, 1)
        if xl.shape != xr.shape:
            raise RetargetError(f"left and right must have the same shape; got {xl.shape} and {xr.shape}")
        out = np.full((len(xl), 3), np.nan)
        ok = np.isfinite(xl).all(axis=1) & np.isfinite(xr).all(axis=1)
        if not ok.any():
            return out
        cl, cr = cv2.correctMatches(self.E, xl[ok][None], xr[ok][None])
        p1 = np.hstack([np.eye(3), np.zeros((3, 1))])
        p2 = np.hstack([self.R, self.T[:, None]])
        h = cv2.triangulatePoints(p1, p2, cl.reshape(-1, 2).T, cr.reshape(-1, 2).T)
        out[ok] = (h[:3] / h[3]).T
        return out

    def to_dict(self) -> dict:
        """JSON-able description; `from_dict` inverts it."""
        out = {name: getattr(self, name).tolist() for name in self._SHAPES}
        out.update(format=_FORMAT, size=list(self.size), rms=self.rms, meta=self.meta)
        return out

    @classmethod
    def from_dict(cls, data: dict) -> StereoCalibration:
        """The calibration `to_dict` described; RetargetError naming what is missing."""
        if not isinstance(data, dict):
            raise RetargetError(f"a stereo calibration must be a dict; got {type(data).__name__}")
        missing = [k for k in (*cls._SHAPES, "size", "rms") if k not in data]
        if missing:
            raise RetargetError(f"stereo calibration lacks {', '.join(missing)}")
        return cls(**{k: data[k] for k in (*cls._SHAPES, "size", "rms")}, meta=data.get("meta", {}))

    def save(self, path) -> None:
        """Write an .npz holding one JSON string (readable without pickle)."""
        np.savez(path, calibration=np.array(json.dumps(self.to_dict())))

    @classmethod
    def load(cls, path) -> StereoCalibration:
        """Read what `save` wrote; RetargetError naming the file if it is not one."""
        path = Path(path)
        if not path.is_file():
            raise RetargetError(f"stereo calibration file {str(path)!r} does not exist")
        try:
            loaded = np.load(path, allow_pickle=False)
            if not isinstance(loaded, np.lib.npyio.NpzFile):
                raise ValueError("it holds a single array, not an .npz archive")
            with loaded as npz:
                data = json.loads(str(npz["calibration"]))
        except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
            # BadZipFile: a file that starts like a zip (as .npz files do) but is not one
            raise RetargetError(
                f"{str(path)!r} is not a stereo calibration saved by retarget: {exc}"
            ) from None
        if not isinstance(data, dict) or data.get("format") != _FORMAT:
            found = data.get("format") if isinstance(data, dict) else type(data).__name__
            raise RetargetError(f"{str(path)!r}: unknown calibration format {found!r}")
        try:
            return cls.from_dict(data)
        except RetargetError as exc:
            raise RetargetError(f"{str(path)!r}: {exc}") from None


def calibration_from_points(object_points, left_points, right_points, size,
                            meta: dict | None = None, *, tangential: bool = False
                            ) -> StereoCalibration:
    """A `StereoCalibration` from pattern points seen in V view pairs.

    object_points : (P, 3) float, the pattern (`pattern_points`), or (V, P, 3).
    left_points, right_points : (V, P, 2) float pixels of the pattern in each view.
    size : (width, height) px.
    tangential : fit the tangential distortion (p1, p2) too. Off by default: webcam
        lenses have next to none, and p1, p2 trade off against the principal point, whose
        error shifts every triangulated point (on the synthetic rig, 12 views: principal
        point within 0.5 px instead of 2 px, 3D error at 1 m about halved).
    Each camera is calibrated alone (`cv2.calibrateCamera`, k3 fixed at 0: a handful of
    views cannot pin a sixth-order term), then both jointly with their relative pose
    (`cv2.stereoCalibrate`, intrinsics refined from those guesses).
    `RetargetError` for fewer than 3 views or mismatched shapes.
    """
    lp = np.asarray(left_points, dtype=np.float32)
    rp = np.asarray(right_points, dtype=np.float32)
    obj = np.asarray(object_points, dtype=np.float32)
    if lp.ndim != 3 or lp.shape[2] != 2 or rp.shape != lp.shape:
        raise RetargetError(
            f"left_points and right_points must both be (V, P, 2); got {lp.shape} and {rp.shape}"
        )
    if obj.ndim == 2:
        obj = np.broadcast_to(obj, (len(lp),) + obj.shape)
    if obj.shape != lp.shape[:2] + (3,):
        raise RetargetError(f"object_points must be ({lp.shape[1]}, 3) or (V, P, 3); got {obj.shape}")
    if len(lp) < 3:
        raise RetargetError(f"stereo calibration needs at least 3 view pairs with the pattern; got {len(lp)}")
    w, h = (int(s) for s in size)
    objs = [o.reshape(-1, 1, 3) for o in obj]
    lefts = [p.reshape(-1, 1, 2) for p in lp]
    rights = [p.reshape(-1, 1, 2) for p in rp]
    flags = cv2.CALIB_FIX_K3 | (0 if tangential else cv2.CALIB_ZERO_TANGENT_DIST)
    rms1, K1, d1, _, _ = cv2.calibrateCamera(objs, lefts, (w, h), None, None, flags=flags)
    rms2, K2, d2, _, _ = cv2.calibrateCamera(objs, rights, (w, h), None, None, flags=flags)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    rms, K1, d1, K2, d2, R, T, E, F = cv2.stereoCalibrate(
        objs, lefts, rights, K1, d1, K2, d2, (w, h),
        flags=cv2.CALIB_USE_INTRINSIC_GUESS | flags, criteria=criteria,
    )
    info = {"views": len(lp), "rms_left": float(rms1), "rms_right": float(rms2),
            "tangential": bool(tangential)}
    info.update(meta or {})
    return StereoCalibration(K1, d1.ravel()[:5], K2, d2.ravel()[:5], R, T, E, F, (w, h), rms, info)


def calibrate_stereo(left_images: Sequence, right_images: Sequence, pattern, *,
                     tangential: bool = False) -> StereoCalibration:
    """Calibrate a camera pair from views of a pattern (Woodward §3, with OpenCV's method).

    left_images, right_images : equally many images, pair i taken at the same moment:
        paths or uint8 arrays ((H, W) gray or (H, W, 3) BGR), all of one size.
    pattern : see `pattern_points`; its size sets the units of everything 3D.
    tangential : see `calibration_from_points`.
    Pairs where either image lacks the pattern are skipped (listed in
    ``meta["skipped"]``); `RetargetError` naming them if fewer than 3 pairs remain.
    """
    kind, cols, rows, size = _pattern(pattern)
    if len(left_images) != len(right_images):
        raise RetargetError(
            f"calibrate_stereo: {len(left_images)} left images but {len(right_images)} right ones"
        )
    found_l, found_r, skipped, image_size = [], [], [], None
    for i, (a, b) in enumerate(zip(left_images, right_images)):
        ga, gb = _gray(a, f"left image {i}"), _gray(b, f"right image {i}")
        for side, g in (("left", ga), ("right", gb)):
            if image_size is None:
                image_size = g.shape[::-1]
            elif g.shape[::-1] != image_size:
                raise RetargetError(
                    f"calibrate_stereo: {side} image {i} is {g.shape[1]}x{g.shape[0]}, "
                    f"the first was {image_size[0]}x{image_size[1]}"
                )
        pa, pb = find_pattern(ga, pattern), find_pattern(gb, pattern)
        if pa is None or pb is None:
            missing = [side for side, p in (("left", pa), ("right", pb)) if p is None]
            skipped.append({"pair": i, "missing_in": missing})
            continue
        if kind != "acircles" and np.dot(pa[-1] - pa[0], pb[-1] - pb[0]) < 0:
            # The detectors started from opposite ends of a symmetric pattern; two
            # cameras side by side see it the same way round.
            pb = pb[::-1]
        found_l.append(pa)
        found_r.append(pb)
    if len(found_l) < 3:
        detail = "; ".join(f"pair {s['pair']}: not found in {' and '.join(s['missing_in'])}"
                           for s in skipped[:10])
        raise RetargetError(
            f"calibrate_stereo: the {kind} pattern ({cols}x{rows}) was found in both images of "
            f"{len(found_l)} of {len(left_images)} pairs; at least 3 are needed"
            + (f" ({detail})" if detail else "")
        )
    meta = {"pattern": [kind, cols, rows, size], "skipped": skipped}
    return calibration_from_points(pattern_points(pattern), np.stack(found_l), np.stack(found_r),
                                   image_size, meta, tangential=tangential)


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
    layout: Layout | str,
    fps: float = 30.0,
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
        (default `layout_marker_colors(layout)`).
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
    layout = layout if isinstance(layout, Layout) else get_layout(layout)
    colors = tuple(colors) if colors is not None else layout_marker_colors(layout)
    if len(colors) != layout.n_points:
        raise RetargetError(
            f"colors must give {layout.n_points} colours for layout {layout.name!r}; got {len(colors)}"
        )
    if head_motion not in ("remove", "keep"):
        raise RetargetError(f"head_motion must be 'remove' or 'keep'; got {head_motion!r}")
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
    rotvec = np.full((len(rot), 3), np.nan)
    ok = np.isfinite(rot).all(axis=(1, 2))
    rotvec[ok] = np.array([cv2.Rodrigues(r)[0].ravel() for r in rot[ok]]).reshape(-1, 3)
    pose = {"rotvec": _json_rows(rotvec, 6), "translation": _json_rows(trans, 4)}
    return (stabilised if remove else points), pose


def _json_rows(values: np.ndarray, decimals: int) -> list:
    """Rows of floats for JSON, None where a value is NaN (JSON has no NaN)."""
    return [[None if np.isnan(v) else round(float(v), decimals) for v in row] for row in values]


def track_stereo_videos(left, right, calibration: StereoCalibration | str | os.PathLike, *,
                        layout: Layout | str,
                        anchors: Sequence[str | int] | None = None,
                        progress: Callable[[int, int], None] | None = None,
                        **options) -> Take:
    """A 3D `Take` from a pair of synchronised colour-marker videos (Woodward §5).

    left, right : video paths (the left camera's and the right one's);
    calibration : a `StereoCalibration` or the path of one saved by `save`.
    layout, anchors, progress and the `options` (colors, assignment, head_motion,
    temporal_window, hold, max_jump, max_epipolar) as `track_stereo_frames`.
    The shorter video sets the length (``meta["frames_dropped"]`` counts the other's
    extra frames); the left video's frame rate is the take's.
    """
    from retarget.sources.video import VideoReader

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
