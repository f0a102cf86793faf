"""Rigid head motion: the pose of the head from stable points, and its removal.

Woodward et al., §5.1 "Head local coordinate frame and reference marker positions": to
measure the non-rigid motion of an expression, the rigid motion of the head is removed
from every frame using anchor markers that expressions do not move, and the markers are
compared with a neutral recorded in that head frame during the first seconds (head
movement allowed, face still). Woodward builds the frame from four anchors arranged as
two orthogonal vectors and notes that "a minimum of three points can be used"; here the
frame is the least-squares rigid fit of any K >= 3 anchors (Kabsch 1976; Umeyama 1991,
without scale), which uses every anchor, averages their noise and tolerates a lost one.

Conventions: ``R, t`` map a frame **into the neutral's head frame**,
``stabilised = points @ R.T + t``; the head's own pose relative to the neutral is the
inverse, ``(R.T, -R.T @ t)``. Units are those of the points (cm, mm, ...).

Stable points (`STABLE_POINT_NAMES`, iBUG names from `retarget.layouts`): the nose root,
bridge and tip and the inner and outer eye corners. On the sample face's 12 expressions
they move at most 2.4 mm (eye corners) and 0.9 mm (nose). Layouts with fewer than
`MIN_STABLE` of them (``dutreve21`` has only the nose tip) add `STABLE_FALLBACK_NAMES`:
the nose alae and the inner lower lids (at most 3.1 mm and 0.8 mm on the sample face).

Degenerate input (policy): a frame whose stable points are fewer than 3 usable (finite)
or collinear keeps the previous frame's pose (the head moves little between frames);
frames before the first estimable pose get NaN points and a NaN pose, as lost points are
NaN everywhere in `retarget.sources`.
"""

from __future__ import annotations

import warnings
from itertools import combinations
from math import comb

import numpy as np

from retarget.errors import RetargetError
from retarget.layouts import Layout, get_layout

__all__ = [
    "STABLE_POINT_NAMES",
    "STABLE_FALLBACK_NAMES",
    "MIN_STABLE",
    "stable_indices",
    "rigid_transform",
    "remove_head_motion",
    "head_neutral",
    "HeadMotionRemover",
    "rigid_anchors",
    "anchored_poses",
]

STABLE_POINT_NAMES: tuple[str, ...] = (
    "nose_root",
    "nose_bridge_upper",
    "nose_bridge_lower",
    "nose_tip",
    "eye_right_inner",
    "eye_left_inner",
    "eye_right_outer",
    "eye_left_outer",
)
"""iBUG point names that expressions barely move: the head frame's anchors."""

STABLE_FALLBACK_NAMES: tuple[str, ...] = (
    "nose_ala_right",
    "nose_ala_left",
    "eye_right_lower_inner",
    "eye_left_lower_inner",
)
"""Anchors added when a layout holds fewer than `MIN_STABLE` of `STABLE_POINT_NAMES`."""

MIN_STABLE = 4
"""Fewest primary anchors used alone: 3 fix a pose, one more averages noise."""

# The second principal spread of the anchors (relative to the first) below which they
# count as collinear: a rotation about their line would be undetermined.
_COLLINEAR_TOL = 1e-3


def stable_indices(layout: Layout | str) -> np.ndarray:
    """(K,) int64 indices of the layout's anchor points, in the layout's order.

    A layout that names its own anchors (a custom layout's, marked by the user) has those.
    Otherwise the layout's points named in `STABLE_POINT_NAMES`; with
    `STABLE_FALLBACK_NAMES` added when fewer than `MIN_STABLE` are present. `RetargetError`
    if the result has fewer than 3 points.
    """
    layout = layout if isinstance(layout, Layout) else get_layout(layout)
    if layout.anchors:
        return np.asarray(layout.anchors, dtype=np.int64)
    names = np.asarray(layout.point_names)
    keep = np.isin(names, STABLE_POINT_NAMES)
    if keep.sum() < MIN_STABLE:
        keep |= np.isin(names, STABLE_FALLBACK_NAMES)
    if keep.sum() < 3:
        raise RetargetError(
            f"layout {layout.name!r} has {int(keep.sum())} stable points "
            f"({', '.join(names[keep]) or 'none'}); head pose needs 3 of "
            f"{STABLE_POINT_NAMES + STABLE_FALLBACK_NAMES}"
        )
    return np.flatnonzero(keep)


