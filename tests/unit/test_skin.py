"""Skin weights container and linear blend skinning (Dutreve §3.1)."""

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.skin import SkinWeights, skin_displacements


@pytest.fixture
def dense():
    rng = np.random.default_rng(2)
    w = rng.random((40, 6)) ** 4
    w[5] = 0.0  # a vertex on the root joint only
    return w / np.maximum(w.sum(1, keepdims=True), 1e-9) * rng.uniform(0.5, 1.0, (40, 1))


def test_lbs_is_vertex_plus_weighted_feature_displacements(dense):
    sk = SkinWeights.from_dense(dense)
    d = np.random.default_rng(3).normal(size=(6, 3))
    out = skin_displacements(sk, d)
    np.testing.assert_allclose(out, dense @ d, rtol=1e-5, atol=1e-6)
    assert np.all(out[5] == 0.0)


def test_batched_frames_match_frame_by_frame(dense):
    sk = SkinWeights.from_dense(dense, k=3)
    d = np.random.default_rng(4).normal(size=(5, 6, 3))
    batch = skin_displacements(sk.matrix(), d)
    for f in range(5):
        np.testing.assert_allclose(batch[f], skin_displacements(sk, d[f]), atol=1e-6)


def test_top_k_keeps_the_largest_and_each_rows_sum(dense):
    sk = SkinWeights.from_dense(dense, k=2)
    assert sk.indices.shape == (40, 2)
    np.testing.assert_allclose(sk.row_sums(), dense.sum(1), rtol=1e-5, atol=1e-7)
    largest = np.argsort(-dense, axis=1)[:, :2]
    rows = dense.sum(1) > 0
    assert np.array_equal(np.sort(sk.indices[rows], 1), np.sort(largest[rows], 1))


def test_save_and_load_round_trip(tmp_path, dense):
    sk = SkinWeights.from_dense(dense, k=4, method="ellipsoid")
    sk.save(tmp_path / "rig.npz")
    back = SkinWeights.load(tmp_path / "rig.npz")
    assert back.method == "ellipsoid" and back.n_joints == 6
    np.testing.assert_array_equal(back.indices, sk.indices)
    np.testing.assert_array_equal(back.weights, sk.weights)


def test_bad_rigs_and_shapes_are_refused(tmp_path, dense):
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(RetargetError, match="could not read rig"):
        SkinWeights.load(tmp_path / "bad.npz")
    np.savez(tmp_path / "inconsistent.npz", joint_indices=np.full((3, 2), 9), weights=np.ones((3, 2)), n_joints=4)
    with pytest.raises(RetargetError, match="inconsistent"):
        SkinWeights.load(tmp_path / "inconsistent.npz")
    with pytest.raises(RetargetError, match=r"shape \(\.\.\., 6, 3\)"):
        skin_displacements(SkinWeights.from_dense(dense), np.zeros((5, 3)))
