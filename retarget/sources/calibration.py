"""Stereo calibration: a camera pair's intrinsics and relative pose from views of a
pattern, and the checks a pair of videos must pass before anything is tracked in them.

Woodward et al. §3 calibrate the two webcams on a target of known geometry. Calibration
here is OpenCV's (Zhang's method) rather than Tsai's: `cv2.calibrateCamera` per camera on
checkerboard or circle-grid views, then `cv2.stereoCalibrate` for the pose of the right
camera in the left camera's frame. 3D points are in the **left camera's frame** (x right,
y down, z along the left camera's axis) in the units of the pattern's square (e.g. mm).

Videos of a pair (`retarget.sources.stereo` tracks them): `video_pair_size` refuses two
videos that cannot be one moment seen twice (sizes or frame counts differ),
`calibration_views` picks frame pairs spread over two videos of the pattern moved around,
and `calibrate_stereo_videos` calibrates from them. Refusals name the videos by path.

Checkerboard corners (issue 17). On webcam-like views (a vertical pair of 640 x 480
webcams 80 mm apart, focal 768 px, the board 0.8-1.2 m away; renders blurred, unevenly
lit, noisy and JPEG-compressed, a fifth of the pairs poor: `webcam_cameras` and
`webcam_look` in `retarget.testing.stereo_rig`), `findChessboardCornersSB`'s corners,
accurate as they look (median error 0.06 px), lie 0.02-0.05 px outwards from the
board's centre on average. A bias that scales the board trades against its distance:
the focal lengths came out 0.45-1.39 % off over six seeds of 20 pairs (9 x 6 corners,
30 mm squares, tilts drawn with a 15 degree spread), the baseline up to 0.56 mm off 80,
where the true corners give the exact values and the true ones plus 0.07 px of
independent noise about 0.1 %. Measured on those six seeds (worst over them):

- `cv2.cornerSubPix` after the detector, half-window 2 / 3 / 4 / 5 / 7 px: focal
  0.76 / 0.40 / 0.19 / 0.10 / 0.09 %, baseline 0.33 / 0.24 / 0.15 / 0.10 / 0.06 mm; a
  window small for the blur is noisy (reprojection RMS up to 0.36 px at 2 px);
- half-window 0.3 / 0.4 / 0.5 times the view's shortest corner spacing (2-12 px): focal
  0.14 / 0.07 / 0.11 %, baseline 0.12 / 0.07 / 0.04 mm, RMS 0.06-0.08 px at 0.4, mean
  outward bias under 0.003 px. Kept at 0.4: the window grows with the board's image
  (more edge pixels, less noise) yet holds only its corner's two edge lines;
- the detector's corners with `CALIB_FIX_ASPECT_RATIO`: no change (0.50-1.39 %);
  dropping views whose reprojection RMS exceeds 1.5 times the median, recalibrating:
  still 0.69-1.23 % (the bias is in every view), and after refinement mixed (better on
  four seeds, worse on two), so not done.

`python bench/stereo.py` prints the figures on that material (the webcam-like row).
"""

from __future__ import annotations

import json
import os
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from retarget.errors import RetargetError
from retarget.sources.video import VideoReader

__all__ = [
    "CALIBRATION_VIEWS",
    "StereoCalibration",
    "pattern_points",
    "find_pattern",
    "calibrate_stereo",
    "calibration_from_points",
    "calibration_views",
    "calibrate_stereo_videos",
    "video_pair_size",
]

CALIBRATION_VIEWS = 20
"""Pattern frame pairs `calibrate_stereo_videos` uses at most, spread over the videos:
the pattern search costs about 0.15 s an image, and 20 well spread views calibrate as well
as hundreds of neighbouring frames."""

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
    Checkerboards use OpenCV's sector-based detector (`findChessboardCornersSB`), its
    corners then refined where the edges cross (`cv2.cornerSubPix`; the detector's own
    corners are biased outwards on blurred, compressed webcam images, which biases the
    focal length: see the module docstring); circle grids use `findCirclesGrid` (blob
    centres).
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
    if kind == "checkerboard":
        corners = _refined_corners(gray, corners.reshape(rows, cols, 2))
    return corners.reshape(-1, 2).astype(np.float32)


def _refined_corners(gray: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """(rows * cols, 2) float32 checkerboard corners moved to where the image's edges
    cross (`cv2.cornerSubPix`), from the detector's corners `grid` (rows, cols, 2) px.

    The half-window is 0.4 times the shortest corner spacing of the view (2 to 12 px):
    it then holds only the two edge lines through its corner, as long as possible, and
    the refinement averages over the most edge pixels (see the module docstring for
    what the window sizes measured).
    """
    spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=-1).min(),
                  np.linalg.norm(np.diff(grid, axis=1), axis=-1).min())
    half = int(np.clip(0.4 * spacing, 2, 12))
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-4)
    return cv2.cornerSubPix(gray, grid.reshape(-1, 1, 2).astype(np.float32), (half, half),
                            (-1, -1), criteria).reshape(-1, 2)


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


def video_pair_size(left, right) -> tuple[int, int]:
    """(width, height) of two videos of one moment (paths), which must agree in size and
    in the frame count their headers state (frames are paired by index)."""
    sizes, counts = [], []
    for path in (left, right):
        with VideoReader(path) as reader:
            sizes.append(tuple(reader.size))
            counts.append(reader.n_frames)
    a, b = str(left), str(right)
    if sizes[0] != sizes[1]:
        raise RetargetError(f"{a!r} is {sizes[0][0]}x{sizes[0][1]} but {b!r} is "
                            f"{sizes[1][0]}x{sizes[1][1]}: the two cameras must film at one size")
    if all(counts) and counts[0] != counts[1]:
        raise RetargetError(f"{a!r} has {counts[0]} frames but {b!r} has {counts[1]}: a stereo "
                            "pair is matched frame by frame, so both videos must start and end "
                            "on the same moment")
    return sizes[0]


def calibration_views(left, right, count: int) -> tuple[list, list]:
    """At most `count` frame pairs spread over two calibration videos (paths), each side a
    list of (H, W, 3) uint8 BGR images.

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


def calibrate_stereo_videos(left, right, pattern, *,
                            views: int = CALIBRATION_VIEWS) -> StereoCalibration:
    """A pair's calibration from its two videos of the pattern (paths), `views` frame
    pairs spread over them (`calibration_views`, then `calibrate_stereo`)."""
    lefts, rights = calibration_views(left, right, views)
    try:
        return calibrate_stereo(lefts, rights, pattern)
    except RetargetError as exc:
        raise RetargetError(f"checkerboard videos {str(left)!r} and {str(right)!r} "
                            f"({len(lefts)} frame pairs searched): {exc}") from exc