def _rigid_transforms(src: np.ndarray, dst: np.ndarray, weights: np.ndarray):
    """Batched weighted Kabsch: (F, K, 3), (F, K, 3), (F, K) -> R (F,3,3), t (F,3), ok (F,).

    Weights of zero drop a point (its coordinates may be anything finite). `ok` is False
    where fewer than 3 points have weight or they are collinear; R, t are NaN there.
    """
    w = weights / np.maximum(weights.sum(axis=1, keepdims=True), np.finfo(float).tiny)
    src_mean = np.einsum("fk,fkd->fd", w, src)
    dst_mean = np.einsum("fk,fkd->fd", w, dst)
    a = src - src_mean[:, None]
    b = dst - dst_mean[:, None]
    cov = np.einsum("fk,fki,fkj->fij", w, a, b)
    spread = np.linalg.eigvalsh(np.einsum("fk,fki,fkj->fij", w, a, a))  # ascending
    ok = ((weights > 0).sum(axis=1) >= 3) & (spread[:, 1] > _COLLINEAR_TOL**2 * spread[:, 2])
    u, _, vt = np.linalg.svd(cov)
    # A reflection would fit coplanar anchors as well as a rotation; force det(R) = +1.
    d = np.sign(np.linalg.det(np.einsum("fij,fjk->fik", u, vt)))
    d[d == 0] = 1.0
    vt = vt * np.stack([np.ones_like(d), np.ones_like(d), d], axis=1)[:, :, None]
    rot = np.einsum("fji,fkj->fik", vt, u)  # V diag(1, 1, d) U^T
    trans = dst_mean - np.einsum("fij,fj->fi", rot, src_mean)
    rot[~ok] = np.nan
    trans[~ok] = np.nan
    return rot, trans, ok


def _usable(points: np.ndarray, weights: np.ndarray | None) -> np.ndarray:
    """Weights with NaN rows zeroed: (..., K, 3), (K,) | None -> (..., K) float64."""
    finite = np.isfinite(points).all(axis=-1)
    w = np.ones(points.shape[:-1]) if weights is None else np.broadcast_to(weights, points.shape[:-1])
    return np.where(finite, w, 0.0)


def rigid_transform(src, dst, weights=None) -> tuple[np.ndarray, np.ndarray]:
    """The rotation and translation taking `src` onto `dst` in the least-squares sense.

    src, dst : (N, 3) float, same units; rows with a NaN in either are ignored.
    weights : optional (N,) float >= 0, each point's weight.
    Returns R (3, 3) float64 with det +1 and t (3,) float64 minimising
    ``sum_i w_i |R src_i + t - dst_i|²`` (Kabsch; Umeyama without scale). `RetargetError`
    if fewer than 3 usable rows remain or they are collinear.
    """
    s = np.asarray(src, dtype=np.float64)
    d = np.asarray(dst, dtype=np.float64)
    if s.ndim != 2 or s.shape[1] != 3 or d.shape != s.shape:
        raise RetargetError(f"src and dst must both have shape (N, 3); got {s.shape} and {d.shape}")
    if weights is not None:
        weights = np.asarray(weights, dtype=np.float64)
        if weights.shape != (len(s),) or not np.all(np.isfinite(weights)) or np.any(weights < 0):
            raise RetargetError(
                f"weights must be ({len(s)},) finite and >= 0; got shape {weights.shape}"
            )
    w = _usable(s, weights) * _usable(d, None)
    rot, trans, ok = _rigid_transforms(
        np.nan_to_num(s)[None], np.nan_to_num(d)[None], w[None]
    )
    if not ok[0]:
        raise RetargetError(
            f"rigid_transform needs at least 3 usable, non-collinear points; got "
            f"{int((w > 0).sum())} usable of {len(s)}"
        )
    return rot[0], trans[0]


def _check_stable(stable, n_points: int) -> np.ndarray:
    k = np.asarray(stable)
    if k.ndim != 1 or not np.issubdtype(k.dtype, np.integer) or k.size < 3:
        raise RetargetError(f"stable must be (K,) integer indices with K >= 3; got {k!r}")
    if np.any((k < 0) | (k >= n_points)):
        raise RetargetError(f"stable indices {k.tolist()} fall outside [0, {n_points})")
    return k


