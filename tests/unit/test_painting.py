"""Painted skin weights (retarget.weights.painting): the painting rule, edits validated
against the automatic rig's envelope, merging, resetting joints; the browser's twin of
the rule (web/static/js/weightRows.js, run in node) against the library's."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.skin import SkinWeights
from retarget.weights.painting import (
    automatic_rows, painted_rig, painted_vertices, reset_joints, weight_edit, with_weight,
)

ROOT = Path(__file__).resolve().parents[2]
N = 7


def convex_rig(n_vertices=30, k=3, seed=0) -> SkinWeights:
    """A sparse non-negative rig (like ellipsoid's): k of N joints per vertex, rows summing
    to 1 or less, one vertex on the root only."""
    rng = np.random.default_rng(seed)
    dense = rng.random((n_vertices, N)) ** 3
    dense *= rng.uniform(0.4, 1.0, (n_vertices, 1)) / dense.sum(1, keepdims=True)
    dense[0] = 0.0
    return SkinWeights.from_dense(dense, k, "ellipsoid")


def signed_rig(n_vertices=30, seed=1) -> SkinWeights:
    """A dense rig with negative weights and rows overshooting 1 (like biharmonic's)."""
    rng = np.random.default_rng(seed)
    dense = rng.normal(0.05, 0.2, (n_vertices, N))
    dense[:, 2] = rng.uniform(0.3, 1.2, n_vertices)
    return SkinWeights.from_dense(dense, None, "biharmonic")


def dense(rig: SkinWeights) -> np.ndarray:
    return rig.dense()


# -- the painting rule ------------------------------------------------------------------

@pytest.mark.parametrize("b", [0.0, 0.2, 0.55, 1.0])
def test_painting_a_non_negative_row_scales_the_others_and_the_root_alike(b):
    rows = dense(convex_rig())[1:]
    j = 1
    a = rows[:, j]
    out = with_weight(rows, j, b)
    np.testing.assert_allclose(out[:, j], b)
    others = np.delete(rows, j, axis=1)
    expected = others * ((1 - b) / (1 - a))[:, None]
    np.testing.assert_allclose(np.delete(out, j, axis=1), expected, atol=1e-12)
    root, new_root = 1 - rows.sum(1), 1 - out.sum(1)
    np.testing.assert_allclose(new_root, root * (1 - b) / (1 - a), atol=1e-12)
    assert out.min() >= 0 and out.sum(1).max() <= 1 + 1e-12


def test_lowering_a_row_with_nothing_else_gives_the_rest_to_the_root():
    row = np.zeros((1, N))
    row[0, 3] = 1.0
    out = with_weight(row, 3, 0.25)
    assert out[0, 3] == 0.25 and np.count_nonzero(out) == 1  # the root holds 0.75


def test_painting_a_signed_row_is_continuous_and_never_deepens_a_negative_weight():
    rows = dense(signed_rig())
    j = 4
    for b in (0.0, 0.3, 1.0):
        out = with_weight(rows, j, b)
        others = np.delete(rows, j, 1)
        new = np.delete(out, j, 1)
        assert np.all(new >= np.minimum(others, 0) - 1e-12)  # negatives shrink or stay
        assert np.all(out.sum(1) <= np.maximum(rows.sum(1), 1) + 1e-12)
    # continuity: a tiny change of w_j changes the row by about as much
    a = np.clip(rows[:, j], 0, 1)
    step = with_weight(rows, j, np.clip(a + 1e-6, 0, 1)) - with_weight(rows, j, a)
    assert np.abs(step).max() < 1e-4


def test_painting_refuses_values_outside_0_1():
    with pytest.raises(RetargetError, match=r"\[0, 1\]; got 1.5"):
        with_weight(np.zeros((2, N)), 0, [0.5, 1.5])


# -- edits ---------------------------------------------------------------------------------

def edit_of(rig, vertices, rows):
    """Edit arguments (vertices, (R, N) joint indices, (R, N) weights) of dense rows."""
    rows = np.asarray(rows)
    return np.asarray(vertices), np.broadcast_to(np.arange(rig.n_joints), rows.shape), rows


def test_an_edit_keeps_the_k_largest_influences_and_each_rows_sum():
    rig = convex_rig(k=3)
    rows = np.array([[0.05, 0.3, 0.0, 0.2, 0.1, 0.25, 0.0],
                     [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
    edit = weight_edit(*edit_of(rig, [9, 4], rows), rig)
    assert list(edit.vertices) == [4, 9]  # ascending
    assert edit.indices.shape == (2, 3)
    kept = automatic_rows(SkinWeights(edit.indices, edit.weights, N), [1])[0]
    assert set(np.flatnonzero(kept)) == {1, 3, 5}
    np.testing.assert_allclose(kept.sum(), rows[0].sum(), rtol=1e-6)
    np.testing.assert_allclose(kept[[1, 3, 5]] / kept[[1, 3, 5]].sum(), np.array([0.3, 0.2, 0.25]) / 0.75, rtol=1e-6)
    assert not edit.weights[0].any()  # vertex 4 on the root only


def test_an_edit_may_list_free_slots_twice_and_any_order():
    rig = convex_rig(k=3)
    edit = weight_edit([5], [[6, 0, 0, 2]], [[0.5, 0.0, 0.0, 0.25]], rig)
    row = automatic_rows(SkinWeights(edit.indices, edit.weights, N), [0])[0]
    np.testing.assert_allclose(row, [0, 0, 0.25, 0, 0, 0, 0.5])


@pytest.mark.parametrize("vertices, indices, weights, message", [
    ([], np.zeros((0, 3), int), np.zeros((0, 3)), r"non-empty list of vertex indices; got shape \(0,\)"),
    ([1.0], [[0]], [[0.5]], r"vertices must be integers; got float64"),
    ([1, 2], [[0, 1]], [[0.5, 0.1]], r"must both be \(2, K\) arrays.*got \(1, 2\) and \(1, 2\)"),
    ([1], [[0, 1]], [[0.5]], r"got \(1, 2\) and \(1, 1\)"),
    ([30], [[0]], [[0.5]], r"vertex index 30 \(row 0\) is out of range: the mesh has 30 vertices \(0..29\)"),
    ([3, -1], [[0], [0]], [[0.5], [0.5]], r"vertex index -1 \(row 1\) is out of range"),
    ([3, 8, 3], [[0]] * 3, [[0.5]] * 3, r"vertex 3 is given twice \(rows 0 and 2\)"),
    ([3], [[0, 7]], [[0.5, 0.1]], r"joint index 7 \(row 0, vertex 3, slot 1\) is out of range: the rig has 7 joints \(0..6\)"),
    ([3], [[0.0]], [[0.5]], r"indices must be integer joint indices; got float64"),
    ([3], [[0, 1]], [[np.nan, 0.1]], r"weight nan \(row 0, vertex 3, joint 0\) is not a finite number"),
    ([3], [[0, 1]], [[0.5, np.inf]], r"weight inf \(row 0, vertex 3, joint 1\) is not a finite number"),
    ([3], [[2, 2]], [[0.3, 0.1]], r"joint 2 is given twice in row 0 \(vertex 3\)"),
    ([3], [[0, 1]], [[0.5, -0.2]], r"weight -0.2 \(row 0, vertex 3, joint 1\) is negative; vertex 3's automatic "
                                   r"weights are all non-negative, so its painted ones must be too"),
    ([3, 4], [[0, 1]] * 2, [[0.5, 0.1], [0.9, 0.3]], r"row 1 \(vertex 4\) sums to 1.2, over 1: .*static root joint"),
    ([3], [[0, 1]], [[1.5, 0.0]], r"weight 1.5 \(row 0, vertex 3, joint 0\) is over 1"),
    ([3], list(range(N)) + [0], [[0.1] * 8], r"rows have 8 influences; the rig has only 7 joints"),
])
def test_bad_edits_are_refused_with_the_reason(vertices, indices, weights, message):
    rig = convex_rig()
    indices, weights = np.asarray(indices), np.asarray(weights)
    if indices.ndim == 1:
        indices, weights = indices[None], weights.reshape(1, -1)
    with pytest.raises(RetargetError, match=message):
        weight_edit(np.asarray(vertices, dtype=np.asarray(vertices).dtype if len(vertices) else int),
                    indices, weights, rig)


def test_a_signed_rig_accepts_its_own_negatives_and_refuses_deeper_ones():
    rig = signed_rig()
    auto = dense(rig)
    v = int(np.argmin(auto.min(1)))
    row = auto[v].copy()
    weight_edit(*edit_of(rig, [v], [row]), rig)  # the automatic row itself is fine
    j = int(np.argmin(row))
    row[j] -= 0.05
    with pytest.raises(RetargetError, match=rf"vertex {v}, joint {j}\) is negative; the most negative automatic "
                                            rf"weight of vertex {v} is {auto[v].min():.6g}: painting may shrink"):
        weight_edit(*edit_of(rig, [v], [row]), rig)


def test_merging_an_edit_replaces_only_its_rows():
    rig = convex_rig()
    rows = with_weight(automatic_rows(rig, [2, 11]), 4, 0.8)
    painted = painted_rig(rig, weight_edit(*edit_of(rig, [2, 11], rows), rig))
    after, before = dense(painted), dense(rig)
    np.testing.assert_allclose(after[[2, 11]], dense(SkinWeights.from_dense(rows, 3)), atol=1e-6)
    assert np.all(after[[2, 11], 4] > 0.8)  # joint 4 kept, scaled up with the others kept
    untouched = np.setdiff1d(np.arange(rig.n_vertices), [2, 11])
    assert np.array_equal(after[untouched], before[untouched])
    assert list(painted_vertices(painted, rig)) == [2, 11]
    assert painted.n_influences == rig.n_influences and painted.method == rig.method


def test_a_painted_rig_is_its_automatic_rig_plus_its_painted_rows(tmp_path):
    from retarget.weights.painting import WeightEdit, painted_rows
    rig = convex_rig()
    painted = paint(rig, rig, [3, 12, 20], 5, [0.9, 0.7, 0.4])
    rows = painted_rows(painted, rig)
    assert list(rows.vertices) == [3, 12, 20]
    rows.save(tmp_path / "rows.npz")
    again = painted_rig(rig, WeightEdit.load(tmp_path / "rows.npz"))
    assert np.array_equal(again.indices, painted.indices) and np.array_equal(again.weights, painted.weights)
    np.savez(tmp_path / "bad.npz", vertices=np.arange(2), joint_indices=np.zeros((3, 2)), weights=np.zeros((3, 2)))
    with pytest.raises(RetargetError, match=r"painted rows .*bad.npz' are inconsistent"):
        WeightEdit.load(tmp_path / "bad.npz")
    with pytest.raises(RetargetError, match=r"could not read painted rows"):
        WeightEdit.load(tmp_path / "missing.npz")


# -- reset ---------------------------------------------------------------------------------

def paint(rig, automatic, vertices, joint, values):
    rows = with_weight(automatic_rows(rig, vertices), joint, values)
    return painted_rig(rig, weight_edit(*edit_of(rig, vertices, rows), automatic))


def test_resetting_a_joint_paints_it_back_to_automatic_and_keeps_the_other_joints_painting():
    auto = convex_rig(k=N)
    painted = paint(auto, auto, [1, 2, 3, 4], 2, [0.9, 0.0, 0.5, 1.0])
    painted = paint(painted, auto, [5, 6], 5, [0.7, 0.1])
    assert set(painted_vertices(painted, auto)) == {1, 2, 3, 4, 5, 6}

    reset = reset_joints(painted, auto, [2])
    np.testing.assert_allclose(dense(reset)[:, 2], dense(auto)[:, 2], atol=1e-6)  # joint 2 is back
    np.testing.assert_allclose(dense(reset)[:5], dense(auto)[:5], atol=1e-6)  # vertex 4 (all joint 2) too
    # painting joint 5 had scaled joint 2 at vertices 5 and 6: resetting 2 scales 5 there in turn
    assert np.all(np.abs(dense(reset)[5:7, 5] - dense(auto)[5:7, 5]) > 1e-3)
    assert list(painted_vertices(reset, auto)) == [5, 6]
    assert not len(painted_vertices(reset_joints(painted, auto, None), auto))


def test_resetting_a_joint_keeps_the_proportions_of_the_rest_of_the_row():
    auto = convex_rig(k=N)
    once = paint(auto, auto, [7], 1, [0.6])
    twice = paint(once, auto, [7], 3, [0.2])
    row = dense(reset_joints(twice, auto, [3]))[7]
    assert abs(row[3] - dense(auto)[7, 3]) < 1e-6
    before = np.append(np.delete(dense(twice)[7], 3), 1 - dense(twice)[7].sum())  # the root last
    after = np.append(np.delete(row, 3), 1 - row.sum())
    np.testing.assert_allclose(after, before * (after[-1] / before[-1]), atol=1e-6)


def test_reset_of_a_signed_rig_undoes_raising_exactly_and_lowering_within_the_envelope():
    auto = signed_rig()
    a = dense(auto)[:, 2]
    raised = np.flatnonzero(a < 0.9)[:8]
    painted = paint(auto, auto, raised, 2, np.minimum(1.0, a[raised] + 0.1))
    assert not len(painted_vertices(reset_joints(painted, auto, [2]), auto))

    lowered = np.flatnonzero((a > 0.2) & (a < 1))[:8]
    painted = paint(auto, auto, lowered, 2, 0.0)
    reset = reset_joints(painted, auto, [2, 2])
    weight_edit(np.arange(auto.n_vertices), *np.broadcast_arrays(np.arange(N), dense(reset)), auto)  # valid
    np.testing.assert_allclose(dense(reset)[:, 2], a, atol=1e-6)


@pytest.mark.parametrize("joints, message", [
    ([], "at least one joint"), ([7], r"joint 7 is not a joint index: the rig has 7 joints \(0..6\)"),
    ([-1], "joint -1 is not"), (["2"], "joint '2' is not"), ([True], "joint True is not"),
])
def test_bad_reset_joints_are_refused(joints, message):
    rig = convex_rig()
    with pytest.raises(RetargetError, match=message):
        reset_joints(rig, rig, joints)


def test_a_rig_of_another_shape_is_not_its_automatic_rig():
    with pytest.raises(RetargetError, match=r"does not match its automatic rig"):
        reset_joints(convex_rig(k=3), convex_rig(k=4), [1])


# -- the browser's twin ------------------------------------------------------------------

def paint_in_node(tmp_path, rig: SkinWeights, ops) -> tuple[np.ndarray, np.ndarray]:
    node = shutil.which("node")
    assert node, "node (Node.js 20) is required: the browser's painting rule is tested with it"
    path = tmp_path / "rows.json"
    path.write_text(json.dumps({"k": rig.n_influences, "indices": rig.indices.ravel().tolist(),
                                "weights": rig.weights.astype(float).ravel().tolist(), "ops": ops}))
    out = subprocess.run([node, str(ROOT / "tests" / "js" / "paint_rows.mjs"), str(path)],
                         capture_output=True, text=True, check=True)
    result = json.loads(out.stdout)
    shape = rig.indices.shape
    return (np.array(result["indices"], np.int32).reshape(shape),
            np.array(result["weights"], np.float32).reshape(shape))


@pytest.mark.parametrize("make", [lambda: convex_rig(k=3), lambda: convex_rig(k=N), signed_rig])
def test_the_browser_paints_rows_as_the_library_does(tmp_path, make):
    rig = make()
    rng = np.random.default_rng(5)
    ops = [[int(v), int(rng.integers(N)), float(rng.choice([0.0, 1.0, rng.random()]))]
           for v in rng.permutation(rig.n_vertices)]
    indices, weights = paint_in_node(tmp_path, rig, ops)
    got = dense(SkinWeights(indices, weights, N))
    expected = automatic_rows(rig, np.arange(rig.n_vertices))
    for v, j, b in ops:
        expected[v] = dense(SkinWeights.from_dense(with_weight(expected[v:v + 1], j, b), rig.n_influences))[0]
    np.testing.assert_allclose(got, expected, atol=2e-6)
    # and the library accepts every row the browser painted
    weight_edit(np.arange(rig.n_vertices), indices, weights, rig)
