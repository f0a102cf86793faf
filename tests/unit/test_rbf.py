"""RBF space transform (Dutreve §2): scipy as oracle, exactness, degenerate-input policy."""

import numpy as np
import pytest
from scipy.interpolate import RBFInterpolator

from retarget.errors import RetargetError
from retarget.rbf import RBFInterpolant, RBFTransform


@pytest.fixture
def cloud():
    rng = np.random.default_rng(1)
    s0 = rng.normal(size=(30, 3))
    t0 = s0 * [1.2, 0.9, 1.1] + 0.1 * np.sin(3 * s0)
    query = rng.normal(size=(50, 3))
    return s0, t0, query


@pytest.mark.parametrize("kernel,kwargs,scipy_kwargs", [
    ("linear", {}, {"kernel": "linear", "degree": 1}),
    ("thin_plate_spline", {}, {"kernel": "thin_plate_spline", "degree": 1}),
    ("gaussian", {"shape": 2.0}, {"kernel": "gaussian", "epsilon": 0.5, "degree": -1}),
    ("linear", {"degree": 0}, {"kernel": "linear", "degree": 0}),
])
def test_matches_scipy_where_the_maths_is_the_same(cloud, kernel, kwargs, scipy_kwargs):
    s0, t0, query = cloud
    ours = RBFTransform(kernel, smoothing=0.0, **kwargs).fit(s0, t0).transform(query)
    theirs = RBFInterpolator(s0, t0, **scipy_kwargs)(query)
    np.testing.assert_allclose(ours, theirs, rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize("kernel", ["adaptive_multiquadric", "linear", "thin_plate_spline", "exponential", "gaussian"])
def test_interpolates_the_training_pairs(cloud, kernel):
    s0, t0, _ = cloud
    np.testing.assert_allclose(RBFTransform(kernel, smoothing=0.0).fit(s0, t0).transform(s0), t0, atol=1e-8)


def test_adaptive_multiquadric_uses_nearest_other_centre_distance(cloud):
    s0, t0, _ = cloud
    rbf = RBFTransform("adaptive_multiquadric").fit(s0, t0)
    d = np.linalg.norm(s0[:, None] - s0[None], axis=2)
    np.fill_diagonal(d, np.inf)
    np.testing.assert_allclose(rbf.shape_, d.min(1))
    # Dutreve eq. 1: F(s) = sum_i w_i sqrt(|s - s_i|² + sc_i²), no polynomial as written.
    x = np.array([[0.3, -0.2, 0.5]])
    h = np.sqrt(np.linalg.norm(x - s0, axis=1) ** 2 + rbf.shape_**2)
    np.testing.assert_allclose(rbf.transform(x)[0], h @ rbf.coefs_, atol=1e-10)


def test_linear_polynomial_reproduces_an_affine_map_exactly(cloud):
    s0, _, query = cloud
    a = np.array([[1.5, 0.2, 0.0], [-0.1, 0.8, 0.3], [0.0, 0.4, 1.1]])
    b = np.array([3.0, -1.0, 2.0])
    rbf = RBFTransform("linear", smoothing=0.0).fit(s0, s0 @ a.T + b)
    np.testing.assert_allclose(rbf.transform(query), query @ a.T + b, atol=1e-9)


def test_2d_source_maps_into_3d_target_space(cloud):
    s0, t0, _ = cloud
    rbf = RBFTransform("linear", smoothing=0.0).fit(s0[:, :2], t0)
    out = rbf.transform(s0[:, :2])
    assert out.shape == (30, 3)
    np.testing.assert_allclose(out, t0, atol=1e-8)
    # z = 0 padding is the same thing (Dutreve §4)
    padded = np.hstack([s0[:, :2], np.zeros((30, 1))])
    np.testing.assert_allclose(rbf.transform(padded), out)
    assert len(rbf.axes_) == 2  # the polynomial spans the source plane only


def test_coplanar_3d_source_is_handled_as_the_plane_it_spans(cloud):
    """Markers seen by one camera, stored with a constant z: the polynomial cannot span
    the missing axis, so the fit is the 2D one, and scipy's 2D interpolator agrees."""
    s0, t0, query = cloud
    flat = s0.copy()
    flat[:, 2] = 4.0
    assert np.isfinite(RBFTransform("linear").fit(flat, t0).transform(query)).all()
    exact = RBFTransform("linear", smoothing=0.0).fit(flat, t0)
    np.testing.assert_allclose(exact.transform(flat), t0, atol=1e-8)
    on_plane = np.hstack([query[:, :2], np.full((50, 1), 4.0)])
    theirs = RBFInterpolator(s0[:, :2], t0, kernel="linear", degree=1)(query[:, :2])
    np.testing.assert_allclose(exact.transform(on_plane), theirs, rtol=1e-7, atol=1e-9)


def test_smoothing_is_scale_free(cloud):
    s0, t0, query = cloud
    small = RBFTransform("linear", smoothing=10.0).fit(s0, t0).transform(query)
    big = RBFTransform("linear", smoothing=10.0).fit(10 * s0, 10 * t0).transform(10 * query)
    np.testing.assert_allclose(big, 10 * small, rtol=1e-8, atol=1e-8)


def test_large_smoothing_leaves_the_least_squares_affine_map(cloud):
    s0, t0, query = cloud
    x = np.hstack([s0, np.ones((len(s0), 1))])
    affine, *_ = np.linalg.lstsq(x, t0, rcond=None)
    out = RBFTransform("linear", smoothing=1e9).fit(s0, t0).transform(query)
    np.testing.assert_allclose(out, np.hstack([query, np.ones((50, 1))]) @ affine, atol=1e-5)


def test_lost_points_stay_lost(cloud):
    s0, t0, query = cloud
    query[3] = np.nan
    out = RBFTransform("linear").fit(s0, t0).transform(query)
    assert np.isnan(out[3]).all() and np.isfinite(np.delete(out, 3, axis=0)).all()


def test_operator_is_the_linear_map_of_the_transform(cloud):
    s0, t0, query = cloud
    rbf = RBFTransform("thin_plate_spline").fit(s0, t0)
    np.testing.assert_allclose(RBFInterpolant("thin_plate_spline").fit(s0).operator(query) @ t0,
                               rbf.transform(query), atol=1e-9)


@pytest.mark.parametrize("source,target,message", [
    (lambda s: np.vstack([s, s[4:5]]), lambda t: np.vstack([t, t[0:1]]), "source points 4 and 30 coincide"),
    (lambda s: s[:5], lambda t: t[:4], "same number of feature points; got 5 and 4"),
    (lambda s: np.where(np.arange(30)[:, None] == 7, np.nan, s), lambda t: t, "point 7"),
    (lambda s: np.outer(np.arange(30.0), [1.0, 2.0, 3.0]), lambda t: t, "collinear"),
    (lambda s: s[:, :1], lambda t: t, r"shape \(N, 2\) or \(N, 3\)"),
    (lambda s: s[:2], lambda t: t[:2], "collinear"),
])
def test_degenerate_input_is_refused_with_a_reason(cloud, source, target, message):
    s0, t0, _ = cloud
    with pytest.raises(RetargetError, match=message):
        RBFTransform("linear").fit(source(s0), target(t0))


def test_misuse_is_refused(cloud):
    s0, t0, _ = cloud
    with pytest.raises(RetargetError, match="not fitted"):
        RBFTransform().transform(s0)
    with pytest.raises(RetargetError, match="unknown RBF kernel 'cubic'"):
        RBFTransform("cubic")
    with pytest.raises(RetargetError, match="smoothing"):
        RBFTransform(smoothing=-1.0)
    with pytest.raises(RetargetError, match="degree"):
        RBFTransform(degree=2)
