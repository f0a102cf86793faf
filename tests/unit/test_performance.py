"""`retarget.performance.Performance`, one played performance: a take plays whole at its own
times, regions mask each frame without refitting the transform, and a recording keeps the
rate it was played at with each frame's true time."""

from __future__ import annotations

import numpy as np
import pytest

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.performance import Performance
from retarget.sample_face import DEMO_PERFORMER, sample_face
from retarget.sources.take import Take

IBUG = get_layout("ibug68")


@pytest.fixture(scope="module")
def faces():
    target = sample_face(1)
    performer = sample_face(1, identity=DEMO_PERFORMER)
    jaw = list(performer.expression_names).index("jawOpen")
    neutral = performer.vertices[performer.landmarks68]
    opening = performer.expressions[jaw][performer.landmarks68]
    return target.vertices[target.landmarks68], neutral, opening


def _take(neutral, opening, n=45, fps=30.0) -> Take:
    weights = np.clip((np.arange(n) / fps - 0.6) * 2.0, 0.0, 1.0)  # still for 0.6 s, then opens
    frames = neutral + weights[:, None, None] * opening
    return Take(frames.astype(np.float32), IBUG.point_names, fps, layout="ibug68")


def test_a_take_plays_whole_at_its_own_times(faces):
    target, neutral, opening = faces
    take = _take(neutral, opening)
    clip = Performance(target, "ibug68").play(take, "jaw")
    assert clip.n_frames == take.n_frames == 45
    np.testing.assert_allclose(clip.times, take.frame_times())
    still = np.abs(clip.displacements[:18]).max()
    assert still < 1e-4 and np.abs(clip.displacements[-1]).max() > 0.1


def test_regions_mask_each_frame_without_refitting(faces):
    target, neutral, opening = faces
    performance = Performance(target, "ibug68", {"neutral": {"mode": "frame", "frame": 0}})
    cue = performance.cue(_take(neutral, opening))
    fitted = performance._fitted()
    whole = performance.displacements(cue.points)
    performance.set_regions(["brows"])
    assert performance._fitted() is fitted  # the same transform, masked per frame
    brows = IBUG.region_mask("brows")
    masked = performance.displacements(cue.points)
    np.testing.assert_array_equal(masked[:, brows], whole[:, brows])
    assert not masked[:, ~brows].any()


def test_a_recording_keeps_the_rate_it_was_played_at_and_the_true_times(faces):
    target, neutral, opening = faces
    performance = Performance(target, "ibug68", {"neutral": {"mode": "frame", "frame": 0}})
    performance.start_recording()
    times = np.cumsum(np.r_[0, np.random.default_rng(1).uniform(1 / 30, 3 / 30, 29)])  # frames dropped
    for i, t in enumerate(times):
        performance.push(neutral + (i / 30) * opening, float(t))
    take = performance.stop_recording(source="live", fps=30.0)
    assert take.fps == 30.0 and take.n_frames == 30 and take.source == "live"
    np.testing.assert_allclose(take.frame_times(), times - times[0])
    with pytest.raises(RetargetError, match="nothing was recorded"):
        performance.stop_recording()
