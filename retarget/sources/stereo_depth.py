"""Depth noise of triangulated stickers, smoothed along each camera ray in the head frame.

A stereo pair measures a sticker's image position to a tenth of a pixel but its depth
only through the disparity: with Woodward's webcams (§3) 1 m away and a baseline of 8 cm,
a tenth of a pixel of disparity is 1.6 mm of depth, while the same tenth across the image
is 0.13 mm. So a triangulated sticker's error lies almost wholly along its line of sight.
Expressions move stickers mostly across it, and slowly along it (a pucker takes a third of
a second); the head's motion is removed first (`retarget.sources.headpose`), so a still
sticker stands still. Each sticker's component along its left-camera ray is therefore
replaced by the running median of that component over `window` frames, in the head frame,
and the components across the ray are kept as measured (25 frames, under a second at
30 fps: on issue 17's material 15 frames leave 1.5-1.8 mm median shape error, 25 frames
1.3-1.7, 35 no better). The 3-frame temporal mean of §5 smooths every direction alike and
so also blurs fast lip motion across the ray.
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

__all__ = ["sight_smoothed"]


def sight_smoothed(points, rot, trans, window: int = 25) -> np.ndarray:
    """(F, M, 3) float64 left-camera-frame points with their depth noise smoothed.

    points : (F, M, 3) float in the left camera's frame (camera at the origin), NaN where
        unseen. rot (F, 3, 3), trans (F, 3): each frame's head pose, ``stabilised =
        p @ R.T + t`` (`anchored_poses`); NaN where none.
    window : odd number of frames of the running median (1: the points unchanged).
    In the head frame each point's offset from its running median (over the frames of the
    window that see it) loses its component along the ray from the camera through the
    point; the result is mapped back into the camera frame.
    """
    p = np.asarray(points, dtype=np.float64)
    if window <= 1 or len(p) < 3:
        return p.copy()
    half = window // 2
    stab = np.einsum("fnj,fij->fni", p, rot) + trans[:, None]
    padded = np.pad(stab, ((half, half), (0, 0), (0, 0)), constant_values=np.nan)
    with warnings.catch_warnings():   # a window seeing a sticker nowhere: NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        median = np.nanmedian(sliding_window_view(padded, window, axis=0), axis=-1)
    # The ray through each point, turned into the head frame.
    ray = p / np.linalg.norm(p, axis=2, keepdims=True)
    ray = np.einsum("fnj,fij->fni", ray, rot)
    along = np.einsum("fni,fni->fn", stab - median, ray)
    steady = stab - along[..., None] * ray
    # Back into the camera frame: p = R^T (s - t).
    out = np.einsum("fni,fij->fnj", steady - trans[:, None], rot)
    ok = np.isfinite(out).all(axis=2)
    return np.where(ok[..., None], out, p)
