"""Tests for retarget.sources.headpose: Kabsch fits against known rigid motions, head
motion removal on the sample face's expressions (ground truth: the same frames before the
head moved), the held-pose policy and the online twin."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.sample_face import demo_weights, posed_vertices, sample_face
from retarget.sources.headpose import (
    STABLE_FALLBACK_NAMES,
    STABLE_POINT_NAMES,
    HeadMotionRemover,
    head_neutral,
    remove_head_motion,
    rigid_transform,
    stable_indices,
)


@pytest.fixture(scope="module")
def performance():
    """Sample-face iBUG landmarks (F, 68, 3) cm with expressions, and the same with head motion."""
    face = sample_face()
    n_frames = 60
    # Every third frame of the 10 s demo loop: all 12 expressions appear.
    weights = demo_weights(n_frames * 5, fps=30.0)[::5]
    still = posed_vertices(face, weights)[:, face.landmarks68]
    rng = np.random.default_rng(7)
    angles = np.cumsum(rng.normal(0, 2.0, (n_frames, 3)), axis=0)  # degrees, a random walk
    rot = Rotation.from_euler("xyz", angles, degrees=True).as_matrix()
    trans = np.cumsum(rng.normal(0, 0.5, (n_frames, 3)), axis=0)  # cm
    moving = np.einsum("fij,fnj->fni", rot, still) + trans[:, None]
    return still, moving, rot, trans, face.vertices[face.landmarks68]


def test_rigid_transform_recovers_a_known_motion_ignoring_nan_rows():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(12, 3)) * 5
    rot = Rotation.random(random_state=3).as_matrix()
    t = np.array([10.0, -4.0, 2.5])
    dst = src @ rot.T + t
    src[4] = np.nan
    dst[7, 1] = np.nan
    dst[0] += 100.0  # an outlier, switched off by its weight
    weights = np.ones(12)
    weights[0] = 0.0
    r_fit, t_fit = rigid_transform(src, dst, weights)
    assert np.allclose(r_fit, rot, atol=1e-12)
    assert np.allclose(t_fit, t, atol=1e-12)


def test_rigid_transform_gives_a_rotation_for_coplanar_points():
    # Coplanar points fit a reflection as well as a rotation; the fit must be the rotation.
    src = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [3, 1, 0]], dtype=float)
    rot = Rotation.from_euler("z", 30, degrees=True).as_matrix()
    r_fit, _ = rigid_transform(src, src @ rot.T)
    assert np.isclose(np.linalg.det(r_fit), 1.0)
    assert np.allclose(r_fit, rot, atol=1e-12)


@pytest.mark.parametrize(
    "src, dst, match",
    [
        (np.eye(3)[:2], np.eye(3)[:2], "at least 3"),
        (np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3.0]]),
         np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3.0]]), "collinear"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan] * 3]),
         np.array([[0, 0, 0], [np.nan] * 3, [0, 1, 0], [0, 0, 1.0]]), "2 usable of 4"),
        (np.zeros((4, 3)), np.zeros((4, 2)), "shape"),
    ],
)
def test_rigid_transform_refuses_degenerate_input(src, dst, match):
    with pytest.raises(RetargetError, match=match):
        rigid_transform(src, dst)


def test_stable_indices_name_the_anchor_points():
    ibug = get_layout("ibug68")
    k = stable_indices("ibug68")
    assert {ibug.point_names[i] for i in k} == set(STABLE_POINT_NAMES)
    # dutreve21 has the nose tip only among the primary anchors: the fallbacks join it.
    dutreve = get_layout("dutreve21")
    names = {dutreve.point_names[i] for i in stable_indices(dutreve)}
    assert "nose_tip" in names and names & set(STABLE_FALLBACK_NAMES)
    assert len(names) >= 3
    with pytest.raises(RetargetError, match="stable points"):
        stable_indices(ibug.select("brows"))


def test_remove_head_motion_undoes_a_pure_rigid_motion_exactly(performance):
    _, moving, rot, trans, neutral = performance
    rigid = np.einsum("fij,nj->fni", rot, neutral) + trans[:, None]
    out, r_fit, t_fit = remove_head_motion(rigid, neutral, stable_indices("ibug68"))
    assert out.dtype == np.float32 and out.shape == rigid.shape
    assert np.abs(out - neutral).max() < 1e-4  # float32 of cm values
    assert np.allclose(r_fit, np.transpose(rot, (0, 2, 1)), atol=1e-9)


def test_remove_head_motion_keeps_the_expressions(performance):
    still, moving, _, _, neutral = performance
    out, _, _ = remove_head_motion(moving, neutral, stable_indices("ibug68"))
    err = np.linalg.norm(out - still, axis=2)
    # The anchors move with expressions (the eye corners 2.4 mm when the brows rise), which
    # tilts the fitted head frame a little: 4 mm at the chin, 10 cm below them, in the
    # surprise frames (jaw open + brows up), far below the chin's own 35 mm motion.
    motion = np.linalg.norm(still - neutral, axis=2)
    assert np.median(err) < 0.01 and np.percentile(err, 95) < 0.2 and err.max() < 0.5  # cm
    assert motion.max() > 7 * err.max()
    # Without removal the error would be the head motion itself.
    assert np.median(np.linalg.norm(moving - still, axis=2)) > 20 * np.median(err)


def test_a_frame_without_a_pose_holds_the_previous_one(performance):
    still, moving, _, _, neutral = performance
    k = stable_indices("ibug68")
    frames = moving.copy()
    frames[0:2, k[2:]] = np.nan  # 2 anchors left: no pose yet
    frames[10, k[:-2]] = np.nan  # 2 anchors left: hold frame 9's
    out, r_fit, t_fit = remove_head_motion(frames, neutral, k)
    assert np.isnan(out[:2]).all() and np.isnan(r_fit[:2]).all() and np.isnan(t_fit[:2]).all()
    assert np.isfinite(out[2:10]).all() and np.isfinite(out[11:]).all()
    assert np.isnan(out[10, k[:-2]]).all() and np.isfinite(np.delete(out[10], k[:-2], 0)).all()
    assert np.array_equal(r_fit[10], r_fit[9]) and np.array_equal(t_fit[10], t_fit[9])
    ref, _, _ = remove_head_motion(moving[9:10], neutral, k)
    assert np.allclose(out[10], frames[10] @ r_fit[9].T + t_fit[9], atol=1e-4, equal_nan=True)
    assert not np.allclose(out[10], ref[0], atol=1e-3)  # the head did move between 9 and 10


def test_online_remover_matches_offline(performance):
    _, moving, _, _, neutral = performance
    k = stable_indices("ibug68")
    frames = moving.copy()
    frames[0, k[2:]] = np.nan
    frames[20, k[:6]] = np.nan
    frames[30, 5] = np.nan
    offline, r_off, _ = remove_head_motion(frames, neutral, k)
    remover = HeadMotionRemover(neutral, k)
    online = np.stack([remover(f) for f in frames])
    assert np.array_equal(np.isnan(online), np.isnan(offline))
    assert np.allclose(online, offline, atol=1e-5, equal_nan=True)
    remover.reset()
    for f in frames[:21]:
        remover(f)
    assert remover.held_ and np.array_equal(remover.rotation_, r_off[19])
    remover.reset()
    assert np.isnan(remover(frames[0])).all()


def test_head_neutral_recovers_the_rest_shape_from_a_moving_head(performance):
    _, _, rot, trans, neutral = performance
    k = stable_indices("ibug68")
    rng = np.random.default_rng(1)
    frames = np.einsum("fij,nj->fni", rot, neutral) + trans[:, None]
    frames = frames + rng.normal(0, 0.02, frames.shape)  # 0.2 mm noise
    frames[3, 50] = np.nan
    estimate = head_neutral(frames[:30], k)
    # In the first frame's head frame: compare after one rigid fit on all points.
    r_fit, t_fit = rigid_transform(estimate, neutral)
    assert np.abs(estimate @ r_fit.T + t_fit - neutral).max() < 0.03
    # The raw per-point median of a moving head is far off.
    raw = np.nanmedian(frames[:30], axis=0)
    r_raw, t_raw = rigid_transform(raw, neutral)
    assert np.abs(raw @ r_raw.T + t_raw - neutral).max() > 0.3
    lost = frames[:30].copy()
    lost[:, 60] = np.nan
    with pytest.raises(RetargetError, match=r"points \[60\] are lost in every frame"):
        head_neutral(lost, k)


def test_remove_head_motion_validates_its_input(performance):
    _, moving, _, _, neutral = performance
    with pytest.raises(RetargetError, match="neutral must have shape"):
        remove_head_motion(moving, neutral[:10], [27, 30, 36])
    with pytest.raises(RetargetError, match="outside"):
        remove_head_motion(moving, neutral, np.array([27, 30, 99]))
    with pytest.raises(RetargetError, match="K >= 3"):
        remove_head_motion(moving, neutral, np.array([27, 30]))
    bad = neutral.copy()
    bad[[27, 28, 29, 30, 36, 39]] = np.nan
    with pytest.raises(RetargetError, match="2 finite stable points"):
        remove_head_motion(moving, bad, stable_indices("ibug68"))


def test_an_anchor_placed_later_anchors_the_next_frames():
    """`HeadMotionRemover.place`: an anchor the neutral lacked joins at its head-frame
    place, and then pins the pose with the others (here it alone sees a turn the three
    first anchors share an offset of one of them among fewer points)."""
    rng = np.random.default_rng(4)
    rest = rng.normal(size=(6, 3)) * 5
    partial = rest.copy()
    partial[3] = np.nan
    remover = HeadMotionRemover(partial, [0, 1, 2, 3])
    assert remover.stable.tolist() == [0, 1, 2]
    turn = Rotation.from_rotvec([0.0, 0.3, 0.0]).as_matrix()
    np.testing.assert_allclose(remover(rest @ turn.T), rest, atol=1e-4)
    remover.place([3], rest[[3]])
    assert remover.stable.tolist() == [0, 1, 2, 3]
    noisy = rest @ turn.T
    noisy[0] += 0.5  # one anchor off: with four, the fit shares it out
    with_four = remover(noisy)
    three = HeadMotionRemover(partial, [0, 1, 2, 3])(noisy)
    others = [1, 2, 3, 4, 5]  # point 0 carries its own offset either way
    assert np.abs(with_four - rest)[others].max() < np.abs(three - rest)[others].max()
    with pytest.raises(RetargetError, match="not all anchors"):
        remover.place([5], rest[[5]])