def _check_frames(frames, neutral, stable) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    f = np.asarray(frames, dtype=np.float64)
    n = np.asarray(neutral, dtype=np.float64)
    if f.ndim != 3 or f.shape[2] != 3:
        raise RetargetError(f"frames must have shape (F, N, 3); got {f.shape}")
    if n.shape != f.shape[1:]:
        raise RetargetError(f"neutral must have shape {f.shape[1:]} to match frames; got {n.shape}")
    k = _check_stable(stable, f.shape[1])
    # An anchor lost in the neutral cannot anchor anything; the others still can.
    finite = np.isfinite(n[k]).all(axis=1)
    if finite.sum() < 3:
        raise RetargetError(
            f"neutral has {int(finite.sum())} finite stable points of {k.tolist()}; need 3"
        )
    return f, n, k[finite]


def _held(rot, trans, ok):
    """Each frame's pose, a frame without one holding the last frame that had one."""
    last = np.maximum.accumulate(np.where(ok, np.arange(len(ok)), -1))
    src = np.maximum(last, 0)
    rot, trans = rot[src], trans[src]
    rot[last < 0] = np.nan
    trans[last < 0] = np.nan
    return rot, trans


def remove_head_motion(frames, neutral, stable):
    """Every frame mapped back into the neutral's head frame (Woodward §5.1).

    frames : (F, N, 3) float, any units; a lost point is a NaN row.
    neutral : (N, 3) float, the same points at rest in the head frame wanted.
    stable : (K,) int, K >= 3, indices of the anchor points (`stable_indices`).
    Returns stabilised (F, N, 3) float32, R (F, 3, 3) float64 and t (F, 3) float64 with
    ``stabilised[f] = frames[f] @ R[f].T + t[f]``. See the module docstring for frames
    whose anchors do not fix a pose.
    """
    f, n, k = _check_frames(frames, neutral, stable)
    src = f[:, k]
    w = _usable(src, None)
    rot, trans, ok = _rigid_transforms(
        np.nan_to_num(src), np.broadcast_to(n[k], src.shape), w
    )
    rot, trans = _held(rot, trans, ok)
    out = np.einsum("fnj,fij->fni", f, rot) + trans[:, None]
    return out.astype(np.float32), rot, trans


def head_neutral(frames, stable, iterations: int = 2) -> np.ndarray:
    """(N, 3) float32: the rest shape of frames recorded with the head moving.

    Woodward §5.1 records the neutral in the first seconds with the face still and head
    movement allowed. Each frame is registered on its anchors to the current estimate
    (first the first frame whose anchors fix a pose), and the per-point median of the
    registered frames is the next estimate; its head frame is the first such frame's.
    frames : (F, N, 3) float; stable : (K,) int. `RetargetError` if no frame has a
    pose, or a point is lost in every frame; a point seen only in frames with no pose
    comes out NaN.
    """
    f = np.asarray(frames, dtype=np.float64)
    if f.ndim != 3 or f.shape[2] != 3 or f.shape[0] == 0:
        raise RetargetError(f"frames must have shape (F, N, 3) with F >= 1; got {f.shape}")
    lost = ~np.isfinite(f).all(axis=2).any(axis=0)
    if lost.any():
        raise RetargetError(
            f"head_neutral: points {np.flatnonzero(lost).tolist()} are lost in every frame"
        )
    k = _check_stable(stable, f.shape[1])
    posed = np.isfinite(f[:, k]).all(axis=2).sum(axis=1) >= 3
    if not posed.any():
        raise RetargetError("head_neutral: no frame has 3 finite stable points")
    estimate = f[int(np.argmax(posed))]
    for _ in range(max(1, iterations)):
        registered, _, _ = remove_head_motion(f, estimate, k)
        with warnings.catch_warnings():   # a point seen only in frames with no pose: NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            estimate = np.nanmedian(registered, axis=0)
    return estimate.astype(np.float32)


