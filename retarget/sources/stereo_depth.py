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

The weights alone still lag a move that is mostly along the ray: a jaw dropping at double
pace takes the chin or a mouth corner 5-10 mm back while it moves only 1-3 mm across, so
within a weight's width the frames before and after the move count alike and the median
sits between them. But within a window an expression moves a sticker along one path, so
its depth changes in step with its across-ray position, which is measured finely: the
window's depth is fitted by weighted least squares as a linear function of the across-ray
offset (its slope, ridge-regularised, is the depth change per mm of image-plane motion),
and the weighted median is taken of the depths with that trend removed, i.e. of each
frame's depth carried to this frame's across-ray position. A still sticker has no
across-ray spread, the ridge keeps its slope near 0 and the median is the old one. (Issue
17's material, 5 passes, named anchors, median / p95 shape error per seed 0, 1, 2: plain
weighted median 0.65 / 2.77, 0.85 / 3.22, 0.73 / 2.68 mm; with the trend 0.63 / 2.61, 0.86
/ 2.82, 0.69 / 2.54; held-out seeds 3-6 0.73 / 2.87, 1.57 / 4.33, 0.78 / 3.30, 0.91 / 3.47
-> 0.76 / 2.98, 1.70 / 4.46, 0.73 / 2.95, 0.86 / 2.91.)
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

__all__ = ["sight_smoothed", "expression_depth", "weighted_median_along"]

_CHUNK = 1024   # frames per block: the windows are (frames, stickers, 3, window) floats


