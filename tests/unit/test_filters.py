"""Tests for retarget.sources.filters: Woodward's 3-frame mean and the One Euro filter,
offline against online, noise and lag properties, lost points."""

from __future__ import annotations

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.sources.filters import OneEuroFilter, TemporalMean, one_euro, temporal_mean


def test_temporal_mean_is_the_causal_mean_of_three_frames():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(10, 4, 3))
    y = temporal_mean(x)
    np.testing.assert_allclose(y[0], x[0], rtol=1e-6)
    np.testing.assert_allclose(y[1], (x[0] + x[1]) / 2, rtol=1e-5)
    for f in range(2, 10):
        np.testing.assert_allclose(y[f], x[f - 2:f + 1].mean(axis=0), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(temporal_mean(x, window=1), x, rtol=1e-6)


def test_temporal_mean_divides_white_noise_std_by_sqrt_three():
    rng = np.random.default_rng(1)
    noise = rng.normal(scale=2.0, size=(6000, 3, 3))
    ratio = temporal_mean(noise)[2:].std() / noise.std()
    assert abs(ratio - 1 / np.sqrt(3)) < 0.02


def test_temporal_mean_skips_lost_points():
    x = np.arange(8, dtype=float)[:, None, None] * np.ones((1, 2, 2))
    x[3, 0] = np.nan
    x[4:7, 1] = np.nan
    y = temporal_mean(x)
    np.testing.assert_allclose(y[3, 0], (1 + 2) / 2)      # frame 3 lost: mean of 1, 2
    np.testing.assert_allclose(y[4, 0], (2 + 4) / 2)      # frames 2, 4 seen
    assert np.isnan(y[6, 1]).all()                        # lost in frames 4, 5, 6
    np.testing.assert_allclose(y[7, 1], 7.0)              # only frame 7 seen


def test_temporal_mean_online_equals_offline():
    rng = np.random.default_rng(2)
    x = rng.normal(size=(30, 5, 2))
    x[rng.random((30, 5)) < 0.2] = np.nan
    online = TemporalMean(3)
    np.testing.assert_allclose(np.stack([online(f) for f in x]), temporal_mean(x), rtol=1e-6, atol=1e-7, equal_nan=True)
    online.reset()
    np.testing.assert_allclose(online(x[5]), x[5], equal_nan=True)


def test_one_euro_online_equals_offline_and_reset_restarts():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(40, 6, 3))
    t = np.cumsum(rng.uniform(0.01, 0.05, size=40))
    offline = one_euro(x, t, min_cutoff=np.linspace(0.5, 3, 6), beta=0.2)
    f = OneEuroFilter(np.linspace(0.5, 3, 6), 0.2)
    online = np.stack([f(x[i], t[i]) for i in range(40)])
    np.testing.assert_array_equal(online, offline)
    f.reset()
    np.testing.assert_allclose(f(x[7], t[7]), x[7], rtol=1e-6)  # first frame passes through


def test_one_euro_matches_the_scalar_reference_on_one_coordinate():
    # Casiez et al. 2012: alpha = 1 / (1 + tau / te), tau = 1 / (2 pi fc)
    rng = np.random.default_rng(4)
    x = np.cumsum(rng.normal(size=50))
    t = np.arange(50) / 60.0
    min_cutoff, beta, d_cutoff = 1.2, 0.3, 1.0

    def alpha(fc, te):
        return 1.0 / (1.0 + 1.0 / (2 * np.pi * fc * te))

    xh, dxh, expected = x[0], 0.0, [x[0]]
    for i in range(1, 50):
        te = t[i] - t[i - 1]
        dxh = alpha(d_cutoff, te) * (x[i] - xh) / te + (1 - alpha(d_cutoff, te)) * dxh
        fc = min_cutoff + beta * abs(dxh)
        xh = alpha(fc, te) * x[i] + (1 - alpha(fc, te)) * xh
        expected.append(xh)
    got = one_euro(x[:, None, None], t, min_cutoff, beta, d_cutoff)[:, 0, 0]
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-5)