class HeadMotionRemover:
    """Online `remove_head_motion`: one frame per call, the same result as offline.

    neutral : (N, 3) float, rest points in the head frame wanted.
    stable : (K,) int, K >= 3, anchor indices (`stable_indices`).
    Calling with points (N, 3) returns them stabilised, (N, 3) float32; after a call,
    ``rotation_`` (3, 3) and ``translation_`` (3,) hold that frame's R and t
    (NaN until a pose was first estimated) and ``held_`` says the pose was carried over
    from an earlier frame because this one's anchors did not fix it.
    """

    def __init__(self, neutral, stable):
        n = np.array(neutral, dtype=np.float64)  # a copy: `place` writes into it
        _, self.neutral, self.stable = _check_frames(n[None], n, stable)
        self._anchors = _check_stable(stable, len(n))
        self._target = self.neutral[self.stable][None]
        self.reset()

    def place(self, indices, positions) -> None:
        """Anchors the neutral lacked (unseen when it was taken: a live source) join it at
        `positions` (K, 3), their places in the head frame; the pose held so far stays."""
        idx = np.asarray(indices, dtype=np.int64)
        if not np.isin(idx, self._anchors).all():
            raise RetargetError(f"place: {idx.tolist()} are not all anchors of {self._anchors.tolist()}")
        self.neutral[idx] = positions
        self.stable = np.union1d(self.stable, idx)
        self._target = self.neutral[self.stable][None]

    def reset(self) -> None:
        """Forget the held pose, as at construction."""
        self.rotation_ = np.full((3, 3), np.nan)
        self.translation_ = np.full(3, np.nan)
        self.held_ = False

    def __call__(self, points) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64)
        if p.shape != self.neutral.shape:
            raise RetargetError(f"points must have shape {self.neutral.shape}; got {p.shape}")
        src = p[self.stable][None]
        rot, trans, ok = _rigid_transforms(np.nan_to_num(src), self._target, _usable(src, None))
        self.held_ = not ok[0]
        if ok[0]:
            self.rotation_, self.translation_ = rot[0], trans[0]
        return (p @ self.rotation_.T + self.translation_).astype(np.float32)


def rigid_anchors(points, count: int = 4, window: int = 1, *, modes: int = 3) -> np.ndarray:
    """(count,) int64 indices of the most mutually rigid markers of a take, ascending.

    points : (F, M, 3) float, NaN where a marker is unseen (stereo: millimetres of depth
    noise along each line of sight). A pair's rigidity is how far its distance moves with
    the expression: the pair's distance over the frames both are seen in (at least 5 and
    a fifth of the take; `window` > 1: first a running median over that many frames) is
    fitted by least squares to the take's first `modes` modes of deformation, and the
    spread (90th percentile of the absolute deviation from the median) of the fitted part
    is the pair's. The modes are the principal components of the distances between the
    markers seen in nearly every frame (95 %; on a face the mouth, chin and nose, whose
    distances change with the jaw, the lips and the smile), so the motion of a marker
    that moves with the jaw or the lips is fitted and counts, while a rigid pair's depth
    noise, uncorrelated with the modes, is mostly left out. The set is the `count`
    markers seen in a quarter of the frames or more whose measured pairs have the least
    mean spread, searched exhaustively (greedily beyond
    `_EXHAUSTIVE` sets): two markers never seen together (the two temples, hidden in turn)
    need not be, while the stiffest pair alone does not pick the set (the lower lip and
    the chin move together and so are mutually rigid). On a face: nose, forehead,
    temples, Woodward §5.1's anchors. (Issue 17's 13 stickers, 7 seeds: the named
    anchors on 3, a brow for one temple on the other 4, shape error p95 2.5-3.1 mm on
    seeds 0-2; the position-averaged median spread with a set grown from the stiffest
    pair before took the chin, a lip, a cheek or a brow on every seed, 4.2-5.9 mm. A
    running mean of the positions blurred the distances of markers seen in part of its
    window, the temples most.) Without two markers seen throughout there are no modes and
    the pair's own spread counts. `RetargetError` if fewer than `count` markers are ever
    seen.
    """
    p = np.asarray(points, dtype=np.float64)
    m = p.shape[1]
    if m < count or count < 3:
        raise RetargetError(f"rigid_anchors: {m} markers, {count} anchors asked (at least 3)")
    seen = np.isfinite(p).all(axis=2)
    spread = _pair_spreads(p, window, modes)
    often = np.flatnonzero(seen.mean(axis=0) >= 0.25)
    if len(often) < count:
        often = np.argsort(-seen.sum(axis=0), kind="stable")[:count]
    return np.sort(_stiffest_set(spread, often, count))


