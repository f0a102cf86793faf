"""Tests for retarget.sources.conditioning: head motion removal, neutral capture modes,
filters, per-region gain and one-euro parameters, settings validation, and that a take
conditioned offline equals the same frames pushed one by one."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from retarget.errors import RetargetError
from retarget.layouts import get_layout
from retarget.sample_face import EXPRESSION_NAMES, demo_weights, posed_vertices, sample_face
from retarget.sources.conditioning import ConditionSettings, SourceConditioner, condition_take
from retarget.sources.filters import temporal_mean
from retarget.sources.headpose import stable_indices
from retarget.sources.take import Take

IBUG = get_layout("ibug68")
FACE = sample_face(1)
NEUTRAL = FACE.vertices[FACE.landmarks68]                          # (68, 3) cm
# an expression that leaves the stable points (nose, eye corners) still to 0.03 mm
STILL_ANCHORS = np.zeros(len(EXPRESSION_NAMES))
for name in ("jawOpen", "eyeBlink_L", "mouthFrown_L", "mouthFrown_R", "cheekPuff"):
    STILL_ANCHORS[EXPRESSION_NAMES.index(name)] = 1.0
EXPRESSION = posed_vertices(FACE, STILL_ANCHORS)[FACE.landmarks68]
KEEP = {"neutral": {"mode": "frame", "frame": 0}, "head_pose": "keep"}


def _moved(points, rotvec, shift):
    rotation = Rotation.from_rotvec(rotvec).as_matrix()
    return points @ rotation.T + np.asarray(shift), rotation


def _performance(frames=60, fps=30.0, seed=0):
    """(F, 68, 3) demo expressions and the same under a smooth rigid head motion."""
    face = posed_vertices(FACE, demo_weights(frames, fps))[:, FACE.landmarks68]
    t = np.arange(frames) / fps
    rotvecs = np.c_[0.2 * np.sin(2 * t), 0.3 * np.sin(1.3 * t + 1), 0.1 * np.sin(t)]
    moved = np.stack([_moved(face[i], rotvecs[i], [np.sin(t[i]), 0.5, -2 * t[i]])[0] for i in range(frames)])
    return face, moved


def test_rigid_head_motion_is_removed_and_reported_as_rotation():
    conditioner = SourceConditioner("ibug68", 3, {"neutral": {"mode": "frame", "frame": 0}})
    first = conditioner.push(NEUTRAL, 0.0)
    np.testing.assert_allclose(first, NEUTRAL, atol=1e-5)
    for i, (rotvec, shift) in enumerate([([0.3, -0.2, 0.1], [2.0, -1.0, 5.0]), ([0, 0.6, 0], [0, 0, -3.0])]):
        moved, rotation = _moved(EXPRESSION, rotvec, shift)
        out = conditioner.push(moved, 0.1 * (i + 1))
        assert np.abs(moved - EXPRESSION).max() > 1.0                 # centimetres of head motion ...
        np.testing.assert_allclose(out, EXPRESSION, atol=0.01)        # ... gone to 0.1 mm
        np.testing.assert_allclose(conditioner.rotation_, rotation, atol=1e-3)
    keep = SourceConditioner("ibug68", 3, KEEP)
    keep.push(NEUTRAL, 0.0)
    np.testing.assert_allclose(keep.push(moved, 0.1), moved, atol=1e-5)
    np.testing.assert_array_equal(keep.rotation_, np.eye(3))


def test_first_seconds_neutral_is_captured_while_the_head_moves():
    # 0.5 s of a still face under head motion, then expressions under head motion
    still = np.stack([_moved(NEUTRAL, [0.1 * np.sin(i), 0.2 * np.cos(i) - 0.2, 0], [i * 0.1, 0, 0])[0]
                      for i in range(16)])
    face, moved = _performance(frames=40)
    frames = np.concatenate([still, moved])
    take = Take(frames, IBUG.point_names, 30.0, layout="ibug68")
    out, neutral = condition_take(take, {"neutral": {"mode": "first_seconds", "seconds": 0.5}})
    # t <= 0.5 s: frames 0..15 give the neutral, and every frame is kept, at its own time
    assert out.n_frames == 56
    np.testing.assert_allclose(out.frame_times(), np.arange(56) / 30)
    # the neutral is the still face, in the first frame's head frame
    np.testing.assert_allclose(neutral, still[0], atol=1e-3)
    # each output frame is the face in that same head frame: compare shapes by aligning
    # the truth once, on the first frame's pose; the still frames are the neutral
    rotation0 = Rotation.from_rotvec([0, 0.2 * np.cos(0) - 0.2, 0]).as_matrix()
    expected = np.concatenate([np.repeat(still[:1], 16, 0), face @ rotation0.T])
    error = (out.points - out.points.mean(1, keepdims=True)) - (expected - expected.mean(1, keepdims=True))
    assert np.median(np.abs(error)) < 0.01 and np.abs(error).max() < 0.5


def test_keep_mode_neutral_is_the_takes_neutral_and_frame_mode_waits_for_its_frame():
    _, moved = _performance(frames=30)
    take = Take(moved, IBUG.point_names, 30.0, layout="ibug68")
    out, neutral = condition_take(take, {"neutral": {"mode": "first_seconds", "seconds": 0.2},
                                         "head_pose": "keep"})
    np.testing.assert_allclose(neutral, take.neutral(seconds=0.2), atol=1e-6)  # frames 0..6
    np.testing.assert_array_equal(out.points, take.points)  # every frame, as it was
    conditioner = SourceConditioner("ibug68", 3, {"neutral": {"mode": "frame", "frame": 3}, "head_pose": "keep"})
    outputs = [conditioner.push(moved[i], i / 30) for i in range(6)]
    assert outputs[:3] == [None] * 3 and conditioner.neutral_ is not None
    np.testing.assert_array_equal(conditioner.neutral_, moved[3].astype(np.float32))
    conditioner.reset()
    assert conditioner.neutral_ is None and conditioner.push(moved[0], 0.0) is None


def test_given_neutral():
    conditioner = SourceConditioner("ibug68", 3, {"neutral": {"mode": "given"}}, neutral=NEUTRAL)
    moved, _ = _moved(EXPRESSION, [0.1, 0.2, 0.3], [1, 2, 3])
    np.testing.assert_allclose(conditioner.push(moved, 0.0), EXPRESSION, atol=0.01)
    with pytest.raises(RetargetError, match='neutral mode "given" needs the neutral points'):
        SourceConditioner("ibug68", 3, {"neutral": {"mode": "given"}})
    with pytest.raises(RetargetError, match="a neutral was given but the neutral mode is 'first_seconds'"):
        SourceConditioner("ibug68", 3, None, neutral=NEUTRAL)


def test_gain_scales_only_its_regions_motion():
    face, _ = _performance(frames=40)
    take = Take(face, IBUG.point_names, 30.0, layout="ibug68")
    plain, s0 = condition_take(take, KEEP)
    gained, _ = condition_take(take, {**KEEP, "gain": {"all": 0.5, "mouth": 2.0, "nose_tip": 0.0}})
    mouth = IBUG.region_mask("mouth")
    nose = IBUG.index("nose_tip")
    rest = ~mouth
    rest[nose] = False
    np.testing.assert_allclose(gained.points[:, mouth], s0[mouth] + 2.0 * (plain.points[:, mouth] - s0[mouth]), atol=1e-5)
    np.testing.assert_allclose(gained.points[:, rest], s0[rest] + 0.5 * (plain.points[:, rest] - s0[rest]), atol=1e-5)
    np.testing.assert_allclose(gained.points[:, nose], np.broadcast_to(s0[nose], (40, 3)), atol=1e-6)
    assert np.abs(plain.points[:, mouth] - s0[mouth]).max() > 0.3  # the mouth did move


def test_filters_run_after_head_removal():
    face, moved = _performance(frames=30)
    rng = np.random.default_rng(1)
    noisy = moved + rng.normal(scale=0.02, size=moved.shape)
    take = Take(noisy, IBUG.point_names, 30.0, layout="ibug68")
    stabilised, _ = condition_take(take, {"neutral": {"mode": "frame", "frame": 0}})
    averaged, _ = condition_take(take, {"neutral": {"mode": "frame", "frame": 0}, "filter": "mean3"})
    np.testing.assert_allclose(averaged.points, temporal_mean(stabilised.points), atol=1e-5)


def test_one_euro_per_region_and_unit_free_beta():
    face, _ = _performance(frames=150)  # the brows rise at 3.7 s
    rng = np.random.default_rng(2)
    noisy = face + rng.normal(scale=0.02, size=face.shape)
    settings = {**KEEP, "filter": "one_euro",
                "one_euro": {"all": {"min_cutoff": 1e5, "beta": 0.0}, "brows": {"min_cutoff": 0.3, "beta": 0.0}}}
    take = Take(noisy, IBUG.point_names, 30.0, layout="ibug68")
    out, _ = condition_take(take, settings)
    brows = IBUG.region_mask("brows")
    np.testing.assert_allclose(out.points[:, ~brows], noisy[:, ~brows], atol=2e-3)  # a 100 kHz cutoff passes all
    lag = np.abs(out.points[:, brows] - face[:, brows]).max()
    assert lag > 0.1                                                                  # a 0.3 Hz one lags
    # beta is per face size: the same settings on the take in mm give the result in mm
    speedy = {**KEEP, "filter": "one_euro", "one_euro": {"all": {"min_cutoff": 0.5, "beta": 8.0}}}
    cm, _ = condition_take(take, speedy)
    mm, _ = condition_take(Take(noisy * 10, IBUG.point_names, 30.0, layout="ibug68"), speedy)
    np.testing.assert_allclose(mm.points, 10 * cm.points, rtol=1e-4, atol=1e-3)


def test_offline_equals_pushing_every_frame_once_the_neutral_is_known():
    _, moved = _performance(frames=45)
    moved[10:14, 5] = np.nan
    take = Take(moved, IBUG.point_names, 30.0, layout="ibug68")
    settings = {"neutral": {"mode": "first_seconds", "seconds": 0.3}, "filter": "one_euro",
                "one_euro": {"mouth": {"min_cutoff": 2.0, "beta": 3.0}}, "gain": {"brows": 1.5}}
    out, neutral = condition_take(take, settings)
    # the neutral is what a live capture of the first 0.3 s (frames 0..9) takes
    live = SourceConditioner("ibug68", 3, ConditionSettings.from_dict(settings))
    for p, t in zip(take.points[:11], take.frame_times()[:11]):
        live.push(p, t)
    np.testing.assert_array_equal(live.neutral_, neutral)
    # and every frame is pushed through a conditioner that has that neutral from the start
    given = dict(settings, neutral={"mode": "given"})
    known = SourceConditioner("ibug68", 3, ConditionSettings.from_dict(given), neutral=neutral)
    pushed = [known.push(p, t) for p, t in zip(take.points, take.frame_times())]
    np.testing.assert_array_equal(np.stack(pushed), out.points)
    assert out.n_frames == 45 and out.meta["conditioning"]["neutral"]["mode"] == "first_seconds"
    assert np.isnan(out.points[10:14, 5]).all() and np.isfinite(np.delete(out.points[:, 5], range(10, 14), 0)).all()


def test_two_dimensional_sources_keep_their_head_pose():
    face, _ = _performance(frames=10)
    conditioner = SourceConditioner("ibug68", 2, {"neutral": {"mode": "frame", "frame": 0}})
    for i in range(10):
        out = conditioner.push(face[i, :, :2] + 3.0, i / 30)
    np.testing.assert_allclose(out, face[9, :, :2] + 3.0, atol=1e-5)
    np.testing.assert_array_equal(conditioner.rotation_, np.eye(3))


def test_points_without_a_layout_take_the_all_selector():
    points = np.random.default_rng(3).normal(size=(5, 4, 3))
    take = Take(points, ("a", "b", "c", "d"), 30.0)
    out, s0 = condition_take(take, {**KEEP, "gain": {"all": 2.0}})
    np.testing.assert_allclose(out.points, s0 + 2 * (points - s0), atol=1e-5)
    with pytest.raises(RetargetError, match="only the selector 'all'; got 'mouth'"):
        condition_take(take, {**KEEP, "gain": {"mouth": 2.0}})
    with pytest.raises(RetargetError, match="head pose removal needs a layout"):
        condition_take(take, {"neutral": {"mode": "frame", "frame": 0}})


def test_capture_errors_name_points_and_spans():
    _, moved = _performance(frames=20)
    moved[:8, IBUG.index("chin")] = np.nan
    take = Take(moved, IBUG.point_names, 30.0, layout="ibug68")
    with pytest.raises(RetargetError, match="neutral frame 2 has lost points: chin"):
        condition_take(take, {"neutral": {"mode": "frame", "frame": 2}})
    with pytest.raises(RetargetError, match="ends before its neutral capture does"):
        condition_take(take, {"neutral": {"mode": "first_seconds", "seconds": 5.0}})
    conditioner = SourceConditioner("ibug68", 3)
    with pytest.raises(RetargetError, match=r"points must have shape \(68, 3\); got \(68, 2\)"):
        conditioner.push(np.zeros((68, 2)), 0.0)
    with pytest.raises(RetargetError, match="dims must be 2 or 3"):
        SourceConditioner("ibug68", 4)


def test_a_live_capture_waits_for_points_its_span_missed():
    """With `lost_wait`, a "first_seconds" capture whose span never saw a point goes on
    until it does (its neutral then holds the point where it was first seen); without
    it, or past the wait, the capture is refused naming the point."""
    chin = IBUG.index("chin")
    frames = np.repeat(NEUTRAL[None], 12, axis=0)
    frames[:5, chin] = np.nan  # seen from the sixth frame, 0.5 s in at 10 fps
    settings = {"neutral": {"mode": "first_seconds", "seconds": 0.2}, "head_pose": "keep"}
    waiting = SourceConditioner("ibug68", 3, settings, lost_wait=1.0)
    out = [waiting.push(f, i / 10) for i, f in enumerate(frames)]
    assert all(o is None for o in out[:6]) and out[6] is not None
    np.testing.assert_allclose(waiting.neutral_, NEUTRAL, atol=1e-5)
    with pytest.raises(RetargetError, match="lost throughout the first 0.2 s: chin"):
        at_once = SourceConditioner("ibug68", 3, settings)
        for i, f in enumerate(frames):
            at_once.push(f, i / 10)
    with pytest.raises(RetargetError, match="lost_wait must be"):
        SourceConditioner("ibug68", 3, settings, lost_wait=-1.0)


@pytest.mark.parametrize("late_from", [8, 18])
def test_a_take_point_lost_through_the_capture_takes_its_place_once_seen(late_from):
    """A take plays though a point is lost through its neutral's span (a sticker take's
    temple): the neutral holds it where it sits over its first span seen, in the head
    frame; seen only in the take's last frames, at the median of those."""
    _, moved = _performance(frames=20)
    chin = IBUG.index("chin")
    moved[:late_from, chin] = np.nan
    take = Take(moved, IBUG.point_names, 30.0, layout="ibug68")
    out, neutral = condition_take(take, {"neutral": {"mode": "first_seconds", "seconds": 0.2}})
    assert np.isfinite(neutral).all() and np.isfinite(out.points[late_from:, chin]).all()
    times = take.frame_times()
    span = (times >= times[late_from]) & (times <= times[late_from] + 0.2)   # its first 0.2 s seen
    assert span.sum() >= 2
    np.testing.assert_allclose(neutral[chin], np.median(out.points[span, chin], axis=0), atol=1e-4)
    with pytest.raises(RetargetError, match="ends before its neutral capture does"):
        condition_take(Take(moved[:3], IBUG.point_names, 30.0, layout="ibug68"),
                       {"neutral": {"mode": "first_seconds", "seconds": 0.2}})


