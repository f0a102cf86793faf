"""Smaller exports (issue 19): any rig as a four-influence skin (`retarget.weights.skin_fit`)
with its error recorded, the animation rate and key reduction (`retarget.gltf.keys`).

The oracles are independent of the code under test: the fit's recorded error against a
frame-by-frame brute force, what a glTF viewer draws (`retarget.gltf.animation`, the
specification's evaluation) against `skin_displacements`, reduced keys against every key
of the unreduced curve, resampled clips against `np.interp`.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from retarget.clips import Clip, ContractionClip
from retarget.errors import RetargetError
from retarget.gltf import export_gltf, export_muscles_gltf, read_gltf
from retarget.gltf.animation import drawn_vertices
from retarget.gltf.document import GltfDocument
from retarget.gltf.influences import is_joint_based, joint_influences
from retarget.gltf.keys import Keys, kept_keys, resampled
from retarget.landmarks import from_vertex_indices
from retarget.mesh import mesh_from_arrays
from retarget.muscles import place_muscles
from retarget.muscles.morphs import muscle_morphs
from retarget.sample_face import demo_weights, sample_face
from retarget.skin import SkinWeights, skin_displacements
from retarget.weights import compute_weights
from retarget.weights.skin_fit import four_influence_skin, motion_moment, skin_fit_error
from tests.gltf_check import assert_valid_gltf

FPS = 30.0


@pytest.fixture(scope="module")
def face():
    f = sample_face(1)
    mesh = mesh_from_arrays(f.vertices, f.faces, uv=f.uv, name="face")
    points = from_vertex_indices(f.landmarks68, mesh.n_vertices, "ibug68")
    frames = 90
    motion = np.tensordot(demo_weights(frames, FPS), f.expressions[:, f.landmarks68], axes=(1, 0))
    # uneven times, as a webcam delivers them: 29.7 fps with jitter
    rng = np.random.default_rng(3)
    times = np.cumsum(np.r_[0.0, (1 / 29.7) * (1 + 0.2 * rng.uniform(-1, 1, frames - 1))])
    clip = Clip("take", motion.astype(np.float32), times)
    weights = compute_weights("biharmonic", mesh.vertices, mesh.faces, points)
    return {"mesh": mesh, "points": points, "clip": clip, "weights": weights,
            "neutral": points.positions(mesh.vertices)}


def test_the_skin_form_of_a_dense_rig_is_a_one_set_skin_a_viewer_draws_as_its_weights_say(face, tmp_path):
    data = export_gltf(face["mesh"], face["points"], face["weights"], [face["clip"]], form="skin",
                       mesh_units="cm")
    path = tmp_path / "skin.glb"
    path.write_bytes(data)
    assert_valid_gltf(path)
    gltf = GltfDocument(data, "skin", None)
    attributes = vars(gltf.doc.meshes[0].primitives[0].attributes)
    assert attributes.get("JOINTS_0") is not None and attributes.get("JOINTS_1") is None
    assert not gltf.doc.meshes[0].primitives[0].targets
    back = read_gltf(data)
    assert back.deformation == "skin" and is_joint_based(back.weights)
    # what a viewer draws is the fitted skin exactly (to float32), in metres
    fitted = four_influence_skin(face["weights"], face["neutral"], face["clip"].displacements)
    clip = face["clip"]
    drawn = drawn_vertices(gltf, clip.times[::15])
    expected = 0.01 * (face["mesh"].vertices + skin_displacements(fitted, clip.displacements[::15]))
    assert np.abs(drawn - expected).max() < 1e-6
    # and the file's record of the error is the brute-force error of what it draws
    record = gltf.doc.scenes[0].extras["retarget"]["fit"]
    exact = face["mesh"].vertices + skin_displacements(face["weights"], clip.displacements)
    approx = face["mesh"].vertices + skin_displacements(fitted, clip.displacements)
    error = np.linalg.norm(exact - approx, axis=2)                      # (F, V) cm
    motion = np.linalg.norm(exact - face["mesh"].vertices, axis=2)
    assert record["from"] == "morph" and record["frames"] == clip.n_frames
    assert record["rms_relative"] == pytest.approx(np.sqrt((error ** 2).sum() / (motion ** 2).sum()), rel=1e-4)
    assert record["rms_mm"] == pytest.approx(10 * np.sqrt((error ** 2).mean()), rel=1e-4)
    assert record["worst_vertex_mm"] == pytest.approx(10 * np.sqrt((error ** 2).mean(0)).max(), rel=1e-4)
    assert 0 < record["rms_relative"] < 0.08


def test_the_fit_beats_keeping_the_four_largest_weights_and_keeps_rows_that_already_fit(face):
    weights, neutral, motion = face["weights"], face["neutral"], face["clip"].displacements
    fitted = four_influence_skin(weights, neutral, motion)
    assert (fitted.weights >= 0).all() and (fitted.row_sums() <= 1 + 1e-5).all()
    assert joint_influences(fitted)[0].shape[1] == 4
    # the obvious alternative: the four largest weights, negatives dropped, rescaled to the row
    dense = weights.dense()
    top = np.argsort(-dense, axis=1)[:, :4]
    kept = np.clip(np.take_along_axis(dense, top, 1), 0, None)
    kept *= np.clip(dense.sum(1, keepdims=True), 0, 1) / np.maximum(kept.sum(1, keepdims=True), 1e-12)
    naive = SkinWeights(top.astype(np.int32), kept.astype(np.float32), weights.n_joints)
    assert skin_fit_error(weights, fitted, motion).rms_relative < 0.8 * skin_fit_error(weights, naive, motion).rms_relative
    # a rig that is already a four-slot skin comes back as it was
    sparse = compute_weights("ellipsoid", face["mesh"].vertices, face["mesh"].faces, face["points"])
    fits = (sparse.weights > 0).sum(1) <= 3
    again = four_influence_skin(sparse, neutral, motion)
    assert np.abs(again.dense()[fits] - sparse.dense()[fits]).max() < 1e-6


def test_each_row_is_the_best_feasible_subset_of_its_four_largest_weights(face):
    weights, neutral, motion = face["weights"], face["neutral"], face["clip"].displacements
    fitted = four_influence_skin(weights, neutral, motion)
    c = motion_moment(neutral, motion)
    dense, got = weights.dense(), fitted.dense()
    rng = np.random.default_rng(0)
    for v in rng.choice(len(dense), 40, replace=False):
        w = dense[v]
        candidates = np.argsort(-w)[:4]
        cost = lambda x: (w - x) @ c @ (w - x)  # noqa: E731
        best = cost(got[v])
        # brute force over a grid of feasible rows on the same candidates never does better
        grid = np.linspace(0, 1, 11)
        for values in itertools.product(grid, repeat=3):
            if sum(values) > 1:
                continue
            x = np.zeros_like(w)
            x[candidates[:3]] = values
            assert cost(x) >= best - 1e-9


def test_kept_keys_drop_only_what_the_line_reproduces():
    times = np.arange(200) / 30.0
    rng = np.random.default_rng(1)
    corners = np.sort(rng.choice(np.arange(1, 199), 12, replace=False))
    knots = np.r_[0, corners, 199]
    values = np.column_stack([np.interp(np.arange(200), knots, rng.normal(size=len(knots))) for _ in range(3)])
    noisy = values + rng.uniform(-1e-4, 1e-4, values.shape)
    kept = kept_keys(times, noisy, 1e-3)
    assert set(knots) <= set(kept) and len(kept) < 3 * len(knots)
    line = np.column_stack([np.interp(times, times[kept], noisy[kept, a]) for a in range(3)])
    assert np.abs(line - noisy).max() <= 1e-3
    assert np.array_equal(kept_keys(times, noisy, 0.0), np.arange(200))


def test_resampled_clips_sit_on_the_rate_and_follow_the_take(face):
    clip = face["clip"]
    for rate in (24, 25, 30, 60):
        at = resampled(clip, rate)
        assert np.allclose(np.diff(at.times), 1 / rate) and at.times[0] == clip.times[0]
        assert at.times[-1] <= clip.times[-1] + 1e-9 and clip.times[-1] - at.times[-1] < 1 / rate
        expected = np.interp(at.times, clip.times, clip.displacements[:, 30, 1])
        assert np.allclose(at.displacements[:, 30, 1], expected, atol=1e-6)
    for bad in (23, 0, -30, float("nan"), True):
        with pytest.raises(RetargetError, match="rate must be one of 24, 25, 30, 60"):
            resampled(clip, bad)


def test_a_key_reduced_export_draws_within_the_tolerance_of_the_take(face, tmp_path):
    mesh, points, weights, clip = face["mesh"], face["points"], face["weights"], face["clip"]
    turns = np.column_stack([np.zeros((clip.n_frames, 1)), np.sin(np.linspace(0, 0.3, clip.n_frames))[:, None],
                             np.zeros((clip.n_frames, 1)), np.cos(np.linspace(0, 0.3, clip.n_frames))[:, None]])
    turning = Clip("turn", clip.displacements, clip.times, head_rotations=turns)
    for form in ("exact", "skin"):
        full = export_gltf(mesh, points, weights, [turning], form=form, mesh_units="cm")
        reduced = export_gltf(mesh, points, weights, [turning], form=form, key_tolerance=0.05,
                              mesh_units="cm")
        path = tmp_path / f"{form}.glb"
        path.write_bytes(reduced)
        assert_valid_gltf(path)
        assert len(reduced) < len(full)
        a, b = GltfDocument(full, "full", None), GltfDocument(reduced, "reduced", None)
        keys = sum(b.accessor(s.input).shape[0] for s in b.doc.animations[0].samplers)
        assert keys < 0.6 * sum(a.accessor(s.input).shape[0] for s in a.doc.animations[0].samplers)
        # every third frame of the take: kept keys and frames whose keys were dropped
        at = clip.times[::3]
        gap = np.abs(drawn_vertices(a, at) - drawn_vertices(b, at)).max()
        # 0.05 mm per component of every joint or feature; a morph vertex sums its features'
        # (its weights' |sum| stays below 2 on this rig), the head adds its own 0.05 mm
        assert gap < 3 * 0.05e-3, (form, gap)
        assert GltfDocument(reduced, "r", None).doc.scenes[0].extras["retarget"]["key_tolerance_mm"] == 0.05
        back = read_gltf(reduced)
        assert np.allclose(back.clips[0].times, clip.times.astype(np.float32)[np.isin(
            clip.times.astype(np.float32), back.clips[0].times)])


def test_rate_and_reduction_reach_the_muscle_export(face):
    mesh, points = face["mesh"], face["points"]
    model = place_muscles(mesh.vertices, mesh.faces, points.positions(mesh.vertices), "ibug68")
    morphs = muscle_morphs(model)
    dofs = len(morphs.names) + 1
    t = np.arange(90) / 29.7
    contractions = np.column_stack([0.5 * (1 - np.cos(t[:, None] * np.arange(1, dofs))) / 2,
                                    0.1 * np.clip(np.sin(t), 0, None)])
    clip = ContractionClip("muscles", contractions, t)
    data = export_muscles_gltf(mesh, morphs, [clip], rate=24, key_tolerance=0.05, mesh_units="cm")
    gltf = GltfDocument(data, "muscles", None)
    inputs = {gltf.accessor(s.input).shape[0] for s in gltf.doc.animations[0].samplers}
    assert max(inputs) <= int(t[-1] * 24) + 1
    # reduced keys stay on the 24 fps grid
    times = gltf.accessor(gltf.doc.animations[0].samplers[1].input)[:, 0]
    assert np.allclose(np.round(times * 24), times * 24, atol=1e-3)


def test_bad_export_options_are_refused_before_any_work(face):
    mesh, points, weights = face["mesh"], face["points"], face["weights"]
    with pytest.raises(RetargetError, match="form must be one of exact, skin"):
        export_gltf(mesh, points, weights, form="joints")
    with pytest.raises(RetargetError, match="rate must be one of"):
        export_gltf(mesh, points, weights, rate=29.97)
    for bad in (-1.0, float("inf"), float("nan")):
        with pytest.raises(RetargetError, match="key tolerance must be a number of millimetres"):
            Keys(None, bad)