def _pair_spreads(p: np.ndarray, window: int, modes: int) -> np.ndarray:
    """(M, M) each pair's expression-fitted distance spread for `rigid_anchors` (NaN where
    the pair is seen together too seldom, and on the diagonal); p (F, M, 3)."""
    n_frames = p.shape[0]
    seen = np.isfinite(p).all(axis=2)
    dist = np.linalg.norm(p[:, :, None] - p[:, None], axis=3)                 # (F, M, M)
    with warnings.catch_warnings():   # pairs never seen together: NaN throughout
        warnings.simplefilter("ignore", RuntimeWarning)
        if window > 1:
            half = window // 2
            padded = np.pad(dist, ((half, half), (0, 0), (0, 0)), constant_values=np.nan)
            runs = np.nanmedian(np.lib.stride_tricks.sliding_window_view(padded, window, axis=0), axis=-1)
            dist = np.where(np.isfinite(dist), runs, np.nan)
        dev = dist - np.nanmedian(dist, axis=0)
    both = np.isfinite(dev)
    y = np.where(both, dev, 0.0)
    core = np.flatnonzero(seen.mean(axis=0) >= 0.95)
    i, j = np.triu_indices(len(core), 1)
    signals = y[:, core[i], core[j]]
    if signals.shape[1] and modes > 0:
        u, _, _ = np.linalg.svd(signals - signals.mean(axis=0), full_matrices=False)
        basis = np.concatenate([np.ones((n_frames, 1)), u[:, :modes]], axis=1)   # (F, B)
        # Each pair's least squares over its own frames (normal equations, batched).
        gram = np.einsum("fmn,fa,fb->mnab", both.astype(np.float64), basis, basis)
        rhs = np.einsum("fmn,fa->mna", y, basis)
        sol = np.linalg.solve(gram + 1e-9 * np.eye(basis.shape[1]), rhs[..., None])[..., 0]
        moved = np.einsum("fa,mna->fmn", basis[:, 1:], sol[..., 1:])
        moved = np.where(both, moved, np.nan)
    else:
        moved = dev
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        spread = np.nanpercentile(np.abs(moved - np.nanmedian(moved, axis=0)), 90, axis=0)
    spread[both.sum(axis=0) < max(5, 0.2 * n_frames)] = np.nan
    np.fill_diagonal(spread, np.nan)
    return spread


# Candidate sets scored at once by `rigid_anchors`; beyond, the set grows greedily.
_EXHAUSTIVE = 20000


def _set_scores(spread: np.ndarray, sets: np.ndarray) -> np.ndarray:
    """(S,) the mean spread of the measured pairs of each set (S, K); inf where fewer
    than K of its pairs are measured (a set must hang together)."""
    k = sets.shape[1]
    i, j = np.triu_indices(k, 1)
    pairs = spread[sets[:, i], sets[:, j]]
    measured = np.isfinite(pairs).sum(axis=1)
    total = np.where(np.isfinite(pairs), pairs, 0.0).sum(axis=1)
    return np.where(measured >= min(k, len(i)), total / np.maximum(measured, 1), np.inf)


def _stiffest_set(spread: np.ndarray, candidates: np.ndarray, count: int) -> np.ndarray:
    """(count,) indices among `candidates` whose pairs have the least mean `spread` (M, M)."""
    if comb(len(candidates), count) <= _EXHAUSTIVE:
        sets = candidates[np.array(list(combinations(range(len(candidates)), count)))]
        scores = _set_scores(spread, sets)
        return sets[int(np.argmin(scores))]
    # Greedy: the best third for the stiffest pair, then one at a time.
    sub = np.where(np.isfinite(spread), spread, np.inf)[np.ix_(candidates, candidates)]
    a, b = np.unravel_index(np.argmin(sub), sub.shape)
    chosen = [int(candidates[a]), int(candidates[b])]
    while len(chosen) < count:
        rest = np.setdiff1d(candidates, chosen)
        grown = np.concatenate([np.tile(chosen, (len(rest), 1)), rest[:, None]], axis=1)
        chosen.append(int(rest[int(np.argmin(_set_scores(spread, grown)))]))
    return np.array(chosen, dtype=np.int64)