@pytest.mark.parametrize("head_pose", ["keep", "remove"])
def test_a_point_missed_past_the_wait_joins_when_it_shows(head_pose):
    """Past `lost_wait` the capture is taken without the points it never saw (Woodward's
    temples, seen only when the head turns): they come out NaN, ``waiting_`` names them,
    and each joins once seen for the capture's span, at its median place then (in the head
    frame: a late anchor anchors too), in a new ``neutral_`` array."""
    temple = IBUG.index("eye_left_outer")   # a stable point of ibug68: it anchors the head
    assert temple in stable_indices(IBUG)
    rng = np.random.default_rng(3)
    turn = Rotation.from_rotvec([0.0, 0.3, 0.05]).as_matrix()
    frames = np.repeat(NEUTRAL[None], 30, axis=0) + rng.normal(0, 0.01, (30, *NEUTRAL.shape))
    frames[20:] = frames[20:] @ turn.T + [1.0, 0.5, -2.0]   # the head turns, the face still
    frames[:12, temple] = np.nan   # seen from 1.2 s in at 10 fps
    settings = {"neutral": {"mode": "first_seconds", "seconds": 0.2}, "head_pose": head_pose}
    late = SourceConditioner("ibug68", 3, settings, lost_wait=0.2)
    out, waiting, neutrals = [], [], []
    for i, f in enumerate(frames):
        out.append(late.push(f, i / 10))
        waiting.append(late.waiting_)
        neutrals.append(late.neutral_)
    first = next(i for i, o in enumerate(out) if o is not None)
    assert first == 5 and waiting[first:15] == [("eye_left_outer",)] * (15 - first)
    captured = neutrals[first]
    assert all(n is captured for n in neutrals[first:15])
    assert np.isnan(captured[temple]).all() and np.isfinite(np.delete(captured, temple, axis=0)).all()
    # seen from 1.2 s, it joins at the first frame past its 0.2 s span, as the capture did
    assert all(np.isnan(o[temple]).all() for o in out[first:15])
    assert waiting[15] == () and neutrals[15] is not captured
    assert np.isfinite(out[15][temple]).all()
    np.testing.assert_allclose(late.neutral_[temple], NEUTRAL[temple], atol=0.05)
    np.testing.assert_allclose(np.delete(late.neutral_, temple, axis=0), np.delete(captured, temple, axis=0))
    # after the turn, the face is still: with the head removed, every point is at its neutral
    if head_pose == "remove":
        np.testing.assert_allclose(out[-1], late.neutral_, atol=0.1)
    assert np.isfinite(out[-1]).all()
    late.reset()
    assert late.waiting_ == () and late.neutral_ is None


