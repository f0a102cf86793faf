"""Unnamed 3D markers named by where they sit on the face, not by the order met (issue 17 §2).

A stereo sticker tracker names its columns m01..mM in the order it first meets the
stickers, so the same stickers met in another order (one hidden at the start, the head
turned, another take) would drive other points. A layout made from a stereo sticker take
keeps where each sticker sat (`retarget.custom_layouts.take_reference`), and
`matched_places` says which of its points each of another session's places is: a
similarity (rotation, scale and shift: each head frame is the camera's at that session's
first head pose, and the reference is scaled to the built-in face) and a one-to-one
assignment (Hungarian, with "none" at a gate's cost, so a few missing or extra stickers
stay unnamed rather than pull the rest), fitted in turn from several starting head turns
and centres; the run with the lowest total cost wins. `retarget.sources.markers.assign_markers` does
the same for 2D takes' pixels.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial.distance import cdist

from retarget.errors import RetargetError
from retarget.similarity import similarity_transform

__all__ = ["matched_places"]

_TURNS = [(yaw, pitch) for yaw in (0.0, -30.0, 30.0, -60.0, 60.0) for pitch in (0.0, -20.0, 20.0)]
"""Starting head turns (degrees about the vertical, then the ear-to-ear axis): the two head
frames' poses may differ by a head turned 30 degrees each way."""
_ROUNDS = 30   # assignment-and-fit rounds per start (they settle in under 10)


def matched_places(places, reference, *, known=None, gate: float = 0.5) -> np.ndarray:
    """(M,) int64: the reference row each place is, -1 for none.

    places : (M, 3) float in the reference's axes (`retarget.custom_layouts.stereo_reference`
        converts a stereo head frame), any scale and shift, the head turned up to about
        60 degrees left or right and 30 up or down from the reference's; NaN rows stay -1.
    reference : (N, 3) float, a layout's reference points (N >= 3, not all at one point).
    known : optional (M,) int, rows already named (-1 for a place to name): with 3 or more,
        they keep their rows, the similarity is fitted to them and the others take the
        free rows (a sticker met later); fewer: every place is named afresh.
    gate : a place whose row, after the fit, is further than `gate` times the reference's
        median nearest-neighbour spacing stays -1 (a sticker the reference has not).
    """
    p = np.asarray(places, dtype=np.float64)
    ref = np.asarray(reference, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or ref.ndim != 2 or ref.shape[1] != 3 or len(ref) < 3:
        raise RetargetError(f"matched_places takes places (M, 3) and a reference (N >= 3, 3); got "
                            f"{p.shape} and {ref.shape}")
    if not np.isfinite(ref).all():
        raise RetargetError("matched_places: the reference has a point that is not finite")
    spacing = np.median(np.sort(cdist(ref, ref), axis=1)[:, 1])
    if not spacing > 0:
        raise RetargetError("matched_places: reference points coincide")
    limit = gate * spacing
    seen = np.flatnonzero(np.isfinite(p).all(axis=1))
    out = np.full(len(p), -1, np.int64)
    known = None if known is None else np.asarray(known, dtype=np.int64)
    if known is not None and (known[seen] >= 0).sum() >= 3:
        out[seen] = _extended(p[seen], ref, known[seen], limit)
    elif len(seen) >= 3:
        out[seen] = _searched(p[seen], ref, limit)
    return out


def _searched(p: np.ndarray, ref: np.ndarray, limit: float) -> np.ndarray:
    """(M,) rows of the lowest-cost run over the starting turns and centres (module doc)."""
    spread_p = np.median(np.linalg.norm(p - np.median(p, axis=0), axis=1))
    scale = np.median(np.linalg.norm(ref - np.median(ref, axis=0), axis=1)) / spread_p if spread_p > 0 else 1.0
    best_cost, best = np.inf, np.full(len(p), -1, np.int64)
    # Two centres: a stray sticker drags the mean, and a missing one can move the median
    # across the gap between the brows and the mouth (on 13 stickers, 3 cm).
    for centre in (np.mean, np.median):
        mid_p, mid_ref = centre(p, axis=0), centre(ref, axis=0)
        for yaw, pitch in _TURNS:
            rot = _turn(yaw, pitch)
            rows, cost = _settled(p, ref, (scale, rot, mid_ref - scale * rot @ mid_p), limit)
            if cost < best_cost:
                best_cost, best = cost, rows
    return best


def _settled(p: np.ndarray, ref: np.ndarray, fit, limit: float) -> tuple[np.ndarray, float]:
    """(M,) rows and their total cost once assignment and similarity agree, from `fit`
    (s, R, t: ``s R p + t`` in the reference's frame); cost inf for a run left with
    fewer than 3 matches (no fit)."""
    rows = None
    for _ in range(_ROUNDS):
        scale, rot, trans = fit
        new, cost = _assigned(scale * p @ rot.T + trans, ref, limit)
        matched = new >= 0
        if matched.sum() < 3:
            return new, np.inf
        if rows is not None and np.array_equal(new, rows):
            break
        rows = new
        fit = similarity_transform(p[matched], ref[rows[matched]])
    return new, cost


def _extended(p: np.ndarray, ref: np.ndarray, rows: np.ndarray, limit: float) -> np.ndarray:
    """(M,) `rows` with the -1 ones assigned among the reference's free rows, by the
    similarity fitted to the named ones (they keep their rows: a name never changes)."""
    named = rows >= 0
    scale, rot, trans = similarity_transform(p[named], ref[rows[named]])
    free = np.setdiff1d(np.arange(len(ref)), rows[named])
    out = rows.copy()
    if free.size and (~named).any():
        new, _ = _assigned(scale * p[~named] @ rot.T + trans, ref[free], limit)
        out[~named] = np.where(new >= 0, free[new], -1)
    return out


def _assigned(moved: np.ndarray, ref: np.ndarray, limit: float) -> tuple[np.ndarray, float]:
    """(M,) the one-to-one assignment of `moved` (M, 3) to rows of `ref` (N, 3) of least
    total distance, a place further than `limit` from every free row being -1 (its cost
    `limit`), and that total cost."""
    cost = np.concatenate([cdist(moved, ref), np.full((len(moved), len(moved)), limit)], axis=1)
    r, c = linear_sum_assignment(cost)   # every place gets a column: r is 0..M-1
    return np.where(c < len(ref), c, -1).astype(np.int64), float(cost[r, c].sum())


def _turn(yaw: float, pitch: float) -> np.ndarray:
    """(3, 3) rotation by `yaw` degrees about +y (up), then `pitch` about +x."""
    a, b = np.radians(yaw), np.radians(pitch)
    turn = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    nod = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(b), -np.sin(b)], [0.0, np.sin(b), np.cos(b)]])
    return nod @ turn