def _skew(v: np.ndarray) -> np.ndarray:
    """(..., 3, 3) cross-product matrices of (..., 3) vectors."""
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def _sight_weighted(p, ref, weights, rot, trans, ratio: float, steps: int = 3):
    """Rigid poses refined for triangulation noise that lies along the lines of sight.

    p : (F, K, 3) points in the camera frame (camera at the origin; any finite value
    where `weights` is 0); ref (K, 3) their head-frame places; weights (F, K); rot (F, 3,
    3), trans (F, 3) the starting poses (``ref ~ p @ R.T + t``). A stereo point is `ratio`
    times less sure along its ray than across it, so each residual is weighed by the
    information matrix ``I - (1 - 1/ratio^2) u u^T`` (u the ray, turned into the head
    frame) and the pose takes up to `steps` Gauss-Newton steps on that Mahalanobis cost
    (turning about the anchors' centre), a frame keeping its pose where a step does not
    lower the cost (anchors that barely fix some turn once the depth counts less, e.g.
    brow, nose and cheek, would otherwise send it far off). Returns the refined (rot,
    trans).
    """
    u = p / np.maximum(np.linalg.norm(p, axis=2, keepdims=True), 1e-12)
    info = np.eye(3) - (1.0 - ratio**-2) * u[..., :, None] * u[..., None, :]
    eye = np.broadcast_to(np.eye(3), p.shape + (3,))

    def cost(r, t):
        q = np.einsum("fij,fkj->fki", r, p) + t[:, None]
        wh = np.einsum("fij,fkjl,fml->fkim", r, info, r) * weights[..., None, None]
        return q, wh, np.einsum("fka,fkab,fkb->f", q - ref, wh, q - ref)

    q, wh, before = cost(rot, trans)
    for _ in range(steps):
        # Turned about the anchors' centre, not the head frame's origin (the camera, 1 m
        # away), so the linear model holds to a far larger turn.
        centre = np.einsum("fk,fki->fi", weights, q) / np.maximum(weights.sum(axis=1), 1e-12)[:, None]
        jac = np.concatenate([-_skew(q - centre[:, None]), eye], axis=-1)    # (F, K, 3, 6)
        hess = np.einsum("fkai,fkab,fkbj->fij", jac, wh, jac) + 1e-9 * np.eye(6)
        grad = np.einsum("fkai,fkab,fkb->fi", jac, wh, q - ref)
        step = -np.linalg.solve(hess, grad[..., None])[..., 0]
        # Rodrigues' formula for the rotation increment.
        angle = np.linalg.norm(step[:, :3], axis=1)
        k = _skew(step[:, :3] / np.maximum(angle, 1e-12)[:, None])
        turn = (np.eye(3) + np.sin(angle)[:, None, None] * k
                + (1 - np.cos(angle))[:, None, None] * (k @ k))
        new_rot = turn @ rot
        new_trans = np.einsum("fij,fj->fi", turn, trans - centre) + centre + step[:, 3:]
        new_q, new_wh, after = cost(new_rot, new_trans)
        better = after < before      # a step that does not lower the cost is not taken
        rot = np.where(better[:, None, None], new_rot, rot)
        trans = np.where(better[:, None], new_trans, trans)
        q = np.where(better[:, None, None], new_q, q)
        wh = np.where(better[:, None, None, None], new_wh, wh)
        before = np.where(better, after, before)
    return rot, trans