def test_a_point_seen_only_before_the_head_pose_is_fixed_waits_and_joins():
    """A point seen in the capture only in frames whose anchors fix no head pose (two of
    them in view) has no registered place: its neutral is NaN. It waits (``waiting_``) and
    joins once seen, as a point never seen does, instead of staying undriven for good."""
    mouth = IBUG.index("mouth_corner_right")
    stable = stable_indices(IBUG)
    frames = np.repeat(NEUTRAL[None], 30, axis=0)
    frames[0, stable[2:]] = np.nan          # frame 0: 2 anchors, no pose
    frames[1:12, mouth] = np.nan            # the mouth corner seen in frame 0 only, then from 1.2 s
    settings = {"neutral": {"mode": "first_seconds", "seconds": 0.2}, "head_pose": "remove"}
    late = SourceConditioner("ibug68", 3, settings, lost_wait=0.2)
    out, waiting = [], []
    for i, f in enumerate(frames):
        out.append(late.push(f, i / 10))
        waiting.append(late.waiting_)
    first = next(i for i, o in enumerate(out) if o is not None)
    assert waiting[first] == ("mouth_corner_right",)
    assert np.isfinite(out[-1]).all()
    np.testing.assert_allclose(late.neutral_[mouth], NEUTRAL[mouth], atol=1e-5)