def sight_smoothed(points, rot, trans, window: int = 45, *, across: float = 2.0,
                   ridge: float = 10.0) -> np.ndarray:
    """(F, M, 3) float64 left-camera-frame points with their depth noise smoothed.

    points : (F, M, 3) float in the left camera's frame (camera at the origin), NaN where
        unseen. rot (F, 3, 3), trans (F, 3): each frame's head pose, ``stabilised =
        p @ R.T + t`` (`anchored_poses`); NaN where none.
    window : odd number of frames of the centred window (1: the points unchanged).
    across : calibration units (mm), the Gaussian width of the weight on the distance
        across the ray between a window frame's head-frame position and this frame's
        (inf: a plain running median).
    ridge : mm^2 (weight x squared distance), the regularisation of the slope of depth
        against across-ray position: the slope is shrunk toward 0 unless the window's
        weighted across-ray spread well exceeds it (inf: no trend, the plain weighted
        median of the depths).
    In the head frame each point moves along the ray from the camera through it to the
    weighted median of the window frames' positions along that ray (over those that see
    it), each first carried to this frame's across-ray position by the window's fitted
    trend of depth against across-ray position; the result is mapped back into the
    camera frame.
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
        shift[part] = weighted_median_along(windows[part] - stab[part, ..., None], ray[part], across,
                                             ridge)
    steady = stab + shift[..., None] * ray
    # Back into the camera frame: p = R^T (s - t).
    out = np.einsum("fni,fij->fnj", steady - trans[:, None], rot)
    ok = np.isfinite(out).all(axis=2)
    return np.where(ok[..., None], out, p)


def weighted_median_along(diff: np.ndarray, ray: np.ndarray, across: float,
                           ridge: float = np.inf) -> np.ndarray:
    """(F, M) the weighted median over the window of the offsets `diff` (F, M, 3, W) along
    `ray` (F, M, 3), each weighted by exp(-d^2 / 2 across^2), d its length across the ray,
    and first carried to across-ray offset 0 along the window's weighted least-squares
    trend of offset along against offset across (slope ridge-regularised by `ridge`, mm^2;
    inf: none); NaN where no window frame sees the point."""
    along = np.einsum("fniw,fni->fnw", diff, ray)
    side = diff - along[:, :, None, :] * ray[..., None]              # (F, M, 3, W) across
    off = np.linalg.norm(side, axis=2)
    seen = np.isfinite(along)
    weight = np.where(seen, np.exp(-0.5 * (np.nan_to_num(off) / across) ** 2), 0.0)
    if np.isfinite(ridge):
        along = along - _trend(np.nan_to_num(along), np.nan_to_num(side), weight, ridge)
    order = np.argsort(np.where(seen, along, np.inf), axis=-1)
    along = np.take_along_axis(along, order, axis=-1)
    cum = np.cumsum(np.take_along_axis(weight, order, axis=-1), axis=-1)
    # The first offset at which half the weight is reached.
    at = (cum < 0.5 * cum[..., -1:]).sum(axis=-1, keepdims=True)
    at = np.minimum(at, along.shape[-1] - 1)
    return np.where(seen.any(axis=-1), np.take_along_axis(along, at, axis=-1)[..., 0], np.nan)


def _trend(along: np.ndarray, side: np.ndarray, weight: np.ndarray, ridge: float) -> np.ndarray:
    """(F, M, W) the depth each window frame owes to its across-ray offset: b . side, with
    b (F, M, 3) the ridge-regularised weighted least-squares slope of `along` (F, M, W)
    against `side` (F, M, 3, W) (intercept free; zero weight where unseen). The across-ray
    offsets span a plane, so the ridge also keeps the slope along the ray itself at 0."""
    total = np.maximum(weight.sum(axis=-1), 1e-12)
    x = side - np.einsum("fniw,fnw->fni", side, weight)[..., None] / total[..., None, None]
    y = along - (weight * along).sum(axis=-1, keepdims=True) / total[..., None]
    cov = np.einsum("fnw,fniw,fnjw->fnij", weight, x, x) + ridge * np.eye(3)
    slope = np.linalg.solve(cov, np.einsum("fnw,fniw,fnw->fni", weight, x, y)[..., None])[..., 0]
    return np.einsum("fni,fniw->fnw", slope, side)


def expression_depth(points, rot, trans, modes: int = 8, *, share: float = 0.5,
                     sight_ratio: float = 6.0, iterations: int = 15) -> np.ndarray:
    """(F, M, 3) float64 left-camera-frame points whose depth is drawn toward the take's
    expression model.

    points : (F, M, 3) float in the left camera's frame (camera at the origin), NaN where
        unseen; rot (F, 3, 3), trans (F, 3): the head poses (``stabilised = p @ R.T + t``).
    modes : K, the expression modes (capped at a quarter of the frames and of 3 M).
    share : how far (0-1) each point's depth moves from its own to the model's.
    sight_ratio : how many times less sure a point is along its ray than across it.
    Neighbouring stickers move together: an expression is a few muscles' pull, so in the
    head frame the take's shapes lie near a low-dimensional space, ``s_f = mu + w_f B``
    (blendshapes; Woodward's retargeting itself rests on it). The model (mu the median
    shape, B (K, M, 3) modes, w_f (K,) weights) is fitted by alternating least squares,
    each point's residual weighed by its information matrix ``I - (1 - 1/r^2) u u^T`` (u
    its ray in the head frame, r `sight_ratio`): the fine across-ray positions of all the
    stickers fix each frame's weights, and so the model's depth of every sticker, which a
    sticker's own depth noise barely moves. (Issue 17's material after the depth smoothing,
    named anchors, median / p95 shape error per seed 0-6: without 0.63 / 2.61, 0.86 /
    2.82, 0.69 / 2.54, 0.76 / 2.98, 1.70 / 4.46, 0.73 / 2.95, 0.86 / 2.91 mm; K 8, share
    0.5: 0.64 / 2.54, 0.82 / 2.73, 0.69 / 2.39, 0.72 / 2.69, 1.62 / 4.24, 0.68 / 2.71,
    0.83 / 2.82; share 1 follows the model too closely where a real face leaves it, K 4
    is too few for the mouth and K 10 starts to fit the noise.)
    """
    p = np.asarray(points, dtype=np.float64)
    n_frames, m = p.shape[:2]
    k = min(int(modes), n_frames // 4, (3 * m) // 4)
    if k < 1 or share <= 0:
        return p.copy()
    stab = np.einsum("fnj,fij->fni", p, rot) + trans[:, None]
    ray = np.einsum("fnj,fij->fni", p / np.linalg.norm(p, axis=2, keepdims=True), rot)
    seen = np.isfinite(stab).all(axis=2) & np.isfinite(ray).all(axis=2)
    seen &= seen.sum(axis=0) >= 2             # a sticker seen once has no place in the model
    ray = np.where(seen[..., None], ray, 0.0)
    info = np.eye(3) - (1.0 - sight_ratio**-2) * ray[..., :, None] * ray[..., None, :]
    info = np.where(seen[..., None, None], info, 0.0)                       # (F, M, 3, 3)
    mean = np.nanmedian(np.where(seen[..., None], stab, np.nan), axis=0) if seen.any() else None
    if mean is None:
        return p.copy()
    mean = np.nan_to_num(mean)
    x = np.where(seen[..., None], stab - mean, 0.0)                          # (F, M, 3)
    # Start from the principal components of the shapes as measured.
    basis = np.linalg.svd(x.reshape(n_frames, -1), full_matrices=False)[2][:k].reshape(k, m, 3)
    eye_k, eye_3k = np.eye(k), np.eye(3 * k)
    for _ in range(iterations):
        # Each frame's weights; the small ridge keeps those a frame cannot see at 0.
        a = np.einsum("kni,fnij,lnj->fkl", basis, info, basis, optimize=True) + 1e-3 * eye_k
        b = np.einsum("kni,fnij,fnj->fk", basis, info, x, optimize=True)
        w = np.linalg.solve(a, b[..., None])[..., 0]
        # Each sticker's modes (K, 3) over the frames that see it.
        g = np.einsum("fk,fnij,fl->nkilj", w, info, w, optimize=True).reshape(m, 3 * k, 3 * k)
        g += 1e-9 * eye_3k
        h = np.einsum("fk,fnij,fnj->nki", w, info, x, optimize=True).reshape(m, 3 * k)
        basis = np.linalg.solve(g, h[..., None])[..., 0].reshape(m, k, 3).transpose(1, 0, 2)
        # Unit modes, the scale in the weights: the weights' ridge then means one thing.
        basis /= np.maximum(np.linalg.norm(basis.reshape(k, -1), axis=1), 1e-12)[:, None, None]
    a = np.einsum("kni,fnij,lnj->fkl", basis, info, basis, optimize=True) + 1e-3 * eye_k
    b = np.einsum("kni,fnij,fnj->fk", basis, info, x, optimize=True)
    w = np.linalg.solve(a, b[..., None])[..., 0]
    model = np.einsum("fk,kni->fni", w, basis)
    move = share * np.einsum("fni,fni->fn", model - x, ray)
    steady = stab + move[..., None] * ray
    out = np.einsum("fni,fij->fnj", steady - trans[:, None], rot)
    return np.where(seen[..., None] & np.isfinite(out).all(axis=2, keepdims=True), out, p)