def anchored_poses(points, anchors, iterations: int = 2, *, sight_ratio: float = 1.0,
                   marker_weight: float = 0.0, pose_window: int = 1):
    """Per-frame head poses from whichever anchors each frame sees (Woodward §5.1).

    points : (F, M, 3) float, NaN where unseen; anchors : (K,) int indices, K >= 3.
    The head frame is that of the first frame seeing 3 anchors. Every anchor gets a
    position in the head frame (its registered positions' median over the take), so a
    frame is fitted to the head-frame positions of **all** anchors it sees: when the set
    of visible anchors changes (a temple turning away) the pose does not jump, as it
    would fitted to the first frame's subset. A frame seeing fewer than 3 anchors is
    fitted to every marker it sees, each weighted by the inverse square of its spread in
    the head frame (the stable ones count); a frame with no pose at all holds the last.
    sight_ratio : for stereo points in the camera frame (camera at the origin), how many
        times noisier they are along the line of sight than across it; above 1, frames
        with 3 anchors are refined for it (`_sight_weighted`: on issue 17's stickers, 80
        mm baseline at 1 m, 6 takes the median shape error from 1.27 to 0.84 mm with 2
        smoothing passes).
    marker_weight : above 0, the anchors' head-frame places come from poses fitted to
        every marker, an anchor weighing 1 and another marker this much, each over the
        square of its spread, refined for `sight_ratio` (`_marker_places`): anchors never
        seen together (the two temples, each seen with forehead and nose bridge alone)
        are tied by the markers seen with both, not by the first frames. On issue 17's
        held-out seed 4 (weight 5) the temples' distance 5.0 -> 0.8 mm off, with
        `pose_window` 17 the shape error 1.62 / 4.24 -> 0.70 / 2.54 mm.
    pose_window : above 1 (odd), the poses are smoothed over that many frames (a cubic
        Savitzky-Golay fit of the rotation vector and of the motion of the anchors'
        centre, `_smoothed_poses`): the head moves smoothly, the pose's noise does not.
    Returns R (F, 3, 3), t (F, 3) float64 (``stabilised = p @ R.T + t``) and the
    head-frame reference (M, 3) float64 (NaN for a marker never seen with a pose).
    """
    p = np.asarray(points, dtype=np.float64)
    k = _check_stable(anchors, p.shape[1])
    seen = np.isfinite(p).all(axis=2)
    count = seen[:, k].sum(axis=1)
    if not (count >= 3).any():
        raise RetargetError("anchored_poses: no frame sees 3 anchors")
    start = int(np.argmax(count >= 3))
    is_anchor = np.isin(np.arange(p.shape[1]), k)
    # First pass, frames in order from the start outwards: each marker's head-frame
    # position is the mean of its registrations so far; a frame is registered on the
    # anchors it sees that have one, helped by the other markers (weight 0.1) when that
    # is fewer than 3 (a temple hidden at the start gets its place from a frame where the
    # other temple is hidden too).
    total = np.where(seen[start, :, None], p[start], 0.0)
    hits = seen[start].astype(np.float64)
    for f in list(range(start + 1, len(p))) + list(range(start - 1, -1, -1)):
        use = seen[f] & (hits > 0)
        if (use & is_anchor).sum() < 3:
            if (use & is_anchor).sum() < 2 or use.sum() < 3:
                continue
            weight = np.where(is_anchor, 1.0, 0.1)[use]
        else:
            use &= is_anchor
            weight = None
        try:
            rot, trans = rigid_transform(p[f, use], total[use] / hits[use, None], weight)
        except RetargetError:
            continue
        total[seen[f]] += p[f, seen[f]] @ rot.T + trans
        hits[seen[f]] += 1
    ref = np.full(p.shape[1:], np.nan)
    ref[k] = np.where(hits[k, None] > 0, total[k] / np.maximum(hits[k], 1)[:, None], np.nan)
    for _ in range(max(1, iterations)):
        rot, trans, ok = _rigid_transforms(
            np.nan_to_num(p[:, k]), np.broadcast_to(np.nan_to_num(ref[k]), (len(p), len(k), 3)),
            (seen[:, k] & np.isfinite(ref[k]).all(axis=1)).astype(np.float64))
        # Frames short of anchors: every marker, weighted by its steadiness.
        registered = np.einsum("fnj,fij->fni", p, rot) + trans[:, None]
        with warnings.catch_warnings():   # a marker no posed frame sees stays NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            ref_all = np.nanmedian(registered, axis=0)
            spread = np.sqrt(np.nanmean(((registered - ref_all) ** 2).sum(axis=2), axis=0))
        w_all = np.where(np.isfinite(spread), 1.0 / np.maximum(np.nan_to_num(spread), 0.5) ** 2, 0.0)
        short = ~ok
        if short.any():
            w = np.where(seen[short] & np.isfinite(ref_all).all(axis=1), w_all, 0.0)
            r2, t2, ok2 = _rigid_transforms(np.nan_to_num(p[short]),
                                            np.broadcast_to(np.nan_to_num(ref_all), p[short].shape), w)
            rot[short], trans[short] = r2, t2
            ok[short] = ok2
        if marker_weight > 0:
            ref_all = _marker_places(p, seen, registered, is_anchor, marker_weight, sight_ratio)
        ref[k] = np.where(np.isfinite(ref_all[k]), ref_all[k], ref[k])
    if sight_ratio > 1:
        w = (seen[:, k] & np.isfinite(ref[k]).all(axis=1)).astype(np.float64)
        full = w.sum(axis=1) >= 3
        rot[full], trans[full] = _sight_weighted(np.nan_to_num(p[full][:, k], nan=1.0), ref[k], w[full],
                                                 rot[full], trans[full], sight_ratio)
    rot, trans = _held(rot, trans, ok)
    # The head frame is the start frame's camera frame: the references' median frame
    # differs from it by a little rigid motion, composed away here.
    r0, t0 = rot[start].copy(), trans[start].copy()
    rot = np.einsum("ji,fjk->fik", r0, rot)
    trans = (trans - t0) @ r0
    ref_all = (ref_all - t0) @ r0
    if pose_window > 1:
        ref_k = (ref[k] - t0) @ r0
        rot, trans = _smoothed_poses(rot, trans, np.nanmedian(ref_k, axis=0), pose_window)
    return rot, trans, ref_all