def test_settings_round_trip_through_json_and_defaults():
    settings = ConditionSettings(neutral={"mode": "frame", "frame": 4}, head_pose="keep", apply_rotation=True,
                                 filter="one_euro", one_euro={"mouth": {"min_cutoff": 2, "beta": 1}, "d_cutoff": 2},
                                 gain={"brows": 1.5})
    back = ConditionSettings.from_dict(json.loads(json.dumps(settings.to_dict())))
    assert back == settings and back.neutral == {"mode": "frame", "seconds": 0.5, "frame": 4}
    default = ConditionSettings.from_dict({})
    assert default == ConditionSettings() and default.head_pose == "remove" and default.filter == "none"


@pytest.mark.parametrize("data, message", [
    ({"colour": 1}, "unknown conditioning settings: colour"),
    ({"neutral": {"mode": "later"}}, "neutral mode must be one of first_seconds, frame, given"),
    ({"neutral": {"seconds": -1}}, "neutral seconds must be a number >= 0"),
    ({"neutral": {"frame": 1.5}}, "neutral frame must be an integer >= 0"),
    ({"neutral": {"when": 0}}, "neutral has unknown keys: when"),
    ({"head_pose": "fix"}, "head_pose must be one of remove, keep"),
    ({"filter": "kalman"}, "filter must be one of none, mean3, one_euro"),
    ({"apply_rotation": "yes"}, "apply_rotation must be true or false"),
    ({"gain": {"lips": 2}}, "gain selector 'lips' is not a region, group or point name"),
    ({"gain": {"mouth": -1}}, r"gain\['mouth'\] must be a number >= 0"),
    ({"one_euro": {"mouth": {"min_cutoff": 0}}}, r"one_euro\['mouth'\] min_cutoff must be a number > 0"),
    ({"one_euro": {"mouth": {"speed": 1}}}, r"one_euro\['mouth'\] must be"),
    ({"one_euro": {"d_cutoff": 0}}, "one_euro d_cutoff must be a number > 0"),
    ([1], "conditioning settings must be an object"),
])
def test_bad_settings_are_refused_by_name(data, message):
    with pytest.raises(RetargetError, match=message):
        ConditionSettings.from_dict(data)