def test_one_euro_low_jitter_at_rest_and_low_lag_in_fast_motion():
    rng = np.random.default_rng(5)
    fps, n = 60.0, 600
    t = np.arange(n) / fps
    noise = rng.normal(scale=0.05, size=(n, 8, 2))
    # a still point and a fast sweep (20 units/s, 400 noise std per second)
    ramp = 20.0 * t[:, None, None] * np.ones((1, 8, 2))
    settled = slice(60, None)

    def jitter(y):
        return float(y[settled].std())

    def lag(y):
        return float(np.abs(y - ramp)[settled].mean())

    plain_rest = one_euro(noise, t, min_cutoff=1.0, beta=0.0)  # a plain 1 Hz low-pass
    euro_rest = one_euro(noise, t, min_cutoff=1.0, beta=0.5)
    plain_fast = one_euro(ramp + noise, t, min_cutoff=1.0, beta=0.0)
    euro_fast = one_euro(ramp + noise, t, min_cutoff=1.0, beta=0.5)
    assert jitter(euro_rest) < 0.5 * noise.std()              # smooths at rest ...
    assert jitter(euro_rest) < 1.5 * jitter(plain_rest)       # ... nearly like the low-pass
    assert lag(euro_fast) < 0.1 * lag(plain_fast)             # but follows fast motion
    # a low-pass as quick in motion (cutoff raised until its lag matches) jitters more
    quick = 1.0
    while lag(one_euro(ramp + noise, t, min_cutoff=quick, beta=0.0)) > lag(euro_fast):
        quick *= 1.5
    assert jitter(one_euro(noise, t, min_cutoff=quick, beta=0.0)) > 2 * jitter(euro_rest)


def test_one_euro_lost_points_stay_lost_and_come_back():
    x = np.ones((20, 3, 2))
    x[:, 1] = np.linspace(0, 5, 20)[:, None]
    x[5:10, 1] = np.nan
    t = np.arange(20) / 30
    y = one_euro(x, t, 1.0, 0.0)
    assert np.isnan(y[5:10, 1]).all()
    assert np.isfinite(y[10:, 1]).all() and np.isfinite(np.delete(y, 1, axis=1)).all()
    np.testing.assert_allclose(y[:, 0], 1.0)
    # held state: the first frame back moves from the last estimate toward the new value
    assert y[4, 1, 0] < y[10, 1, 0] < x[10, 1, 0]


def test_one_euro_equal_times_hold_the_estimate_and_backward_times_are_refused():
    f = OneEuroFilter(1.0, 0.1)
    first = f(np.zeros((2, 2)), 0.0)
    same = f(np.ones((2, 2)), 0.0)
    np.testing.assert_array_equal(same, first)
    with pytest.raises(RetargetError, match="time went backwards"):
        f(np.ones((2, 2)), -0.1)


@pytest.mark.parametrize("kwargs, message", [
    ({"min_cutoff": 0.0}, "min_cutoff must be finite and > 0"),
    ({"beta": -1.0}, "beta must be finite and >= 0"),
    ({"min_cutoff": [[1.0]]}, "min_cutoff must be finite"),
    ({"d_cutoff": np.nan}, "d_cutoff must be finite"),
])
def test_one_euro_refuses_bad_parameters(kwargs, message):
    with pytest.raises(RetargetError, match=message):
        OneEuroFilter(**kwargs)


def test_shapes_are_checked():
    with pytest.raises(RetargetError, match="min_cutoff has 3 values for 2 points"):
        OneEuroFilter([1, 2, 3])(np.zeros((2, 3)), 0.0)
    with pytest.raises(RetargetError, match=r"shape \(F, N, D\)"):
        temporal_mean(np.zeros((3, 2)))
    with pytest.raises(RetargetError, match="window must be an integer >= 1"):
        temporal_mean(np.zeros((3, 2, 2)), window=0)
    with pytest.raises(RetargetError, match=r"times must have shape \(3,\)"):
        one_euro(np.zeros((3, 2, 2)), [0, 1])
    m = TemporalMean()
    m(np.zeros((2, 3)))
    with pytest.raises(RetargetError, match="earlier frames"):
        m(np.zeros((3, 3)))
