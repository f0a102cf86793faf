"""The retargeting pipeline (Dutreve §4): transfer, partial retargeting, lost points, 2D."""

import numpy as np
import pytest
from scipy.interpolate import RBFInterpolator

from retarget.errors import RetargetError
from retarget.pipeline import Retargeter, transfer
from retarget.skin import SkinWeights


@pytest.fixture
def points():
    rng = np.random.default_rng(5)
    s0 = rng.normal(size=(20, 3))
    t0 = 3.0 * s0 + [1.0, 2.0, 3.0] + 0.05 * rng.normal(size=(20, 3))
    frames = s0 + 0.1 * rng.normal(size=(4, 20, 3))
    return s0, t0, frames


def test_neutral_source_gives_zero_displacement_even_when_smoothed(points):
    s0, t0, _ = points
    for smoothing in (0.0, 100.0):
        d = Retargeter(smoothing=smoothing).fit(s0, t0).displacements(s0)
        assert d.dtype == np.float32 and d.shape == (20, 3)
        np.testing.assert_allclose(d, 0.0, atol=1e-5)


def test_displacements_follow_the_fitted_space_transform(points):
    s0, t0, frames = points
    rt = Retargeter("linear", smoothing=0.0).fit(s0, t0)
    expected = rt.transform_.transform(frames) - t0
    np.testing.assert_allclose(rt.displacements(frames), expected, atol=1e-5)
    oracle = RBFInterpolator(s0, t0, kernel="linear", degree=1)  # Dutreve eq. 1-2, scipy's own solve
    np.testing.assert_allclose(rt.displacements(frames),
                               np.stack([oracle(f) for f in frames]) - t0, atol=1e-5)
    # A source three times smaller than the target: motion is scaled up by the transform.
    assert np.linalg.norm(rt.displacements(frames)) > 2.0 * np.linalg.norm(frames - s0)


def test_partial_retargeting_holds_masked_points_at_neutral(points):
    s0, t0, frames = points
    mask = np.zeros(20, dtype=bool)
    mask[:5] = True
    d = Retargeter().fit(s0, t0).displacements(frames, mask=mask)
    assert np.all(d[:, 5:] == 0.0) and np.abs(d[:, :5]).max() > 0.01


def test_a_lost_point_keeps_its_neutral_position_for_that_frame(points):
    s0, t0, frames = points
    frames = frames.copy()
    frames[2, 7] = np.nan
    d = Retargeter().fit(s0, t0).displacements(frames)
    assert np.all(d[2, 7] == 0.0) and np.isfinite(d).all() and np.abs(d[1, 7]).max() > 0


def test_2d_source_drives_3d_target(points):
    s0, t0, frames = points
    rt = Retargeter().fit(s0[:, :2], t0)
    d = rt.displacements(frames[:, :, :2])
    assert d.shape == (4, 20, 3) and np.isfinite(d).all()
    with pytest.raises(RetargetError, match=r"shape \(F, 20, 2\)"):
        rt.displacements(frames)
    # the same kernel in scipy, fitted on the image-plane points, is the oracle
    exact = Retargeter("linear", smoothing=0.0).fit(s0[:, :2], t0)
    theirs = RBFInterpolator(s0[:, :2], t0, kernel="linear", degree=1)
    expected = np.stack([theirs(f[:, :2]) for f in frames]) - t0
    np.testing.assert_allclose(exact.displacements(frames[:, :, :2]), expected, atol=1e-5)


def test_transfer_deforms_the_mesh_by_skinning(points):
    s0, t0, frames = points
    rng = np.random.default_rng(6)
    vertices = rng.normal(size=(50, 3))
    dense = rng.random((50, 20))
    dense /= dense.sum(1, keepdims=True)
    sk = SkinWeights.from_dense(dense)
    rt = Retargeter().fit(s0, t0)
    seen = []
    out = transfer(vertices, sk, rt, frames, progress=seen.append, chunk=3)
    assert out.shape == (4, 50, 3) and out.dtype == np.float32
    np.testing.assert_allclose(out[1], vertices + dense @ rt.displacements(frames[1]), atol=1e-5)
    assert seen[-1] == 1.0 and len(seen) == 2


@pytest.mark.parametrize("call,message", [
    (lambda s0, t0, f: Retargeter().displacements(f), "not fitted"),
    (lambda s0, t0, f: Retargeter().fit(s0[:19], t0), "same number of feature points; got 19 and 20"),
    (lambda s0, t0, f: Retargeter().fit(s0, t0).displacements(f, mask=np.ones(3, bool)), r"mask must be a boolean array of shape \(20,\)"),
    (lambda s0, t0, f: Retargeter().fit(s0, t0[:, :2]), "target neutral"),
    (lambda s0, t0, f: transfer(np.zeros((7, 3)), SkinWeights.from_dense(np.ones((5, 20)) / 20),
                                Retargeter().fit(s0, t0), f), "the rig has 20 joints for 5 vertices; the mesh has 7"),
])
def test_misuse_is_refused_with_a_reason(points, call, message):
    with pytest.raises(RetargetError, match=message):
        call(*points)


def test_default_smoothing_follows_the_source_dimension(points):
    from retarget.pipeline import DEFAULT_SMOOTHING

    s0, t0, _ = points
    assert Retargeter().fit(s0, t0).transform_.smoothing == DEFAULT_SMOOTHING[3]
    assert Retargeter().fit(s0[:, :2], t0).transform_.smoothing == DEFAULT_SMOOTHING[2]
    assert Retargeter(smoothing=0.5).fit(s0[:, :2], t0).transform_.smoothing == 0.5


def test_a_source_with_fewer_points_drives_every_joint():
    """21 markers (NaN rows in the neutral for the 47 others) on a 68-joint target: the
    driven joints move as with the full source, the others follow by interpolation."""
    from retarget.layouts import get_layout
    from retarget.sample_face import sample_face

    face = sample_face()
    lm = np.asarray(face.landmarks68)
    s0 = face.vertices[lm]
    t0 = s0 * 1.3 + np.array([1.0, -2.0, 0.5])
    frame = s0 + face.expressions[list(face.expression_names).index("jawOpen")][lm]
    full = Retargeter().fit(s0, t0).displacements(frame)
    driven = np.zeros(68, bool)
    driven[list(get_layout("dutreve21").ibug68)] = True
    partial_neutral = np.where(driven[:, None], s0, np.nan)
    part = Retargeter().fit(partial_neutral, t0).displacements(frame)
    np.testing.assert_allclose(part[driven], full[driven], atol=1e-5)
    # the undriven joints move with the expression, and in the same direction as truth
    moved = np.linalg.norm(full, axis=1) > 0.1
    assert (moved & ~driven).sum() >= 10
    cos = (part * full).sum(1) / (np.linalg.norm(part, axis=1) * np.linalg.norm(full, axis=1) + 1e-12)
    assert np.median(cos[moved & ~driven]) > 0.8
    # the neutral frame stays at rest everywhere
    assert np.abs(Retargeter().fit(partial_neutral, t0).displacements(s0)).max() < 1e-5
