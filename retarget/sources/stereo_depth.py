"""Depth noise of triangulated stickers, smoothed along each camera ray in the head frame.

A stereo pair measures a sticker's image position to a tenth of a pixel but its depth
only through the disparity: with Woodward's webcams (§3) 1 m away and a baseline of 8 cm,
a tenth of a pixel of disparity is 1.6 mm of depth, while the same tenth across the image
is 0.13 mm. So a triangulated sticker's error lies almost wholly along its line of sight.
The head's motion is removed first (`retarget.sources.headpose`), so a still sticker
stands still. Each sticker's component along its left-camera ray is therefore replaced by
a median over `window` frames in the head frame, and the components across the ray are
kept as measured. Expressions do move stickers along the ray too (a jaw dropping at double
pace takes the chin 10-15 mm back within a few frames), and a plain running median lags
such a move by half its window. But they move the sticker across the ray as well, which is
measured finely: the median is weighted by how near (Gaussian, `across` mm) each frame's
position across the ray is to this frame's (a bilateral filter in the across-ray
coordinates), so frames where the sticker was elsewhere hardly count and a longer window
can quiet the still stretches (issue 17's material, with the pose of `anchored_poses(...,
sight_ratio=6)`, 2 passes, median over 3 seeds of the median / p95 shape error: plain median over
25 frames 1.00 / 3.59 mm, over 45 frames 0.90 / 3.59; weighted over 45 frames with
`across` 2 mm 0.84 / 2.91, 1 mm 0.87 / 3.19, 3 mm 0.86 / 3.07). The 3-frame temporal
mean of §5 smooths every direction alike and so also blurs fast lip motion across the ray.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

__all__ = ["sight_smoothed"]

_CHUNK = 1024   # frames per block: the windows are (frames, stickers, 3, window) floats


def sight_smoothed(points, rot, trans, window: int = 45, *, across: float = 2.0) -> np.ndarray:
    """(F, M, 3) float64 left-camera-frame points with their depth noise smoothed.

    points : (F, M, 3) float in the left camera's frame (camera at the origin), NaN where
        unseen. rot (F, 3, 3), trans (F, 3): each frame's head pose, ``stabilised =
        p @ R.T + t`` (`anchored_poses`); NaN where none.
    window : odd number of frames of the centred window (1: the points unchanged).
    across : calibration units (mm), the Gaussian width of the weight on the distance
        across the ray between a window frame's head-frame position and this frame's
        (inf: a plain running median).
    In the head frame each point moves along the ray from the camera through it to the
    weighted median of the window frames' positions along that ray (over those that see
    it); the result is mapped back into the camera frame.
    """
    p = np.asarray(points, dtype=np.float64)
    if window <= 1 or len(p) < 3:
        return p.copy()
    half = window // 2
    stab = np.einsum("fnj,fij->fni", p, rot) + trans[:, None]
    padded = np.pad(stab, ((half, half), (0, 0), (0, 0)), constant_values=np.nan)
    windows = sliding_window_view(padded, window, axis=0)          # (F, M, 3, W), a view
    # The ray through each point, turned into the head frame.
    ray = p / np.linalg.norm(p, axis=2, keepdims=True)
    ray = np.einsum("fnj,fij->fni", ray, rot)
    shift = np.full(p.shape[:2], np.nan)
    for f0 in range(0, len(p), _CHUNK):
        part = slice(f0, f0 + _CHUNK)
        shift[part] = _weighted_median_along(windows[part] - stab[part, ..., None], ray[part], across)
    steady = stab + shift[..., None] * ray
    # Back into the camera frame: p = R^T (s - t).
    out = np.einsum("fni,fij->fnj", steady - trans[:, None], rot)
    ok = np.isfinite(out).all(axis=2)
    return np.where(ok[..., None], out, p)


def _weighted_median_along(diff: np.ndarray, ray: np.ndarray, across: float) -> np.ndarray:
    """(F, M) the weighted median over the window of the offsets `diff` (F, M, 3, W) along
    `ray` (F, M, 3), each weighted by exp(-d^2 / 2 across^2), d its length across the ray;
    NaN where no window frame sees the point."""
    along = np.einsum("fniw,fni->fnw", diff, ray)
    off = np.linalg.norm(diff - along[:, :, None, :] * ray[..., None], axis=2)
    seen = np.isfinite(along)
    weight = np.where(seen, np.exp(-0.5 * (np.nan_to_num(off) / across) ** 2), 0.0)
    order = np.argsort(np.where(seen, along, np.inf), axis=-1)
    along = np.take_along_axis(along, order, axis=-1)
    cum = np.cumsum(np.take_along_axis(weight, order, axis=-1), axis=-1)
    # The first offset at which half the weight is reached.
    at = (cum < 0.5 * cum[..., -1:]).sum(axis=-1, keepdims=True)
    at = np.minimum(at, along.shape[-1] - 1)
    return np.where(seen.any(axis=-1), np.take_along_axis(along, at, axis=-1)[..., 0], np.nan)