def test_live_capture_waits_for_a_face_and_starts_again_after_a_failed_capture():
    """A camera that shows no face at first (all points lost) delays the capture rather
    than failing it; a capture spoiled by a lost point fails once, then the next frames
    capture the neutral afresh."""
    face, _ = _performance(frames=30)
    conditioner = SourceConditioner("ibug68", 3, {"neutral": {"mode": "first_seconds", "seconds": 0.1},
                                                  "head_pose": "keep", "filter": "none"})
    lost = np.full((68, 3), np.nan)
    assert all(conditioner.push(lost, i / 30) is None for i in range(10))   # no face yet
    spoiled = NEUTRAL.copy()
    spoiled[IBUG.index("chin")] = np.nan
    outputs = [conditioner.push(spoiled, (10 + i) / 30) for i in range(4)]  # 0.1 s of frames
    with pytest.raises(RetargetError, match="chin"):
        conditioner.push(spoiled, 14 / 30)                                  # the capture ends: chin never seen
    assert all(o is None for o in outputs)
    for i in range(4):                                                      # a new capture of the neutral
        assert conditioner.push(NEUTRAL, (15 + i) / 30) is None
    out = [conditioner.push(face[i], (19 + i) / 30) for i in range(10)]
    np.testing.assert_allclose(conditioner.neutral_, NEUTRAL, atol=1e-5)
    assert all(o is not None for o in out)
    np.testing.assert_allclose(out[-1], face[9], atol=1e-4)