def _marker_places(p, seen, registered, is_anchor, weight: float, ratio: float, rounds: int = 3):
    """(M, 3) every marker's head-frame place: the median of its registrations by poses
    fitted to all the markers each frame sees, an anchor weighing 1 and another marker
    `weight`, each over the square of its spread (floor 0.5), refined for `ratio`
    (`_sight_weighted`), in `rounds` alternations starting from `registered` (F, M, 3).

    Anchors seen only apart, each with the same two others, leave a turn about those two
    free; the markers seen with both fix it. Fitted isotropically the markers' depth
    noise, larger towards the edge of the face as the head turns, biases that turn (issue
    17, seed 4, weight 10: the temples' distance 3.9 mm off; refined for it 1.6 mm).
    """
    reg = registered
    for _ in range(rounds):
        with warnings.catch_warnings():   # a marker no posed frame sees stays NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            place = np.nanmedian(reg, axis=0)
            spread = np.sqrt(np.nanmean(((reg - place) ** 2).sum(axis=2), axis=0))
        w = np.where(np.isfinite(spread), 1.0 / np.maximum(np.nan_to_num(spread), 0.5) ** 2, 0.0)
        w = np.where(seen & np.isfinite(place).all(axis=1), w * np.where(is_anchor, 1.0, weight), 0.0)
        target = np.broadcast_to(np.nan_to_num(place), p.shape)
        rot, trans, ok = _rigid_transforms(np.nan_to_num(p), target, w)
        if ratio > 1 and ok.any():
            rot[ok], trans[ok] = _sight_weighted(np.nan_to_num(p[ok], nan=1.0), np.nan_to_num(place),
                                                 w[ok], rot[ok], trans[ok], ratio)
        reg = np.einsum("fnj,fij->fni", p, rot) + trans[:, None]
        reg[~ok] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmedian(reg, axis=0)


def _smoothed_poses(rot, trans, centre, window: int, order: int = 3):
    """Poses (F, 3, 3), (F, 3) (``head = p @ R.T + t``) smoothed over `window` frames: a
    Savitzky-Golay fit of order `order` to each frame's rotation vector and to the camera-
    frame place of the head-frame point `centre` (3,) (the anchors' middle, so that a
    turn does not show as a move). Frames without a pose (NaN) are left out."""
    from scipy.signal import savgol_filter
    from scipy.spatial.transform import Rotation

    ok = np.isfinite(rot).all(axis=(1, 2)) & np.isfinite(trans).all(axis=1)
    idx = np.flatnonzero(ok)
    window = min(int(window) - (1 - int(window) % 2), len(idx) - (1 - len(idx) % 2))   # odd
    if window <= order + 1 or not np.isfinite(centre).all():
        return rot, trans
    rotvec = Rotation.from_matrix(rot[idx]).as_rotvec()
    place = np.einsum("fji,fj->fi", rot[idx], centre - trans[idx])       # R^T (c - t)
    rotvec = savgol_filter(rotvec, window, order, axis=0)
    place = savgol_filter(place, window, order, axis=0)
    rot, trans = rot.copy(), trans.copy()
    rot[idx] = Rotation.from_rotvec(rotvec).as_matrix()
    trans[idx] = centre - np.einsum("fij,fj->fi", rot[idx], place)
    return rot, trans

