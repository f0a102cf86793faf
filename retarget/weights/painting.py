"""Painted skin weights: what a painted row may be, merging an edit into a rig, resetting
joints to the automatic rig.

The browser paints (the web app's static/js/model/weightRows.js is this module's JavaScript
twin); this module is the authority on what a stored painted rig is. A painted rig is a `SkinWeights`
with the automatic rig's vertices, joints and influence count k.

Rows and the static root. A row's feature weights plus the root's share ``1 - sum(row)``
sum to 1 by definition (`retarget.skin`): the root is the influence that keeps a vertex
still. Painting joint j to a weight b is one rule, `with_weight`, which for a
non-negative row is the normalisation of Blender's and Maya's weight painting: the other
influences, the root included, scale by ``(1 - b) / (1 - a)`` so the row keeps summing
to 1. Written as a blend it holds for any row: raising w_j blends the row toward the row
that is all j; lowering blends it toward the other influences' non-negative parts,
normalised to 1 (the root takes everything when there are none).

The envelope. Sparse automatic rigs (ellipsoid, geodesic) are non-negative with rows
summing to at most 1; interpolating ones (biharmonic, RBF, Laplacian) have negative
weights and rows that overshoot 1 (`retarget.skin`). Painting blends rows toward
non-negative rows summing to at most 1, so a painted row never leaves its automatic
row's envelope: every weight in ``[min(0, min a), max(1, max a)]`` and the row sum in
``[min(0, sum a), max(1, sum a)]`` for the automatic row a. An edit outside it is
refused: for a non-negative rig that is any negative weight or a row summing over 1. The
envelope is the automatic row's, not the current painted row's, so undoing a stroke
(which sends older rows back) and resetting always stay inside it.

At most k influences: an edited row with more non-zero weights keeps the k largest |w|,
scaled so the row keeps its sum (`SkinWeights.top_k`'s rule).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from retarget.errors import RetargetError
from retarget.skin import SkinWeights

TOLERANCE = 1e-4
"""Slack of the envelope: float32 weights summed over up to N influences."""

CHANGED = 1e-6
"""A weight differing from the automatic one by more than this counts as painted."""


@dataclass(frozen=True, eq=False)
class WeightEdit:
    """Replacement rows for some vertices of a rig.

    vertices : (R,) int64, distinct vertex indices, ascending.
    indices : (R, k) int32, joint indices of each row's influences.
    weights : (R, k) float32, their weights; unused slots have weight 0.
    """

    vertices: np.ndarray
    indices: np.ndarray
    weights: np.ndarray

    @property
    def n_rows(self) -> int:
        return len(self.vertices)

    def save(self, file) -> None:
        """Write an .npz with ``vertices`` (R,) int64, ``joint_indices`` (R, k) int32 and
        ``weights`` (R, k) float32."""
        np.savez_compressed(file, vertices=self.vertices, joint_indices=self.indices,
                            weights=self.weights)

    @classmethod
    def load(cls, path) -> "WeightEdit":
        try:
            with np.load(path, allow_pickle=False) as z:
                v, idx, w = z["vertices"], z["joint_indices"], z["weights"]
        except (OSError, KeyError, ValueError) as exc:
            raise RetargetError(f"could not read painted rows {str(path)!r}: {exc}") from exc
        if v.ndim != 1 or idx.ndim != 2 or idx.shape != w.shape or len(idx) != len(v):
            raise RetargetError(f"painted rows {str(path)!r} are inconsistent: vertices {v.shape}, "
                                f"joint_indices {idx.shape}, weights {w.shape}")
        return cls(v.astype(np.int64), idx.astype(np.int32), w.astype(np.float32))


def weight_edit(vertices, indices, weights, automatic: SkinWeights) -> WeightEdit:
    """A validated, normalised edit of a rig whose automatic rig is `automatic`.

    vertices : (R,) integer vertex indices, each at most once.
    indices : (R, K) integer joint indices, K <= N; a joint at most once per row (slots
        of weight 0 are free and may repeat).
    weights : (R, K) weights, within the automatic rows' envelope (module docstring).
    Rows keep at most k = ``automatic.n_influences`` influences (the k largest |w|,
    scaled to keep the row's sum). Raises `RetargetError` naming the row, vertex, joint
    and value at fault.
    """
    n_vertices, n_joints = automatic.n_vertices, automatic.n_joints
    v = np.asarray(vertices)
    if v.ndim != 1 or len(v) == 0:
        raise RetargetError(f"vertices must be a non-empty list of vertex indices; got shape {v.shape}")
    if v.dtype.kind not in "iu":
        raise RetargetError(f"vertices must be integers; got {v.dtype} values")
    if len(v) > n_vertices:  # checked before the rows are copied: each vertex at most once
        raise RetargetError(f"the edit has {len(v)} rows; the mesh has only {n_vertices} vertices")
    try:
        idx, w = np.asarray(indices), np.asarray(weights)
    except ValueError as exc:  # ragged lists
        raise RetargetError(f"indices and weights must be rectangular (R, K) arrays: {exc}") from None
    if idx.ndim != 2 or idx.shape != w.shape or len(idx) != len(v) or idx.shape[1] == 0:
        raise RetargetError(
            f"indices and weights must both be ({len(v)}, K) arrays, one row of K >= 1 "
            f"influences per vertex; got {idx.shape} and {w.shape}")
    if idx.shape[1] > n_joints:
        raise RetargetError(f"rows have {idx.shape[1]} influences; the rig has only {n_joints} joints")
    if idx.dtype.kind not in "iu":
        raise RetargetError(f"indices must be integer joint indices; got {idx.dtype} values")
    if w.dtype.kind not in "iuf":
        raise RetargetError(f"weights must be numbers; got {w.dtype} values")
    v = v.astype(np.int64)
    bad = np.flatnonzero((v < 0) | (v >= n_vertices))
    if len(bad):
        r = bad[0]
        raise RetargetError(f"vertex index {v[r]} (row {r}) is out of range: the mesh has "
                            f"{n_vertices} vertices (0..{n_vertices - 1})")
    order = np.argsort(v, kind="stable")
    repeated = np.flatnonzero(np.diff(v[order]) == 0)
    if len(repeated):
        first, second = sorted(order[repeated[0]:repeated[0] + 2])
        raise RetargetError(f"vertex {v[first]} is given twice (rows {first} and {second})")
    idx = idx.astype(np.int64)
    bad = np.argwhere((idx < 0) | (idx >= n_joints))
    if len(bad):
        r, s = bad[0]
        raise RetargetError(f"joint index {idx[r, s]} (row {r}, vertex {v[r]}, slot {s}) is out "
                            f"of range: the rig has {n_joints} joints (0..{n_joints - 1})")
    w = w.astype(np.float64)
    bad = np.argwhere(~np.isfinite(w))
    if len(bad):
        r, s = bad[0]
        raise RetargetError(f"weight {w[r, s]} (row {r}, vertex {v[r]}, joint {idx[r, s]}) is "
                            f"not a finite number")
    _check_distinct_joints(idx, w, v)

    rows = np.zeros((len(v), n_joints))
    np.add.at(rows, (np.arange(len(v))[:, None], idx), w)  # free slots add 0 wherever they point
    _check_envelope(rows, automatic_rows(automatic, v), v)
    kept = SkinWeights.from_dense(rows, automatic.n_influences)
    return WeightEdit(v[order], kept.indices[order], kept.weights[order])


def painted_rig(rig: SkinWeights, edit: WeightEdit) -> SkinWeights:
    """`rig` with the edit's rows in place of its own (a new `SkinWeights`)."""
    if edit.indices.shape[1] != rig.n_influences or (len(edit.vertices) and edit.vertices.max() >= rig.n_vertices):
        raise RetargetError(f"the edit's rows ({edit.indices.shape[1]} influences) do not fit the rig "
                            f"({rig.n_vertices} vertices, {rig.n_influences} influences)")
    indices, weights = rig.indices.copy(), rig.weights.copy()
    indices[edit.vertices] = edit.indices
    weights[edit.vertices] = edit.weights
    return SkinWeights(indices, weights, rig.n_joints, rig.method)


def with_weight(rows: np.ndarray, joint: int, value) -> np.ndarray:
    """(R, N) float64 rows with joint `joint` at `value` and the other influences, the
    root included, rescaled so every row keeps summing to 1 (module docstring).

    rows : (R, N) feature weights, any signs.
    value : (R,) or scalar target weights in [0, 1].
    Raising blends a row toward the row that is all `joint`; lowering toward the other
    influences' non-negative parts normalised to 1 (all root when there are none). For a
    non-negative row summing to at most 1 both are ``others * (1 - b) / (1 - a)``.
    """
    rows = np.asarray(rows, dtype=np.float64)
    b = np.broadcast_to(np.asarray(value, dtype=np.float64), rows.shape[:1])
    if np.any((b < 0) | (b > 1)) or not np.all(np.isfinite(b)):
        raise RetargetError(f"painted weights must lie in [0, 1]; got {b[(b < 0) | (b > 1) | ~np.isfinite(b)][0]}")
    a = rows[:, joint]
    target, _ = _lowered_target(rows, joint)
    raise_, lower = b > a, b < a
    s = np.zeros_like(a)
    s[raise_] = (b[raise_] - a[raise_]) / (1.0 - a[raise_])
    s[lower] = (a[lower] - b[lower]) / a[lower]
    target[raise_] = 0.0
    out = (1.0 - s)[:, None] * rows + s[:, None] * target
    out[:, joint] = np.where(raise_ | lower, b, a)
    return out


def reset_joints(rig: SkinWeights, automatic: SkinWeights, joints=None) -> SkinWeights:
    """The painted `rig` with the influence of `joints` (None: every joint) back to the
    automatic rig's.

    For each joint j in turn, every vertex whose w_j differs between the rigs gets the
    automatic w_j back, the rest of its row (root included) keeping its painted
    proportions: scaled by ``(1 - a) / (1 - p)`` for the painted weight p and automatic
    weight a, which undoes raising or lowering j exactly, or where that would leave the
    envelope (a lowered row of an interpolating rig) by `with_weight`. So resetting the
    joint painted last restores its vertices' automatic rows. Where neither rule can
    reach the automatic w_j (a row painted all j with nothing left to scale, or an
    automatic weight outside [0, 1] that scaling cannot reach inside the envelope) the
    vertex takes its automatic row.
    """
    _check_compatible(rig, automatic)
    if joints is None:
        return SkinWeights(automatic.indices.copy(), automatic.weights.copy(), automatic.n_joints,
                           automatic.method)
    joints = list(joints)
    if not joints:
        raise RetargetError("joints must name at least one joint to reset (null resets all)")
    for j in joints:
        if isinstance(j, bool) or not isinstance(j, (int, np.integer)) or not 0 <= j < rig.n_joints:
            raise RetargetError(f"joint {j!r} is not a joint index: the rig has {rig.n_joints} "
                                f"joints (0..{rig.n_joints - 1})")
    current = rig
    for j in dict.fromkeys(int(j) for j in joints):
        painted, auto = _column(current, j), _column(automatic, j)
        vertices = np.flatnonzero(np.abs(painted - auto) > CHANGED)
        if not len(vertices):
            continue
        rows = automatic_rows(current, vertices)
        auto_rows = automatic_rows(automatic, vertices)
        b, p = auto[vertices], painted[vertices]
        scalable = np.abs(1.0 - p) > CHANGED
        scaled = rows * np.divide(1.0 - b, 1.0 - p, out=np.ones_like(p), where=scalable)[:, None]
        scaled[:, j] = b
        scalable &= _inside(scaled, auto_rows)
        _, room = _lowered_target(rows, j)
        blendable = (b >= 0) & (b <= 1) & ((b >= p) | (room > 0))
        blended = with_weight(rows, j, np.clip(b, 0, 1))
        reset = np.where(scalable[:, None], scaled, np.where(blendable[:, None], blended, auto_rows))
        kept = SkinWeights.from_dense(reset, rig.n_influences)
        current = painted_rig(current, WeightEdit(vertices, kept.indices, kept.weights))
    return current


def painted_rows(rig: SkinWeights, automatic: SkinWeights) -> WeightEdit:
    """The rows of `rig` that differ from the automatic rig's: what turns `automatic`
    into `rig` by `painted_rig` (so a painted rig is stored as its painted rows)."""
    vertices = painted_vertices(rig, automatic)
    return WeightEdit(vertices, rig.indices[vertices], rig.weights[vertices])


def painted_vertices(rig: SkinWeights, automatic: SkinWeights) -> np.ndarray:
    """(P,) int64 ascending: the vertices whose row differs from the automatic rig's."""
    _check_compatible(rig, automatic)
    diff = rig.matrix() - automatic.matrix()
    if hasattr(diff, "tocsr"):
        largest = abs(diff.tocsr()).max(axis=1).toarray().ravel()
    else:
        largest = np.abs(diff).max(1)
    return np.flatnonzero(largest > CHANGED)


def automatic_rows(rig: SkinWeights, vertices) -> np.ndarray:
    """(R, N) float64 dense rows of `rig` for `vertices`."""
    vertices = np.asarray(vertices, dtype=np.int64)
    rows = np.zeros((len(vertices), rig.n_joints))
    np.add.at(rows, (np.arange(len(vertices))[:, None], rig.indices[vertices]), rig.weights[vertices])
    return rows


def _column(rig: SkinWeights, joint: int) -> np.ndarray:
    """(V,) float64 weight of `joint` at every vertex."""
    return np.where(rig.indices == joint, rig.weights.astype(np.float64), 0.0).sum(1)


def _lowered_target(rows: np.ndarray, joint: int) -> tuple[np.ndarray, np.ndarray]:
    """The rows lowering `joint` blends toward, (R, N), and each row's room (R,): the
    non-negative parts of the other influences and of the root, their sum."""
    others = np.maximum(rows, 0.0)
    others[:, joint] = 0.0
    root = np.maximum(0.0, 1.0 - rows.sum(1))
    room = others.sum(1) + root
    target = np.divide(others, room[:, None], out=np.zeros_like(others), where=room[:, None] > 0)
    return target, room


def _check_distinct_joints(idx: np.ndarray, w: np.ndarray, v: np.ndarray) -> None:
    live = np.where(w != 0, idx, -1 - np.arange(idx.shape[1]))  # free slots never collide
    ordered = np.sort(live, axis=1)
    twice = np.argwhere(ordered[:, 1:] == ordered[:, :-1])
    if len(twice):
        r, s = twice[0]
        raise RetargetError(f"joint {ordered[r, s]} is given twice in row {r} (vertex {v[r]}); "
                            f"each joint at most once per row")


def _envelope(auto: np.ndarray) -> tuple[np.ndarray, ...]:
    """(R,) lowest and highest weight and lowest and highest sum the rows of (R, N)
    automatic rows `auto` allow (module docstring)."""
    sums = auto.sum(1)
    return (np.minimum(0.0, auto.min(1)), np.maximum(1.0, auto.max(1)),
            np.minimum(0.0, sums), np.maximum(1.0, sums))


def _inside(rows: np.ndarray, auto: np.ndarray) -> np.ndarray:
    """(R,) bool: each of the (R, N) `rows` lies in its automatic row's envelope."""
    low, high, sum_low, sum_high = _envelope(auto)
    sums = rows.sum(1)
    return ((rows >= low[:, None] - TOLERANCE).all(1) & (rows <= high[:, None] + TOLERANCE).all(1)
            & (sums >= sum_low - TOLERANCE) & (sums <= sum_high + TOLERANCE))


def _check_envelope(rows: np.ndarray, auto: np.ndarray, v: np.ndarray) -> None:
    """Refuse rows outside their automatic rows' envelope (module docstring)."""
    low, high, sum_low, sum_high = _envelope(auto)
    bad = np.argwhere(rows < low[:, None] - TOLERANCE)
    if len(bad):
        r, j = bad[0]
        if low[r] == 0:
            why = (f"vertex {v[r]}'s automatic weights are all non-negative, so its painted "
                   f"ones must be too")
        else:
            why = (f"the most negative automatic weight of vertex {v[r]} is {low[r]:.6g}: painting "
                   f"may shrink negative weights, not deepen them")
        raise RetargetError(f"weight {rows[r, j]:.6g} (row {r}, vertex {v[r]}, joint {j}) is "
                            f"negative; {why}")
    bad = np.argwhere(rows > high[:, None] + TOLERANCE)
    if len(bad):
        r, j = bad[0]
        raise RetargetError(f"weight {rows[r, j]:.6g} (row {r}, vertex {v[r]}, joint {j}) is over "
                            f"{high[r]:.6g}, the most a weight of vertex {v[r]} may be (1, or its "
                            f"largest automatic weight)")
    sums = rows.sum(1)
    over = np.flatnonzero(sums > sum_high + TOLERANCE)
    if len(over):
        r = over[0]
        raise RetargetError(f"row {r} (vertex {v[r]}) sums to {sums[r]:.6g}, over "
                            f"{sum_high[r]:.6g}: a vertex's feature weights sum to at most 1 (or "
                            f"its automatic sum), the static root joint holding the rest")
    under = np.flatnonzero(sums < sum_low - TOLERANCE)
    if len(under):
        r = under[0]
        raise RetargetError(f"row {r} (vertex {v[r]}) sums to {sums[r]:.6g}, below "
                            f"{sum_low[r]:.6g}, its automatic sum")


def _check_compatible(rig: SkinWeights, automatic: SkinWeights) -> None:
    if (rig.n_vertices, rig.n_joints, rig.n_influences) != (
            automatic.n_vertices, automatic.n_joints, automatic.n_influences):
        raise RetargetError(
            f"the painted rig ({rig.n_vertices} vertices, {rig.n_joints} joints, k {rig.n_influences}) "
            f"does not match its automatic rig ({automatic.n_vertices}, {automatic.n_joints}, "
            f"k {automatic.n_influences})")
