"""ArkitDrive (the stream's per-frame 52 weights with the user's gains) and ArkitSettings
(gains, painted fixes, rig: checked, round-tripped, applied), on synthetic shapes."""

import math

import numpy as np
import pytest

from retarget.arkit import ARKIT_NAMES, ArkitDrive, ArkitSettings, ArkitShapes, ArkitSolver
from retarget.errors import RetargetError


@pytest.fixture(scope="module")
def shapes() -> ArkitShapes:
    rng = np.random.default_rng(16)
    return ArkitShapes(ARKIT_NAMES, rng.normal(size=(52, 30, 3)).astype(np.float32),
                       rng.normal(size=(52, 68, 3)).astype(np.float32))


def test_weights_are_the_solvers_times_the_gains_clipped(shapes):
    gains = np.ones(52)
    jaw, smile = ARKIT_NAMES.index("jawOpen"), ARKIT_NAMES.index("mouthSmileLeft")
    gains[jaw], gains[smile] = 2.0, 0.0
    truth = np.zeros(52)
    truth[[jaw, smile, ARKIT_NAMES.index("eyeBlinkRight")]] = [0.7, 0.5, 0.3]
    frames = np.stack([np.tensordot(s * truth, shapes.at_points, axes=1) for s in (0.2, 0.4, 1.0)])
    drive, solver = ArkitDrive(shapes, gains), ArkitSolver(shapes.at_points)
    for frame in frames:
        w = drive.weights(frame)
        assert w.dtype == np.float32 and w.shape == (52,)
        np.testing.assert_allclose(w, np.clip(solver.solve(frame) * gains, 0, 1).astype(np.float32))
    assert w[jaw] == 1.0 and w[smile] == 0.0  # 0.7 x 2 saturates; a gain of 0 silences
    drive.reset()
    np.testing.assert_array_equal(drive.weights_frames(frames)[-1], w)
    np.testing.assert_allclose(drive.displacements(w), shapes.posed(np.zeros((30, 3)), w), atol=1e-6)
    lost = np.zeros(68, bool)
    lost[:5] = True
    assert drive.weights(frames[1], lost).shape == (52,)
    for bad in (np.ones(51), np.full(52, 2.5), np.full(52, np.nan), -np.ones(52)):
        with pytest.raises(RetargetError, match="gains"):
            drive.set_gains(bad)


def test_settings_round_trip_apply_and_fit(shapes):
    data = {"rig": "project", "gains": {"jawOpen": 1.25},
            "masks": {"eyeBlinkLeft": {"vertices": [2, 5, 9], "values": [0.0, 0.5, 1]}}}
    settings = ArkitSettings.from_json(data, 30)
    assert settings.rig == "project" and settings.gains[ARKIT_NAMES.index("jawOpen")] == 1.25
    assert ArkitSettings.from_json(settings.to_json(), 30).to_json() == settings.to_json()
    assert settings.to_json()["masks"] == {"eyeBlinkLeft": {"vertices": [2, 5], "values": [0.0, 0.5]}}
    fixed = settings.fixed_deltas(shapes.deltas)
    k = ARKIT_NAMES.index("eyeBlinkLeft")
    assert not fixed[k, 2].any() and np.allclose(fixed[k, 5], 0.5 * shapes.deltas[k, 5])
    np.testing.assert_array_equal(np.delete(fixed, k, axis=0), np.delete(shapes.deltas, k, axis=0))
    assert ArkitSettings().fixed_deltas(shapes.deltas) is shapes.deltas
    assert settings.fitting(30).fixes and not settings.fitting(5).fixes  # painted on another mesh
    assert ArkitSettings().to_json()["rig"] == "default"


@pytest.mark.parametrize("data, reason", [
    ({"gains": {"jawOpen": 10 ** 400}}, "gain of jawOpen"),
    ({"gains": {"jawOpen": math.inf}}, "gain of jawOpen"),
    ({"gains": {"jawOpen": None}}, "gain of jawOpen"),
    ({"gains": ["jawOpen"]}, "gains must be an object"),
    ({"masks": {"jawOpen": {"vertices": [10 ** 30], "values": [0.5]}}}, "vertex 10000"),
    ({"masks": {"jawOpen": {"vertices": [-1], "values": [0.5]}}}, "vertex -1"),
    ({"masks": {"jawOpen": {"vertices": [1], "values": [math.nan]}}}, "values must be numbers in [0, 1]"),
    ({"masks": {"jawOpen": {"vertices": [1], "values": [10 ** 400]}}}, "values must be numbers"),
    ({"masks": {"jawOpen": {"vertices": [1.5], "values": [0.5]}}}, "integer vertex indices"),
    ({"masks": {"jawOpen": [1, 2]}}, "vertices and values"),
    ({"masks": {"jawOpen": {"vertices": [1], "values": [0.5], "x": 1}}}, "vertices and values"),
])
def test_settings_refusals_name_the_shape_and_value(data, reason):
    with pytest.raises(RetargetError) as caught:
        ArkitSettings.from_json(data, 30)
    assert reason in str(caught.value)
